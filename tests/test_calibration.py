"""Subject shape calibration in ``PoseTracker``: the tracker refines the body
shape over its first frames and keeps it, unless told the shape."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose import synth
from depthpose.pipeline import PipelineConfig, PoseTracker

#: The subject is this tall; the tracker's default model is 1.75 m.
SUBJECT_HEIGHT = 1.92
#: A short calibration keeps the test fast: 4 consecutive healthy frames.
FAST = dict(calibration_frames=4, calibration_every=1, recheck_every=0)
FRAMES = 12


@pytest.fixture(scope="module")
def templates():
    return dp.TemplateDatabase.default(progress=False)


@pytest.fixture(scope="module")
def tall():
    seq = synth.make_sequence(motion="walk", frames=FRAMES, height=SUBJECT_HEIGHT, seed=11,
                              fps=15)  # fmt: skip
    fx, fy, cx, cy = (float(v) for v in seq["intrinsics"])
    cam = dp.Camera(fx, fy, cx, cy, seq["depth"].shape[2], seq["depth"].shape[1])
    frames = seq["depth"].astype(np.float32) / 1000
    return seq, cam, seq["background"].astype(np.float32) / 1000, frames


def _track(tracker, frames, joints):
    err = []
    for d, gt in zip(frames, joints, strict=True):
        res = tracker.update(d)
        err.append(np.linalg.norm(res.joints - gt, axis=1).mean())
    return np.array(err)


@pytest.fixture(scope="module")
def told(tall, templates):
    """A tracker told the shape (the default model, 1.75 m: wrong for this subject)."""
    seq, cam, bg, frames = tall
    model = dp.BodyModel()
    tr = PoseTracker(cam, model=model, templates=templates, background=bg,
                     config=PipelineConfig(**FAST))  # fmt: skip
    return tr, model, _track(tr, frames, seq["joints"])


def test_tracker_told_the_shape_does_not_calibrate(told):
    tr, model, _ = told
    assert not tr.calibrated and not tr.calibrating
    assert tr.shape_factors is None and tr.calibration is None and tr.calibration_error is None
    assert np.array_equal(tr.model.shape, model.shape)


def test_tracker_calibrates_an_unknown_shape_and_keeps_it(tall, templates, told):
    seq, cam, bg, frames = tall
    tr = PoseTracker(cam, templates=templates, background=bg, config=PipelineConfig(**FAST))
    assert tr.calibrating
    err = _track(tr, frames, seq["joints"])
    assert tr.calibrated and tr.calibration_error is None
    # Frame 0 from the templates, frames 1..4 tracked: the 4th healthy one calibrates.
    k = tr.calibration_frame
    assert k is not None and 5 <= k <= FRAMES - 4, k
    truth = SUBJECT_HEIGHT / 1.75  # every factor of the taller subject's proportions
    names = tr.model.shape_factor_names
    f = dict(zip(names, tr.shape_factors, strict=True))
    lengths = ["torso_length", "upper_arm", "forearm", "thigh", "shin"]
    before = np.abs(1.0 - truth)
    after = np.mean([abs(f[n] - truth) for n in lengths])
    assert after < 0.75 * before, f
    assert not np.array_equal(tr.model.shape, tr.base_model.shape)
    # Joint error after the calibration, against the tracker told the (wrong) shape.
    _, _, err_told = told
    assert err[k:].mean() < 0.85 * err_told[k:].mean(), (err[k:], err_told[k:])
    # reset() forgets the track and keeps the shape; reset(shape=True) starts again.
    calibrated = tr.model.shape
    tr.reset()
    assert tr.calibrated and np.array_equal(tr.model.shape, calibrated)
    tr.reset(shape=True)
    assert not tr.calibrated and tr.calibrating
    assert np.array_equal(tr.model.shape, tr.base_model.shape)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("calibration_frames", -1),
        ("calibration_frames", 2.5),
        ("calibration_every", 0),
        ("calibration_rounds", 0),
        ("calibration_prior_weight", -1.0),
        ("calibration_prior_weight", float("nan")),
        ("prior_weight", float("inf")),
        ("velocity_damping", 2.0),
        ("track_stride", 0),
        ("track_stride", 9),
        ("candidate_stride", 0),
        ("candidate_stride", 1.5),
        ("recheck_hypotheses", 0),
        ("lost_hypotheses", 0),
        ("final_stride", 0),
        ("final_stride", 9),
        ("finals", 0),
        ("finals", 2.5),
        ("final_iterations", 0),
        ("final_iterations", 3.5),
        ("candidates", 0),
        ("candidates", 769),
    ],
)
def test_nonsense_calibration_settings_are_rejected(field, value):
    cam = dp.Camera.itop()
    with pytest.raises(dp.DepthPoseError, match=field):
        PoseTracker(cam, config=PipelineConfig(**{field: value}))


def test_bad_calibrate_argument():
    with pytest.raises(dp.DepthPoseError, match="calibrate"):
        PoseTracker(dp.Camera.itop(), calibrate="yes")  # type: ignore[arg-type]
    with pytest.raises(dp.DepthPoseError, match="config"):
        PoseTracker(dp.Camera.itop(), config={"calibration_frames": 4})  # type: ignore[arg-type]


def test_calibration_can_be_switched_off(tall, templates):
    seq, cam, bg, frames = tall
    off = PipelineConfig(**{**FAST, "calibration_frames": 0})
    for tr in (
        PoseTracker(cam, templates=templates, background=bg, config=off),
        PoseTracker(
            cam, templates=templates, background=bg, config=PipelineConfig(**FAST), calibrate=False
        ),  # fmt: skip
    ):
        assert not tr.calibrating
        _track(tr, frames[:6], seq["joints"][:6])
        assert not tr.calibrated and tr.shape_factors is None
