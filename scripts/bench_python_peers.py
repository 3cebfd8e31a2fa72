#!/usr/bin/env python3
"""displace against embreex, from Python, on the same rays: the bench of
the Python package against the usual way to cast rays at a height field
(tessellate it, hand the mesh to Embree through embreex). Run by hand, not
in CI.

Cases (each a height field in [0, 1] and a physical extent):

* ``dem``: a 4096 x 4096 elevation model, 30 m a texel, 1200 m of relief --
  synthetic fractal terrain (ridged band-limited noise on broad hills, fixed
  seed), or a one-band TIFF given with ``--dem PATH`` (mapped lowest to
  highest onto [0, 1]);
* ``studded``: ``gen:studded`` at 1024 x 1024 over (1, 1, 0.1), its heights
  taken from ``displace.bake("gen:studded", size=(1024, 1024, 16)).heights``.

Engines: displace (``displace.bake`` then ``face.run``) with its distance
map at two resolutions (``--map-div 4,1``: a voxel column over 4 x 4
texels, as Donnelly's maps are coarser than the textures they serve, and
one a texel), and embreex on the
standard tessellation at x1 (a vertex per texel centre, two triangles per
cell) and x4 (each cell split 4 x 4, the new vertices bilinear in the
texels). Both answer through the same call, ``run(origins, dirs, dists,
query, output)``.

Rays (float32, unit directions, the same for every engine):

* first hits: from just above the relief (z = 1.001 SZ) over the texel
  centres' square, 5..90 degrees below the horizon, uniform azimuth; t_max
  where the ray leaves that square (the tessellation covers only the
  centres' square, displace's clamped surface the whole tile), traced with
  ``run(..., output=True)``;
* occlusion: sight lines between two random points 1 % of SZ above the
  surface, t_max just short of the far one, ``run(..., query="OCCLUDED")``.

Measured, for each case and engine, each in a fresh subprocess:

* set-up: the bake against tessellation (numpy) + ``TriangleMesh`` (copies
  the mesh into Embree) + the BVH build (Embree commits on the first
  ``run``); both build on every core;
* memory: peak resident set (``VmHWM``) over a baseline taken after
  importing numpy and the library and loading the heights (the peak is
  reset there through /proc/self/clear_refs, so that the imports' own
  transient peak does not hide the set-up's), and what stays resident
  after the set-up (the mesh's numpy arrays freed);
* first hits and occlusion queries per second on 1 and 2 threads.
  displace: ``threads=1/2``. embreex's ``run`` is single-threaded per call:
  the 2-thread figure runs it on two Python threads over halves of the
  rays, which only helps if it releases the GIL (the table says whether it
  did: its 2-thread speed-up is printed);
* agreement with displace: hit/miss (occluded or not) on the same rays, and
  the median |t difference| where both hit.

The binding's overhead: the first-hit rays written as float32 .npy (N, 6)
and traced by the CLI, ``displace trace --height H --extent ... --size WxHxD
--rays rays.npy -o hits.npy`` (its printed Mrays/s: the trace alone, not
its bake), on RAYON_NUM_THREADS=1 and 2, against ``face.intersect`` on the
same rays and threads (timed around the call: argument checks, the trace,
the output arrays). The two are measured in pairs, in the displace worker
while its face is built: a call of ``face.intersect``, then a run of the
CLI, ``--repeat`` times over, the best of each side taken, so that both see
the shared machine's load of the same minute (measured minutes apart, a
2-thread row moved by 10-20 % between runs). The hits must be the same
bits; the table says.

Usage (from the repository's root; the release CLI for the overhead):

    cargo build --release -p displace-cli
    target/pyenv/bin/python scripts/bench_python_peers.py [--quick] [--rays N]
        [--dem PATH] [--displace-bin PATH] [--cases dem,studded] [--sub 1,4]
        [--map-div 4,1] [--threads 1,2] [--repeat 3] [--keep DIR]

``--quick``: a 512 x 512 DEM, a 256 x 256 studded face, 50 000 rays, one
repeat -- a smoke run in well under a minute on two cores. Engines whose
estimated peak memory exceeds 80 % of the available memory are skipped
(``--force`` runs them anyway): embreex at x4 on the 4096 DEM is ~5e8
triangles.
"""

import argparse
import gc
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAGE = os.sysconf("SC_PAGE_SIZE")
MIB = 2.0**20


