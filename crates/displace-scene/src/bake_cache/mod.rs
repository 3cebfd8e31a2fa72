//! One bake per height source, resolution and proportions, shared by every
//! face that asks for it (the ray-tracer paper had to bake per face, its section 2.3), kept
//! in memory for the scene and on disk across runs, keyed by a hash of
//! everything the bake depends on.
//!
//! On disk an entry is `<key>.ktx2`, the KTX2 container `displace bake`
//! writes, in r32f and with a checksum of the whole file (module `entry`): a
//! corrupt entry (a flipped bit on disk) or a foreign one is warned about
//! and baked again rather than trusted, since a wrong distance would make
//! the tracer step through the surface. The normal map is rebuilt from the
//! height map (cheap); only the distance transform is cached. Entries of
//! the earlier container (`<key>.dmap`) are never read: their keys are
//! simply baked again.
//!
//! Many processes may share one cache directory (the tasks of a render
//! farm on a shared file system): a lock file next to an entry
//! ([`crate::bake_lock`]) has one of them bake it while the others wait
//! and read it, and a directory that cannot be written falls back to
//! baking in memory with a warning ([`BakeCache::warnings`]).

mod entry;

use crate::bake_lock::{lock_path, observe, take_over, try_lock, Attempt, STALE_AFTER};
use crate::error::Result;
use crate::sampler::hash;
use displace_core::io::atomic::remove_stale_temps;
use displace_core::{bake, Address, BakeOptions, DisplacementMap, Extent, HeightMap, NormalMap};
use entry::Entry;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How long a render waits for another process's bake before it says so.
const NOTICE_AFTER: Duration = Duration::from_secs(2);

/// Bumped whenever the bake's output for the same inputs could change.
/// (3: entries end with a checksum.)
const BAKE_VERSION: u64 = 3;

/// The cache directory: `$DISPLACE_CACHE` if set (an empty value disables
/// the disk cache), else `$XDG_CACHE_HOME/displace`, else
/// `~/.cache/displace`.
pub fn default_cache_dir() -> Option<PathBuf> {
    if let Some(v) = std::env::var_os("DISPLACE_CACHE") {
        return (!v.is_empty()).then(|| PathBuf::from(v));
    }
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME").filter(|v| !v.is_empty()) {
        return Some(PathBuf::from(x).join("displace"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("displace"))
}

/// Bakes by key, in memory for one scene and on disk across runs: the
/// ray-tracer paper baked the distance map anew for every face (its
/// section 2.3), while faces of one height source and one aspect can share
/// a bake (the metric convention of `displace_core::convention`).
#[derive(Default)]
pub struct BakeCache {
    dir: Option<PathBuf>,
    memory: Mutex<HashMap<u64, Arc<DisplacementMap>>>,
    baked: AtomicUsize,
    loaded: AtomicUsize,
    shared: AtomicUsize,
    warnings: Mutex<Vec<String>>,
    /// Raised to stop a bake or a wait ([`BakeCache::cancelled_by`]).
    cancel: Option<Arc<AtomicBool>>,
    /// How long a lock may stay unchanged before it is taken over
    /// ([`STALE_AFTER`] unless a test sets it).
    takeover_after: Option<Duration>,
}

/// Counts of what the cache did, for reports and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Bakes computed.
    pub baked: usize,
    /// Bakes read from disk.
    pub loaded: usize,
    /// Requests answered from memory (faces sharing a bake).
    pub shared: usize,
}

/// Aspects equal to 6 significant digits share a bake: faces built from the
/// same numbers in different orders must not differ by a rounding.
fn aspect_key(a: f32) -> u64 {
    let digits = 6 - a.abs().log10().floor() as i32;
    ((a as f64 * 10f64.powi(digits)).round() as i64) as u64 ^ (digits as u64) << 56
}

impl BakeCache {
    /// A cache writing to `dir` (see [`default_cache_dir`]); `None` keeps bakes
    /// in memory only.
    pub fn new(dir: Option<PathBuf>) -> Self {
        Self {
            dir,
            ..Self::default()
        }
    }

