#!/usr/bin/env python3
"""Side-by-side benchmark of displace against the renderers a user would pick
instead (issue 3, "Benchmarks"): Mitsuba 3 (`llvm_ad_rgb`, `direct`) for
whole renders and image difference, Embree (through `embreex`) for first-hit
rays per second on the same camera rays.

The same surface for all: `displace export-mesh` writes the height field as
a triangle grid at the height map's resolution and at 4x; the peers render
that mesh, we render the displaced quad it came from. The scene is one
displaced face (x along u, y along v, z up, the frame of `export-mesh` and
`displace trace`), one Lambertian material, one point light, and a pinhole
camera 45 degrees above the face looking at its centre whose view stays
inside the face (no ray reaches the shell's side walls, which the mesh lacks).

Every measurement runs in its own process, so peak memory (the process's
VmHWM) is that one tool's. Usage:

    pip install -r scripts/requirements-bench.txt
    cargo build --release -p displace-cli
    python3 scripts/bench_render_peers.py [--size 512] [--spp 16] [--rays 1000]

Mitsuba's LLVM backend is pointed at `libLLVM-19` when one is installed
(`DRJIT_LIBLLVM_PATH`; LLVM 15 is known to crash).
"""

import argparse
import glob
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

# Height maps of the seed scenes: (name, source, texels, extent SX,SY,SZ, map size).
MAPS = {
    "studded": ("gen:studded?period=32", 256, (1.0, 1.0, 0.1), (256, 256, 16)),
    "gaussian": ("gen:gaussian", 512, (1.0, 1.0, 0.3), (256, 256, 32)),
}
# 45 degrees down onto the face centre; vfov keeps the view inside the face
# with a margin of more than a shell depth (see the module docstring).
CAMERA_DISTANCE = 1.2
VFOV = 20.0
LIGHT_POS = (-0.2, 0.3, 0.9)
LIGHT_INTENSITY = 1.5
ALBEDO = 0.7


def camera():
    c = np.array([0.5, 0.5, 0.0])
    s = math.sqrt(0.5)
    pos = c + CAMERA_DISTANCE * np.array([0.0, -s, s])
    return pos, c, np.array([0.0, 0.0, 1.0])


