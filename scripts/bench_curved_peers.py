#!/usr/bin/env python3
"""A displaced sphere at a 1024x1024 height map: displace's curved shells
against the same surface tessellated, traced by Embree (`embreex`) and
rendered by Mitsuba 3 (`llvm_ad_rgb`, `direct`).

The surface is `S = P + depth h(uv) N` over the built-in sphere (48 x 24
quads, normals interpolated then normalised), which `displace export-mesh
--scene` tessellates to sub-edges of `--edge-texels` height texels (1: the
map's resolution; 0.5: twice as fine). We trace and render the scene itself.
Every measurement runs in its own process, so peak memory is that tool's.

    pip install -r scripts/requirements-bench.txt
    cargo build --release -p displace-cli
    python3 scripts/bench_curved_peers.py [--edges 1] [--size 512] [--spp 16]

Prints first-hit and shadow-ray throughput (the same rays from the same
files to `displace trace --scene` and to Embree), memory (our maps against
Embree's structure and mesh), set-up (our scene load with its bake against
the tessellation and the BVH build) and whole renders (ours against
Mitsuba's, after its JIT compile), with the ratios.
"""

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render_peers as peers  # noqa: E402  (the scene, rays, Embree and Mitsuba workers)

CAMERA = (np.array([0.0, 0.8, -3.4]), np.array([0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
VFOV = 38.0
LIGHT_POS = (-2.0, 4.0, -3.0)
LIGHT_INTENSITY = 30.0
ALBEDO = 0.7
DEPTH = 0.05


VIEW = (*CAMERA, VFOV)
LIGHT = (LIGHT_POS, LIGHT_INTENSITY)


def scene_toml(size, spp):
    return peers.scene_header(size, spp, VIEW, LIGHT, ALBEDO, "scripts/bench_curved_peers.py") + f"""
[[shapes]]
type = "mesh"
path = "builtin:sphere"
material = "white"
[shapes.displacement]
height = "gen:noise"
height_size = [1024, 1024]
depth = {DEPTH}
map_size = [512, 512, 16]
address = "repeat"
tiles = [2, 1]
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--displace", default="target/release/displace")
    ap.add_argument("--edges", default="1", help="sub-edge lengths in texels, comma-separated")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rays", type=int, default=1000, help="first-hit rays: an NxN grid")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--ply", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker == "mitsuba":
        return peers.worker_mitsuba(a.ply, a.size, a.spp, VIEW, LIGHT, ALBEDO, a.repeat)

    env, exe, work = peers.setup(a.displace, a.workdir, "displace-curved-")
    toml = os.path.join(work, "sphere.toml")
    with open(toml, "w") as f:
        f.write(scene_toml(a.size, a.spp))
    me = [sys.executable, os.path.abspath(__file__)]
    embree = [sys.executable, peers.__file__]

    ours_img = os.path.join(work, "sphere.ours.exr")
    render_s, rss_render = peers.render_ours(exe, toml, ours_img, a.repeat, env)
    img_ours = peers.read_linear(ours_img)
    rays_path = os.path.join(work, "rays.npy")
    np.save(rays_path, np.concatenate(peers.camera_rays(a.rays, VIEW), axis=1))
    hits_path = os.path.join(work, "hits.npy")
    shadow_path = os.path.join(work, "shadow.npy")
    blocked_path = os.path.join(work, "blocked.npy")
    f1 = peers.trace_ours(exe, toml, rays_path, hits_path, 1, a.repeat, env)
    fn = peers.trace_ours(exe, toml, rays_path, hits_path, a.threads, a.repeat, env)
    n_shadow = peers.shadow_rays(hits_path, rays_path, shadow_path, LIGHT_POS)
    s1 = peers.trace_ours(exe, toml, shadow_path, blocked_path, 1, a.repeat, env, True)
    sn = peers.trace_ours(exe, toml, shadow_path, blocked_path, a.threads, a.repeat, env, True)
    ours = {"setup_s": fn["load_s"], "memory_mb": fn["maps_mb"], "rss": max(fn["rss"], rss_render),
            "first": (f1["mrays"], fn["mrays"]), "shadow": (s1["mrays"], sn["mrays"]),
            "render_s": render_s, "hits": fn["found"], "blocked": sn["found"]}

    meshes = []
    for e in [float(x) for x in a.edges.split(",")]:
        ply = os.path.join(work, f"sphere.e{e:g}.ply")
        out, _, mesh_s, _ = peers.run_measured(
            [exe, "export-mesh", "--scene", toml, "--edge-texels", str(e), "-o", ply], env)
        out, _, _, rss_e = peers.run_measured(
            embree + ["--worker", "embree", "--ply", ply, "--ray-file", rays_path,
                      "--shadow-file", shadow_path, "--threads", str(a.threads),
                      "--repeat", str(a.repeat)], env)
        em = json.loads(out.strip().splitlines()[-1])
        out, _, _, rss_m = peers.run_measured(
            me + ["--worker", "mitsuba", "--ply", ply, "--size", str(a.size),
                  "--spp", str(a.spp), "--repeat", str(a.repeat)], env)
        mi = json.loads(out.strip().splitlines()[-1])
        img_m = np.load(mi["image"])
        meshes.append({"edge": e, "tris": em["triangles"], "export_s": mesh_s,
                       "build_s": em["build_s"], "memory_mb": em["structure_mb"] + em["mesh_mb"],
                       "rss": rss_e, "first": (em["mrays_1t"], em["mrays_nt"]),
                       "shadow": (em["shadow_1t"], em["shadow_nt"]), "hits": em["hits"],
                       "blocked": em["blocked"], "render_s": mi["render_s"],
                       "mitsuba_first_s": mi["first_s"], "mitsuba_load_s": mi["load_s"],
                       "rss_mitsuba": rss_m,
                       "rmse": float(np.sqrt(np.mean((img_m - img_ours) ** 2)))})

    t = a.threads
    print(f"\ndisplaced sphere, 1024x1024 heights (gen:noise, 2x1 tiles, depth {DEPTH}); "
          f"{a.size}x{a.size} at {a.spp} spp; {a.rays ** 2} camera rays, {n_shadow} shadow rays; "
          f"{t} threads; workdir {work}")
    print(f"{'surface':<26} {'tris':>10} {'setup s':>9} {'memory MB':>10} {'peak MB':>8} "
          f"{'first Mrays/s 1t/nt':>20} {'shadow Mrays/s 1t/nt':>21} {'render s':>9} {'RMSE':>7}")
    print(f"{'displace (curved shells)':<26} {'-':>10} {ours['setup_s']:>9.2f} "
          f"{ours['memory_mb']:>10.1f} {ours['rss']:>8.0f} "
          f"{ours['first'][0]:>9.2f} /{ours['first'][1]:>8.2f} "
          f"{ours['shadow'][0]:>10.2f} /{ours['shadow'][1]:>8.2f} {ours['render_s']:>9.2f} {'-':>7}")
    for m in meshes:
        print(f"{'mesh ' + format(m['edge'], 'g') + ' texel: Embree/Mitsuba':<26} {m['tris']:>10} "
              f"{m['build_s']:>9.2f} {m['memory_mb']:>10.1f} {max(m['rss'], m['rss_mitsuba']):>8.0f} "
              f"{m['first'][0]:>9.2f} /{m['first'][1]:>8.2f} "
              f"{m['shadow'][0]:>10.2f} /{m['shadow'][1]:>8.2f} {m['render_s']:>9.2f} "
              f"{m['rmse']:>7.4f}")
    print("setup: ours = scene load with its bake (no cache); mesh = Embree's BVH build "
          "(the tessellation itself: " +
          ", ".join(f"{m['edge']:g} texel {m['export_s']:.1f} s" for m in meshes) + ")")
    print(f"hits: ours {ours['hits']}, meshes " + ", ".join(str(m['hits']) for m in meshes) +
          f"; blocked shadow rays: ours {ours['blocked']}, meshes " +
          ", ".join(str(m['blocked']) for m in meshes))
    print(f"\nratios, ours / peer ({t} threads):")
    for m in meshes:
        print(f"  vs {m['edge']:g}-texel mesh: first hits {ours['first'][1] / m['first'][1]:.2f}, "
              f"shadow {ours['shadow'][1] / m['shadow'][1]:.2f}, "
              f"memory {ours['memory_mb'] / m['memory_mb']:.3f}, "
              f"setup {ours['setup_s'] / m['build_s']:.3f}, "
              f"render {ours['render_s'] / m['render_s']:.1f}")
    with open(os.path.join(work, "results.json"), "w") as f:
        json.dump({"args": vars(a), "ours": ours, "meshes": meshes}, f, indent=1)


if __name__ == "__main__":
    main()