    /// The same cache, stopping its bakes and waits when `cancel` is raised
    /// (they end in [`crate::Error::Cancelled`]).
    pub fn cancelled_by(mut self, cancel: Option<Arc<AtomicBool>>) -> Self {
        self.cancel = cancel;
        self
    }

    fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::SeqCst))
    }

    /// What the cache has done so far.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            baked: self.baked.load(Ordering::Relaxed),
            loaded: self.loaded.load(Ordering::Relaxed),
            shared: self.shared.load(Ordering::Relaxed),
        }
    }

    /// The map for `height` baked at `size` for tile proportions `extent`.
    pub fn get(
        &self,
        height: &HeightMap,
        size: [usize; 3],
        extent: Extent,
    ) -> Result<Arc<DisplacementMap>> {
        let [ax, ay] = extent.aspect();
        let mut words = vec![
            BAKE_VERSION,
            height.width() as u64,
            height.height() as u64,
            (height.address() == Address::Repeat) as u64,
            size[0] as u64,
            size[1] as u64,
            size[2] as u64,
            aspect_key(ax),
            aspect_key(ay),
        ];
        words.extend(height.data().iter().map(|v| v.to_bits() as u64));
        let key = hash(&words);
        // The lock is held during a bake on purpose: two faces asking for the
        // same map at once must not bake it twice.
        let mut memory = self.memory.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(m) = memory.get(&key) {
            self.shared.fetch_add(1, Ordering::Relaxed);
            return Ok(m.clone());
        }
        // A canonical extent, so that equal keys give bit-equal bakes.
        let extent = Extent::new(ax, ay, 1.0)?;
        let path = self
            .dir
            .as_ref()
            .map(|d| d.join(format!("{key:016x}.{}", entry::EXTENSION)));
        let map = match &path {
            Some(p) => self.shared_bake(p, height, size, extent)?,
            None => self.bake(height, size, extent)?,
        };
        let map = Arc::new(map);
        memory.insert(key, map.clone());
        Ok(map)
    }
}

impl BakeCache {
    /// Bakes in memory.
    fn bake(
        &self,
        height: &HeightMap,
        size: [usize; 3],
        extent: Extent,
    ) -> Result<DisplacementMap> {
        let mut opts = BakeOptions::new(size, extent);
        opts.cancel = self.cancel.clone();
        let m = match bake(height, &opts) {
            Err(displace_core::Error::Cancelled) => return Err(crate::Error::Cancelled),
            m => m?,
        };
        self.baked.fetch_add(1, Ordering::Relaxed);
        Ok(m)
    }

