//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod scene_toml;

use displace_render::{render, Aov, Crop, Image, RenderOptions, Rendered, Scene, SceneOptions};
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

/// A pool of `threads` threads, to render the same scene on different
/// thread counts.
pub fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

/// `scene` rendered over the `width x height` pixels at `(x, y)` only, with
/// `aovs`; an error where the rectangle leaves the image.
pub fn render_crop(
    scene: &Scene,
    [x, y, width, height]: [u32; 4],
    aovs: Vec<Aov>,
) -> displace_render::Result<(Crop, Rendered)> {
    let crop = Crop {
        x,
        y,
        width,
        height,
    };
    let opts = RenderOptions {
        crop: Some(crop),
        aovs,
        ..Default::default()
    };
    render(scene, &opts).map(|r| (crop, r))
}

/// Every pixel of `crop`, row by row, as its index in the full image
/// (`width` wide) and in the crop's own image.
pub fn crop_pixels(crop: Crop, width: u32) -> impl Iterator<Item = (usize, usize)> {
    (0..crop.height).flat_map(move |y| {
        (0..crop.width).map(move |x| {
            (
                ((crop.y + y) * width + crop.x + x) as usize,
                (y * crop.width + x) as usize,
            )
        })
    })
}

/// The camera, a Lambert material `m` and a floor of 100 x 100 repeating
/// tiles of a studded map (map coordinates in the thousands of cells),
/// seen from 2 units above: the scene of the tests that no ray slips
/// through a displaced surface. `[image]` and lights are the caller's.
pub const WIDE_STUDDED_FLOOR: &str =
    "[camera]\nposition = [0.3, 2, -1.5]\nlook_at = [0, 0, 0]\nvfov = 40\n\
    [materials.m]\ntype = \"lambert\"\ncolor = [0.9, 0.9, 0.9]\n\
    [[shapes]]\ntype = \"quad\"\norigin = [-200, 0, -200]\nedge_u = [0, 0, 400]\n\
    edge_v = [400, 0, 0]\nmaterial = \"m\"\n\
    [shapes.displacement]\nheight = \"gen:studded?period=4\"\nheight_size = [64, 64]\n\
    depth = 0.1\nmap_size = [32, 32, 8]\naddress = \"repeat\"\ntiles = [100, 100]\n";
