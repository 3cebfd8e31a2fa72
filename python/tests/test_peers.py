"""embreex's and trimesh's answers on the tessellated field, and ours on
the displaced one: the same hits within the two surfaces' difference.

The height field is bilinear between texel centres (clamped past them);
its tessellation at 4x4 quads a cell, two triangles each, differs from it
by less than `delta` (measured). Rays that pass within a few `delta` of the
surface without hitting it (grazing) may fairly be hit by one surface and
missed by the other; every other ray must agree (>= 99.9%)."""

import numpy as np
import pytest

import displace

embreex = pytest.importorskip("embreex", reason="pip install embreex (the test extra)")
trimesh = pytest.importorskip("trimesh", reason="pip install trimesh (the test extra)")
from embreex import rtcore_scene  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402

W, H = 48, 40
EXTENT = (2.0, 1.6, 0.3)
SUB = 4


def heights(rng):
    """A smooth field of a few bumps in [0, 1]."""
    y, x = np.mgrid[0:H, 0:W]
    h = np.zeros((H, W))
    for _ in range(6):
        cx, cy, r = rng.uniform(0, W), rng.uniform(0, H), rng.uniform(3, 9)
        h += rng.uniform(0.2, 1.0) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * r * r))
    return (h / h.max() * 0.95).astype(np.float32)


def bilinear(h, u, v):
    """The clamped bilinear height at texture coordinates (u, v) in [0, 1]."""
    px = np.clip(u * W - 0.5, 0, W - 1)
    py = np.clip(v * H - 0.5, 0, H - 1)
    i0 = np.minimum(np.floor(px).astype(int), W - 2)
    j0 = np.minimum(np.floor(py).astype(int), H - 2)
    fx, fy = px - i0, py - j0
    a, b = h[j0, i0], h[j0, i0 + 1]
    c, d = h[j0 + 1, i0], h[j0 + 1, i0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def tessellate(h):
    """Vertices at the tile's edges and texel centres, each interval split
    SUB times; heights sampled from the bilinear field."""
    def axis(n):
        knots = np.concatenate([[0.0], (np.arange(n) + 0.5) / n, [1.0]])
        return np.concatenate(
            [np.linspace(knots[k], knots[k + 1], SUB, endpoint=False) for k in range(len(knots) - 1)] + [[1.0]]
        )
    us, vs = axis(W), axis(H)
    uu, vv = np.meshgrid(us, vs)
    z = bilinear(h.astype(np.float64), uu, vv) * EXTENT[2]
    verts = np.column_stack([uu.ravel() * EXTENT[0], vv.ravel() * EXTENT[1], z.ravel()])
    nu, nv = len(us), len(vs)
    idx = np.arange(nu * nv).reshape(nv, nu)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return verts, faces


def clearance(h, o, d, t_end, samples=600):
    """The least height of each ray above the bilinear surface on [0, t_end]
    (negative: the ray went under it)."""
    t = np.linspace(0, 1, samples)[None, :] * t_end[:, None]
    p = o[:, None, :] + t[..., None] * d[:, None, :]
    inside = (p[..., 0] >= 0) & (p[..., 0] <= EXTENT[0]) & (p[..., 1] >= 0) & (p[..., 1] <= EXTENT[1])
    z = bilinear(h.astype(np.float64), p[..., 0] / EXTENT[0], p[..., 1] / EXTENT[1]) * EXTENT[2]
    gap = np.where(inside, p[..., 2] - z, np.inf)
    return gap.min(axis=1)


@pytest.fixture
def field(rng):
    h = heights(rng)
    face = displace.bake(h, size=(W, H, 16), extent=EXTENT)
    verts, faces = tessellate(h)
    # The tessellation's largest departure from the bilinear surface.
    cu = (verts[faces].mean(axis=1)[:, 0] / EXTENT[0], verts[faces].mean(axis=1)[:, 1] / EXTENT[1])
    delta = np.abs(verts[faces].mean(axis=1)[:, 2] - bilinear(h.astype(np.float64), *cu) * EXTENT[2]).max()
    return h, face, verts, faces, max(delta, 1e-6)


def skimming_rays(rng, n):
    """Rays from above the shell, inside the tile, at shallow angles: many
    meet bumps, many pass over everything and leave the tile."""
    o = np.column_stack([rng.uniform(0.05, 0.95, n) * EXTENT[0], rng.uniform(0.05, 0.95, n) * EXTENT[1],
                         rng.uniform(1.01, 1.3, n) * EXTENT[2]])
    az = rng.uniform(0, 2 * np.pi, n)
    el = rng.uniform(np.radians(3), np.radians(50), n)
    d = np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), -np.sin(el)])
    return o.astype(np.float32), d.astype(np.float32)