    /// The entry at `path`, read if there, else baked once among all the
    /// processes sharing the directory ([`crate::bake_lock`]): the holder
    /// of the lock bakes and writes it, the others wait and read it. A
    /// directory that cannot take the lock (read-only, not creatable) is
    /// warned about and the map baked in memory.
    fn shared_bake(
        &self,
        path: &Path,
        height: &HeightMap,
        size: [usize; 3],
        extent: Extent,
    ) -> Result<DisplacementMap> {
        // The distance map, or why not: `None` for no entry, else what is
        // wrong with the one there.
        let read = || match entry::read(path, size, extent.aspect(), height.address()) {
            Entry::Found(distance) => {
                self.loaded.fetch_add(1, Ordering::Relaxed);
                Ok(distance)
            }
            Entry::Absent => Err(None),
            Entry::Unusable(why) => Err(Some(why)),
        };
        // A read entry with the normals worked out from the heights.
        let found = |distance| -> Result<DisplacementMap> {
            Ok(DisplacementMap {
                height: height.clone(),
                normals: NormalMap::from_height(height, extent)?,
                distance,
                extent,
            })
        };
        let dir = path.parent().unwrap_or(Path::new("."));
        let lock = lock_path(path);
        let mut wait = Duration::from_millis(20);
        let takeover_after = self.takeover_after.unwrap_or(STALE_AFTER);
        // The lock as last seen, and since when it has not changed.
        let mut seen = None;
        let mut since = Instant::now();
        let started = Instant::now();
        let mut told = false;
        loop {
            if let Ok(d) = read() {
                return found(d);
            }
            let attempt = match std::fs::create_dir_all(dir) {
                Ok(()) => try_lock(&lock),
                Err(e) => Attempt::Unwritable(e),
            };
            match attempt {
                Attempt::Acquired(_guard) => {
                    // Written by a holder that released just before we locked.
                    match read() {
                        Ok(d) => return found(d),
                        Err(Some(why)) => self.warn(format!(
                            "bake cache entry {}: {why}: baked again",
                            path.display()
                        )),
                        Err(None) => {}
                    }
                    // Killed bakes leave temporaries no run would rename.
                    remove_stale_temps(dir);
                    let m = self.bake(height, size, extent)?;
                    // A cache that cannot be written only costs time next run.
                    if let Err(e) = entry::write(path, &m.distance, extent) {
                        self.warn(format!(
                            "bake cache entry {}: not written: {e}",
                            path.display()
                        ));
                    }
                    return Ok(m);
                }
                Attempt::Held => {
                    if self.cancelled() {
                        return Err(crate::Error::Cancelled);
                    }
                    let now = observe(&lock);
                    if now != seen {
                        seen = now;
                        since = Instant::now();
                    } else if since.elapsed() >= takeover_after {
                        let holder = seen.take().map(|o| o.holder).unwrap_or_default();
                        self.warn(format!(
                            "bake cache lock {} (held by `{holder}`) was not refreshed for {} s: taken over",
                            lock.display(),
                            takeover_after.as_secs_f32()
                        ));
                        take_over(&lock);
                        since = Instant::now();
                        continue;
                    }
                    if !told && started.elapsed() >= NOTICE_AFTER {
                        told = true;
                        // Said at once, not with the warnings after the
                        // load: the user is waiting now.
                        eprintln!(
                            "waiting for another process's bake: the bake cache lock {} is held by `{}`; it is taken over if not refreshed for {} s",
                            lock.display(),
                            seen.as_ref().map(|o| o.holder.as_str()).unwrap_or(""),
                            takeover_after.as_secs_f32()
                        );
                    }
                    std::thread::sleep(wait);
                    wait = (wait * 2).min(Duration::from_millis(500));
                }
                Attempt::Unwritable(e) => {
                    self.warn(format!(
                        "bake cache {} is not writable ({e}): baking in memory",
                        dir.display()
                    ));
                    return self.bake(height, size, extent);
                }
            }
        }
    }

    fn warn(&self, message: String) {
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(message);
    }

    /// What went wrong with the disk cache without stopping the render (a
    /// read-only directory, an entry that could not be written), for the
    /// caller to show.
    pub fn warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn height() -> HeightMap {
        displace_core::generators::generate("gen:gaussian", 16, 16, Address::Clamp).unwrap()
    }

    /// A bake of [`height`] at `size` through a cache on an empty
    /// directory, and the one entry it wrote.
    struct Baked {
        dir: tempfile::TempDir,
        h: HeightMap,
        extent: Extent,
        map: Arc<DisplacementMap>,
        entry: PathBuf,
    }

    fn baked_entry(size: [usize; 3]) -> Baked {
        let dir = tempfile::tempdir().unwrap();
        let h = height();
        let extent = Extent::new(1.0, 1.0, 1.0).unwrap();
        let map = BakeCache::new(Some(dir.path().to_path_buf()))
            .get(&h, size, extent)
            .unwrap();
        let entry = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        Baked {
            dir,
            h,
            extent,
            map,
            entry,
        }
    }

    #[test]
    fn shares_in_memory_and_reloads_from_disk_bit_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let h = height();
        let cache = BakeCache::new(Some(dir.path().to_path_buf()));
        let a = cache
            .get(&h, [8, 8, 4], Extent::new(2.0, 2.0, 0.5).unwrap())
            .unwrap();
        // Same proportions, other scale: the same bake.
        let b = cache
            .get(&h, [8, 8, 4], Extent::new(4.0, 4.0, 1.0).unwrap())
            .unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(
            cache.stats(),
            CacheStats {
                baked: 1,
                loaded: 0,
                shared: 1
            }
        );

        let again = BakeCache::new(Some(dir.path().to_path_buf()));
        let c = again
            .get(&h, [8, 8, 4], Extent::new(2.0, 2.0, 0.5).unwrap())
            .unwrap();
        assert_eq!(
            again.stats(),
            CacheStats {
                baked: 0,
                loaded: 1,
                shared: 0
            }
        );
        assert_eq!(a.distance, c.distance);

