"""Body shape calibration: BodyModel.fit_shape / fit.fit_shape on rendered depth, bad input."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose._core import BodyModel
from depthpose.fit import ShapeFitResult, fit_shape

CAM = dp.Camera(285.71, 285.71, 159.5, 119.5, 320, 240)


def poses(model: BodyModel) -> np.ndarray:
    a = np.array(model.neutral_pose(), dtype=float)
    a[2], a[4] = 2.8, 0.3
    a[8:12] = [0.4, 0.5, 0.0, 0.9]
    a[12:16] = [0.0, 0.9, 0.0, 0.4]
    a[16], a[18] = 0.3, 0.4
    b = np.array(model.neutral_pose(), dtype=float)
    b[2], b[4] = 3.0, -0.4
    b[8:12] = [0.0, 1.2, 0.0, 0.3]
    b[12:16] = [0.8, 0.12, 0.0, 1.2]
    b[19], b[20], b[21] = 0.5, 0.2, 0.8
    return np.stack([a, b])


def truth_factors(model: BodyModel) -> dict[str, float]:
    f = dict.fromkeys(model.shape_factor_names, 1.0)
    f.update(torso_width=1.1, upper_arm=0.85, forearm=0.85)
    return f


def test_shape_factors_scale_the_model():
    base = BodyModel()
    names = base.shape_factor_names
    assert len(names) == 12 and len(set(names)) == 12
    same = base.with_shape_factors(np.ones(12))
    np.testing.assert_array_equal(same.shape, base.shape)
    f = truth_factors(base)
    m = base.with_shape_factors(np.array([f[n] for n in names]))
    s0, s1 = dict(base.shape_dict()), dict(m.shape_dict())
    assert s1["upper_arm_length"] == pytest.approx(0.85 * s0["upper_arm_length"])
    assert s1["forearm_length"] == pytest.approx(0.85 * s0["forearm_length"])
    assert s1["chest_radius_x"] == pytest.approx(1.1 * s0["chest_radius_x"])
    assert s1["thigh_length"] == s0["thigh_length"]
    with pytest.raises(dp.DepthPoseError, match="factors"):
        base.with_shape_factors(np.ones(11))
    with pytest.raises(dp.DepthPoseError, match="factors"):
        base.with_shape_factors(np.full(12, np.nan))


def test_fit_shape_recovers_arms_and_torso_and_lowers_joint_error():
    """Depth of a body with 15 % shorter arms and a 10 % wider torso, two views, fitted
    from the default model and perturbed poses: those factors come back within a few
    percent, the energy never increases, and refitting the poses with the calibrated
    model lowers the joint error."""
    base = BodyModel()
    names = base.shape_factor_names
    f_true = truth_factors(base)
    truth = base.with_shape_factors(np.array([f_true[n] for n in names]))
    true_poses = poses(base)
    depths = np.stack([truth.render_depth(p, CAM)[0] for p in true_poses])
    rng = np.random.default_rng(3)
    init = true_poses.copy()
    init[:, :3] += rng.uniform(-0.03, 0.03, (2, 3))
    init[:, 3:] += rng.uniform(-0.05, 0.05, (2, 19))
    init = np.stack([base.clamp_pose(p) for p in init])
    # The data are the model's own ellipsoids: a weak prior (the default, 1e5, is for
    # real bodies, whose surfaces the ellipsoids only approximate).
    r = base.fit_shape(depths, CAM, init, masks=depths > 0, prior_weight=1e3)
    assert isinstance(r, ShapeFitResult)
    got = r.factors_dict()
    for n in ("torso_width", "upper_arm", "forearm"):
        assert got[n] == pytest.approx(f_true[n], abs=0.04), (n, got)
    assert np.all((r.factors >= 0.7) & (r.factors <= 1.4))
    trace = r.energy_trace
    assert np.all(np.diff(trace) <= 0) and trace[-1] == pytest.approx(r.energy)
    assert r.poses.shape == (2, 22) and r.joints.shape == (2, 15, 3)
    assert r.labels.shape == (2, 240, 320) and r.labels.dtype == np.int16
    np.testing.assert_allclose(r.model.shape, truth.shape, rtol=0.3)
    # Joint error after refitting each frame's pose: default vs calibrated shape.
    err_base, err_fit = [], []
    for d, p0, pt in zip(depths, init, true_poses, strict=True):
        gt = truth.joints(pt)
        a = dp.fit_pose(d, CAM, p0, model=base)
        b = dp.fit_pose(d, CAM, p0, model=r.model)
        err_base.append(np.linalg.norm(a.joints - gt, axis=1).mean())
        err_fit.append(np.linalg.norm(b.joints - gt, axis=1).mean())
    assert np.mean(err_fit) < 0.6 * np.mean(err_base), (err_base, err_fit)
    # The module-level wrapper is the same computation (deterministic).
    r2 = fit_shape(
        list(depths), CAM, list(init), model=base, masks=list(depths > 0), prior_weight=1e3
    )
    np.testing.assert_array_equal(r2.factors, r.factors)


def test_fit_shape_rejects_bad_input():
    base = BodyModel()
    p = poses(base)
    depth = base.render_depth(p[0], CAM)[0]
    depths = np.stack([depth, depth])
    with pytest.raises(dp.DepthPoseError, match="depths"):
        base.fit_shape([], CAM, p)
    with pytest.raises(dp.DepthPoseError, match="depths"):
        base.fit_shape(depth, CAM, p)  # a single (H, W) image is not a list of frames
    with pytest.raises(dp.DepthPoseError, match="poses"):
        base.fit_shape(depths, CAM, p[:1])
    bad = p.copy()
    bad[1, 9] = np.nan
    with pytest.raises(dp.DepthPoseError, match="poses"):
        base.fit_shape(depths, CAM, bad)
    with pytest.raises(dp.DepthPoseError, match="poses"):
        base.fit_shape(depths, CAM, p[:, :20])
    with pytest.raises(dp.DepthPoseError, match="depths"):
        base.fit_shape(depths[:, :100], CAM, p)
    with pytest.raises(dp.DepthPoseError, match="masks"):
        base.fit_shape(depths, CAM, p, masks=np.ones((1, 240, 320), bool))
    with pytest.raises(dp.DepthPoseError, match="masks"):
        base.fit_shape(depths, CAM, p, masks=np.ones((2, 240, 100), bool))
    with pytest.raises(dp.DepthPoseError, match="bounds"):
        base.fit_shape(depths, CAM, p, bounds=(1.2, 1.4))
    with pytest.raises(dp.DepthPoseError, match="iterations"):
        base.fit_shape(depths, CAM, p, iterations=0)
    with pytest.raises(dp.DepthPoseError, match="prior_weight"):
        base.fit_shape(depths, CAM, p, prior_weight=-1.0)
    with pytest.raises(dp.NoBodyError):
        base.fit_shape(np.zeros((2, 240, 320), np.float32), CAM, p)
    with pytest.raises(dp.DepthPoseError, match="depths"):
        base.fit_shape("not a depth", CAM, p)
