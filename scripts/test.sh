#!/usr/bin/env bash
# The whole test suite: installs depthpose with its test extra (builds the wheel), then
# runs the Rust tests and the Python tests. Tests that need ../shared/data skip without it.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
step() { echo "== $1 ($((SECONDS - start)) s)"; }
step "installing depthpose[test]"
python3 -m pip install --quiet --disable-pip-version-check ".[test]"
step "Rust tests"
cargo test --quiet
step "Python tests"
# From the project root pytest imports the installed wheel: python/ is not on sys.path.
python3 -m pytest -q tests "$@"
step "done"
