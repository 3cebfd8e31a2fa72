#!/usr/bin/env python3
"""Switching from embreex on a tessellated height field to displace.

The usual way to cast rays at a height field from Python is to tessellate
it (one vertex per texel centre, two triangles per cell) and hand the mesh
to Embree through embreex. displace traces the bilinear height field itself
from a baked distance map, and its ``DistanceMap.run`` takes and returns
what ``EmbreeScene.run`` does, so the switch is one line:

    # before: tessellate, build a BVH, trace
    scene = embreex.rtcore_scene.EmbreeScene()
    embreex.mesh_construction.TriangleMesh(scene, vertices, indices)
    out = scene.run(origins, dirs, output=True)

    # after: bake, trace
    face = displace.bake(heights, size=(512, 512, 16), extent=(SX, SY, SZ))
    out = face.run(origins, dirs, output=True)          # <- the one-line change

``out`` has the same keys either way (u, v, Ng, tfar, primID, geomID): tfar
is the hit's ray parameter (1e37 on a miss), geomID 0 on a hit and -1 on a
miss. What differs: primID is the height-map cell (j * W + i) instead of the
triangle's index, u/v the texture coordinate instead of barycentrics.

This script builds a 512 x 512 terrain in [0, 1], tessellates it, traces
the same rays both ways and prints side by side: set-up time (tessellation
and BVH build against the bake), memory, rays per second, how often the two
agree on hit or miss, and the median |t difference|.

Run it from the repository's root:

    target/pyenv/bin/python python/examples/from_embreex.py
    target/pyenv/bin/python python/examples/from_embreex.py --size 2048 --rays 2000000

``main(argv)`` returns the numbers as a dict.

Note on the tile's edge: vertices at texel centres cover only x in
[0.5, W - 0.5] / W * SX (and so for y); displace's bilinear surface is
clamped beyond the centres out to the tile's edge. The rays here stay over
the centres' square so that both surfaces are the same shape.
"""

import argparse
import os
import time

import numpy as np

