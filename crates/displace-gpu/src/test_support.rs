//! One GPU device shared by every test of a test binary, and the policy for
//! machines without one (a GPU test that finds no adapter must not pass
//! quietly in CI): with `CI` set, a missing adapter fails the test; elsewhere it fails
//! too, loudly, unless `DISPLACE_ALLOW_NO_GPU=1` lets the GPU tests pass
//! without running.

use crate::GpuContext;
use std::sync::OnceLock;

static SHARED: OnceLock<Result<GpuContext, String>> = OnceLock::new();

/// The shared device, or `None` when there is none and the environment
/// allows that. Panics (fails the test) otherwise.
pub fn test_context() -> Option<&'static GpuContext> {
    let shared = SHARED.get_or_init(|| GpuContext::new_headless().map_err(|e| e.to_string()));
    match shared {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            let in_ci = std::env::var_os("CI").is_some();
            let allowed = std::env::var("DISPLACE_ALLOW_NO_GPU").is_ok_and(|v| v == "1");
            if in_ci {
                panic!("GPU test: no usable GPU adapter in CI: {e}. CI must install mesa-vulkan-drivers.");
            }
            eprintln!("\n!!!!!!!! GPU TEST NOT RUN: no usable GPU adapter: {e}");
            if !allowed {
                panic!("no GPU adapter ({e}); install mesa-vulkan-drivers, or set DISPLACE_ALLOW_NO_GPU=1 to skip GPU tests knowingly");
            }
            eprintln!("!!!!!!!! DISPLACE_ALLOW_NO_GPU=1: skipping this GPU test\n");
            None
        }
    }
}

/// `&[(name, offset)]` of the fields of a `repr(C)` Rust mirror of a WGSL
/// struct, for checking it against the offsets naga lays the WGSL out with:
/// one spelling for this crate's layout tests and its integration tests, so
/// a field list cannot drift from the names it is compared by.
#[macro_export]
macro_rules! field_offsets {
    ($t:ty { $($field:ident),* $(,)? }) => {
        &[$((stringify!($field), std::mem::offset_of!($t, $field))),*]
    };
}
