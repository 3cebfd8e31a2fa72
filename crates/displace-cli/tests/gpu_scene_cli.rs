//! `displace gpu-render SCENE` against `displace render` on the same scene
//! file (a small scene rendered by gpu-render and by the CPU renderer
//! agrees within a stated tolerance; the UV AOV matches on at least 99.5%
//! of pixels), and bad scene input through gpu-render.
#![cfg(feature = "gpu")]

mod bad_scenes;
mod cli_common;

use bad_scenes::{assert_fails_alike, bad_scenes, FILE};
use cli_common::{displaced_quad, failed, frame, gpu_scratch_dir, lambert, quad, sphere};
use displace_core::io::npy::read_file;
use displace_gpu::test_support::test_context;
use std::path::Path;
use std::process::{Command, Output};

fn displace() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_displace"));
    // Bakes stay in memory: tests must not share a disk cache.
    c.env("DISPLACE_CACHE", "");
    c
}

/// The camera and light of [`scene`].
const QUAD_CAMERA: &str =
    "position = [0.5, -0.45, 0.95]\nlook_at = [0.5, 0.5, 0.0]\nup = [0.0, 0.0, 1.0]\nvfov = 50.0";
const QUAD_LIGHT: &str = "position = [-0.3, 0.2, 1.5]\nintensity = [3.0, 2.5, 2.0]";

/// The keys of the clay material most scenes here draw: a Lambert surface.
const CLAY: &str = "type = \"lambert\"\ncolor = [0.8, 0.6, 0.4]";

/// The displacement of [`scene`]'s quad, without the closing brace: a
/// test adds its own keys.
const QUAD_DISPLACEMENT: &str =
    r#"height = "gen:gaussian", height_size = [64, 64], depth = 0.15, map_size = [64, 64, 16]"#;

/// One displaced quad seen from above, lit from the side.
fn scene(material: &str) -> String {
    scene_with(material, "")
}

/// [`scene`] with `extra` keys in the quad's displacement.
fn scene_with(material: &str, extra: &str) -> String {
    frame([64, 64], QUAD_CAMERA, QUAD_LIGHT)
        + &displaced_quad(material, &format!("{QUAD_DISPLACEMENT}{extra}"))
}