        // Other proportions: another bake.
        again
            .get(&h, [8, 8, 4], Extent::new(2.0, 1.0, 0.5).unwrap())
            .unwrap();
        assert_eq!(again.stats().baked, 1);
    }

    /// A lock that names a live process on this host (our own) and is dated
    /// an hour ahead, as a reused process id or a machine with a wrong
    /// clock leave one: it is never refreshed, so the waiter takes it over
    /// after the bound (shortened here), bakes, and says so; and a wait
    /// ends at once, in `Cancelled`, when the cancel flag is raised.
    #[test]
    fn unrefreshed_locks_are_taken_over_and_waits_can_be_cancelled() {
        let b = baked_entry([8, 8, 4]);
        let lock = lock_path(&b.entry);
        std::fs::remove_file(&b.entry).unwrap();
        let plant = || {
            let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
            std::fs::write(&lock, format!("{} {}\n", host.trim(), std::process::id())).unwrap();
            std::fs::File::options()
                .write(true)
                .open(&lock)
                .unwrap()
                .set_modified(std::time::SystemTime::now() + Duration::from_secs(3600))
                .unwrap();
        };
        plant();
        let mut cache = BakeCache::new(Some(b.dir.path().to_path_buf()));
        cache.takeover_after = Some(Duration::from_millis(300));
        let start = Instant::now();
        let m = cache.get(&b.h, [8, 8, 4], b.extent).unwrap();
        assert!(start.elapsed() < Duration::from_secs(10));
        assert_eq!(m.distance, b.map.distance);
        assert_eq!(cache.stats().baked, 1);
        let w = cache.warnings();
        assert!(
            w.iter()
                .any(|w| w.contains("was not refreshed") && w.contains("taken over")),
            "{w:?}"
        );
        assert!(!lock.exists());

        std::fs::remove_file(&b.entry).unwrap();
        plant();
        let cancel = Arc::new(AtomicBool::new(false));
        let cache =
            BakeCache::new(Some(b.dir.path().to_path_buf())).cancelled_by(Some(cancel.clone()));
        let start = Instant::now();
        let got = std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(Duration::from_millis(300));
                cancel.store(true, Ordering::SeqCst);
            });
            cache.get(&b.h, [8, 8, 4], b.extent)
        });
        assert!(
            matches!(got, Err(crate::Error::Cancelled)),
            "{:?}",
            got.err()
        );
        assert!(start.elapsed() < Duration::from_secs(5));
        assert_eq!(cache.stats().baked, 0);
    }

    /// Four caches (as four processes would) on one empty directory at
    /// once: one bakes, the others wait on its lock and read its entry.
    #[test]
    fn concurrent_caches_on_one_directory_bake_once() {
        let dir = tempfile::tempdir().unwrap();
        let h = height();
        let extent = Extent::new(1.0, 1.0, 0.25).unwrap();
        let maps: Vec<(CacheStats, Arc<DisplacementMap>)> = std::thread::scope(|s| {
            let jobs: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        let c = BakeCache::new(Some(dir.path().join("cache")));
                        let m = c.get(&h, [16, 16, 8], extent).unwrap();
                        (c.stats(), m)
                    })
                })
                .collect();
            jobs.into_iter().map(|j| j.join().unwrap()).collect()
        });
        assert_eq!(maps.iter().map(|(s, _)| s.baked).sum::<usize>(), 1);
        assert_eq!(maps.iter().map(|(s, _)| s.loaded).sum::<usize>(), 3);
        assert!(maps.iter().all(|(_, m)| m.distance == maps[0].1.distance));
        let left: Vec<_> = std::fs::read_dir(dir.path().join("cache"))
            .unwrap()
            .collect();
        assert_eq!(left.len(), 1, "{left:?}");
    }

    #[test]
    fn a_bake_removes_temporaries_of_killed_runs() {
        let dir = tempfile::tempdir().unwrap();
        // Left by a process that no longer runs (no pid is above 2^22).
        let stale = dir.path().join(".0123456789abcdef.ktx2.4194305.3.tmp");
        std::fs::write(&stale, b"half a map").unwrap();
        BakeCache::new(Some(dir.path().to_path_buf()))
            .get(&height(), [8, 8, 4], Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap();
        assert!(!stale.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "{left:?}");
    }

    /// Every single-bit flip of an entry, header or values, is caught:
    /// the map is baked again and equals the original.
    #[test]
    fn flipped_bits_are_rebaked_never_trusted() {
        let Baked {
            dir,
            h,
            extent,
            map: original,
            entry,
        } = baked_entry([4, 4, 2]);
        let good = std::fs::read(&entry).unwrap();
        for bit in (0..good.len() * 8).step_by(7) {
            let mut bad = good.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            std::fs::write(&entry, &bad).unwrap();
            let cache = BakeCache::new(Some(dir.path().to_path_buf()));
            let map = cache.get(&h, [4, 4, 2], extent).unwrap();
            assert_eq!(cache.stats().baked, 1, "bit {bit} was trusted");
            assert_eq!(map.distance, original.distance);
        }
    }

    #[test]
    fn corrupt_cache_files_are_rebaked() {
        let dir = tempfile::tempdir().unwrap();
        let h = height();
        let cache = BakeCache::new(Some(dir.path().to_path_buf()));
        cache
            .get(&h, [8, 8, 4], Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap();
        // A KTX2 identifier followed by garbage.
        for e in std::fs::read_dir(dir.path()).unwrap() {
            std::fs::write(e.unwrap().path(), b"\xABKTX 20\xBB\r\n\x1A\ngarbage").unwrap();
        }
        let again = BakeCache::new(Some(dir.path().to_path_buf()));
        again
            .get(&h, [8, 8, 4], Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap();
        assert_eq!(again.stats().baked, 1);
        let warnings = again.warnings();
        assert!(
            warnings.len() == 1 && warnings[0].contains("baked again"),
            "{warnings:?}"
        );
    }

    /// A KTX2 map another tool wrote (here `displace bake`'s writer, with
    /// no checksum) at an entry's name, or an entry of other settings, is
    /// not trusted: it is warned about and baked again, and the rebaked
    /// entry is read by the next run.
    #[test]
    fn foreign_and_mismatched_entries_are_warned_about_and_rebaked() {
        let Baked {
            dir,
            h,
            extent,
            map: original,
            entry: path,
        } = baked_entry([8, 8, 4]);
        assert_eq!(path.extension().unwrap(), entry::EXTENSION);
        let other = bake(&h, &BakeOptions::new([4, 4, 2], extent)).unwrap();
        for (what, map) in [
            ("foreign", &original.distance),
            ("other size", &other.distance),
        ] {
            match what {
                "foreign" => displace_core::io::ktx2::write(
                    &path,
                    map,
                    extent,
                    displace_core::distance_map::Format::R32F,
                )
                .unwrap(),
                _ => entry::write(&path, map, extent).unwrap(),
            }
            let cache = BakeCache::new(Some(dir.path().to_path_buf()));
            let m = cache.get(&h, [8, 8, 4], extent).unwrap();
            assert_eq!(cache.stats().baked, 1, "{what}");
            assert_eq!(m.distance, original.distance, "{what}");
            let warnings = cache.warnings();
            assert!(
                warnings.len() == 1 && warnings[0].contains("baked again"),
                "{what}: {warnings:?}"
            );
            let next = BakeCache::new(Some(dir.path().to_path_buf()));
            next.get(&h, [8, 8, 4], extent).unwrap();
            assert_eq!((next.stats().loaded, next.warnings().len()), (1, 0));
        }
    }

    /// An entry of the earlier container at the same key is never read.
    #[test]
    fn old_dmap_entries_are_ignored() {
        let Baked {
            dir,
            h,
            extent,
            entry,
            ..
        } = baked_entry([8, 8, 4]);
        std::fs::rename(&entry, entry.with_extension("dmap")).unwrap();
        let again = BakeCache::new(Some(dir.path().to_path_buf()));
        again.get(&h, [8, 8, 4], extent).unwrap();
        assert_eq!((again.stats().baked, again.warnings().len()), (1, 0));
    }
}
