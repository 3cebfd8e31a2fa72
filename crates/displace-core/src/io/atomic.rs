//! Write-then-rename, so that a reader (or a failed run) never sees a
//! half-written file: the data goes to a temporary file in the destination's
//! directory (same file system, so the rename is atomic), is flushed and
//! fsynced, and only then replaces the destination. On any error the
//! temporary file is removed and the destination is left untouched.
//!
//! A command with several outputs (a map and its normal map, an image and
//! its AOVs) opens a [`Batch`]: every write on that thread then stays under
//! its temporary name until [`Batch::commit`] renames them all, so a failure
//! in the last output leaves none of the earlier ones behind.

use crate::{Error, Result};
use std::cell::RefCell;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The longest file name most file systems take (ext4, XFS, tmpfs, APFS).
const NAME_MAX: usize = 255;

thread_local! {
    /// Temporary files written under an open [`Batch`], with their
    /// destinations, in the order written.
    static STAGED: RefCell<Option<Vec<(PathBuf, PathBuf)>>> = const { RefCell::new(None) };
}

/// The outputs of one command, committed together. While a batch is open,
/// [`write_atomic`] on the same thread leaves each file under its temporary
/// name; [`Batch::commit`] renames them all into place, and dropping the
/// batch uncommitted (an error, a panic) removes them.
#[must_use = "a batch writes nothing until it is committed"]
pub struct Batch {
    /// False for a batch opened inside another: the outer one commits.
    owner: bool,
}

impl Batch {
    /// Opens a batch on this thread (joining the open one, if any).
    pub fn new() -> Self {
        let owner = STAGED.with(|s| {
            let mut s = s.borrow_mut();
            let fresh = s.is_none();
            if fresh {
                *s = Some(Vec::new());
            }
            fresh
        });
        Self { owner }
    }

    /// Renames every staged file into place, in the order written. A rename
    /// that fails removes the files not yet renamed and is reported; the
    /// ones before it are already in place (renames are atomic one by one,
    /// not together).
    pub fn commit(self) -> Result<()> {
        if !self.owner {
            return Ok(());
        }
        let staged = take_staged();
        // A destination that cannot be replaced is found before any rename,
        // so that none of the batch lands.
        if let Some((_, dest)) = staged.iter().find(|(_, d)| d.is_dir()) {
            for (t, _) in &staged {
                let _ = std::fs::remove_file(t);
            }
            return Err(Error::Io {
                path: dest.clone(),
                source: std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "a directory is in the way of this output",
                ),
            });
        }
        let mut pending = staged.iter();
        while let Some((tmp, dest)) = pending.next() {
            if let Err(source) = std::fs::rename(tmp, dest) {
                let _ = std::fs::remove_file(tmp);
                for (t, _) in pending {
                    let _ = std::fs::remove_file(t);
                }
                return Err(Error::Io {
                    path: dest.clone(),
                    source,
                });
            }
            sync_parent(dest);
        }
        Ok(())
    }
}

impl Default for Batch {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Batch {
    fn drop(&mut self) {
        if self.owner {
            // Empty after a commit; otherwise nothing of the batch survives.
            for (tmp, _) in take_staged() {
                let _ = std::fs::remove_file(tmp);
            }
        }
    }
}

fn take_staged() -> Vec<(PathBuf, PathBuf)> {
    STAGED.with(|s| s.borrow_mut().take()).unwrap_or_default()
}

/// Writes the bytes `write` produces to `path`, atomically.
///
/// ```
/// # let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("hello.txt");
/// displace_core::io::atomic::write_atomic(&path, |w| w.write_all(b"hello")).unwrap();
/// assert_eq!(std::fs::read(&path).unwrap(), b"hello");
/// ```
pub fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let mut file = AtomicFile::create(path)?;
    write(file.writer()).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    file.commit()
}

/// A file written in pieces (a bake streaming its slabs) under a temporary
/// name next to `path`, moved into place by [`AtomicFile::commit`] (or
/// staged in the open [`Batch`]) and removed if dropped uncommitted, so an
/// error or an interrupted bake leaves nothing behind. Created before the
/// work starts, it also finds an unwritable destination before any is done.
pub struct AtomicFile {
    path: PathBuf,
    tmp: RemoveOnDrop,
    out: BufWriter<File>,
}

impl AtomicFile {
    /// Creates the temporary file for `path`.
    pub fn create(path: &Path) -> Result<Self> {
        let (tmp_path, file) = create_temp(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Self {
            path: path.to_path_buf(),
            tmp: RemoveOnDrop(Some(tmp_path)),
            out: BufWriter::with_capacity(1 << 20, file),
        })
    }

