#!/usr/bin/env python3
"""What Mitsuba 3 spends on a sample's camera ray alone, against its whole
`direct` sample, on the scene of `scripts/bench_render_peers.py` (the same
camera, light and material, the mesh that script exports): the `depth`
integrator traces only the camera rays (and writes their distance), the
`direct` one adds the shadow ray and the shading. Both in Mitsuba's
`llvm_ad_rgb` wavefront, which hands Embree coherent packets of a pixel's
samples; the ray benchmark's Embree peer (`embreex`) traces one ray per call.
Prints nanoseconds of one core per sample (best of three renders after the
kernels' compile), the figures docs/cpu-tracer.md sets the render target
against.

    python3 scripts/bench_render_peers.py --scales 1 --workdir W   # writes W/*.x1.ply
    python3 scripts/mitsuba_stages.py W/studded.x1.ply [--size 512] [--spp 16]
"""

import argparse
import glob
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render_peers as peers  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ply", help="a mesh written by bench_render_peers.py (its x1 mesh)")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    a = ap.parse_args()
    if not os.path.isfile(a.ply):
        sys.exit(f"error: {a.ply}: no such mesh (run bench_render_peers.py --workdir first)")
    llvm = sorted(glob.glob("/usr/lib/*/libLLVM.so.19*") + glob.glob("/usr/lib/*/libLLVM-19*.so*"))
    if llvm and "DRJIT_LIBLLVM_PATH" not in os.environ:
        os.environ["DRJIT_LIBLLVM_PATH"] = llvm[0]
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    pos, look, up = peers.camera()
    samples = a.size * a.size * a.spp
    for name, integrator in [
        ("camera rays only (depth)", {"type": "depth"}),
        ("camera and shadow ray, shaded (direct)",
         {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0}),
    ]:
        scene = mi.load_dict({
            "type": "scene",
            "integrator": integrator,
            "sensor": {
                "type": "perspective", "fov": peers.VFOV, "fov_axis": "y",
                "to_world": mi.ScalarTransform4f().look_at(
                    origin=pos.tolist(), target=look.tolist(), up=up.tolist()),
                "film": {"type": "hdrfilm", "width": a.size, "height": a.size,
                         "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                "sampler": {"type": "independent", "sample_count": a.spp},
            },
            "mesh": {"type": "ply", "filename": a.ply,
                     "bsdf": {"type": "diffuse",
                              "reflectance": {"type": "rgb", "value": peers.ALBEDO}}},
            "light": {"type": "point", "position": list(peers.LIGHT_POS),
                      "intensity": {"type": "rgb", "value": peers.LIGHT_INTENSITY}},
        })
        times = []
        for k in range(4):  # the first compiles the kernels
            t = time.perf_counter()
            mi.render(scene, seed=k)
            times.append(time.perf_counter() - t)
        best = min(times[1:])
        ns = best * a.threads / samples * 1e9
        print(f"{name}: {best:.3f} s, {ns:.1f} ns of a core per sample ({a.threads} threads)")


if __name__ == "__main__":
    main()
