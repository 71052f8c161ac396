"""Argument checks of the Python layer: the native converter's checks (see
``depthpose._core``), so that every module checks an argument by the same rules and
with the same messages as the native functions.

Every check names the argument. A value of the wrong Python type raises
:class:`~depthpose.InvalidTypeError` (a ``TypeError`` and an ``InvalidInputError``), a
wrong value :class:`~depthpose.InvalidInputError`, a value beyond a size limit
:class:`~depthpose.ResourceLimitError`; arrays are checked for their size before
anything is copied (see ``docs/robustness.md``).
"""

from __future__ import annotations

from ._core import _check_array as array
from ._core import _check_integer as integer
from ._core import _check_mask as mask
from ._core import _check_number as number
from ._core import _check_numbers as numbers_array

__all__ = ["array", "integer", "mask", "number", "numbers_array"]
