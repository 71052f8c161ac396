"""Argument checks of the Python layer, with the rules of the native converter.

Every check names the argument. A value of the wrong Python type raises
:class:`~depthpose.InvalidTypeError` (a ``TypeError`` and an ``InvalidInputError``), a
wrong value :class:`~depthpose.InvalidInputError`, a value beyond a size limit
:class:`~depthpose.ResourceLimitError`. Arrays are checked the way ``depthpose._core``
checks them (see ``docs/robustness.md``): their size before anything is copied, then
their dtype.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ._core import (
    MAX_ARRAY_ELEMENTS,
    MAX_IMAGE_PIXELS,
    InvalidInputError,
    InvalidTypeError,
    ResourceLimitError,
)

__all__ = [
    "array",
    "brief",
    "integer",
    "mask",
    "number",
    "type_name",
]


def type_name(value: Any) -> str:
    """The name of ``value``'s type, as messages show it."""
    return type(value).__name__


def brief(value: Any) -> str:
    """A number as a message prints it: at most 8 significant digits."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, numbers.Integral):
        try:
            text = str(int(value))
        except ValueError:  # beyond Python's limit on printed digits
            return "an integer of thousands of digits"
        if len(text) <= 20:
            return text
        sign, digits = ("-", text[1:]) if text.startswith("-") else ("", text)
        return f"{sign}{digits[0]}.{digits[1:4]}e{len(digits) - 1}"
    if isinstance(value, numbers.Real):
        try:
            return f"{float(value):.8g}"
        except (OverflowError, ValueError):
            return "a number beyond the float range"
    return type_name(value)


def integer(value: Any, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """A Python or numpy integer (not a bool) within [``low``, ``high``]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise InvalidTypeError(f"{name}: expected an integer, got {type_name(value)}")
    v = int(value)
    if (low is not None and v < low) or (high is not None and v > high):
        lo = "" if low is None else str(low)
        hi = "" if high is None else str(high)
        raise InvalidInputError(f"{name}: must be an integer in {lo}..{hi}, got {brief(v)}")
    return v


def number(
    value: Any,
    name: str,
    *,
    low: float = -math.inf,
    high: float = math.inf,
    low_open: bool = False,
) -> float:
    """A finite Python or numpy real number (not a bool) within [``low``, ``high``]
    (``low_open``: above ``low``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InvalidTypeError(f"{name}: expected a number, got {type_name(value)}")
    try:
        v = float(value)
    except OverflowError:
        raise InvalidInputError(f"{name}: {brief(value)} is beyond any sensible value") from None
    inside = (v > low if low_open else v >= low) and v <= high
    if not (math.isfinite(v) and inside):
        lo = "(" if low_open else "["
        raise InvalidInputError(
            f"{name}: must be a finite number in {lo}{brief(low)}, {brief(high)}], got {brief(v)}"
        )
    return v


def array(value: Any, name: str, *, image: int = 0) -> np.ndarray:
    """``value`` if it is a numpy array within its size limit (not copied): an image
    (``image`` > 0: H × W at most ``MAX_IMAGE_PIXELS``, and ``image`` values a pixel)
    or any other array (``MAX_ARRAY_ELEMENTS``)."""
    if not isinstance(value, np.ndarray):
        raise InvalidTypeError(f"{name}: expected a numpy array, got {type_name(value)}")
    if image:
        _image_size(value, name)
        limit, most = "MAX_IMAGE_PIXELS", image * MAX_IMAGE_PIXELS
    else:
        limit, most = "MAX_ARRAY_ELEMENTS", MAX_ARRAY_ELEMENTS
    if value.size > most:
        raise ResourceLimitError(
            f"{name}: {value.size} elements (shape {value.shape}) exceed the limit "
            f"{limit} = {MAX_IMAGE_PIXELS if image else MAX_ARRAY_ELEMENTS}"
        )
    return value


def _image_size(value: np.ndarray, name: str) -> None:
    if value.ndim >= 2 and value.shape[0] * value.shape[1] > MAX_IMAGE_PIXELS:
        raise ResourceLimitError(
            f"{name}: an image of {value.shape[0]}x{value.shape[1]} pixels exceeds the limit "
            f"MAX_IMAGE_PIXELS = {MAX_IMAGE_PIXELS}"
        )


def _not_numbers(dtype: np.dtype) -> str | None:
    """Why ``dtype`` cannot hold numbers (None if it can)."""
    kind = dtype.kind
    if kind in "fiu":
        return None
    return {
        "b": "a bool array where numbers are expected",
        "c": "complex numbers are not supported",
        "O": "an object array; convert it with numpy.asarray(x, dtype=float)",
        "U": "a string array where numbers are expected",
        "S": "a string array where numbers are expected",
    }.get(kind, "not a numeric array")


def mask(value: Any, shape: tuple[int, ...], name: str = "mask") -> np.ndarray:
    """A mask of exactly ``shape`` as a C-contiguous bool array: bool, or an integer
    dtype holding only 0 and 1. Anything else (strings, floats, other integers) is
    refused rather than cast: ``np.array(['False'])`` is not a False mask."""
    m = array(value, name, image=1)
    if m.shape != tuple(shape):
        raise InvalidInputError(f"{name}: shape {m.shape} does not match {tuple(shape)}")
    kind = m.dtype.kind
    if kind == "b":
        return np.ascontiguousarray(m)
    if kind in "iu":
        bad = (m != 0) & (m != 1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InvalidInputError(
                f"{name}: an integer mask must hold only 0 and 1, got "
                f"{brief(m.ravel()[k])} at flat index {k}"
            )
        return np.ascontiguousarray(m, dtype=bool)
    msg = (
        f"{name}: a mask must be a bool array (or integers 0 and 1), got dtype {m.dtype}; "
        "use mask != 0 or mask.astype(bool) if that is what you mean"
    )
    if kind in "OUSV":
        raise InvalidTypeError(msg)
    raise InvalidInputError(msg)


def numbers_array(value: Any, name: str, *, ndim: int | None = None) -> np.ndarray:
    """A numeric array (any layout) as float64, without NaN or inf."""
    a = array(np.asarray(value) if isinstance(value, (list, tuple)) else value, name)
    why = _not_numbers(a.dtype)
    if why is not None:
        cls = InvalidInputError if a.dtype.kind == "b" else InvalidTypeError
        raise cls(f"{name}: dtype {a.dtype}: {why}")
    if ndim is not None and a.ndim != ndim:
        raise InvalidInputError(f"{name}: expected a {ndim}-D array, got shape {a.shape}")
    out = a.astype(np.float64)
    if not np.isfinite(out).all():
        k = int(np.flatnonzero(~np.isfinite(out))[0])
        raise InvalidInputError(
            f"{name}: holds a non-finite value ({out.ravel()[k]}) at flat index {k}"
        )
    return out
