"""Depth sequences on disk: a .npz in the shared layout, a folder of depth frames, or a
single depth image. Used by ``depthpose estimate`` and ``depthpose batch``.

A folder is read frame by frame: :meth:`Sequence.iter_frames` yields each frame or
the error that frame raised (corrupt, truncated, another size), so one bad frame
does not stop the others.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import numpy as np
import numpy.typing as npt

from . import _validate
from ._core import (
    MAX_DEPTH_SCALE,
    MIN_DEPTH_SCALE,
    Camera,
    DepthPoseError,
    FileFormatError,
    InvalidInputError,
    InvalidTypeError,
)
from .io import missing_file, read_depth, read_npz

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["Sequence", "open_sequence", "expand_inputs"]

FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".pfm", ".u16")


@dataclass
class Sequence:
    """A depth sequence: frames are read on demand with :meth:`frames` or
    :meth:`iter_frames`."""

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

    def _range(self, start: int, stop: int | None) -> tuple[int, int]:
        start = _validate.integer(start, "start", low=0)
        stop = self.n_frames if stop is None else _validate.integer(stop, "stop", low=0)
        stop = min(stop, self.n_frames)
        if start > stop:
            raise InvalidInputError(f"start/stop: bad frame range [{start}, {stop})")
        return start, stop

    def _npz_depth(self, start: int, stop: int) -> np.ndarray:
        arrays = read_npz(self.path, "a depth sequence", keys=["depth"])
        if "depth" not in arrays:
            raise FileFormatError(f"{self.path}: no 'depth' array")
        depth = arrays["depth"][start:stop]
        return _to_metres(depth, self.depth_scale, self.path)

    def _read_file(self, k: int) -> np.ndarray:
        f = self.files[k]
        d = read_depth(f, scale=self.depth_scale)
        shape = (self.camera.height, self.camera.width)
        if d.shape != shape:
            raise FileFormatError(
                f"{f}: frame is {d.shape[1]}x{d.shape[0]} pixels, the sequence is "
                f"{shape[1]}x{shape[0]}"
            )
        return d

    def frames(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Depth frames [start, stop) as float32 metres, (k, H, W). A frame that cannot
        be read raises its error (see :meth:`iter_frames` for reading around it)."""
        start, stop = self._range(start, stop)
        if self.kind == "npz":
            return self._npz_depth(start, stop)
        out = [self._read_file(k) for k in range(start, stop)]
        shape = (self.camera.height, self.camera.width)
        return np.stack(out) if out else np.zeros((0, *shape), np.float32)

    def iter_frames(
        self, start: int = 0, stop: int | None = None
    ) -> Iterator[tuple[int, np.ndarray | DepthPoseError]]:
        """(index, frame) for each frame in [start, stop): the depth (H, W) float32
        metres, or the :class:`DepthPoseError` (a ``MissingFileError`` or
        ``FileFormatError``) that frame raised when read."""
        start, stop = self._range(start, stop)
        if self.kind == "npz":
            depth = self._npz_depth(start, stop)
            for k in range(start, stop):
                yield k, depth[k - start]
            return
        for k in range(start, stop):
            try:
                yield k, self._read_file(k)
            except DepthPoseError as e:
                yield k, e

    def frame_name(self, k: int) -> str:
        """How messages name frame ``k``: its file, or its index in the .npz."""
        if self.files and 0 <= k < len(self.files):
            return str(self.files[k])
        return f"{self.path}[{k}]"


def _to_metres(depth: np.ndarray, scale: float, path: Path) -> np.ndarray:
    if depth.dtype == np.uint16:
        return depth.astype(np.float32) * np.float32(scale)
    if depth.dtype.kind == "f":
        return np.ascontiguousarray(depth, dtype=np.float32)
    raise FileFormatError(f"{path}: depth must be uint16 or float, got {depth.dtype}")


def _camera(
    intrinsics: npt.ArrayLike | None,
    shape: tuple[int, int],
    path: Path,
    camera: Camera | Callable[[tuple[int, int]], Camera] | None = None,
) -> Camera:
    shape = (int(shape[0]), int(shape[1]))
    if camera is not None:
        if intrinsics is not None:
            raise InvalidInputError("camera: give either camera or intrinsics, not both")
        cam = camera if isinstance(camera, Camera) else camera(shape)
        if not isinstance(cam, Camera):
            raise InvalidTypeError(f"camera: expected a depthpose.Camera, got {type(cam)}")
        if cam.shape != shape:
            raise InvalidInputError(
                f"camera: the camera is {cam.width}x{cam.height} pixels but {path} is "
                f"{shape[1]}x{shape[0]}"
            )
        return cam
    if intrinsics is None:
        raise InvalidInputError(
            f"intrinsics: {path} has no camera intrinsics; pass --intrinsics fx fy cx cy"
        )
    vals = _validate.numbers_array(intrinsics, "intrinsics").ravel()
    if vals.size != 4:
        raise InvalidInputError(f"intrinsics: need [fx, fy, cx, cy], got {vals.size} values")
    return Camera.from_intrinsics([float(v) for v in vals], (int(shape[0]), int(shape[1])))


