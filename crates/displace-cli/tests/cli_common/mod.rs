//! What several CLI test files share: running the binary, reading a run's
//! stderr, listing what a run left in its directory, the smallest scene
//! `render` draws, and the parts of the scenes the GPU tests compare
//! renderers on.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// A scratch directory for a test that needs the GPU, or `None` where
/// displace-gpu's test policy lets such a test pass without one.
#[cfg(feature = "gpu")]
pub fn gpu_scratch_dir() -> Option<tempfile::TempDir> {
    displace_gpu::test_support::test_context()?;
    Some(tempfile::tempdir().unwrap())
}

/// Runs `displace ARGS` in `dir` and returns what it did.
pub fn displace(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_displace"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run displace")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `o` failed without a panic, its message holding every needle and none
/// of the `absent` ones.
pub fn failed(o: &Output, needles: &[&str], absent: &[&str]) -> String {
    let msg = stderr(o);
    assert!(!o.status.success(), "succeeded: {msg}");
    assert!(!msg.contains("panicked"), "{msg}");
    for n in needles {
        assert!(msg.contains(n), "`{n}` not in: {msg}");
    }
    for a in absent {
        assert!(!msg.contains(a), "`{a}` in: {msg}");
    }
    msg
}

/// `text` with every `from` replaced by `to`; panics where `from` is not in
/// it, so a variant of a scene cannot quietly become the scene itself when
/// the scene's text drifts.
pub fn replaced(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "`{from}` is not in the text:\n{text}");
    text.replace(from, to)
}

/// The arguments of a command line without quoting: its words.
pub fn words(command: &str) -> Vec<&str> {
    command.split_whitespace().collect()
}

/// The names in `dir`, sorted.
pub fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A lit sphere, 8 x 8 pixels at 1 spp: renders in milliseconds.
pub const SPHERE_SCENE: &str = r#"
[image]
width = 8
height = 8
spp = 1
[camera]
position = [0, 1, -3]
look_at = [0, 0, 0]
[materials.m]
type = "lambert"
color = [0.5, 0.5, 0.5]
[[lights]]
type = "point"
position = [0, 3, -1]
intensity = [5, 5, 5]
[[shapes]]
type = "sphere"
center = [0, 0, 0]
radius = 1
material = "m"
"#;

/// Runs `displace ARGS` in `dir` with the bake cache in `dir/cache`, none
/// of the scheduler's task-index variables but those in `env` (a test run
/// under Slurm must not leak its own), and returns what it did.
pub fn displace_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_displace"));
    c.args(args)
        .current_dir(dir)
        .env("DISPLACE_CACHE", dir.join("cache"))
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("run displace")
}

/// A small bake of `height` (32 x 32 texels, 32 x 32 x 8 voxels) for
/// [`floor_scene`].
pub fn small_bake(height: &str) -> String {
    format!(r#"height = "{height}", height_size = [32, 32], depth = 0.1, map_size = [32, 32, 8]"#)
}

/// Asserts that a run succeeded (its stderr as the message) and returns it.
pub fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// A displaced floor under an area light, whose soft shadows draw random
/// numbers: `width` x `height_px` pixels at 2 spp; `displacement` is the
/// body of the floor's displacement table.
pub fn floor_scene(width: u32, height_px: u32, seed: u64, displacement: &str) -> String {
    format!(
        r#"
[image]
width = {width}
height = {height_px}
spp = 2
shadow_samples = 2
seed = {seed}
[camera]
position = [0, 1.6, -2.2]
look_at = [0, 0, 0]
vfov = 50
[materials.floor]
type = "lambert"
color = [0.7, 0.6, 0.5]
[[lights]]
type = "area"
origin = [-0.3, 2, -0.3]
edge_u = [0.6, 0, 0]
edge_v = [0, 0, 0.6]
radiance = [6, 6, 6]
{floor}displacement = {{ {displacement} }}
"#,
        floor = quad("[-1, 0, -1]", "[2, 0, 0]", "[0, 0, 2]", "floor"),
    )
}

/// What the GPU comparison scenes share: `width` x `height` pixels,
/// primitive visibility and direct light only (one sample, no reflections),
/// a pinhole `camera` and one point `light` (TOML keys of each).
pub fn frame([width, height]: [u32; 2], camera: &str, light: &str) -> String {
    format!(
        r#"[image]
width = {width}
height = {height}
spp = 1
max_depth = 0
shadow_samples = 1

[camera]
{camera}

[[lights]]
type = "point"
{light}
"#
    )
}

/// One displaced unit quad in the xy plane, in material `clay` (`material`
/// holds its TOML keys), displaced by the inline table `displacement`.
pub fn displaced_quad(material: &str, displacement: &str) -> String {
    format!("\n[materials.clay]\n{material}\n\n")
        + &quad(
            "[0.0, 0.0, 0.0]",
            "[1.0, 0.0, 0.0]",
            "[0.0, 1.0, 0.0]",
            "clay",
        )
        + &format!("displacement = {{ {displacement} }}\n")
}

/// `[materials.NAME]`: a Lambert surface of linear RGB `color`.
pub fn lambert(name: &str, color: &str) -> String {
    format!("[materials.{name}]\ntype = \"lambert\"\ncolor = {color}\n")
}

/// One `[[lights]]` point light of radiant `intensity` at `position`.
pub fn point_light(position: &str, intensity: &str) -> String {
    format!("[[lights]]\ntype = \"point\"\nposition = {position}\nintensity = {intensity}\n")
}

/// A `[[shapes]]` quad `origin + a edge_u + b edge_v` of `material`.
pub fn quad(origin: &str, edge_u: &str, edge_v: &str, material: &str) -> String {
    format!(
        "[[shapes]]\ntype = \"quad\"\norigin = {origin}\nedge_u = {edge_u}\nedge_v = {edge_v}\nmaterial = \"{material}\"\n"
    )
}

/// A `[[shapes]]` sphere of `material`.
pub fn sphere(center: &str, radius: f32, material: &str) -> String {
    format!(
        "[[shapes]]\ntype = \"sphere\"\ncenter = {center}\nradius = {radius:?}\nmaterial = \"{material}\"\n"
    )
}
