"""Shared helpers of the hostile-input tests (tests/test_hostile_*.py).

The contract every public function keeps, whatever it is given: it returns, or it
raises a :class:`depthpose.DepthPoseError` whose message names the argument, is short,
prints numbers briefly and shows no Rust debug output. A wrong Python type is also a
``TypeError``. Nothing else escapes: no panic, no ``OverflowError``, no numpy error.

``DEPTHPOSE_FUZZ_EXAMPLES`` sets the Hypothesis examples per test (default: a CI-sized
run; see docs/robustness.md).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from typing import Any

import depthpose as dp
import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

#: Examples per Hypothesis test: ``DEPTHPOSE_FUZZ_EXAMPLES``, else ``default``.
EXAMPLES = int(os.environ.get("DEPTHPOSE_FUZZ_EXAMPLES", "0") or 0)


def fuzz(default: int = 25) -> settings:
    """Hypothesis settings of a hostile test: ``default`` examples (or
    ``DEPTHPOSE_FUZZ_EXAMPLES``), no deadline (the first call of a function may load
    a database)."""
    return settings(
        max_examples=EXAMPLES or default,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )


_DEBUG = re.compile(r"\w+ \{ \w+: |Some\(|Ok\(|Err\(|\bNone\b\)|\b0x[0-9a-f]{12}")
_LONG_NUMBER = re.compile(r"\d{41,}")


def check_message(e: BaseException, names: tuple[str, ...] = ()) -> None:
    """A clear error: short, no long numbers, no Rust debug structs, naming one of
    ``names`` when given."""
    msg = str(e)
    assert msg, f"{type(e).__name__} without a message"
    assert len(msg) < 600, f"message of {len(msg)} characters: {msg[:200]}..."
    assert not _LONG_NUMBER.search(msg), f"a number printed in full: {msg}"
    assert not _DEBUG.search(msg), f"debug output in the message: {msg}"
    if names:
        assert any(n in msg for n in names), f"{msg!r} names none of {names}"


def outcome(call: Callable[[], Any], names: tuple[str, ...] = ()) -> Any:
    """Runs ``call``: its value, or the DepthPoseError it raised (checked by
    :func:`check_message`). Any other exception fails the test."""
    try:
        return call()
    except dp.DepthPoseError as e:
        if isinstance(e, TypeError):
            assert isinstance(e, dp.InvalidTypeError), type(e)
        check_message(e, names)
        return e
    except BaseException as e:  # a panic, an OverflowError, a numpy error: all bugs
        raise AssertionError(f"{type(e).__name__} escaped: {e}") from e


def refused(
    call: Callable[[], Any], kind: type[BaseException] = dp.DepthPoseError, *names: str
) -> BaseException:
    """``call`` must raise ``kind`` whose message names one of ``names``."""
    r = outcome(call, names)
    assert isinstance(r, kind), f"expected {kind.__name__}, got {r!r}"[:300]
    return r


# ---- layouts -----------------------------------------------------------------------


def layouts(a: np.ndarray) -> dict[str, np.ndarray]:
    """``a`` (C order) in other memory layouts with the same logical content: Fortran
    order, negative strides, a strided view, non-native byte order, unaligned."""
    out = {"fortran": np.asfortranarray(a)}
    if a.ndim >= 1 and a.shape[0] > 1:
        out["reversed"] = a[::-1].copy()[::-1]
    wide = np.repeat(a, 2, axis=-1) if a.ndim else a
    out["strided"] = wide[..., ::2] if a.ndim else a
    if a.dtype.itemsize > 1:
        out["byteswapped"] = a.astype(a.dtype.newbyteorder())
        raw = np.zeros(a.nbytes + 1, np.uint8)
        unaligned = raw[1:].view(a.dtype).reshape(a.shape)
        unaligned[...] = a
        out["unaligned"] = unaligned
    for k, v in out.items():
        assert np.array_equal(v, a, equal_nan=a.dtype.kind == "f"), k
    return out


# ---- values ------------------------------------------------------------------------

#: Python values of the wrong type for a number, an array, a path or an object.
WRONG_TYPES = [
    "3",
    b"3",
    None,
    [1.0, "a"],
    {"a": 1},
    object(),
    1j,
    float,
    np.array(["a", "b"]),
]

#: Integers beyond every range, and small bad ones.
BAD_INTS = [-1, 2**63, 2**64 + 1, 2**127, 2**200, -(2**200), 10**400]

#: Floats that are no valid setting for most arguments.
BAD_REALS = [float("nan"), float("inf"), -float("inf"), 1e308, -1e308, 5e-324, 10**400]

finite_floats = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
extreme_floats = st.sampled_from(
    [0.0, -0.0, 5e-324, 1e-310, 1e-30, 1e30, 1e300, -1e300, float("nan"), float("inf"),
     -float("inf"), 65535.0, 65.536, 3.4e38]
)  # fmt: skip
any_float = st.one_of(finite_floats, extreme_floats)
