//! `cargo run -p displace-bevy --example headless -- OUT.png [WxH]
//! [--method ours|ours-fixed|pom|relief] [--frames N]`: the `stone`
//! example's scene (a floor displaced by GPU Gems 2 ch. 8 distance mapping
//! through `DistanceMappedMaterial`, a sphere and a torus through
//! `CurvedMappedMaterial`'s curved shells) rendered offscreen and written
//! to a PNG: no window, any wgpu adapter (lavapipe in CI). `--method`
//! draws the floor and the sphere with Bevy's parallax occlusion or relief
//! mapping of the same height map instead; `--frames N` renders N more frames and prints their
//! mean time (BENCHMARKS.md).

#[allow(dead_code)] // the stone example uses the rest
mod common;

use bevy::pbr::ParallaxMappingMethod;
use bevy::prelude::*;
use bevy::render::render_resource::TextureFormat;
use displace_bevy::headless::Headless;
use displace_bevy::{DistanceMappedMaterial, MarchMethod};
use std::process::ExitCode;
use std::time::Instant;

struct Args {
    out: String,
    size: (u32, u32),
    method: String,
    frames: u32,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        out: String::new(),
        size: (640, 480),
        method: "ours".into(),
        frames: 0,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--method" => args.method = it.next().ok_or("--method needs a value")?,
            "--frames" => {
                let v = it.next().ok_or("--frames needs a value")?;
                args.frames = v
                    .parse()
                    .map_err(|_| format!("--frames {v}: not a count"))?;
            }
            s if args.out.is_empty() => args.out = s.to_string(),
            s => {
                args.size = parse_size(s)
                    .ok_or(format!("size `{s}`: expected WIDTHxHEIGHT, 1 to 8192 each"))?
            }
        }
    }
    if args.out.is_empty() {
        return Err(
            "usage: headless OUT.png [WxH] [--method ours|ours-fixed|pom|relief] [--frames N]"
                .into(),
        );
    }
    if !["ours", "ours-fixed", "pom", "relief"].contains(&args.method.as_str()) {
        return Err(format!(
            "--method {}: expected ours, ours-fixed, pom or relief",
            args.method
        ));
    }
    Ok(args)
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let (width, height) = args.size;
    let mut app = Headless::new(width, height, TextureFormat::Rgba8UnormSrgb);
    let target = app.target();
    let world = app.world_mut();
    let stone = common::spawn(world);
    match args.method.as_str() {
        "pom" | "relief" => {
            let method = if args.method == "pom" {
                ParallaxMappingMethod::Occlusion
            } else {
                ParallaxMappingMethod::Relief { max_steps: 5 }
            };
            let bevy = common::bevy_parallax(world, &stone, method);
            common::show_bevy(world, &stone, &bevy);
        }
        "ours-fixed" => {
            let mut ours = world.resource_mut::<Assets<DistanceMappedMaterial>>();
            let floor = ours.get_mut(&stone.floor_material);
            // The floor's march; the curved sphere's chords keep theirs.
            if let Some(mut m) = floor {
                m.extension = m.extension.clone().with_method(MarchMethod::Fixed);
            }
        }
        _ => {}
    }
    world.spawn((Camera3d::default(), target, common::camera_transform()));
    let image = match app.capture() {
        Ok(image) => image,
        Err(e) => {
            eprintln!("headless: {e}");
            return ExitCode::FAILURE;
        }
    };
    if args.frames > 0 {
        let start = Instant::now();
        for _ in 0..args.frames {
            app.update();
        }
        let ms = start.elapsed().as_secs_f64() * 1e3 / args.frames as f64;
        println!(
            "{} {width}x{height}: {ms:.1} ms per frame (mean of {} frames, update + render + GPU wait)",
            args.method, args.frames
        );
    }
    let Some(data) = image.data.as_ref() else {
        eprintln!("headless: the frame has no pixels");
        return ExitCode::FAILURE;
    };
    let rgb: Vec<u8> = data
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let Some(buffer) = image::RgbImage::from_raw(image.width(), image.height(), rgb) else {
        eprintln!(
            "headless: the frame is not {}x{} RGBA8",
            image.width(),
            image.height()
        );
        return ExitCode::FAILURE;
    };
    if let Err(e) = buffer.save(&args.out) {
        eprintln!("headless: writing {}: {e}", args.out);
        return ExitCode::FAILURE;
    }
    println!("rendered {width}x{height} -> {}", args.out);
    ExitCode::SUCCESS
}

fn parse_size(s: &str) -> Option<(u32, u32)> {
    let (w, h) = s.split_once('x')?;
    let (w, h) = (w.parse().ok()?, h.parse().ok()?);
    ((1..=8192).contains(&w) && (1..=8192).contains(&h)).then_some((w, h))
}