# ------------------------------------------------------------ height fields --


def band_noise(rng, n, freq):
    """Gaussian noise band-limited around `freq` cycles per map (a real FFT
    filter), unit standard deviation, float32."""
    ky = np.fft.fftfreq(n)[:, None] * n
    kx = np.fft.rfftfreq(n)[None, :] * n
    band = np.exp(-0.5 * ((np.hypot(ky, kx) - freq) / (0.5 * freq)) ** 2)
    spec = np.fft.rfft2(rng.standard_normal((n, n), dtype=np.float32))
    spec *= band
    out = np.fft.irfft2(spec, s=(n, n)).astype(np.float32)
    out /= out.std()
    return out


def synthetic_dem(n, seed=7):
    """(n, n) float32 fractal terrain in [0, 1]: broad gaussian hills plus
    ridged band-limited noise (the viewshed example's recipe)."""
    rng = np.random.default_rng(seed)
    c = ((np.arange(n) + 0.5) / n).astype(np.float32)
    hills = np.zeros((n, n), np.float32)
    for _ in range(6):
        cx, cy = rng.uniform(0.15, 0.85, 2)
        r = rng.uniform(0.08, 0.22)
        gx = np.exp(-((c - cx) ** 2) / (2 * r * r)).astype(np.float32)
        gy = np.exp(-((c - cy) ** 2) / (2 * r * r)).astype(np.float32)
        hills += np.float32(rng.uniform(0.4, 1.0)) * gy[:, None] * gx[None, :]
    ridged = np.zeros((n, n), np.float32)
    weight = 1.0
    for octave in range(min(9, int(np.log2(n)) - 1)):
        r = 1.0 - np.abs(band_noise(rng, n, 1.5 * 2**octave)) / 2.5
        np.clip(r, 0, 1, out=r)
        ridged += np.float32(weight) * r * r
        weight *= 0.4
    z = hills / hills.max() + 0.35 * ridged / ridged.max()
    z -= z.min()
    z /= z.max()
    return z.astype(np.float32)


def read_dem(path):
    """A one-band TIFF (Pillow) mapped lowest..highest onto [0, 1]."""
    from PIL import Image

    Image.MAX_IMAGE_PIXELS = None
    with Image.open(path) as im:
        z = np.asarray(im, dtype=np.float64)
    if z.ndim != 2:
        sys.exit(f"--dem {path}: a one-band image is needed, got shape {z.shape}")
    lo, hi = np.nanmin(z), np.nanmax(z)
    return ((np.nan_to_num(z, nan=lo) - lo) / (hi - lo)).astype(np.float32), float(hi - lo)


def bilinear(h, x, y, extent):
    """The clamped bilinear height (in [0, 1]) of the (H, W) texel array h
    at (x, y) in the extent's units; texel (j, i) at ((i + .5) / W SX,
    (j + .5) / H SY)."""
    rows, cols = h.shape
    px = np.clip(x / extent[0] * cols - 0.5, 0, cols - 1)
    py = np.clip(y / extent[1] * rows - 0.5, 0, rows - 1)
    i0 = np.minimum(np.floor(px).astype(np.int64), cols - 2)
    j0 = np.minimum(np.floor(py).astype(np.int64), rows - 2)
    fx, fy = px - i0, py - j0
    a, b = h[j0, i0].astype(np.float64), h[j0, i0 + 1]
    c, d = h[j0 + 1, i0].astype(np.float64), h[j0 + 1, i0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


# ---------------------------------------------------------------------- rays --


def centre_square(shape, extent):
    rows, cols = shape
    lo = np.array([0.5 / cols * extent[0], 0.5 / rows * extent[1]])
    hi = np.array([(cols - 0.5) / cols * extent[0], (rows - 0.5) / rows * extent[1]])
    return lo, hi


def hit_rays(n, shape, extent, seed=1):
    """(N, 6) float32 rays from z = 1.001 SZ over the centres' square, unit
    directions 5..90 degrees below the horizon, and (N,) t_max where each
    leaves the square (in the units of the extent)."""
    rng = np.random.default_rng(seed)
    lo, hi = centre_square(shape, extent)
    xy = rng.uniform(lo, hi, (n, 2))
    e = np.radians(rng.uniform(5.0, 90.0, n))
    a = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), -np.sin(e)])
    with np.errstate(divide="ignore"):
        tx = np.where(d[:, 0] > 0, (hi[0] - xy[:, 0]) / d[:, 0], (lo[0] - xy[:, 0]) / d[:, 0])
        ty = np.where(d[:, 1] > 0, (hi[1] - xy[:, 1]) / d[:, 1], (lo[1] - xy[:, 1]) / d[:, 1])
    t_max = np.minimum(np.abs(tx), np.abs(ty))
    o = np.column_stack([xy, np.full(n, 1.001 * extent[2])])
    return np.column_stack([o, d]).astype(np.float32), t_max.astype(np.float32)


