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
    InvalidInputError,
    InvalidTypeError,
    ShapeFitResult,
)
from depthpose._core import fit_pose as _fit_pose
from depthpose._core import fit_poses as _fit_poses
from depthpose._core import label_all_pixels as _label_all_pixels
from depthpose._core import pose_from_joints as _pose_from_joints

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


def _config(config: None | FitConfig | Mapping[str, Any]) -> FitConfig | None:
    if config is None or isinstance(config, FitConfig):
        return config
    if isinstance(config, Mapping):
        bad = [k for k in config if not isinstance(k, str)]
        if bad:
            raise InvalidTypeError(f"config: keys must be setting names, got {bad[0]!r}")
        try:
            return FitConfig(**dict(config))
        except TypeError as e:
            if isinstance(e, InvalidTypeError):
                raise
            raise InvalidTypeError(f"config: {e}") from None
    raise InvalidTypeError(
        f"config: expected a FitConfig, a dict or None, got {type(config).__name__}"
    )


def _array(value: Any, name: str) -> Any:
    """Lists and tuples as numpy arrays (a ragged one is refused by name); arrays and
    anything else pass through for the native checks."""
    if isinstance(value, (list, tuple)):
        try:
            return np.asarray(value)
        except (ValueError, TypeError):
            raise InvalidInputError(f"{name}: not a rectangular array of numbers") from None
    return value


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
    resume: FitResult | None = None,
) -> FitResult:
    """Fit the body to `depth` (H, W; float metres or uint16 mm) from `init_pose` (22,).

    `mask` (H, W) bool selects the person's pixels (default: every reading). `prior`
    (22,) adds `prior_weight/2 * |pose - prior|^2` to the M-step (tracking). Returns a
    `FitResult` with `pose`, `joints` (15, 3), `labels` (H, W) int16 (-1 = background or
    outlier), `energy`, `energy_trace`, `iterations`, `converged`, `reason`,
    `part_counts` and `outliers`.

    A fresh fit also runs from `init_pose` moved so that its visible surface's centroid
    lies on the observed points' (when that moves it by 1 cm or more), in parallel, and
    returns the lower-energy result; this rescues starts that are a few centimetres off
    (`FitConfig(recentred_start=False)` turns it off); `swapped_limb_starts=True` also
    starts from the pose with its left and right legs (and arms) exchanged, at up to 3x
    the work. With a `stride`,
    `FitConfig(full_resolution_iterations=N)` continues the strided EM on every pixel
    for up to N iterations (coarse to fine).

    `resume`: an earlier `FitResult` on this image (e.g. a brief fit with a small
    `max_iterations`) whose EM should go on: it continues from `init_pose` (normally
    `resume.pose`) with `resume`'s labels and iteration count, so the outlier distance
    keeps annealing where it was and `max_iterations` counts the earlier iterations.
    Continuing a full-resolution fit that hit its iteration limit gives exactly the
    longer fit.
    """
    return _fit_pose(
        depth,
        camera,
        _array(init_pose, "init_pose"),
        model=model,
        mask=mask,
        config=_config(config),
        prior=None if prior is None else _array(prior, "prior"),
        prior_weight=prior_weight,
        resume=resume,
    )


def fit_poses(
    depth: np.ndarray,
    camera: Camera,
    init_poses: np.ndarray | Sequence[np.ndarray],
    *,
    model: BodyModel | None = None,
    mask: np.ndarray | None = None,
    config: None | FitConfig | Mapping[str, Any] = None,
    prior: np.ndarray | None = None,
    prior_weight: float = 100.0,
    resume: Sequence[FitResult] | None = None,
) -> list[FitResult]:
    """`fit_pose` from each of `init_poses` ((K, 22), K ≥ 1) on the same image.

    The foreground cloud and its graph are built once and the K fits run in parallel
    (one fit's work is mostly sequential), so on several cores this is much faster than
    K `fit_pose` calls; each result is identical to its own `fit_pose` call. `resume`:
    K earlier results, the k-th continued from `init_poses[k]` (see `fit_pose`).
    """
    return _fit_poses(
        depth,
        camera,
        _array(init_poses, "init_poses"),
        model=model,
        mask=mask,
        config=_config(config),
        prior=None if prior is None else _array(prior, "prior"),
        prior_weight=prior_weight,
        resume=resume,
    )


def label_all_pixels(
    depth: np.ndarray,
    camera: Camera,
    result: FitResult,
    *,
    model: BodyModel | None = None,
    mask: np.ndarray | None = None,
    config: None | FitConfig | Mapping[str, Any] = None,
    prior: np.ndarray | None = None,
    prior_weight: float = 100.0,
) -> FitResult:
    """`result` labelled at every pixel of `depth`.

    For a fit with a `stride` and `label_all_pixels=False` in its config (its labels
    are the EM's, at every `stride`-th pixel only), e.g. the best of several candidate
    fits: one E-step at its pose from those labels, exactly what the same fit with
    `label_all_pixels=True` returns. Pass the fit's own `depth`, `mask`, `model`,
    `config` and `prior`. A result already labelled at every pixel, or a config without
    a stride, comes back unchanged.
    """
    return _label_all_pixels(
        depth,
        camera,
        result,
        model=model,
        mask=mask,
        config=_config(config),
        prior=None if prior is None else _array(prior, "prior"),
        prior_weight=prior_weight,
    )


def pose_from_joints(
    joints: np.ndarray, model: BodyModel | None = None, init: np.ndarray | None = None
) -> np.ndarray:
    """The pose (22,) whose joints best match `joints` (15, 3) in the camera frame."""
    return _pose_from_joints(
        _array(joints, "joints"), model, None if init is None else _array(init, "init")
    )


def fit_shape(
    depths: np.ndarray | Sequence[np.ndarray],
    camera: Camera,
    poses: np.ndarray | Sequence[np.ndarray],
    *,
    model: BodyModel | None = None,
    masks: np.ndarray | Sequence[np.ndarray] | None = None,
    iterations: int = 3,
    config: None | FitConfig | Mapping[str, Any] = None,
    lm_iterations: int = 20,
    prior_weight: float = 1e5,
    bounds: tuple[float, float] = (0.7, 1.4),
) -> ShapeFitResult:
    """Calibrate the body shape of `model` (default `BodyModel()`) on a few frames.

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
    return base.fit_shape(
        depths,
        camera,
        poses,
        masks=masks,
        iterations=iterations,
        config=_config(config),
        lm_iterations=lm_iterations,
        prior_weight=prior_weight,
        bounds=bounds,
    )
