//! One bake per height source, resolution and proportions, shared by every
//! face that asks for it (the ray-tracer paper had to bake per face, its section 2.3), kept
//! in memory for the scene and on disk across runs, keyed by a hash of
//! everything the bake depends on.
//!
//! Disk format (`<key>.dmap`, little endian): magic `DSPLDM01`, `u32` width,
//! height, depth, `f32` aspect x, aspect y, `u8` addressing (0 clamp, 1
//! repeat), `f32` bound on the stored values' underestimate, then `width * height * depth` `f32`
//! values in the core's `[k][j][i]` order, then a `u64` checksum of the bound
//! and the values (`checksum`): a corrupt entry (a flipped bit on disk) is
//! baked again rather than trusted, since a wrong distance would make the
//! tracer step through the surface. The normal map is rebuilt from the
//! height map (cheap); only the distance transform is cached.
//!
//! Many processes may share one cache directory (the tasks of a render
//! farm on a shared file system): a lock file next to an entry
//! ([`crate::bake_lock`]) has one of them bake it while the others wait
//! and read it, and a directory that cannot be written falls back to
//! baking in memory with a warning ([`BakeCache::warnings`]).

use crate::bake_lock::{lock_path, try_lock, Attempt};
use crate::error::Result;
use crate::sampler::{hash, hash_iter};
use displace_core::io::atomic::{remove_stale_temps, write_atomic};
use displace_core::{
    bake, Address, BakeOptions, DisplacementMap, DistanceMap, Extent, HeightMap, NormalMap,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

const MAGIC: &[u8; 8] = b"DSPLDM01";
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
            .map(|d| d.join(format!("{key:016x}.dmap")));
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
        let m = bake(height, &BakeOptions::new(size, extent))?;
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
        let read = || {
            let m = read_map(path, height, size, extent)?;
            self.loaded.fetch_add(1, Ordering::Relaxed);
            Some(m)
        };
        let dir = path.parent().unwrap_or(Path::new("."));
        let lock = lock_path(path);
        let mut wait = Duration::from_millis(20);
        loop {
            if let Some(m) = read() {
                return Ok(m);
            }
            let attempt = match std::fs::create_dir_all(dir) {
                Ok(()) => try_lock(&lock),
                Err(e) => Attempt::Unwritable(e),
            };
            match attempt {
                Attempt::Acquired(_guard) => {
                    // Written by a holder that released just before we locked.
                    if let Some(m) = read() {
                        return Ok(m);
                    }
                    // Killed bakes leave temporaries no run would rename.
                    remove_stale_temps(dir);
                    let m = self.bake(height, size, extent)?;
                    // A cache that cannot be written only costs time next run.
                    if let Err(e) = write_map(path, &m.distance) {
                        self.warn(format!(
                            "bake cache entry {}: not written: {e}",
                            path.display()
                        ));
                    }
                    return Ok(m);
                }
                Attempt::Held => {
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

fn write_map(path: &Path, map: &DistanceMap) -> displace_core::Result<()> {
    write_atomic(path, |w| {
        w.write_all(MAGIC)?;
        for n in map.size() {
            w.write_all(&(n as u32).to_le_bytes())?;
        }
        for a in map.aspect() {
            w.write_all(&a.to_le_bytes())?;
        }
        w.write_all(&[(map.address() == Address::Repeat) as u8])?;
        w.write_all(&map.data_underestimate().to_le_bytes())?;
        let mut buf = Vec::with_capacity(map.data().len() * 4);
        for v in map.data() {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        w.write_all(&buf)?;
        w.write_all(&checksum(map.data_underestimate(), map.data()).to_le_bytes())
    })
}

/// Checksum of an entry's bound and values.
fn checksum(under: f32, data: &[f32]) -> u64 {
    hash_iter(
        std::iter::once(under)
            .chain(data.iter().copied())
            .map(|v| v.to_bits() as u64),
    )
}

/// The cached map, or `None` if absent, unreadable or not the one asked for
/// (then it is baked again and overwritten).
fn read_map(
    path: &Path,
    height: &HeightMap,
    size: [usize; 3],
    extent: Extent,
) -> Option<DisplacementMap> {
    // A cache entry replaced by a FIFO or a device must not hang the run.
    displace_core::io::check_input(path, "cache entry", displace_core::io::MAX_ARRAY_FILE_BYTES)
        .ok()?;
    let bytes = std::fs::read(path).ok()?;
    let header = 8 + 12 + 8 + 1 + 4;
    if bytes.len() < header || &bytes[..8] != MAGIC {
        return None;
    }
    let u32_at =
        |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes")) as usize;
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let stored = [u32_at(8), u32_at(12), u32_at(16)];
    let aspect = [f32_at(20), f32_at(24)];
    let address = match bytes[28] {
        0 => Address::Clamp,
        1 => Address::Repeat,
        _ => return None,
    };
    let under = f32_at(29);
    let n = size.iter().product::<usize>();
    if stored != size
        || address != height.address()
        || aspect != extent.aspect()
        || bytes.len() != header + 4 * n + 8
    {
        return None;
    }
    let data: Vec<f32> = bytes[header..header + 4 * n]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    let stored_sum = u64::from_le_bytes(bytes[header + 4 * n..].try_into().expect("8 bytes"));
    if stored_sum != checksum(under, &data) {
        return None;
    }
    let distance = DistanceMap::from_raw(size, aspect, address, data, under).ok()?;
    Some(DisplacementMap {
        height: height.clone(),
        normals: NormalMap::from_height(height, extent),
        distance,
        extent,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn height() -> HeightMap {
        displace_core::generators::generate("gen:gaussian", 16, 16, Address::Clamp).unwrap()
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
        let stale = dir.path().join(".0123456789abcdef.dmap.4194305.3.tmp");
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
        let dir = tempfile::tempdir().unwrap();
        let h = height();
        let extent = Extent::new(1.0, 1.0, 1.0).unwrap();
        let original = BakeCache::new(Some(dir.path().to_path_buf()))
            .get(&h, [4, 4, 2], extent)
            .unwrap();
        let entry = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
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
        for e in std::fs::read_dir(dir.path()).unwrap() {
            std::fs::write(e.unwrap().path(), b"DSPLDM01garbage").unwrap();
        }
        let again = BakeCache::new(Some(dir.path().to_path_buf()));
        again
            .get(&h, [8, 8, 4], Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap();
        assert_eq!(again.stats().baked, 1);
    }
}
