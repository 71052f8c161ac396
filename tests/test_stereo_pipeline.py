"""Stereo end to end: a synthetic rectified pair of the body model, textured on
its surface, through ``estimate_stereo``; every joint within 10 cm of the truth."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from conftest import shared
from depthpose import estimate_stereo
from depthpose.pipeline import JOINT_NAMES

#: Baseline (m) and the distances of the subject's hip centre and of the back wall.
BASELINE = 0.25
SUBJECT_Z = 2.8
WALL_Z = 4.2
#: Lattice spacing (m) of the solid texture: about 3 pixels at the subject.
TEXTURE_CELL = 0.03
#: Samples per pixel side when rendering the images.
SUPERSAMPLE = 3


def _hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, seed: int) -> np.ndarray:
    """A pseudo-random value in [0, 1) per integer lattice point (64-bit mixing)."""
    with np.errstate(over="ignore"):
        h = (
            ix.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
            ^ iy.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
            ^ iz.astype(np.uint64) * np.uint64(0x165667B19E3779F9)
            ^ np.uint64(seed)
        )
        h ^= h >> np.uint64(31)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _solid_texture(points: np.ndarray, cell: float, seed: int) -> np.ndarray:
    """Value noise on a 3-D lattice, trilinearly interpolated: a texture attached to
    the surface (the same 3-D point has the same brightness in both views)."""
    q = points / cell
    i0 = np.floor(q).astype(np.int64)
    f = q - i0
    f = f * f * (3 - 2 * f)  # smooth
    out = np.zeros(len(points))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = (
                    (f[:, 0] if dx else 1 - f[:, 0])
                    * (f[:, 1] if dy else 1 - f[:, 1])
                    * (f[:, 2] if dz else 1 - f[:, 2])
                )
                out += w * _hash01(i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz, seed)
    return out


def _view(model, pose, camera, offset_x: float, seed: int):
    """The gray image and depth of the scene (body in front of a fronto-parallel wall)
    seen by a camera displaced by ``offset_x`` metres along x from the left one. Points
    are textured in the left camera's frame, so both views agree; each pixel averages
    SUPERSAMPLE² samples (a sensor integrates over the pixel: point samples of a fine
    texture would alias differently in the two views)."""
    k = SUPERSAMPLE
    fx, fy, cx, cy = camera.intrinsics
    fine = dp.Camera(fx * k, fy * k, (cx + 0.5) * k - 0.5, (cy + 0.5) * k - 0.5,
                     camera.width * k, camera.height * k)  # fmt: skip
    shifted = pose.copy()
    shifted[0] -= offset_x
    body, _ = model.render_depth(shifted, fine)
    body = np.asarray(body, np.float64)
    z = np.where((body > 0) & (body < WALL_Z), body, WALL_Z)
    fx, fy, cx, cy = fine.intrinsics
    v, u = np.mgrid[0 : fine.height, 0 : fine.width].astype(np.float64)
    pts = np.stack([(u - cx) / fx * z + offset_x, (v - cy) / fy * z, z], -1).reshape(-1, 3)
    tex = 0.65 * _solid_texture(pts, TEXTURE_CELL, seed)
    tex += 0.35 * _solid_texture(pts, TEXTURE_CELL / 2, seed + 1)
    img = (40 + 180 * tex).reshape(camera.height, k, camera.width, k).mean((1, 3))
    # The depth at the pixel centres (for checking the disparity).
    depth = z.reshape(camera.height, k, camera.width, k)[:, k // 2, :, k // 2]
    return img, depth


def make_pair(seed: int = 7):
    """Left/right images, the background depth (the wall, as the matcher sees the empty
    scene), the true joints and the camera."""
    # A VGA camera with the field of view of the ITOP sensor: stereo rigs for pose are
    # VGA or larger, and the matcher's window (5 px) is what fattening is measured in.
    itop = dp.Camera.itop()
    camera = dp.Camera(2 * itop.fx, 2 * itop.fy, 2 * itop.cx + 0.5, 2 * itop.cy + 0.5, 640, 480)
    model = dp.BodyModel()
    pose = np.zeros(22)
    pose[:3] = [0.05, 0.05, SUBJECT_Z]
    pose[3:6] = [0.0, 0.35, 0.0]  # turned a little
    names = model.param_names
    # Arms away from the body, one elbow bent, one knee bent: every joint is visible.
    for name, value in [
        ("r_shoulder_abduction", 0.6),
        ("l_shoulder_abduction", 0.8),
        ("l_elbow_flexion", 0.9),
        ("r_hip_flexion", 0.35),
        ("r_knee_flexion", 0.5),
    ]:
        pose[names.index(name)] = value
    pose = model.clamp_pose(pose)
    rng = np.random.default_rng(seed)
    left, depth_left = _view(model, pose, camera, 0.0, seed=seed)
    right, _ = _view(model, pose, camera, BASELINE, seed=seed)
    left = np.clip(left + rng.normal(0, 1.0, left.shape), 0, 255).astype(np.uint8)
    right = np.clip(right + rng.normal(0, 1.0, right.shape), 0, 255).astype(np.uint8)
    background = np.full(camera.shape, WALL_Z, np.float32)
    return left, right, background, np.asarray(model.joints(pose)), camera, depth_left


@pytest.fixture(scope="module")
def pair():
    return make_pair()


def test_stereo_pair_of_the_body_gives_every_joint_within_10cm(pair):
    left, right, background, truth, camera, _ = pair
    templates = dp.TemplateDatabase.default(progress=False)
    res = estimate_stereo(
        left, right, camera, BASELINE, templates=templates, background_depth=background
    )
    err = np.linalg.norm(res.joints - truth, axis=1)
    assert (err < 0.10).all(), dict(zip(JOINT_NAMES, np.round(err, 3), strict=True))
    assert res.timings["stereo"] > 0 and res.timings["total"] >= res.timings["stereo"]


def test_estimate_stereo_rejects_bad_arguments(pair):
    left, right, background, _, camera, _ = pair
    with pytest.raises(dp.DepthPoseError, match="baseline"):
        estimate_stereo(left, right, camera, 0.0)
    with pytest.raises(dp.DepthPoseError, match="baseline"):
        estimate_stereo(left, right, camera, float("nan"))
    with pytest.raises(dp.DepthPoseError, match="camera"):
        estimate_stereo(left, right, "camera", BASELINE)  # type: ignore[arg-type]
    with pytest.raises(dp.DepthPoseError, match="mask"):
        estimate_stereo(left, right, camera, BASELINE, background_depth=background,
                        mask=np.ones(camera.shape, bool))  # fmt: skip
    with pytest.raises(dp.DepthPoseError, match="mask"):
        estimate_stereo(left, right, camera, BASELINE, mask=np.ones((10, 10), bool))
    with pytest.raises(dp.DepthPoseError, match="left"):
        estimate_stereo(left[:, :200], right[:, :200], camera, BASELINE)


def test_without_a_background_the_person_is_found_and_fitted(pair):
    left, right, _, truth, camera, _ = pair
    res = estimate_stereo(left, right, camera, BASELINE)
    assert res.segmentation_method == "planes"
    err = np.linalg.norm(res.joints - truth, axis=1)
    assert (err < 0.10).all(), dict(zip(JOINT_NAMES, np.round(err, 3), strict=True))


def test_fattening_removal_keeps_the_person_and_drops_no_interior_match(pair):
    left, right, _, _, camera, depth = pair
    kept = dp.StereoPoseEstimator(camera, BASELINE)
    kept.estimate(left, right)
    raw = dp.StereoPoseEstimator(camera, BASELINE, fattening=False)
    raw.estimate(left, right)
    assert kept.disparity is not None and raw.disparity is not None
    removed = np.isfinite(raw.disparity) & ~np.isfinite(kept.disparity)
    # Only matches next to a large unmatched region go, and never more than the
    # window's half side (2 px) from it.
    from scipy import ndimage

    gaps = ~np.isfinite(raw.disparity)
    labels, n = ndimage.label(gaps)
    sizes = ndimage.sum(gaps, labels, range(1, n + 1))
    large = np.isin(labels, 1 + np.flatnonzero(sizes >= 64))
    near = ndimage.binary_dilation(large, np.ones((5, 5), bool))
    assert removed.any() and not (removed & ~near).any()
    kept_same = np.isfinite(kept.disparity)
    assert np.array_equal(kept.disparity[kept_same], raw.disparity[kept_same])


def test_weighing_points_by_depth_noise_fits_the_pair_too(pair):
    """With ``weigh_points`` the fit weighs points by their depth noise: a
    different fit of the same disparity, the joints but at most one within 10 cm (a
    hand drifts: weighing the far points down is not better here, which is why it is
    off by default)."""
    left, right, _, truth, camera, _ = pair
    alike = dp.StereoPoseEstimator(camera, BASELINE).estimate(left, right)
    weighed = dp.StereoPoseEstimator(camera, BASELINE, weigh_points=True)
    res = weighed.estimate(left, right)
    assert not np.array_equal(res.pose, alike.pose)
    err = np.linalg.norm(res.joints - truth, axis=1)
    assert (err < 0.10).sum() >= 14, dict(zip(JOINT_NAMES, np.round(err, 3), strict=True))


def test_tracker_follows_pairs_and_keeps_the_disparity(pair):
    left, right, _, truth, camera, _ = pair
    tracker = dp.StereoPoseTracker(camera, BASELINE, calibrate=False)
    first = tracker.update(left, right)
    second = tracker.update(left, right)
    assert first.source == "templates" and second.source == "tracking"
    assert tracker.disparity is not None and tracker.disparity.shape == camera.shape
    err = np.linalg.norm(second.joints - truth, axis=1)
    assert (err < 0.10).all(), dict(zip(JOINT_NAMES, np.round(err, 3), strict=True))
    assert second.timings["stereo"] > 0
    tracker.reset()
    assert tracker.update(left, right).source == "templates"


def test_stereo_pose_rejects_bad_arguments(pair):
    left, right, background, _, camera, _ = pair
    with pytest.raises(dp.DepthPoseError, match="right"):
        dp.StereoPoseTracker(camera, BASELINE).update(left, right[:, :300])
    with pytest.raises(dp.DepthPoseError, match="background"):
        dp.StereoPoseTracker(camera, BASELINE, background=left)  # type: ignore[arg-type]
    with pytest.raises(dp.DepthPoseError, match="background"):
        dp.StereoPoseTracker(camera, BASELINE, background=(left, right),
                             background_depth=background)  # fmt: skip
    with pytest.raises(dp.DepthPoseError, match="disparity_tolerance"):
        dp.StereoPoseTracker(camera, BASELINE, disparity_tolerance=-1.0)
    for bad in (-0.5, float("nan")):
        with pytest.raises(dp.InvalidInputError, match="disparity_sigma"):
            dp.StereoPoseTracker(camera, BASELINE, disparity_sigma=bad)
    with pytest.raises(dp.DepthPoseError, match="weigh_points"):
        dp.StereoPoseTracker(camera, BASELINE, weigh_points="yes")  # type: ignore[arg-type]
    with pytest.raises(dp.DepthPoseError, match="doffs"):
        dp.StereoPoseTracker(camera, BASELINE, doffs=float("inf"))


def test_tracked_stereo_person_without_background():
    """The shared rendered pairs of a walking person: tracked without the empty scene,
    the joints within 10 cm in at least 90 % of cases, and the person's disparity
    dense and right within 2 px."""
    data = np.load(shared("stereo_person", "dm_walk_front.npz"))
    fx, fy, cx, cy = data["intrinsics"]
    camera = dp.Camera(fx, fy, cx, cy, 640, 480)
    tracker = dp.StereoPoseTracker(camera, float(data["baseline"]))
    hits, bad, density = [], [], []
    for k in range(len(data["left"])):
        res = tracker.update(data["left"][k], data["right"][k])
        hits.append(np.linalg.norm(res.joints - data["joints"][k], axis=1) < 0.10)
        assert tracker.disparity is not None
        mask = data["mask"][k]
        got, want = tracker.disparity[mask], data["disparity"][k][mask]
        density.append(np.isfinite(got).mean())
        bad.append(np.mean(np.abs(got - want)[np.isfinite(got)] > 2))
    assert np.mean(hits) >= 0.9
    assert max(bad) <= 0.02 and min(density) >= 0.85
