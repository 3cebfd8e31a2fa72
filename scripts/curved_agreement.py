#!/usr/bin/env python3
"""How closely `displace` renders a scene's displaced meshes to the displaced
surface they stand for, `S = P + depth h(uv) N` (vertex positions, normals
normalised after interpolation and texture coordinates interpolated over
each triangle): the surface pbrt-v4 and Cycles draw when they subdivide a
mesh and move its vertices along the interpolated normals.

The ground truth is that surface tessellated with sub-edges of a quarter
height texel (`displace export-mesh --scene`), traced as plain triangles by
the same BVH. Both are traced with `displace trace --scene` on the same
camera rays (one per pixel centre of the scene's image), and the script
prints the measures of the curved-surface tests: the share of pixels whose
hit or miss agree (wanted: at least 99.5%), the share of the pixels hit by
both whose hit positions lie within 2% of the mesh's displacement depth
(wanted: at least 99%), per mesh and in all, and the seams: neighbouring
pixels whose normals break by more than 30 degrees (on a smooth height
field, the prisms' walls).

    pip install numpy
    cargo build --release -p displace-cli
    python3 scripts/curved_agreement.py scenes/gpu_meshes.toml

The scene's shapes should be displaced meshes only (other shapes are not in
the ground truth, and pixels that see them in ours count as disagreeing).
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile
import tomllib

import numpy as np


def camera_rays(cam, width, height):
    """A pinhole ray through every pixel centre, row by row from the top."""
    pos = np.array(cam["position"], float)
    look = np.array(cam["look_at"], float)
    up = np.array(cam.get("up", [0, 1, 0]), float)
    fwd = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    t = math.tan(math.radians(cam.get("vfov", 40)) / 2)
    fx, fy = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height)
    sx = ((2 * fx - 1) * t * width / height).reshape(-1, 1)
    sy = ((1 - 2 * fy) * t).reshape(-1, 1)
    d = fwd + sx * right + sy * upv
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(pos, d.shape)
    return np.ascontiguousarray(np.hstack([o, d]), np.float32)


def reference_scene(scene, obj, width, height):
    """The ground truth as a scene: the same camera, the exported surfaces
    as one plain mesh, a light (the trace needs none, the loader one)."""
    cam = scene["camera"]
    vec = lambda v: "[" + ", ".join(repr(float(x)) for x in v) + "]"
    return f"""[image]
width = {width}
height = {height}

[camera]
position = {vec(cam["position"])}
look_at = {vec(cam["look_at"])}
up = {vec(cam.get("up", [0, 1, 0]))}
vfov = {float(cam.get("vfov", 40))!r}

[materials.m]
type = "lambert"
color = [0.5, 0.5, 0.5]

[[lights]]
type = "point"
position = {vec(cam["position"])}
intensity = [1, 1, 1]

[[shapes]]
type = "mesh"
path = "{obj}"
material = "m"
"""


def normal_breaks(hits, width, height, degrees=30.0):
    """Seams in a normal image: pairs of neighbouring pixels on the same
    shape, both hit, whose geometric normals differ by more than `degrees`
    (across rows and down columns). Over a smooth height field the ground
    truth has them only where one part of a mesh passes in front of
    another; flat prisms have them along every wall between two prisms."""
    n = hits[:, 4:7].reshape(height, width, 3)
    shape = hits[:, 7].reshape(height, width)
    hit = np.isfinite(hits[:, 0]).reshape(height, width)
    count = 0
    for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                 ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        cos = np.clip(np.sum(n[a] * n[b], axis=-1), -1.0, 1.0)
        pair = hit[a] & hit[b] & (shape[a] == shape[b])
        count += int(np.sum(pair & (np.degrees(np.arccos(cos)) > degrees)))
    return count


def run(cmd):
    print("+", " ".join(cmd), file=sys.stderr)
    subprocess.run(cmd, check=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--displace", default="target/release/displace")
    p.add_argument("--edge-texels", default="0.25")
    p.add_argument("--workdir", default=None)
    a = p.parse_args()
    with open(a.scene, "rb") as f:
        scene = tomllib.load(f)
    width, height = scene["image"]["width"], scene["image"]["height"]
    shapes = scene.get("shapes", [])
    depths = [s["displacement"]["depth"] for s in shapes if s.get("type") == "mesh" and "displacement" in s]
    if not depths:
        sys.exit(f"{a.scene}: no displaced meshes")
    work = a.workdir or tempfile.mkdtemp(prefix="curved_")
    os.makedirs(work, exist_ok=True)
    obj = os.path.join(work, "reference.obj")
    run([a.displace, "export-mesh", "--scene", a.scene, "--edge-texels", a.edge_texels, "-o", obj])
    ref_toml = os.path.join(work, "reference.toml")
    with open(ref_toml, "w") as f:
        f.write(reference_scene(scene, os.path.abspath(obj), width, height))
    rays = os.path.join(work, "rays.npy")
    np.save(rays, camera_rays(scene["camera"], width, height))
    ours, ref = os.path.join(work, "ours.npy"), os.path.join(work, "reference.npy")
    run([a.displace, "trace", "--scene", a.scene, "--rays", rays, "-o", ours])
    run([a.displace, "trace", "--scene", ref_toml, "--rays", rays, "-o", ref])
    h_ours, h_ref = np.load(ours), np.load(ref)
    hit_o, hit_r = np.isfinite(h_ours[:, 0]), np.isfinite(h_ref[:, 0])
    n = len(h_ours)
    # Shape index of ours -> the displaced mesh's depth.
    mesh_of_shape = {}
    k = 0
    for i, s in enumerate(shapes):
        if s.get("type") == "mesh" and "displacement" in s:
            mesh_of_shape[i] = k
            k += 1
    both = hit_o & hit_r
    shape = h_ours[:, 7].astype(int)
    depth = np.array([depths[mesh_of_shape[s]] if s in mesh_of_shape else np.nan for s in shape])
    err = np.linalg.norm(h_ours[:, 1:4] - h_ref[:, 1:4], axis=1) / depth
    print(f"{a.scene}: {width}x{height} rays, ground truth at {a.edge_texels}-texel sub-edges")
    print(f"hit or miss agree: {np.mean(hit_o == hit_r) * 100:.2f}% of {n} pixels "
          f"(ours hit {hit_o.sum()}, the ground truth {hit_r.sum()}; wanted >= 99.5%)")
    within = np.mean(err[both] <= 0.02) * 100 if both.any() else float("nan")
    print(f"hit positions within 2% of the depth: {within:.2f}% of the {both.sum()} pixels both hit "
          f"(wanted >= 99%); error / depth median {np.nanmedian(err[both]):.4f}, "
          f"99th percentile {np.nanpercentile(err[both], 99):.4f}")
    print(f"neighbouring pixels whose normals break by more than 30 degrees (seams on a smooth "
          f"height field): ours {normal_breaks(h_ours, width, height)}, the ground truth "
          f"{normal_breaks(h_ref, width, height)}")
    for s, m in mesh_of_shape.items():
        sel = both & (shape == s)
        if sel.any():
            print(f"  mesh {m} ({shapes[s].get('path')}): {sel.sum()} pixels, within 2%: "
                  f"{np.mean(err[sel] <= 0.02) * 100:.2f}%, median {np.median(err[sel]):.4f}")


if __name__ == "__main__":
    main()
