"""Pictures: depth colour maps, masks and labels over depth, skeletons (numpy only;
the 3-D views use matplotlib from the ``viz`` extra)."""

from __future__ import annotations

import os
from typing import Union

import numpy as np

from . import _core
from ._core import InvalidInputError

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["colorize_depth", "overlay_mask", "overlay_labels", "save_png", "montage", "PART_COLORS"]

#: Distinct colours for up to 16 labels (body parts), RGB uint8.
PART_COLORS = np.array(
    [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 212],
        [0, 128, 128],
        [220, 190, 255],
        [170, 110, 40],
        [255, 250, 200],
        [128, 0, 0],
        [170, 255, 195],
    ],
    dtype=np.uint8,
)


def colorize_depth(
    depth: np.ndarray, near: float | None = None, far: float | None = None
) -> np.ndarray:
    """(H, W, 3) uint8: near is bright, far is dark, no reading is black."""
    d = np.asarray(depth, dtype=np.float32)
    if d.ndim != 2:
        raise InvalidInputError(f"depth: expected a 2-D array, got shape {d.shape}")
    valid = np.isfinite(d) & (d > 0)
    if not valid.any():
        return np.zeros((*d.shape, 3), np.uint8)
    lo = float(np.percentile(d[valid], 1)) if near is None else near
    hi = float(np.percentile(d[valid], 99)) if far is None else far
    t = np.clip((hi - np.where(valid, d, hi)) / max(hi - lo, 1e-6), 0, 1)
    g = (40 + 215 * t).astype(np.uint8)
    rgb = np.stack([g, g, g], axis=-1)
    rgb[~valid] = 0
    return rgb


def overlay_mask(
    rgb: np.ndarray, mask: np.ndarray, color: tuple[int, int, int] = (60, 200, 90), alpha=0.5
) -> np.ndarray:
    """Tints the pixels of ``mask`` in ``color``."""
    out = rgb.astype(np.float32).copy()
    out[mask] = (1 - alpha) * out[mask] + alpha * np.asarray(color, np.float32)
    return out.astype(np.uint8)


def overlay_labels(rgb: np.ndarray, labels: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    """Colours each labelled pixel (label >= 0) by its part."""
    out = rgb.astype(np.float32).copy()
    lab = np.asarray(labels)
    on = lab >= 0
    colors = PART_COLORS[lab[on] % len(PART_COLORS)].astype(np.float32)
    out[on] = (1 - alpha) * out[on] + alpha * colors
    return out.astype(np.uint8)


def montage(images: list[np.ndarray], columns: int = 4, pad: int = 2) -> np.ndarray:
    """Tiles equally sized (H, W, 3) images into one picture."""
    if not images:
        raise InvalidInputError("images: need at least one image")
    h, w = images[0].shape[:2]
    rows = (len(images) + columns - 1) // columns
    out = np.zeros((rows * (h + pad) - pad, columns * (w + pad) - pad, 3), np.uint8)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        out[r * (h + pad) : r * (h + pad) + h, c * (w + pad) : c * (w + pad) + w] = im
    return out


def save_png(path: PathLike, rgb: np.ndarray) -> None:
    """Writes an (H, W, 3) uint8 image as PNG."""
    _core.write_rgb_png(os.fspath(path), np.ascontiguousarray(rgb, dtype=np.uint8))
