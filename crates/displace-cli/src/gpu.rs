//! `displace gpu-render` and `displace bench gpu`: the wgpu paths of
//! `displace-gpu` from the command line, and the GPU backend of the batch
//! ray query ([`trace_physical_gpu`]).
//!
//! `gpu-render SCENE` draws the displaced faces of a scene file ([`scene`]);
//! without one it draws a built-in scene (one displaced planar face, a
//! pinhole camera, a point light) configured by flags.

pub(crate) mod scene;

use crate::args::parse_extent;
use anyhow::{bail, Context, Result};
use displace_core::convention::parse_size;
use displace_core::io::atomic::Batch;
use displace_core::io::height::{load, HeightOptions, HeightRange};
use displace_core::{
    bake, Address, BakeOptions, DisplacementMap, DistanceMap, Extent, MapRay, Method, TraceOptions,
};
use displace_gpu::bench::bench_config;
use displace_gpu::{DistanceTexture, GpuContext, PlaneScene, RayTracer, Renderer, Shadows};
use displace_render::film::output::ImageFile;
use displace_render::texture::srgb_to_linear;
use glam::Vec3;
use std::path::PathBuf;

/// The displaced face: its height source, bake and proportions.
#[derive(clap::Args, Debug, Clone)]
pub struct FaceArgs {
    /// Height map: `gen:NAME?params`, a PNG, JPEG, TIFF or EXR.
    #[arg(long, default_value = "gen:studded")]
    pub height: String,
    /// Distance-map voxels, WxHxD (generated heights use W x H texels).
    #[arg(long, default_value = "256x256x16", value_name = "WxHxD")]
    pub map_size: String,
    /// Face width, height and displacement depth.
    #[arg(long, default_value = "1,1,0.1", value_name = "SX,SY,SZ", value_parser = parse_extent, allow_hyphen_values = true)]
    pub extent: Extent,
    /// clamp or repeat.
    #[arg(long, default_value = "clamp")]
    pub address: Address,
    /// Which values become heights 0 and 1: `auto` or LO,HI (as `bake`).
    #[arg(long, value_name = "auto|LO,HI", value_parser = crate::args::parse_height_range, allow_hyphen_values = true)]
    pub height_range: Option<HeightRange>,
}

/// With SCENE, the CPU renderer's scene file: each displaced parallelogram,
/// triangle and mesh is drawn by the GPU raster path with its own bake and
/// its material's colour, lit by the first point light (else the centre of
/// the first area light, as a point of intensity radiance x area); every
/// other shape (quads, boxes, spheres, plain meshes, visible area-light
/// quads) is drawn as plain triangles in the same depth buffer. Left out,
/// and listed on stderr: textures, reflections, other lights, depth of
/// field, shadows between faces and shadows on plain shapes. --height, --map-size, --extent,
/// --address, --method, --iterations, --eye and --light configure the
/// built-in plane only.
#[derive(clap::Args, Debug)]
pub struct GpuRenderArgs {
    /// Scene TOML (docs/scenes.md); omitted: the built-in displaced plane.
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub face: FaceArgs,
    /// Output image: .png (sRGB, as rendered) or .exr (its linear values).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Image size [default: the scene's, or 640x480 for the built-in plane].
    #[arg(long, value_name = "WxH")]
    pub size: Option<String>,
    /// Also write `<output stem>.uvkt.npy`, float32 [height, width, 4]: u,
    /// v, hit kind (0 none, 1 surface, 2 wall, 3 non-displaced shape) and
    /// map-space t (world distance from the eye for kind 3) per pixel.
    #[arg(long)]
    pub uv_aov: bool,
    /// Scene mode: do not read or write the on-disk bake cache.
    #[arg(long)]
    pub no_cache: bool,
    /// sphere (early out, exact refinement) or sphere-fixed (Donnelly's loop).
    #[arg(long, default_value = "sphere")]
    pub method: Method,
    #[arg(long, default_value_t = 64)]
    pub iterations: u32,
    /// none, hard or soft (a second march towards the light).
    #[arg(long, default_value = "hard")]
    pub shadows: Shadows,
    /// r32-load, r8-load, r16-linear or r8-linear.
    #[arg(long, default_value = "r8-linear")]
    pub distance: DistanceTexture,
    /// Camera position [default: oblique, above the face].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    pub eye: Option<Vec3>,
    /// Point light position.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    pub light: Option<Vec3>,
}

