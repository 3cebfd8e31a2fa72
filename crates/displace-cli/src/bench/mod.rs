//! `displace bench`: measurements that go into BENCHMARKS.md, one
//! subcommand per subject.

mod bake;
mod probe;
mod render;
mod trace;

use anyhow::Result;
use render::BenchRenderArgs;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Bake throughput (Mvoxels/s) next to `edt` and scipy on the same volume.
    Bake(bake::BenchBakeArgs),
    /// Map-space trace throughput (rays/s, one core and all) and iterations.
    Trace(trace::BenchTraceArgs),
    /// Primary and shadow rays per second on displaced surfaces, per scene,
    /// on one core and on all.
    Render(BenchRenderArgs),
    /// GPU raster and compute paths and the bare fetch loop, ms/frame and
    /// Gpixels/s by GPU timestamps.
    #[cfg(feature = "gpu")]
    Gpu(crate::gpu::BenchGpuArgs),
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchCommand::Bake(a) => bake::run(a),
        BenchCommand::Trace(a) => trace::run(a),
        BenchCommand::Render(a) => render::run(a),
        #[cfg(feature = "gpu")]
        BenchCommand::Gpu(a) => crate::gpu::run_bench(a),
    }
}
