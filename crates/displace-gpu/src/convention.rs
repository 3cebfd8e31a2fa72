//! The codes and tolerances the shaders share with Rust
//! ([`displace_shaders::codes`], re-exported here), and what this crate adds
//! to them: its bound on a trace's steps and the code of its shadow modes.

pub use displace_shaders::codes::*;

/// Most steps the GPU paths trace a ray with (`--iterations`, a scene's
/// `iterations`). The cause of the all-miss answer at 17000
/// sphere-fixed steps: lavapipe (llvmpipe) ends every loop of one shader
/// invocation once the loops have run 65535 iterations in all (Mesa's
/// `LP_MAX_TGSI_LOOP_ITERATIONS`), and the trace after the cut read as a
/// miss. Measured (`cargo run -p displace-gpu --example iteration_limit`):
/// 16382 steps agree with the CPU, 16383 do not, about four loop iterations
/// a step. The compute path flags a cut loop and refuses the batch
/// ([`FLAG_LOOP_CUT`]); the raster path cannot report one, so both are
/// bounded here: 4096 steps use a quarter of the budget and leave the rest
/// to the exact walk. Hardware drivers have no such limit but stop long
/// invocations with a watchdog.
pub const MAX_GPU_ITERATIONS: u32 = 4096;

/// Refuses a step count outside `1..=MAX_GPU_ITERATIONS`
/// ([`crate::Error::Iterations`]).
pub fn check_iterations(n: u32) -> crate::Result<()> {
    if (1..=MAX_GPU_ITERATIONS).contains(&n) {
        Ok(())
    } else {
        Err(crate::Error::Iterations(n))
    }
}

/// The shader's code for a shadow mode: the only way a [`crate::Shadows`]
/// reaches the GPU.
pub fn shadows_code(s: crate::Shadows) -> u32 {
    match s {
        crate::Shadows::None => SHADOWS_NONE,
        crate::Shadows::Hard => SHADOWS_HARD,
        crate::Shadows::Soft => SHADOWS_SOFT,
    }
}
