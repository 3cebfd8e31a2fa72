//! The bad scene files that every scene-reading command must refuse with
//! one message, written once for the tests that compare those commands
//! (`gpu-render` against `render`, `view` against `gpu-render`).

use std::path::Path;
use std::process::Output;

/// The name every case is written under: the malformed case's message
/// starts with it.
pub const FILE: &str = "bad.toml";

/// One bad scene: what is wrong, the file's text, and a piece of the
/// message that must name the problem.
pub struct BadScene {
    pub what: &'static str,
    pub text: String,
    pub needle: String,
}

impl BadScene {
    /// Writes the scene into `dir` as [`FILE`].
    pub fn write(&self, dir: &Path) {
        std::fs::write(dir.join(FILE), &self.text).unwrap();
    }
}

/// A syntax error, an unknown key and a missing height file, each made
/// from `good` (a scene whose twelfth line is `vfov = 50.0` and whose
/// displacement reads `height`).
pub fn bad_scenes(good: &str, height: &str) -> Vec<BadScene> {
    assert!(good.lines().nth(11) == Some("vfov = 50.0"), "{good}");
    assert!(good.contains(height), "{height} not in {good}");
    let missing = "no_such_height.png";
    [
        (
            "malformed",
            good.replace("vfov = 50.0", "vfov = = 50.0"),
            format!("{FILE}:12:8:"),
        ),
        (
            "unknown key",
            good.replace("vfov = 50.0", "vfov = 50.0\nzoom = 2.0"),
            "zoom".to_string(),
        ),
        (
            "missing height",
            good.replace(height, missing),
            missing.to_string(),
        ),
    ]
    .into_iter()
    .map(|(what, text, needle)| BadScene { what, text, needle })
    .collect()
}

/// `ours` and `reference` both failed on `case`, ours without a panic and
/// naming the problem, word for word as the reference, and `dir` holds
/// nothing but the scene file (no output, no leftover temporary).
pub fn assert_fails_alike(case: &BadScene, ours: &Output, reference: &Output, dir: &Path) {
    let what = case.what;
    let err = String::from_utf8_lossy(&ours.stderr);
    assert!(!ours.status.success(), "{what}: succeeded");
    assert!(!reference.status.success(), "{what}: reference succeeded");
    assert!(err.contains(&case.needle), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert_eq!(err, String::from_utf8_lossy(&reference.stderr), "{what}");
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, [FILE], "{what}");
}