    /// Where the bytes go, in order.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        &mut self.out
    }

    /// Flushes what is buffered and asks the kernel to start writing the
    /// file's dirty pages to the device now, without waiting for them
    /// (Linux's `sync_file_range(SYNC_FILE_RANGE_WRITE)`), so that the
    /// fsync of [`Self::commit`] finds little left to write: a streamed
    /// bake calls it after each slice, and its writes overlap the slices
    /// still being computed (the fsync of a 16 MB map was 7 ms, an eighth
    /// of its whole bake). Only a hint: where the call is not supported
    /// the commit writes everything, as before.
    pub fn start_writeback(&mut self) -> std::io::Result<()> {
        self.out.flush()?;
        #[cfg(target_os = "linux")]
        {
            use std::os::fd::AsRawFd;
            // SAFETY: a plain system call on a file descriptor this file
            // owns; offset 0 and length 0 name the whole file.
            unsafe {
                libc::sync_file_range(
                    self.out.get_ref().as_raw_fd(),
                    0,
                    0,
                    libc::SYNC_FILE_RANGE_WRITE,
                );
            }
        }
        Ok(())
    }

    /// The same file opened again for direct writes from its start
    /// ([`super::direct`]), while nothing has gone through
    /// [`Self::writer`]; `None` where the file system refuses direct I/O.
    pub fn direct_append(&self) -> Option<super::direct::DirectAppend> {
        if !self.out.buffer().is_empty() {
            return None;
        }
        super::direct::DirectAppend::open(self.tmp.0.as_deref()?)
    }

    /// Flushes and fsyncs the file, then renames it into place (or stages
    /// it in the open [`Batch`]).
    pub fn commit(self) -> Result<()> {
        let Self { path, tmp, out } = self;
        let path = path.as_path();
        let io_err = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        let tmp_path = tmp.0.clone().expect("armed until committed");
        let file = out.into_inner().map_err(|e| io_err(e.into_error()))?;
        file.sync_all().map_err(io_err)?;
        drop(file);
        let staged = STAGED.with(|s| match s.borrow_mut().as_mut() {
            Some(list) => {
                // A second write of the same path in one batch replaces the first.
                if let Some(k) = list.iter().position(|(_, d)| d == path) {
                    let (old, _) = list.remove(k);
                    let _ = std::fs::remove_file(old);
                }
                list.push((tmp_path.clone(), path.to_path_buf()));
                true
            }
            None => false,
        });
        if !staged {
            std::fs::rename(&tmp_path, path).map_err(io_err)?;
            sync_parent(path);
        }
        tmp.disarm();
        Ok(())
    }
}

/// Persists a rename; a failure here loses nothing already written.
fn sync_parent(path: &Path) {
    if let Some(dir) = parent_dir(path) {
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
}

fn parent_dir(path: &Path) -> Option<&Path> {
    match path.parent() {
        Some(p) if p.as_os_str().is_empty() => Some(Path::new(".")),
        other => other,
    }
}

/// A fresh, exclusively created file next to `path`: `.NAME.PID.N.tmp`,
/// with `NAME` cut short when the whole would pass [`NAME_MAX`] bytes (a
/// valid 250-byte output name must not fail for its temporary's sake).
fn create_temp(path: &Path) -> std::io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the output path names no file",
        )
    })?;
    let dir = parent_dir(path).unwrap_or(Path::new("."));
    // A run killed before it renamed (SIGKILL, a power cut) left its
    // temporary of this output behind; no later run would remove it.
    remove_stale(dir, |stem| is_temp_of(stem, name.as_bytes()));
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(temp_name(name.as_bytes(), std::process::id(), n));
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Refuses an output of `bytes` at `path` when the file system of its
/// directory has less free space (to an unprivileged writer): a bake of
/// gigabytes would otherwise run to the end and fail there, its temporary
/// file removed and its work lost. Checked before the work starts, as
/// memory is. A directory whose file system cannot be asked passes (the
/// write itself will say).
pub fn check_free_space(path: &Path, bytes: u64) -> Result<()> {
    let dir = parent_dir(path).unwrap_or(Path::new("."));
    match free_bytes(dir) {
        Some(free) if free < bytes => Err(Error::DiskSpace {
            path: path.to_path_buf(),
            needed: bytes,
            free,
        }),
        _ => Ok(()),
    }
}

