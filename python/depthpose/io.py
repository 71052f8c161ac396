"""Reading and writing depth images and gray images.

Depth in memory is float32 metres, 0 or NaN = no reading. On disk, each format has one
unit:

========================  =================================================  ==========
format                    unit                                               no reading
========================  =================================================  ==========
16-bit PNG / TIFF         integer units of ``scale`` metres (default 0.001:  0
                          millimetres), 0..65535
float TIFF (32/64-bit)    metres (``scale`` ignored)                         0 or NaN
``.npy``                  float32 metres; uint16 arrays are units of         0 or NaN
                          ``scale`` metres
``.pfm``                  float32 metres                                     0 or NaN
raw ``.u16``              little-endian uint16 units of ``scale`` metres     0
========================  =================================================  ==========

:func:`write_depth` takes depth as every function does (float metres, or uint16
millimetres) and refuses what the format cannot store instead of clipping it: a PNG
holds 1..65535 units (65.535 m in millimetres; a depth that would round to 0 units is
refused too, as it would read back as no reading); NaN is written as 0 in a PNG and
kept as NaN in ``.npy`` and ``.pfm``. ``scale`` must lie in [1e-6, 1] metres per unit.

A missing file raises :class:`~depthpose.MissingFileError` (a ``FileNotFoundError``
and a :class:`~depthpose.FileFormatError`); an unreadable, corrupt or truncated one
:class:`~depthpose.FileFormatError`.
"""

from __future__ import annotations

import errno
import os
import zipfile
from pathlib import Path
from typing import Union

import numpy as np

from . import _core, _validate
from ._core import (
    MAX_DEPTH_SCALE,
    MAX_IMAGE_PIXELS,
    MIN_DEPTH_SCALE,
    FileFormatError,
    InvalidInputError,
    InvalidTypeError,
    MissingFileError,
    ResourceLimitError,
)

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "read_depth",
    "write_depth",
    "read_image",
    "read_float_image",
    "read_pfm",
    "write_pfm",
    "missing_file",
    "read_npz",
]

#: Shape assumed for raw ``.u16`` files when none is given (Kinect v1).
KINECT_SHAPE = (480, 640)


def missing_file(path: PathLike) -> MissingFileError:
    """The error for a file or folder that does not exist."""
    return MissingFileError(errno.ENOENT, "no such file", os.fspath(path))


def _path(path: object, name: str = "path") -> Path:
    if isinstance(path, (str, os.PathLike)):
        p = Path(path)
        if str(p) == "":
            raise InvalidInputError(f"{name}: empty path")
        return p
    raise InvalidTypeError(
        f"{name}: expected a path (str or os.PathLike), got {type(path).__name__}"
    )


def _existing(path: object) -> Path:
    p = _path(path)
    if not p.exists():
        raise missing_file(p)
    if p.is_dir():
        raise FileFormatError(f"{p}: is a directory, not an image file")
    return p


def _scale(scale: object) -> float:
    return _validate.number(scale, "scale", low=MIN_DEPTH_SCALE, high=MAX_DEPTH_SCALE)


def _check_pixels(path: Path, shape: tuple[int, ...]) -> None:
    if len(shape) >= 2 and shape[0] * shape[1] > MAX_IMAGE_PIXELS:
        raise ResourceLimitError(
            f"{path}: an image of {shape[0]}x{shape[1]} pixels exceeds the limit "
            f"MAX_IMAGE_PIXELS = {MAX_IMAGE_PIXELS}"
        )


def _as_depth(arr: np.ndarray, path: Path, scale: float) -> np.ndarray:
    if arr.ndim != 2:
        raise FileFormatError(f"{path}: expected a 2-D depth image, got shape {arr.shape}")
    if arr.size == 0:
        raise FileFormatError(f"{path}: the depth image is empty (shape {arr.shape})")
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) * np.float32(scale)
    if arr.dtype.kind != "f":
        raise FileFormatError(f"{path}: depth must be float metres or uint16, got {arr.dtype}")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    bad = np.isinf(out) | (out < 0)
    if bad.any():
        r, c = np.unravel_index(int(np.flatnonzero(bad)[0]), out.shape)
        raise FileFormatError(
            f"{path}: depth holds {out[r, c]} at row {r}, column {c} (depth is >= 0 metres; "
            "NaN or 0 mean no reading)"
        )
    return out


