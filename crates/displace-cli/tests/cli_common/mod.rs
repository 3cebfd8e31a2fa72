//! What several CLI test files share: running the binary, reading a run's
//! stderr, listing what a run left in its directory, and the smallest scene
//! `render` draws.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

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