fn run(args: &[&str], dir: &Path) -> Output {
    let out = displace().args(args).current_dir(dir).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn rgb(path: &Path) -> Vec<[f32; 3]> {
    image::open(path)
        .unwrap()
        .to_rgb8()
        .pixels()
        .map(|p| p.0.map(f32::from))
        .collect()
}

/// Where both renderers see the face: UV within 1e-3 of the CPU's on at
/// least 99.5% of pixels (hit or miss agreeing too); mean absolute sRGB
/// difference of the colour at most `max_mean` (8-bit steps) over pixels
/// both hit; the light of radiant `intensity` (TOML RGB).
fn compare(material: &str, intensity: &str, max_mean: f32) {
    let light = format!("position = [-0.3, 0.2, 1.5]\nintensity = {intensity}");
    let text = frame([64, 64], QUAD_CAMERA, &light) + &displaced_quad(material, QUAD_DISPLACEMENT);
    compare_scene(&text, material, max_mean);
}

/// [`compare`]'s verdict on the scene `text`, `label` naming it; nothing
/// where the environment allows running without a GPU.
fn compare_scene(text: &str, label: &str, max_mean: f32) {
    if test_context().is_none() {
        return;
    }
    let m = measure_scene(text);
    let frac = m.matching as f64 / m.pixels as f64;
    let mean = m.colour_mean();
    let hits = m.both_hit;
    eprintln!("{label}: uv match {frac:.4}, colour mean |diff| {mean:.2}/255 over {hits} hits");
    assert!(
        hits > 1000,
        "the face covers too little of the image: {hits}"
    );
    assert!(frac >= 0.995, "UV AOV matches on {frac}");
    assert!(mean <= max_mean, "mean colour difference {mean}");
}

/// Per-pixel agreement of the two renderers' 64x64 UV AOVs and colours.
struct Agreement {
    pixels: usize,
    /// Both miss, or both hit with UV within 1e-3.
    matching: usize,
    /// Hit on one and not the other.
    coverage_differs: usize,
    both_hit: usize,
    /// Both hit with UV within 1e-3.
    uv_close: usize,
    colour_sum: f32,
}

impl Agreement {
    fn colour_mean(&self) -> f32 {
        self.colour_sum / self.both_hit.max(1) as f32
    }

    /// The share of the pixels both hit whose UVs agree within 1e-3, and
    /// the share of all pixels that one hits and the other misses; both
    /// printed with the colour difference under `label`.
    fn shares(&self, label: &str) -> (f64, f64) {
        let uv = self.uv_close as f64 / self.both_hit as f64;
        let coverage = self.coverage_differs as f64 / self.pixels as f64;
        eprintln!(
            "{label}: uv within 1e-3 on {uv:.4} of {} pixels both hit; hit/miss differs on {coverage:.4}; colour mean |diff| {:.2}/255",
            self.both_hit,
            self.colour_mean()
        );
        (uv, coverage)
    }
}

fn measure_scene(text: &str) -> Agreement {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("one.toml"), text).unwrap();
    run(
        &["render", "one.toml", "-o", "cpu.png", "--aov", "uv,depth"],
        d,
    );
    run(&["gpu-render", "one.toml", "-o", "gpu.png", "--uv-aov"], d);
    let cpu_uv = read_file(&d.join("cpu.uv.npy")).unwrap();
    let cpu_depth = read_file(&d.join("cpu.depth.npy")).unwrap();
    let gpu = read_file(&d.join("gpu.uvkt.npy")).unwrap();
    assert_eq!(gpu.shape, [64, 64, 4]);
    let (cpu_c, gpu_c) = (rgb(&d.join("cpu.png")), rgb(&d.join("gpu.png")));
    let n = 64 * 64;
    let mut m = Agreement {
        pixels: n,
        matching: 0,
        coverage_differs: 0,
        both_hit: 0,
        uv_close: 0,
        colour_sum: 0.0,
    };
    for i in 0..n {
        let cpu_hit = cpu_depth.data[i].is_finite();
        let gpu_hit = gpu.data[4 * i + 2] > 0.0;
        if cpu_hit != gpu_hit {
            m.coverage_differs += 1;
            continue;
        }
        if !cpu_hit {
            m.matching += 1;
            continue;
        }
        m.both_hit += 1;
        let du = (cpu_uv.data[2 * i] - gpu.data[4 * i]).abs();
        let dv = (cpu_uv.data[2 * i + 1] - gpu.data[4 * i + 1]).abs();
        if du.max(dv) <= 1e-3 {
            m.matching += 1;
            m.uv_close += 1;
        }
        m.colour_sum += (0..3)
            .map(|c| (cpu_c[i][c] - gpu_c[i][c]).abs())
            .sum::<f32>()
            / 3.0;
    }
    m
}

/// Lambert: the two differ by the CPU's jittered sample position inside
/// the pixel (spp 1; the GPU samples the pixel centre), the 8-bit albedo
/// texture and the filtered normal map.
#[test]
fn lambert_quad_matches_the_cpu_renderer() {
    compare(CLAY, "[3.0, 2.5, 2.0]", 4.0);
}

/// Normalised Blinn-Phong with a grey highlight (the GPU's is white: the
/// mean of specular colour and light is used, so the light here is white).
#[test]
fn phong_quad_matches_the_cpu_renderer() {
    compare(
        "type = \"phong\"\ncolor = [0.7, 0.5, 0.3]\nspecular = [0.3, 0.3, 0.3]\nshininess = 20.0",
        "[2.5, 2.5, 2.5]",
        5.0,
    );
}

/// A face tiled 2 x 2 by a repeating map: the shell box spans all tiles and
/// the UV AOV counts tiles, as on the CPU.
#[test]
fn tiled_quad_matches_the_cpu_renderer() {
    let repeat = ", address = \"repeat\", tiles = [2.0, 2.0]";
    compare_scene(&scene_with(CLAY, repeat), "tiled", 6.0);
}

