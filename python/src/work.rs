//! Running the crates' work from Python: off the GIL, on a thread pool of
//! the size asked for, interruptible by Ctrl-C (`KeyboardInterrupt`), and
//! reporting progress to an optional callback on the calling thread.
//!
//! Why this shape: Python delivers signals to the main thread only, and
//! only when it runs Python code, so a long render that holds the thread in
//! Rust would ignore Ctrl-C. The work runs on a helper thread instead while
//! the caller's thread waits in short slices, checking for signals (and
//! calling the progress callback) between them; on an interrupt it sets
//! the job's cancel flag, which the bake and the render poll, and raises
//! `KeyboardInterrupt` once the job has stopped.

use crate::errors;
use pyo3::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

/// How often a waiting caller looks for signals and progress.
const POLL: Duration = Duration::from_millis(20);

/// The pools made for `threads=` counts, kept for the next call: building a
/// pool starts its threads, which a batch of queries should not pay for
/// every time.
fn pool(threads: Option<usize>) -> PyResult<Option<Arc<rayon::ThreadPool>>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    let Some(n) = threads else {
        return Ok(None);
    };
    if n == 0 || n > 4096 {
        return Err(errors::value(format!(
            "threads={n}: expected 1 to 4096 (or None for every core)"
        )));
    }
    let mut pools = POOLS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&n) {
        return Ok(Some(p.clone()));
    }
    let p = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(|i| format!("displace-{i}"))
        .build()
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("threads={n}: {e}")))?;
    let p = Arc::new(p);
    pools.insert(n, p.clone());
    Ok(Some(p))
}

/// What a job shares with the thread waiting for it: its cancel flag and
/// its progress (done, of all).
#[derive(Default)]
pub struct Job {
    /// Set by the waiting thread on an interrupt; polled by the work (and
    /// handed to the bake, which keeps it past the call: hence shared).
    pub cancel: Arc<AtomicBool>,
    done: AtomicUsize,
    total: AtomicUsize,
}

impl Job {
    /// Records progress: `done` of `total` steps.
    pub fn progress(&self, done: usize, total: usize) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(done, Ordering::Relaxed);
    }

    /// Whether the job was asked to stop.
    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Runs `work` on `threads` threads (`None`: every core) without the GIL,
/// interruptible and with progress (see the module's notes). Small jobs
/// (`quick`) run on the calling thread without the helper: a batch of a few
/// rays should not pay for a thread's start.
///
/// Returns `work`'s value; raises `KeyboardInterrupt` (or the callback's
/// exception) when interrupted, after `work` has returned.
pub fn run<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    progress: Option<&Bound<'_, PyAny>>,
    quick: bool,
    work: impl FnOnce(&Arc<Job>) -> T + Send,
) -> PyResult<T> {
    let pool = pool(threads)?;
    let job = Arc::new(Job::default());
    let install = |job: &Arc<Job>| match &pool {
        Some(p) => p.install(|| work(job)),
        None => work(job),
    };
    if quick && progress.is_none() {
        return Ok(py.detach(|| install(&job)));
    }
    let progress = progress.map(|p| p.clone().unbind());
    let mut interrupted: Option<PyErr> = None;
    let value = py.detach(|| {
        std::thread::scope(|s| {
            // The worker wakes this thread when it is done, so a job pays
            // no part of a polling slice for finishing between polls.
            let waiting = std::thread::current();
            let shared = &job;
            let handle = s.spawn(move || {
                let value = install(shared);
                waiting.unpark();
                value
            });
            let mut shown = (usize::MAX, usize::MAX);
            loop {
                std::thread::park_timeout(POLL);
                let finished = handle.is_finished();
                Python::attach(|py| {
                    if interrupted.is_none() {
                        if let Err(e) = py.check_signals() {
                            job.cancel.store(true, Ordering::Relaxed);
                            interrupted = Some(e);
                        }
                    }
                    let now = (
                        job.done.load(Ordering::Relaxed),
                        job.total.load(Ordering::Relaxed),
                    );
                    if let (Some(cb), None, true) = (&progress, &interrupted, now != shown) {
                        shown = now;
                        if now.1 > 0 {
                            if let Err(e) = cb.call1(py, now) {
                                job.cancel.store(true, Ordering::Relaxed);
                                interrupted = Some(e);
                            }
                        }
                    }
                });
                if finished {
                    break;
                }
            }
            handle.join()
        })
    });
    match (value, interrupted) {
        (_, Some(e)) => Err(e),
        (Ok(v), None) => Ok(v),
        (Err(panic), None) => std::panic::resume_unwind(panic),
    }
}
