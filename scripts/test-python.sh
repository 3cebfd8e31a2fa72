#!/usr/bin/env bash
# The Python package's tests, as scripts/test.sh runs them after the Rust
# tests: a virtual environment under target/, the package built and
# installed from ./python by pip (maturin, as the README's install command
# does it, here with the dev profile so that the build reuses what `cargo
# test` compiled), then pytest over python/tests (the examples included).
# The tests compare against the `displace` binary `cargo test` built.
set -euo pipefail
cd "$(dirname "$0")/.."
venv="${DISPLACE_PY_VENV:-target/pyenv}"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
venv="$(cd "$venv" && pwd)"
"$venv/bin/pip" install -q --disable-pip-version-check -r python/requirements-test.txt
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
MATURIN_PEP517_ARGS="${MATURIN_PEP517_ARGS:---profile dev}" \
  "$venv/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps ./python
if [ -z "${DISPLACE_BIN:-}" ]; then
  cargo build -q --bin displace
  export DISPLACE_BIN="$CARGO_TARGET_DIR/debug/displace"
fi
# From the repository's root: in python/ the source folder `displace`
# would shadow the installed package.
exec "$venv/bin/python" -m pytest -q -p no:cacheprovider python/tests "$@"