#[derive(clap::Args, Debug)]
pub struct BenchGpuArgs {
    #[command(flatten)]
    pub face: FaceArgs,
    /// Frame sizes [default: the set: 1280x1024 with a 256x256x16
    /// map at 8 and 16 iterations, 1920x1080 and 3840x2160 with a
    /// 512x512x64 map at 16 and 32].
    #[arg(long = "frame", value_name = "WxH")]
    pub frames_sizes: Vec<String>,
    /// Iteration counts for `--frame` sizes.
    #[arg(long = "iterations", default_values_t = [16u32])]
    pub iterations: Vec<u32>,
    /// Frames per measurement.
    #[arg(long, default_value_t = 10)]
    pub frames: u32,
}

fn parse_vec3(s: &str) -> Result<Vec3, String> {
    parse_floats::<3>(s).map(Vec3::from_array)
}

fn parse_floats<const N: usize>(s: &str) -> Result<[f32; N], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != N {
        return Err(format!("`{s}`: expected {N} comma-separated numbers"));
    }
    let mut out = [0.0f32; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("`{s}`: `{p}` is not a number"))?;
        if !o.is_finite() {
            return Err(format!("`{s}`: `{p}` is not finite"));
        }
    }
    Ok(out)
}

pub(crate) fn image_size(s: &str) -> Result<[u32; 2]> {
    let [w, h] = parse_size::<2>(s).with_context(|| format!("--size {s}"))?;
    let max = displace_gpu::raster::MAX_IMAGE_EDGE as usize;
    if w > max || h > max {
        bail!("--size {s}: each side must be at most {max}");
    }
    Ok([w as u32, h as u32])
}

/// Bakes the face's map for `ctx`, refusing first, from the height map's
/// header and the asked size, a map this GPU's textures cannot hold and a
/// bake past the memory limit: nothing is decoded or baked for a map the
/// GPU would then refuse.
fn bake_face(ctx: &GpuContext, face: &FaceArgs, map_size: &str) -> Result<DisplacementMap> {
    let size = parse_size::<3>(map_size).with_context(|| format!("--map-size {map_size}"))?;
    DistanceMap::check_size(size).with_context(|| format!("--map-size {map_size}"))?;
    let height_args = crate::args::HeightArgs {
        height_size: None,
        channel: None,
        address: face.address,
        height_range: face.height_range,
    };
    let dims = crate::args::height_dimensions(&face.height, &height_args, [size[0], size[1]])?;
    displace_gpu::GpuMap::check_sizes(ctx, dims, size)
        .with_context(|| format!("--height {} --map-size {map_size}", face.height))?;
    crate::bake::check_bake_memory(
        &face.height,
        &height_args,
        size,
        false,
        crate::bake::BakeHolds::Whole,
    )?;
    let height = load(
        &face.height,
        &HeightOptions {
            size: [size[0], size[1]],
            address: face.address,
            range: face.height_range.unwrap_or_default(),
            ..HeightOptions::default()
        },
    )
    .with_context(|| format!("loading height map {}", face.height))?;
    bake(&height, &BakeOptions::new(size, face.extent)).context("baking the distance map")
}

/// Writes a GPU frame's RGBA8 (sRGB) texels as an RGB PNG: the frames are
/// opaque, so the alpha channel is dropped, as `render` writes its PNGs.
pub(crate) fn write_png_rgba8(
    path: &std::path::Path,
    width: u32,
    height: u32,
    rgba8: &[u8],
) -> displace_render::Result<()> {
    let rgb: Vec<u8> = rgba8
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    displace_render::film::output::write_png_rgb8(path, width, height, &rgb)
}

