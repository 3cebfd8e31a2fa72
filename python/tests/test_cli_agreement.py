"""The bindings answer exactly what the command line answers: the same
function runs behind both, so hits are equal bit for bit."""

import numpy as np
import pytest

import displace
from conftest import REPO, rays_from_above


def write_rays(path, o, d, t_max=None):
    cols = [o, d] if t_max is None else [o, d, t_max[:, None]]
    np.save(path, np.hstack(cols).astype(np.float32))


@pytest.mark.parametrize("height", ["gen:studded", "gen:gaussian", "gen:noise"])
def test_face_hits_equal_displace_trace(cli, tmp_path, rng, height):
    extent = (1.0, 1.0, 0.1)
    o, d = rays_from_above(rng, 5000, extent)
    write_rays(tmp_path / "rays.npy", o, d)
    cli("trace", "--height", height, "--extent", "1,1,0.1", "--size", "64x64x8",
        "--rays", tmp_path / "rays.npy", "-o", tmp_path / "hits.npy")
    want = np.load(tmp_path / "hits.npy")
    face = displace.bake(height, size=(64, 64, 8), extent=extent)
    got = face.intersect(o, d)
    assert np.isfinite(want[:, 0]).sum() > 1000, "the rays must hit"
    assert (~np.isfinite(want[:, 0])).sum() > 100, "and some must miss"
    np.testing.assert_array_equal(got["t"], want[:, 0])
    np.testing.assert_array_equal(got["position"], want[:, 1:4])
    np.testing.assert_array_equal(got["iterations"], want[:, 4].astype(np.uint32))
    # Hits lie on the tile and their normals are unit.
    hit = np.isfinite(got["t"])
    assert np.all(got["cell"][hit] >= 0) and np.all(got["cell"][~hit] == -1)
    np.testing.assert_allclose(np.linalg.norm(got["normal"][hit], axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(o[hit] + got["t"][hit, None] * d[hit], got["position"][hit], atol=2e-5)


def test_saved_map_traces_as_the_cli_reads_it(cli, tmp_path, rng):
    """A map saved from Python is the CLI's bake, byte for byte, and the CLI
    traces it (`--map`) as Python does."""
    extent = (2.0, 1.0, 0.25)
    face = displace.bake("gen:studded", size=(64, 32, 8), extent=extent)
    for name in ("m.ktx2", "m.dds", "m.npy"):
        face.save(tmp_path / name)
        cli("bake", "gen:studded", "--size", "64x32x8", "--extent", "2,1,0.25", "-o", tmp_path / f"cli_{name}")
        assert (tmp_path / name).read_bytes() == (tmp_path / f"cli_{name}").read_bytes(), name
    o, d = rays_from_above(rng, 3000, extent)
    write_rays(tmp_path / "rays.npy", o, d)
    cli("trace", "--height", "gen:studded", "--extent", "2,1,0.25", "--map", tmp_path / "m.ktx2",
        "--rays", tmp_path / "rays.npy", "-o", tmp_path / "hits.npy")
    want = np.load(tmp_path / "hits.npy")
    loaded = displace.load(tmp_path / "m.ktx2", "gen:studded")
    assert loaded.extent == face.extent and loaded.size == face.size
    np.testing.assert_array_equal(loaded.intersect(o, d)["t"], want[:, 0])
    # .npy and .dds need the extent they were baked with.
    with pytest.raises(ValueError, match="extent"):
        displace.load(tmp_path / "m.npy", "gen:studded")
    npy = displace.load(tmp_path / "m.npy", "gen:studded", extent)
    np.testing.assert_array_equal(npy.intersect(o, d)["t"], face.intersect(o, d)["t"])


SCENES = ["cornell_studded.toml", "cornell_gaussian.toml", "gpu_meshes.toml", "stone.toml"]


@pytest.mark.parametrize("name", SCENES)
def test_scene_hits_equal_trace_scene(cli, tmp_path, rng, name):
    path = REPO / "scenes" / name
    scene = displace.Scene(path, cache=False)
    # Rays from around the scene towards its middle, some bounded.
    n = 4000
    o = rng.normal(0, 1, (n, 3)).astype(np.float32)
    o /= np.linalg.norm(o, axis=1, keepdims=True)
    o *= 3.0
    target = rng.uniform(-0.8, 0.8, (n, 3)).astype(np.float32)
    d = (target - o).astype(np.float32)
    t_max = rng.uniform(0.2, 2.0, n).astype(np.float32)
    write_rays(tmp_path / "rays.npy", o, d, t_max)
    cli("trace", "--scene", path, "--no-cache", "--rays", tmp_path / "rays.npy", "-o", tmp_path / "hits.npy")
    cli("trace", "--scene", path, "--no-cache", "--any-hit", "--rays", tmp_path / "rays.npy",
        "-o", tmp_path / "blocked.npy")
    want = np.load(tmp_path / "hits.npy")
    got = scene.intersect(o, d, t_max)
    assert np.isfinite(want[:, 0]).sum() > 100
    np.testing.assert_array_equal(got["t"], want[:, 0])
    np.testing.assert_array_equal(got["position"], want[:, 1:4])
    np.testing.assert_array_equal(got["normal"], want[:, 4:7])
    np.testing.assert_array_equal(got["shape"], want[:, 7].astype(np.int64))
    blocked = np.load(tmp_path / "blocked.npy")[:, 0] > 0
    np.testing.assert_array_equal(scene.occluded(o, d, t_max), blocked)
    # A ray blocked within t_max has a first hit within t_max.
    np.testing.assert_array_equal(blocked, got["t"] <= t_max)


def test_render_equals_displace_render(cli, tmp_path):
    """The colour image is the CLI's (written as .npy: linear, unclamped)."""
    path = REPO / "scenes" / "cornell_studded.toml"
    cli("render", path, "--spp", "2", "--size", "48x40", "--no-cache", "-o", tmp_path / "img.exr")
    scene = displace.Scene(path, cache=False)
    img = scene.render(spp=2, size=(48, 40))
    assert img.shape == (40, 48, 3) and img.dtype == np.float32
    assert np.all(np.isfinite(img)) and img.mean() > 0.01
    # The CLI's PNG is the same linear image, clamped and sRGB-encoded.
    from PIL import Image

    cli("render", path, "--spp", "2", "--size", "48x40", "--no-cache", "-o", tmp_path / "img8.png")
    png = np.asarray(Image.open(tmp_path / "img8.png").convert("RGB")).astype(np.int32)
    c = np.clip(img, 0, 1)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    ours = np.round(srgb * 255).astype(np.int32)
    assert np.abs(ours - png).max() <= 1, "the colour image differs from the CLI's"
    assert (ours == png).mean() > 0.99

    cli("render", path, "--spp", "2", "--size", "48x40", "--no-cache", "--aov", "depth",
        "-o", tmp_path / "img.png")
    aov = scene.render(spp=2, size=(48, 40), aovs=["depth"])
    depth = np.load(tmp_path / "img.depth.npy")
    np.testing.assert_array_equal(aov["depth"], depth.reshape(aov["depth"].shape))
    np.testing.assert_array_equal(aov["color"], img)
