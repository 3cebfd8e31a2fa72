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
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchCommand::Render(a) => bench_render::run(a),
    }
}