/// Refuses a `size` frame that this GPU cannot hold
/// ([`displace_gpu::raster::Targets::check`]) or whose memory passes the
/// limit, before anything is loaded or baked: the readback and the image
/// on the host, the device's targets too where the device is the CPU
/// (lavapipe), and the UV image's copy when it is written.
fn check_frame(ctx: &GpuContext, [w, h]: [u32; 2], uv_aov: bool) -> Result<()> {
    use displace_gpu::raster::{DEVICE_BYTES_PER_PIXEL, READBACK_BYTES_PER_PIXEL};
    displace_gpu::raster::Targets::check(ctx, [w, h]).with_context(|| format!("--size {w}x{h}"))?;
    let per_pixel = READBACK_BYTES_PER_PIXEL
        + if ctx.is_software() {
            DEVICE_BYTES_PER_PIXEL
        } else {
            0
        }
        + if uv_aov { 16 } else { 0 };
    displace_core::memory::check(
        &format!("a {w}x{h} GPU frame"),
        u128::from(w) * u128::from(h) * per_pixel,
    )?;
    Ok(())
}

fn open_gpu() -> Result<GpuContext> {
    let ctx = GpuContext::new_headless().context("opening a GPU")?;
    eprintln!("gpu: {}", ctx.describe());
    Ok(ctx)
}

/// `<output stem>.uvkt.npy` next to `output`.
/// Every file `gpu-render` writes: the image, and the UV image with
/// `--uv-aov`; checked against its inputs before any work.
fn written(args: &GpuRenderArgs) -> Vec<(String, PathBuf)> {
    let mut out = vec![("-o".to_string(), args.output.clone())];
    if args.uv_aov {
        out.push(("--uv-aov".to_string(), uv_aov_path(&args.output)));
    }
    out
}

fn uv_aov_path(output: &std::path::Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    output
        .parent()
        .unwrap_or(std::path::Path::new(""))
        .join(format!("{stem}.uvkt.npy"))
}

/// Refuses outputs that cannot be written, before any GPU work: an
/// unknown image type, a missing directory, and `--iterations` out of
/// range for the built-in plane.
fn check_render_args(args: &GpuRenderArgs) -> Result<ImageFile> {
    let kind = ImageFile::from_path(&args.output)?;
    crate::outputs::check_output_dir(&args.output)?;
    check_gpu_iterations(args.iterations).context("--iterations")?;
    Ok(kind)
}

/// Refuses a step count outside
/// `1..=displace_gpu::convention::MAX_GPU_ITERATIONS` (whose docs say why).
pub fn check_gpu_iterations(n: u32) -> Result<()> {
    Ok(displace_gpu::convention::check_iterations(n)?)
}

/// Writes the frame (PNG as rendered, sRGB; EXR as its linear values) and
/// with `uv_aov` the AOV, together: both or neither.
fn write_outputs(
    output: &std::path::Path,
    kind: ImageFile,
    image: &displace_gpu::Image,
    uv_aov: bool,
) -> Result<()> {
    let batch = Batch::new();
    if uv_aov {
        let npy = uv_aov_path(output);
        let data: Vec<f32> = image.uv.iter().flatten().copied().collect();
        displace_core::io::npy::write_file(
            &npy,
            &[image.height as usize, image.width as usize, 4],
            &data,
        )
        .with_context(|| format!("writing {}", npy.display()))?;
    }
    match kind {
        ImageFile::Png => write_png_rgba8(output, image.width, image.height, &image.rgba8),
        ImageFile::Exr => {
            // The frame is rendered to an 8-bit sRGB target: its EXR is
            // those values decoded to linear, as `render` writes EXR.
            let pixels = image
                .rgba8
                .chunks_exact(4)
                .map(|p| {
                    Vec3::from_array([p[0], p[1], p[2]].map(|c| srgb_to_linear(c as f32 / 255.0)))
                })
                .collect();
            let linear = displace_render::Image {
                width: image.width,
                height: image.height,
                pixels,
            };
            displace_render::film::output::write_image(output, &linear)
        }
    }
    .with_context(|| format!("writing {}", output.display()))?;
    batch.commit().context("moving the outputs into place")
}