def occlusion_rays(n, heights, extent, seed=2, lift=0.01):
    """(N, 6) float32 sight lines between two random points `lift` SZ above
    the bilinear surface over the centres' square, directions unit, and
    (N,) t_max just short of the far point."""
    rng = np.random.default_rng(seed)
    lo, hi = centre_square(heights.shape, extent)
    p = rng.uniform(lo, hi, (n, 2))
    q = rng.uniform(lo, hi, (n, 2))
    zp = (bilinear(heights, p[:, 0], p[:, 1], extent) + lift) * extent[2]
    zq = (bilinear(heights, q[:, 0], q[:, 1], extent) + lift) * extent[2]
    o = np.column_stack([p, zp])
    d = np.column_stack([q, zq]) - o
    length = np.linalg.norm(d, axis=1)
    d /= length[:, None]
    t_max = length * (1 - 1e-4)
    return np.column_stack([o, d]).astype(np.float32), t_max.astype(np.float32)


# -------------------------------------------------------------- tessellation --


def tessellate(heights, extent, sub, block=256):
    """The tessellation over the texel centres, each cell split sub x sub,
    the vertices' heights bilinear in the texels: float32 (V, 3) vertices,
    int32 (T, 3) indices, two triangles a quad. Filled in blocks of rows to
    keep the temporaries small."""
    rows, cols = heights.shape
    sx, sy, sz = extent
    nu, nv = sub * (cols - 1) + 1, sub * (rows - 1) + 1
    if nu * nv >= 2**31:
        raise MemoryError(f"{nu * nv} vertices: more than int32 indices address")
    s = np.arange(nu) / sub
    i0 = np.minimum(np.floor(s).astype(np.int64), cols - 2)
    fx = (s - i0).astype(np.float32)
    xs = ((s + 0.5) / cols * sx).astype(np.float32)
    verts = np.empty((nv * nu, 3), np.float32)
    for r0 in range(0, nv, block):
        r = np.arange(r0, min(nv, r0 + block))
        t = r / sub
        j0 = np.minimum(np.floor(t).astype(np.int64), rows - 2)
        fy = (t - j0).astype(np.float32)[:, None]
        lines = heights[j0] * (1 - fy) + heights[j0 + 1] * fy  # (len(r), cols)
        z = lines[:, i0] * (1 - fx) + lines[:, i0 + 1] * fx
        v = verts[r0 * nu:(r0 + len(r)) * nu].reshape(len(r), nu, 3)
        v[..., 0] = xs[None, :]
        v[..., 1] = ((t + 0.5) / rows * sy).astype(np.float32)[:, None]
        v[..., 2] = z * np.float32(sz)
    cells = (nu - 1) * (nv - 1)
    idx = np.empty((2 * cells, 3), np.int32)
    for r0 in range(0, nv - 1, block):
        r1 = min(nv - 1, r0 + block)
        a = (np.arange(r0, r1)[:, None] * nu + np.arange(nu - 1)[None, :]).ravel()
        b, c = a + 1, a + nu
        d = c + 1
        k0, k1 = r0 * (nu - 1), r1 * (nu - 1)
        idx[k0:k1] = np.column_stack([a, b, d])
        idx[cells + k0:cells + k1] = np.column_stack([a, d, c])
    return verts, idx


