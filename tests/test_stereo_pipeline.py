"""Stereo end to end (issue #8): a synthetic rectified pair of the body model, textured on
its surface, through ``estimate_stereo``; every joint within 10 cm of the truth."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose.pipeline import JOINT_NAMES, estimate_stereo

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
    camera = dp.Camera.itop()
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
    est = dp.PoseEstimator(camera, templates=templates)
    res = estimate_stereo(left, right, camera, BASELINE, estimator=est, background=background)
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
        estimate_stereo(left, right, camera, BASELINE, background=background,
                        mask=np.ones(camera.shape, bool))  # fmt: skip
    with pytest.raises(dp.DepthPoseError, match="mask"):
        estimate_stereo(left, right, camera, BASELINE, mask=np.ones((10, 10), bool))
    with pytest.raises(dp.DepthPoseError, match="left"):
        estimate_stereo(left[:, :200], right[:, :200], camera, BASELINE)
