"""Shared fixtures: the CLI binary the bindings are checked against, and
rays drawn from fixed seeds (CI is deterministic; DISPLACE_PY_SEED explores)."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def _find_cli():
    env = os.environ.get("DISPLACE_BIN")
    if env:
        return pathlib.Path(env)
    for profile in ("debug", "release"):
        p = REPO / "target" / profile / "displace"
        if p.exists():
            return p
    return None


@pytest.fixture(scope="session")
def cli():
    """Runs the `displace` binary; fails (never skips) when it is missing:
    the README's test command builds it before pytest runs."""
    exe = _find_cli()
    assert exe is not None and exe.exists(), (
        "no displace binary: build it (cargo build --bin displace) or set DISPLACE_BIN"
    )

    def run(*args):
        out = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
        assert out.returncode == 0, f"displace {' '.join(map(str, args))}:\n{out.stderr}"
        return out.stdout

    return run


@pytest.fixture
def rng():
    """A fixed seed in CI; DISPLACE_PY_SEED=N draws other cases."""
    return np.random.default_rng(int(os.environ.get("DISPLACE_PY_SEED", "20261205")))


def rays_from_above(rng, n, extent, spread=0.6, height=1.5):
    """`n` rays starting above a tile of `extent`, pointing down within
    `spread` of vertical (some leave the tile and miss)."""
    sx, sy, sz = extent
    o = np.column_stack(
        [rng.uniform(0, sx, n), rng.uniform(0, sy, n), np.full(n, height * sz)]
    )
    d = np.column_stack(
        [rng.uniform(-spread, spread, n) * sx, rng.uniform(-spread, spread, n) * sy, -np.full(n, sz)]
    )
    return o.astype(np.float32), d.astype(np.float32)