def map_size(shape, depth, div):
    """The distance map's size for heights of `shape` at `div` texels a
    voxel a side (at least 1 voxel)."""
    rows, cols = shape
    return max(1, cols // div), max(1, rows // div), depth


def estimate_bytes(engine, shape, depth, sub):
    """A rough peak-memory estimate of an engine's set-up, to skip what
    cannot fit (`sub`: displace's map divisor, embreex's cell split)."""
    rows, cols = shape
    if engine == "displace":
        w, h, d = map_size(shape, depth, sub)
        return rows * cols * 24 + w * h * (4 * d + 24) * 2
    v = (sub * (cols - 1) + 1) * (sub * (rows - 1) + 1)
    t = 2 * sub * sub * (cols - 1) * (rows - 1)
    # numpy mesh + Embree's copy (16-byte vertices) + BVH and its build.
    return v * (12 + 16) + t * (12 + 12 + 96)


def available_bytes():
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 1 << 62


# -------------------------------------------------------------------- worker --


def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


def peak():
    """The peak resident set: VmHWM, which clear_refs resets. (Not
    ru_maxrss: that also keeps the resident set of the process image that
    exec replaced, the forked driver's, hundreds of MiB after a big case.)"""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def reset_peak():
    """Resets the process's peak resident set (Linux >= 4.0: "5" to
    /proc/self/clear_refs), so that VmHWM measures from here on and not
    the imports' transient peak. False where it cannot."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def best_of(repeat, fn):
    """(the least seconds of `repeat` calls of fn, the last result)."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def worker(args):
    """One engine on one case, in a fresh process: prints one JSON line."""
    work = args.work
    meta = json.load(open(os.path.join(work, "case.json")))
    extent = tuple(meta["extent"])
    threads = [int(t) for t in args.threads.split(",")]
    if args.worker == "displace":
        import displace  # noqa: F401
    else:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
    heights = np.load(os.path.join(work, "heights.npy"))
    gc.collect()
    # The baseline: numpy, the library and the heights resident. With the
    # peak reset, VmHWM - baseline is the set-up's own peak; without,
    # the imports' earlier peak may hide part of it (then it is a floor).
    res = {"engine": args.worker, "sub": args.sub, "peak_reset": reset_peak()}
    base_rss = rss()
    base_peak = base_rss if res["peak_reset"] else peak()

    t0 = time.perf_counter()
    if args.worker == "displace":
        face = displace.bake(heights, size=map_size(heights.shape, meta["depth"], args.sub),
                             extent=extent)
        res["setup_s"] = time.perf_counter() - t0
        res["held_bytes"] = face.nbytes
        engine = face
    else:
        verts, idx = tessellate(heights, extent, args.sub)
        t1 = time.perf_counter()
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, verts, idx)
        t2 = time.perf_counter()
        res["triangles"] = len(idx)
        res["mesh_bytes"] = verts.nbytes + idx.nbytes
        del verts, idx
        gc.collect()
        one = np.array([[1e-3 * extent[0], 1e-3 * extent[1], 2 * extent[2]]], np.float32)
        scene.run(one, np.array([[0, 0, -1]], np.float32))  # commits: builds the BVH
        t3 = time.perf_counter()
        res["setup_s"] = t3 - t0
        res["setup_parts"] = {"tessellate": t1 - t0, "TriangleMesh": t2 - t1, "bvh": t3 - t2}
        engine = scene
    res["peak_bytes"] = peak() - base_peak
    gc.collect()
    res["retained_bytes"] = rss() - base_rss

    hit = np.load(os.path.join(work, "hit_rays.npy"))
    hit_t = np.load(os.path.join(work, "hit_tmax.npy"))
    occ = np.load(os.path.join(work, "occ_rays.npy"))
    occ_t = np.load(os.path.join(work, "occ_tmax.npy"))
    ho, hd = np.ascontiguousarray(hit[:, :3]), np.ascontiguousarray(hit[:, 3:])
    oo, od = np.ascontiguousarray(occ[:, :3]), np.ascontiguousarray(occ[:, 3:])

    def query(o, d, tmax, kind, nthreads):
        # embreex writes tfar into `dists` in place: a fresh copy each call.
        kw = {"output": True} if kind == "INTERSECT" else {"query": "OCCLUDED"}
        if args.worker == "displace":
            return engine.run(o, d, tmax.copy(), threads=nthreads, **kw)
        if nthreads == 1:
            return engine.run(o, d, tmax.copy(), **kw)
        parts = np.array_split(np.arange(len(o)), nthreads)
        outs = [None] * nthreads

        def one_part(k):
            s = slice(parts[k][0], parts[k][-1] + 1)
            outs[k] = engine.run(o[s], d[s], tmax[s].copy(), **kw)

        pool = [threading.Thread(target=one_part, args=(k,)) for k in range(nthreads)]
        for p in pool:
            p.start()
        for p in pool:
            p.join()
        if kind == "INTERSECT":
            return {key: np.concatenate([x[key] for x in outs]) for key in outs[0]}
        return np.concatenate(outs)

    for nt in threads:
        s, out = best_of(args.repeat, lambda: query(ho, hd, hit_t, "INTERSECT", nt))
        res[f"hit_{nt}"] = len(ho) / s
        s, occl = best_of(args.repeat, lambda: query(oo, od, occ_t, "OCCLUDED", nt))
        res[f"occ_{nt}"] = len(oo) / s
    tag = f"{args.worker}{args.sub}"
    np.save(os.path.join(work, f"{tag}_tfar.npy"), np.where(out["geomID"] == -1, np.inf, out["tfar"]))
    np.save(os.path.join(work, f"{tag}_occ.npy"), occl == 0)

    if args.worker == "displace":
        # The overhead: face.intersect on the (N, 6) rays without t_max, as
        # `displace trace` reads them, paired with runs of the CLI on the
        # same rays, one after the other (see the module's docstring).
        for nt in threads:
            best, cli_best, cli_err = float("inf"), None, None
            command = cli_command(args.cli, work, meta, nt, args.sub) if args.cli else None
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                fh = face.intersect(ho, hd, threads=nt)
                best = min(best, time.perf_counter() - t0)
                if command and not cli_err:
                    rate, cli_err = cli_once(*command[:2])
                    if rate:
                        cli_best = max(cli_best or 0.0, rate)
            res[f"intersect_{nt}"] = len(ho) / best
            if command:
                res[f"cli_{nt}"] = cli_best
                res[f"cli_path_{nt}"] = command[2]
                res[f"cli_error_{nt}"] = cli_err
        np.save(os.path.join(work, f"intersect{args.sub}.npy"),
                np.column_stack([fh["t"], fh["position"], fh["iterations"].astype(np.float32)]))
    print(json.dumps(res))


