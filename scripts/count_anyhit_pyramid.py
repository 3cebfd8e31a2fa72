#!/usr/bin/env python3
"""How many fetches an any-hit query over a maximum-height pyramid would
take, against the distance-map tracer's iterations, on the same rays: the
measurement behind the design for grazing any-hit rays in
docs/cpu-tracer.md ("Any-hit rays over terrain").

Why: an elevation model's line-of-sight rays graze the terrain (the
benchmark's: 0.3 degrees from horizontal at the median), so the distance
map's conservative steps, bounded by the ray's small clearance, stay short
the whole way, and the any-hit query costs hundreds of iterations where a
tessellated mesh's BVH costs a few dozen node visits. A maximum mipmap
(Tevs, Ihrke and Seidel, "Maximum Mipmaps for Fast, Accurate, and Scalable
Dynamic Height Field Rendering", I3D 2008) skips a whole node wherever the
ray's lowest point over it lies above the node's maximum, whichever way the
ray climbs; this counts its node visits.

The walk here is a plain recursive one in Python, nodes visited front to
back, over the full-resolution heights; a leaf (one bilinear cell) is
judged by sampling the ray against the bilinear surface at nine points, an
approximation of the exact patch solve that the Rust tracer would use; the
script checks its answers against the binding's first hits (`blocked` if
the first hit lies within `t_max`) and prints the agreement.

Input: a work directory of ``scripts/bench_python_peers.py --keep DIR``
(its ``dem`` case: ``case.json``, ``heights.npy``, ``occ_rays.npy``,
``occ_tmax.npy``). Usage, from the repository's root, with the package
installed (README, "Python"):

    target/pyenv/bin/python scripts/bench_python_peers.py --cases dem \\
        --map-div 4 --sub 1 --repeat 1 --threads 1 --keep /tmp/bdem
    target/pyenv/bin/python scripts/count_anyhit_pyramid.py --work /tmp/bdem/dem \\
        [--rays 3000] [--map 1024x1024x16]
"""

import argparse
import json
import os
import sys
import time

import numpy as np


def pyramid(heights, sz):
    """Level 0: each bilinear cell's maximum (its four corners), then 2x2
    maxima up to one node, in physical height units."""
    h = heights.astype(np.float64)
    levels = [np.maximum.reduce([h[:-1, :-1], h[1:, :-1], h[:-1, 1:], h[1:, 1:]]) * sz]
    while levels[-1].shape[0] > 1 or levels[-1].shape[1] > 1:
        a = levels[-1]
        a = np.pad(a, ((0, a.shape[0] % 2), (0, a.shape[1] % 2)), constant_values=-np.inf)
        levels.append(np.maximum.reduce([a[0::2, 0::2], a[1::2, 0::2], a[0::2, 1::2], a[1::2, 1::2]]))
    return levels


def bilinear(heights, sz, cx, cy, x, y):
    """The surface's height at physical `(x, y)` (texel centres at (i + 0.5) * cx)."""
    n_y, n_x = heights.shape
    u, v = x / cx - 0.5, y / cy - 0.5
    i = np.clip(np.floor(u).astype(int), 0, n_x - 2)
    j = np.clip(np.floor(v).astype(int), 0, n_y - 2)
    fu, fv = u - i, v - j
    h = heights
    return sz * ((1 - fv) * ((1 - fu) * h[j, i] + fu * h[j, i + 1])
                 + fv * ((1 - fu) * h[j + 1, i] + fu * h[j + 1, i + 1]))


