from __future__ import annotations

from pathlib import Path

import pytest

#: The shared reference data, beside the project (as in CI).
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with the reason."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared reference data not found at {p}")
    return p