# -------------------------------------------------------------------- driver --


def find_cli(given):
    if given:
        return given if os.path.exists(given) else None
    p = os.path.join(REPO, "target", "release", "displace")
    return p if os.path.exists(p) else None


def cli_command(exe, work, meta, nthreads, div):
    """`displace trace` on the case's first-hit rays: (argv, environment,
    output path)."""
    w, h, d = map_size(meta["shape"], meta["depth"], div)
    ext = ",".join(f"{v:.9g}" for v in meta["extent"])
    out = os.path.join(work, f"cli{div}_{nthreads}.npy")
    cmd = [exe, "trace", "--height", os.path.join(work, "heights.tif"), "--extent", ext,
           "--size", f"{w}x{h}x{d}", "--rays", os.path.join(work, "hit_rays.npy"),
           "-o", out]
    return cmd, dict(os.environ, RAYON_NUM_THREADS=str(nthreads)), out


def cli_once(cmd, env):
    """One run of the CLI: (its printed rays a second, None) or (None, the
    error's last line)."""
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        return None, (p.stderr.strip().splitlines() or ["?"])[-1]
    m = re.search(r"\(([\d.]+) Mrays/s", p.stdout)
    return (float(m.group(1)) * 1e6 if m else None), None


def same_bits(a, b):
    """Equal as the CLI's and the binding's hits should be: bit for bit, NaN
    for NaN."""
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint32), b.view(np.uint32)))


