#!/usr/bin/env python3
"""Line of sight and a viewshed over an elevation model, with displace.

What it shows:

* an elevation model in metres (a GeoTIFF-like one-band float32 TIFF) baked
  once into a distance map with ``displace.bake(tiff, size, extent,
  height_range=(lo, hi))`` -- no tessellation;
* line of sight between an observer standing on a peak and a few targets,
  one shadow ray each (``face.occluded``), and where each blocked sight
  line first meets the ground (``face.intersect``);
* a viewshed: for every texel centre, 1.7 m above the ground, whether the
  observer sees it -- one occlusion ray per texel, all in one call;
* a self-check against a brute-force numpy line of sight on the same
  bilinear height field (on a subsample of targets).

The elevation model is synthetic (gaussian hills plus ridged fractal noise,
fixed seed, 200..1400 m, 30 m per texel) so that the example needs no data.

Run it from the repository's root:

    target/pyenv/bin/python python/examples/viewshed.py --out /tmp/v
    target/pyenv/bin/python python/examples/viewshed.py --out /tmp/v --size 2048   # bigger

It writes ``dem.tif`` (the elevation model) and ``viewshed.png`` (hillshade,
viewshed, sight lines and their profiles) into ``--out`` (a new temporary
directory when not given) and prints the numbers. ``main(argv)`` returns
them as a dict.

Frame: the baked face spans x in [0, SX] (columns), y in [0, SY] (image
rows: row 0 lies at y = 0.5 texel), z in [0, SZ] with z = elevation - lo and
SZ = hi - lo. Heights are bilinear between texel centres. The surface is the
top of a solid: a ray that starts under it is blocked at once, so points
are lifted above the ground, never set on it.
"""

import argparse
import os
import sys
import tempfile
import time

import numpy as np

import displace

OBSERVER_HEIGHT = 2.0  # m above the ground, on the peak
TARGET_HEIGHT = 1.7  # m above the ground: a person's eyes


# ---------------------------------------------------------------- terrain --


def band_noise(rng, n, freq):
    """Gaussian noise band-limited around `freq` cycles per map (FFT filter),
    unit standard deviation."""
    white = rng.standard_normal((n, n))
    k = np.fft.fftfreq(n) * n
    kr = np.hypot(k[:, None], k[None, :])
    band = np.exp(-0.5 * ((kr - freq) / (0.5 * freq)) ** 2)
    out = np.fft.ifft2(np.fft.fft2(white) * band).real
    return out / out.std()


def synthetic_dem(n, seed=7, lo=200.0, hi=1400.0):
    """An (n, n) float32 elevation model in metres spanning exactly [lo, hi]:
    a few broad gaussian hills plus ridged fractal noise (mountain ridges)."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    hills = np.zeros((n, n))
    for _ in range(6):
        cx, cy = rng.uniform(0.15, 0.85, 2)
        r = rng.uniform(0.08, 0.22)
        hills += rng.uniform(0.4, 1.0) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * r * r))
    ridged = np.zeros((n, n))
    weight = 1.0
    for octave in range(6):
        r = 1.0 - np.abs(band_noise(rng, n, 1.5 * 2**octave)) / 2.5
        ridged += weight * np.clip(r, 0, 1) ** 2
        weight *= 0.4
    z = hills / hills.max() + 0.35 * ridged / ridged.max()
    z = (z - z.min()) / (z.max() - z.min())
    return (lo + (hi - lo) * z).astype(np.float32)


def write_tiff(path, dem):
    """A one-band float32 TIFF (mode "F"), as GDAL writes a DEM's band."""
    from PIL import Image

    Image.fromarray(dem.astype(np.float32), mode="F").save(path)


def summits(z, count, radius):
    """(rows, cols) of the `count` highest texels that are the highest
    within `radius` texels (a separable running maximum)."""
    win = 2 * radius + 1
    pad = np.pad(z, radius, mode="edge")
    from numpy.lib.stride_tricks import sliding_window_view as windows

    m = windows(windows(pad, win, axis=1).max(-1), win, axis=0).max(-1)
    j, i = np.nonzero(z >= m)
    order = np.argsort(z[j, i])[::-1][:count]
    return j[order], i[order]