fn run_scene(args: &GpuRenderArgs, path: &std::path::Path) -> Result<()> {
    if args.eye.is_some() || args.light.is_some() {
        bail!(
            "--eye and --light configure the built-in plane; a scene has its own camera and lights"
        );
    }
    let kind = check_render_args(args)?;
    let size = args.size.as_deref().map(image_size).transpose()?;
    // The scene file before it is loaded (and its bakes made), every file
    // it reads once they are known.
    let written = written(args);
    crate::outputs::check_not_scene_inputs(&written, &[], Some(path))?;
    let loaded = scene::load(path, size, args.no_cache)?;
    crate::outputs::check_not_scene_inputs(&written, &loaded.sources, Some(path))?;
    let ctx = open_gpu()?;
    check_frame(&ctx, [loaded.width, loaded.height], args.uv_aov)?;
    let (draws, image) = scene::render(&ctx, &loaded, args.distance, args.shadows)
        .with_context(|| format!("rendering {}", path.display()))?;
    if !draws.left_out.is_empty() {
        eprintln!("gpu-render: not drawn: {}", draws.left_out.join("; "));
    }
    write_outputs(&args.output, kind, &image, args.uv_aov)?;
    println!(
        "rendered {} displaced faces and meshes and {} plain triangles, {}x{} -> {}",
        draws.displaced(),
        draws.plain_triangles,
        image.width,
        image.height,
        args.output.display()
    );
    Ok(())
}

pub fn run_render(args: GpuRenderArgs) -> Result<()> {
    if let Some(path) = args.scene.clone() {
        return run_scene(&args, &path);
    }
    let kind = check_render_args(&args)?;
    let size = image_size(args.size.as_deref().unwrap_or("640x480"))?;
    if args.method == Method::Exact {
        bail!(
            "--method exact is the CPU reference; the GPU paths trace with sphere or sphere-fixed"
        );
    }
    let height = std::path::Path::new(&args.face.height);
    if !args
        .face
        .height
        .starts_with(displace_core::generators::PREFIX)
    {
        let written = written(&args);
        let written: Vec<(&str, &std::path::Path)> = written
            .iter()
            .map(|(n, p)| (n.as_str(), p.as_path()))
            .collect();
        crate::outputs::check_not_inputs(&written, &[("--height", height)])?;
    }
    let ctx = open_gpu()?;
    check_frame(&ctx, size, args.uv_aov)?;
    let map = bake_face(&ctx, &args.face, &args.face.map_size)?;
    let mut scene = PlaneScene::for_map(&map, size);
    scene.draw.method = args.method;
    scene.draw.iterations = args.iterations;
    scene.draw.shadows = args.shadows;
    if let Some(eye) = args.eye {
        scene.view.eye = eye;
    }
    if let Some(light) = args.light {
        scene.view.light = light;
    }
    let renderer = Renderer::new(&ctx, &map, args.distance).context("building the GPU renderer")?;
    let image = renderer
        .render(&ctx, &scene)
        .context("rendering on the GPU")?;
    write_outputs(&args.output, kind, &image, args.uv_aov)?;
    println!(
        "rendered {}x{} -> {}",
        image.width,
        image.height,
        args.output.display()
    );
    Ok(())
}

pub fn run_bench(args: BenchGpuArgs) -> Result<()> {
    let configs: Vec<(String, String, Vec<u32>)> = if args.frames_sizes.is_empty() {
        vec![
            ("1280x1024".into(), "256x256x16".into(), vec![8, 16]),
            ("1920x1080".into(), "512x512x64".into(), vec![16, 32]),
            ("3840x2160".into(), "512x512x64".into(), vec![16, 32]),
        ]
    } else {
        args.frames_sizes
            .iter()
            .map(|s| {
                (
                    s.clone(),
                    args.face.map_size.clone(),
                    args.iterations.clone(),
                )
            })
            .collect()
    };
    let ctx = open_gpu()?;
    if ctx.is_software() {
        println!("note: {} is a software rasteriser: these figures measure the CPU it runs on, not a GPU", ctx.info.name);
    }
    println!(
        "| path | variant | frame | map | iterations | ms/frame | Gpix/s | timer | wall ms/frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (frame, map_size, iterations) in configs {
        let size = image_size(&frame)?;
        let map = bake_face(&ctx, &args.face, &map_size)?;
        for &n in &iterations {
            for row in bench_config(&ctx, &map, size, n, args.frames)
                .with_context(|| format!("benchmarking {frame} at {n} iterations"))?
            {
                println!(
                    "| {} | {} | {frame} | {map_size} | {n} | {:.3} | {:.3} | {} | {:.3} |",
                    row.path,
                    row.variant,
                    row.timing.ms_per_frame,
                    row.gpix_per_s(),
                    if row.timing.gpu_timestamps {
                        "timestamps"
                    } else {
                        "wall clock"
                    },
                    row.timing.wall_ms_per_frame
                );
            }
        }
    }
    Ok(())
}

