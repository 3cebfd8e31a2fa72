#!/usr/bin/env python3
"""An adversarial user's sweep of the command line, run against a built
binary (not in CI: the tests hold each fixed case; this runs variants of
every kind at once, as a new user's inputs would come): files that claim
huge sizes, limits that are not the machine's (`ulimit -v`), values past
what single precision holds, outputs over inputs, signals in the first
moments of long work, late and misleading refusals.

Each case must end with exit 1 or 2 (or 0 where it is answered right),
never a panic or an abort, leave no temporary file or partial output, and
say what its needles name. Usage (from the repository's root):

    cargo build --release -p displace-cli
    python3 scripts/adversarial_sweep.py target/release/displace .

prints one line per case and `N of M ok`; docs/reliability.md has what
each kind did before its fix."""
import os, re, signal, struct, subprocess, sys, tempfile, time, shutil, glob

BIN = os.path.abspath(sys.argv[1])
REPO = os.path.abspath(sys.argv[2])
results = []

def run(args, cwd, timeout=60, env=None, vlimit_gb=8, sigint_after=None):
    e = dict(os.environ, **(env or {}))
    pre = ["bash", "-c", f"ulimit -v {vlimit_gb*1024*1024}; exec \"$@\"", "x"]
    t0 = time.time()
    p = subprocess.Popen(pre + [BIN] + args, cwd=cwd, env=e, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if sigint_after is not None:
        time.sleep(sigint_after)
        p.send_signal(signal.SIGINT)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill(); out, err = p.communicate()
        return 999, out, err + "\nTIMEOUT", time.time() - t0
    return p.returncode, out, err, time.time() - t0

def leftovers(d):
    return [f for f in os.listdir(d) if f.endswith(".tmp")]

def case(name, args, files=None, expect_rc=(1, 2), needles=(), must_not_exist=(), **kw):
    d = tempfile.mkdtemp(prefix="adv_")
    for fname, content in (files or {}).items():
        mode = "wb" if isinstance(content, bytes) else "w"
        with open(os.path.join(d, fname), mode) as f:
            f.write(content)
    before = set(os.listdir(d))
    rc, out, err, t = run(args, d, **kw)
    msg = (err.strip().splitlines() or [""])[-1][:220]
    problems = []
    if rc not in expect_rc:
        problems.append(f"rc {rc}")
    if "panicked" in err or "memory allocation" in err or rc in (101, 134, 139):
        problems.append("panic/abort")
    for n in needles:
        if n not in err + out:
            problems.append(f"missing '{n}'")
    left = leftovers(d)
    if left:
        problems.append(f"left {left}")
    for m in must_not_exist:
        if os.path.exists(os.path.join(d, m)):
            problems.append(f"{m} written")
    results.append((name, "ok" if not problems else "FAIL " + "; ".join(problems), f"{t:.1f}s", msg))
    shutil.rmtree(d, ignore_errors=True)

# --- helpers
def exr_rgb(d, w=8, h=8):
    """A small linear RGB EXR written by displace itself (a render)."""
    scene = open(os.path.join(REPO, "scenes/flatmap.toml")).read()
    p = os.path.join(d, "s.exr")
    subprocess.run([BIN, "render", "--size", f"{w}x{h}", "--spp", "1", "-q", "-o", p], cwd=d, check=True, capture_output=True)
    return open(p, "rb").read()

def patch_window(b, key, xmax, ymax):
    k = key + b"\0box2i\0"
    at = b.index(k) + len(k) + 4
    b = bytearray(b)
    b[at + 8:at + 12] = struct.pack("<i", xmax)
    b[at + 12:at + 16] = struct.pack("<i", ymax)
    return bytes(b)

def npy(shape, data=b"", descr="<f4"):
    h = "{'descr': '%s', 'fortran_order': False, 'shape': (%s), }" % (descr, "".join(f"{v}, " for v in shape))
    pad = 64 - (10 + len(h) + 1) % 64
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(h) + pad + 1) + h.encode() + b" " * pad + b"\n" + data

RAYS = None
tmp = tempfile.mkdtemp()
small = exr_rgb(tmp)
subprocess.run([BIN, "render", "--size", "4x4", "--spp", "1", "-q", "-o", os.path.join(tmp, "t.png")], check=True, capture_output=True)
png = open(os.path.join(tmp, "t.png"), "rb").read()
RAYS = npy((1, 6), struct.pack("<6f", 0.5, 0.5, 1, 0, 0, -1))
huge_data = patch_window(small, b"dataWindow", 29999, 29999)
huge_disp = patch_window(small, b"displayWindow", 3000000, 40)