/// A `flip_v` quad (a left-handed face frame): drawn with the opposite
/// winding, displaced along the quad's own normal, UV running back along
/// `edge_v`, as on the CPU.
#[test]
fn flipped_quad_matches_the_cpu_renderer() {
    compare_scene(&scene_with(CLAY, ", flip_v = true"), "flip_v", 4.0);
}

/// Two displaced quads, the upright one in front of the other: one draw
/// each into a shared depth buffer must give the CPU's visibility (which
/// face, which texel) pixel for pixel. The colour is not compared tightly:
/// the CPU shades the shadow the upright face casts on the other, which the
/// GPU path leaves out (each face shadows only itself), and the studs'
/// texel-sized detail turns the CPU's jittered sample into large per-pixel
/// differences; measured mean difference 14.3/255 (bound 32).
#[test]
fn two_quads_occlude_each_other_as_on_the_cpu() {
    let camera =
        "position = [0.5, -0.9, 0.8]\nlook_at = [0.5, 0.5, 0.1]\nup = [0.0, 0.0, 1.0]\nvfov = 55.0";
    let text = frame([64, 64], camera, QUAD_LIGHT)
        + &displaced_quad(CLAY, QUAD_DISPLACEMENT)
        + "\n"
        + &lambert("blue", "[0.2, 0.3, 0.8]")
        + &quad(
            "[0.2, 0.3, 0.05]",
            "[0.6, 0.0, 0.0]",
            "[0.0, 0.0, 0.5]",
            "blue",
        )
        + r#"displacement = { height = "gen:studded", height_size = [64, 64], depth = 0.05, map_size = [64, 64, 8] }
"#;
    compare_scene(&text, "two quads", 32.0);
}

/// The scene's camera and light around a displaced mesh `shape` (TOML of
/// one `[[shapes]]` entry, material `clay`).
fn mesh_scene(shape: &str) -> String {
    frame(
        [64, 64],
        "position = [3.3, 2.7, -3.9]\nlook_at = [0.0, 0.0, 0.0]\nvfov = 45.0",
        "position = [1.5, 4.0, -3.0]\nintensity = [12.0, 11.0, 10.0]",
    ) + &format!(
        r#"
[materials.clay]
type = "lambert"
color = [0.8, 0.6, 0.4]

{shape}
"#
    )
}

/// A displaced built-in cube: its faces are exact planes, where the GPU's
/// locally flat shell is the CPU's prism, and its edges are creases, where
/// the GPU draws walls as the CPU's prisms have them; so both see the same
/// texel and the same silhouette. Measured: UV within 1e-3 on 100% of the
/// 1315 pixels both hit, hit/miss differing on no pixel, mean sRGB colour
/// difference 10.6/255 (the studs' sharp edges under the CPU's jittered
/// sample, and its shadows of one face on another, which the GPU leaves
/// out); bounds 99.5%, 0.5% and 16/255.
#[test]
fn displaced_cube_matches_the_cpu_renderer_on_its_faces() {
    if test_context().is_none() {
        return;
    }
    let m = measure_scene(&mesh_scene(
        r#"[[shapes]]
type = "mesh"
path = "builtin:cube"
rotate_y = 15
material = "clay"
displacement = { height = "gen:studded?period=8", height_size = [64, 64], depth = 0.08, map_size = [64, 64, 8] }"#,
    ));
    let (uv, coverage) = m.shares("cube");
    assert!(m.both_hit > 1000, "{}", m.both_hit);
    assert!(uv >= 0.995, "uv agrees on {uv}");
    assert!(coverage <= 0.005, "hit/miss differs on {coverage}");
    assert!(
        m.colour_mean() <= 16.0,
        "colour differs by {}",
        m.colour_mean()
    );
}

