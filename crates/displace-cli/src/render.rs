//! `displace render`: ray trace a scene file (or the built-in studded Cornell
//! box) to PNG/EXR, with optional AOVs. Ctrl-C (or SIGTERM, SIGHUP) stops
//! the render and writes nothing; the outputs are written to temporary
//! names and renamed into place together at the end. `--tile I/N` renders
//! one farm tile to an EXR tile file for `displace merge`.

use anyhow::{bail, Context, Result};
use displace_core::io::atomic::Batch;
use displace_render::film::output::{aov_paths, write_aov, write_image, ImageFile};
use displace_render::film::tile_file::{write_tile, TileMeta};
use displace_render::film::tiling::{tile_rect, TileArg, TileIndex};
use displace_render::{render, Aov, Crop, RenderOptions, Scene, SceneOptions};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file (TOML, see docs/scenes.md). Without one, the built-in
    /// studded Cornell box with soft shadows.
    pub scene: Option<PathBuf>,
    /// Output image: .png (sRGB) or .exr (linear).
    #[arg(short, long, default_value = "out.png")]
    pub output: PathBuf,
    /// Samples per pixel (overrides the scene).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Light transport (overrides the scene's `integrator`): whitted (the
    /// seed's ray tracer) or path (path tracing with multiple importance
    /// sampling).
    #[arg(long)]
    pub integrator: Option<String>,
    /// The path integrator's numbers (overrides the scene's `sampler`):
    /// sobol (Owen-scrambled Sobol points, the default) or independent.
    #[arg(long)]
    pub sampler: Option<String>,
    /// Image size WxH (overrides the scene).
    #[arg(long)]
    pub size: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Render only the region x,y,w,h of the full image.
    #[arg(long)]
    pub crop: Option<String>,
    /// Render farm tile I of N (bands of whole rows of 16-pixel render
    /// tiles, counted from 0) to an EXR tile file for `displace merge`;
    /// `auto/N` takes I from SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX.
    #[arg(long, conflicts_with_all = ["crop", "aov"])]
    pub tile: Option<String>,
    /// AOVs to write next to the output, comma separated: depth, normal, uv,
    /// position, iterations (each as OUT.NAME.npy and OUT.NAME.png).
    #[arg(long, value_delimiter = ',')]
    pub aov: Vec<String>,
    /// Override every displaced face's tracing method: sphere,
    /// sphere-fixed or exact.
    #[arg(long)]
    pub method: Option<String>,
    /// Do not read or write the on-disk bake cache.
    #[arg(long)]
    pub no_cache: bool,
    /// The frame of the scene's `[animation]` to render, or `auto` (from
    /// SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX: one frame per task). A
    /// `%04d` in the output name is replaced by the frame number.
    #[arg(long, conflicts_with = "frames")]
    pub frame: Option<String>,
    /// Render frames A..B (B not included) of the scene's `[animation]`, one
    /// after the other, to OUT_%04d.png (the frame number replaces a
    /// `%04d` in the output name, or is appended to its stem).
    #[arg(long, conflicts_with_all = ["tile", "crop"])]
    pub frames: Option<String>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// What every frame of one `render` command shares, checked up front.
struct Plan {
    size: Option<[u32; 2]>,
    crop: Option<Crop>,
    aovs: Vec<Aov>,
    method: Option<displace_core::Method>,
    integrator: Option<displace_render::Integrator>,
    sampler: Option<displace_render::SamplerKind>,
    tile: Option<TileIndex>,
    pool: rayon::ThreadPool,
    cancel: Arc<AtomicBool>,
    /// Every file the command writes, of every frame: the images and their
    /// AOVs, each with the option that names it.
    written: Vec<(String, std::path::PathBuf)>,
}

