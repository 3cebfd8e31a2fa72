#!/usr/bin/env python3
"""A simulated spinning-lidar scan of a displaced surface, written as a
point cloud.

What it shows:

* a height map baked with a physical extent (metres): by default the
  built-in fractal noise, ``gen:noise``, over 40 m x 40 m with 1.5 m of
  relief (``--height gen:studded`` for the checkerboard of blocks, or any
  ``gen:...`` source or height-map file);
* a scanner 10 m above the middle of the tile casting a spinning pattern:
  ``--beams`` lasers spread in elevation (default 32, from -60 to -10
  degrees) times ``--azimuths`` firings a turn (default 1024);
* the first hits from one ``face.intersect`` call: with unit directions,
  ``t`` is the range in metres; misses (beams that leave the tile) come
  back as ``t = inf`` and are dropped;
* optional gaussian range noise (``--noise`` metres, fixed seed) applied
  along each beam;
* an ASCII PLY, ``scan.ply`` (x y z range nx ny nz intensity ring), and a
  top-down PNG of the points coloured by height, ``scan.png``.

Run it from the repository's root:

    target/pyenv/bin/python python/examples/lidar.py --out /tmp/lidar
    target/pyenv/bin/python python/examples/lidar.py --out /tmp/lidar --height gen:studded --noise 0
    target/pyenv/bin/python python/examples/lidar.py --out /tmp/lidar --beams 64 --azimuths 4096 --size 2048

``main(argv)`` returns the numbers as a dict.

Frame: the face spans x in [0, SX], y in [0, SY] and z in [0, SZ] (the
surface lies between z = 0 and z = SZ); the scanner's height is measured
from z = 0.
"""

import argparse
import os
import tempfile
import time

import numpy as np

import displace


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", help="output directory (default: a new temporary one)")
    p.add_argument("--height", default="gen:noise", help="height source (default gen:noise)")
    p.add_argument("--extent", default="40,40,1.5", help="SX,SY,SZ in metres (default 40,40,1.5)")
    p.add_argument("--size", type=int, default=512, help="texels a side of the bake (default 512)")
    p.add_argument("--depth", type=int, default=16, help="distance-map voxels in z (default 16)")
    p.add_argument("--scanner-height", type=float, default=10.0, help="metres above z = 0 (default 10)")
    p.add_argument("--beams", type=int, default=32, help="lasers (default 32)")
    p.add_argument("--elevation", default="-60,-10", help="lowest,highest beam in degrees (default -60,-10)")
    p.add_argument("--azimuths", type=int, default=1024, help="firings a turn (default 1024)")
    p.add_argument("--noise", type=float, default=0.01, help="range noise sigma in metres (default 0.01)")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    return p.parse_args(argv)


def spinning_pattern(beams, elev_lo, elev_hi, azimuths):
    """Unit directions (beams * azimuths, 3) of a spinning lidar, firing by
    firing (all beams of one azimuth in a row, as the sensor reports them),
    with each firing's ring (beam index) and azimuth in radians."""
    elev = np.radians(np.linspace(elev_lo, elev_hi, beams))
    az = 2 * np.pi * np.arange(azimuths) / azimuths
    a, e = np.meshgrid(az, elev, indexing="ij")  # (azimuths, beams)
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1)
    ring = np.broadcast_to(np.arange(beams), a.shape)
    return d.reshape(-1, 3), ring.ravel(), a.ravel()


def bilinear(h, u, v):
    """The clamped bilinear height of the (H, W) array h at texture
    coordinates (u, v) in [0, 1]; texel (j, i) sits at ((i + 0.5) / W,
    (j + 0.5) / H)."""
    rows, cols = h.shape
    px = np.clip(u * cols - 0.5, 0, cols - 1)
    py = np.clip(v * rows - 0.5, 0, rows - 1)
    i0 = np.minimum(np.floor(px).astype(np.int64), cols - 2)
    j0 = np.minimum(np.floor(py).astype(np.int64), rows - 2)
    fx, fy = px - i0, py - j0
    a, b = h[j0, i0], h[j0, i0 + 1]
    c, e = h[j0 + 1, i0], h[j0 + 1, i0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + e * fx) * fy


def write_ply(path, columns, comment):
    """An ASCII PLY of one `vertex` element; `columns` is a list of
    (name, ply type, array, printf format)."""
    n = len(columns[0][2])
    header = ["ply", "format ascii 1.0", f"comment {comment}", f"element vertex {n}"]
    header += [f"property {ptype} {name}" for name, ptype, _, _ in columns]
    header.append("end_header")
    table = np.column_stack([np.asarray(c[2], dtype=np.float64) for c in columns])
    with open(path, "w") as f:
        f.write("\n".join(header) + "\n")
        np.savetxt(f, table, fmt=" ".join(c[3] for c in columns))


