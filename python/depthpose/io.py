"""Reading and writing depth images and gray images.

Depth is float32 metres, 0 or NaN = no reading. 16-bit PNG/TIFF files hold integer
units of ``scale`` metres (millimetres by default). Supported depth formats: 16-bit PNG
and TIFF, float TIFF, ``.npy``, ``.pfm`` and raw little-endian ``.u16`` (give ``shape``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Union

import numpy as np

from . import _core
from ._core import FileFormatError, InvalidInputError

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["read_depth", "write_depth", "read_image", "read_pfm", "write_pfm"]

#: Shape assumed for raw ``.u16`` files when none is given (Kinect v1).
KINECT_SHAPE = (480, 640)


def _existing(path: PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"{p}: no such file")
    if p.is_dir():
        raise FileFormatError(f"{p}: is a directory, not an image file")
    return p


def _as_depth(arr: np.ndarray, path: Path) -> np.ndarray:
    if arr.ndim != 2:
        raise FileFormatError(f"{path}: expected a 2-D depth image, got shape {arr.shape}")
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) * np.float32(0.001)
    if arr.dtype.kind != "f":
        raise FileFormatError(f"{path}: depth must be float metres or uint16 mm, got {arr.dtype}")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    if np.isinf(out).any() or (out < 0).any():
        raise FileFormatError(f"{path}: depth holds negative or infinite values")
    return out


def read_pfm(path: PathLike) -> np.ndarray:
    """A PFM image (``Pf`` gray or ``PF`` colour, first channel) as float32, top row first."""
    p = _existing(path)
    with open(p, "rb") as f:
        header = f.readline().strip()
        if header not in (b"Pf", b"PF"):
            raise FileFormatError(f"{p}: not a PFM file (header {header[:8]!r})")
        try:
            dims = f.readline().split()
            width, height = int(dims[0]), int(dims[1])
            scale = float(f.readline().strip())
        except (ValueError, IndexError) as e:
            raise FileFormatError(f"{p}: corrupt PFM header") from e
        channels = 3 if header == b"PF" else 1
        count = width * height * channels
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    if width <= 0 or height <= 0 or data.size < count:
        raise FileFormatError(f"{p}: truncated PFM ({data.size} of {count} values)")
    img = data[:count].reshape(height, width, channels)[..., 0]
    return np.ascontiguousarray(np.flipud(img), dtype=np.float32)


def write_pfm(path: PathLike, image: np.ndarray) -> None:
    """Writes a 2-D float image as little-endian gray PFM."""
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2:
        raise InvalidInputError(f"image: expected a 2-D array, got shape {img.shape}")
    with open(path, "wb") as f:
        f.write(b"Pf\n%d %d\n-1.0\n" % (img.shape[1], img.shape[0]))
        f.write(np.ascontiguousarray(np.flipud(img)).astype("<f4").tobytes())


def read_depth(
    path: PathLike, scale: float = 0.001, shape: tuple[int, int] | None = None
) -> np.ndarray:
    """Reads a depth image as float32 metres (0 = no reading).

    ``scale`` converts integer units to metres (16-bit PNG/TIFF and ``.u16``; default mm).
    ``shape`` (height, width) is needed for raw ``.u16`` files that are not 640×480.
    """
    if not (isinstance(scale, (int, float)) and np.isfinite(scale) and scale > 0):
        raise InvalidInputError(f"scale: must be a positive number, got {scale!r}")
    p = _existing(path)
    suffix = p.suffix.lower()
    if suffix in (".png", ".tif", ".tiff"):
        return _core.read_depth_image(str(p), scale)
    if suffix == ".npy":
        try:
            arr = np.load(p, allow_pickle=False)
        except (ValueError, OSError, EOFError) as e:
            raise FileFormatError(f"{p}: not a readable .npy file ({e})") from e
        return _as_depth(arr, p)
    if suffix == ".pfm":
        return _as_depth(read_pfm(p), p)
    if suffix in (".u16", ".raw"):
        h, w = shape if shape is not None else KINECT_SHAPE
        raw = np.fromfile(p, dtype="<u2")
        if raw.size != h * w:
            raise FileFormatError(
                f"{p}: holds {raw.size} 16-bit values, not {h}x{w}; pass shape=(height, width)"
            )
        return raw.reshape(h, w).astype(np.float32) * np.float32(scale)
    raise FileFormatError(
        f"{p}: unknown depth format {suffix!r} (use .png, .tif, .npy, .pfm or .u16)"
    )


def write_depth(path: PathLike, depth: np.ndarray, scale: float = 0.001) -> None:
    """Writes depth (H, W) metres as 16-bit PNG (units of ``scale``), ``.npy`` or ``.pfm``."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".png":
        _core.write_depth_png(str(p), depth, scale)
    elif suffix == ".npy":
        np.save(p, np.asarray(depth, dtype=np.float32))
    elif suffix == ".pfm":
        write_pfm(p, np.asarray(depth, dtype=np.float32))
    else:
        raise InvalidInputError(f"path: unknown depth format {suffix!r} (use .png, .npy or .pfm)")


def read_image(path: PathLike) -> np.ndarray:
    """Any PNG/TIFF/JPEG as a gray float32 image (integer types scaled to [0, 1])."""
    return _core.read_gray_image(str(_existing(path)))