pub fn run(args: RenderArgs) -> Result<()> {
    // Everything that can be refused is refused before any work.
    ImageFile::from_path(&args.output)?;
    let size = args
        .size
        .as_deref()
        .map(|s| displace_core::convention::parse_size::<2>(s).map(|[w, h]| [w as u32, h as u32]))
        .transpose()
        .context("--size")?;
    let crop: Option<Crop> = args.crop.as_deref().map(str::parse).transpose()?;
    let aovs: Vec<Aov> = args
        .aov
        .iter()
        .map(|a| a.trim().parse())
        .collect::<Result<_, _>>()?;
    if let Some(k) = (1..aovs.len()).find(|&k| aovs[..k].contains(&aovs[k])) {
        bail!(
            "--aov {} is asked for twice: each AOV is written once, beside the image",
            aovs[k].name()
        );
    }
    let method = parse_flag(args.method.as_deref(), "--method")?;
    let integrator = parse_flag(args.integrator.as_deref(), "--integrator")?;
    let sampler = parse_flag(args.sampler.as_deref(), "--sampler")?;
    let tile = args
        .tile
        .as_deref()
        .map(|t| resolve_tile(t, &args.output))
        .transpose()?;
    if args.frame.as_deref().map(str::trim) == Some("auto")
        && args
            .tile
            .as_deref()
            .is_some_and(|t| t.trim().starts_with("auto"))
    {
        bail!("--frame auto with --tile auto/N: both would take the one task index; give one of them explicitly");
    }
    let jobs = crate::frames::jobs(args.frame.as_deref(), args.frames.as_deref(), &args.output)?;
    // Every file of every frame, named and checked before the first frame:
    // a name too long, or two outputs on one file, found after frame 0 was
    // written (or after a whole render) would lose the work.
    let mut written = Vec::new();
    for (frame, output) in &jobs {
        let at = |name: &str| match frame {
            Some(f) if jobs.len() > 1 => format!("{name} (frame {f})"),
            _ => name.to_string(),
        };
        written.push((at("-o"), output.to_path_buf()));
        for &aov in &aovs {
            let (npy, png) = aov_paths(output, aov);
            let name = at(&format!("--aov {}", aov.name()));
            written.extend([(name.clone(), npy), (name, png)]);
        }
    }
    for (_, path) in &written {
        crate::outputs::check_output_dir(path)?;
    }
    let named: Vec<(&str, &std::path::Path)> = written
        .iter()
        .map(|(n, p)| (n.as_str(), p.as_path()))
        .collect();
    crate::outputs::check_distinct_outputs(&named)?;
    if let (Some(range), Some((Some(last), _))) = (&args.frames, jobs.last()) {
        let count = Scene::animation_frames(args.scene.as_deref())?;
        let count =
            count.with_context(|| format!("--frames {range}: the scene has no [animation]"))?;
        if *last >= count {
            bail!("--frames {range}: the animation has {count} frames (0..{count})");
        }
    }
    let pool = crate::threads::pool(args.threads)?;
    let cancel = crate::progress::cancel_flag();
    let plan = Plan {
        written,
        size,
        crop,
        aovs,
        method,
        integrator,
        sampler,
        tile,
        pool,
        cancel,
    };
    for (frame, output) in &jobs {
        render_one(&args, &plan, *frame, output)?;
    }
    Ok(())
}