def prepare_case(name, args, work):
    quick = args.quick
    if name == "dem":
        if args.dem:
            heights, relief = read_dem(args.dem)
            label = os.path.basename(args.dem)
        else:
            n = args.dem_size or (512 if quick else 4096)
            heights, relief = synthetic_dem(n), 1200.0
            label = f"synthetic DEM {n}x{n}"
        rows, cols = heights.shape
        extent = (cols * args.texel, rows * args.texel, relief)
    else:
        import displace

        n = args.studded_size or (256 if quick else 1024)
        heights = displace.bake("gen:studded", size=(n, n, 16)).heights
        extent = (1.0, 1.0, 0.1)
        label = f"gen:studded {n}x{n}"
    heights = np.ascontiguousarray(heights, dtype=np.float32)
    meta = {"name": name, "label": label, "shape": list(heights.shape), "extent": list(extent),
            "depth": args.depth}
    np.save(os.path.join(work, "heights.npy"), heights)
    from PIL import Image

    Image.fromarray(heights, mode="F").save(os.path.join(work, "heights.tif"))
    n_rays = args.rays or (50_000 if quick else 1_000_000)
    r, t = hit_rays(n_rays, heights.shape, extent)
    np.save(os.path.join(work, "hit_rays.npy"), r)
    np.save(os.path.join(work, "hit_tmax.npy"), t)
    r, t = occlusion_rays(n_rays, heights, extent)
    np.save(os.path.join(work, "occ_rays.npy"), r)
    np.save(os.path.join(work, "occ_tmax.npy"), t)
    meta["rays"] = n_rays
    json.dump(meta, open(os.path.join(work, "case.json"), "w"))
    return meta, heights


def run_worker(engine, sub, args, work, cli=None):
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", engine, "--sub", str(sub),
           "--work", work, "--threads", args.threads, "--repeat", str(args.repeat)]
    if cli and engine == "displace":
        cmd += ["--cli", cli]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or [f"exit {p.returncode}"])[-1]
        return {"engine": engine, "sub": sub, "error": f"exit {p.returncode}: {last}"}
    res = json.loads(p.stdout.strip().splitlines()[-1])
    res["wall_s"] = wall
    return res


def engine_name(res, meta):
    """How a table names an engine: displace with its map, embreex with its
    tessellation."""
    if res["engine"] == "displace":
        w, h, d = map_size(meta["shape"], meta["depth"], res["sub"])
        return f"displace, map {w}x{h}x{d}"
    return f"embreex x{res['sub']}"


