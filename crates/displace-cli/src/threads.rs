//! The worker threads of a command's `--threads` (`render`, the benches):
//! one rayon pool, its size checked.

use anyhow::{bail, Context, Result};

/// Most worker threads `--threads` may ask for: each costs a stack and a
/// kernel thread, and 100000 of them exhaust the machine long before any
/// work is done; far more than any machine this runs on has cores.
pub const MAX_THREADS: usize = 1024;

/// The worker pool of `--threads` (all cores when `None`), refusing 0 and
/// more than [`MAX_THREADS`].
pub fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        if n > MAX_THREADS {
            bail!("--threads {n}: at most {MAX_THREADS} worker threads");
        }
        b = b.num_threads(n);
    }
    b.build().context("starting the worker threads")
}
