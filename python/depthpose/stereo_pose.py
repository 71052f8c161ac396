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

import numpy as np

from ._core import (
    BodyModel,
    Camera,
    InvalidInputError,
    PipelineConfig,
    PoseResult,
    StereoPoseEstimator,
    StereoPoseTracker,
    TemplateDatabase,
)

__all__ = ["StereoPoseEstimator", "StereoPoseTracker", "estimate_stereo"]


def estimate_stereo(
    left: np.ndarray,
    right: np.ndarray,
    camera: Camera,
    baseline: float,
    *,
    doffs: float = 0.0,
    background: tuple[np.ndarray, np.ndarray] | None = None,
    background_depth: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    max_disparity: int | None = None,
    model: BodyModel | None = None,
    templates: TemplateDatabase | None = None,
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