SCENE = """[image]
width = 16
height = 16
spp = 1

[camera]
position = [0, 0, -4]
look_at = [0, 0, 0]
{camera}

[materials.m]
type = "lambert"
color = {color}
{material}

[[lights]]
type = "point"
position = [0, 3, -3]
intensity = [10, 10, 10]
{lights}

[[shapes]]
{shape}
material = "m"
{extra}
"""
def scene(camera="", color="[0.5, 0.5, 0.5]", material="", lights="", shape='type = "sphere"\ncenter = [0, 0, 0]\nradius = 1', extra=""):
    return SCENE.format(camera=camera, color=color, material=material, lights=lights, shape=shape, extra=extra)

# 1. sizes
case("bake: EXR dataWindow 30000^2", ["bake", "h.exr", "--size", "16x16x4", "-o", "m.ktx2"], {"h.exr": huge_data}, needles=["30000x30000"], must_not_exist=["m.ktx2"])
case("gpu-render --height EXR dataWindow 30000^2", ["gpu-render", "--height", "h.exr", "--map-size", "16x16x4", "-o", "r.png"], {"h.exr": huge_data}, must_not_exist=["r.png"], env={"WGPU_BACKEND": "vulkan"})
case("scene texture EXR displayWindow 3e6x41", ["render", "s.toml", "-o", "o.png"], {"t.exr": huge_disp, "s.toml": scene(material='texture = "t.exr"')}, must_not_exist=["o.png"])
case("bake 52000^2 under ulimit -v 8G", ["bake", "gen:flat", "--height-size", "52000x52000", "--size", "32x32x8", "-o", "m.npy"], needles=["52000x52000"], must_not_exist=["m.npy"])
case("bake 30000^2 under ulimit -v 3G", ["bake", "gen:flat", "--height-size", "30000x30000", "--size", "32x32x8", "-o", "m.npy"], needles=["needs about"], must_not_exist=["m.npy"], vlimit_gb=3)
case("gpu-render --size 20000x20000", ["gpu-render", "s.toml", "--size", "20000x20000", "-o", "o.png"], {"s.toml": scene()}, must_not_exist=["o.png"], env={"WGPU_BACKEND": "vulkan"})
case("npy claiming 2^40 voxels", ["trace", "--map", "m.npy", "--height", "gen:gaussian", "--extent", "1,1,0.1", "--rays", "r.npy", "-o", "h.npy"], {"m.npy": npy((256, 65536, 65536), b"\0" * 64), "r.npy": RAYS}, must_not_exist=["h.npy"])
# 3. silently wrong
case("colour 1e17", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(color="[1e17, 0.5, 0.5]")}, must_not_exist=["o.png"])
case("emission 1e16", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(material="emission = [1e16, 1, 1]")}, must_not_exist=["o.png"])
case("sphere radius 1e21", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(shape='type = "sphere"\ncenter = [0, 0, 0]\nradius = 1e21')}, must_not_exist=["o.png"])
case("aperture 1e31", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(camera="aperture = 1e31")}, must_not_exist=["o.png"])
case("builtin mesh scale 8e10", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(shape='type = "mesh"\npath = "builtin:sphere"\nscale = 8e10')}, expect_rc=(0, 1, 2))
case("OBJ with BOM renders", ["render", "s.toml", "-o", "o.png"], {"m.obj": "\ufeffv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("utf-8"), "s.toml": scene(shape='type = "mesh"\npath = "m.obj"')}, expect_rc=(0,))
# 4. inputs overwritten
case("render -o its own texture (png)", ["render", "s.toml", "-o", "t.png"], {"t.png": png, "s.toml": scene(material='texture = "t.png"')}, needles=["input"])
case("trace -o its rays", ["trace", "--height", "gen:gaussian", "--extent", "1,1,0.1", "--size", "8x8x2", "--rays", "r.npy", "-o", "r.npy"], {"r.npy": RAYS})
# 5. partial files and late checks
case("bake SIGINT at 0.3 s", ["bake", "gen:gaussian", "--height-size", "8192x8192", "--size", "1024x1024x128", "-o", "m.ktx2"], expect_rc=(1, 2, 130), must_not_exist=["m.ktx2"], sigint_after=0.3)
case("export-mesh SIGINT at 1 s", ["export-mesh", "gen:gaussian", "--height-size", "3000x3000", "--extent", "1,1,0.1", "--scale", "2", "-o", "m.obj"], expect_rc=(1, 2, 130), must_not_exist=["m.obj"], sigint_after=1.0)
case("render --frames clash at frame 2", ["render", "s.toml", "--frames", "0..4", "-o", "t.png"], {"t_0002.png": png, "s.toml": scene(material='texture = "t_0002.png"') + "\n[animation]\nframes = 4\n"}, needles=["t_0002.png"], must_not_exist=["t_0000.png", "t_0001.png"])
case("output name of 280 bytes", ["render", "s.toml", "-o", "x" * 276 + ".png"], {"s.toml": scene()})
# 6. misleading or late refusals
case("nested keys", ["render", "s.toml", "-o", "o.png"], {"s.toml": "[" + ".".join(["b"] * 400) + "]\nx = 1\n"}, must_not_exist=["o.png"])
case("OBJ vt 1e31", ["render", "s.toml", "-o", "o.png"], {"m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 1e31 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n", "s.toml": scene(shape='type = "mesh"\npath = "m.obj"')}, needles=["m.obj:4"], must_not_exist=["o.png"])
case("animation.light = 3 of 1", ["render", "s.toml", "--frames", "0..2", "-o", "o.png"], {"s.toml": scene() + "\n[animation]\nframes = 2\nlight = 3\n"}, needles=["light"], must_not_exist=["o_0000.png"])
case("DDS claiming 4 array layers", ["trace", "--map", "m.dds", "--height", "gen:gaussian", "--extent", "1,1,0.1", "--rays", "r.npy", "-o", "h.npy"], {"m.dds": b"DDS " + struct.pack("<7I", 124, 0x1007 | 0x800000, 4, 4, 0, 2, 1) + b"\0" * 44 + struct.pack("<8I", 32, 4, 0x30315844, 0, 0, 0, 0, 0) + struct.pack("<5I", 0x1000, 0x200000, 0, 0, 0) + struct.pack("<5I", 41, 4, 0, 4, 0) + b"\0" * 200, "r.npy": RAYS}, must_not_exist=["h.npy"])

case("sphere radius 1e19", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(shape='type = "sphere"\ncenter = [0, 0, 0]\nradius = 1e19')}, needles=["radius"], must_not_exist=["o.png"])
case("focus_distance 1e25", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(camera="aperture = 0.1\nfocus_distance = 1e25")}, needles=["focus_distance"], must_not_exist=["o.png"])
case("triangle vertex 3e18", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(shape='type = "triangle"\nvertices = [[0, 0, 0], [3e18, 0, 0], [0, 1, 0]]')}, must_not_exist=["o.png"])
case("mesh translate 5e18", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(shape='type = "mesh"\npath = "builtin:cube"\ntranslate = [5e18, 0, 0]')}, must_not_exist=["o.png"])
case("light intensity 3e15", ["render", "s.toml", "-o", "o.png"], {"s.toml": scene(lights="").replace("intensity = [10, 10, 10]", "intensity = [3e15, 1, 1]")}, must_not_exist=["o.png"])
case("merge of a non-tile EXR", ["merge", "s.exr", "-o", "m.exr"], {"s.exr": small}, must_not_exist=["m.exr"])
case("merge of a truncated tile", ["merge", "s.exr", "-o", "m.exr"], {"s.exr": small[: len(small) // 2]}, must_not_exist=["m.exr"])
case("compare --out over a file", ["compare", "--height", "gen:gaussian", "--out", "f"], {"f": "x"}, expect_rc=(1, 2))
case("distance npy of NaN", ["trace", "--map", "m.npy", "--height", "gen:gaussian", "--extent", "1,1,0.1", "--rays", "r.npy", "-o", "h.npy"], {"m.npy": npy((2, 4, 4), struct.pack("<32f", *([float("nan")] * 32))), "r.npy": RAYS}, must_not_exist=["h.npy"])

case("gpu-render --size 16384x16384", ["gpu-render", "s.toml", "--size", "16384x16384", "-o", "o.png"], {"s.toml": scene()}, expect_rc=(0, 1, 2), timeout=120, env={"WGPU_BACKEND": "vulkan"})
case("render --aov depth over a texture", ["render", "s.toml", "--aov", "depth", "-o", "o.png"], {"o.depth.png": png, "s.toml": scene(material='texture = "o.depth.png"')}, needles=["input"], must_not_exist=["o.png"])
case("gpu-render --uv-aov over its scene", ["gpu-render", "o.uvkt.npy", "--uv-aov", "-o", "o.png"], {"o.uvkt.npy": scene()}, needles=["input"], must_not_exist=["o.png"], env={"WGPU_BACKEND": "vulkan"})
case("gpu-render -o its height", ["gpu-render", "--height", "h.png", "--map-size", "16x16x4", "-o", "h.png"], {"h.png": png}, needles=["input"], env={"WGPU_BACKEND": "vulkan"})
case("gpu-render -o its scene", ["gpu-render", "s.toml", "-o", "s.toml"], {"s.toml": scene()}, expect_rc=(1, 2))

w = max(len(r[0]) for r in results)
for r in results:
    print(f"{r[0]:<{w}}  {r[1]:<30} {r[2]:>6}  {r[3]}")
print(sum(r[1] == "ok" for r in results), "of", len(results), "ok")
