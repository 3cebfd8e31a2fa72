//! Seeded mutation fuzzing of every parser, on stable Rust: the
//! repository's scenes, a small OBJ, PNG and EXR height maps, the npy, KTX2
//! and DDS maps of a small bake, its bake-cache entry and a farm tile are mutated (bytes
//! flipped, inserted, deleted, duplicated, truncated, numbers replaced by
//! extreme ones) and fed back. Every parser must answer `Ok` or `Err`,
//! never panic, and the run's peak resident memory stays under a bound; a
//! panic names the parser and the case and keeps its input under
//! `target/fuzz-crashes` to reproduce. The seed is fixed, so a run is
//! repeatable; `DISPLACE_FUZZ_CASES` sets the number of cases per corpus
//! (default 1000) and `DISPLACE_FUZZ_SEED` picks other cases. See
//! docs/reliability.md for what was tried and found.

mod common;

use common::*;
use displace_core::io::{dds, height, ktx2, npy};
use displace_core::random::SplitMix64;
use displace_core::{bake, Address, BakeOptions, Extent};
use displace_render::bake_cache::BakeCache;
use displace_render::film::tiling::TileIndex;
use displace_render::film::{merge, tile_file, tile_file::TileMeta};
use displace_render::{Scene, SceneOptions};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// The project's seeded generator, with the draws that pick mutations.
struct Rng(SplitMix64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Values that break careless parsers: extremes, signs, non-numbers.
const NASTY: &[&str] = &[
    "0",
    "-1",
    "1e30",
    "-3e38",
    "nan",
    "inf",
    "4294967296",
    "-0",
    "1e-45",
    "\"\"",
    "[]",
    "{}",
    "9223372036854775807",
    "65537",
];

/// One to four mutations of `input`; `text` inputs also get whole tokens
/// replaced by [`NASTY`] values.
fn mutate(rng: &mut Rng, input: &[u8], text: bool) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(v.len() + 1);
        match rng.below(if text { 7 } else { 6 }) {
            0 if !v.is_empty() => {
                let at = at.min(v.len() - 1);
                v[at] ^= 1 << rng.below(8);
            }
            1 => v.insert(at, rng.next() as u8),
            2 if at < v.len() => {
                let n = rng.below(16).min(v.len() - at);
                v.drain(at..at + n);
            }
            3 => {
                let n = rng.below(64).min(v.len() - at);
                let piece: Vec<u8> = v[at..at + n].to_vec();
                v.splice(at..at, piece);
            }
            4 => v.truncate(at),
            5 if !v.is_empty() => {
                // A byte set to an extreme.
                let at = at.min(v.len() - 1);
                v[at] = [0, 0xff, 0x7f, 0x80][rng.below(4)];
            }
            6 => {
                // A number-like token replaced by a nasty value.
                let s = String::from_utf8_lossy(&v).into_owned();
                let starts: Vec<usize> = s
                    .char_indices()
                    .filter(|(i, c)| {
                        c.is_ascii_digit()
                            && !s[..*i].ends_with(|p: char| p.is_ascii_alphanumeric() || p == '.')
                    })
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&i) = starts.get(rng.below(starts.len())) {
                    let end = s[i..]
                        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-'))
                        .map_or(s.len(), |e| i + e);
                    let mut t = s[..i].to_string();
                    t.push_str(NASTY[rng.below(NASTY.len())]);
                    t.push_str(&s[end..]);
                    v = t.into_bytes();
                }
            }
            _ => {}
        }
    }
    v
}

fn cases() -> usize {
    std::env::var("DISPLACE_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000)
}

fn crash_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/fuzz-crashes")
}