/// Bytes an unprivileged process may still write on the file system of
/// `dir` (`statvfs`: available blocks times the fragment size).
fn free_bytes(dir: &Path) -> Option<u64> {
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `c` is a NUL-terminated path and `st` a buffer of the size
    // `statvfs` fills; it is read only when the call succeeds.
    let ok = unsafe { libc::statvfs(c.as_ptr(), st.as_mut_ptr()) } == 0;
    if !ok {
        return None;
    }
    // SAFETY: filled by the successful call above.
    let st = unsafe { st.assume_init() };
    // `fsblkcnt_t` and `c_ulong` are u64 here, narrower elsewhere.
    #[allow(clippy::unnecessary_cast)]
    let (blocks, size) = (st.f_bavail as u64, st.f_frsize as u64);
    Some(blocks.saturating_mul(size))
}

/// `.NAME.PID.N.tmp`, `NAME` shortened to keep the whole within
/// [`NAME_MAX`] bytes (the PID and counter keep it unique).
fn temp_name(name: &[u8], pid: u32, n: u64) -> std::ffi::OsString {
    let suffix = format!(".{pid}.{n}.tmp");
    let keep = name.len().min(NAME_MAX - 1 - suffix.len());
    let mut out = Vec::with_capacity(NAME_MAX);
    out.push(b'.');
    out.extend_from_slice(&name[..keep]);
    out.extend_from_slice(suffix.as_bytes());
    std::ffi::OsString::from_vec(out)
}

/// The output name (as [`temp_name`] kept it) and the process id in a
/// name [`temp_name`] made, if it is one.
fn temp_parts(name: &[u8]) -> Option<(&[u8], u32)> {
    let inner = name.strip_prefix(b".")?.strip_suffix(b".tmp")?;
    let mut parts = inner.rsplitn(3, |&b| b == b'.');
    std::str::from_utf8(parts.next()?)
        .ok()?
        .parse::<u64>()
        .ok()?;
    let pid = std::str::from_utf8(parts.next()?).ok()?.parse().ok()?;
    let stem = parts.next().filter(|rest| !rest.is_empty())?;
    Some((stem, pid))
}

/// Whether `stem` (the output name a temporary keeps) is `name`'s, whole
/// or cut short by [`temp_name`] for length.
fn is_temp_of(stem: &[u8], name: &[u8]) -> bool {
    stem == name || (stem.len() >= NAME_MAX / 2 && name.starts_with(stem))
}

/// Removes from `dir` the temporary files of processes that no longer run
/// (a bake killed by SIGKILL or a power cut leaves its `.NAME.PID.N.tmp`
/// behind, and no later run would ever rename it). A process is taken as
/// running while `/proc/PID` exists; without `/proc` nothing is removed.
/// Returns how many were removed.
pub fn remove_stale_temps(dir: &Path) -> usize {
    remove_stale(dir, |_| true)
}

/// [`remove_stale_temps`] of the temporaries whose output name (as
/// [`temp_name`] kept it) passes `of`.
fn remove_stale(dir: &Path, of: impl Fn(&[u8]) -> bool) -> usize {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return 0;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some((stem, pid)) = temp_parts(name.as_bytes()) else {
            continue;
        };
        if !of(stem) {
            continue;
        }
        let is_file = e.file_type().is_ok_and(|t| t.is_file());
        if is_file && !proc.join(pid.to_string()).exists() && std::fs::remove_file(e.path()).is_ok()
        {
            removed += 1;
        }
    }
    removed
}

struct RemoveOnDrop(Option<PathBuf>);

