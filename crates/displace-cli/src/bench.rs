//! `displace bench`: measurements that go into BENCHMARKS.md, one
//! subcommand per subject.

use crate::bench_render::{self, BenchRenderArgs};
use anyhow::Result;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Primary and shadow rays per second on displaced surfaces, per scene,
    /// on one core and on all.
    Render(BenchRenderArgs),
    /// GPU raster and compute paths and the bare fetch loop, ms/frame and
    /// Gpixels/s by GPU timestamps.
    Gpu(crate::gpu::BenchGpuArgs),
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchCommand::Render(a) => bench_render::run(a),
        BenchCommand::Gpu(a) => crate::gpu::run_bench(a),
    }
}