def _pfm_header(data: bytes, path: Path) -> tuple[int, int, int, float, int]:
    """(width, height, channels, scale, offset of the pixels) of a PFM file: the magic
    ``Pf``/``PF``, width, height and scale, separated by white space, then one white
    space character before the pixels."""
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace() and pos - start < 64:
            pos += 1
        if pos == start or pos >= len(data):
            raise FileFormatError(f"{path}: truncated PFM header")
        tokens.append(data[start:pos])
    magic = tokens[0]
    if magic not in (b"Pf", b"PF"):
        raise FileFormatError(f"{path}: not a PFM file (header {magic[:8]!r})")
    try:
        width, height = int(tokens[1]), int(tokens[2])
        scale = float(tokens[3])
    except ValueError:
        raise FileFormatError(f"{path}: corrupt PFM header") from None
    if width <= 0 or height <= 0 or not np.isfinite(scale) or scale == 0:
        raise FileFormatError(
            f"{path}: corrupt PFM header (size {width}x{height}, scale {_validate.brief(scale)})"
        )
    _check_pixels(path, (height, width))
    return width, height, 3 if magic == b"PF" else 1, scale, pos + 1


def read_pfm(path: PathLike) -> np.ndarray:
    """A PFM image (``Pf`` gray or ``PF`` colour, first channel) as float32, top row first."""
    p = _existing(path)
    with open(p, "rb") as f:
        head = f.read(256)
        width, height, channels, scale, offset = _pfm_header(head, p)
        count = width * height * channels
        f.seek(offset)
        raw = f.read(4 * count + 1)
    if len(raw) < 4 * count:
        raise FileFormatError(f"{p}: truncated PFM ({len(raw) // 4} of {count} values)")
    data = np.frombuffer(raw[: 4 * count], dtype="<f4" if scale < 0 else ">f4")
    img = data.reshape(height, width, channels)[..., 0]
    return np.ascontiguousarray(np.flipud(img), dtype=np.float32)


def write_pfm(path: PathLike, image: np.ndarray) -> None:
    """Writes a 2-D float image (any real dtype, NaN and inf kept) as little-endian
    gray PFM."""
    p = _path(path)
    img = _validate.array(image, "image", image=1)
    if img.ndim != 2 or img.size == 0:
        raise InvalidInputError(f"image: expected a non-empty 2-D array, got shape {img.shape}")
    why = _validate._not_numbers(img.dtype)
    if why is not None:
        cls = InvalidInputError if img.dtype.kind == "b" else InvalidTypeError
        raise cls(f"image: dtype {img.dtype}: {why}")
    with open(p, "wb") as f:
        f.write(b"Pf\n%d %d\n-1.0\n" % (img.shape[1], img.shape[0]))
        f.write(np.ascontiguousarray(np.flipud(img)).astype("<f4").tobytes())


