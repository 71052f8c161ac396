"""Synthetic depth sequences of the ellipsoid body model moving in a room.

:func:`make_sequence` (native) renders a motion (walk, wave, squat, turn, arm_raise)
with the body renderer, adds a floor and a back wall, and applies a Kinect-v1-like
sensor model: axial noise sigma(z) = 1.2 mm + 1.9 mm (z - 0.4)^2, disparity quantisation
(f = 580 px at 640 columns, baseline 7.5 cm, 1/8 px), a projector shadow to the image
left of the body, dropouts on the far side of depth edges and ~1 % random dropouts. The
result uses the key layout of the shared synthetic data (depth uint16 mm, background,
mask, joints, intrinsics, joint_names, fps, meta) plus ``poses`` (T, 22) and ``labels``
(T, H, W) int16, the ground-truth part of every pixel. Deterministic for a seed; no
external data. This module adds the sequence files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._core import MOTIONS, make_sequence, motion_pose, read_npz

__all__ = ["MOTIONS", "make_sequence", "save", "load", "motion_pose"]


def save(path: str | Path, seq: dict[str, np.ndarray]) -> None:
    """Writes a sequence as a compressed .npz in the shared data's layout."""
    arrays: dict[str, Any] = dict(seq)  # no key is one of savez's own keywords
    np.savez_compressed(path, **arrays)


def load(path: str | Path) -> dict[str, np.ndarray]:
    """Reads a sequence written by `save` (or a shared synthetic sequence)."""
    return read_npz(path, "a sequence file")
