#!/usr/bin/env python3
"""Real height maps for the benchmarks, from data a user's Python already
has: Matplotlib's sample data ships a measured elevation model and a
photograph, so the benchmarks can run on real inputs without a download.

* `terrain.png`: the Jacksboro fault elevation model (USGS, 3 arc-seconds,
  about 90 m a texel, elevations 236-1076 m), its west 344 x 344 texels,
  the elevations' range as 16-bit heights;
* `photo.png`: the portrait of Grace Hopper (a photograph: hair, fabric,
  edges and noise at every scale), its centre 512 x 512 pixels as 8-bit
  luma (Rec. 709 weights, as `displace` reduces colour images).

Both are square PNGs, what `scripts/bench_render_peers.py --maps` takes by
path. Beside them, `terrain.tif`: the whole elevation model (403 x 344) as
float32 metres, what `scripts/bench_python_peers.py --dem W/terrain.tif
--texel 90` takes. Usage:

    pip install matplotlib pillow numpy
    python3 scripts/real_height_maps.py --out W
"""

import argparse
import os

import numpy as np


def sample(name):
    """The path of one of Matplotlib's sample data files."""
    from matplotlib import cbook

    path = cbook.get_sample_data(name, asfileobj=False)
    if not os.path.isfile(path):
        raise SystemExit(f"Matplotlib's sample data lack {name} (looked at {path})")
    return path


def elevations():
    """The elevation model's metres, float32, its rows north to south."""
    return np.load(sample("jacksboro_fault_dem.npz"))["elevation"].astype(np.float32)


def terrain():
    """16-bit heights of the elevation model's west square, its own range
    from 0 to 65535."""
    z = elevations().astype(np.float64)
    n = min(z.shape)
    z = z[:n, :n]
    lo, hi = z.min(), z.max()
    return np.round((z - lo) / (hi - lo) * 65535).astype(np.uint16)


def photo():
    """8-bit luma of the photograph's centre square."""
    from PIL import Image

    rgb = np.asarray(Image.open(sample("grace_hopper.jpg")).convert("RGB"), np.float64)
    n = 512
    r0, c0 = (rgb.shape[0] - n) // 2, (rgb.shape[1] - n) // 2
    rgb = rgb[r0:r0 + n, c0:c0 + n]
    luma = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return np.clip(np.round(luma), 0, 255).astype(np.uint8)


def write_image(path, a):
    """`a` as a one-channel PNG or TIFF (by `path`'s suffix), written under a
    temporary name and renamed."""
    from PIL import Image

    tmp = path + ".tmp"
    # uint16 becomes mode "I;16", uint8 "L", float32 "F": one channel each.
    Image.fromarray(a).save(tmp, format="TIFF" if path.endswith(".tif") else "PNG")
    os.replace(tmp, path)


def write_all(out):
    """Writes both maps into folder `out` (and the elevation model's TIFF);
    returns the two PNGs' paths."""
    os.makedirs(out, exist_ok=True)
    paths = []
    for name, heights in (("terrain", terrain()), ("photo", photo())):
        path = os.path.join(out, f"{name}.png")
        write_image(path, heights)
        print(f"{path}: {heights.shape[1]}x{heights.shape[0]} {heights.dtype}")
        paths.append(path)
    z = elevations()
    write_image(os.path.join(out, "terrain.tif"), z)
    print(f"{os.path.join(out, 'terrain.tif')}: {z.shape[1]}x{z.shape[0]} float32 metres")
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for terrain.png and photo.png")
    write_all(ap.parse_args().out)


if __name__ == "__main__":
    main()