/// Added to every parser's seed: `DISPLACE_FUZZ_SEED` (default 0) fuzzes
/// other cases.
fn seed_offset() -> u64 {
    std::env::var("DISPLACE_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Feeds `cases()` mutations of each of `corpus` to `parse` (which gets
/// the bytes and a file holding them, named `name`, and says whether it
/// accepted them), collecting panics. Asserts that some mutated inputs were
/// still accepted, so the cases reach past the first check.
fn fuzz(
    parser: &str,
    seed: u64,
    corpus: &[Vec<u8>],
    name: &str,
    text: bool,
    parse: &dyn Fn(&[u8], &Path) -> bool,
) -> Vec<String> {
    write_seeds(parser, corpus);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join(name);
    let seed = seed + seed_offset() * 1000;
    let mut rng = Rng(SplitMix64::new(0x9e37_79b9_7f4a_7c15 ^ seed));
    let mut crashes = Vec::new();
    let mut accepted = 0;
    let mut over_bound = peak_resident_bytes().is_some_and(|p| p >= MEMORY_BOUND);
    for k in 0..cases() {
        let input = mutate(&mut rng, &corpus[k % corpus.len()], text);
        std::fs::write(&file, &input).unwrap();
        let result = catch_unwind(AssertUnwindSafe(|| parse(&input, &file)));
        if peak_resident_bytes().is_some_and(|p| p >= MEMORY_BOUND) && !over_bound {
            // Named at the case that first took the peak past the bound.
            over_bound = true;
            let keep = crash_dir().join(format!("{parser}-{seed}-{k}-memory-{name}"));
            let _ = std::fs::create_dir_all(crash_dir());
            let _ = std::fs::write(&keep, &input);
            crashes.push(format!(
                "{parser} case {k}: resident memory peaked past {} MiB; input kept in {}",
                MEMORY_BOUND >> 20,
                keep.display()
            ));
        }
        match result {
            Ok(ok) => accepted += usize::from(ok),
            Err(_) => {
                let keep = crash_dir().join(format!("{parser}-{seed}-{k}-{name}"));
                let _ = std::fs::create_dir_all(crash_dir());
                let _ = std::fs::write(&keep, &input);
                crashes.push(format!(
                    "{parser} case {k}: input kept in {}",
                    keep.display()
                ));
            }
        }
    }
    assert!(
        accepted > 0 || cases() < 50,
        "{parser}: no mutated input was accepted"
    );
    crashes
}

/// With `DISPLACE_FUZZ_CORPUS=DIR`, writes `corpus` to `DIR/PARSER/`: the
/// seed corpora of the cargo-fuzz targets (`fuzz/`, one per parser, named
/// as here), so both fuzzers start from the same inputs.
fn write_seeds(parser: &str, corpus: &[Vec<u8>]) {
    let Some(out) = std::env::var_os("DISPLACE_FUZZ_CORPUS") else {
        return;
    };
    let dir = Path::new(&out).join(parser);
    std::fs::create_dir_all(&dir).unwrap();
    for (k, input) in corpus.iter().enumerate() {
        std::fs::write(dir.join(format!("seed-{k}")), input).unwrap();
    }
}

fn small_map() -> displace_core::DisplacementMap {
    let h = displace_core::generators::generate("gen:studded", 16, 16, Address::Clamp).unwrap();
    bake(
        &h,
        &BakeOptions::new([8, 8, 4], Extent::new(1.0, 1.0, 0.25).unwrap()),
    )
    .unwrap()
}

const OBJ: &str = "# a textured quad and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\no second\nv 0 0 1\nf 1 2 5\n";

/// Small bakes for mutated scenes: a scene's own maps (up to 256 voxels a
/// side) would make each case cost a long bake in a debug build.
fn small_bakes(text: &str) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with("map_size =") {
                "map_size = [8, 8, 4]"
            } else if l.starts_with("height_size =") {
                "height_size = [16, 16]"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn mutated_inputs_never_panic() {
    // As the cargo-fuzz targets do (at half the bound on this run's
    // resident memory below): a mutated size that the memory estimate
    // would allow under the machine's whole memory (a kilobyte of OpenEXR
    // header can claim a 33-million-texel display window) is refused by
    // the estimate here, which is what is being tested, not decoded.
    std::env::set_var(displace_core::memory::LIMIT_ENV, "128M");
    // Panics are caught and reported below; keep their noise off the log.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut crashes = Vec::new();

    let scenes: Vec<Vec<u8>> = std::fs::read_dir(scenes_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| small_bakes(&std::fs::read_to_string(p).unwrap()).into_bytes())
        .collect();
    assert!(scenes.len() >= 12);
    let base = scenes_dir();
    let opts = SceneOptions {
        size: Some([4, 4]),
        ..SceneOptions::default()
    };
    crashes.extend(fuzz("scene", 1, &scenes, "s.toml", true, &|b, _| {
        std::str::from_utf8(b)
            .is_ok_and(|text| Scene::from_toml(text, Path::new("s.toml"), &base, &opts).is_ok())
    }));

    crashes.extend(fuzz(
        "obj",
        2,
        &[OBJ.as_bytes().to_vec()],
        "m.obj",
        true,
        &|_, p| displace_render::mesh::load(p).is_ok(),
    ));

    let map = small_map();
    let extent = map.extent;
    let npy_bytes = npy::to_bytes(&[4, 8, 8], map.distance.data()).unwrap();
    crashes.extend(fuzz("npy", 3, &[npy_bytes], "m.npy", false, &|b, p| {
        let parsed = npy::from_bytes(b).is_ok();
        npy::read_distance_map(p, extent, Address::Clamp).is_ok() || parsed
    }));
    let ktx: Vec<Vec<u8>> = [
        displace_core::distance_map::Format::R8,
        displace_core::distance_map::Format::R32F,
    ]
    .into_iter()
    .map(|f| ktx2::to_bytes(&map.distance, extent, f).unwrap())
    .collect();
    crashes.extend(fuzz("ktx2", 4, &ktx, "m.ktx2", false, &|b, _| {
        ktx2::from_bytes(b).is_ok()
    }));
    let dds_bytes = dds::to_bytes(&map.distance, displace_core::distance_map::Format::R8).unwrap();
    crashes.extend(fuzz("dds", 5, &[dds_bytes], "m.dds", false, &|_, p| {
        dds::read(p, extent, Address::Clamp).is_ok()
    }));

    // Bake-cache entries: a mutated entry is read or refused and baked
    // again, and either way the map handed back is the one baked: a
    // corrupt entry trusted would hand the tracer wrong distances, which
    // step through the surface. Accepted: read from the entry.
    let cache_dir = tempfile::tempdir().unwrap();
    let cached = |dir: &Path| {
        let cache = BakeCache::new(Some(dir.to_path_buf()));
        let got = cache.get(&map.height, [8, 8, 4], extent);
        (got, cache.stats())
    };
    let (original, _) = cached(cache_dir.path());
    let original = original.unwrap();
    let entry = std::fs::read_dir(cache_dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "ktx2"))
        .expect("the bake wrote its cache entry");
    let entry_name = entry.file_name().unwrap().to_string_lossy().into_owned();
    let corpus = [std::fs::read(&entry).unwrap()];
    crashes.extend(fuzz(
        "bake-cache",
        8,
        &corpus,
        &entry_name,
        false,
        &|_, p| {
            let (got, stats) = cached(p.parent().unwrap());
            let got = got.expect("a bad entry is baked again, not an error");
            assert_eq!(
                got.distance, original.distance,
                "a corrupt entry was trusted"
            );
            stats.loaded == 1
        },
    ));

    // Height maps: a 16-bit PNG and an EXR written by our own writers.
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("h.png");
    displace_core::io::png::write_height_png16(&png, &map.height).unwrap();
    let exr = dir.path().join("h.exr");
    let img = displace_render::Image {
        width: 8,
        height: 8,
        pixels: (0..64)
            .map(|k| glam::Vec3::splat(k as f32 / 64.0))
            .collect(),
    };
    displace_render::film::output::write_image(&exr, &img).unwrap();
    // A photograph and a 16-bit terrain export: JPEG and TIFF.
    let jpg = dir.path().join("h.jpg");
    let tif = dir.path().join("h.tif");
    let ramp = |x: u32, y: u32| ((x * 29 + y * 7) % 256) as u8;
    image::RgbImage::from_fn(8, 8, |x, y| image::Rgb([ramp(x, y), ramp(y, x), 90]))
        .save(&jpg)
        .unwrap();
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(8, 8, |x, y| {
        image::Luma([u16::from(ramp(x, y)) * 257])
    })
    .save(&tif)
    .unwrap();
    // Elevation models: one band of float and of signed 16-bit samples,
    // with a no-data value, read by the `tiff` crate.
    let ftif = dir.path().join("f.tif");
    let itif = dir.path().join("i.tif");
    let dem = |name: &Path, write: &dyn Fn(&mut tiff::encoder::TiffEncoder<std::fs::File>)| {
        write(&mut tiff::encoder::TiffEncoder::new(std::fs::File::create(name).unwrap()).unwrap())
    };
    dem(&ftif, &|enc| {
        let mut img = enc
            .new_image::<tiff::encoder::colortype::Gray32Float>(8, 8)
            .unwrap();
        img.encoder()
            .write_tag(tiff::tags::Tag::GdalNodata, "-9999")
            .unwrap();
        let values: Vec<f32> = (0..64)
            .map(|k| f32::from(ramp(k % 8, k / 8)) / 255.0)
            .collect();
        img.write_data(&values).unwrap();
    });
    dem(&itif, &|enc| {
        let values: Vec<i16> = (0..64)
            .map(|k| i16::from(ramp(k % 8, k / 8)) - 100)
            .collect();
        enc.write_image::<tiff::encoder::colortype::GrayI16>(8, 8, &values)
            .unwrap();
    });
    let opts = height::HeightOptions::default();
    let auto = height::HeightOptions {
        range: height::HeightRange::Auto,
        ..opts
    };
    for (parser, seed, file, name) in [
        ("png", 6, &png, "h.png"),
        ("exr", 7, &exr, "h.exr"),
        ("jpeg", 8, &jpg, "h.jpg"),
        ("tiff", 9, &tif, "h.tif"),
        ("float tiff", 10, &ftif, "f.tif"),
        ("signed tiff", 11, &itif, "i.tif"),
    ] {
        let corpus = [std::fs::read(file).unwrap()];
        crashes.extend(fuzz(parser, seed, &corpus, name, false, &|_, p| {
            let path = p.to_string_lossy();
            let height = height::load(&path, &opts).is_ok() | height::load(&path, &auto).is_ok();
            displace_render::texture::Texture::load(p, true).is_ok() || height
        }));
    }

    // Farm tiles as `merge` reads them: the header alone, the whole tile
    // (pixels and checksum), and a merge of the one tile. A mutation of the
    // pixels fails the checksum, so the header counts as accepted.
    let tile = dir.path().join("t.exr");
    let meta = TileMeta {
        content_hash: 0x0123_4567_89ab_cdef,
        full_size: [8, 8],
        rect: displace_render::Crop {
            x: 0,
            y: 0,
            width: 8,
            height: 8,
        },
        tile: TileIndex { index: 0, count: 1 },
    };
    tile_file::write_tile(&tile, &meta, &img).unwrap();
    let corpus = [std::fs::read(&tile).unwrap()];
    crashes.extend(fuzz("tile", 12, &corpus, "t.exr", false, &|_, p| {
        let header = tile_file::read_tile_header(p).is_ok();
        let whole = tile_file::read_tile(p).is_ok();
        let merged = merge::merge_files(&[p.to_path_buf()]).is_ok();
        header || whole || merged
    }));

    std::panic::set_hook(hook);
    assert!(crashes.is_empty(), "{}", crashes.join("\n"));
    // Bounded memory: no mutated size got past the checks into a large
    // allocation. The whole test process's high-water mark (every corpus,
    // its bakes and the test harness) stays far below what a runaway size
    // would take.
    if let Some(peak) = peak_resident_bytes() {
        assert!(
            peak < MEMORY_BOUND,
            "the fuzz run peaked at {} MiB of resident memory (bound {} MiB)",
            peak >> 20,
            MEMORY_BOUND >> 20
        );
    }
}

/// The bound on the fuzz run's resident memory: 256 MiB, where a run
/// measured 8 MiB (a runaway size would take gigabytes).
const MEMORY_BOUND: u64 = 256 << 20;

/// `VmHWM` of this process (Linux), in bytes.
fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
