"""Foundation: camera, depth I/O, points, normals, neighbour graph, foreground."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from conftest import shared
from depthpose import io as dpio


def sphere_depth(cam: dp.Camera, c, r) -> np.ndarray:
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    ray = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1)
    c = np.asarray(c, np.float64)
    a = (ray**2).sum(-1)
    b = ray @ c
    disc = b * b - a * (c @ c - r * r)
    t = np.where(disc >= 0, (b - np.sqrt(np.maximum(disc, 0))) / a, 0.0)
    return t.astype(np.float32)


# ---- camera --------------------------------------------------------------------------
def test_camera_presets_and_round_trip():
    assert dp.Camera.kinect_v1().shape == (480, 640)
    assert dp.Camera.kinect_v1_qvga().shape == (240, 320)
    itop = dp.Camera.itop()
    assert itop.shape == (240, 320) and abs(itop.fx - 285.71) < 1e-9
    rng = np.random.default_rng(0)
    pts = rng.uniform([-1, -1, 0.5], [1, 1, 5], size=(100, 3))
    uv = itop.project(pts)
    back = itop.back_project(uv, pts[:, 2])
    np.testing.assert_allclose(back, pts, atol=1e-12)
    assert np.isnan(itop.project(np.array([[0.0, 0.0, -1.0]]))).all()


@pytest.mark.parametrize(
    "args, name",
    [
        ((0, 100, 10, 10, 20, 20), "fx"),
        ((100, float("nan"), 10, 10, 20, 20), "fy"),
        ((100, 100, 10, 10, 0, 20), "width"),
        ((100, 100, 500, 10, 20, 20), "cx"),
    ],
)
def test_camera_rejects_nonsense(args, name):
    with pytest.raises(dp.DepthPoseError, match=name):
        dp.Camera(*args)


# ---- points, normals, graph ------------------------------------------------------------
def test_points_normals_on_a_sphere():
    cam = dp.Camera(300, 300, 79.5, 59.5, 160, 120)
    c, r = np.array([0.05, -0.02, 1.5]), 0.2
    depth = sphere_depth(cam, c, r)
    cloud = dp.point_cloud(depth, cam)
    assert len(cloud) == int((depth > 0).sum())
    np.testing.assert_allclose(np.linalg.norm(cloud.points - c, axis=1), r, atol=1e-4)
    radial = (cloud.points - c) / r
    cosang = (radial * cloud.normals).sum(1)
    facing = -(radial * cloud.points).sum(1) / np.linalg.norm(cloud.points, axis=1)
    assert (cosang > 0).all()
    assert np.degrees(np.arccos(np.clip(cosang[facing > 0.5], -1, 1))).max() < 2.0
    # pixel coordinates point back at the depth pixels
    rows, cols = cloud.pixels.T
    np.testing.assert_allclose(depth[rows, cols], cloud.points[:, 2])


def test_graph_edges_match_pixels_and_geometry():
    cam = dp.Camera(100, 100, 15.5, 11.5, 32, 24)
    depth = np.full((24, 32), 2.0, np.float32)
    depth[5:9, 5:9] = 0  # a hole
    pts, pix = dp.depth_to_points(depth, cam)
    for conn in (4, 8):
        edges, dist, dz = dp.pixel_graph(depth, cam, connectivity=conn)
        d = np.abs(pix[edges[:, 0]] - pix[edges[:, 1]])
        assert (d.max(1) == 1).all()
        if conn == 4:
            assert (d.sum(1) == 1).all()
        np.testing.assert_allclose(
            dist, np.linalg.norm(pts[edges[:, 1]] - pts[edges[:, 0]], axis=1), rtol=1e-5
        )
        np.testing.assert_allclose(dz, pts[edges[:, 1], 2] - pts[edges[:, 0], 2], atol=1e-6)
    e4, _, _ = dp.pixel_graph(depth, cam, connectivity=4)
    e8, _, _ = dp.pixel_graph(depth, cam, connectivity=8)
    assert len(e8) > len(e4)
    with pytest.raises(dp.DepthPoseError, match="connectivity"):
        dp.pixel_graph(depth, cam, connectivity=6)


def test_uint16_and_float64_depth_are_converted():
    cam = dp.Camera(100, 100, 15.5, 11.5, 32, 24)
    mm = np.full((24, 32), 2500, np.uint16)
    p16, _ = dp.depth_to_points(mm, cam)
    p64, _ = dp.depth_to_points(np.full((24, 32), 2.5), cam)
    np.testing.assert_allclose(p16, p64, atol=1e-6)
    assert p16[:, 2].max() == pytest.approx(2.5)


# ---- bad input -------------------------------------------------------------------------
CAM = dp.Camera(100, 100, 15.5, 11.5, 32, 24)
GOOD = np.full((24, 32), 2.0, np.float32)


@pytest.mark.parametrize(
    "depth, match",
    [
        (np.ones(10, np.float32), "2-D"),
        (np.ones((2, 24, 32), np.float32), "2-D"),
        (np.zeros((0, 32), np.float32), "empty"),
        (np.where(np.eye(24, 32, dtype=bool), np.inf, GOOD).astype(np.float32), ">= 0"),
        (np.where(np.eye(24, 32, dtype=bool), -1.0, GOOD).astype(np.float32), ">= 0"),
        (np.full((24, 64), 2.0, np.float32)[:, ::2], "contiguous"),
        (np.full((24, 32), 2, np.int8), "dtype"),
        (np.full((20, 30), 2.0, np.float32), "camera"),
        ([[2.0] * 32] * 24, "numpy array"),
    ],
)
def test_bad_depth_raises_naming_the_argument(depth, match):
    with pytest.raises(dp.DepthPoseError, match=match) as e:
        dp.depth_to_points(depth, CAM)
    assert isinstance(e.value, ValueError)
    assert "depth" in str(e.value)


def test_nan_and_zero_are_no_reading_not_errors():
    d = GOOD.copy()
    d[0, :5] = np.nan
    d[1, :5] = 0
    pts, _ = dp.depth_to_points(d, CAM)
    assert len(pts) == d.size - 10


def test_all_zero_depth_has_no_body():
    with pytest.raises(dp.NoBodyError, match="no valid reading"):
        dp.foreground_mask(np.zeros((24, 32), np.float32))
    with pytest.raises(dp.DepthPoseError):
        dp.foreground_mask(np.full((24, 32), np.nan, np.float32))


def test_a_piece_across_a_dropout_seam_joins_by_its_step_and_size():
    """A body (40×15 pixels at 2 m) and a 12-pixel piece 0.3 m behind it, beyond a
    one-pixel dropout seam, in front of a wall at 4 m."""
    depth = np.full((60, 80), 4.0, np.float32)
    depth[10:50, 30:45] = 2.0
    depth[20:24, 45] = 0.0  # the seam: no reading
    depth[20:24, 46:49] = 2.3  # the piece
    background = np.full_like(depth, 4.0)
    piece = np.zeros(depth.shape, bool)
    piece[20:24, 46:49] = True

    def kept(**options):
        mask = dp.foreground_mask(depth, background, **options)
        assert mask[10:50, 30:45].all()
        return bool(mask[piece].all()), bool(mask[piece].any())

    assert kept() == (True, True)  # every piece joins by default
    assert kept(min_joined_piece=12) == (True, True)
    assert kept(min_joined_piece=13) == (False, False)
    assert kept(attach_depth=0.35) == (True, True)
    assert kept(attach_depth=0.25) == (False, False)


def test_bad_mask_and_background():
    with pytest.raises(dp.InvalidInputError, match="mask"):
        dp.depth_to_points(GOOD, CAM, mask=np.ones((3, 3), bool))
    with pytest.raises(dp.InvalidInputError, match="background"):
        dp.foreground_mask(GOOD, np.ones((3, 3), np.float32))
    with pytest.raises(dp.InvalidInputError, match="min_depth"):
        dp.foreground_mask(GOOD, min_depth=5.0, max_depth=1.0)


# ---- I/O -------------------------------------------------------------------------------
def test_depth_io_round_trips(tmp_path):
    rng = np.random.default_rng(1)
    depth = np.round(rng.uniform(0.5, 4.0, (24, 32)), 3).astype(np.float32)
    depth[3, 3] = 0
    for name in ("d.png", "d.npy", "d.pfm"):
        dpio.write_depth(tmp_path / name, depth)
        back = dp.read_depth(tmp_path / name)
        np.testing.assert_allclose(back, depth, atol=1e-6, err_msg=name)
    raw = (depth * 1000).round().astype("<u2")
    raw.tofile(tmp_path / "d.u16")
    np.testing.assert_allclose(dp.read_depth(tmp_path / "d.u16", shape=(24, 32)), depth, atol=1e-6)
    with pytest.raises(dp.FileFormatError, match="shape"):
        dp.read_depth(tmp_path / "d.u16")


def test_bad_files(tmp_path):
    with pytest.raises(dp.FileFormatError, match="no such file"):
        dp.read_depth(tmp_path / "missing.png")
    dpio.write_depth(tmp_path / "ok.png", GOOD)
    data = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "trunc.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(dp.FileFormatError, match="corrupt"):
        dp.read_depth(tmp_path / "trunc.png")
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    with pytest.raises(dp.FileFormatError):
        dp.read_depth(tmp_path / "junk.png")
    from depthpose import viz

    viz.save_png(tmp_path / "rgb8.png", np.zeros((4, 5, 3), np.uint8))
    with pytest.raises(dp.FileFormatError, match="not a depth image"):
        dp.read_depth(tmp_path / "rgb8.png")
    gray = dp.read_image(tmp_path / "rgb8.png")
    assert gray.shape == (4, 5) and gray.dtype == np.float32
    (tmp_path / "bad.pfm").write_bytes(b"Pf\n10 10\n-1.0\n" + b"\0" * 12)
    with pytest.raises(dp.FileFormatError, match="truncated"):
        dp.read_depth(tmp_path / "bad.pfm")
    with pytest.raises(dp.FileFormatError, match="unknown depth format"):
        (tmp_path / "x.bmp").write_bytes(b"BM")
        dp.read_depth(tmp_path / "x.bmp")
    with pytest.raises(dp.InvalidInputError, match="scale"):
        dp.read_depth(tmp_path / "ok.png", scale=-1)


def test_npz_readers_refuse_empty_truncated_and_missing_files(tmp_path):
    from depthpose import synth

    np.savez_compressed(tmp_path / "ok.npz", depth=np.zeros((2, 3, 4), np.float32))
    data = (tmp_path / "ok.npz").read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "empty.npz").write_bytes(b"")
    for name in ["trunc.npz", "empty.npz", "missing.npz"]:
        with pytest.raises(dp.FileFormatError, match=name):
            synth.load(tmp_path / name)
        with pytest.raises(dp.FileFormatError, match=name):
            dp.TemplateDatabase.load(tmp_path / name)


# A negative integer argument is bad input that names the argument, not an
# OverflowError from the integer conversion.
_IMG = np.random.default_rng(0).integers(0, 255, (40, 50), np.uint8)
_CAM = dp.Camera(100, 100, 16, 12, 32, 24)
_NEGATIVE_INT_CALLS = {
    "window": lambda: dp.stereo.match(_IMG, _IMG, window=-5),
    "max_disparity": lambda: dp.stereo.match(_IMG, _IMG, max_disparity=-1),
    "num_seeds": lambda: dp.stereo.match(_IMG, _IMG, num_seeds=-1),
    "min_segment": lambda: dp.stereo.match(_IMG, _IMG, min_segment=-1),
    "seed": lambda: dp.stereo.match(_IMG, _IMG, seed=-1),
    "radius": lambda: dp.surface_normals(GOOD, _CAM, radius=-1),
    "connectivity": lambda: dp.pixel_graph(GOOD, _CAM, connectivity=-4),
    "min_component": lambda: dp.foreground_mask(GOOD, min_component=-1),
    "min_joined_piece": lambda: dp.foreground_mask(GOOD, GOOD + 1, min_joined_piece=-1),
    "rings": lambda: dp.BodyModel().superquadric_meshes(dp.BodyModel.neutral_pose(), rings=-3),
    "samples": lambda: dp.surface_context(GOOD, _CAM, samples=-1),
}


@pytest.mark.parametrize("name", sorted(_NEGATIVE_INT_CALLS))
def test_negative_integer_arguments_are_named(name):
    with pytest.raises(dp.DepthPoseError, match=name):
        _NEGATIVE_INT_CALLS[name]()
    with pytest.raises(dp.DepthPoseError, match="seed"):
        dp.stereo.match(_IMG, _IMG, seed=2**64)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda v: dp.Camera(100, 100, 16, 12, v, 24), "width"),
        (lambda v: dp.FitConfig(stride=v), "stride"),
        (lambda v: dp.FitConfig(max_iterations=v), "max_iterations"),
        (lambda v: dp.graphcut.Graph(v), "n_nodes"),
        (lambda v: dp.stereo.match(_IMG, _IMG, window=v), "window"),
    ],
)
def test_huge_integer_arguments_are_named(call, name):
    # Beyond 64 bits too: no OverflowError, and the message shows the value given.
    for v in [2**64 + 1, 10**30]:
        with pytest.raises(dp.DepthPoseError, match=f"{name}.*{v}"):
            call(v)


# ---- foreground on the shared data ----------------------------------------------------------
def test_foreground_iou_on_shared_synthetic_sequences():
    folder = shared("synth")
    ious = []
    for f in sorted(folder.glob("*.npz")):
        d = np.load(f)
        for t in range(0, d["depth"].shape[0], 3):
            m = dp.foreground_mask(d["depth"][t], d["background"])
            g = d["mask"][t]
            ious.append((m & g).sum() / (m | g).sum())
    assert len(ious) > 50
    assert np.mean(ious) >= 0.97, np.mean(ious)
    assert np.min(ious) >= 0.85


def test_foreground_on_real_kinect_frames_picks_the_nearest_person():
    files = sorted(shared("real_depth", "skeltrack").glob("*.u16"))
    assert len(files) == 12
    import scipy.ndimage as ndi

    two_people = 0
    for f in files:
        depth = dp.read_depth(f)
        m = dp.foreground_mask(depth)
        valid = depth > 0
        # nearly all of one person: the mask is a large connected piece of valid pixels
        assert m.sum() > 0.5 * valid.sum() or m.sum() > 40000
        rest = valid & ~m
        lab, n = ndi.label(rest)
        if n and np.bincount(lab.ravel())[1:].max() > 10000:
            # a second person: it must be farther than the chosen one
            two_people += 1
            big = np.argmax(np.bincount(lab.ravel())[1:]) + 1
            assert np.median(depth[lab == big]) > np.median(depth[m]) + 0.2
    assert two_people == 2
