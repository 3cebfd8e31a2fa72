//! The parsers the cargo-fuzz targets feed, one function per target: each
//! takes libFuzzer's bytes, hands them to the parser (through a file where
//! the parser reads files) and must return, `Ok` or `Err`, without a panic,
//! an abort or libFuzzer's memory limit (`-rss_limit_mb`, 2 GiB by default)
//! being reached. The same parsers as the stable mutation test
//! (crates/displace-render/tests/fuzz.rs), whose `DISPLACE_FUZZ_CORPUS=DIR`
//! writes the seed corpora, `DIR/TARGET/`, these start from.

use displace_core::io::{dds, height, ktx2, npy};
use displace_core::{Address, DisplacementMap, Extent, HeightMap};
use displace_render::bake_cache::BakeCache;
use displace_render::texture::Texture;
use displace_render::{Scene, SceneOptions};
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// The memory limit of every scene the fuzzer builds: a mutated scene asks
/// for bakes of any size, and one the estimate allows under the machine's
/// whole memory would take minutes and gigabytes per input; at this limit
/// the estimate refuses them first (the refusal is what is being tested).
const MEMORY_LIMIT: &str = "256M";

/// One directory for the whole run, holding the file each input is
/// written to.
fn dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        // Before any thread of the run reads the environment.
        std::env::set_var(displace_core::memory::LIMIT_ENV, MEMORY_LIMIT);
        tempfile::tempdir().expect("a temporary directory")
    })
    .path()
}

/// `data` written to the run's file `name`, for a parser that reads files.
fn file(data: &[u8], name: &str) -> std::path::PathBuf {
    let path = dir().join(name);
    std::fs::write(&path, data).expect("the input written");
    path
}

/// The tile the map parsers are given.
fn extent() -> Extent {
    Extent::new(1.0, 1.0, 0.25).expect("a valid extent")
}

/// A scene (TOML, relative paths from `scenes/`), built whole: validation,
/// height maps, bakes, textures, at 4x4 pixels.
pub fn scene(data: &[u8]) {
    dir();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let opts = SceneOptions {
        size: Some([4, 4]),
        ..SceneOptions::default()
    };
    let _ = Scene::from_toml(text, Path::new("s.toml"), &base, &opts);
}

/// A mesh (OBJ).
pub fn obj(data: &[u8]) {
    let _ = displace_render::mesh::load(&file(data, "m.obj"));
}

/// A distance map as `.npy`: the array parser and the map reader.
pub fn npy(data: &[u8]) {
    let _ = npy::from_bytes(data);
    let _ = npy::read_distance_map(&file(data, "m.npy"), extent(), Address::Clamp);
}

/// A distance map as KTX2.
pub fn ktx2(data: &[u8]) {
    let _ = ktx2::from_bytes(data);
}

/// A distance map as DDS.
pub fn dds(data: &[u8]) {
    let _ = dds::read(&file(data, "m.dds"), extent(), Address::Clamp);
}

/// An image named `name` as a height map and as a colour texture.
fn image(data: &[u8], name: &str) {
    let path = file(data, name);
    let _ = height::load(&path.to_string_lossy(), &height::HeightOptions::default());
    let _ = Texture::load(&path, true);
}

/// A PNG height map or texture.
pub fn png(data: &[u8]) {
    image(data, "h.png");
}

/// An EXR height map or texture.
pub fn exr(data: &[u8]) {
    image(data, "h.exr");
}

/// A farm tile (OpenEXR with the tile's attributes) as `merge` reads it:
/// the header alone, the whole tile, and a merge of that one tile.
pub fn tile(data: &[u8]) {
    use displace_render::film::{merge, tile_file};
    let path = file(data, "t.exr");
    let _ = tile_file::read_tile_header(&path);
    let _ = tile_file::read_tile(&path);
    let _ = merge::merge_files(&[path]);
}

/// The map a bake-cache entry is read for, baked once through the cache
/// itself, and the entry's file name (its key).
struct Entry {
    height: HeightMap,
    map: Arc<DisplacementMap>,
    name: String,
}

const ENTRY_SIZE: [usize; 3] = [8, 8, 4];

fn entry() -> &'static Entry {
    static ENTRY: OnceLock<Entry> = OnceLock::new();
    ENTRY.get_or_init(|| {
        let height = displace_core::generators::generate("gen:studded", 16, 16, Address::Clamp)
            .expect("a generated map");
        let baked = tempfile::tempdir().expect("a temporary directory");
        let map = BakeCache::new(Some(baked.path().to_path_buf()))
            .get(&height, ENTRY_SIZE, extent())
            .expect("the bake");
        let name = std::fs::read_dir(baked.path())
            .expect("the cache directory")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .find(|n| n.ends_with(".ktx2"))
            .expect("the bake wrote its entry");
        Entry { height, map, name }
    })
}

/// A bake-cache entry: read if intact, else baked again; either way the
/// map handed back must be the one baked (a corrupt entry trusted would
/// give the tracer wrong distances, which step through the surface).
pub fn bake_cache(data: &[u8]) {
    let e = entry();
    let path = file(data, &e.name);
    let cache = BakeCache::new(path.parent().map(Path::to_path_buf));
    let got = cache
        .get(&e.height, ENTRY_SIZE, extent())
        .expect("a bad entry is baked again, not an error");
    assert_eq!(got.distance, e.map.distance, "a corrupt entry was trusted");
}