def _frame_shape(files: list[Path], scale: float, folder: Path) -> tuple[int, int]:
    """The size (H, W) of a folder's frames: that of most of its first three readable
    files (so that one stray image of another size is a failed frame, not the size)."""
    first_error: DepthPoseError | None = None
    shapes: list[tuple[int, int]] = []
    for f in files:
        try:
            shapes.append(read_depth(f, scale=scale).shape)
        except DepthPoseError as e:
            first_error = first_error or e
        if len(shapes) == 3:
            break
    if not shapes:
        raise FileFormatError(
            f"{folder}: none of its {len(files)} depth frames can be read (first: {first_error})"
        )
    return max(shapes, key=shapes.count)


def open_sequence(
    path: PathLike,
    *,
    intrinsics: npt.ArrayLike | None = None,
    depth_scale: float = 0.001,
    camera: Camera | Callable[[tuple[int, int]], Camera] | None = None,
    pattern: str | None = None,
) -> Sequence:
    """Opens a .npz (keys ``depth`` (T, H, W), ``intrinsics``, optional ``background``,
    ``joints``, ``fps``), a folder of depth frames (sorted by name; its size is that of
    most of its first three readable frames) or one depth image. ``depth_scale``:
    metres per integer unit, in [1e-6, 1] (the readers' ``scale``; the CLI's
    ``--depth-scale`` counts units per metre instead). ``camera``: a :class:`Camera`
    (or a function of the image shape (H, W) returning one) instead of ``intrinsics``.
    ``pattern``: for a folder, a glob of the frame files to read (default: every
    depth-image suffix); a matched file that is not a depth image is a failed frame,
    not a failed sequence."""
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path: expected a path (str or os.PathLike), got {type(path)}")
    scale = _validate.number(depth_scale, "depth_scale", low=MIN_DEPTH_SCALE, high=MAX_DEPTH_SCALE)
    p = Path(path)
    if not p.exists():
        raise missing_file(p)
    if pattern is not None and not isinstance(pattern, str):
        raise InvalidTypeError(f"pattern: expected a glob pattern (str), got {type(pattern)}")
    if p.is_dir():
        if pattern is not None:
            files = sorted(f for f in p.glob(pattern) if f.is_file())
            if not files:
                raise FileFormatError(f"{p}: no file inside matches {pattern!r}")
        else:
            files = sorted(f for f in p.iterdir() if f.suffix.lower() in FRAME_SUFFIXES)
        if not files:
            raise FileFormatError(f"{p}: no depth frames ({', '.join(FRAME_SUFFIXES)}) inside")
        bg_file = p / "background.png"
        files = [f for f in files if f.name != "background.png"]
        if not files:
            raise FileFormatError(f"{p}: no depth frames besides background.png")
        shape = _frame_shape(files, scale, p)
        bg = read_depth(bg_file, scale=scale) if bg_file.exists() else None
        return Sequence(
            p,
            p.name,
            "folder",
            len(files),
            _camera(intrinsics, shape, p, camera),
            scale,
            bg,
            files=files,
        )
    if p.suffix.lower() == ".npz":
        d = read_npz(p, "a depth sequence")
        if "depth" not in d:
            raise FileFormatError(f"{p}: no 'depth' array (keys: {sorted(d)})")
        depth_shape = d["depth"].shape
        try:
            intr = d["intrinsics"] if "intrinsics" in d else intrinsics
            bg = d.get("background")
            gt = d["joints"].astype(np.float64) if "joints" in d else None
            fps = float(d["fps"]) if "fps" in d else 30.0
        except (TypeError, ValueError) as e:
            raise FileFormatError(f"{p}: corrupt .npz ({type(e).__name__}: {e})") from None
        if len(depth_shape) == 2:
            raise FileFormatError(f"{p}: 'depth' is one frame {depth_shape}; expected (T, H, W)")
        if len(depth_shape) != 3 or depth_shape[0] == 0:
            raise FileFormatError(f"{p}: 'depth' must be (T, H, W), got {depth_shape}")
        if not (np.isfinite(fps) and fps > 0):
            raise FileFormatError(f"{p}: 'fps' must be a positive number, got {fps}")
        if camera is not None:
            cam = _camera(intrinsics, depth_shape[1:], p, camera)
        else:
            cam = _camera(intr if intrinsics is None else intrinsics, depth_shape[1:], p)
        background = _to_metres(bg, scale, p) if bg is not None else None
        return Sequence(p, p.stem, "npz", depth_shape[0], cam, scale, background, gt, fps)
    first = read_depth(p, scale=scale)
    cam = _camera(intrinsics, first.shape, p, camera)
    return Sequence(p, p.stem, "image", 1, cam, scale, files=[p])


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
