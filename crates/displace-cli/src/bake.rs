//! `displace bake`: height map in, conservative distance map (KTX2, DDS or
//! npy) and optionally a normal map out; and the memory check of a bake,
//! which `trace` shares.

use crate::args::{load_height, parse_extent, parse_format, parse_map_size, HeightArgs};
use crate::outputs::{check_distinct_outputs, check_not_inputs, check_output, check_output_dir};
use crate::progress::{cancel_flag, DelayedBar};
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::parse_size;
use displace_core::distance_map::Format;
use displace_core::io::atomic::Batch;
use displace_core::io::height;
use displace_core::io::stream::MapStream;
use displace_core::io::{self as dio, MapFile};
use displace_core::memory::StreamedBake;
use displace_core::techniques::{ConeKind, ConeMap};
use displace_core::{BakeOptions, Error, Extent, HeightMap, NormalMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `maxTextureDimension3D` of WebGPU's default limits: the largest map side
/// `gpu-render` can upload on every adapter.
pub const WEBGPU_MAX_3D: usize = 2048;

/// The built-in height map baked when none is given.
pub const DEFAULT_HEIGHT: &str = "gen:studded";

#[derive(Args, Debug)]
pub struct BakeArgs {
    /// Height map: gen:NAME[?key=value&...] (flat, gaussian, studded,
    /// grating, text, noise), a PNG, JPEG, TIFF (8/16-bit images; float or
    /// signed elevation rasters) or an EXR file
    #[arg(value_name = "HEIGHT", default_value = DEFAULT_HEIGHT)]
    pub height: String,
    #[command(flatten)]
    pub height_args: HeightArgs,
    /// Distance-map voxels, WxHxD (Donnelly used 256x256x16)
    #[arg(long, default_value = "256x256x16", value_name = "WxHxD")]
    pub size: String,
    /// Physical width, height and displacement depth of one tile of the face
    #[arg(long, default_value = "1,1,0.1", value_name = "SX,SY,SZ", value_parser = parse_extent, allow_hyphen_values = true)]
    pub extent: Extent,
    /// Storage format of .ktx2/.dds maps [default: r8; npy is always float32]
    #[arg(long, value_parser = parse_format)]
    pub format: Option<Format>,
    /// Output: .ktx2 (3D texture), .dds (volume texture) or .npy (float32
    /// (D, H, W) in the units of --extent)
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Also write the tangent-space normal map (+Y up) as a PNG
    #[arg(long, value_name = "NORMALS.png")]
    pub normals: Option<PathBuf>,
    /// Also write the cone map for cone step mapping, at the height map's
    /// resolution: .npy float32 (H, W), row j at v = (j + 0.5) / H, each the
    /// cone ratio (horizontal over vertical; unitless, for this --extent)
    #[arg(long, value_name = "CONES.npy")]
    pub cone: Option<PathBuf>,
    /// Which cones --cone holds: conservative (Dummer 2006, never pass the
    /// surface) or relaxed (Policarpo and Oliveira, GPU Gems 3 ch. 18)
    #[arg(long, default_value = "conservative", value_parser = parse_cone_kind)]
    pub cone_kind: ConeKind,
}

pub fn parse_cone_kind(s: &str) -> Result<ConeKind, String> {
    let choices = [
        ("conservative", ConeKind::Conservative),
        ("relaxed", ConeKind::Relaxed),
    ];
    displace_core::names::parse_choice("cone kind", s, &choices)
}

/// How a checked bake holds its map: whole in memory (`trace`), or
/// streamed to a file with `slab` slices in flight and `held` bytes per
/// voxel kept to the end (`bake`).
#[derive(Clone, Copy, Debug)]
pub enum BakeHolds {
    Whole,
    Streamed {
        slab: usize,
        encoded: u128,
        held: u128,
        normals: bool,
    },
}

/// Refuses a bake whose estimated peak memory exceeds what the machine has
/// available ([`displace_core::memory`]), before the height map is loaded.
pub fn check_bake_memory(
    source: &str,
    args: &HeightArgs,
    size: [usize; 3],
    cones: bool,
    holds: BakeHolds,
) -> Result<()> {
    let opts = args.options(match &args.height_size {
        Some(s) => parse_size::<2>(s).with_context(|| format!("--height-size {s}"))?,
        None => [size[0], size[1]],
    });
    let [w, h] = height::dimensions(source, &opts)
        .with_context(|| format!("loading height map `{source}`"))?;
    // One buffer too large says so first; then the whole job.
    HeightMap::check_size(w, h).with_context(|| format!("height map `{source}`"))?;
    let bytes = match holds {
        BakeHolds::Whole => displace_core::memory::bake_peak_bytes([w, h], size, cones),
        BakeHolds::Streamed {
            slab,
            encoded,
            held,
            normals,
        } => displace_core::memory::streamed_bake_peak_bytes(&StreamedBake {
            height: [w, h],
            map: size,
            slab_slices: slab,
            encoded_bytes_per_voxel: encoded,
            held_bytes_per_voxel: held,
            normals,
            cones,
        }),
    };
    displace_core::memory::check(
        &format!(
            "baking the {w}x{h} height map into {}x{}x{} voxels{}",
            size[0],
            size[1],
            size[2],
            if cones { " with its cone map" } else { "" }
        ),
        bytes,
    )?;
    Ok(())
}

pub fn run(args: BakeArgs) -> Result<()> {
    // Installed before any file is created: a signal in the first moments
    // (while the height map loads) must not kill the process with its
    // temporary file left behind.
    let cancel = cancel_flag();
    let size = parse_map_size(&args.size)?;
    let extent = args.extent;
    let kind = check_output(&args.output)?;
    let format = match (kind, args.format) {
        (MapFile::Npy, None | Some(Format::R32F)) => Format::R32F,
        (MapFile::Npy, Some(f)) => bail!(
            "--format {} with {}: .npy always stores float32 in the units of --extent; \
             formats apply to .ktx2 and .dds",
            f.name(),
            args.output.display()
        ),
        (_, f) => f.unwrap_or_default(),
    };
    if let Some(n) = &args.normals {
        let ext = n
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if ext.as_deref() != Some("png") {
            bail!(
                "--normals {}: the normal map is written as a .png",
                n.display()
            );
        }
        check_output_dir(n).with_context(|| format!("--normals {}", n.display()))?;
    }
    if let Some(c) = &args.cone {
        // Named before the generic output check, whose message is about
        // distance-map file types.
        let npy = c.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy"));
        if !npy
            || check_output(c).with_context(|| format!("--cone {}", c.display()))? != MapFile::Npy
        {
            bail!("--cone {}: the cone map is written as .npy", c.display());
        }
    }
    let mut outputs = vec![("-o", args.output.as_path())];
    outputs.extend(args.normals.as_deref().map(|n| ("--normals", n)));
    outputs.extend(args.cone.as_deref().map(|c| ("--cone", c)));
    check_distinct_outputs(&outputs)?;
    check_not_inputs(&outputs, &[("height map", Path::new(&args.height))])?;
    // A slice per thread: every core busy, and the least memory for that.
    let slab = rayon::current_num_threads();
    let held = if kind == MapFile::Ktx2 && format == Format::R16F {
        2
    } else {
        0
    };
    check_bake_memory(
        &args.height,
        &args.height_args,
        size,
        args.cone.is_some(),
        BakeHolds::Streamed {
            slab,
            encoded: format.bytes_per_voxel() as u128,
            held,
            normals: args.normals.is_some(),
        },
    )?;
    if size.iter().any(|&n| n > WEBGPU_MAX_3D) {
        eprintln!(
            "warning: a {}x{}x{} map exceeds {WEBGPU_MAX_3D} voxels per side, WebGPU's default \
             3D texture limit: gpu-render and view refuse it on such devices. A map coarser \
             than its height map stays conservative (the tracer refines on the full-resolution \
             heights), so --size {}x{}x{} traces the same surface on any GPU",
            size[0],
            size[1],
            size[2],
            size[0].min(WEBGPU_MAX_3D),
            size[1].min(WEBGPU_MAX_3D),
            size[2].min(WEBGPU_MAX_3D),
        );
    }
    // Every output under its temporary name until all are written; the map's
    // file is created first, so an unwritable destination fails before the
    // work.
    let batch = Batch::new();
    let mut stream = MapStream::create(&args.output, format, size, extent)
        .with_context(|| format!("writing {}", args.output.display()))?;
    // The whole command is timed: loading, baking, encoding and writing.
    let start = Instant::now();
    let height = load_height(&args.height, &args.height_args, [size[0], size[1]])?;

    let bar = DelayedBar::new(format!("baking {}x{}x{}", size[0], size[1], size[2]));
    let opts = BakeOptions {
        size,
        extent,
        progress: Some(bar.callback()),
        cancel: Some(cancel.clone()),
    };
    let baked = displace_core::bake_streamed(&height, &opts, slab, &mut stream);
    bar.finish();
    match baked {
        Err(Error::Cancelled) => bail!("interrupted: nothing was written"),
        Err(e @ (Error::Io { .. } | Error::Format { .. })) => {
            return Err(e).with_context(|| format!("writing {}", args.output.display()))
        }
        other => other.context("baking the distance map")?,
    }
    stream
        .finish()
        .with_context(|| format!("writing {}", args.output.display()))?;
    if let Some(n) = &args.normals {
        let normals = NormalMap::from_height(&height, extent)?;
        displace_core::io::png::write_normal_map_png(n, &normals)
            .with_context(|| format!("writing {}", n.display()))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let cones = match &args.cone {
        Some(c) => {
            let start = Instant::now();
            let bar = DelayedBar::counting(
                format!("baking the {} cone map", args.cone_kind.name()),
                "rows",
            );
            let cones = ConeMap::build_with(
                &height,
                extent.aspect(),
                args.cone_kind,
                Some(&bar.callback()),
                Some(&cancel_flag()),
            );
            bar.finish();
            let seconds = start.elapsed().as_secs_f64();
            let cones = match cones {
                Err(Error::Cancelled) => bail!("interrupted: nothing was written"),
                other => other?,
            };
            dio::npy::write_file(c, &[cones.height(), cones.width()], cones.data())
                .with_context(|| format!("writing {}", c.display()))?;
            Some((cones, seconds, c))
        }
        None => None,
    };
    batch.commit().context("moving the outputs into place")?;

    let voxels = (size[0] * size[1] * size[2]) as f64;
    println!(
        "baked {} ({}x{} texels, {}) to {}x{}x{} {} in {:.3} s ({:.1} Mvoxels/s) -> {}",
        args.height,
        height.width(),
        height.height(),
        args.height_args.address.name(),
        size[0],
        size[1],
        size[2],
        if kind == MapFile::Npy {
            "float32"
        } else {
            format.name()
        },
        seconds,
        voxels / seconds / 1e6,
        args.output.display()
    );
    if let Some(n) = &args.normals {
        println!("normal map -> {}", n.display());
    }
    if let Some((cones, seconds, c)) = cones {
        println!(
            "{} cone map {}x{} in {:.3} s ({} KiB) -> {}",
            args.cone_kind.name(),
            cones.width(),
            cones.height(),
            seconds,
            cones.bytes() / 1024,
            c.display()
        );
    }
    Ok(())
}