def _read_npy(p: Path, scale: float) -> np.ndarray:
    """A depth ``.npy``: its header is checked (shape, dtype, size) before the data
    is read."""
    try:
        with open(p, "rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"unsupported .npy version {version}")
    except Exception as e:  # numpy parses the header with Python's tokenizer
        raise FileFormatError(f"{p}: not a readable .npy file ({type(e).__name__})") from None
    if dtype.hasobject:
        raise FileFormatError(f"{p}: holds Python objects, not depth")
    if len(shape) != 2:
        raise FileFormatError(f"{p}: expected a 2-D depth image, got shape {shape}")
    _check_pixels(p, shape)
    try:
        arr = np.load(p, allow_pickle=False)
    except Exception as e:  # a truncated or corrupt body
        raise FileFormatError(f"{p}: not a readable .npy file ({_short(e)})") from None
    return _as_depth(arr, p, scale)


def read_depth(
    path: PathLike, scale: float = 0.001, shape: tuple[int, int] | None = None
) -> np.ndarray:
    """Reads a depth image as float32 metres (0 = no reading).

    ``scale`` converts integer units to metres (16-bit PNG/TIFF, uint16 ``.npy`` and
    ``.u16``; default millimetres), in [1e-6, 1]. ``shape`` (height, width) is needed
    for raw ``.u16`` files that are not 640×480. See the module's table of units.
    """
    s = _scale(scale)
    p = _existing(path)
    suffix = p.suffix.lower()
    if suffix in (".png", ".tif", ".tiff"):
        return _core.read_depth_image(str(p), s)
    if suffix == ".npy":
        return _read_npy(p, s)
    if suffix == ".pfm":
        return _as_depth(read_pfm(p), p, s)
    if suffix in (".u16", ".raw"):
        if shape is None:
            h, w = KINECT_SHAPE
        else:
            if not isinstance(shape, (tuple, list)) or len(shape) != 2:
                raise InvalidInputError(f"shape: expected (height, width), got {shape!r}")
            h = _validate.integer(shape[0], "shape", low=1)
            w = _validate.integer(shape[1], "shape", low=1)
        _check_pixels(p, (h, w))
        size = p.stat().st_size
        if size != 2 * h * w:
            raise FileFormatError(
                f"{p}: holds {size // 2} 16-bit values, not {h}x{w}; pass shape=(height, width)"
            )
        raw = np.fromfile(p, dtype="<u2")
        return raw.reshape(h, w).astype(np.float32) * np.float32(s)
    raise FileFormatError(
        f"{p}: unknown depth format {suffix!r} (use .png, .tif, .npy, .pfm or .u16)"
    )


def write_depth(path: PathLike, depth: np.ndarray, scale: float = 0.001) -> None:
    """Writes depth (H, W) as 16-bit PNG (units of ``scale`` metres), ``.npy`` or
    ``.pfm`` (float32 metres).

    ``depth`` is float metres or uint16 millimetres, as every depthpose function takes
    it (so uint16 input is millimetres in every format). Refuses negative or infinite
    depth and, for PNG, depth the file cannot store (beyond 65535 units, or below half
    a unit); NaN is written as 0 in PNG and kept in ``.npy``/``.pfm``.
    """
    p = _path(path)
    suffix = p.suffix.lower()
    if suffix not in (".png", ".npy", ".pfm"):
        raise InvalidInputError(f"path: unknown depth format {suffix!r} (use .png, .npy or .pfm)")
    s = _scale(scale)
    metres = _validate.depth_image(depth, "depth")
    if suffix == ".png":
        _core.write_depth_png(str(p), metres, s)
    elif suffix == ".npy":
        with open(p, "wb") as f:
            np.save(f, metres)
    else:
        write_pfm(p, metres)


def read_npz(
    path: PathLike, what: str = "a .npz archive", keys: list[str] | None = None
) -> dict[str, np.ndarray]:
    """Every array of a ``.npz`` file (numpy's zip of ``.npy`` arrays), or those named
    in ``keys`` that it holds, read without pickles. A missing file raises
    :class:`~depthpose.MissingFileError`; anything that is not such an archive of
    plain arrays (another file, a truncated archive, a Python object inside) a
    :class:`~depthpose.FileFormatError` saying it is not
    ``what``."""
    p = _existing(path)
    if not zipfile.is_zipfile(p):
        raise FileFormatError(f"{p}: not {what} (not a zip archive of numpy arrays)")
    out: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(p) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                key = info.filename[: -len(".npy")]
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    read_header = (
                        np.lib.format.read_array_header_1_0
                        if version == (1, 0)
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, fortran, dtype = read_header(f)
                    header_len = f.tell()
                if dtype.hasobject:
                    raise FileFormatError(f"{p}: entry {key!r} holds Python objects; not {what}")
                nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
                if header_len + nbytes != info.file_size:
                    raise FileFormatError(
                        f"{p}: entry {key!r} is truncated or corrupt (shape {shape} needs "
                        f"{nbytes} bytes); not {what}"
                    )
            with np.load(p, allow_pickle=False) as d:
                for key in d.files:
                    if keys is None or key in keys:
                        out[key] = d[key]
    except FileFormatError:
        raise
    except Exception as e:  # zipfile, numpy's header parser (tokenizer), decompression
        raise FileFormatError(f"{p}: not {what} ({type(e).__name__}: {_short(e)})") from None
    return out


def _short(e: BaseException) -> str:
    """An exception's message for ours: its first line, at most 120 characters."""
    text = str(e).splitlines()[0] if str(e) else ""
    return text[:117] + "..." if len(text) > 120 else text


def read_image(path: PathLike) -> np.ndarray:
    """Any PNG/TIFF/JPEG as a gray float32 image (integer types scaled to [0, 1], float
    TIFF as stored)."""
    return _core.read_gray_image(str(_existing(path)))


def read_float_image(path: PathLike) -> np.ndarray:
    """A float TIFF (its first channel) or any other image as stored, float32."""
    return _core.read_float_image(str(_existing(path)))
