"""Every accepted dtype and layout gives the same answer; every bad input
raises the named exception with the CLI's message, never a crash."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import displace
from conftest import REPO, rays_from_above


@pytest.fixture(scope="module")
def face():
    return displace.bake("gen:studded", size=(64, 64, 8), extent=(1.0, 1.0, 0.1))


def test_every_dtype_and_layout_gives_the_same_hits(face, rng):
    o, d = rays_from_above(rng, 3000, (1.0, 1.0, 0.1))
    want = face.intersect(o, d)
    both = np.hstack([o, d])
    variants = {
        "float64": (o.astype(np.float64), d.astype(np.float64)),
        "fortran": (np.asfortranarray(o), np.asfortranarray(d)),
        "column slices of (N, 6)": (both[:, :3], both[:, 3:]),
        "lists": (o.tolist(), d.tolist()),
        "strided rows": (np.repeat(o, 2, axis=0)[::2], np.repeat(d, 2, axis=0)[::2]),
        "reversed twice": (o[::-1][::-1], d[::-1][::-1]),
        "float64 fortran": (np.asfortranarray(o, dtype=np.float64), np.asfortranarray(d, dtype=np.float64)),
    }
    for name, (vo, vd) in variants.items():
        got = face.intersect(vo, vd)
        np.testing.assert_array_equal(got["t"], want["t"], err_msg=name)
        np.testing.assert_array_equal(got["position"], want["position"], err_msg=name)
    # Reversed views trace the reversed rays.
    rev = face.intersect(o[::-1], d[::-1])
    np.testing.assert_array_equal(rev["t"], want["t"][::-1])
    # One direction for every ray (embreex's broadcast).
    one = face.intersect(o, d[:1])
    np.testing.assert_array_equal(one["t"], face.intersect(o, np.repeat(d[:1], len(o), 0))["t"])
    # t_max: a number, float32 and float64 arrays alike.
    t32 = np.full(len(o), 0.9, np.float32)
    a = face.occluded(o, d, 0.9)
    np.testing.assert_array_equal(a, face.occluded(o, d, t32))
    np.testing.assert_array_equal(a, face.occluded(o, d, t32.astype(np.float64)))
    np.testing.assert_array_equal(a, want["t"] <= 0.9)


def test_threads_do_not_change_answers(face, rng):
    o, d = rays_from_above(rng, 100_000, (1.0, 1.0, 0.1))
    one = face.intersect(o, d, threads=1)
    two = face.intersect(o, d, threads=2)
    np.testing.assert_array_equal(one["t"], two["t"])
    np.testing.assert_array_equal(face.occluded(o, d, threads=1), face.occluded(o, d, threads=3))


def _copy(hits):
    return {k: np.array(v, copy=True) for k, v in hits.items()}


def _assert_same(hits, want):
    assert hits.keys() == want.keys()
    for k in want:
        np.testing.assert_array_equal(hits[k], want[k], err_msg=k)


@pytest.mark.parametrize("target", ["face", "scene"])
def test_results_outlive_later_queries_and_freed_buffers_are_rewritten(face, rng, target):
    """Queries write into the buffers of results numpy has freed: a result
    still held (or a view of it) is never written, and a query into a freed
    buffer writes every row, misses included."""
    q = face if target == "face" else displace.Scene()
    extent = (1.0, 1.0, 0.1) if target == "face" else (2.0, 2.0, 2.0)
    n = 20000 if target == "face" else 3000
    o1, d1 = rays_from_above(rng, n, extent, spread=1.2)
    o2, d2 = rays_from_above(rng, n, extent, spread=0.3)
    if target == "scene":
        o1 -= 1.0
        o2 -= 1.0
    h1 = q.intersect(o1, d1)
    want1 = _copy(h1)
    h2 = q.intersect(o2, d2)
    want2 = _copy(h2)
    # Rows that miss in one and hit in the other: a stale row would show.
    assert (~np.isfinite(want1["t"]) & np.isfinite(want2["t"])).sum() > 100
    _assert_same(h1, want1)
    del h2
    h3 = q.intersect(o1, d1)  # may be written into h2's buffers
    _assert_same(h3, want1)
    _assert_same(h1, want1)
    view = h3["position"][::3]
    kept = view.copy()
    del h3
    for _ in range(3):
        h4 = q.intersect(o2[: n // 2], d2[: n // 2])
        del h4
    np.testing.assert_array_equal(view, kept)
    del h1
    h5 = q.intersect(o2, d2)
    _assert_same(h5, want2)


def test_height_arrays_of_every_dtype_are_the_files_heights(tmp_path, rng):
    """A uint16 array and the 16-bit PNG of the same codes give one map; so
    do uint8 and float arrays of the same heights."""
    from PIL import Image

    codes = rng.integers(0, 65536, (24, 32)).astype(np.uint16)
    Image.fromarray(codes).save(tmp_path / "h.png")
    from_file = displace.bake(tmp_path / "h.png", size=(32, 24, 8))
    from_array = displace.bake(codes, size=(32, 24, 8))
    np.testing.assert_array_equal(from_file.heights, from_array.heights)
    np.testing.assert_array_equal(from_array.heights, (codes / 65535).astype(np.float32))
    b = rng.integers(0, 256, (24, 32)).astype(np.uint8)
    np.testing.assert_array_equal(displace.bake(b, size=(32, 24, 8)).heights, (b.astype(np.float32) / 255))
    f = rng.uniform(0, 1, (24, 32))
    np.testing.assert_array_equal(displace.bake(f, size=(32, 24, 8)).heights, f.astype(np.float32))
    np.testing.assert_array_equal(
        displace.bake(np.asfortranarray(f), size=(32, 24, 8)).heights, f.astype(np.float32)
    )
    metres = f * 1000 + 200
    ranged = displace.bake(metres, size=(32, 24, 8), height_range="auto")
    np.testing.assert_allclose(ranged.heights, (metres - metres.min()) / np.ptp(metres), atol=1e-6)
    spanned = displace.bake(metres, size=(32, 24, 8), height_range=(0, 2000))
    np.testing.assert_allclose(spanned.heights, metres / 2000, atol=1e-6)


BAD_CALLS = [
    ("origins shape", lambda f, o, d: f.intersect(o[:, :2], d), ValueError, "expected (N, 3)"),
    ("origins 1-D", lambda f, o, d: f.intersect(o[0], d), ValueError, "expected (N, 3)"),
    ("integer dtype", lambda f, o, d: f.intersect(o.astype(np.int64), d), ValueError, "dtype int64"),
    ("complex dtype", lambda f, o, d: f.occluded(o, d.astype(np.complex64)), ValueError, "dtype complex64"),
    ("row counts", lambda f, o, d: f.intersect(o, d[:5]), ValueError, "5 rows for"),
    ("NaN origin", lambda f, o, d: f.intersect(np.where(np.arange(len(o))[:, None] == 7, np.nan, o), d),
     ValueError, "ray 7 has NaN in column 0"),
    ("inf direction", lambda f, o, d: f.occluded(o, np.where(np.arange(len(d))[:, None] == 3, np.inf, d)),
     ValueError, "ray 3 has inf in column 3"),
    ("zero direction", lambda f, o, d: f.intersect(o, np.zeros_like(d)), ValueError, "no length"),
    ("huge origin", lambda f, o, d: f.intersect(o * 1e30, d), ValueError, "at most 1e18"),
    ("float64 overflow", lambda f, o, d: f.intersect(o.astype(np.float64) * 1e300, d), ValueError, "ray 0"),
    ("negative t_max", lambda f, o, d: f.occluded(o, d, -1.0), ValueError, "t_max -1"),
    ("NaN t_max", lambda f, o, d: f.occluded(o, d, np.full(len(o), np.nan)), ValueError, "t_max NaN"),
    ("t_max shape", lambda f, o, d: f.occluded(o, d, np.ones(3)), ValueError, "one per ray"),
    ("query", lambda f, o, d: f.run(o, d, query="NEAREST"), ValueError, "INTERSECT, OCCLUDED or DISTANCE"),
    ("threads 0", lambda f, o, d: f.intersect(o, d, threads=0), ValueError, "threads=0"),
    ("threads negative", lambda f, o, d: f.intersect(o, d, threads=-1), OverflowError, ""),
]


@pytest.mark.parametrize("name,call,exc,message", BAD_CALLS, ids=[b[0] for b in BAD_CALLS])
def test_bad_rays_raise(face, rng, name, call, exc, message):
    o, d = rays_from_above(rng, 50, (1.0, 1.0, 0.1))
    with pytest.raises(exc) as e:
        call(face, o, d)
    assert message in str(e.value), str(e.value)


DEFAULT = (REPO / "crates" / "displace-scene" / "src" / "default_scene.toml").read_text()

BAD_BAKES = [
    ("heights above 1", lambda: displace.bake(np.full((8, 8), 2.0), size=(8, 8, 4)), ValueError, "[0, 1]"),
    ("NaN height", lambda: displace.bake(np.where(np.eye(8) > 0, np.nan, 0.5), size=(8, 8, 4)), ValueError,
     "texel (0, 0) is NaN"),
    ("3-D heights", lambda: displace.bake(np.zeros((4, 4, 3)), size=(8, 8, 4)), ValueError, "2-D"),
    ("1x1 heights", lambda: displace.bake(np.zeros((1, 1)), size=(8, 8, 4)), ValueError, "2x2"),
    ("int32 heights", lambda: displace.bake(np.zeros((8, 8), np.int32), size=(8, 8, 4)), ValueError,
     "dtype int32"),
    ("zero size", lambda: displace.bake("gen:flat", size=(0, 8, 4)), ValueError, ""),
    ("negative extent", lambda: displace.bake("gen:flat", size=(8, 8, 4), extent=(1, -1, 0.1)), ValueError,
     "extent"),
    ("NaN extent", lambda: displace.bake("gen:flat", size=(8, 8, 4), extent=(1, 1, float("nan"))), ValueError,
     "extent"),
    ("bad range", lambda: displace.bake(np.zeros((8, 8)), size=(8, 8, 4), height_range=(1, 0)), ValueError,
     "height range"),
    ("range excludes", lambda: displace.bake(np.full((8, 8), 5.0), size=(8, 8, 4), height_range=(0, 1)),
     ValueError, "outside the height range"),
    ("method", lambda: displace.bake("gen:flat", size=(8, 8, 4), method="newton"), ValueError, "newton"),
    ("address", lambda: displace.bake("gen:flat", size=(8, 8, 4), address="mirror"), ValueError, "mirror"),
    ("generator", lambda: displace.bake("gen:volcano", size=(8, 8, 4)), ValueError, "volcano"),
    ("missing file", lambda: displace.bake("/nonexistent/h.png", size=(8, 8, 4)), FileNotFoundError,
     "/nonexistent/h.png"),
    ("missing map", lambda: displace.load("/nonexistent/m.ktx2", "gen:flat"), FileNotFoundError, "m.ktx2"),
    ("map extension", lambda: displace.load("/tmp/m.png", "gen:flat"), ValueError, "m.png"),
    ("missing scene", lambda: displace.Scene("/nonexistent/s.toml"), FileNotFoundError, "s.toml"),
    ("scene text", lambda: displace.Scene(DEFAULT.replace("width = 384", "width = -3")), ValueError,
     "<toml>:9:"),
    ("scene key", lambda: displace.Scene(DEFAULT.replace("width = 384", "widht = 384")), ValueError, "widht"),
]


@pytest.mark.parametrize("name,call,exc,message", BAD_BAKES, ids=[b[0] for b in BAD_BAKES])
def test_bad_bakes_and_files_raise(name, call, exc, message):
    with pytest.raises(exc) as e:
        call()
    assert message in str(e.value), str(e.value)


def test_bad_renders_raise():
    scene = displace.Scene(REPO / "scenes" / "cornell_studded.toml", cache=False)
    with pytest.raises(ValueError, match="spp 0"):
        scene.render(spp=0, size=(8, 8))
    with pytest.raises(ValueError, match="size"):
        scene.render(size=(0, 8))
    with pytest.raises(ValueError, match="integrator"):
        scene.render(integrator="photon", size=(8, 8))
    with pytest.raises(ValueError, match="AOV"):
        scene.render(size=(8, 8), aovs=["albedo"])


def test_a_bake_over_the_memory_limit_is_refused_before_allocating():
    """MemoryError from the estimate, in a child process so that the limit
    set there cannot leak into other tests; the child's peak memory shows
    nothing was allocated."""
    code = (
        "import resource, displace\n"
        "try:\n"
        "    displace.bake('gen:flat', size=(1024, 1024, 64))\n"
        "except MemoryError as e:\n"
        "    print('MemoryError', e)\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    env = dict(os.environ, DISPLACE_MEMORY_LIMIT="256M")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines[0].startswith("MemoryError") and "needs about" in lines[0], out.stdout
    assert int(lines[-1]) < 500_000, f"peak {lines[-1]} KiB: something was allocated"


def test_saving_refuses_bad_paths(face, tmp_path):
    with pytest.raises(ValueError, match="png"):
        face.save(tmp_path / "m.png")
    with pytest.raises(ValueError, match="npy"):
        face.save(tmp_path / "m.npy", format="r8")
    with pytest.raises((FileNotFoundError, OSError)):
        face.save(tmp_path / "missing-dir" / "m.ktx2")
    assert not list(tmp_path.glob("**/*.ktx2*"))