/// Curved meshes: both renderers trace the same shells along the vertex
/// normals (displace-render's `curved_shell`, the GPU's `curved.wgsl`)
/// and so see the same displaced surface `S = P + depth h(uv) N`: UV
/// within 1e-3 tile on at least 99.5% of the pixels both hit, hit/miss
/// differing on at most 1% (silhouette pixels, where the CPU's jittered
/// sample and the GPU's pixel centre see different sides of an edge).
/// Nothing to check where there is no GPU (`test_context`).
fn curved_mesh_matches(path: &str, displacement: &str) {
    if test_context().is_none() {
        return;
    }
    let m = measure_scene(&mesh_scene(&format!(
        "[[shapes]]\ntype = \"mesh\"\npath = \"{path}\"\nmaterial = \"clay\"\ndisplacement = {{ {displacement} }}"
    )));
    let (uv, coverage) = m.shares(path);
    assert!(m.both_hit > 500, "{}", m.both_hit);
    assert!(uv >= 0.995, "{path}: uv agrees on {uv}");
    assert!(coverage <= 0.01, "{path}: hit/miss differs on {coverage}");
}

#[test]
fn a_displaced_sphere_matches_the_cpu_renderer() {
    curved_mesh_matches(
        "builtin:sphere",
        r#"height = "gen:noise", height_size = [32, 32], depth = 0.12, map_size = [32, 32, 8], address = "repeat", tiles = [2, 1]"#,
    );
}

#[test]
fn a_displaced_torus_matches_the_cpu_renderer() {
    curved_mesh_matches(
        "builtin:torus",
        r#"height = "gen:studded?period=8", height_size = [32, 32], depth = 0.06, map_size = [32, 32, 8], address = "repeat", tiles = [6, 2]"#,
    );
}

/// Bad scenes fail gpu-render with the CPU renderer's own message, a
/// non-zero status, and no output file.
#[test]
fn bad_scenes_fail_like_the_cpu_renderer_and_write_nothing() {
    let good = scene(CLAY);
    for case in bad_scenes(&good, "gen:gaussian") {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        case.write(d);
        let gpu = displace()
            .args(["gpu-render", FILE, "-o", "out.png", "--uv-aov"])
            .current_dir(d)
            .output()
            .unwrap();
        let cpu = displace()
            .args(["render", FILE, "-o", "out.png"])
            .current_dir(d)
            .output()
            .unwrap();
        // Word for word the CPU renderer's message.
        assert_fails_alike(&case, &gpu, &cpu, d);
    }
}

/// A displaced OBJ quad (two triangles with `vt`) drawn through the GPU's
/// mesh path sees what the CPU's triangle prisms see: a flat mesh is where
/// the two treatments coincide (walls on its open boundary included).
/// Measured: UV within 1e-3 on 100% of the 1604 pixels both hit, hit/miss
/// differing on no pixel; bounds 99.5% and 0.5%.
#[test]
fn displaced_obj_mesh_matches_the_cpu_renderer() {
    let Some(dir) = gpu_scratch_dir() else {
        return;
    };
    let obj = dir.path().join("quad.obj");
    std::fs::write(
        &obj,
        "v -2 0 2\nv 2 0 2\nv 2 0 -2\nv -2 0 -2\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
    )
    .unwrap();
    let m = measure_scene(&mesh_scene(&format!(
        r#"[[shapes]]
type = "mesh"
path = "{}"
material = "clay"
displacement = {{ height = "gen:gaussian", height_size = [64, 64], depth = 0.2, map_size = [64, 64, 16] }}"#,
        obj.display()
    )));
    let (uv, coverage) = m.shares("obj quad");
    assert!(m.both_hit > 1000, "{}", m.both_hit);
    assert!(uv >= 0.995, "uv agrees on {uv}");
    assert!(coverage <= 0.005, "hit/miss differs on {coverage}");
}

/// OBJ input errors through gpu-render: a missing file names its path, a
/// malformed one its path and line, an unknown built-in the known ones;
/// word for word the CPU renderer's message, and nothing written.
#[test]
fn bad_meshes_fail_with_their_path_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 oops\nf 1 2 3\n").unwrap();
    std::fs::write(d.join("faces.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    for (path, needle) in [
        ("missing.obj", "missing.obj"),
        ("bad.obj", "bad.obj:3:"),
        ("faces.obj", "faces.obj:4:"),
        ("builtin:teapot", "builtin:torus"),
    ] {
        let text = mesh_scene(&format!(
            "[[shapes]]\ntype = \"mesh\"\npath = \"{path}\"\nmaterial = \"clay\""
        ));
        std::fs::write(d.join("s.toml"), text).unwrap();
        let before = std::fs::read_dir(d).unwrap().count();
        let gpu = displace()
            .args(["gpu-render", "s.toml", "-o", "out.png"])
            .current_dir(d)
            .output()
            .unwrap();
        let cpu = displace()
            .args(["render", "s.toml", "-o", "out.png"])
            .current_dir(d)
            .output()
            .unwrap();
        let gpu_err = failed(&gpu, &[needle], &[]);
        assert_eq!(gpu_err, String::from_utf8_lossy(&cpu.stderr), "{path}");
        assert_eq!(std::fs::read_dir(d).unwrap().count(), before, "{path}");
    }
}

