"""Progress bars on stderr (tqdm), drawn only when stderr is a terminal."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["progress_bar"]


def progress_bar(total: int, desc: str, *, enabled: bool = True, unit: str = "frame") -> Any:
    """A ``tqdm`` bar over ``total`` items on stderr; a no-op bar when ``enabled`` is
    false or stderr is not a terminal (a log file or a pipe gets no bar)."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=None if enabled else True,  # None: disabled when stderr is not a TTY
        dynamic_ncols=True,
        leave=True,
    )
