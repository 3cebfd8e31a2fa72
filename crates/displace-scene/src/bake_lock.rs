//! A lock file next to a bake cache entry (`KEY.dmap.lock`), so that the
//! tasks of a farm that need the same bake at once, on one machine or many
//! sharing the cache directory, compute it once: the first to create the
//! lock bakes, the others wait and then read the entry it wrote.
//!
//! The lock is created exclusively (`O_EXCL`, atomic on local file systems
//! and NFSv3+) and names its holder (`host pid`). The holder refreshes the
//! lock's modification time every [`HEARTBEAT`] while it bakes. A lock is
//! stale, and is broken, when its holder is on this host and no longer
//! runs, or when it has not been refreshed for [`STALE_AFTER`] (a holder on
//! another machine that died; long enough for NFS attribute caching, which
//! can show a modification time up to a minute old). A waiter also watches
//! the lock itself ([`observe`]): one whose holder and modification time do
//! not change for [`STALE_AFTER`] by the waiter's own monotonic clock is
//! taken over ([`take_over`]) whatever its holder or date say, so that a
//! lock naming a live process that is not baking (a reused process id), or
//! dated in the future by a machine with a wrong clock, cannot keep a
//! render waiting for ever. Correctness never
//! rests on the lock: entries are written under temporary names and
//! renamed, so at worst a broken lock costs a second bake, never a
//! half-written entry.

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime};

/// How often a holder refreshes its lock.
pub const HEARTBEAT: Duration = Duration::from_secs(2);
/// A lock not refreshed for this long is taken as abandoned.
pub const STALE_AFTER: Duration = Duration::from_secs(120);

/// The outcome of one attempt at a lock.
pub enum Attempt {
    /// Ours, until the guard is dropped.
    Acquired(LockGuard),
    /// Another live process holds it: wait and look for the entry again.
    Held,
    /// The lock cannot be created at all (a read-only or missing
    /// directory): the caller bakes without the disk cache.
    Unwritable(std::io::Error),
}

/// A held lock: refreshed in the background, removed when dropped.
pub struct LockGuard {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    heartbeat: Option<JoinHandle<()>>,
}

impl Drop for LockGuard {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.heartbeat.take() {
            h.thread().unpark();
            let _ = h.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

/// The lock file of cache entry `entry`.
pub fn lock_path(entry: &Path) -> PathBuf {
    let mut name = entry.file_name().unwrap_or_default().to_os_string();
    name.push(".lock");
    entry.with_file_name(name)
}

fn host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|h| h.trim().to_string())
        .unwrap_or_default()
}

/// One try at the lock at `path`: taken, held by a live process (a stale
/// lock is broken and tried again once), or impossible to create.
pub fn try_lock(path: &Path) -> Attempt {
    for _ in 0..2 {
        match OpenOptions::new().write(true).create_new(true).open(path) {
            Ok(mut f) => {
                let _ = writeln!(f, "{} {}", host(), std::process::id());
                let _ = f.sync_all();
                return Attempt::Acquired(guard(path, f));
            }
            Err(e) if e.kind() == ErrorKind::AlreadyExists => {
                if !is_stale(path) {
                    return Attempt::Held;
                }
                break_lock(path);
            }
            Err(e) => return Attempt::Unwritable(e),
        }
    }
    Attempt::Held
}

fn guard(path: &Path, file: File) -> LockGuard {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let heartbeat = std::thread::Builder::new()
        .name("bake-lock".into())
        .spawn(move || {
            while !flag.load(Ordering::SeqCst) {
                std::thread::park_timeout(HEARTBEAT);
                if !flag.load(Ordering::SeqCst) {
                    let _ = file.set_modified(SystemTime::now());
                }
            }
        })
        .ok();
    LockGuard {
        path: path.to_path_buf(),
        stop,
        heartbeat,
    }
}

/// Whether the lock at `path` was left by a process that is gone.
fn is_stale(path: &Path) -> bool {
    let Ok(meta) = std::fs::metadata(path) else {
        // Gone already: not stale, just try again.
        return false;
    };
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut words = text.split_whitespace();
    if let (Some(h), Some(pid)) = (
        words.next(),
        words.next().and_then(|p| p.parse::<u32>().ok()),
    ) {
        if h == host() && Path::new("/proc/self").exists() {
            return !Path::new("/proc").join(pid.to_string()).exists();
        }
    }
    // Another host's (or an unreadable) lock: only its age can tell.
    meta.modified()
        .ok()
        .and_then(|m| SystemTime::now().duration_since(m).ok())
        .is_some_and(|age| age > STALE_AFTER)
}

/// What a waiter sees of a lock: its holder (`host pid`) and when it was
/// last refreshed. A holder that bakes refreshes it every [`HEARTBEAT`], so
/// the same observation for [`STALE_AFTER`] means that no one is baking.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Observation {
    /// The lock's text: `host pid`.
    pub holder: String,
    /// Its modification time, as the file system reports it.
    pub modified: Option<SystemTime>,
}

/// The lock at `path` as it is now; `None` when it is gone.
pub fn observe(path: &Path) -> Option<Observation> {
    let meta = std::fs::metadata(path).ok()?;
    Some(Observation {
        holder: std::fs::read_to_string(path)
            .unwrap_or_default()
            .trim()
            .to_string(),
        modified: meta.modified().ok(),
    })
}

/// Removes a lock that a waiter found unchanged for [`STALE_AFTER`]: the
/// next [`try_lock`] takes it.
pub fn take_over(path: &Path) {
    break_lock(path);
}

/// Removes a stale lock: renamed away first, so that of several waiters
/// breaking it at once one removes it and the others find it gone.
fn break_lock(path: &Path) {
    static N: AtomicU64 = AtomicU64::new(0);
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(
        ".broken.{}.{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let aside = path.with_file_name(name);
    if std::fs::rename(path, &aside).is_ok() {
        let _ = std::fs::remove_file(aside);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_holder_at_a_time_and_released_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("k.dmap.lock");
        let Attempt::Acquired(g) = try_lock(&p) else {
            panic!("not acquired")
        };
        assert!(matches!(try_lock(&p), Attempt::Held));
        drop(g);
        assert!(!p.exists());
        assert!(matches!(try_lock(&p), Attempt::Acquired(_)));
    }

    #[test]
    fn stale_locks_are_broken() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("k.dmap.lock");
        // This host, a process id above the kernel's maximum: dead.
        std::fs::write(&p, format!("{} 4194305\n", host())).unwrap();
        assert!(matches!(try_lock(&p), Attempt::Acquired(_)));
        // Another host's lock, fresh: held; unrefreshed for too long: broken.
        std::fs::write(&p, "elsewhere 1\n").unwrap();
        assert!(matches!(try_lock(&p), Attempt::Held));
        let old = SystemTime::now() - STALE_AFTER - Duration::from_secs(5);
        File::options()
            .write(true)
            .open(&p)
            .unwrap()
            .set_modified(old)
            .unwrap();
        let Attempt::Acquired(g) = try_lock(&p) else {
            panic!("stale lock kept")
        };
        drop(g);
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{left:?}");
    }

    #[test]
    fn a_missing_directory_is_unwritable() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("no/such/k.dmap.lock");
        assert!(matches!(try_lock(&p), Attempt::Unwritable(_)));
        assert_eq!(
            lock_path(Path::new("/c/0123.dmap")),
            Path::new("/c/0123.dmap.lock")
        );
    }
}
