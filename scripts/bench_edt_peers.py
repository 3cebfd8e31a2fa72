#!/usr/bin/env python3
"""Time the peers of `displace bench bake` on the same occupancy volume.

`displace bench bake` writes the volume it bakes as a uint8 .npy of shape
(D, H, W): 1 where the voxel centre lies below the displaced surface. This
script runs, on that same volume,

  * edt.sdf(volume, anisotropy=spacing, parallel=N)       (PyPI `edt`)
  * edt.edt(volume, anisotropy=spacing, parallel=N)
  * scipy.ndimage.distance_transform_edt(volume, sampling=spacing)

with the anisotropic voxel spacing of our map (depth units, axis order D, H,
W), and prints one JSON line:

  {"voxels": ..., "edt_sdf_seconds": s|null, "edt_seconds": s|null,
   "scipy_seconds": s|null, "missing": [...]}

`edt.sdf` is the peer of our bake: a signed distance on both sides of the
surface, as a distance map stores (it is `edt` of the volume minus `edt` of
its complement). `edt.edt` and scipy give the distance on one side only (to
the nearest background voxel from each foreground voxel, zero elsewhere):
less than a distance map holds, reported to show what one pass costs.

Each time is the best of 3 to 10 runs, adding runs while under two seconds,
the rule `displace bench bake` uses for our bake. Packages that cannot be imported
are listed in "missing" and their times are null; install them with

  python3 -m pip install -r scripts/requirements-bench.txt

(or just `python3 -m pip install numpy edt scipy`)

`BENCH_EDT_PEERS=edt` (or `scipy`) runs only those peers; the others report
null times. scipy's transform of a 4096x4096x64 volume needs more memory than
the project's 23 GB machine has.
"""

import argparse
import os
import json
import sys
import time


def best_time(fn, budget=2.0, runs=10, at_least=3):
    best = float("inf")
    total = 0.0
    for run in range(runs):
        t = time.perf_counter()
        fn()
        s = time.perf_counter() - t
        best = min(best, s)
        total += s
        if run + 1 >= at_least and total > budget:
            break
    return best


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("volume", help="uint8 .npy occupancy volume (D, H, W)")
    p.add_argument("--spacing", required=True, help="voxel spacing along D,H,W")
    p.add_argument("--parallel", type=int, default=2, help="threads for edt")
    args = p.parse_args()

    result = {
        "voxels": None,
        "edt_sdf_seconds": None,
        "edt_seconds": None,
        "scipy_seconds": None,
        "missing": [],
    }
    try:
        import numpy as np
    except ImportError:
        result["missing"] = ["numpy", "edt", "scipy"]
        print(json.dumps(result))
        return 0

    volume = np.load(args.volume)
    if volume.ndim != 3:
        print(f"error: {args.volume}: expected a 3D volume, got shape {volume.shape}", file=sys.stderr)
        return 2
    volume = np.ascontiguousarray(volume != 0, dtype=np.uint8)
    spacing = tuple(float(s) for s in args.spacing.split(","))
    if len(spacing) != 3:
        print(f"error: --spacing {args.spacing}: expected three numbers", file=sys.stderr)
        return 2
    result["voxels"] = int(volume.size)

    # BENCH_EDT_PEERS=edt (or scipy) runs only those: scipy's one-sided
    # transform of a 4096x4096x64 volume takes minutes a run.
    # Peers left out this way have null times and are not "missing".
    wanted = os.environ.get("BENCH_EDT_PEERS", "edt,scipy").split(",")
    try:
        if "edt" in wanted:
            import edt

            result["edt_sdf_seconds"] = best_time(
                lambda: edt.sdf(volume, anisotropy=spacing, black_border=False, parallel=args.parallel)
            )
            result["edt_seconds"] = best_time(
                lambda: edt.edt(volume, anisotropy=spacing, black_border=False, parallel=args.parallel)
            )
    except ImportError:
        result["missing"].append("edt")

    try:
        if "scipy" in wanted:
            from scipy import ndimage

            result["scipy_seconds"] = best_time(lambda: ndimage.distance_transform_edt(volume, sampling=spacing))
    except ImportError:
        result["missing"].append("scipy")

    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