/// Renders one image (one frame, or the whole of a still scene) to
/// `output`.
fn render_one(
    args: &RenderArgs,
    plan: &Plan,
    frame: Option<u32>,
    output: &std::path::Path,
) -> Result<()> {
    let (pool, cancel) = (&plan.pool, &plan.cancel);
    let opts = SceneOptions {
        frame,
        spp: args.spp,
        size: plan.size,
        method: plan.method,
        integrator: plan.integrator,
        sampler: plan.sampler,
        cache_dir: if args.no_cache {
            None
        } else {
            displace_render::default_cache_dir()
        },
        cancel: Some(cancel.clone()),
        no_image: false,
    };
    let start = Instant::now();
    let scene = crate::progress::loaded(pool.install(|| match &args.scene {
        Some(p) => Scene::load(p, &opts),
        None => Scene::default_scene(&opts),
    }))?;
    let setup = start.elapsed();
    // Every frame's outputs, not only this one's: at the first frame, a
    // later frame's name that is one of the scene's files is refused before
    // anything is written.
    crate::outputs::check_not_scene_inputs(&plan.written, scene.sources(), args.scene.as_deref())?;
    let stats = scene.cache_stats();
    for w in scene.warnings() {
        eprintln!("warning: {w}");
    }
    let tile_meta = plan
        .tile
        .map(|t| -> Result<TileMeta> {
            Ok(TileMeta {
                content_hash: scene.content_hash(),
                full_size: [scene.width(), scene.height()],
                rect: tile_rect(scene.width(), scene.height(), t)
                    .with_context(|| format!("--tile {t}"))?,
                tile: t,
            })
        })
        .transpose()?;
    let crop = tile_meta.map(|m| m.rect).or(plan.crop);

    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new(0);
        b.set_style(
            ProgressStyle::with_template(
                "{spinner} rendering [{bar:40}] {percent:>3}% {elapsed_precise} ETA {eta_precise}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        b
    };
    let progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let render_start = Instant::now();
    let result = pool.install(|| {
        render(
            &scene,
            &RenderOptions {
                crop,
                aovs: plan.aovs.clone(),
                progress: Some(&progress),
                cancel: Some(cancel.as_ref()),
            },
        )
    });
    bar.finish_and_clear();
    let rendered = match result {
        Err(displace_render::Error::Cancelled) => bail!("interrupted: nothing was written"),
        other => other?,
    };
    let render_time = render_start.elapsed();

    // The image and its AOVs land together or not at all.
    let batch = Batch::new();
    match &tile_meta {
        Some(meta) => write_tile(output, meta, &rendered.image)?,
        None => write_image(output, &rendered.image)?,
    }
    for a in &rendered.aovs {
        write_aov(output, a)?;
    }
    batch.commit().context("moving the outputs into place")?;
    let name = args
        .scene
        .as_ref()
        .map_or("built-in default scene".to_string(), |p| {
            p.display().to_string()
        });
    let name = match frame {
        Some(f) => format!("{name} frame {f}"),
        None => name,
    };
    if let Some(m) = &tile_meta {
        eprintln!(
            "tile {} of a {}x{} image: rows {}..{}, content hash {:016x}",
            m.tile,
            m.full_size[0],
            m.full_size[1],
            m.rect.y,
            m.rect.y + m.rect.height,
            m.content_hash
        );
    }
    eprintln!(
        "{name}: {}x{} at {} spp ({}), {} primitives, {} threads; setup {:.2} s (bakes: {} computed, {} from cache, {} shared), render {:.2} s -> {}",
        rendered.image.width,
        rendered.image.height,
        scene.spp(),
        scene.integrator().name(),
        scene.primitive_count(),
        pool.current_num_threads(),
        setup.as_secs_f64(),
        stats.baked,
        stats.loaded,
        stats.shared,
        render_time.as_secs_f64(),
        output.display()
    );
    for a in &rendered.aovs {
        let (npy, png) = aov_paths(output, a.aov);
        eprintln!(
            "  {}: {} and {}",
            a.aov.name(),
            npy.display(),
            png.display()
        );
    }
    Ok(())
}

/// `--tile I/N` or `auto/N` (the index from the scheduler), checked with
/// its output before any work: a tile is an EXR tile file.
fn resolve_tile(arg: &str, output: &std::path::Path) -> Result<TileIndex> {
    if ImageFile::from_path(output)? != ImageFile::Exr {
        bail!(
            "--tile {arg}: output {} must be .exr (a tile is linear float with its metadata; `displace merge` writes the PNG)",
            output.display()
        );
    }
    Ok(match arg.parse::<TileArg>()? {
        TileArg::Fixed(t) => t,
        TileArg::Auto { count } => {
            let index = crate::farm_env::task_index(&format!("--tile {arg}"))?;
            TileIndex::new(index, count).with_context(|| format!("--tile {arg}"))?
        }
    })
}

/// The value of an optional named flag (`--method`, `--integrator`,
/// `--sampler`), its parse error reported under the flag's name.
fn parse_flag<T>(value: Option<&str>, flag: &'static str) -> Result<Option<T>>
where
    T: std::str::FromStr,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    value.map(str::parse).transpose().context(flag)
}