def fmt(v, spec):
    return "-" if v is None else format(v, spec)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes: a smoke run")
    ap.add_argument("--rays", type=int, help="rays per query kind (default 1e6, --quick 5e4)")
    ap.add_argument("--dem", help="a one-band TIFF elevation model instead of the synthetic one")
    ap.add_argument("--texel", type=float, default=30.0, help="DEM metres per texel (default 30)")
    ap.add_argument("--dem-size", type=int, help="synthetic DEM texels a side (default 4096, --quick 512)")
    ap.add_argument("--studded-size", type=int, help="studded texels a side (default 1024, --quick 256)")
    ap.add_argument("--depth", type=int, default=16, help="distance-map voxels in z (default 16)")
    ap.add_argument("--cases", default="dem,studded")
    ap.add_argument("--sub", default="1,4", help="embreex tessellations: cells split k x k (default 1,4)")
    ap.add_argument("--map-div", default="4,1",
                    help="displace's distance maps: k x k texels a voxel column, the first compared "
                         "with embreex in the ratio rows (default 4,1)")
    ap.add_argument("--threads", default="1,2", help="thread counts timed (default 1,2)")
    ap.add_argument("--repeat", type=int, help="best of this many (default 3, --quick 1)")
    ap.add_argument("--displace-bin", help="the displace CLI (default target/release/displace)")
    ap.add_argument("--force", action="store_true", help="run engines estimated not to fit in memory")
    ap.add_argument("--keep", help="work directory to keep (default: a temporary one, removed)")
    # The worker mode (one engine in a fresh process).
    ap.add_argument("--worker", choices=["displace", "embreex"], help=argparse.SUPPRESS)
    ap.add_argument("--work", help=argparse.SUPPRESS)
    ap.add_argument("--cli", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.repeat is None:
        args.repeat = 1 if args.quick else 3
    if args.worker:
        args.sub = int(args.sub)
        return worker(args)

    threads = [int(t) for t in args.threads.split(",")]
    subs = [int(s) for s in args.sub.split(",")]
    divs = [int(s) for s in args.map_div.split(",")]
    cli = find_cli(args.displace_bin)
    top = args.keep or tempfile.mkdtemp(prefix="bench-python-peers-")
    os.makedirs(top, exist_ok=True)
    print(f"# displace vs embreex from Python ({os.cpu_count()} cores; work dir {top})\n")
    rows_out, overhead, notes = [], [], []
    try:
        for name in args.cases.split(","):
            work = os.path.join(top, name)
            os.makedirs(work, exist_ok=True)
            t0 = time.perf_counter()
            meta, heights = prepare_case(name, args, work)
            print(f"{meta['label']}: extent {tuple(round(v, 6) for v in meta['extent'])}, "
                  f"{meta['rays']} rays a query, set up in {time.perf_counter() - t0:.1f} s", flush=True)
            results = []
            engines = [("displace", d) for d in divs] + [("embreex", s) for s in subs]
            for engine, sub in engines:
                need = estimate_bytes(engine, heights.shape, args.depth, sub)
                if need > 0.8 * available_bytes() and not args.force:
                    res = {"engine": engine, "sub": sub,
                           "error": f"skipped: needs ~{need / 2**30:.0f} GiB (--force to try)"}
                else:
                    res = run_worker(engine, sub, args, work, cli)
                print(f"  {engine_name(res, meta)}: "
                      f"{res.get('error') or 'done in %.1f s' % res['wall_s']}", flush=True)
                results.append(res)
            dis = results[0]
            # Agreement with the first displace on the same rays.
            if "error" not in dis:
                t_d = np.load(os.path.join(work, f"displace{dis['sub']}_tfar.npy"))
                o_d = np.load(os.path.join(work, f"displace{dis['sub']}_occ.npy"))
                for res in results[1:]:
                    if "error" in res or res["engine"] != "embreex":
                        continue
                    t_e = np.load(os.path.join(work, f"embreex{res['sub']}_tfar.npy"))
                    o_e = np.load(os.path.join(work, f"embreex{res['sub']}_occ.npy"))
                    both = np.isfinite(t_d) & np.isfinite(t_e)
                    res["hit_agree"] = float((np.isfinite(t_d) == np.isfinite(t_e)).mean())
                    res["occ_agree"] = float((o_d == o_e).mean())
                    res["median_dt"] = float(np.median(np.abs(t_d[both] - t_e[both]))) if both.any() else None
                dis["hits"] = int(np.isfinite(t_d).sum())
                dis["blocked"] = int(o_d.sum())
            for res in results:
                res["case"] = meta["label"]
            rows_out.append((meta, results))

            # The binding's overhead against the CLI, for each map size.
            for res in results:
                if not cli or res["engine"] != "displace" or "error" in res:
                    continue
                div = res["sub"]
                ref = np.load(os.path.join(work, f"intersect{div}.npy"))
                for nt in threads:
                    rate, path, err = (res.get(f"cli_{nt}"), res.get(f"cli_path_{nt}"),
                                       res.get(f"cli_error_{nt}"))
                    if err:
                        path = None
                    same = same_bits(np.load(path), ref) if path else None
                    overhead.append({"case": meta["label"], "map": engine_name(res, meta),
                                     "threads": nt, "cli": rate, "py": res.get(f"intersect_{nt}"),
                                     "same": same, "error": err})
            if not cli:
                notes.append("no displace CLI (target/release/displace or --displace-bin): "
                             "the binding's overhead was not measured")
    finally:
        if not args.keep:
            shutil.rmtree(top, ignore_errors=True)

    print_tables(rows_out, overhead, threads, cli, notes)


def print_tables(rows_out, overhead, threads, cli, notes):
    print()
    head = ["case", "engine", "set-up s", "peak MiB", "resident MiB"]
    head += [f"hits/s {t}T (M)" for t in threads] + [f"occl/s {t}T (M)" for t in threads]
    head += ["hit agree", "occl agree", "median abs dt"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    gil = []
    for meta, results in rows_out:
        for res in results:
            name = engine_name(res, meta)
            if "error" in res:
                print(f"| {meta['label']} | {name} | {res['error']} |" + " |" * (len(head) - 3))
                continue
            if res["engine"] == "embreex" and "triangles" in res:
                name += f" ({res['triangles'] / 1e6:.1f}M tris)"
            cells = [meta["label"], name, fmt(res["setup_s"], ".3f"),
                     fmt(res["peak_bytes"] / MIB, ".0f"), fmt(res["retained_bytes"] / MIB, ".0f")]
            cells += [fmt(res.get(f"hit_{t}", 0) / 1e6, ".2f") for t in threads]
            cells += [fmt(res.get(f"occ_{t}", 0) / 1e6, ".2f") for t in threads]
            if res["engine"] == "displace":
                cells += [f"({res.get('hits', '?')} hits)", f"({res.get('blocked', '?')} blocked)", ""]
            else:
                cells += [fmt(res.get("hit_agree"), ".5f"), fmt(res.get("occ_agree"), ".5f"),
                          fmt(res.get("median_dt"), ".2g")]
                if len(threads) > 1:
                    gil.append((meta["label"], res["sub"],
                                res[f"hit_{threads[-1]}"] / res[f"hit_{threads[0]}"],
                                res[f"occ_{threads[-1]}"] / res[f"occ_{threads[0]}"]))
            print("| " + " | ".join(cells) + " |")
        # Ratios displace / embreex: set-up and memory below 1, speed above
        # 1 are in displace's favour.
        pairs = [(d, e) for d in results if d["engine"] == "displace"
                 for e in results if e["engine"] == "embreex"]
        for dis, res in pairs:
            if "error" in dis or "error" in res:
                continue
            cells = [meta["label"], f"**{engine_name(dis, meta)} / embreex x{res['sub']}**",
                     f"{dis['setup_s'] / res['setup_s']:.3f}",
                     f"{dis['peak_bytes'] / max(res['peak_bytes'], 1):.3f}",
                     f"{dis['retained_bytes'] / max(res['retained_bytes'], 1):.3f}"]
            cells += [f"{dis[f'hit_{t}'] / res[f'hit_{t}']:.2f}" for t in threads]
            cells += [f"{dis[f'occ_{t}'] / res[f'occ_{t}']:.2f}" for t in threads]
            cells += ["", "", ""]
            print("| " + " | ".join(cells) + " |")
    if any("error" not in r and not r.get("peak_reset", True) for _, rs in rows_out for r in rs):
        print("\n(the peak could not be reset here: peak MiB are floors, over the imports' own peak)")
    print()
    print("Ratios are displace / embreex: below 1 is better for set-up and memory, above 1 for speed. "
          "Set-up: the bake against tessellation + TriangleMesh + BVH build; both on every core.")
    for label, sub, s_hit, s_occ in gil:
        verdict = (f"releases the GIL: its {threads[-1]}-thread figures are {threads[-1]} Python "
                   "threads over parts of the rays"
                   if max(s_hit, s_occ) > 1.3 else
                   "does not scale on Python threads (GIL held?): read its 1-thread figures")
        print(f"- embreex x{sub} on {label}: {threads[-1]} threads / {threads[0]}: hits {s_hit:.2f}, "
              f"occlusion {s_occ:.2f}: {verdict}")
    for meta, results in rows_out:
        for res in results:
            if "setup_parts" in res:
                p = res["setup_parts"]
                print(f"- embreex x{res['sub']} on {meta['label']}: tessellate {p['tessellate']:.2f} s, "
                      f"TriangleMesh {p['TriangleMesh']:.2f} s, BVH {p['bvh']:.2f} s; "
                      f"mesh arrays {res['mesh_bytes'] / MIB:.0f} MiB")
            elif res["engine"] == "displace" and "held_bytes" in res:
                print(f"- {engine_name(res, meta)} on {meta['label']}: face.nbytes {res['held_bytes'] / MIB:.0f} MiB")

    if overhead:
        print()
        print(f"Binding overhead: `displace trace` ({cli}) against `face.intersect`, same rays")
        if "debug" in cli:
            print("(a debug-profile CLI: comparable only with a package built the same way, as "
                  "scripts/test-python.sh builds it (--profile dev); build both --release for the figures)")
        print()
        print("| case | engine | threads | CLI trace Mrays/s | face.intersect Mrays/s | intersect / CLI | same bits |")
        print("|---|---|---|---|---|---|---|")
        for o in overhead:
            if o["error"]:
                print(f"| {o['case']} | {o['map']} | {o['threads']} | {o['error']} | | | |")
                continue
            ratio = o["py"] / o["cli"] if o["cli"] and o["py"] else None
            same = "-" if o["same"] is None else ("yes" if o["same"] else "**NO**")
            print(f"| {o['case']} | {o['map']} | {o['threads']} | {fmt(o['cli'] and o['cli'] / 1e6, '.2f')} | "
                  f"{fmt(o['py'] and o['py'] / 1e6, '.2f')} | {fmt(ratio, '.3f')} | {same} |")
    for n in notes:
        print(f"\nNote: {n}")


if __name__ == "__main__":
    main()