/// What the first hit of a pixel is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Seen {
    Background,
    Plain,
    Displaced,
}

/// One scene through both renderers, classified per pixel: the CPU's by its
/// depth and iterations AOVs (a plain shape costs no map iterations), the
/// GPU's by the AOV's hit kind (3 for a plain shape); both sampled at the
/// pixel centre.
struct Classified {
    cpu: Vec<Seen>,
    gpu: Vec<Seen>,
    cpu_depth: Vec<f32>,
    /// World height of the CPU's hit.
    cpu_z: Vec<f32>,
    /// The GPU AOV's fourth channel: world distance for a plain hit.
    gpu_t: Vec<f32>,
    cpu_rgb: Vec<[f32; 3]>,
    gpu_rgb: Vec<[f32; 3]>,
}

fn classify(text: &str) -> Classified {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("s.toml"), text).unwrap();
    run(
        &[
            "render",
            "s.toml",
            "-o",
            "cpu.png",
            "--aov",
            "depth,iterations,position",
        ],
        d,
    );
    let out = run(&["gpu-render", "s.toml", "-o", "gpu.png", "--uv-aov"], d);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("rendered 1 displaced faces and meshes and")
            && !stdout.contains(" 0 plain"),
        "{stdout}"
    );
    let depth = read_file(&d.join("cpu.depth.npy")).unwrap().data;
    let iters = read_file(&d.join("cpu.iterations.npy")).unwrap().data;
    let position = read_file(&d.join("cpu.position.npy")).unwrap().data;
    let gpu = read_file(&d.join("gpu.uvkt.npy")).unwrap().data;
    let cpu = depth
        .iter()
        .zip(&iters)
        .map(|(&t, &n)| match (t.is_finite(), n > 0.0) {
            (false, _) => Seen::Background,
            (true, false) => Seen::Plain,
            (true, true) => Seen::Displaced,
        })
        .collect();
    let gpu_seen = gpu
        .chunks_exact(4)
        .map(|c| match c[2] as u32 {
            0 => Seen::Background,
            3 => Seen::Plain,
            _ => Seen::Displaced,
        })
        .collect();
    Classified {
        cpu,
        gpu: gpu_seen,
        cpu_depth: depth,
        cpu_z: position.chunks_exact(3).map(|p| p[2]).collect(),
        gpu_t: gpu.chunks_exact(4).map(|c| c[3]).collect(),
        cpu_rgb: rgb(&d.join("cpu.png")),
        gpu_rgb: rgb(&d.join("gpu.png")),
    }
}

impl Classified {
    /// Fraction of pixels where both see the same kind of thing, and where
    /// both see a plain shape, at the same distance within 0.5%.
    fn agreement(&self) -> f64 {
        let same = (0..self.cpu.len())
            .filter(|&i| {
                self.cpu[i] == self.gpu[i]
                    && (self.cpu[i] != Seen::Plain
                        || (self.gpu_t[i] - self.cpu_depth[i]).abs() <= 5e-3 * self.cpu_depth[i])
            })
            .count();
        same as f64 / self.cpu.len() as f64
    }

    /// Pixels both see as `seen` whose CPU hit's height lies in `z`.
    fn both(&self, seen: Seen, z: std::ops::Range<f32>) -> Vec<usize> {
        (0..self.cpu.len())
            .filter(|&i| self.cpu[i] == seen && self.gpu[i] == seen && z.contains(&self.cpu_z[i]))
            .collect()
    }

