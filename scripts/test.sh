#!/usr/bin/env bash
# The whole test suite: installs depthpose with its test extra (builds the wheel), then
# runs the Rust tests and the Python tests. Tests that need ../shared/data skip without it.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
step() { echo "== $1 ($((SECONDS - start)) s)"; }
# In CI the property tests draw from a fixed seed, so a run is reproducible (Hypothesis
# derandomises under CI by itself); locally they draw fresh cases every run.
if [ "${CI:-}" = true ]; then
    export PROPTEST_RNG_SEED="${PROPTEST_RNG_SEED:-20261203}"
fi
step "installing depthpose[test]"
python3 -m pip install --quiet --disable-pip-version-check ".[test]"
step "Rust tests"
cargo test --quiet
# Again without the AVX-512 kernels (the AVX2 stream), and without any stream (the
# lockstep root-finder), so the paths other CPUs take are tested here too: the body
# model's and the fit's tests.
step "Rust tests without AVX-512 (DEPTHPOSE_NO_AVX512), then without the stream"
DEPTHPOSE_NO_AVX512=1 cargo test --quiet --lib -- body:: fit::
DEPTHPOSE_NO_AVX512=1 DEPTHPOSE_NO_STREAM=1 cargo test --quiet --lib -- body:: fit::
step "Python tests"
# From the project root pytest imports the installed wheel: python/ is not on sys.path.
python3 -m pytest -q tests "$@"
step "done"
