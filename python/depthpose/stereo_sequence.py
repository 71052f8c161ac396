"""Sequences of rectified stereo pairs on disk, read by ``depthpose estimate-stereo``:
a .npz (the keys of the shared ``stereo_person`` data), a folder of pairs, or a left
and a right image.

A folder holds its pairs either in subfolders ``left/`` and ``right/`` (the same file
names) or side by side, each left image's name containing ``left`` and its partner's
the same name with ``right`` in its place. Its optional empty-scene pair is
``left_bg.png`` and ``right_bg.png`` (or ``background.png`` in each subfolder).
:meth:`StereoSequence.iter_pairs` yields each pair or the error reading it raised, so
one bad pair does not stop the others.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import numpy as np
import numpy.typing as npt

from ._core import (
    Camera,
    DepthPoseError,
    FileFormatError,
    InvalidInputError,
    InvalidTypeError,
    _sequence_camera,
    _stereo_pairs,
)
from .io import missing_file, read_image, read_npz

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["StereoSequence", "open_stereo"]

_Pair = tuple[np.ndarray, np.ndarray]


@dataclass
class StereoSequence:
    """Rectified stereo pairs and what the files say about them: the left camera,
    the baseline (metres), the disparity offset, the empty scene's pair and the
    ground-truth joints when present."""

    path: Path
    name: str
    kind: str  # "npz" | "folder" | "images"
    n_frames: int
    camera: Camera
    baseline: float
    doffs: float = 0.0
    background: _Pair | None = None
    gt_joints: np.ndarray | None = None
    files: list[tuple[Path, Path]] = field(default_factory=list)

    def frame_name(self, k: int) -> str:
        """The pair's file names, or its index in a .npz."""
        if self.files:
            return f"{self.files[k][0].name}, {self.files[k][1].name}"
        return f"pair {k}"

    def iter_pairs(self) -> Iterator[tuple[int, _Pair | DepthPoseError]]:
        """Each pair (left, right) in order, or the error that reading it raised."""
        if self.kind == "npz":
            arrays = read_npz(self.path, "a stereo sequence", keys=["left", "right"])
            left, right = _frames(arrays["left"]), _frames(arrays["right"])
            for k in range(self.n_frames):
                yield k, (left[k], right[k])
            return
        shape = (self.camera.height, self.camera.width)
        for k, (lf, rf) in enumerate(self.files):
            try:
                pair = (read_image(lf), read_image(rf))
                for f, image in zip((lf, rf), pair, strict=True):
                    if image.shape != shape:
                        raise FileFormatError(
                            f"{f}: image is {image.shape[1]}x{image.shape[0]} pixels, the "
                            f"sequence is {shape[1]}x{shape[0]}"
                        )
            except DepthPoseError as e:
                yield k, e
                continue
            yield k, pair


def _frames(a: np.ndarray) -> np.ndarray:
    """Images (T, H, W[, C]) from one image (H, W) or a stack."""
    return a[None] if a.ndim == 2 else a


def _number(value: object, name: str, where: Path) -> float:
    try:
        x = float(np.asarray(value, dtype=np.float64).reshape(()))
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: '{name}' must be one number") from None
    return x


def open_stereo(
    path: PathLike,
    right: PathLike | None = None,
    *,
    baseline: float | None = None,
    doffs: float | None = None,
    intrinsics: npt.ArrayLike | None = None,
    camera: Camera | Callable[[tuple[int, int]], Camera] | None = None,
    background: tuple[PathLike, PathLike] | None = None,
) -> StereoSequence:
    """Opens a .npz of pairs (keys ``left`` and ``right`` (T, H, W) or (H, W), optional
    ``intrinsics``, ``baseline``, ``doffs``, ``left_bg``/``right_bg``, ``joints``), a
    folder of pairs, or the left image ``path`` with the right image ``right``.

    ``baseline`` (metres), ``doffs`` (pixels), ``intrinsics`` or ``camera`` (the left
    camera; a function of the image shape (H, W) may stand for it) override what a
    .npz holds and must be given for images. ``background``: the empty scene's pair
    of image files, overriding the one a .npz or a folder holds.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path: expected a path (str or os.PathLike), got {type(path)}")
    p = Path(path)
    if not p.exists():
        raise missing_file(p)
    gt = None
    bg: _Pair | None = None
    files: list[tuple[Path, Path]] = []
    if right is not None:
        r = Path(right)
        if not r.exists():
            raise missing_file(r)
        files = [(p, r)]
        kind, n, name = "images", 1, p.stem
        shape = read_image(p).shape[:2]
    elif p.is_dir():
        files, bg_files = _stereo_pairs(p)
        kind, n, name = "folder", len(files), p.name
        shape = read_image(files[0][0]).shape[:2]
        if bg_files is not None and background is None:
            bg = (read_image(bg_files[0]), read_image(bg_files[1]))
    elif p.suffix.lower() == ".npz":
        d = read_npz(p, "a stereo sequence")
        for key in ("left", "right"):
            if key not in d:
                raise FileFormatError(f"{p}: no '{key}' array (keys: {sorted(d)})")
        left, right_images = _frames(d["left"]), _frames(d["right"])
        if left.ndim not in (3, 4) or left.shape != right_images.shape or not len(left):
            raise FileFormatError(
                f"{p}: 'left' and 'right' must be images of one shape (T, H, W), got "
                f"{d['left'].shape} and {d['right'].shape}"
            )
        kind, n, name = "npz", len(left), p.stem
        shape = left.shape[1:3]
        if intrinsics is None and camera is None and "intrinsics" in d:
            intrinsics = d["intrinsics"]
        if baseline is None and "baseline" in d:
            baseline = _number(d["baseline"], "baseline", p)
        if doffs is None and "doffs" in d:
            doffs = _number(d["doffs"], "doffs", p)
        if "left_bg" in d and "right_bg" in d and background is None:
            bg = (d["left_bg"], d["right_bg"])
        if "joints" in d and d["joints"].shape == (n, 15, 3):
            gt = d["joints"].astype(np.float64)
    else:
        raise FileFormatError(
            f"{p}: expected a .npz of pairs, a folder of pairs, or a left image followed "
            "by its right image"
        )
    if background is not None:
        bg = (read_image(background[0]), read_image(background[1]))
    if baseline is None:
        raise InvalidInputError(f"baseline: {p} gives no baseline; pass --baseline METRES")
    if not (np.isfinite(baseline) and baseline > 0):
        raise InvalidInputError(f"baseline: must be finite and > 0 metres, got {baseline}")
    hw = (int(shape[0]), int(shape[1]))
    cam = _sequence_camera(hw, p, camera=camera, intrinsics=intrinsics)
    return StereoSequence(
        p, name, kind, n, cam, float(baseline), float(doffs or 0.0), bg, gt, files
    )
