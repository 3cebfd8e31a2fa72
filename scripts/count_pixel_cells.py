#!/usr/bin/env python3
"""How many height cells a pixel's camera rays share: the measurement behind
the design of a pixel's rays walked as one packet in docs/cpu-tracer.md
("The design the render target needs").

Why: the render benchmark's Whitted sample costs more in its trace alone
than "at most 3x Mitsuba" allows, and the packet kernel reads every voxel
and every cell's four corner heights lane by lane, in gathers. A pixel's 16
samples leave one pinhole inside a cone a pixel wide; if their rays cross
the same few cells near the surface, one load a cell could serve the whole
pixel. This counts how many.

For `--pixels` random pixels of the render benchmark's 512x512 camera
(`scripts/bench_render_peers.py`), 16 rays each on a jittered 4x4 grid of
the pixel (as the renderer's strata), traced to their first hits with
`displace trace --scene` on the benchmark's two faces: the cells (between
height-texel centres, as the bilinear surface's patches) that each ray's
path crosses from the shell's top to its hit, counted by sampling the
path at a quarter of a texel, and the same for the last four cells before
each hit (where the tracer's exact walk is); per pixel, the sum over its
rays against the number of distinct cells. Pixels with a ray that misses
are left out. Usage, from the repository's root:

    cargo build --release -p displace-cli
    python3 scripts/count_pixel_cells.py [--pixels 4000] [--work DIR]
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render_peers as peers  # noqa: E402  (the benchmark's camera and faces)

SIZE, SPP = 512, 16


def pixel_rays(n, rng):
    """`n` random pixels' 16 jittered rays, (n * 16, 6)."""
    px, py = rng.integers(0, SIZE, n), rng.integers(0, SIZE, n)
    gx, gy = np.meshgrid(np.arange(4), np.arange(4))
    fx = (px[:, None] + (gx.ravel()[None, :] + rng.random((n, SPP))) / 4) / SIZE
    fy = (py[:, None] + (gy.ravel()[None, :] + rng.random((n, SPP))) / 4) / SIZE
    return np.concatenate(peers.film_rays(fx, fy), axis=1)


def cells_crossed(a, e, texels):
    """The cells, in order, that the 2D segment from `a` to `e` (face
    coordinates in [0, 1]) crosses, sampled at a quarter of a texel."""
    n = max(2, int(np.ceil(np.linalg.norm((e - a) * texels) * 4)) + 1)
    s = np.linspace(0.0, 1.0, n)[:, None]
    cells = np.floor((a + s * (e - a)) * texels - 0.5).astype(int)
    seq = []
    for c in map(tuple, cells):
        if not seq or seq[-1] != c:
            seq.append(c)
    return seq


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--displace", default="target/release/displace")
    ap.add_argument("--pixels", type=int, default=4000)
    ap.add_argument("--work", default=None)
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="pixel_cells_")
    os.makedirs(work, exist_ok=True)
    rays = pixel_rays(a.pixels, np.random.default_rng(7))
    rays_path = os.path.join(work, "rays.npy")
    np.save(rays_path, rays)
    for m in ("studded", "gaussian"):
        spec = peers.map_spec(m)
        _, _, texels, (_, _, depth), _ = spec
        toml = os.path.join(work, f"{m}.toml")
        with open(toml, "w") as f:
            f.write(peers.scene_toml(spec, SIZE, SPP))
        hits_path = os.path.join(work, f"{m}.hits.npy")
        subprocess.run([os.path.abspath(a.displace), "trace", "--scene", toml, "--rays",
                        rays_path, "-o", hits_path, "--no-cache"], check=True,
                       capture_output=True)
        hits = np.load(hits_path)
        total, distinct, total_last, distinct_last, pixels = 0, 0, 0, 0, 0
        for p in range(a.pixels):
            rows = range(p * SPP, (p + 1) * SPP)
            if not all(np.isfinite(hits[r, 0]) for r in rows):
                continue
            paths = []
            for r in rows:
                o, d = rays[r, :3].astype(np.float64), rays[r, 3:6].astype(np.float64)
                top = (depth - o[2]) / d[2]
                paths.append(cells_crossed((o + top * d)[:2], (o + hits[r, 0] * d)[:2], texels))
            pixels += 1
            total += sum(len(s) for s in paths)
            distinct += len(set().union(*map(set, paths)))
            total_last += sum(len(s[-4:]) for s in paths)
            distinct_last += len(set().union(*(set(s[-4:]) for s in paths)))
        print(f"{m}: {pixels} pixels whose {SPP} rays all hit; cells a ray crosses from the "
              f"shell's top to its hit {total / pixels / SPP:.1f}, distinct a pixel "
              f"{distinct / pixels:.1f} of {total / pixels:.1f} ({distinct / total:.3f}); the "
              f"last four before each hit: distinct a pixel {distinct_last / pixels:.1f} of "
              f"{total_last / pixels:.1f} ({distinct_last / total_last:.3f})")


if __name__ == "__main__":
    main()