/// The GPU backend of `displace trace`: physical-frame rays `[ox, oy, oz,
/// dx, dy, dz]` (the face's units; map space times the depth) in, `[t, x, y,
/// z, iterations]` out with `t = inf` and NaN coordinates for a miss, the
/// same records the CPU backend writes.
pub fn trace_physical_gpu(
    ctx: &GpuContext,
    map: &DisplacementMap,
    opts: &TraceOptions,
    texture: DistanceTexture,
    rays: &[[f32; 6]],
) -> Result<Vec<[f32; 5]>> {
    map.check_trace(opts).context("trace options")?;
    check_gpu_iterations(opts.iterations).context("--iterations with --backend gpu")?;
    let sz = map.extent.sz;
    let map_rays: Vec<MapRay> = rays
        .iter()
        .map(|r| {
            MapRay::new(
                Vec3::new(r[0], r[1], r[2]) / sz,
                Vec3::new(r[3], r[4], r[5]),
            )
        })
        .collect();
    let tracer = RayTracer::new(ctx, map, texture).context("building the GPU ray query")?;
    let hits = tracer
        .trace(ctx, &map_rays, opts)
        .context("tracing on the GPU")?;
    Ok(rays
        .iter()
        .zip(hits)
        .map(|(r, h)| match h {
            Some(hit) => {
                let p = hit.position * sz;
                let len = Vec3::new(r[3], r[4], r[5]).length();
                [hit.t * sz / len, p.x, p.y, p.z, hit.iterations as f32]
            }
            None => [f32::INFINITY, f32::NAN, f32::NAN, f32::NAN, 0.0],
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_core::generators;

    /// The GPU backend's records equal the CPU's within 1e-3 shell depths.
    #[test]
    fn physical_records_match_the_cpu() {
        let Some(ctx) = displace_gpu::test_support::test_context() else {
            return;
        };
        let height = generators::generate("gen:gaussian", 32, 32, Address::Clamp).unwrap();
        let extent = Extent::new(2.0, 1.0, 0.25).unwrap();
        let map = bake(&height, &BakeOptions::new([32, 32, 8], extent)).unwrap();
        let mut rays = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let o = [i as f32 * 0.1, j as f32 * 0.05, 0.6];
                rays.push([
                    o[0],
                    o[1],
                    o[2],
                    0.3 - i as f32 * 0.02,
                    0.1,
                    -1.0 - j as f32 * 0.1,
                ]);
            }
        }
        let opts = TraceOptions::default();
        let gpu = trace_physical_gpu(ctx, &map, &opts, DistanceTexture::R32Load, &rays).unwrap();
        let mut hits = 0;
        for (r, g) in rays.iter().zip(&gpu) {
            let ray = MapRay::new(
                Vec3::new(r[0], r[1], r[2]) / extent.sz,
                Vec3::new(r[3], r[4], r[5]),
            );
            match map.trace(&ray, &opts) {
                Some(c) => {
                    hits += 1;
                    let p = c.position * extent.sz;
                    let d = (Vec3::new(g[1], g[2], g[3]) - p).length();
                    assert!(d <= 1e-3 * extent.sz, "{r:?}: {g:?} vs {p}");
                    assert!(
                        (g[0] - c.t * extent.sz / Vec3::new(r[3], r[4], r[5]).length()).abs()
                            <= 1e-3 * extent.sz
                    );
                }
                None => assert!(g[0].is_infinite() && g[1].is_nan(), "{r:?}: {g:?}"),
            }
        }
        assert!(hits > 200, "{hits}");
    }
}
