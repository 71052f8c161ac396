"""Memory layouts: every array argument is read in its logical order whatever its
layout (Fortran order, negative strides, strided views, other byte order, unaligned),
giving bit-identical results, or is refused with a clear error (depth images and masks
must be C-contiguous)."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose import graphcut
from hostile import fuzz, layouts, refused
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

CAM = dp.Camera(60.0, 60.0, 19.5, 14.5, 40, 30)
MODEL = dp.BodyModel()
POSE = dp.BodyModel.neutral_pose()
DEPTH, PARTS = MODEL.render_depth(POSE, CAM)


def same(a, b) -> bool:
    """Equal results, bit for bit (tuples and lists element-wise)."""
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    if isinstance(a, dp.FitResult):
        return same((a.pose, a.labels, a.energy), (b.pose, b.labels, b.energy))
    return a == b or (a != a and b != b)


def invariant(call, arg: np.ndarray) -> None:
    """``call(arg)`` gives the same result for every layout of ``arg``."""
    want = call(np.ascontiguousarray(arg))
    for name, other in layouts(np.ascontiguousarray(arg)).items():
        assert same(call(other), want), f"{name} layout read differently"


points = hnp.arrays(
    np.float64, st.tuples(st.integers(2, 6), st.just(3)), elements=st.floats(-2, 2) | st.just(3.0)
)


@fuzz()
@given(points)
def test_camera_projection_reads_every_layout(p):
    p = p + np.array([0.0, 0.0, 3.0])
    invariant(CAM.project, p)
    invariant(lambda uv: CAM.back_project(uv, p[:, 2].copy()), p[:, :2].copy())
    invariant(lambda z: CAM.back_project(np.ascontiguousarray(p[:, :2]), z), p[:, 2].copy())


@fuzz(15)
@given(points, st.integers(0, 2**31))
def test_body_model_reads_every_layout(p, seed):
    rng = np.random.default_rng(seed)
    p = (p * 0.3 + np.array([0.0, 0.0, 3.0])).astype(np.float32)
    invariant(lambda q: MODEL.distances(q, POSE), p)
    labels = rng.integers(-1, 16, len(p))
    invariant(lambda q: MODEL.residuals_and_jacobian(q, labels, POSE), p)
    invariant(lambda lab: MODEL.residuals_and_jacobian(p, lab, POSE), labels)
    pose = POSE + rng.normal(0, 0.1, 22)
    invariant(MODEL.joints, pose)
    invariant(lambda q: MODEL.distances(p, q), pose)
    poses = np.stack([POSE, pose, POSE + 0.01])
    invariant(lambda q: MODEL.depth_discrepancies(q, DEPTH, DEPTH > 0, CAM), poses)
    joints = MODEL.joints(pose)
    invariant(dp.pose_from_joints, joints)


def test_fit_poses_reads_init_poses_in_every_layout():
    inits = np.stack([POSE, POSE + 0.02])
    cfg = {"max_iterations": 1, "recentred_start": False}
    invariant(lambda q: [r.pose for r in dp.fit_poses(DEPTH, CAM, q, config=cfg)], inits)


images = hnp.arrays(np.uint8, st.tuples(st.integers(12, 20), st.integers(30, 40)))


@fuzz(10)
@given(images)
def test_stereo_reads_every_layout(left):
    right = np.roll(left, -2, axis=1)
    invariant(lambda a: dp.stereo.match(a, right, max_disparity=4, num_seeds=50), left)
    invariant(lambda a: dp.stereo.match(left, a, max_disparity=4, num_seeds=50), right)
    disp = np.linspace(0.5, 9.0, left.size, dtype=np.float32).reshape(left.shape)
    invariant(lambda d: dp.stereo.depth_from_disparity(d, 500.0, 0.1), disp)


@fuzz(20)
@given(
    hnp.arrays(
        np.float64, st.tuples(st.integers(2, 8), st.integers(2, 4)), elements=st.floats(0, 9)
    ),
    st.integers(0, 2**31),
)
def test_graph_cuts_read_every_layout(unary, seed):
    n = len(unary)
    rng = np.random.default_rng(seed)
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    weights = rng.uniform(0, 2, n - 1)
    invariant(lambda u: graphcut.alpha_expansion(u, edges, weights), unary)
    invariant(lambda e: graphcut.alpha_expansion(unary, e, weights), edges)
    invariant(lambda w: graphcut.alpha_beta_swap(unary, edges, w), weights)
    ints = np.round(unary * 10).astype(np.int64)
    invariant(lambda u: graphcut.alpha_expansion(u, edges, np.ones(n - 1, np.int64)), ints)

    def cut(cap):
        g = graphcut.Graph(n)
        g.add_edges(edges[:, 0], edges[:, 1], cap, cap)
        g.add_terminal_edges(np.arange(n), unary[:, 0].copy(), unary[:, 1].copy())
        return g.maxflow(threads=1), g.segments()

    invariant(cut, weights)


def test_rgb_png_reads_every_layout(tmp_path):
    rgb = np.random.default_rng(1).integers(0, 256, (7, 9, 3), np.uint8)

    def written(a):
        p = tmp_path / "x.png"
        dp.viz.save_png(p, a)
        return dp.read_image(p)

    invariant(written, rgb)
    invariant(written, rgb.astype(np.int32))


def test_template_database_reads_fortran_order_files(tmp_path):
    db = dp.TemplateDatabase.default(progress=False)
    db.save(tmp_path / "db.npz")
    with np.load(tmp_path / "db.npz") as f:
        arrays = {k: f[k] for k in f.files}
    for k, v in arrays.items():
        if v.ndim >= 2:
            arrays[k] = np.asfortranarray(v)
    np.savez(tmp_path / "f.npz", **arrays)
    back = dp.TemplateDatabase.load(tmp_path / "f.npz")
    assert np.array_equal(back.poses, db.poses) and np.array_equal(back.joints, db.joints)
    found = [c.index for c in back.match(DEPTH, CAM, DEPTH > 0)]
    assert found == [c.index for c in db.match(DEPTH, CAM, DEPTH > 0)]


@pytest.mark.parametrize(
    "call",
    [
        lambda d, m: dp.depth_to_points(d, CAM, m),
        lambda d, m: dp.surface_normals(d, CAM, m),
        lambda d, m: dp.pixel_graph(d, CAM, m),
        lambda d, m: dp.fit_pose(d, CAM, POSE, mask=m, config={"max_iterations": 1}),
        lambda d, m: MODEL.depth_discrepancies(POSE[None], d, m, CAM),
        lambda d, m: dp.surface_context(d, CAM, m),
    ],
)
def test_depth_and_masks_must_be_c_contiguous_and_are_refused_clearly(call):
    mask = DEPTH > 0
    assert call(DEPTH, mask) is not None
    for name, other in layouts(DEPTH).items():
        if other.flags.c_contiguous:
            assert same(call(other, mask), call(DEPTH, mask)), name
        else:
            refused(lambda o=other: call(o, mask), dp.InvalidInputError, "depth")
    for other in layouts(mask).values():
        if not other.flags.c_contiguous:
            refused(lambda o=other: call(DEPTH, o), dp.InvalidInputError, "mask")
    for other in (np.asfortranarray(DEPTH), DEPTH[::-1, ::-1]):
        e = refused(lambda o=other: call(o, mask), dp.InvalidInputError, "depth")
        assert "contiguous" in str(e)
