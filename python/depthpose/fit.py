"""Model fitting: CRF body-part labelling + Levenberg-Marquardt in a hard EM loop.

`fit_pose` fits the body model to the foreground of a depth image from an initial pose;
`pose_from_joints` is inverse kinematics (the pose whose 15 joints best match given
joint positions, NaN rows skipped). Both default to `BodyModel()` (1.75 m reference
proportions).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from depthpose._core import BodyModel, Camera, FitConfig, FitResult
from depthpose._core import fit_pose as _fit_pose
from depthpose._core import pose_from_joints as _pose_from_joints

__all__ = ["FitConfig", "FitResult", "fit_pose", "pose_from_joints"]


def _config(config: None | FitConfig | Mapping[str, Any]) -> FitConfig | None:
    if config is None or isinstance(config, FitConfig):
        return config
    if isinstance(config, Mapping):
        return FitConfig(**dict(config))
    raise TypeError(f"config must be a FitConfig, a dict or None, got {type(config).__name__}")


def fit_pose(
    depth: np.ndarray,
    camera: Camera,
    init_pose: np.ndarray,
    *,
    model: BodyModel | None = None,
    mask: np.ndarray | None = None,
    config: None | FitConfig | Mapping[str, Any] = None,
    prior: np.ndarray | None = None,
    prior_weight: float = 100.0,
) -> FitResult:
    """Fit the body to `depth` (H, W; float metres or uint16 mm) from `init_pose` (22,).

    `mask` (H, W) bool selects the person's pixels (default: every reading). `prior`
    (22,) adds `prior_weight/2 * |pose - prior|^2` to the M-step (tracking). Returns a
    `FitResult` with `pose`, `joints` (15, 3), `labels` (H, W) int16 (-1 = background or
    outlier), `energy`, `energy_trace`, `iterations`, `converged`, `reason`,
    `part_counts` and `outliers`.
    """
    return _fit_pose(
        depth,
        camera,
        np.asarray(init_pose),
        model=model,
        mask=mask,
        config=_config(config),
        prior=None if prior is None else np.asarray(prior),
        prior_weight=prior_weight,
    )


def pose_from_joints(
    joints: np.ndarray, model: BodyModel | None = None, init: np.ndarray | None = None
) -> np.ndarray:
    """The pose (22,) whose joints best match `joints` (15, 3) in the camera frame."""
    return _pose_from_joints(np.asarray(joints), model, None if init is None else np.asarray(init))
