"""Joint accuracy with the definitions of the shared ``eval_pose.py``: MPJPE over finite
predictions, PCK@10cm with a NaN prediction counted as wrong."""

from __future__ import annotations

import numpy as np

from ._core import InvalidInputError

__all__ = ["evaluate"]


def evaluate(pred: np.ndarray, gt: np.ndarray, threshold: float = 0.10) -> dict[str, float]:
    """``mpjpe_mm``, ``pck`` and ``n_missing`` of predictions (T, J, 3) against (T, J, 3)."""
    pred = np.asarray(pred, np.float64)
    gt = np.asarray(gt, np.float64)
    if pred.shape != gt.shape:
        raise InvalidInputError(f"pred: shape {pred.shape} does not match gt's {gt.shape}")
    valid = np.isfinite(pred).all(-1)
    err = np.linalg.norm(np.where(valid[..., None], pred, 0.0) - gt, axis=-1)
    hit = valid & (err <= threshold + 1e-9)
    return {
        "mpjpe_mm": float(1000 * err[valid].mean()) if valid.any() else float("nan"),
        "pck": float(hit.mean()),
        "n_missing": int((~valid).sum()),
    }