def any_hit(levels, heights, sz, cx, cy, o, d, t0, t1):
    """(blocked, node visits) of ray `o + t d`, `t` in `[t0, t1]`."""
    visits = 0

    def node(level, i, j, ta, tb):
        nonlocal visits
        a = levels[level]
        if j >= a.shape[0] or i >= a.shape[1]:
            return False
        s = 1 << level
        lo, hi = ta, tb
        for oo, dd, b0, b1 in ((o[0], d[0], (i * s + 0.5) * cx, ((i + 1) * s + 0.5) * cx),
                               (o[1], d[1], (j * s + 0.5) * cy, ((j + 1) * s + 0.5) * cy)):
            if dd == 0.0:
                if not b0 <= oo <= b1:
                    return False
                continue
            p, q = (b0 - oo) / dd, (b1 - oo) / dd
            lo, hi = max(lo, min(p, q)), min(hi, max(p, q))
        if lo > hi:
            return False
        visits += 1
        if min(o[2] + lo * d[2], o[2] + hi * d[2]) > a[j, i]:
            return False
        if level == 0:
            ts = np.linspace(lo, hi, 9)
            z = bilinear(heights, sz, cx, cy, o[0] + ts * d[0], o[1] + ts * d[1])
            return bool(np.any(o[2] + ts * d[2] < z - 1e-6))
        half = s // 2
        kids = [(2 * i + a_, 2 * j + b_) for b_ in (0, 1) for a_ in (0, 1)]
        kids.sort(key=lambda k: ((k[0] + 0.5) * half * cx - o[0]) * d[0]
                  + ((k[1] + 0.5) * half * cy - o[1]) * d[1])
        return any(node(level - 1, ki, kj, lo, hi) for ki, kj in kids)

    blocked = node(len(levels) - 1, 0, 0, t0, t1)
    return blocked, visits


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", required=True, help="bench_python_peers.py --keep DIR, its dem case")
    ap.add_argument("--rays", type=int, default=3000, help="rays drawn from the occlusion set")
    ap.add_argument("--map", default="1024x1024x16", help="the distance map the binding bakes")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    try:
        import displace
    except ImportError:
        sys.exit("count_anyhit_pyramid: the displace package is not installed (README, 'Python')")
    for f in ("case.json", "heights.npy", "occ_rays.npy", "occ_tmax.npy"):
        if not os.path.exists(os.path.join(args.work, f)):
            sys.exit(f"count_anyhit_pyramid: {args.work}: no {f} (see --help)")
    meta = json.load(open(os.path.join(args.work, "case.json")))
    heights = np.load(os.path.join(args.work, "heights.npy"))
    sx, sy, sz = meta["extent"]
    cx, cy = sx / heights.shape[1], sy / heights.shape[0]
    rays = np.load(os.path.join(args.work, "occ_rays.npy"))
    tmax = np.load(os.path.join(args.work, "occ_tmax.npy"))
    pick = np.random.default_rng(args.seed).choice(len(rays), min(args.rays, len(rays)), replace=False)
    o, d, tm = rays[pick, :3].copy(), rays[pick, 3:].copy(), tmax[pick]

    levels = pyramid(heights, sz)
    walked = [any_hit(levels, heights, sz, cx, cy, o[k].astype(np.float64),
                      d[k].astype(np.float64), 1e-3, float(tm[k])) for k in range(len(o))]
    blocked = np.array([w[0] for w in walked])
    visits = np.array([w[1] for w in walked], dtype=float)

    size = tuple(int(v) for v in args.map.split("x"))
    face = displace.bake(heights, size=size, extent=(sx, sy, sz))
    hits = face.intersect(o, d, tm)
    first = np.isfinite(hits["t"])
    it = hits["iterations"].astype(float)
    t0 = time.perf_counter()
    face.occluded(o, d, tm, threads=1)
    per_ray = (time.perf_counter() - t0) / len(o)

    slope = np.degrees(np.arcsin(np.abs(d[:, 2]) / np.linalg.norm(d, axis=1)))
    print(f"{meta['label']}, {len(o)} occlusion rays (seed {args.seed}), median slope "
          f"{np.median(slope):.2f} deg; pyramid over {heights.shape[1]}x{heights.shape[0]} "
          f"heights, {len(levels)} levels; distance map {args.map}")
    print(f"blocked: {blocked.mean():.3f}; agreement with the binding's first hit within t_max: "
          f"{(blocked == first).mean():.4f}")
    q = lambda a: f"median {np.median(a):.0f}, mean {a.mean():.1f}, p90 {np.percentile(a, 90):.0f}"
    print(f"distance-map tracer, iterations of the first hit (blocked rays): {q(it[first])}")
    print(f"max pyramid, node visits of the any-hit walk (same rays):        {q(visits[first])}")
    print(f"max pyramid, node visits (unblocked rays):                       "
          f"{q(visits[~first]) if (~first).any() else 'none'}")
    print(f"the binding's occluded today: {per_ray * 1e6:.1f} us a ray on one thread")


if __name__ == "__main__":
    main()