def main(argv=None):
    args = parse_args(argv)
    out = args.out or tempfile.mkdtemp(prefix="lidar-")
    os.makedirs(out, exist_ok=True)
    extent = tuple(float(v) for v in args.extent.split(","))
    elev_lo, elev_hi = (float(v) for v in args.elevation.split(","))
    sx, sy, sz = extent

    t0 = time.perf_counter()
    face = displace.bake(args.height, size=(args.size, args.size, args.depth), extent=extent,
                         threads=args.threads)
    bake_s = time.perf_counter() - t0
    print(f"baked {args.height} at {face.size} over {sx:g} x {sy:g} m, {sz:g} m relief, "
          f"in {bake_s:.2f} s ({face.nbytes / 2**20:.1f} MiB)")

    scanner = np.array([sx / 2, sy / 2, args.scanner_height])
    dirs, ring, azimuth = spinning_pattern(args.beams, elev_lo, elev_hi, args.azimuths)
    origins = np.broadcast_to(scanner, dirs.shape)
    t0 = time.perf_counter()
    hits = face.intersect(origins, dirs, threads=args.threads)
    trace_s = time.perf_counter() - t0
    rays_per_s = len(dirs) / trace_s
    hit = np.isfinite(hits["t"])
    print(f"scanner at ({scanner[0]:g}, {scanner[1]:g}, {scanner[2]:g}) m: {args.beams} beams "
          f"({elev_lo:g}..{elev_hi:g} deg) x {args.azimuths} azimuths = {len(dirs)} rays in "
          f"{trace_s:.3f} s ({rays_per_s / 1e6:.2f} Mrays/s, threads={args.threads or 'all'})")

    # The returns: range along the beam with gaussian noise, the point
    # moved along the beam by it (the sensor measures range, not position).
    rng = np.random.default_rng(args.seed)
    true_range = hits["t"][hit].astype(np.float64)
    rng_noise = rng.normal(0.0, args.noise, true_range.shape) if args.noise > 0 else 0.0
    rng_meas = true_range + rng_noise
    d = dirs[hit]
    pts = scanner + rng_meas[:, None] * d
    normal = hits["normal"][hit]
    # A Lambertian return: the cosine between the beam and the surface.
    intensity = np.abs(np.einsum("ij,ij->i", normal, d))
    returns = int(hit.sum())
    print(f"returns: {returns} of {len(dirs)} ({returns / len(dirs):.1%}; the rest leave the tile), "
          f"range {true_range.min():.2f}..{true_range.max():.2f} m, noise sigma {args.noise:g} m")

    # Self-check: every true return lies on its beam (position = scanner +
    # t * d) and on the bilinear surface of the face's heights (returns off
    # the tile's side walls aside: there the normal is horizontal).
    pos = hits["position"][hit].astype(np.float64)
    on_ray = float(np.abs(pos - (scanner + true_range[:, None] * d)).max())
    top = np.abs(normal[:, 2]) > 0.05
    ground = bilinear(face.heights.astype(np.float64), pos[top, 0] / sx, pos[top, 1] / sy) * sz
    on_surface = float(np.abs(pos[top, 2] - ground).max())
    print(f"self-check: returns within {on_ray:.2g} m of their beams and {on_surface:.2g} m of the "
          f"bilinear surface ({int((~top).sum())} on the tile's side walls)")

    ply = os.path.join(out, "scan.ply")
    write_ply(ply, [
        ("x", "float", pts[:, 0], "%.4f"),
        ("y", "float", pts[:, 1], "%.4f"),
        ("z", "float", pts[:, 2], "%.4f"),
        ("range", "float", rng_meas, "%.4f"),
        ("nx", "float", normal[:, 0], "%.5f"),
        ("ny", "float", normal[:, 1], "%.5f"),
        ("nz", "float", normal[:, 2], "%.5f"),
        ("intensity", "float", intensity, "%.4f"),
        ("ring", "uchar", ring[hit], "%d"),
    ], comment=f"simulated lidar scan of {args.height} by displace; scanner at "
               f"{scanner[0]:g} {scanner[1]:g} {scanner[2]:g}")
    print(f"wrote {ply} ({os.path.getsize(ply) / 1e6:.1f} MB)")

    png = os.path.join(out, "scan.png")
    plot(png, pts, extent, scanner, args.height)
    print(f"wrote {png}")

    return {
        "out": out,
        "ply": ply,
        "png": png,
        "rays": int(len(dirs)),
        "returns": returns,
        "bake_s": bake_s,
        "trace_s": trace_s,
        "rays_per_s": rays_per_s,
        "range_min": float(true_range.min()),
        "range_max": float(true_range.max()),
        "position_error": on_ray,
        "surface_error": on_surface,
        "wall_returns": int((~top).sum()),
    }


def plot(path, pts, extent, scanner, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sx, sy, _ = extent
    fig, ax = plt.subplots(figsize=(7, 6.3))
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=pts[:, 2], s=0.8, cmap="viridis", linewidths=0)
    ax.plot(scanner[0], scanner[1], "r+", ms=12, mew=2)
    ax.set_xlim(0, sx)
    ax.set_ylim(0, sy)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"lidar returns on {title}, {len(pts)} points (top view)")
    fig.colorbar(sc, ax=ax, label="z (m)", shrink=0.85)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