def camera_rays(n):
    """Rays through the pixel centres of an n x n image, as
    displace_render::camera::Camera::ray makes them (pinhole)."""
    pos, look, up = camera()
    fwd = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    t = math.tan(math.radians(VFOV) / 2)
    f = (np.arange(n) + 0.5) / n
    fx, fy = np.meshgrid(f, f)
    sx = ((2 * fx - 1) * t).reshape(-1, 1)
    sy = ((1 - 2 * fy) * t).reshape(-1, 1)
    d = fwd + sx * right + sy * upv
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(pos, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def scene_toml(m, size, spp):
    src, texels, (sx, sy, sz), msize = MAPS[m]
    pos, look, up = camera()
    v = lambda a: "[" + ", ".join(repr(float(x)) for x in a) + "]"
    return f"""# written by scripts/bench_render_peers.py
[image]
width = {size}
height = {size}
spp = {spp}
shadow_samples = 1
max_depth = 0
seed = 1

[camera]
position = {v(pos)}
look_at = {v(look)}
up = {v(up)}
vfov = {VFOV}

[materials.white]
type = "lambert"
color = {v([ALBEDO] * 3)}

[[lights]]
type = "point"
position = {v(LIGHT_POS)}
intensity = {v([LIGHT_INTENSITY] * 3)}

[[shapes]]
type = "quad"
origin = [0.0, 0.0, 0.0]
edge_u = {v([sx, 0, 0])}
edge_v = {v([0, sy, 0])}
material = "white"
[shapes.displacement]
height = "{src}"
height_size = [{texels}, {texels}]
depth = {sz}
map_size = {list(msize)}
"""


def read_ply(path):
    """The binary PLY that `displace export-mesh` writes: 8 float32 per
    vertex (x y z nx ny nz u v), faces as (uchar 3, int32 x 3)."""
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            header += f.readline()
        nv = int(re.search(rb"element vertex (\d+)", header).group(1))
        nf = int(re.search(rb"element face (\d+)", header).group(1))
        verts = np.fromfile(f, np.float32, nv * 8).reshape(nv, 8)
        faces = np.fromfile(f, np.dtype([("n", "u1"), ("i", "<i4", 3)]), nf)
    assert (faces["n"] == 3).all()
    return np.ascontiguousarray(verts[:, :3]), np.ascontiguousarray(faces["i"])


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


# ---------------------------------------------------------------- workers


def worker_embree(ply, n, threads, repeat):
    from concurrent.futures import ThreadPoolExecutor
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    t = time.perf_counter()
    verts, faces = read_ply(ply)
    load_s = time.perf_counter() - t
    o, d = camera_rays(n)
    before = rss_mb()
    t = time.perf_counter()
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, verts, faces)
    scene.run(o[:1], d[:1])  # embreex commits (builds the BVH) on first use
    build_s = time.perf_counter() - t
    structure_mb = rss_mb() - before
    out = {"load_s": load_s, "build_s": build_s, "structure_mb": structure_mb,
           "triangles": len(faces)}

    def trace(k):
        # output=1: u, v, Ng, t, ids, as a first hit that is shaded needs.
        chunks = np.array_split(np.arange(len(o)), 64 * k)
        def one(idx):
            r = scene.run(o[idx], d[idx], output=1)
            return int((r["geomID"] >= 0).sum())
        with ThreadPoolExecutor(k) as ex:
            hits = sum(ex.map(one, chunks))  # warm-up
            best = math.inf
            for _ in range(repeat):
                t0 = time.perf_counter()
                sum(ex.map(one, chunks))
                best = min(best, time.perf_counter() - t0)
        return len(o) / best / 1e6, hits

    out["mrays_1t"], out["hits"] = trace(1)
    out["mrays_nt"], _ = trace(threads)
    print(json.dumps(out))


def worker_mitsuba(ply, size, spp):
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    pos, look, up = camera()
    t = time.perf_counter()
    scene = mi.load_dict({
        "type": "scene",
        # One shadow ray per sample, as ours; a point light cannot be hit by
        # BSDF samples, so they would only cost rays.
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "perspective", "fov": VFOV, "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=pos.tolist(), target=look.tolist(), up=up.tolist()),
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "grid": {"type": "ply", "filename": ply,
                 "bsdf": {"type": "diffuse",
                          "reflectance": {"type": "rgb", "value": ALBEDO}}},
        "light": {"type": "point", "position": list(LIGHT_POS),
                  "intensity": {"type": "rgb", "value": LIGHT_INTENSITY}},
    })
    load_s = time.perf_counter() - t
    times = []
    for _ in range(2):  # the first includes the LLVM kernel compile
        t = time.perf_counter()
        img = np.array(mi.render(scene, seed=len(times)))
        times.append(time.perf_counter() - t)
    out_path = ply.replace(".ply", ".mitsuba.npy")
    np.save(out_path, img[..., :3].astype(np.float32))
    print(json.dumps({"load_s": load_s, "first_s": times[0], "render_s": times[1],
                      "image": out_path}))


# ---------------------------------------------------------------- driver


def vm_hwm_mb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def run_measured(cmd, env=None):
    """Runs cmd; (stdout, stderr, wall seconds, peak RSS MB of that process
    alone). The peak is the kernel's high-water mark of the process's own
    memory (VmHWM, polled every 5 ms until it exits; monotonic, so only the
    last few ms can be missed). Not wait4's ru_maxrss: that also counts the
    image a process had before exec, here the size of this Python process."""
    t = time.perf_counter()
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        p = subprocess.Popen(cmd, stdout=fo, stderr=fe, env=env, text=True)
        peak = 0.0
        while p.poll() is None:
            peak = max(peak, vm_hwm_mb(p.pid) or 0.0)
            time.sleep(0.005)
        wall = time.perf_counter() - t
        fo.seek(0)
        fe.seek(0)
        out, err = fo.read(), fe.read()
    if p.returncode != 0:
        sys.exit(f"command failed ({p.returncode}): {' '.join(cmd)}\n{err}")
    return out, err, wall, peak


