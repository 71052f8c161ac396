"""Pose from rectified stereo pairs: :class:`StereoPoseTracker` (a video of pairs),
:class:`StereoPoseEstimator` (each pair from scratch) and :func:`estimate_stereo` (one
pair).

Each ``update`` is one call into the native core: Growing Correspondence Seeds match
the pair, the band of background pixels the person's disparity spreads to along its
outline (foreground fattening) is removed, the disparity becomes depth, and the depth
goes through the estimator or the tracker. The segmentation tolerates the stereo
depth's noise, which grows as Z²/(f·B); in a video the previous pair's matches seed
the next. The pair of the empty scene is optional.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core, _validate
from ._core import BodyModel, Camera, InvalidInputError, InvalidTypeError, PipelineConfig
from ._core import PoseResult as PoseResult
from .pipeline import _check, _native_templates

__all__ = ["StereoPoseEstimator", "StereoPoseTracker", "estimate_stereo"]

_Pair = tuple[np.ndarray, np.ndarray]


def _pair(background: Any) -> _Pair | None:
    if background is None:
        return None
    if not isinstance(background, (tuple, list)) or len(background) != 2:
        raise InvalidTypeError(
            "background: expected the empty scene's pair (left, right), got "
            f"{_validate.type_name(background)}"
        )
    return (background[0], background[1])


class StereoPoseTracker:
    """Pose through a video of rectified stereo pairs.

    Parameters
    ----------
    camera
        The left camera (its size and intrinsics; ``fx`` is the focal length of the
        disparity). Left pixel ``x`` matches right pixel ``x - d``.
    baseline
        Distance between the camera centres, metres.
    doffs
        The x-offset of the right principal point from the left one, pixels
        (Middlebury's ``doffs``; 0 for a pair rectified to a common principal point).
    model, templates, config, calibrate
        As for :class:`~depthpose.PoseTracker`.
    background
        The pair ``(left, right)`` of the empty scene, for background subtraction
        (optional: without it the person is found automatically).
    background_depth
        Or the empty scene's depth (H, W) in metres.
    max_disparity
        The largest disparity searched (default: the whole line).
    fattening
        Remove the band of background pixels along the person's outline that take the
        person's disparity (default True).
    disparity_tolerance
        Disparity error (pixels) the segmentation tolerates on a floor, a wall or
        against the background (default 1).
    disparity_sigma
        The matched disparity's standard deviation in pixels (default 0.25, this
        matcher's on textured surfaces): depth noise σ_Z = Z²·disparity_sigma/(f·B)
        grows with depth, and the tracker's lost test allows for the discrepancy it
        adds to a good fit's. 0: no noise model.
    weigh_points
        Weigh each point in the fit by how precisely its depth is known,
        1/(σ² + σ_Z²) (default False: every point alike).

    Raises
    ------
    InvalidInputError
        A bad argument.
    """

    _track = True

    def __init__(
        self,
        camera: Camera,
        baseline: float,
        *,
        doffs: float = 0.0,
        model: BodyModel | None = None,
        templates: Any = None,
        config: PipelineConfig | None = None,
        background: _Pair | None = None,
        background_depth: np.ndarray | None = None,
        calibrate: bool | None = None,
        max_disparity: int | None = None,
        fattening: bool = True,
        disparity_tolerance: float = 1.0,
        disparity_sigma: float = 0.25,
        weigh_points: bool = False,
    ) -> None:
        _check(camera, model, config)
        self._native = _core._StereoPose(
            camera,
            _native_templates(templates),
            _validate.number(baseline, "baseline", low=0.0, low_open=True),
            doffs=doffs,
            model=model,
            config=config,
            background=_pair(background),
            background_depth=background_depth,
            track=self._track,
            calibrate=calibrate,
            max_disparity=max_disparity,
            fattening=fattening,
            disparity_tolerance=disparity_tolerance,
            disparity_sigma=disparity_sigma,
            weigh_points=weigh_points,
        )

    def update(
        self, left: np.ndarray, right: np.ndarray, mask: np.ndarray | None = None
    ) -> PoseResult:
        """The pose of the next pair.

        Parameters
        ----------
        left, right
            The rectified images, gray (H, W) or colour (H, W, 3), any numeric dtype.
        mask
            (H, W) bool: the person's pixels in the left image (default: found).

        Returns
        -------
        PoseResult
            Its ``timings`` begin with the stereo stage (``stereo``); the pair's
            disparity is :attr:`disparity`.

        Raises
        ------
        NoBodyError
            No person in the pair's depth.
        InvalidInputError
            A bad argument.
        """
        return self._native.update(left, right, mask)

    def reset(self, shape: bool = False) -> None:
        """Forgets the video (the track and the last disparity); the calibrated shape
        too when ``shape`` is true."""
        self._native.reset(shape)

    @property
    def disparity(self) -> np.ndarray | None:
        """The last pair's disparity (H, W) in pixels, NaN unmatched."""
        return self._native.disparity

    @property
    def camera(self) -> Camera:
        return self._native.camera

    @property
    def baseline(self) -> float:
        return self._native.baseline

    @property
    def model(self) -> BodyModel:
        """The model fitted with (the calibrated one once calibrated)."""
        return self._native.model

    @property
    def config(self) -> PipelineConfig:
        return self._native.config

    @property
    def shape_factors(self) -> np.ndarray | None:
        """The calibrated shape factors (12,), when tracking and calibrated."""
        return self._native.shape_factors

    @property
    def calibration_error(self) -> str | None:
        """Why the shape calibration failed, else None."""
        return self._native.calibration_error


class StereoPoseEstimator(StereoPoseTracker):
    """Pose of each rectified pair from scratch: the parameters of
    :class:`StereoPoseTracker` (``calibrate`` has no effect); :meth:`update` takes a
    pair and forgets it."""

    _track = False

    def estimate(
        self, left: np.ndarray, right: np.ndarray, mask: np.ndarray | None = None
    ) -> PoseResult:
        """The pose of one pair (as :meth:`StereoPoseTracker.update`)."""
        return self._native.update(left, right, mask)


def estimate_stereo(
    left: np.ndarray,
    right: np.ndarray,
    camera: Camera,
    baseline: float,
    *,
    doffs: float = 0.0,
    background: _Pair | None = None,
    background_depth: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    max_disparity: int | None = None,
    model: BodyModel | None = None,
    templates: Any = None,
    config: PipelineConfig | None = None,
) -> PoseResult:
    """The pose of one rectified pair (a :class:`StereoPoseEstimator` made for it; make
    one yourself to estimate many pairs).

    Parameters are those of :class:`StereoPoseEstimator` and ``mask``, the person's
    pixels in the left image (not with a background).

    Raises
    ------
    NoBodyError
        No person in the pair's depth.
    InvalidInputError
        A bad argument.
    """
    if mask is not None and (background is not None or background_depth is not None):
        raise InvalidInputError("mask: give either mask or a background, not both")
    est = StereoPoseEstimator(
        camera,
        baseline,
        doffs=doffs,
        model=model,
        templates=templates,
        config=config,
        background=background,
        background_depth=background_depth,
        max_disparity=max_disparity,
    )
    return est.estimate(left, right, mask)