def test_embreex_run_agrees_on_the_tessellated_field(field, rng):
    h, face, verts, faces, delta = field
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, verts.astype(np.float32), faces.astype(np.int32))
    o, d = skimming_rays(rng, 20000)
    theirs = scene.run(o, d, output=True)
    ours = face.run(o, d, output=True)
    hit_t, hit_o = theirs["primID"] >= 0, ours["primID"] >= 0
    assert 0.2 < hit_o.mean() < 0.9, "the rays must both hit and miss"
    # Rays that graze the surface (within 3 delta, hit or not) are not judged.
    t_end = np.where(hit_o, ours["tfar"], 10.0)
    gap = clearance(h, o.astype(np.float64), d.astype(np.float64), np.minimum(t_end, 10.0) * 0.999)
    fair = np.abs(gap) > 3 * delta
    assert fair.mean() > 0.8
    agree = (hit_t == hit_o)[fair].mean()
    assert agree >= 0.999, f"hit/miss agreement {agree:.5f} on {fair.sum()} rays (delta {delta:.2e})"
    both = hit_t & hit_o & fair
    # Distances agree within the surfaces' difference along the ray.
    sin_el = np.maximum(-d[both, 2], 0.05)
    assert np.all(np.abs(theirs["tfar"][both] - ours["tfar"][both]) <= 4 * delta / sin_el + 1e-4)
    # OCCLUDED and DISTANCE in embreex's conventions.
    occ_t = scene.run(o, d, query="OCCLUDED")
    occ_o = face.run(o, d, query="OCCLUDED")
    assert occ_o.dtype == np.int32 and set(np.unique(occ_o)) <= {0, -1}
    assert ((occ_t == 0) == (occ_o == 0))[fair].mean() >= 0.999
    dist = face.run(o, d, query="DISTANCE")
    np.testing.assert_array_equal(dist, ours["tfar"])
    assert np.all(dist[~hit_o] == np.float32(1e37))
    np.testing.assert_allclose(np.linalg.norm(ours["Ng"][hit_o], axis=1), 1, atol=1e-5)


def test_trimesh_queries_agree_on_the_tessellated_field(field, rng):
    h, face, verts, faces, delta = field
    mesh = trimesh.Trimesh(vertices=verts, faces=faces, process=False)
    o, d = skimming_rays(rng, 4000)
    first_t = mesh.ray.intersects_first(o, d)
    first_o = face.intersects_first(o, d)
    hit_t, hit_o = first_t >= 0, first_o >= 0
    any_o = face.intersects_any(o, d)
    np.testing.assert_array_equal(any_o, hit_o)
    t = face.intersect(o, d)["t"]
    gap = clearance(h, o.astype(np.float64), d.astype(np.float64), np.where(hit_o, t, 10.0) * 0.999)
    fair = np.abs(gap) > 3 * delta
    assert (hit_t == hit_o)[fair].mean() >= 0.999
    loc_t, ray_t, _ = mesh.ray.intersects_location(o, d, multiple_hits=False)
    loc_o, ray_o, cell_o = face.intersects_location(o, d)
    assert loc_o.dtype == np.float64 and ray_o.dtype == np.int64
    np.testing.assert_array_equal(np.sort(ray_o), np.flatnonzero(hit_o))
    np.testing.assert_array_equal(cell_o, first_o[ray_o])
    common = np.intersect1d(ray_t[fair[ray_t]], ray_o)
    theirs = {r: p for r, p in zip(ray_t, loc_t)}
    ours = {r: p for r, p in zip(ray_o, loc_o)}
    far = [r for r in common if np.linalg.norm(theirs[r] - ours[r]) > 4 * delta / max(-d[r, 2], 0.05) + 1e-4]
    assert not far, f"{len(far)} of {len(common)} locations differ; first ray {far[:1]}"
    ids, rays_ = face.intersects_id(o, d)
    np.testing.assert_array_equal(ids, cell_o)
    np.testing.assert_array_equal(rays_, ray_o)
