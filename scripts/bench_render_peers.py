#!/usr/bin/env python3
"""Side-by-side benchmark of displace against the renderers a user would pick
instead: Mitsuba 3 (`llvm_ad_rgb`, `direct`) for whole renders and image
difference, Embree (through `embreex`) for first-hit and shadow rays per
second, on the same rays read from the same files: the camera's rays, and
the shadow rays from our first hits to the light, traced by
`displace trace --scene` (first hits, `--any-hit`) and by Embree's
intersect and occluded queries.

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

`--maps` takes the seed scenes' generated faces by name (`studded`,
`gaussian`) and square PNG height maps by path, e.g. the real terrain and
photograph that `scripts/real_height_maps.py` writes:

    python3 scripts/real_height_maps.py --out W
    python3 scripts/bench_render_peers.py --maps studded,W/terrain.png,W/photo.png

or, the same in one step (the two real maps written into the workdir):

    python3 scripts/bench_render_peers.py --real

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


def camera_rays(n, view=None):
    """Rays through the pixel centres of an n x n image, as
    displace_render::camera::Camera::ray makes them (pinhole); written once
    to a file that both tools read. `view` is (position, look_at, up, vfov),
    this script's camera by default."""
    f = (np.arange(n) + 0.5) / n
    fx, fy = np.meshgrid(f, f)
    return film_rays(fx, fy, view)