impl RemoveOnDrop {
    fn disarm(mut self) {
        self.0 = None;
    }
}

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_larger_than_the_free_space_are_refused_first() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("m.ktx2");
        let free = free_bytes(dir.path()).expect("statvfs of a temporary directory");
        assert!(free > 0);
        check_free_space(&out, 0).unwrap();
        check_free_space(&out, free / 2).unwrap();
        let e = check_free_space(&out, free.saturating_mul(2).max(free + 1)).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(e, Error::DiskSpace { .. }) && msg.contains("m.ktx2") && msg.contains("free"),
            "{msg}"
        );
        // Nothing was created by the check.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        // The streamed writer asks before it creates its temporary file.
        let e = crate::io::stream::MapStream::create(
            &out,
            crate::distance_map::Format::R32F,
            [u32::MAX as usize, 65_536, 8],
            crate::Extent::new(1.0, 1.0, 0.1).unwrap(),
        );
        assert!(matches!(e, Err(Error::DiskSpace { .. })), "{:?}", e.err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.bin");
        write_atomic(&p, |w| w.write_all(b"one")).unwrap();
        write_atomic(&p, |w| w.write_all(b"two")).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(entries(dir.path()), vec!["a.bin"]);
    }

    #[test]
    fn failure_leaves_nothing_and_keeps_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.bin");
        let err = write_atomic(&p, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("boom"))
        })
        .unwrap_err();
        assert!(
            err.to_string().contains("boom") && err.to_string().contains("a.bin"),
            "{err}"
        );
        assert!(entries(dir.path()).is_empty());

        write_atomic(&p, |w| w.write_all(b"old")).unwrap();
        assert!(write_atomic(&p, |_| Err(std::io::Error::other("boom"))).is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(entries(dir.path()), vec!["a.bin"]);
    }

    #[test]
    fn a_name_of_250_bytes_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let name = format!("{}.npy", "n".repeat(246));
        assert_eq!(name.len(), 250);
        let p = dir.path().join(&name);
        write_atomic(&p, |w| w.write_all(b"x")).unwrap();
        assert_eq!(entries(dir.path()), vec![name]);
        let t = temp_name(&[b'a'; 255], u32::MAX, u64::MAX);
        assert_eq!(t.len(), NAME_MAX);
        let (stem, pid) = temp_parts(t.as_bytes()).unwrap();
        assert_eq!(pid, u32::MAX);
        assert!(is_temp_of(stem, &[b'a'; 255]) && !is_temp_of(stem, b"a"));
    }

    #[test]
    fn a_batch_commits_all_or_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.bin"), dir.path().join("b.bin"));
        {
            let _batch = Batch::new();
            write_atomic(&a, |w| w.write_all(b"a")).unwrap();
            assert!(!a.exists(), "renamed before the commit");
            assert!(write_atomic(&b, |_| Err(std::io::Error::other("boom"))).is_err());
            // Dropped uncommitted: nothing of it is left.
        }
        assert!(entries(dir.path()).is_empty(), "{:?}", entries(dir.path()));
        let batch = Batch::new();
        write_atomic(&a, |w| w.write_all(b"1")).unwrap();
        write_atomic(&b, |w| w.write_all(b"2")).unwrap();
        write_atomic(&a, |w| w.write_all(b"3")).unwrap();
        batch.commit().unwrap();
        assert_eq!(entries(dir.path()), vec!["a.bin", "b.bin"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"3");
        // A directory in the way of one output: none of them lands.
        let c = dir.path().join("c.bin");
        std::fs::create_dir(&c).unwrap();
        let batch = Batch::new();
        write_atomic(&dir.path().join("d.bin"), |w| w.write_all(b"d")).unwrap();
        write_atomic(&c, |w| w.write_all(b"c")).unwrap();
        let e = batch.commit().unwrap_err().to_string();
        assert!(e.contains("c.bin"), "{e}");
        assert_eq!(entries(dir.path()), vec!["a.bin", "b.bin", "c.bin"]);
        std::fs::remove_dir(&c).unwrap();
        // Outside a batch, writes land at once again.
        write_atomic(&b, |w| w.write_all(b"4")).unwrap();
        assert_eq!(std::fs::read(&b).unwrap(), b"4");
    }

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        // A process id above the kernel's maximum (2^22) is never running.
        let dead = dir.path().join(".k.dmap.4194305.0.tmp");
        let live = dir
            .path()
            .join(format!(".k.dmap.{}.0.tmp", std::process::id()));
        let other = dir.path().join(".k.dmap.tmp");
        for p in [&dead, &live, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        assert_eq!(remove_stale_temps(dir.path()), 1);
        assert!(!dead.exists() && live.exists() && other.exists());
    }

    /// An output's own stale temporaries (a killed run's, of the same
    /// name, whole or cut short for length) are removed when the output is
    /// next written; others' are left, and so are live processes'.
    #[test]
    fn writing_an_output_removes_its_stale_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let long = "m".repeat(250) + ".ktx2";
        for name in ["m.ktx2", long.as_str()] {
            let out = dir.path().join(name);
            let stale = dir.path().join(temp_name(name.as_bytes(), 4194305, 0));
            let live = dir
                .path()
                .join(temp_name(name.as_bytes(), std::process::id(), 99));
            let other = dir.path().join(temp_name(b"n.ktx2", 4194305, 0));
            for p in [&stale, &live, &other] {
                std::fs::write(p, b"x").unwrap();
            }
            write_atomic(&out, |w| w.write_all(b"map")).unwrap();
            assert_eq!(std::fs::read(&out).unwrap(), b"map");
            assert!(!stale.exists(), "{name}");
            assert!(live.exists() && other.exists(), "{name}");
            std::fs::remove_file(&live).unwrap();
            std::fs::remove_file(&other).unwrap();
        }
    }

    #[test]
    fn missing_directory_is_an_error_naming_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("no/such/dir/a.bin");
        let err = write_atomic(&p, |w| w.write_all(b"x")).unwrap_err();
        assert!(err.to_string().contains("a.bin"), "{err}");
    }
}
