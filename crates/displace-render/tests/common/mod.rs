//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod scene_toml;

use displace_render::{render, Image, RenderOptions, Rendered, Scene, SceneOptions};
use std::path::{Path, PathBuf};

pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// Options for tests: memory-only bakes, so tests neither need nor touch
/// the user's cache.
pub fn opts() -> SceneOptions {
    SceneOptions::default()
}

pub fn scene(text: &str) -> Scene {
    Scene::from_toml(text, Path::new("test.toml"), Path::new("."), &opts()).unwrap()
}

pub fn scene_err(text: &str) -> String {
    match Scene::from_toml(text, Path::new("test.toml"), Path::new("."), &opts()) {
        Ok(_) => panic!("scene was accepted"),
        Err(e) => e.to_string(),
    }
}

pub fn image(scene: &Scene) -> Image {
    render(scene, &RenderOptions::default()).unwrap().image
}

pub fn render_with(scene: &Scene, opts: &RenderOptions) -> Rendered {
    render(scene, opts).unwrap()
}
