//! `displace view SCENE`: the scene file's displaced faces in a window,
//! drawn every frame by the GPU raster path that `gpu-render` uses (the same
//! loading ([`crate::gpu::scene`]), validation, bakes and faces:
//! `displace_gpu::scene_draws`), with an
//! orbit camera and live controls (`displace_gpu::view`).
//!
//! `--frames N --screenshot OUT.png` renders N frames, writes the last as
//! presented and exits: with `--script` this is how tests and the README's
//! screenshots drive the viewer.

use crate::gpu::{image_size, scene};
use anyhow::{bail, Context, Result};
use displace_gpu::view::controls::parse_script;
use displace_gpu::view::window::{run as run_window, ViewOptions};
use displace_gpu::view::ViewScene;
use displace_gpu::{DistanceTexture, Shadows};
use std::path::PathBuf;

/// Draws the displaced faces of a scene file as `gpu-render SCENE` does
/// (what it leaves out is listed on stderr), in a window.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {
    /// Scene TOML (docs/scenes.md).
    pub scene: PathBuf,
    /// Window size [default: the scene's image size].
    #[arg(long, value_name = "WxH")]
    pub size: Option<String>,
    /// Render this many frames, then exit.
    #[arg(long, value_name = "N")]
    pub frames: Option<u32>,
    /// Write the last of --frames as PNG (sRGB, as presented, overlay
    /// included unless the script turns it off).
    #[arg(long, value_name = "OUT.png", requires = "frames")]
    pub screenshot: Option<PathBuf>,
    /// Commands applied before the first frame, `;`-separated (listed below).
    #[arg(long)]
    pub script: Option<String>,
    /// Starting shadows: none, hard or soft (the `s` key cycles them).
    #[arg(long, default_value = "hard")]
    pub shadows: Shadows,
    /// r32-load, r16-linear or r8-linear.
    #[arg(long, default_value = "r8-linear")]
    pub distance: DistanceTexture,
    /// Do not read or write the on-disk bake cache.
    #[arg(long)]
    pub no_cache: bool,
}

pub fn run(args: ViewArgs) -> Result<()> {
    let script = parse_script(args.script.as_deref().unwrap_or(""))?;
    if args.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    if let Some(out) = &args.screenshot {
        if !out
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        {
            bail!("--screenshot {}: the screenshot is a .png", out.display());
        }
    }
    let size = args.size.as_deref().map(image_size).transpose()?;
    let loaded = scene::load(&args.scene, size, args.no_cache)?;
    let opts = ViewOptions {
        size: [loaded.width, loaded.height],
        frames: args.frames,
        screenshot: args.screenshot.is_some(),
        script,
        title: format!("displace view {}", args.scene.display()),
    };
    let shot = run_window(opts, |ctx| -> Result<ViewScene> {
        eprintln!("gpu: {}", ctx.describe());
        let prepared = displace_gpu::from_scene(ctx, &loaded, args.distance, args.shadows)
            .with_context(|| format!("preparing {}", args.scene.display()))?;
        if !prepared.left_out.is_empty() {
            eprintln!("view: not drawn: {}", prepared.left_out.join("; "));
        }
        Ok(ViewScene {
            view: prepared.view,
            draws: prepared.draws,
            background: prepared.background,
        })
    })?;
    if let (Some(path), Some(shot)) = (&args.screenshot, shot) {
        crate::gpu::write_png_rgba8(path, shot.width, shot.height, &shot.rgba8)
            .with_context(|| format!("writing {}", path.display()))?;
        println!(
            "{} frames, {}x{} -> {}",
            args.frames.unwrap_or(0),
            shot.width,
            shot.height,
            path.display()
        );
    }
    Ok(())
}