def film_rays(fx, fy, view=None):
    """Pinhole rays through film points `(fx, fy)` (arrays of one shape, in
    [0, 1] from the image's top left), in their order flattened: float32
    origins and unit directions, as `camera_rays`."""
    pos, look, up, vfov = view or (*camera(), VFOV)
    fwd = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    t = math.tan(math.radians(vfov) / 2)
    sx = ((2 * fx - 1) * t).reshape(-1, 1)
    sy = ((1 - 2 * fy) * t).reshape(-1, 1)
    d = fwd + sx * right + sy * upv
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(pos, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def toml_vec(a):
    return "[" + ", ".join(repr(float(x)) for x in a) + "]"


def scene_header(size, spp, view, light, albedo, source):
    """The scene TOML every peer benchmark shares before its shape: the
    image, the pinhole `view` (position, look_at, up, vfov), one white
    Lambertian material and one point `light` (position, intensity)."""
    pos, look, up, vfov = view
    v = toml_vec
    return f"""# written by {source}
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
vfov = {vfov}

[materials.white]
type = "lambert"
color = {v([albedo] * 3)}

[[lights]]
type = "point"
position = {v(light[0])}
intensity = {v([light[1]] * 3)}
"""


# A height file's face: its extent's depth and its distance map's size (the
# studded face's, which the render benchmark's camera and light were set for).
FILE_DEPTH = 0.1
FILE_MAP_SIZE = (256, 256, 16)


def png_size(path):
    """Width and height from a PNG's IHDR chunk (no imaging library needed)."""
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        sys.exit(f"{path}: not a PNG file (--maps takes PNG height maps by path)")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def map_spec(m):
    """(name, source, texels, extent, map size) of a `--maps` entry: a seed
    face by name, or a square PNG height map by path (its file name's stem
    names it), on a unit face `FILE_DEPTH` deep."""
    if m in MAPS:
        return (m, *MAPS[m])
    if not os.path.isfile(m):
        sys.exit(f"--maps: {m!r} is neither one of {sorted(MAPS)} nor a file")
    w, h = png_size(m)
    if w != h:
        sys.exit(f"{m}: {w}x{h} texels; the benchmark's face is square (crop it)")
    name = os.path.splitext(os.path.basename(m))[0]
    return (name, os.path.abspath(m), w, (1.0, 1.0, FILE_DEPTH), FILE_MAP_SIZE)


def scene_toml(spec, size, spp):
    """The benchmark's scene of one face, `spec` as `map_spec` gives it."""
    _, src, texels, (sx, sy, sz), msize = spec
    view = (*camera(), VFOV)
    light = (LIGHT_POS, LIGHT_INTENSITY)
    v = toml_vec
    return scene_header(size, spp, view, light, ALBEDO, "scripts/bench_render_peers.py") + f"""
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
    """The binary PLY that `displace export-mesh` writes: float32 vertex
    properties starting with x y z (8 for a height field: x y z nx ny nz u
    v; 5 for a scene's surface: x y z u v), faces as (uchar 3, int32 x 3)."""
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            header += f.readline()
        nv = int(re.search(rb"element vertex (\d+)", header).group(1))
        nf = int(re.search(rb"element face (\d+)", header).group(1))
        vertex_part = header.split(b"element face")[0]
        k = len(re.findall(rb"property float ", vertex_part))
        verts = np.fromfile(f, np.float32, nv * k).reshape(nv, k)
        faces = np.fromfile(f, np.dtype([("n", "u1"), ("i", "<i4", 3)]), nf)
    assert (faces["n"] == 3).all()
    return np.ascontiguousarray(verts[:, :3]), np.ascontiguousarray(faces["i"])


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


# ---------------------------------------------------------------- workers


def worker_embree(ply, rays_path, shadow_path, threads, repeat):
    from concurrent.futures import ThreadPoolExecutor
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    t = time.perf_counter()
    verts, faces = read_ply(ply)
    load_s = time.perf_counter() - t
    rays = np.load(rays_path)
    o, d = np.ascontiguousarray(rays[:, :3]), np.ascontiguousarray(rays[:, 3:6])
    shadow = np.load(shadow_path)
    so, sd = np.ascontiguousarray(shadow[:, :3]), np.ascontiguousarray(shadow[:, 3:6])
    st = np.ascontiguousarray(shadow[:, 6])
    before = rss_mb()
    t = time.perf_counter()
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, verts, faces)
    scene.run(o[:1], d[:1])  # embreex commits (builds the BVH) on first use
    build_s = time.perf_counter() - t
    structure_mb = rss_mb() - before
    out = {"load_s": load_s, "build_s": build_s, "structure_mb": structure_mb,
           "mesh_mb": (verts.nbytes + faces.nbytes) / 2**20, "triangles": len(faces)}

    def timed(k, n, one):
        chunks = np.array_split(np.arange(n), 64 * k)
        with ThreadPoolExecutor(k) as ex:
            found = sum(ex.map(one, chunks))  # warm-up
            best = math.inf
            for _ in range(repeat):
                t0 = time.perf_counter()
                sum(ex.map(one, chunks))
                best = min(best, time.perf_counter() - t0)
        return n / best / 1e6, found

    def first(idx):
        # output=1: u, v, Ng, t, ids, as a first hit that is shaded needs.
        r = scene.run(o[idx], d[idx], output=1)
        return int((r["geomID"] >= 0).sum())

    def occluded(idx):
        r = scene.run(so[idx], sd[idx], dists=st[idx], query="OCCLUDED")
        return int((r >= 0).sum())

    out["mrays_1t"], out["hits"] = timed(1, len(o), first)
    out["mrays_nt"], _ = timed(threads, len(o), first)
    out["shadow_1t"], out["blocked"] = timed(1, len(so), occluded)
    out["shadow_nt"], _ = timed(threads, len(so), occluded)
    print(json.dumps(out))


def worker_mitsuba(ply, size, spp, view=None, light=None, albedo=ALBEDO, repeat=1):
    """Mitsuba 3 (`llvm_ad_rgb`, `direct`) renders the PLY mesh under `view`
    (position, look_at, up, vfov) lit by the point `light` (position,
    intensity), this script's scene by default; prints the load time, both
    renders' times and where the second render's image is. The render time
    is the best of `repeat` renders after the first (which compiles the
    LLVM kernels), as `render_ours` takes the best of as many of ours."""
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    pos, look, up, vfov = view or (*camera(), VFOV)
    light_pos, intensity = light or (LIGHT_POS, LIGHT_INTENSITY)
    t = time.perf_counter()
    scene = mi.load_dict({
        "type": "scene",
        # One shadow ray per sample, as ours; a point light cannot be hit by
        # BSDF samples, so they would only cost rays.
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "perspective", "fov": vfov, "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=pos.tolist(), target=look.tolist(), up=up.tolist()),
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "mesh": {"type": "ply", "filename": ply,
                 "bsdf": {"type": "diffuse",
                          "reflectance": {"type": "rgb", "value": albedo}}},
        "light": {"type": "point", "position": list(light_pos),
                  "intensity": {"type": "rgb", "value": intensity}},
    })
    load_s = time.perf_counter() - t
    times = []
    for k in range(1 + max(1, repeat)):  # the first includes the LLVM kernel compile
        t = time.perf_counter()
        img = np.array(mi.render(scene, seed=min(k, 1)))
        times.append(time.perf_counter() - t)
    out_path = ply.replace(".ply", ".mitsuba.npy")
    np.save(out_path, img[..., :3].astype(np.float32))
    print(json.dumps({"load_s": load_s, "first_s": times[0], "render_s": min(times[1:]),
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


def render_ours(exe, toml, out, repeat, env):
    """`displace render` of `toml` to `out`, `repeat` times, each in its own
    process: the best render time (after the scene load, as it prints it)
    and the peak MB of any run. Every run renders the same image (the
    renders are deterministic)."""
    best, peak = math.inf, 0.0
    for _ in range(max(1, repeat)):
        _, err, _, rss = run_measured([exe, "render", toml, "-o", out, "--no-cache", "-q"], env)
        best = min(best, float(re.search(r"render ([\d.]+) s", err).group(1)))
        peak = max(peak, rss)
    return best, peak


def trace_ours(exe, toml, rays, out, threads, repeat, env, any_hit=False):
    """`displace trace --scene` on `threads` threads, best of `repeat` runs:
    Mrays/s as it prints them (the queries alone, not the scene load), the
    fastest load (bake included, no cache), the maps' MB, and the peak MB of
    the process. Each run times its queries as `worker_embree` times
    Embree's: a first pass untimed (it wakes the thread pool and faults in
    the buffers), then the best of `repeat` passes (`--repeat`)."""
    env = dict(env, RAYON_NUM_THREADS=str(threads))
    cmd = [exe, "trace", "--scene", toml, "--rays", rays, "-o", out, "--no-cache",
           "--repeat", str(repeat)]
    if any_hit:
        cmd.append("--any-hit")
    best, load, maps, peak, found = 0.0, math.inf, 0.0, 0.0, 0
    for _ in range(repeat):
        text, _, _, rss = run_measured(cmd, env)
        m = re.search(r"loaded the scene in ([\d.]+) s \(displacement maps ([\d.]+) MB\)", text)
        r = re.search(r"traced \d+ rays \((\d+) \w+\) in [\d.]+ s \(([\d.]+) Mrays/s", text)
        best = max(best, float(r.group(2)))
        found = int(r.group(1))
        load = min(load, float(m.group(1)))
        maps, peak = float(m.group(2)), max(peak, rss)
    return {"mrays": best, "load_s": load, "maps_mb": maps * 1e6 / 2**20, "rss": peak,
            "found": found}


def shadow_rays(hits_path, rays_path, out_path, light_pos=LIGHT_POS):
    """The render's shadow rays from our first hits: from each hit (just off
    the surface on the camera's side) to the point light at `light_pos`,
    where the light is above the surface: `(N, 7)`, t_max just short of the
    light."""
    hits, rays = np.load(hits_path), np.load(rays_path)
    ok = np.isfinite(hits[:, 0])
    p, n, d = hits[ok, 1:4], hits[ok, 4:7], rays[ok, 3:6]
    n = np.where((np.sum(n * d, axis=1) > 0)[:, None], -n, n)
    o = p + n * 1e-4
    to = np.array(light_pos, np.float32) - o
    lit = np.sum(to * n, axis=1) > 0
    out = np.concatenate([o[lit], to[lit], np.full((lit.sum(), 1), 1.0 - 1e-4)], axis=1)
    np.save(out_path, out.astype(np.float32))
    return len(out)


def setup(displace, workdir, prefix):
    """What a benchmark's main starts from: the environment (with Mitsuba's
    LLVM, `DRJIT_LIBLLVM_PATH`, where one is installed and none is set),
    the absolute path of the built `displace` binary (exits if it is not
    there) and the work folder (`workdir`, or a new temporary one named
    `prefix...`), created."""
    env = dict(os.environ)
    llvm = sorted(glob.glob("/usr/lib/*/libLLVM.so.19*") + glob.glob("/usr/lib/*/libLLVM-19*.so*"))
    if llvm and "DRJIT_LIBLLVM_PATH" not in env:
        env["DRJIT_LIBLLVM_PATH"] = llvm[0]
    exe = os.path.abspath(displace)
    if not os.access(exe, os.X_OK):
        sys.exit(f"{exe}: not built (cargo build --release -p displace-cli)")
    work = workdir or tempfile.mkdtemp(prefix=prefix)
    os.makedirs(work, exist_ok=True)
    return env, exe, work


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--displace", default="target/release/displace")
    ap.add_argument("--maps", default="studded,gaussian",
                    help="comma-separated: seed faces by name, square PNG height maps by path")
    ap.add_argument("--real", action="store_true",
                    help="also the real terrain and photograph of scripts/real_height_maps.py "
                         "(needs matplotlib and pillow)")
    ap.add_argument("--scales", default="1,4")
    ap.add_argument("--size", type=int, default=512, help="image size (square)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rays", type=int, default=1000, help="first-hit rays: an NxN grid")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workdir", default=None, help="keep meshes and images here")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--ply", help=argparse.SUPPRESS)
    ap.add_argument("--ray-file", help=argparse.SUPPRESS)
    ap.add_argument("--shadow-file", help=argparse.SUPPRESS)
    a = ap.parse_args()

    if a.worker == "embree":
        return worker_embree(a.ply, a.ray_file, a.shadow_file, a.threads, a.repeat)
    if a.worker == "mitsuba":
        return worker_mitsuba(a.ply, a.size, a.spp, repeat=a.repeat)

    env, exe, work = setup(a.displace, a.workdir, "displace-peers-")
    me = [sys.executable, os.path.abspath(__file__)]
    rows = []
    entries = a.maps.split(",")
    if a.real:
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        import real_height_maps

        entries += real_height_maps.write_all(work)
    for entry in entries:
        spec = map_spec(entry)
        m, src, texels, ext, _ = spec
        toml = os.path.join(work, f"{m}.toml")
        with open(toml, "w") as f:
            f.write(scene_toml(spec, a.size, a.spp))
        # Ours: whole render (bake included, no disk cache) and first-hit rays.
        ours_img = os.path.join(work, f"{m}.ours.exr")
        render_s, rss = render_ours(exe, toml, ours_img, a.repeat, env)
        img_ours = read_linear(ours_img)
        # First hits and the shadow rays from them: the same files go to
        # `displace trace --scene` and to Embree.
        rays_path = os.path.join(work, "rays.npy")
        if not os.path.exists(rays_path):
            o, d = camera_rays(a.rays)
            np.save(rays_path, np.concatenate([o, d], axis=1))
        hits_path = os.path.join(work, f"{m}.hits.npy")
        shadow_path = os.path.join(work, f"{m}.shadow.npy")
        first_1 = trace_ours(exe, toml, rays_path, hits_path, 1, a.repeat, env)
        first_n = trace_ours(exe, toml, rays_path, hits_path, a.threads, a.repeat, env)
        n_shadow = shadow_rays(hits_path, rays_path, shadow_path)
        blocked_path = os.path.join(work, f"{m}.blocked.npy")
        shadow_1 = trace_ours(exe, toml, shadow_path, blocked_path, 1, a.repeat, env, True)
        shadow_n = trace_ours(exe, toml, shadow_path, blocked_path, a.threads, a.repeat, env, True)
        rows.append({
            "map": m, "tool": "displace", "tris": "-",
            "setup_s": first_n["load_s"], "render_s": render_s,
            "rss_render": rss, "rss_rays": first_n["rss"],
            "mrays_1t": first_1["mrays"], "mrays_nt": first_n["mrays"],
            "shadow_1t": shadow_1["mrays"], "shadow_nt": shadow_n["mrays"],
            "memory_mb": first_n["maps_mb"], "shadow_rays": n_shadow,
            "blocked": shadow_n["found"], "rmse": None, "hits": first_n["found"],
        })
        ours = rows[-1]
        for k in [int(s) for s in a.scales.split(",")]:
            ply = os.path.join(work, f"{m}.x{k}.ply")
            # A generated map is told its size; a file has its own.
            sized = ["--height-size", f"{texels}x{texels}"] if src.startswith("gen:") else []
            _, _, mesh_s, _ = run_measured(
                [exe, "export-mesh", src, *sized,
                 "--extent", ",".join(map(str, ext)), "--scale", str(k), "-o", ply], env)
            out, _, _, rss_e = run_measured(
                me + ["--worker", "embree", "--ply", ply, "--ray-file", rays_path,
                      "--shadow-file", shadow_path,
                      "--threads", str(a.threads), "--repeat", str(a.repeat)], env)
            e = json.loads(out.strip().splitlines()[-1])
            out, _, wall_m, rss_m = run_measured(
                me + ["--worker", "mitsuba", "--ply", ply, "--size", str(a.size),
                      "--spp", str(a.spp), "--repeat", str(a.repeat)], env)
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
                "shadow_1t": e["shadow_1t"], "shadow_nt": e["shadow_nt"], "blocked": e["blocked"],
                "memory_mb": e["structure_mb"] + e["mesh_mb"],
                "hits": e["hits"], "mitsuba_load_s": r["load_s"], "mitsuba_first_s": r["first_s"],
                "render_s": r["render_s"], "rss_render": rss_m, "rmse": rmse,
            })
        ours["mean"] = float(img_ours.mean())

    n = a.rays * a.rays
    t = a.threads
    print(f"\n{a.size}x{a.size} image at {a.spp} spp (direct light, one point light); "
          f"first hits: {n} camera rays 45 degrees down, shadow rays from our hits to the "
          f"light; {t} threads; workdir {work}")
    print(f"{'map':<9} {'surface':<22} {'tris':>9} {'setup s':>18} {'memory':>8} "
          f"{'first hits Mrays/s':>18} {'shadow Mrays/s':>16} {'render s':>16} {'RMSE':>8}")
    print(f"{'':<9} {'':<22} {'':>9} {'':>18} {'MB':>8} {'1 thr':>8} {f'{t} thr':>9} "
          f"{'1 thr':>7} {f'{t} thr':>8} {'':>16} {'vs ours':>8}")
    for r in rows:
        if r["tool"] == "displace":
            surf = "displace (bake+trace)"
            setup_s = f"load {r['setup_s']:.2f}"
            rend = f"{r['render_s']:.2f}"
            rmse = f"mean {r['mean']:.3f}"
        else:
            surf = f"{r['tool']}: Embree/Mitsuba"
            setup_s = f"bvh {r['embree_build_s']:.2f}"
            rend = f"{r['render_s']:.2f} (1st {r['mitsuba_first_s']:.1f})"
            rmse = f"{r['rmse']:.4f}"
        print(f"{r['map']:<9} {surf:<22} {str(r['tris']):>9} {setup_s:>18} {r['memory_mb']:>8.1f} "
              f"{r['mrays_1t']:>8.2f} {r['mrays_nt']:>9.2f} {r['shadow_1t']:>7.2f} "
              f"{r['shadow_nt']:>8.2f} {rend:>16} {rmse:>8}")
    print("\nsetup: ours = scene load with the bake (no cache); mesh = Embree BVH build; "
          "mesh export times: " +
          ", ".join(f"{r['map']} {r['tool']} {r['mesh_s']:.2f} s" for r in rows if "mesh_s" in r))
    print("memory: ours = the displacement maps (heights, normals, distance values and codes); "
          "mesh = Embree's resident growth at build plus the vertex and index arrays")
    loads = ", ".join(f"{r['map']} {r['tool']} {r['mitsuba_load_s']:.2f} s"
                      for r in rows if "mitsuba_load_s" in r)
    print(f"render: whole render after scene load, the best of {a.repeat} runs each (Mitsuba: "
          f"of {a.repeat} renders after its first, which compiles its kernels; loads: {loads})")
    print(f"Mitsuba's LLVM: {env.get('DRJIT_LIBLLVM_PATH', 'Dr.Jit default')}")
    print(f"\nratios ({t} threads; first hits and shadow rays: ours / Embree, at least 1 wanted; "
          "memory and setup against the x4 mesh: at most 0.5 and 0.25 wanted; render: ours / "
          "Mitsuba's faster, at most 3 wanted)")
    for m in dict.fromkeys(r["map"] for r in rows):
        ours = next(r for r in rows if r["map"] == m and r["tool"] == "displace")
        meshes = [r for r in rows if r["map"] == m and r["tool"] != "displace"]
        for r in meshes:
            print(f"  {m} vs {r['tool']}: first hits {ours['mrays_nt'] / r['mrays_nt']:.2f}, "
                  f"shadow {ours['shadow_nt'] / r['shadow_nt']:.2f}, "
                  f"memory {ours['memory_mb'] / r['memory_mb']:.3f}, "
                  f"setup {ours['setup_s'] / r['embree_build_s']:.3f}")
        fastest = min(r["render_s"] for r in meshes)
        print(f"  {m} render: ours {ours['render_s']:.2f} s / Mitsuba {fastest:.2f} s = "
              f"{ours['render_s'] / fastest:.1f}")
    with open(os.path.join(work, "results.json"), "w") as f:
        json.dump({"args": vars(a), "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
