#!/usr/bin/env bash
# The whole test suite: installs depthpose with its test extra (builds the wheel), then
# runs the Rust tests and the Python tests. Tests that need ../shared/data skip without it.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --disable-pip-version-check ".[test]"
cargo test --quiet
# Run from tests/ so that `import depthpose` is the installed wheel, not the source tree.
python3 -m pytest -q tests "$@"
