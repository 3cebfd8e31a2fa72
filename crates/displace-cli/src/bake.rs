//! `displace bake`: height map in, conservative distance map (KTX2, DDS or
//! npy) and optionally a normal map out. Also the argument parsing shared
//! with `trace`, `compare` and `export-mesh` (height sources, sizes,
//! extents, output checks).

use crate::progress::{cancel_flag, DelayedBar};
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::parse_size;
use displace_core::distance_map::Format;
use displace_core::io::atomic::Batch;
use displace_core::io::height::{self, Channel, HeightOptions, HeightRange};
use displace_core::io::stream::MapStream;
use displace_core::io::{self as dio, MapFile};
use displace_core::memory::StreamedBake;
use displace_core::techniques::{ConeKind, ConeMap};
use displace_core::{Address, BakeOptions, DistanceMap, Error, Extent, HeightMap, NormalMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `maxTextureDimension3D` of WebGPU's default limits: the largest map side
/// `gpu-render` can upload on every adapter.
pub const WEBGPU_MAX_3D: usize = 2048;

/// The built-in height map baked when none is given.
pub const DEFAULT_HEIGHT: &str = "gen:studded";

/// How a height source is read (shared by `bake`, `trace`, `compare` and
/// `export-mesh`).
#[derive(Args, Debug, Clone)]
pub struct HeightArgs {
    /// Texels of a generated height map (`gen:...`), WxH [default: the
    /// distance map's W x H]
    #[arg(long, value_name = "WxH")]
    pub height_size: Option<String>,
    /// Channel of a colour image that holds the height [default: Rec. 709
    /// luminance]
    #[arg(long, value_parser = parse_channel)]
    pub channel: Option<Channel>,
    /// Texture addressing: a repeating height map bakes a tiling distance map
    #[arg(long, default_value = "clamp", value_parser = parse_address)]
    pub address: Address,
    /// Which values become heights 0 and 1: `auto` (the map's lowest and
    /// highest) or LO,HI in the file's values (an elevation model's metres,
    /// an image's codes) [default: 8/16-bit images by their full scale,
    /// float data as stored, in [0, 1]]
    #[arg(long, value_name = "auto|LO,HI", value_parser = parse_height_range, allow_hyphen_values = true)]
    pub height_range: Option<HeightRange>,
}

impl HeightArgs {
    /// The core's options for these arguments, `size` texels for a
    /// generated map.
    pub fn options(&self, size: [usize; 2]) -> HeightOptions {
        HeightOptions {
            channel: self.channel,
            size,
            address: self.address,
            range: self.height_range.unwrap_or_default(),
        }
    }
}

pub(crate) fn parse_height_range(s: &str) -> Result<HeightRange, String> {
    s.parse().map_err(|e: displace_core::Error| e.to_string())
}

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

pub fn parse_channel(s: &str) -> Result<Channel, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

pub fn parse_address(s: &str) -> Result<Address, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

pub fn parse_format(s: &str) -> Result<Format, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

/// `SX,SY,SZ`: three positive finite numbers.
pub fn parse_extent(s: &str) -> Result<Extent, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("`{s}`: expected three numbers SX,SY,SZ"));
    }
    let mut v = [0.0f32; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("`{s}`: `{p}` is not a number"))?;
    }
    Extent::new(v[0], v[1], v[2]).map_err(|e| e.to_string())
}

/// `WxHxD`, refused (before anything is allocated) when too large.
pub fn parse_map_size(s: &str) -> Result<[usize; 3]> {
    let size = parse_size::<3>(s).with_context(|| format!("--size {s}"))?;
    DistanceMap::check_size(size).with_context(|| format!("--size {s}"))?;
    Ok(size)
}

/// Loads `source`, with generated maps at `--height-size` or `default_size`.
pub fn load_height(source: &str, args: &HeightArgs, default_size: [usize; 2]) -> Result<HeightMap> {
    let size = match &args.height_size {
        Some(s) if !source.starts_with(displace_core::generators::PREFIX) => bail!(
            "--height-size {s} sets the size of a generated height map (gen:...); `{source}` has its own size"
        ),
        Some(s) => {
            let size = parse_size::<2>(s).with_context(|| format!("--height-size {s}"))?;
            HeightMap::check_size(size[0], size[1])
                .with_context(|| format!("--height-size {s}"))?;
            size
        }
        None => default_size,
    };
    let opts = args.options(size);
    height::load(source, &opts).with_context(|| format!("loading height map `{source}`"))
}

/// Refuses an output path whose file type or directory cannot work, before
/// any time is spent baking.
pub fn check_output(path: &Path) -> Result<MapFile> {
    let kind = MapFile::from_path(path).with_context(|| format!("output {}", path.display()))?;
    check_output_dir(path)?;
    Ok(kind)
}

/// Refuses an output path whose directory does not exist, so that no work
/// is done for a file that cannot be written.
pub fn check_output_dir(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!(
                "output {}: directory {} does not exist",
                path.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// `trace` writes `.npy` only; checked before any work is done, with a
/// message that names only what trace can write.
pub fn check_npy_output(path: &Path) -> Result<()> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    {
        bail!("output {}: hits are written as .npy", path.display());
    }
    check_output_dir(path)
}

/// Refuses two outputs of one command that name the same file: the later
/// write would silently replace the earlier one.
pub fn check_distinct_outputs(outputs: &[(&str, &Path)]) -> Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    for (i, (a_name, a)) in outputs.iter().enumerate() {
        for (b_name, b) in &outputs[..i] {
            if absolute(a) == absolute(b) {
                bail!(
                    "{b_name} and {a_name} are the same file ({}): each output needs its own path",
                    a.display()
                );
            }
        }
    }
    Ok(())
}

/// Refuses an output that names one of the command's inputs (the same
/// file, through whatever path: a link or `./` counts): the output is
/// written under a temporary name and renamed over the path at the end, so
/// the input would be replaced by what was made from it. Generated inputs
/// (`gen:...`, `builtin:...`) and inputs that do not exist yet name no
/// file.
pub fn check_not_inputs(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let identity = |p: &Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    for (out_name, out) in outputs {
        let out_id = identity(out);
        for (in_name, input) in inputs {
            let same = match (out_id, identity(input)) {
                (Some(a), Some(b)) => a == b,
                _ => absolute(out) == absolute(input),
            };
            if same {
                bail!(
                    "{out_name} {} is also an input ({in_name}): writing it would replace the file it is made from; choose another output path",
                    out.display()
                );
            }
        }
    }
    Ok(())
}

/// [`check_not_inputs`] for a command that writes `output` from a loaded
/// scene: every file the scene read (height maps, textures, meshes), and
/// the scene file itself where given.
pub fn check_not_scene_inputs(
    output: &Path,
    scene: &displace_render::Scene,
    scene_file: Option<&Path>,
) -> Result<()> {
    let mut read: Vec<(&str, &Path)> = scene
        .sources()
        .iter()
        .map(|p| ("a file the scene reads", p.as_path()))
        .collect();
    read.extend(scene_file.map(|p| ("scene", p)));
    check_not_inputs(&[("-o", output)], &read)
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
        cancel: Some(cancel_flag()),
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
        let normals = NormalMap::from_height(&height, extent);
        height::write_normal_map_png(n, &normals)
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
            );
            bar.finish();
            let seconds = start.elapsed().as_secs_f64();
            if cancel_flag().load(std::sync::atomic::Ordering::SeqCst) {
                bail!("interrupted: nothing was written");
            }
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
