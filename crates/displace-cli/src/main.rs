//! `displace`: bake distance maps, trace rays, render displaced scenes, and
//! measure it all. Each subcommand lives in its own module; errors are
//! reported with context and a non-zero exit code.

mod args;
mod bake;
mod bench;
mod compare;
mod export;
mod farm_env;
mod frames;
#[cfg(feature = "gpu")]
mod gpu;
mod merge;
mod outputs;
mod progress;
mod render;
mod threads;
mod trace;
#[cfg(feature = "gpu")]
mod view;

use clap::{Parser, Subcommand};

/// Large buffers (height and distance maps, films) in transparent huge
/// pages: a trace through a large map reads it at scattered places, and in
/// 4 KiB pages most of those reads also miss the TLB
/// ([`displace_core::memory::HugePages`]).
#[global_allocator]
static ALLOC: displace_core::memory::HugePages = displace_core::memory::HugePages;

#[derive(Parser)]
#[command(
    name = "displace",
    version,
    about = "Per-pixel displacement mapping with distance functions"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Bake a height map into a conservative 3D distance map (KTX2, DDS or
    /// npy) and optionally a normal map.
    Bake(bake::BakeArgs),
    /// Batch ray queries against one displaced face, or with --scene against
    /// a whole scene (first hits or any-hit; rays and hits as .npy).
    Trace(trace::TraceArgs),
    /// Ray trace a scene (or the built-in studded Cornell box) to PNG/EXR.
    Render(render::RenderArgs),
    /// Stitch the EXR tiles of `render --tile I/N` into the whole image,
    /// bit-identical to one render, after checking they are one render's
    /// tiles covering it exactly once.
    Merge(merge::MergeArgs),
    /// Measure: `bench bake`, `bench trace`, `bench render`, `bench gpu`.
    Bench(bench::BenchArgs),
    /// Write a height field as a triangle grid, or a scene's displaced meshes as their tessellated displaced surfaces (OBJ/PLY), for other renderers.
    ExportMesh(export::ExportMeshArgs),
    #[cfg(feature = "gpu")]
    /// Render a scene's displaced quads, triangles and meshes on the GPU,
    /// offscreen, to PNG (Donnelly's shaders); without SCENE, a built-in
    /// displaced plane configured by flags.
    GpuRender(gpu::GpuRenderArgs),
    /// Show a scene's displaced faces in a window (GPU raster path): orbit
    /// camera, live depth, iterations, method, shadows and light.
    #[cfg(feature = "gpu")]
    #[command(after_help = displace_gpu::view::controls::KEYS_HELP)]
    View(view::ViewArgs),
    /// Parallax, POM, relief, cone stepping, maximum mipmaps and distance
    /// mapping against the exact hit: CSV, plots and an image grid.
    Compare(compare::CompareArgs),
}

/// Why a GPU option is refused by a build without the `gpu` feature.
#[cfg(not(feature = "gpu"))]
const NO_GPU: &str =
    "this displace was built without GPU support (rebuild it with the default cargo feature `gpu`)";

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {
        Command::Bake(args) => bake::run(args),
        Command::Trace(args) => trace::run(args),
        Command::Render(args) => render::run(args),
        Command::Merge(args) => merge::run(args),
        Command::Bench(args) => bench::run(args),
        Command::ExportMesh(args) => export::run(args),
        #[cfg(feature = "gpu")]
        Command::GpuRender(args) => gpu::run_render(args),
        #[cfg(feature = "gpu")]
        Command::View(args) => view::run(args),
        Command::Compare(args) => compare::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", report(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes, joined by `: ` as `{:#}` joins them, but
/// without a cause whose text the message already ends with: the typed
/// errors print their source themselves (`FILE: No such file or directory`),
/// so `{:#}` would say it twice.
fn report(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.ends_with(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::report;
    use anyhow::Context;

    #[test]
    fn causes_already_in_the_message_are_not_repeated() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let typed = displace_core::Error::Io {
            path: "a.png".into(),
            source: io,
        };
        let e = Err::<(), _>(typed).context("loading a.png").unwrap_err();
        assert_eq!(format!("{e:#}"), "loading a.png: a.png: gone: gone");
        assert_eq!(report(&e), "loading a.png: a.png: gone");
    }
}
