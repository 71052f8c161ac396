"""Model fitting: CRF body-part labelling + Levenberg-Marquardt in a hard EM loop.

`fit_pose` fits the body model to the foreground of a depth image from an initial pose
(`fit_poses` from several start poses at once, in parallel; `label_all_pixels` labels
every pixel of a strided fit that kept only its EM's labels);
`pose_from_joints` is inverse kinematics (the pose whose 15 joints best match given
joint positions, NaN rows skipped). Both default to `BodyModel()` (1.75 m reference
proportions). `fit_shape` calibrates the body shape (12 symmetric scale factors of
segment lengths and radii) on a few frames together with their poses; it is
`BodyModel.fit_shape` of the base model.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from depthpose._core import (
    BodyModel,
    Camera,
    FitConfig,
    FitResult,
    InvalidTypeError,
    ShapeFitResult,
    fit_pose,
    fit_poses,
    label_all_pixels,
    pose_from_joints,
)

__all__ = [
    "FitConfig",
    "FitResult",
    "ShapeFitResult",
    "fit_pose",
    "fit_poses",
    "fit_shape",
    "label_all_pixels",
    "pose_from_joints",
]


def fit_shape(
    depths: np.ndarray | Sequence[np.ndarray],
    camera: Camera,
    poses: np.ndarray | Sequence[np.ndarray],
    *,
    model: BodyModel | None = None,
    masks: np.ndarray | Sequence[np.ndarray] | None = None,
    iterations: int | None = None,
    config: None | FitConfig | Mapping[str, Any] = None,
    lm_iterations: int | None = None,
    prior_weight: float | None = None,
    bounds: tuple[float, float] | None = None,
) -> ShapeFitResult:
    """Calibrate the body shape of `model` (default `BodyModel()`) on a few frames.

    `BodyModel.fit_shape` of the base model, whose documentation holds the options and
    their defaults (an option left at None takes its default there).
    `depths`: (F, H, W) or a list of (H, W) depth images (float metres or uint16 mm);
    `poses`: (F, 22) initial poses (e.g. the tracker's or `fit_pose`'s on those frames);
    `masks`: optional (F, H, W) person masks. Alternates per-frame pose/label fits with a
    joint Levenberg-Marquardt over the 12 shape factors (`BodyModel.shape_factor_names`,
    each within `bounds`) and all poses, for at most `iterations` rounds; the energy never
    increases. Returns a `ShapeFitResult`: `model` (the calibrated `BodyModel`),
    `factors` (12,), `poses` (F, 22), `joints` (F, 15, 3), `labels`, `energy_trace`.
    """
    if model is not None and not isinstance(model, BodyModel):
        raise InvalidTypeError(f"model: expected a depthpose.BodyModel, got {type(model).__name__}")
    base = BodyModel() if model is None else model
    given = {
        "iterations": iterations,
        "lm_iterations": lm_iterations,
        "prior_weight": prior_weight,
        "bounds": bounds,
    }
    options: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
    return base.fit_shape(depths, camera, poses, masks=masks, config=config, **options)
