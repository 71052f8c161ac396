"""The whole pipeline on depth images: :class:`PoseEstimator` (a frame from scratch),
:class:`PoseTracker` (a video) and :func:`estimate_frames` (a sequence). Stereo pairs
go through :mod:`depthpose.stereo_pose`.

:class:`PoseEstimator` and :class:`PoseTracker` are native classes: each ``estimate``
and ``update`` is one call into the native core, which finds the person, searches the
templates, fits the body and returns a :class:`PoseResult`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _validate
from ._core import (
    JOINT_NAMES,
    BodyModel,
    Camera,
    DepthPoseError,
    InvalidInputError,
    InvalidTypeError,
    PipelineConfig,
    PoseEstimator,
    PoseResult,
    PoseTracker,
    TemplateDatabase,
    mirror_view,
    rest_pose_penalty,
    swap_limbs,
)

__all__ = [
    "JOINT_NAMES",
    "FramesResult",
    "PipelineConfig",
    "PoseEstimator",
    "PoseResult",
    "PoseTracker",
    "estimate_frames",
    "mirror_view",
    "rest_pose_penalty",
    "swap_limbs",
]


@dataclass
class FramesResult:
    """Per-frame results of a sequence; failed frames are NaN with their error."""

    joints: np.ndarray  # (T, 15, 3)
    pose: np.ndarray  # (T, 22)
    confidence: np.ndarray  # (T, 15)
    errors: list[dict[str, Any]]  # {"frame": index, "error": message}
    seconds: list[float] = field(default_factory=list)
    #: Tracked: the calibrated shape factors, else None.
    shape_factors: np.ndarray | None = None
    #: Tracked: why the shape calibration failed, else None.
    calibration_error: str | None = None
    #: Tracked: the frame whose update ran the calibration, else None.
    calibration_frame: int | None = None


def estimate_frames(
    frames: np.ndarray,
    camera: Camera,
    *,
    background: np.ndarray | None = None,
    track: bool = True,
    templates: TemplateDatabase | None = None,
    model: BodyModel | None = None,
    config: PipelineConfig | None = None,
    warmup: int = 0,
    first_frame: int = 0,
    on_frame: Callable[[int, PoseResult], None] | None = None,
    calibrate: bool | None = None,
) -> FramesResult:
    """Poses of frames (T, H, W), tracked (default) or each from scratch.

    The first ``warmup`` frames only prime the tracker and are not returned. A frame that
    raises a :class:`DepthPoseError` is recorded as NaN with its error, the tracker is
    reset and the loop goes on. ``on_frame(index, result)`` is called after each
    returned frame (``index`` counts from ``first_frame``).
    """
    if isinstance(frames, (list, tuple)):
        try:
            frames = np.asarray(frames)
        except (ValueError, TypeError):
            raise InvalidInputError("frames: not a stack of equally sized depth images") from None
    if not isinstance(frames, np.ndarray):
        raise InvalidTypeError(f"frames: expected a numpy array, got {type(frames).__name__}")
    if frames.ndim != 3:
        raise InvalidInputError(f"frames: expected (T, H, W), got shape {frames.shape}")
    if frames.dtype.kind not in "fu":
        raise (InvalidTypeError if frames.dtype.kind in "OUSV" else InvalidInputError)(
            f"frames: depth must be float metres or uint16 millimetres, got dtype {frames.dtype}"
        )
    if isinstance(warmup, int) and not isinstance(warmup, bool) and warmup > frames.shape[0]:
        raise InvalidInputError(f"warmup: {warmup} exceeds the {frames.shape[0]} frames")
    warmup = _validate.integer(warmup, "warmup", low=0, high=frames.shape[0])
    first_frame = _validate.integer(first_frame, "first_frame", low=0)
    if not isinstance(track, (bool, np.bool_)):
        raise InvalidTypeError(f"track: expected True or False, got {type(track).__name__}")
    if on_frame is not None and not callable(on_frame):
        raise InvalidTypeError(f"on_frame: expected a callable, got {type(on_frame).__name__}")
    n = frames.shape[0] - warmup
    out = FramesResult(np.full((n, 15, 3), np.nan), np.full((n, 22), np.nan), np.zeros((n, 15)), [])
    tracker: PoseTracker | None = None
    if track:
        tracker = PoseTracker(camera, model=model, templates=templates, config=config,
                              background=background, calibrate=calibrate)  # fmt: skip
        step: Callable[[np.ndarray], PoseResult] = tracker.update
    else:
        estimator = PoseEstimator(camera, model=model, templates=templates, config=config,
                                  background=background)  # fmt: skip
        step = estimator.estimate
    for k in range(frames.shape[0]):
        t0 = time.perf_counter()
        try:
            res = step(frames[k])
        except DepthPoseError as e:
            if tracker is not None:
                tracker.reset()
            if k >= warmup:
                out.errors.append({"frame": first_frame + k, "error": f"{type(e).__name__}: {e}"})
            continue
        if tracker is not None and out.calibration_frame is None:
            if tracker.calibration_frame is not None:
                out.calibration_frame = first_frame + k
        if k >= warmup:
            out.joints[k - warmup] = res.joints
            out.pose[k - warmup] = res.pose
            out.confidence[k - warmup] = res.confidence
            out.seconds.append(time.perf_counter() - t0)
            if on_frame is not None:
                on_frame(first_frame + k, res)
    if tracker is not None:
        out.shape_factors = tracker.shape_factors
        out.calibration_error = tracker.calibration_error
    return out