    /// The sRGB channel differences (8-bit steps) on `pixels`, sorted.
    fn colour_diffs(&self, pixels: &[usize]) -> Diffs {
        let mut d: Vec<f32> = pixels
            .iter()
            .flat_map(|&i| (0..3).map(move |k| (self.cpu_rgb[i][k] - self.gpu_rgb[i][k]).abs()))
            .collect();
        d.sort_by(f32::total_cmp);
        assert!(!d.is_empty(), "no pixels to compare");
        Diffs(d)
    }

    /// [`Classified::both`] pixels whose four neighbours are seen alike
    /// too: away from silhouettes, where the CPU's jittered sample may land
    /// on the other side.
    fn inside(&self, seen: Seen, z: std::ops::Range<f32>, width: usize) -> Vec<usize> {
        let n = self.cpu.len();
        let alike = |i: usize| self.cpu[i] == seen && self.gpu[i] == seen;
        self.both(seen, z)
            .into_iter()
            .filter(|&i| {
                i % width > 0
                    && i % width + 1 < width
                    && i >= width
                    && i + width < n
                    && [i - 1, i + 1, i - width, i + width].into_iter().all(alike)
            })
            .collect()
    }
}

/// Sorted colour differences.
struct Diffs(Vec<f32>);

impl Diffs {
    fn mean(&self) -> f32 {
        self.0.iter().sum::<f32>() / self.0.len() as f32
    }

    fn quantile(&self, f: f64) -> f32 {
        self.0[((self.0.len() as f64 * f) as usize).min(self.0.len() - 1)]
    }
}

/// The camera, light and displaced floor of the plain-shape tests, with
/// `shapes` (TOML `[[shapes]]` entries, material `wall`) added.
fn plain_scene(shapes: &str) -> String {
    frame(
        [64, 64],
        "position = [0.5, -0.8, 1.0]\nlook_at = [0.5, 0.6, 0.2]\nup = [0.0, 0.0, 1.0]\nvfov = 60.0",
        "position = [0.3, -0.3, 1.6]\nintensity = [3.0, 2.5, 2.0]",
    ) + &displaced_quad(CLAY, QUAD_DISPLACEMENT)
        + "\n"
        + &lambert("wall", "[0.3, 0.6, 0.7]")
        + shapes
}

/// A quad of the plain scenes' material `wall`.
fn wall_quad(origin: &str, edge_u: &str, edge_v: &str) -> String {
    quad(origin, edge_u, edge_v, "wall")
}

/// A Lambert wall behind a displaced floor, nothing between either and the
/// light: both renderers see background, wall and floor on the same pixels,
/// and the wall's colour is the CPU's direct term. The colour differs by
/// the CPU's jittered sample position in the pixel (spp 1) on a smoothly
/// shaded wall, and 8-bit rounding; colours are compared away from the
/// wall's silhouette. Measured: classes (and wall depths) agree on 100% of
/// the 4096 pixels; over 1020 wall pixels the sRGB colour's mean |diff| is
/// 0.35/255, its 99th percentile 1/255; bounds 99%, 1.5/255 and 4/255.
#[test]
fn a_plain_wall_matches_the_cpu_renderer() {
    if test_context().is_none() {
        return;
    }
    let wall = wall_quad("[-0.2, 1.2, 0.0]", "[1.4, 0.0, 0.0]", "[0.0, 0.0, 1.0]");
    let c = classify(&plain_scene(&wall));
    let agree = c.agreement();
    let all = f32::NEG_INFINITY..f32::INFINITY;
    let wall = c.inside(Seen::Plain, all.clone(), 64);
    let floor = c.both(Seen::Displaced, all);
    let d = c.colour_diffs(&wall);
    let (mean, p99) = (d.mean(), d.quantile(0.99));
    eprintln!(
        "wall: classes agree {agree:.4}, {} wall and {} floor pixels, colour mean {mean:.2}/255, p99 {p99}/255",
        wall.len(),
        floor.len()
    );
    assert!(wall.len() > 500 && floor.len() > 500);
    assert!(agree >= 0.99, "classes agree on {agree}");
    assert!(
        mean < 1.5 && p99 <= 4.0,
        "wall colour mean {mean}, p99 {p99}"
    );
}

