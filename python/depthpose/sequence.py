"""Depth sequences on disk: a .npz in the shared layout, a folder of 16-bit PNG frames, or
a single depth image. Used by ``depthpose estimate`` and ``depthpose batch``."""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import numpy as np

from ._core import Camera, FileFormatError, InvalidInputError
from .io import read_depth

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["Sequence", "open_sequence", "expand_inputs"]

FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".pfm", ".u16")


@dataclass
class Sequence:
    """A depth sequence: frames are read on demand with :meth:`frames`."""

    path: Path
    name: str
    kind: str  # "npz" | "folder" | "image"
    n_frames: int
    camera: Camera
    depth_scale: float = 0.001
    background: np.ndarray | None = None
    gt_joints: np.ndarray | None = None
    fps: float = 30.0
    files: list[Path] = field(default_factory=list)

    def frames(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Depth frames [start, stop) as float32 metres, (k, H, W)."""
        stop = self.n_frames if stop is None else min(stop, self.n_frames)
        if not 0 <= start <= stop:
            raise InvalidInputError(f"start/stop: bad frame range [{start}, {stop})")
        if self.kind == "npz":
            with np.load(self.path, allow_pickle=False) as d:
                depth = d["depth"][start:stop]
            return _to_metres(depth, self.depth_scale, self.path)
        out = [read_depth(f, scale=self.depth_scale) for f in self.files[start:stop]]
        shape = (self.camera.height, self.camera.width)
        for f, d in zip(self.files[start:stop], out, strict=False):
            if d.shape != shape:
                raise FileFormatError(f"{f}: frame is {d.shape}, the sequence is {shape}")
        return np.stack(out) if out else np.zeros((0, *shape), np.float32)


def _to_metres(depth: np.ndarray, scale: float, path: Path) -> np.ndarray:
    if depth.dtype == np.uint16:
        return depth.astype(np.float32) * np.float32(scale)
    if depth.dtype.kind == "f":
        return np.ascontiguousarray(depth, dtype=np.float32)
    raise FileFormatError(f"{path}: depth must be uint16 or float, got {depth.dtype}")


def _camera(intrinsics, shape: tuple[int, int], path: Path) -> Camera:
    if intrinsics is None:
        raise InvalidInputError(
            f"intrinsics: {path} has no camera intrinsics; pass --intrinsics fx fy cx cy"
        )
    vals = [float(v) for v in np.asarray(intrinsics).ravel()]
    return Camera.from_intrinsics(vals, shape)


def open_sequence(path: PathLike, *, intrinsics=None, depth_scale: float = 0.001) -> Sequence:
    """Opens a .npz (keys ``depth`` (T, H, W), ``intrinsics``, optional ``background``,
    ``joints``, ``fps``), a folder of depth frames (sorted by name) or one depth image."""
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"{p}: no such file or folder")
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in FRAME_SUFFIXES)
        if not files:
            raise FileFormatError(f"{p}: no depth frames ({', '.join(FRAME_SUFFIXES)}) inside")
        bg_file = p / "background.png"
        files = [f for f in files if f.name != "background.png"]
        if not files:
            raise FileFormatError(f"{p}: no depth frames besides background.png")
        first = read_depth(files[0], scale=depth_scale)
        bg = read_depth(bg_file, scale=depth_scale) if bg_file.exists() else None
        return Sequence(
            p,
            p.name,
            "folder",
            len(files),
            _camera(intrinsics, first.shape, p),
            depth_scale,
            bg,
            files=files,
        )
    if p.suffix.lower() == ".npz":
        try:
            d = np.load(p, allow_pickle=False)
            keys = set(d.files)
        except Exception as e:  # zipfile/pickle/OS errors of a corrupt file
            raise FileFormatError(f"{p}: not a readable .npz ({type(e).__name__}: {e})") from e
        with d:
            if "depth" not in keys:
                raise FileFormatError(f"{p}: no 'depth' array (keys: {sorted(keys)})")
            try:
                depth_shape = d["depth"].shape
                intr = d["intrinsics"] if "intrinsics" in keys else intrinsics
                bg = d["background"] if "background" in keys else None
                gt = d["joints"].astype(np.float64) if "joints" in keys else None
                fps = float(d["fps"]) if "fps" in keys else 30.0
            except Exception as e:
                raise FileFormatError(f"{p}: corrupt .npz ({type(e).__name__}: {e})") from e
        if len(depth_shape) == 2:
            raise FileFormatError(f"{p}: 'depth' is one frame {depth_shape}; expected (T, H, W)")
        if len(depth_shape) != 3 or depth_shape[0] == 0:
            raise FileFormatError(f"{p}: 'depth' must be (T, H, W), got {depth_shape}")
        cam = _camera(intr if intrinsics is None else intrinsics, depth_shape[1:], p)
        background = _to_metres(bg, depth_scale, p) if bg is not None else None
        return Sequence(p, p.stem, "npz", depth_shape[0], cam, depth_scale, background, gt, fps)
    first = read_depth(p, scale=depth_scale)
    return Sequence(
        p, p.stem, "image", 1, _camera(intrinsics, first.shape, p), depth_scale, files=[p]
    )


def expand_inputs(inputs: list[str]) -> list[Path]:
    """Files and folders named or matched by glob patterns, in order, without repeats."""
    out: list[Path] = []
    for item in inputs:
        matches = sorted(glob.glob(item)) if any(c in item for c in "*?[") else [item]
        if not matches:
            raise FileFormatError(f"{item}: the pattern matches nothing")
        for m in matches:
            p = Path(m)
            if p not in out:
                out.append(p)
    return out
