#!/usr/bin/env bash
# The whole test suite, as the README gives it and CI runs it: system
# packages, formatting, lints, then every test of the workspace (GPU tests on
# lavapipe when no GPU is present; they fail, never skip, when no adapter is
# found under CI), the check that the CLI and the Python extension build
# the tracer identically (scripts/check_same_core.py), and the Python
# package's tests (scripts/test-python.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
  XDG_RUNTIME_DIR="$(mktemp -d)"
  chmod 700 "$XDG_RUNTIME_DIR"
  export XDG_RUNTIME_DIR
fi
cargo fmt --all --check
cargo clippy --workspace --all-targets -- -D warnings
# The CLI and the Python extension link one build of the tracer.
python3 scripts/check_same_core.py
cargo test --workspace
bash scripts/test-python.sh
