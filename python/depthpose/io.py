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
from typing import Union

from ._core import (
    KINECT_SHAPE,
    MissingFileError,
    read_depth,
    read_float_image,
    read_image,
    read_npz,
    read_pfm,
    write_depth,
    write_npz,
    write_pfm,
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
    "write_npz",
    "KINECT_SHAPE",
]


def missing_file(path: PathLike) -> MissingFileError:
    """The error for a file or folder that does not exist."""
    return MissingFileError(errno.ENOENT, "no such file", os.fspath(path))
