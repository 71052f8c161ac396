"""Depth sequences on disk: a .npz in the shared layout, a folder of depth frames, or a
single depth image. Used by ``depthpose estimate`` and ``depthpose batch``.

:func:`open_sequence` and :class:`Sequence` are native (documented in
``depthpose/_core.pyi``); :func:`expand_inputs` turns the command line's inputs and
glob patterns into paths.
"""

from __future__ import annotations

import glob
from pathlib import Path

from ._core import FileFormatError, Sequence, open_sequence

__all__ = ["Sequence", "open_sequence", "expand_inputs"]


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