/// Occlusion both ways through the one depth buffer: a plain quad floating
/// above the displaced floor hides it, and the floor hides a large plain
/// quad under it (seen only around the floor's edges). The CPU's per-pixel
/// visibility is the reference. Measured: classes (and plain depths) agree
/// on 100% of pixels, the floating quad hides the floor on 56; bounds 99%
/// and 40 (a floor drawn over the quad would break both).
#[test]
fn plain_and_displaced_shapes_occlude_each_other() {
    if test_context().is_none() {
        return;
    }
    let floating = wall_quad("[0.2, 0.2, 0.4]", "[0.6, 0.0, 0.0]", "[0.0, 0.6, 0.0]");
    let under = wall_quad("[-1.0, -0.5, -0.3]", "[3.0, 0.0, 0.0]", "[0.0, 3.0, 0.0]");
    let c = classify(&plain_scene(&format!("{floating}{under}")));
    let agree = c.agreement();
    // Where the floating quad hides the floor: the floor on those pixels
    // without it.
    let bare = classify(&plain_scene(&under));
    let hidden = c
        .both(Seen::Plain, 0.39..0.41)
        .into_iter()
        .filter(|&i| bare.cpu[i] == Seen::Displaced && bare.gpu[i] == Seen::Displaced)
        .count();
    let near = c.both(Seen::Plain, 0.39..0.41);
    let under = c.both(Seen::Plain, -0.31..-0.29);
    let floor = c.both(Seen::Displaced, f32::NEG_INFINITY..f32::INFINITY);
    eprintln!(
        "occlusion: classes agree {agree:.4}; {} floating ({hidden} over the floor), {} under, {} floor pixels",
        near.len(),
        under.len(),
        floor.len()
    );
    assert!(near.len() > 200, "floating quad on {} pixels", near.len());
    assert!(
        under.len() > 200,
        "quad under the floor on {} pixels",
        under.len()
    );
    assert!(floor.len() > 500, "floor on {} pixels", floor.len());
    assert!(
        hidden > 40,
        "the floating quad hides the floor on {hidden} pixels"
    );
    assert!(agree >= 0.99, "classes agree on {agree}");
}

/// The seed Cornell box on the GPU: walls, ceiling and back wall drawn
/// round the displaced floor (background where the CPU has it, within 1%
/// of pixels), the left wall red and the right wall green as in the CPU
/// render.
#[test]
fn cornell_box_walls_are_drawn() {
    if test_context().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell_studded.toml");
    let scene = scene.to_str().unwrap();
    run(
        &[
            "gpu-render",
            scene,
            "-o",
            "gpu.png",
            "--uv-aov",
            "--size",
            "96x96",
        ],
        d,
    );
    run(
        &[
            "render", scene, "-o", "cpu.png", "--size", "96x96", "--spp", "1", "--aov", "depth",
        ],
        d,
    );
    // The box is open towards the camera: background only past its front
    // edges, on the same pixels as on the CPU.
    let kinds = read_file(&d.join("gpu.uvkt.npy")).unwrap().data;
    let depth = read_file(&d.join("cpu.depth.npy")).unwrap().data;
    let differ = kinds
        .chunks_exact(4)
        .zip(&depth)
        .filter(|(k, t)| (k[2] > 0.0) != t.is_finite())
        .count();
    let background = depth.iter().filter(|t| !t.is_finite()).count();
    eprintln!("cornell: {background} background pixels, coverage differs on {differ}");
    assert!(
        differ <= 96 * 96 / 100,
        "coverage differs on {differ} pixels"
    );
    // Mean colour of columns x0..x1 over rows 30%..60% of the 96 x 96 image.
    let mean = |img: &[[f32; 3]], x0: usize, x1: usize| {
        let mut sum = [0.0f32; 3];
        let mut n = 0.0;
        for y in 29..58 {
            for x in x0..x1 {
                for k in 0..3 {
                    sum[k] += img[y * 96 + x][k];
                }
                n += 1.0;
            }
        }
        sum.map(|s| s / n)
    };
    for (name, img) in [
        ("gpu", rgb(&d.join("gpu.png"))),
        ("cpu", rgb(&d.join("cpu.png"))),
    ] {
        let (left, right) = (mean(&img, 3, 12), mean(&img, 84, 93));
        let back = mean(&img, 40, 56);
        eprintln!("{name}: left {left:?}, right {right:?}, back {back:?}");
        assert!(
            left[0] > 2.0 * left[1] && left[0] > 2.0 * left[2] && left[0] > 60.0,
            "{name} left wall {left:?}"
        );
        assert!(
            right[1] > 1.5 * right[0] && right[1] > 1.2 * right[2] && right[1] > 40.0,
            "{name} right wall {right:?}"
        );
        assert!(back.iter().all(|&c| c > 60.0), "{name} back wall {back:?}");
    }
}

