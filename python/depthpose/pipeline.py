"""The whole pipeline on depth images: :class:`PoseEstimator` (a frame from scratch),
:class:`PoseTracker` (a video) and :func:`estimate_frames` (a sequence). Stereo pairs
go through :mod:`depthpose.stereo_pose`.

Each ``estimate`` and ``update`` is one call into the native core, which finds the
person, searches the templates, fits the body and returns a :class:`PoseResult`; the
classes here only choose the template database and document the API.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core, _validate
from ._core import (
    JOINT_NAMES,
    BodyModel,
    Camera,
    DepthPoseError,
    InvalidInputError,
    InvalidTypeError,
    PipelineConfig,
    PoseResult,
    ShapeFitResult,
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


def _native_templates(templates: Any) -> Any:
    """The native database of a :class:`~depthpose.templates.TemplateDatabase` (the
    cached default one when None)."""
    from .templates import TemplateDatabase

    if templates is None:
        templates = TemplateDatabase.default()
    if not isinstance(templates, TemplateDatabase):
        raise InvalidTypeError(
            f"templates: expected a TemplateDatabase, got {type(templates).__name__}"
        )
    return templates._db


def _check(camera: Any, model: Any, config: Any) -> None:
    if not isinstance(camera, Camera):
        raise InvalidTypeError(f"camera: expected a depthpose.Camera, got {type(camera).__name__}")
    if model is not None and not isinstance(model, BodyModel):
        raise InvalidTypeError(f"model: expected a BodyModel, got {type(model).__name__}")
    if config is not None and not isinstance(config, PipelineConfig):
        raise InvalidTypeError(f"config: expected a PipelineConfig, got {type(config).__name__}")


class PoseEstimator:
    """Pose from scratch, one frame at a time.

    Parameters
    ----------
    camera
        The depth camera (the frames' size and intrinsics). Frames from sensors of high
        resolution are processed at a reduced working resolution; results come back in
        the input's pixel grid.
    model
        The subject's body, when its shape is known. Without it the body is
        ``BodyModel()`` (1.75 m reference proportions) scaled, frame by frame, to the
        size that explains the depth best (``config.size_range``).
    templates
        A :class:`~depthpose.templates.TemplateDatabase` (default: the cached default
        database, built on first use).
    config
        A :class:`PipelineConfig`.
    background
        A frame of the empty scene (H, W) for background subtraction; without it the
        person is found automatically (:func:`~depthpose.segment_person`).
    """

    def __init__(
        self,
        camera: Camera,
        *,
        model: BodyModel | None = None,
        templates: Any = None,
        config: PipelineConfig | None = None,
        background: np.ndarray | None = None,
    ) -> None:
        _check(camera, model, config)
        self._native = _core._PoseEstimator(
            camera, _native_templates(templates), model=model, config=config, background=background
        )

    @property
    def camera(self) -> Camera:
        return self._native.camera

    @property
    def working_camera(self) -> Camera:
        """The camera the pipeline works with (the input's, reduced for large images)."""
        return self._native.working_camera

    @property
    def model(self) -> BodyModel:
        return self._native.model

    @property
    def config(self) -> PipelineConfig:
        return self._native.config

    def estimate(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """The pose of one frame: the person's pixels (``mask``, else found), the
        template search with its swapped and mirrored hypotheses, EM from the most
        promising, and the pose whose body explains the depth best.

        Parameters
        ----------
        depth
            (H, W) float metres or uint16 millimetres; 0 or NaN = no reading.
        mask
            (H, W) bool: the person's pixels (default: found automatically).

        Raises
        ------
        NoBodyError
            No person in the frame.
        InvalidInputError
            A bad argument.
        """
        return self._native.estimate(depth, mask)

    def person_mask(self, depth: np.ndarray) -> np.ndarray:
        """The person's pixels (H, W) as :meth:`estimate` finds them."""
        return self._native.person_mask(depth)

    def discrepancies(
        self, poses: np.ndarray, depth: np.ndarray, mask: np.ndarray | None = None
    ) -> np.ndarray:
        """How badly each of ``poses`` (N, 22) explains ``depth``: the rendered body
        against the person's pixels, the depth difference capped at 0.1 m (0 =
        perfectly, about 1 = unrelated). (N,)."""
        return self._native.discrepancies(np.asarray(poses).reshape(-1, 22), depth, mask)

    def discrepancy(
        self, pose: np.ndarray, depth: np.ndarray, mask: np.ndarray | None = None
    ) -> float:
        """:meth:`discrepancies` of one pose."""
        return float(self.discrepancies(np.asarray(pose).reshape(1, 22), depth, mask)[0])

    def penalty(self, poses: np.ndarray) -> np.ndarray:
        """The rest-pose penalty of each of ``poses`` (:func:`rest_pose_penalty` with
        ``config.pose_prior_weight``): what a pose's discrepancy is charged when poses
        compete."""
        return self._native.penalty(np.asarray(poses).reshape(-1, 22))


class PoseTracker:
    """Pose through a depth video: each :meth:`update` starts from the previous pose.

    Parameters are those of :class:`PoseEstimator`, and
    ``calibrate``: fit the subject's body shape over the first usable frames (None:
    when no ``model`` is given; a given model is taken as the subject's known shape).
    Without a ``model`` the body's size is found on the first frame and the shape is
    calibrated from there.

    A tracked frame starts from the previous pose moved on by a damped velocity, with a
    prior toward that prediction. When the fit explains too little of the person or the
    depth much worse than lately, the track is lost and the template search runs (the
    tracked pose among its starts). With ``config.recheck_every`` > 0 the search also
    runs every that many frames and the track switches when it finds a clearly better
    pose.

    With ``config.learn_background`` and no ``background``, the tracker learns the
    scene's static background over the frames, outside the person's mask, and segments
    the person in front of it once enough is known (``result.segmentation_method ==
    "learned"``; the learning's time is ``timings["background"]``). What it learned is
    kept across :meth:`reset` (the same camera and scene).
    """

    def __init__(
        self,
        camera: Camera,
        *,
        model: BodyModel | None = None,
        templates: Any = None,
        config: PipelineConfig | None = None,
        background: np.ndarray | None = None,
        calibrate: bool | None = None,
    ) -> None:
        _check(camera, model, config)
        if calibrate is not None and not isinstance(calibrate, (bool, np.bool_)):
            raise InvalidTypeError(
                f"calibrate: expected True, False or None, got {type(calibrate).__name__}"
            )
        self._native = _core._PoseTracker(
            camera,
            _native_templates(templates),
            model=model,
            config=config,
            background=background,
            calibrate=None if calibrate is None else bool(calibrate),
        )

    def update(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """The pose of the next frame (arguments as :meth:`PoseEstimator.estimate`).
        While calibrating, a usable frame may be kept for the shape calibration, and
        the frame that completes it runs it (``timings["calibration"]``)."""
        return self._native.update(depth, mask)

    def reset(self, shape: bool = False) -> None:
        """Forgets the track. The calibrated shape is kept (the same subject) unless
        ``shape`` is true: then the starting model is restored and calibrated again."""
        self._native.reset(shape)

    def start_from(self, pose: np.ndarray) -> None:
        """Starts the track from a known pose (22,): the next :meth:`update` refines it
        instead of searching the templates."""
        self._native.start_from(pose)

    @property
    def camera(self) -> Camera:
        return self._native.camera

    @property
    def model(self) -> BodyModel:
        """The model tracked with (the calibrated one once calibrated)."""
        return self._native.model

    @property
    def base_model(self) -> BodyModel:
        """The model the tracker started with."""
        return self._native.base_model

    @property
    def config(self) -> PipelineConfig:
        return self._native.config

    @property
    def lost_frames(self) -> int:
        return self._native.lost_frames

    @property
    def switches(self) -> int:
        return self._native.switches

    @property
    def calibrating(self) -> bool:
        """Whether the tracker is still collecting frames to calibrate the shape."""
        return self._native.calibrating

    @property
    def calibrated(self) -> bool:
        return self._native.calibrated

    @property
    def shape_factors(self) -> np.ndarray | None:
        """The calibrated shape factors (12,) relative to :attr:`base_model`."""
        return self._native.shape_factors

    @property
    def calibration(self) -> ShapeFitResult | None:
        """The shape fit of the calibration (None before or when it failed)."""
        return self._native.calibration

    @property
    def calibration_error(self) -> str | None:
        """Why the calibration failed, else None."""
        return self._native.calibration_error

    @property
    def calibration_frame(self) -> int | None:
        """Frames :meth:`update` had been given when the calibration ran."""
        return self._native.calibration_frame


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
    templates: Any = None,
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