import displace
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss():
    """Resident bytes of this process now (/proc/self/statm)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


def terrain(n, seed=11):
    """An (n, n) float32 smooth-ish terrain in [0, 1]: a fractal sum of
    band-limited noise (FFT-filtered), gain 0.5 an octave."""
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n) * n
    kr = np.hypot(k[:, None], k[None, :])
    z = np.zeros((n, n))
    for octave in range(6):
        f = 2.0 * 2**octave
        band = np.exp(-0.5 * ((kr - f) / (0.5 * f)) ** 2)
        layer = np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * band).real
        z += 0.5**octave * layer / layer.std()
    z = (z - z.min()) / (z.max() - z.min())
    return z.astype(np.float32)


def tessellate(heights, extent):
    """The standard tessellation: a vertex at each texel centre, (i + 0.5) /
    W * SX, (j + 0.5) / H * SY, h * SZ; two triangles per cell of four
    adjacent centres. float32 vertices (V, 3), int32 indices (T, 3)."""
    rows, cols = heights.shape
    sx, sy, sz = extent
    x = (np.arange(cols) + 0.5) / cols * sx
    y = (np.arange(rows) + 0.5) / rows * sy
    xx, yy = np.meshgrid(x, y)
    vertices = np.column_stack([xx.ravel(), yy.ravel(), heights.ravel() * sz]).astype(np.float32)
    idx = np.arange(rows * cols, dtype=np.int32).reshape(rows, cols)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    indices = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3),
                              np.stack([a, d, c], -1).reshape(-1, 3)])
    return vertices, np.ascontiguousarray(indices)


def rays(n, extent, size, max_angle=60.0, seed=5, up_fraction=0.1):
    """`n` float32 rays from above the tile (z = 1.5 SZ), within `max_angle`
    degrees of straight down, each aimed at a point of z = 0 over the texel
    centres' square so that the whole ray stays over it; `up_fraction` of
    them point up instead and miss both surfaces."""
    rng = np.random.default_rng(seed)
    sx, sy, sz = extent
    cols, rows = size
    lo = np.array([0.5 / cols * sx, 0.5 / rows * sy])
    hi = np.array([(cols - 0.5) / cols * sx, (rows - 0.5) / rows * sy])
    start = rng.uniform(lo, hi, (n, 2))
    # Uniform over the cone's solid angle; the end clamped into the square
    # (which only steepens the ray).
    cos_t = rng.uniform(np.cos(np.radians(max_angle)), 1.0, n)
    tan_t = np.sqrt(1 - cos_t**2) / cos_t
    phi = rng.uniform(0, 2 * np.pi, n)
    run = 1.5 * sz * tan_t
    end = np.clip(start + run[:, None] * np.column_stack([np.cos(phi), np.sin(phi)]), lo, hi)
    o = np.column_stack([start, np.full(n, 1.5 * sz)])
    d = np.column_stack([end - start, np.full(n, -1.5 * sz)])
    up = rng.random(n) < up_fraction
    d[up, 2] *= -1
    return o.astype(np.float32), d.astype(np.float32)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=512, help="texels a side (default 512)")
    p.add_argument("--depth", type=int, default=16, help="distance-map voxels in z (default 16)")
    p.add_argument("--extent", default="100,100,8", help="SX,SY,SZ (default 100,100,8)")
    p.add_argument("--rays", type=int, default=200_000, help="rays (default 200000)")
    p.add_argument("--max-angle", type=float, default=60.0,
                   help="largest angle of a ray from straight down, degrees (default 60)")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    n = args.size
    extent = tuple(float(v) for v in args.extent.split(","))
    heights = terrain(n)
    origins, dirs = rays(args.rays, extent, (n, n), args.max_angle)
    print(f"height field {n}x{n} in [0, 1] over {extent}; {len(origins)} rays from above")

    # ---- before: embreex on the tessellated field -------------------------
    base = rss()
    t0 = time.perf_counter()
    vertices, indices = tessellate(heights, extent)
    t1 = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices, indices)
    scene.run(origins[:1], dirs[:1])  # the first run commits: the BVH is built here
    t2 = time.perf_counter()
    emb_setup = t2 - t0
    emb_rss = rss() - base
    mesh_bytes = vertices.nbytes + indices.nbytes

    t0 = time.perf_counter()
    emb = scene.run(origins, dirs, output=True)
    emb_s = time.perf_counter() - t0

    # ---- after: displace on the height field itself -----------------------
    base = rss()
    t0 = time.perf_counter()
    face = displace.bake(heights, size=(n, n, args.depth), extent=extent)
    dis_setup = time.perf_counter() - t0
    dis_rss = rss() - base

    t0 = time.perf_counter()
    dis = face.run(origins, dirs, output=True)  # <- was: scene.run(origins, dirs, output=True)
    dis_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    face.run(origins, dirs, output=True, threads=1)
    dis1_s = time.perf_counter() - t0

    # ---- the same answers? -------------------------------------------------
    emb_hit = emb["geomID"] != -1
    dis_hit = dis["geomID"] != -1
    agree = float((emb_hit == dis_hit).mean())
    both = emb_hit & dis_hit
    dt = np.abs(emb["tfar"][both].astype(np.float64) - dis["tfar"][both])
    # |t| is in units of the direction; the directions are about 1.5 SZ long
    # vertically, so convert to the units of the extent along the ray.
    dlen = np.linalg.norm(dirs[both].astype(np.float64), axis=1)
    dd = dt * dlen
    # The two surfaces differ by at most `twist` (the bilinear patch's twist
    # against its two triangles); along a ray meeting the surface at a
    # glancing angle that becomes twist / cos(incidence).
    h = heights.astype(np.float64)
    twist = np.abs(h[:-1, :-1] + h[1:, 1:] - h[:-1, 1:] - h[1:, :-1]).max() / 4 * extent[2]
    cos_in = np.abs(np.einsum("ij,ij->i", dis["Ng"][both], dirs[both])) / dlen
    within = float((dd <= twist / np.maximum(cos_in, 0.02) + 1e-5 * extent[2]).mean())

    mib = 2.0**20
    print()
    print(f"{'':28s}{'embreex (tessellated)':>24s}{'displace':>16s}")
    print(f"{'set-up (s)':28s}{emb_setup:24.3f}{dis_setup:16.3f}   "
          "(tessellation + BVH build on the first run | bake)")
    print(f"{'arrays held (MiB)':28s}{mesh_bytes / mib:24.1f}{face.nbytes / mib:16.1f}   "
          "(vertices + indices | face.nbytes)")
    print(f"{'resident growth (MiB)':28s}{emb_rss / mib:24.1f}{dis_rss / mib:16.1f}   "
          "(/proc/self/statm across the set-up)")
    n_rays = len(origins)
    print(f"{'rays/s, 1 thread (M)':28s}{n_rays / emb_s / 1e6:24.2f}{n_rays / dis1_s / 1e6:16.2f}")
    print(f"{'rays/s, all cores (M)':28s}{'(single-threaded)':>24s}{len(origins) / dis_s / 1e6:16.2f}"
          f"   ({os.cpu_count()} cores)")
    print(f"{'hits':28s}{int(emb_hit.sum()):24d}{int(dis_hit.sum()):16d}")
    print()
    print(f"hit/miss agreement: {agree:.5f}; on the {int(both.sum())} rays both hit, "
          f"median |t difference| = {np.median(dt):.3g} (ray units), "
          f"{np.median(dd):.3g} along the ray (extent units); {within:.4f} of them within the "
          f"surfaces' largest difference ({twist:.3g}) over the cosine of incidence")

    return {
        "size": n,
        "rays": int(len(origins)),
        "embreex_setup_s": emb_setup,
        "displace_setup_s": dis_setup,
        "mesh_bytes": int(mesh_bytes),
        "face_nbytes": int(face.nbytes),
        "embreex_rss": int(emb_rss),
        "displace_rss": int(dis_rss),
        "embreex_rays_per_s": len(origins) / emb_s,
        "displace_rays_per_s_1": len(origins) / dis1_s,
        "displace_rays_per_s": len(origins) / dis_s,
        "embreex_hits": int(emb_hit.sum()),
        "displace_hits": int(dis_hit.sum()),
        "agreement": agree,
        "median_dt": float(np.median(dt)),
        "median_dist": float(np.median(dd)),
        "within_surface_difference": within,
        "max_surface_difference": float(twist),
    }


if __name__ == "__main__":
    main()
