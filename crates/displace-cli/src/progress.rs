//! Terminal feedback for long jobs: a progress bar that appears only once a
//! job has run for a second (short bakes stay quiet), on stderr so stdout
//! keeps only results, and a Ctrl-C flag the bake polls so an interrupted run
//! stops cleanly and leaves no output file.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// A progress bar created lazily after `delay`.
pub struct DelayedBar {
    start: Instant,
    delay: Duration,
    label: String,
    /// What a step is ("slices", "rows").
    unit: &'static str,
    bar: Mutex<Option<ProgressBar>>,
}

impl DelayedBar {
    /// A bar counting the slices of a bake.
    pub fn new(label: impl Into<String>) -> Arc<Self> {
        Self::counting(label, "slices")
    }

    pub fn counting(label: impl Into<String>, unit: &'static str) -> Arc<Self> {
        Arc::new(Self {
            start: Instant::now(),
            delay: Duration::from_secs(1),
            label: label.into(),
            unit,
            bar: Mutex::new(None),
        })
    }

    /// Records `done` of `total` steps.
    pub fn update(&self, done: usize, total: usize) {
        if self.start.elapsed() < self.delay {
            return;
        }
        let mut slot = self.bar.lock().unwrap_or_else(|e| e.into_inner());
        let bar = slot.get_or_insert_with(|| {
            let bar =
                ProgressBar::with_draw_target(Some(total as u64), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template(&format!(
                    "{{msg}} [{{bar:40}}] {{pos}}/{{len}} {}, {{elapsed}} elapsed, ETA {{eta}}",
                    self.unit
                ))
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_message(self.label.clone());
            bar
        });
        bar.set_position(done as u64);
    }

    /// The callback [`displace_core::BakeOptions::progress`] takes.
    pub fn callback(self: &Arc<Self>) -> Arc<dyn Fn(usize, usize) + Send + Sync> {
        let me = Arc::clone(self);
        Arc::new(move |done, total| me.update(done, total))
    }

    /// Removes the bar, if it was ever shown.
    pub fn finish(&self) {
        if let Some(bar) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            bar.finish_and_clear();
        }
    }
}

/// The process-wide Ctrl-C flag, raised by SIGINT, SIGTERM and SIGHUP alike
/// (ctrlc's `termination` feature), so a killed or hung-up job stops as
/// cleanly as an interrupted one. The first call installs the handler; if
/// another part of the program already installed one, the flag still works
/// for code that sets it directly but Ctrl-C keeps its default behaviour
/// (ending the process, which leaves no output file either: outputs are only
/// renamed into place once complete).
pub fn cancel_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let f = Arc::clone(&flag);
        let _ = ctrlc::set_handler(move || f.store(true, Ordering::SeqCst));
        flag
    })
    .clone()
}

/// A scene's load with the Ctrl-C flag's end told as an interruption: the
/// load stops in a bake or in a wait for another process's bake
/// (`SceneOptions::cancel`) and nothing has been written.
pub fn loaded<T>(r: std::result::Result<T, displace_scene::Error>) -> anyhow::Result<T> {
    match r {
        Err(displace_scene::Error::Cancelled) => anyhow::bail!("interrupted: nothing was written"),
        other => Ok(other?),
    }
}

/// [`displace_core::io::atomic::write_atomic`] that stops at the Ctrl-C
/// flag: a mesh export streams gigabytes through one writer, and an
/// interrupt must end it with its temporary file removed, not run on (or,
/// without a handler, die and leave the file).
pub fn write_interruptible<F>(path: &std::path::Path, write: F) -> anyhow::Result<()>
where
    F: FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
{
    use anyhow::Context;
    let flag = cancel_flag();
    let result = displace_core::io::atomic::write_atomic(path, |w| {
        write(&mut Interruptible {
            inner: w,
            flag: &flag,
        })
    });
    if flag.load(Ordering::SeqCst) {
        anyhow::bail!("interrupted: nothing was written");
    }
    result.with_context(|| format!("writing {}", path.display()))
}

/// A writer that fails once the flag is raised. Not with
/// `ErrorKind::Interrupted`, which `write_all` retries for ever.
struct Interruptible<'a> {
    inner: &'a mut dyn std::io::Write,
    flag: &'a AtomicBool,
}

impl std::io::Write for Interruptible<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.flag.load(Ordering::Relaxed) {
            return Err(std::io::Error::other("interrupted"));
        }
        self.inner.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}
