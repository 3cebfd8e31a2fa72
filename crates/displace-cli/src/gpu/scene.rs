//! `displace gpu-render SCENE` and `displace view SCENE`: the scene file
//! loaded and placed in the world exactly as `displace render` loads it, and
//! drawn by the GPU raster path ("the same scene TOML as the CPU renderer,
//! with the same camera conventions, so one scene renders on both and can
//! be compared"). What is drawn of it and what is left out is
//! `displace_gpu::scene_draws`; this module adds the command line's
//! options and the context of its messages.

use anyhow::{Context, Result};
use displace_gpu::{from_scene, DistanceTexture, GpuContext, Image, SceneDraws, Shadows};
use displace_scene::{SceneOptions, World};
use std::path::Path;

/// Loads `path` exactly as `displace render` does, and prints its warnings
/// as it does.
pub fn load(path: &Path, size: Option<[u32; 2]>, no_cache: bool) -> Result<World> {
    let opts = SceneOptions {
        size,
        cache_dir: if no_cache {
            None
        } else {
            displace_scene::default_cache_dir()
        },
        cancel: Some(crate::progress::cancel_flag()),
        ..SceneOptions::default()
    };
    let world = crate::progress::loaded(World::load(path, &opts))?;
    for w in &world.warnings {
        eprintln!("warning: {w}");
    }
    Ok(world)
}

/// The draws of `scene` and one frame of them.
pub fn render(
    ctx: &GpuContext,
    scene: &World,
    texture: DistanceTexture,
    shadows: Shadows,
) -> Result<(SceneDraws, Image)> {
    let draws = from_scene(ctx, scene, texture, shadows)?;
    let image = draws
        .render(ctx)
        .context("rendering the scene on the GPU")?;
    Ok((draws, image))
}
