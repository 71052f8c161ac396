"""The documentation site builds (mkdocs, strict) and documents every public name."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import depthpose as dp
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_and_documents_every_public_name(tmp_path: Path) -> None:
    pytest.importorskip("mkdocstrings")
    if not (ROOT / "mkdocs.yml").exists():
        pytest.skip("mkdocs.yml is not here (tests run from an installed wheel)")
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", str(site)],
        cwd=ROOT,
        check=True,
    )
    documented: set[str] = set()
    for page in (site / "api").glob("*/index.html"):
        documented |= set(re.findall(r'id="depthpose\.([A-Za-z_0-9]+)"', page.read_text()))
    missing = [n for n in dp.__all__ if n not in documented and n != "__version__"]
    assert not missing, f"public names without a documented entry: {missing}"