/// A sphere over the displaced floor and a visible area-light quad behind
/// it: the tessellated sphere covers the CPU's exact sphere's pixels at
/// its distances, and the emitter is seen at full (clamped) radiance from
/// its front on both. Measured: classes and plain depths agree on 100% of
/// pixels, 196 sphere pixels, 30 light pixels away from its edges, all
/// white on both; bounds 99%, 100 and 20.
#[test]
fn a_sphere_and_a_visible_area_light_match_the_cpu_renderer() {
    if test_context().is_none() {
        return;
    }
    let shapes = sphere("[0.5, 0.5, 0.42]", 0.2, "wall")
        + r#"
[[lights]]
type = "area"
origin = [0.35, 1.3, 0.65]
edge_u = [0.3, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.2]
radiance = [5.0, 5.0, 5.0]
"#;
    let c = classify(&plain_scene(&shapes));
    let agree = c.agreement();
    let sphere = c.both(Seen::Plain, 0.21..0.63);
    let light = c.inside(Seen::Plain, 0.64..0.86, 64);
    eprintln!(
        "sphere: classes agree {agree:.4}; {} sphere, {} light pixels",
        sphere.len(),
        light.len()
    );
    assert!(sphere.len() > 100, "sphere on {} pixels", sphere.len());
    assert!(light.len() > 20, "light on {} pixels", light.len());
    assert!(agree >= 0.99, "classes agree on {agree}");
    for i in light {
        assert_eq!(c.cpu_rgb[i], [255.0; 3], "CPU light pixel {i}");
        assert_eq!(c.gpu_rgb[i], [255.0; 3], "GPU light pixel {i}");
    }
}

/// A built-in torus without displacement over the displaced floor: drawn
/// as its own triangles with its vertex normals, on the CPU's pixels at the
/// CPU's distances, and shaded as the CPU shades it (the CPU interpolates
/// the same normals). Colours are compared away from silhouettes; the
/// tail of the differences is where the CPU's torus shadows itself (the
/// GPU leaves shadows on plain shapes out). Measured: classes and plain
/// depths agree on 100% of pixels; over 510 torus pixels the sRGB colour's
/// |diff| has mean 2.76/255, median 1, 90th percentile 6, 99th 24; bounds
/// 99%, mean 4/255, median 2/255.
#[test]
fn a_plain_mesh_matches_the_cpu_renderer() {
    if test_context().is_none() {
        return;
    }
    let c = classify(&plain_scene(
        r#"
[[shapes]]
type = "mesh"
path = "builtin:torus"
translate = [0.5, 0.5, 0.35]
scale = 0.3
rotate_y = 30
material = "wall"
"#,
    ));
    let agree = c.agreement();
    let torus = c.inside(Seen::Plain, f32::NEG_INFINITY..f32::INFINITY, 64);
    let d = c.colour_diffs(&torus);
    let (mean, q) = (d.mean(), |f| d.quantile(f));
    eprintln!(
        "torus: classes agree {agree:.4}; {} torus pixels, colour mean {mean:.2}/255, median {}, p90 {}, p99 {}",
        torus.len(), q(0.5), q(0.9), q(0.99)
    );
    assert!(torus.len() > 100, "torus on {} pixels", torus.len());
    assert!(agree >= 0.99, "classes agree on {agree}");
    assert!(
        mean < 4.0 && q(0.5) <= 2.0,
        "torus colour mean {mean}, median {}",
        q(0.5)
    );
}