def read_linear(path):
    if path.endswith(".npy"):
        return np.load(path)
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path))[..., :3]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--displace", default="target/release/displace")
    ap.add_argument("--maps", default="studded,gaussian")
    ap.add_argument("--scales", default="1,4")
    ap.add_argument("--size", type=int, default=512, help="image size (square)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rays", type=int, default=1000, help="first-hit rays: an NxN grid")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workdir", default=None, help="keep meshes and images here")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--ply", help=argparse.SUPPRESS)
    a = ap.parse_args()

    if a.worker == "embree":
        return worker_embree(a.ply, a.rays, a.threads, a.repeat)
    if a.worker == "mitsuba":
        return worker_mitsuba(a.ply, a.size, a.spp)

    env = dict(os.environ)
    llvm = sorted(glob.glob("/usr/lib/*/libLLVM.so.19*") + glob.glob("/usr/lib/*/libLLVM-19*.so*"))
    if llvm and "DRJIT_LIBLLVM_PATH" not in env:
        env["DRJIT_LIBLLVM_PATH"] = llvm[0]
    exe = os.path.abspath(a.displace)
    if not os.access(exe, os.X_OK):
        sys.exit(f"{exe}: not built (cargo build --release -p displace-cli)")
    work = a.workdir or tempfile.mkdtemp(prefix="displace-peers-")
    os.makedirs(work, exist_ok=True)
    me = [sys.executable, os.path.abspath(__file__)]
    rows = []
    for m in a.maps.split(","):
        src, texels, ext, _ = MAPS[m]
        toml = os.path.join(work, f"{m}.toml")
        with open(toml, "w") as f:
            f.write(scene_toml(m, a.size, a.spp))
        # Ours: whole render (bake included, no disk cache) and first-hit rays.
        ours_img = os.path.join(work, f"{m}.ours.exr")
        _, err, wall, rss = run_measured(
            [exe, "render", toml, "-o", ours_img, "--no-cache", "-q"], env)
        mt = re.search(r"setup ([\d.]+) s.*render ([\d.]+) s", err)
        img_ours = read_linear(ours_img)
        out, _, _, rss_b = run_measured(
            [exe, "bench", "render", toml, "--size", f"{a.rays}x{a.rays}", "--spp", "1",
             "--threads", str(a.threads), "--repeat", str(a.repeat), "--tsv"], env)
        hdr, vals = [l.split("\t") for l in out.strip().splitlines()[:2]]
        b = dict(zip(hdr, vals))
        rows.append({
            "map": m, "tool": "displace", "tris": "-",
            "setup_s": float(b["setup_s"]), "render_s": float(mt.group(2)),
            "render_wall_s": wall, "rss_render": rss, "rss_rays": rss_b,
            "mrays_1t": float(b["primary_mrays_1t"]),
            "mrays_nt": float(b[f"primary_mrays_{a.threads}t"]),
            "rmse": None, "hits": int(b["primary_rays"]),
        })
        ours = rows[-1]
        for k in [int(s) for s in a.scales.split(",")]:
            ply = os.path.join(work, f"{m}.x{k}.ply")
            _, _, mesh_s, _ = run_measured(
                [exe, "export-mesh", src, "--height-size", f"{texels}x{texels}",
                 "--extent", ",".join(map(str, ext)), "--scale", str(k), "-o", ply], env)
            out, _, _, rss_e = run_measured(
                me + ["--worker", "embree", "--ply", ply, "--rays", str(a.rays),
                      "--threads", str(a.threads), "--repeat", str(a.repeat)], env)
            e = json.loads(out.strip().splitlines()[-1])
            out, _, wall_m, rss_m = run_measured(
                me + ["--worker", "mitsuba", "--ply", ply, "--size", str(a.size),
                      "--spp", str(a.spp)], env)
            r = json.loads(out.strip().splitlines()[-1])
            img_m = np.load(r["image"])
            rmse = float(np.sqrt(np.mean((img_m - img_ours) ** 2)))
            flipped = float(np.sqrt(np.mean((img_m[:, ::-1] - img_ours) ** 2)))
            if flipped < 0.5 * rmse:
                sys.exit(f"{m} x{k}: Mitsuba's image is mirrored against ours "
                         f"(RMSE {rmse:.4f}, mirrored {flipped:.4f}): camera conventions differ")
            rows.append({
                "map": m, "tool": f"mesh x{k}", "tris": e["triangles"],
                "mesh_s": mesh_s, "embree_build_s": e["build_s"], "embree_mb": e["structure_mb"],
                "rss_rays": rss_e, "mrays_1t": e["mrays_1t"], "mrays_nt": e["mrays_nt"],
                "hits": e["hits"], "mitsuba_load_s": r["load_s"], "mitsuba_first_s": r["first_s"],
                "render_s": r["render_s"], "rss_render": rss_m, "rmse": rmse,
            })
        ours["mean"] = float(img_ours.mean())

    n = a.rays * a.rays
    print(f"\n{a.size}x{a.size} image at {a.spp} spp (direct light, one point light); "
          f"first hits: {n} camera rays 45 degrees down; {a.threads} threads; workdir {work}")
    print(f"{'map':<9} {'surface':<22} {'tris':>9} {'setup s':>18} {'first-hit Mrays/s':>18} "
          f"{'peak MB':>8} {'render s':>16} {'peak MB':>8} {'RMSE':>8}")
    print(f"{'':<9} {'':<22} {'':>9} {'':>18} {'1 thr':>8} {f'{a.threads} thr':>9} "
          f"{'(rays)':>8} {'':>16} {'(render)':>8} {'vs ours':>8}")
    for r in rows:
        if r["tool"] == "displace":
            surf = "displace (bake+trace)"
            setup = f"bake {r['setup_s']:.2f}"
            rend = f"{r['render_s']:.2f}"
            rmse = f"mean {r['mean']:.3f}"
        else:
            surf = f"{r['tool']}: Embree/Mitsuba"
            setup = f"bvh {r['embree_build_s']:.2f} (+{r['embree_mb']:.0f}MB)"
            rend = f"{r['render_s']:.2f} (1st {r['mitsuba_first_s']:.1f})"
            rmse = f"{r['rmse']:.4f}"
        print(f"{r['map']:<9} {surf:<22} {str(r['tris']):>9} {setup:>18} {r['mrays_1t']:>8.2f} "
              f"{r['mrays_nt']:>9.2f} {r['rss_rays']:>8.0f} {rend:>16} {r['rss_render']:>8.0f} {rmse:>8}")
    print("\nsetup: ours = scene build with the bake (no cache); mesh = Embree BVH build "
          "(and its resident-memory growth); mesh export times: " +
          ", ".join(f"{r['map']} {r['tool']} {r['mesh_s']:.2f} s" for r in rows if "mesh_s" in r))
    print("render: whole render after scene load (Mitsuba: second render, after its JIT "
          "compile; loads: " + ", ".join(f"{r['map']} {r['tool']} {r['mitsuba_load_s']:.2f} s"
                                          for r in rows if "mitsuba_load_s" in r) + ")")
    print(f"Mitsuba's LLVM: {env.get('DRJIT_LIBLLVM_PATH', 'Dr.Jit default')}")
    print("peak MB: peak resident memory of the measuring process (ours: bench render / render; "
          "peers: the Python worker, interpreter and rays included)")
    with open(os.path.join(work, "results.json"), "w") as f:
        json.dump({"args": vars(a), "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