def hillshade(z, dx, azimuth=315.0, altitude=45.0):
    """Lambertian hillshade of the (H, W) array z (rows along +y) in [0, 1]."""
    gy, gx = np.gradient(z, dx)
    az, alt = np.radians(azimuth), np.radians(altitude)
    light = np.array([np.sin(az) * np.cos(alt), np.cos(az) * np.cos(alt), np.sin(alt)])
    n = np.stack([-gx, -gy, np.ones_like(z)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.clip(n @ light, 0, 1)


# ----------------------------------------------- brute-force line of sight --


def bilinear(h, x, y, sx, sy):
    """The clamped bilinear height of the (H, W) texel array h at (x, y) in
    metres: texel (j, i) sits at ((i + 0.5) / W * sx, (j + 0.5) / H * sy)."""
    hgt, wid = h.shape
    px = np.clip(x / sx * wid - 0.5, 0, wid - 1)
    py = np.clip(y / sy * hgt - 0.5, 0, hgt - 1)
    i0 = np.minimum(np.floor(px).astype(np.int64), wid - 2)
    j0 = np.minimum(np.floor(py).astype(np.int64), hgt - 2)
    fx, fy = px - i0, py - j0
    a, b = h[j0, i0], h[j0, i0 + 1]
    c, d = h[j0 + 1, i0], h[j0 + 1, i0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def brute_force_clearance(h, extent, origin, targets, t_max, per_texel=4):
    """For each segment origin -> origin + t (target - origin), t in
    [0, t_max], the least height of the segment above the bilinear terrain
    (negative: it goes under, the target is hidden), sampled `per_texel`
    times per texel of horizontal run."""
    sx, sy, _ = extent
    hgt, wid = h.shape
    out = np.empty(len(targets))
    for k, (tgt, tm) in enumerate(zip(targets, t_max)):
        d = tgt - origin
        run = np.hypot(d[0] / sx * wid, d[1] / sy * hgt)
        t = np.linspace(0.0, tm, max(2, int(np.ceil(per_texel * run)) + 1))
        p = origin[None, :] + t[:, None] * d[None, :]
        out[k] = np.min(p[:, 2] - bilinear(h, p[:, 0], p[:, 1], sx, sy))
    return out


# ------------------------------------------------------------------- main --


def stop_short(length):
    """t_max for a ray whose direction is (target - origin) of `length`
    metres: it stops just before the target (at most 1 m, at most 0.1 %),
    so that the target's own point never counts as an obstacle."""
    return (1.0 - np.minimum(1e-3, 1.0 / np.maximum(length, 1e-6))).astype(np.float32)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", help="output directory (default: a new temporary one)")
    p.add_argument("--size", type=int, default=512, help="texels a side (default 512)")
    p.add_argument("--texel", type=float, default=30.0, help="metres per texel (default 30)")
    p.add_argument("--depth", type=int, default=16, help="distance-map voxels in z (default 16)")
    p.add_argument("--check", type=int, default=2000, help="targets checked by brute force (default 2000)")
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    p.add_argument("--seed", type=int, default=7)
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    out = args.out or tempfile.mkdtemp(prefix="viewshed-")
    os.makedirs(out, exist_ok=True)
    n = args.size

    # 1. The elevation model, written as a DEM file would come.
    dem = synthetic_dem(n, seed=args.seed)
    tiff = os.path.join(out, "dem.tif")
    write_tiff(tiff, dem)
    lo, hi = float(np.floor(dem.min())), float(np.ceil(dem.max()))
    sx = sy = n * args.texel
    sz = hi - lo
    extent = (sx, sy, sz)
    print(f"elevation model {n}x{n}, {args.texel:g} m/texel ({sx / 1000:.2f} x {sy / 1000:.2f} km), "
          f"{lo:.0f}..{hi:.0f} m -> {tiff}")

    # 2. Bake it: lo maps to z = 0, hi to z = SZ.
    t0 = time.perf_counter()
    face = displace.bake(tiff, size=(n, n, args.depth), extent=extent, height_range=(lo, hi),
                         threads=args.threads)
    bake_s = time.perf_counter() - t0
    h = face.heights.astype(np.float64) * sz  # metres above lo, as the face sees them
    read_err = float(np.abs(h + lo - dem).max())
    print(f"baked {face.size} in {bake_s:.2f} s, {face.nbytes / 2**20:.1f} MiB; "
          f"file read back within {read_err:.3g} m")

    cx = (np.arange(n) + 0.5) / n * sx  # texel centres
    cy = (np.arange(n) + 0.5) / n * sy

    # 3. The observer: on the highest peak, 2 m above the ground.
    peaks_j, peaks_i = summits(h, 5, radius=max(2, n // 16))
    j, i = peaks_j[0], peaks_i[0]
    observer = np.array([cx[i], cy[j], h[j, i] + OBSERVER_HEIGHT])
    print(f"observer at x={observer[0]:.0f} m y={observer[1]:.0f} m, "
          f"{observer[2] + lo:.0f} m a.s.l. ({OBSERVER_HEIGHT:g} m above the peak)")

    # 4. Line of sight to a few targets 1.7 m above the ground: the other
    #    summits and a few points in the valleys.
    fractions = np.array([[0.12, 0.15], [0.50, 0.08], [0.92, 0.30]])
    tx = np.concatenate([cx[peaks_i[1:]], fractions[:, 0] * sx])
    ty = np.concatenate([cy[peaks_j[1:]], fractions[:, 1] * sy])
    targets = np.column_stack([tx, ty, bilinear(h, tx, ty, sx, sy) + TARGET_HEIGHT])
    dirs = targets - observer
    length = np.linalg.norm(dirs, axis=1)
    t_max = stop_short(length)
    origins = np.broadcast_to(observer, dirs.shape)  # one origin a ray (stride 0 is fine)
    blocked = face.occluded(origins, dirs, t_max)
    first = face.intersect(origins, dirs, t_max)
    consistent = bool(np.array_equal(blocked, np.isfinite(first["t"])))
    print("line of sight (target 1.7 m above the ground):")
    los = []
    for k in range(len(targets)):
        line = (f"  target {k}: x={tx[k]:7.0f} y={ty[k]:7.0f} z={targets[k, 2] + lo:6.0f} m a.s.l., "
                f"{length[k] / 1000:5.2f} km: ")
        entry = {"target": targets[k].tolist(), "distance_m": float(length[k]), "visible": not blocked[k]}
        if blocked[k]:
            p = first["position"][k]
            entry["blocked_at"] = p.tolist()
            line += (f"BLOCKED by the ground {first['t'][k] * length[k] / 1000:.2f} km out, "
                     f"at {p[2] + lo:.0f} m a.s.l.")
        else:
            line += "visible"
        print(line)
        los.append(entry)
    if not consistent:
        print("  WARNING: occluded() and intersect() disagree on these sight lines")

    # 5. The viewshed: one shadow ray per texel centre, in one call.
    gx, gy = np.meshgrid(cx, cy)
    pts = np.column_stack([gx.ravel(), gy.ravel(), h.ravel() + TARGET_HEIGHT])
    vdirs = (pts - observer).astype(np.float32)
    vlen = np.linalg.norm(pts - observer, axis=1)
    vt_max = stop_short(vlen)
    origin = observer[None, :].astype(np.float32)
    origins = np.broadcast_to(origin, vdirs.shape)
    t0 = time.perf_counter()
    hidden = face.occluded(origins, vdirs, vt_max, threads=args.threads)
    trace_s = time.perf_counter() - t0
    visible = ~hidden.reshape(n, n)
    rays_per_s = visible.size / trace_s
    vis_frac = float(visible.mean())
    print(f"viewshed: {visible.size} rays in {trace_s:.3f} s ({rays_per_s / 1e6:.2f} Mrays/s, "
          f"threads={args.threads or 'all'}); visible fraction {vis_frac:.4f} "
          f"({vis_frac * sx * sy / 1e6:.1f} of {sx * sy / 1e6:.1f} km^2)")

    # 6. Self-check: brute-force line of sight on a random subsample, on the
    #    same float32 rays (origin, direction, t_max) as displace traced.
    rng = np.random.default_rng(1)
    pick = rng.choice(visible.size, size=min(args.check, visible.size), replace=False)
    o64 = origin[0].astype(np.float64)
    ends = o64 + vdirs[pick].astype(np.float64)
    t0 = time.perf_counter()
    clearance = brute_force_clearance(h, extent, o64, ends, vt_max[pick].astype(np.float64))
    brute_s = time.perf_counter() - t0
    brute_hidden = clearance < 0
    agree = brute_hidden == hidden[pick]
    agreement = float(agree.mean())
    # A disagreement is "grazing" when the sight line passes within a metre
    # of the ground (the sampled brute force itself is uncertain there).
    grazing = np.abs(clearance) < 1.0
    print(f"self-check on {len(pick)} targets against brute-force bilinear line of sight "
          f"({brute_s:.1f} s): agreement {agreement:.4f}; "
          f"{int((~agree).sum())} disagree, {int((~agree & grazing).sum())} of them grazing (< 1 m)")

    # 7. The figure.
    png = os.path.join(out, "viewshed.png")
    figure(png, dem, visible, extent, observer, targets, blocked, first, h, lo, args.texel)
    print(f"wrote {png}")

    return {
        "out": out,
        "tiff": tiff,
        "png": png,
        "size": n,
        "extent": extent,
        "height_range": (lo, hi),
        "bake_s": bake_s,
        "read_error_m": read_err,
        "observer": observer.tolist(),
        "line_of_sight": los,
        "los_consistent": consistent,
        "visible_fraction": vis_frac,
        "rays": int(visible.size),
        "rays_per_s": rays_per_s,
        "checked": int(len(pick)),
        "agreement": agreement,
        "disagree": int((~agree).sum()),
        "disagree_grazing": int((~agree & grazing).sum()),
    }


def figure(path, dem, visible, extent, observer, targets, blocked, first, h, lo, texel):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    sx, sy, _ = extent
    km = [0, sx / 1000, 0, sy / 1000]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14, 6.5), gridspec_kw={"width_ratios": [1.1, 1]})
    shade = hillshade(dem.astype(np.float64), texel)
    rgb = plt.get_cmap("terrain")((dem - dem.min()) / np.ptp(dem))[..., :3]
    rgb = rgb * (0.35 + 0.65 * shade[..., None])
    ax.imshow(rgb, origin="lower", extent=km)
    ax.imshow(np.where(visible, 1.0, np.nan), origin="lower", extent=km,
              cmap=ListedColormap(["#ff2a00"]), alpha=0.45, interpolation="nearest")
    ax.plot(observer[0] / 1000, observer[1] / 1000, "*", ms=18, mfc="yellow", mec="black", label="observer")
    for k, t in enumerate(targets):
        c = "red" if blocked[k] else "lime"
        ax.plot([observer[0] / 1000, t[0] / 1000], [observer[1] / 1000, t[1] / 1000], "-", c=c, lw=1.5)
        ax.plot(t[0] / 1000, t[1] / 1000, "o", ms=7, mfc=c, mec="black")
        ax.annotate(str(k), (t[0] / 1000, t[1] / 1000), xytext=(5, 5), textcoords="offset points",
                    color="white", fontsize=10, weight="bold")
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_title(f"viewshed (red: visible, {visible.mean():.1%}) from the peak")

    # Profiles of the sight lines: terrain under each, the line, the hit.
    for k, t in enumerate(targets):
        d = t - observer
        s = np.linspace(0, 1, 600)
        p = observer[None, :] + s[:, None] * d[None, :]
        dist = s * np.hypot(d[0], d[1]) / 1000
        ground = bilinear(h, p[:, 0], p[:, 1], sx, sy) + lo
        line, = ax2.plot(dist, ground, lw=1)
        ax2.plot(dist, p[:, 2] + lo, "--", c=line.get_color(), lw=1)
        if blocked[k]:
            hp = first["position"][k]
            hd = np.hypot(hp[0] - observer[0], hp[1] - observer[1]) / 1000
            ax2.plot(hd, hp[2] + lo, "x", c="red", ms=9, mew=2)
        ax2.annotate(str(k), (dist[-1], ground[-1]), xytext=(3, 0), textcoords="offset points")
    ax2.set_xlabel("distance from the observer (km)")
    ax2.set_ylabel("elevation (m a.s.l.)")
    ax2.set_title("sight lines (dashed) over the ground; x: first obstruction")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
