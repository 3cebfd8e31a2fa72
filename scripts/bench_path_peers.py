#!/usr/bin/env python3
"""Our path tracer against Mitsuba 3's on the seed's studded Cornell box
(BENCHMARKS.md): `scenes/cornell_studded_shadows.toml`, its walls, its ceiling
area light and its displaced floor, rendered by `displace render
--integrator path` (the displaced quad, sphere traced) and by Mitsuba 3
(`llvm_ad_rgb`, `path`, the same bounce limit) on the floor tessellated at
the height map's resolution by `displace export-mesh`, at 16, 64 and 256
spp. The mean of two Mitsuba renders at 4096 spp (`independent`, on seeds no
timed render uses) is the reference: the script prints each render's time
and RMSE against it, and our RMSE over Mitsuba's at equal render time
(Mitsuba's RMSE at our time interpolated on its log-log RMSE-time line;
below 1 we are ahead). Since the two converged images differ a little (see
below), a second table gives the noise alone: each render against its own
renderer's converged image (ours: the mean of two renders at --floor-spp on
seeds of their own; Mitsuba's: the reference), less that image's own noise
(half the RMSE between its two renders, subtracted in quadrature), and the
same ratio at equal time. RMSE is over linear RGB clamped to [0, 1] (see
`rmse`).

Conventions matched: the camera (pinhole, vertical fov), one-sided area light
(Mitsuba `rectangle` + `area`), two-sided Lambertian walls (`twosided` +
`diffuse`, as our surfaces are two-sided), the studded floor's mesh in the
quad's frame (`export-mesh` writes x = u, y = v, z = height; the quad's u
runs along world z, v along world x, its normal is +y), box pixel filter.
Bounces: our `max_depth = 4` (pbrt's count: 1 is direct light) is Mitsuba's
`max_depth = 5` (1 there is emitters only). Russian roulette: ours after 3
bounces, Mitsuba's after its default `rr_depth = 5`. The fill light of the
scene is a Whitted stand-in (`fill = true`) and in neither render. What
differs by design: our floor is the bilinear surface with its shell's side
walls, the mesh two triangles per texel and no walls, so the converged
images differ a little (the RMSE floor is printed: our 1024-spp render
against the reference).

Times are render times alone (ours: the `render` seconds `displace render`
prints, after its bake; Mitsuba's: the second `mi.render` call, after the
kernel compile), each the best of `--repeat` runs, on every core. Usage:

    pip install -r scripts/requirements-bench.txt
    cargo build --release -p displace-cli
    python3 scripts/bench_path_peers.py [--size 128] [--spp 16,64,256] [--ref-spp 4096]
        [--sampler sobol|independent] [--mitsuba-sampler independent|ldsampler|...]

Samplers: ours draws Owen-scrambled Sobol points by default (`--sampler`);
Mitsuba's timed renders use `--mitsuba-sampler` (its default, `independent`,
unless told; `ldsampler` is its own (0, 2)-sequence, the like-for-like
comparison of ours), its reference always `independent`.
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

SCENE = "scenes/cornell_studded_shadows.toml"
# The scene file's values, repeated for Mitsuba.
CAMERA = {"position": [278, 273, -800], "look_at": [278, 273, 0], "up": [0, 1, 0], "vfov": 40}
LIGHT = {"origin": [213, 554, 227], "edge_u": [130, 0, 0], "edge_v": [0, 0, 105],
         "radiance": [40, 36, 30]}
MATERIALS = {"white": [0.73, 0.73, 0.73], "red": [0.65, 0.05, 0.05],
             "green": [0.12, 0.45, 0.15]}
# (origin, edge_u, edge_v, material) of the walls and ceiling.
WALLS = [
    ([0, 555, 0], [555, 0, 0], [0, 0, 555], "white"),
    ([0, 0, 555], [0, 555, 0], [555, 0, 0], "white"),
    ([555, 0, 0], [0, 0, 555], [0, 555, 0], "red"),
    ([0, 0, 0], [0, 555, 0], [0, 0, 555], "green"),
]
FLOOR = {"height": "gen:studded?period=32", "texels": 256, "extent": (555, 555, 40),
         "material": "white"}
MAX_DEPTH = 4


def libllvm():
    for pat in ["/usr/lib/llvm-19/lib/libLLVM*.so*", "/usr/lib/x86_64-linux-gnu/libLLVM-19*.so*"]:
        hits = sorted(glob.glob(pat))
        if hits:
            return hits[0]
    return None


def rectangle(mi, origin, eu, ev):
    """Mitsuba's rectangle ([-1, 1]^2 in z = 0, normal +z) onto the
    parallelogram origin + a eu + b ev, normal eu x ev."""
    o, u, v = (np.array(x, float) for x in (origin, eu, ev))
    n = np.cross(u, v)
    n /= np.linalg.norm(n)
    c = o + 0.5 * (u + v)
    m = np.column_stack([0.5 * u, 0.5 * v, n, c])
    m = np.vstack([m, [0, 0, 0, 1]])
    return mi.ScalarTransform4f(m.tolist())


def worker_mitsuba(ply, size, spp, repeat, seed, sampler):
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    diffuse = lambda c: {"type": "twosided",
                         "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": c}}}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH + 1},
        "sensor": {
            "type": "perspective", "fov": CAMERA["vfov"], "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=CAMERA["position"], target=CAMERA["look_at"], up=CAMERA["up"]),
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": sampler, "sample_count": spp},
        },
        "light": {"type": "rectangle",
                  "to_world": rectangle(mi, LIGHT["origin"], LIGHT["edge_u"], LIGHT["edge_v"]),
                  "emitter": {"type": "area",
                              "radiance": {"type": "rgb", "value": LIGHT["radiance"]}},
                  "bsdf": diffuse([0, 0, 0])},
        # Mesh frame (x = u, y = v, z = h) to the floor quad's: world x = v,
        # world y = h, world z = u.
        "floor": {"type": "ply", "filename": ply,
                  "to_world": mi.ScalarTransform4f([[0, 1, 0, 0], [0, 0, 1, 0],
                                                    [1, 0, 0, 0], [0, 0, 0, 1]]),
                  "bsdf": diffuse(MATERIALS[FLOOR["material"]])},
    }
    for k, (o, u, v, m) in enumerate(WALLS):
        scene[f"wall{k}"] = {"type": "rectangle", "to_world": rectangle(mi, o, u, v),
                             "bsdf": diffuse(MATERIALS[m])}
    scene = mi.load_dict(scene)
    t = time.perf_counter()
    mi.render(scene, seed=seed, spp=min(spp, 4))  # the kernel compile
    first = time.perf_counter() - t
    times = []
    for r in range(repeat):
        t = time.perf_counter()
        # spp given each time: a render's spp stays the sampler's count.
        img = np.array(mi.render(scene, seed=seed + 1 + r, spp=spp))
        times.append(time.perf_counter() - t)
    out = ply.replace(".ply", f".mitsuba{spp}.npy")
    np.save(out, img[..., :3].astype(np.float32))
    print(json.dumps({"render_s": min(times), "compile_s": first, "image": out}))


def run(cmd, env=None):
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit(f"command failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr}")
    return p.stdout, p.stderr


def read_exr(path):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path))[..., :3].astype(np.float32)


def ours(exe, size, spp, repeat, work, env, sampler, scene=SCENE, tag=""):
    """Best render time of `repeat` runs (the bake is cached after the
    first) and the image."""
    best, img = math.inf, None
    out = os.path.join(work, f"ours{spp}{tag}.exr")
    for _ in range(repeat):
        _, err = run([exe, "render", scene, "--integrator", "path", "--spp", str(spp),
                      "--size", f"{size}x{size}", "--sampler", sampler, "-q", "-o", out], env)
        m = re.search(r"render ([\d.]+) s", err)
        best = min(best, float(m.group(1)))
    img = read_exr(out)
    return best, img


def rmse(a, b):
    """On the displayable range, each value clamped to [0, 1]: the light's
    own pixels (radiance 40) would otherwise weigh their anti-aliased
    edges, where the two renderers' pixel footprints differ, above every
    other pixel of the image."""
    return float(np.sqrt(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)))


def equal_time_table(rows):
    """Prints `rows` ((spp, our s, our RMSE, Mitsuba's s, Mitsuba's RMSE))
    as a table with our RMSE over Mitsuba's at our render time, read off a
    least-squares line through Mitsuba's log RMSE against log time; returns
    that line's slope."""
    lt = np.log([r[3] for r in rows])
    le = np.log([r[4] for r in rows])
    slope, icpt = np.polyfit(lt, le, 1)
    print("| spp | ours: render s | ours: RMSE | Mitsuba: render s | Mitsuba: RMSE "
          "| Mitsuba's RMSE at our time | ours / Mitsuba at equal time |")
    print("|---|---|---|---|---|---|---|")
    for spp, t_o, e_o, t_m, e_m in rows:
        at = math.exp(icpt + slope * math.log(t_o))
        print(f"| {spp} | {t_o:.2f} | {e_o:.4f} | {t_m:.2f} | {e_m:.4f} | {at:.4f} "
              f"| {e_o / at:.2f} |")
    return slope


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--displace", default="target/release/displace")
    ap.add_argument("--size", type=int, default=128, help="image size (square)")
    ap.add_argument("--spp", default="16,64,256")
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--floor-spp", type=int, default=4096,
                    help="spp of our own converged render: the converged difference against "
                         "Mitsuba's reference, and our reference for the noise alone")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--sampler", default="sobol",
                    help="our path integrator's numbers: sobol (our default) or independent")
    ap.add_argument("--mitsuba-sampler", default="independent",
                    help="Mitsuba's sampler for the timed renders (its default: independent; "
                         "also stratified, multijitter, orthogonal, ldsampler); the reference "
                         "is always independent")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--ply", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker == "mitsuba":
        return worker_mitsuba(a.ply, a.size, int(a.spp), a.repeat, a.seed, a.mitsuba_sampler)

    env = dict(os.environ)
    if "DRJIT_LIBLLVM_PATH" not in env and libllvm():
        env["DRJIT_LIBLLVM_PATH"] = libllvm()
    work = a.workdir or tempfile.mkdtemp(prefix="bench_path_")
    os.makedirs(work, exist_ok=True)
    env["DISPLACE_CACHE"] = os.path.join(work, "cache")
    exe = os.path.abspath(a.displace)
    ply = os.path.join(work, "floor.ply")
    sx, sy, sz = FLOOR["extent"]
    t = FLOOR["texels"]
    run([exe, "export-mesh", FLOOR["height"], "--height-size", f"{t}x{t}",
         "--extent", f"{sx},{sy},{sz}", "-o", ply], env)
    me = [sys.executable, os.path.abspath(__file__), "--size", str(a.size)]

    def mitsuba(spp, repeat, seed, sampler):
        out, _ = run(me + ["--worker", "mitsuba", "--ply", ply, "--spp", str(spp),
                           "--repeat", str(repeat), "--seed", str(seed),
                           "--mitsuba-sampler", sampler], env)
        r = json.loads(out.strip().splitlines()[-1])
        return r["render_s"], np.load(r["image"])

    print(f"reference: Mitsuba at {a.ref_spp} spp, {a.size}x{a.size}, twice ...", flush=True)
    ref_s, ref_a = mitsuba(a.ref_spp, 1, 1000, "independent")
    _, ref_b = mitsuba(a.ref_spp, 1, 5000, "independent")
    # Two references on other seeds than the timed renders: their mean is
    # the reference, and how far they differ gives its own noise (each
    # one's RMSE is their difference over sqrt 2, the mean's over 2).
    ref = 0.5 * (ref_a + ref_b)
    ref_noise = rmse(ref_a, ref_b) / 2
    spps = [int(s) for s in a.spp.split(",")]
    rows, own = [], []
    for spp in spps:
        t_m, img_m = mitsuba(spp, a.repeat, 0, a.mitsuba_sampler)
        t_o, img_o = ours(exe, a.size, spp, a.repeat, work, env, a.sampler)
        rows.append((spp, t_o, rmse(img_o, ref), t_m, rmse(img_m, ref)))
        own.append(img_o)
        if spp == spps[0]:
            flipped = rmse(img_o[:, ::-1], ref)
            if flipped < 0.7 * rows[-1][2]:
                sys.exit(f"our image is mirrored against Mitsuba's (RMSE {rows[-1][2]:.4f}, "
                         f"mirrored {flipped:.4f}): camera conventions differ")
    # Our converged images likewise: two, on seeds the timed renders do not
    # use (a timed render's Sobol points are the first of the same seed's
    # longer render, so against that one its error would read low).
    with open(SCENE) as f:
        text = f.read()
    floors = []
    for seed in (1001, 1002):
        scene = os.path.join(work, f"seed{seed}.toml")
        with open(scene, "w") as f:
            seeded, n = re.subn(r"(?m)^seed = \d+$", f"seed = {seed}", text)
            if n != 1:
                sys.exit(f"{SCENE}: expected one `seed = N` line to vary, found {n}")
            f.write(seeded)
        floors.append(ours(exe, a.size, a.floor_spp, 1, work, env, a.sampler, scene,
                           f"_seed{seed}")[1])
    img_f = 0.5 * (floors[0] + floors[1])
    floor_noise = rmse(*floors) / 2
    floor = rmse(img_f, ref)

    def alone(e, ref_e):
        """An RMSE against a converged image without that image's own noise
        (independent of the render's, so their squares add)."""
        return math.sqrt(max(e * e - ref_e * ref_e, 0.0))

    # The noise alone: each renderer against its own converged image (ours
    # of the bilinear floor with its shell's walls, Mitsuba's of the mesh),
    # less that image's own noise, so neither the converged difference
    # between the two surfaces, which the first table counts in our error,
    # nor either reference's noise is in it.
    noise = [(spp, t_o, alone(rmse(img, img_f), floor_noise), t_m, alone(e_m, ref_noise))
             for (spp, t_o, _, t_m, e_m), img in zip(rows, own)]
    print(f"\nsamplers: ours {a.sampler}, Mitsuba {a.mitsuba_sampler}")
    print(f"\n{a.size}x{a.size}, max_depth {MAX_DEPTH} (Mitsuba {MAX_DEPTH + 1}), "
          f"{os.cpu_count()} threads; reference: the mean of two {a.ref_spp}-spp Mitsuba "
          f"renders ({ref_s:.1f} s each), its own noise {ref_noise:.5f}; "
          f"means: reference {ref.mean():.4f}, ours at {a.floor_spp} spp {img_f.mean():.4f}\n")
    slope = equal_time_table(rows)
    print(f"\nconverged difference (the mean of two of ours at {a.floor_spp} spp against the "
          f"reference): RMSE {floor:.4f}, of which the two images' own noise "
          f"{math.hypot(floor_noise, ref_noise):.4f}, so the surfaces differ by about "
          f"{alone(floor, math.hypot(floor_noise, ref_noise)):.4f}; "
          f"Mitsuba's RMSE falls as time^{slope:.2f}")
    print(f"\nthe noise alone, each against its own converged image less that image's noise "
          f"(ours: the mean of two at {a.floor_spp} spp, its noise {floor_noise:.5f}; "
          f"Mitsuba's: the reference):\n")
    equal_time_table(noise)
    print(f"images and the mesh: {work}")


if __name__ == "__main__":
    main()
