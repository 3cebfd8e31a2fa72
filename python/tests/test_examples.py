"""The examples run end to end, at small sizes, and say what they claim:
the viewshed agrees with a brute-force line of sight, the lidar returns lie
on the surface, the switch from embreex finds the same hits."""

import contextlib
import importlib.util
import io
import os

from conftest import REPO


def run_example(name, argv):
    spec = importlib.util.spec_from_file_location(name, REPO / "python" / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    with contextlib.redirect_stdout(io.StringIO()):
        return module.main(argv)


def test_viewshed(tmp_path):
    r = run_example("viewshed", ["--out", str(tmp_path), "--size", "256", "--texel", "60"])
    assert os.path.getsize(r["png"]) > 10_000 and os.path.exists(r["tiff"])
    assert r["read_error_m"] < 1e-3
    assert 0.01 < r["visible_fraction"] < 0.99
    assert r["agreement"] >= 0.98


def test_lidar(tmp_path):
    r = run_example("lidar", ["--out", str(tmp_path), "--size", "256", "--azimuths", "256"])
    assert r["returns"] > 0.5 * r["rays"]
    assert r["position_error"] < 1e-4
    with open(r["ply"], "rb") as f:
        assert f.readline().strip() == b"ply"


def test_from_embreex():
    r = run_example("from_embreex", ["--size", "128", "--rays", "20000"])
    assert r["agreement"] >= 0.999
