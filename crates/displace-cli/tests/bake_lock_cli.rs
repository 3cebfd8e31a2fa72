//! The bake cache shared by many processes, as the tasks of a farm share
//! it: four renders started at once on one empty cache directory bake the
//! map once (the others wait on its lock and read it), all four images are
//! the same, and no lock or temporary file is left. A cache directory that
//! cannot be written falls back to baking in memory with a warning; a
//! read-only one that holds the entry is read.

mod cli_common;

use cli_common::{files, floor_scene, stderr};
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// A floor whose bake takes long enough (a 128x128x32 map) for the four
/// renders to meet on it; a tiny image.
fn scene() -> String {
    floor_scene(
        16,
        16,
        0,
        r#"height = "gen:noise?seed=5", height_size = [128, 128], depth = 0.1, map_size = [128, 128, 32]"#,
    )
}

fn render(dir: &Path, cache: &Path, out: &str) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_displace"));
    c.args(["render", "-q", "s.toml", "-o", out])
        .current_dir(dir)
        .env("DISPLACE_CACHE", cache)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

fn scene_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), scene()).unwrap();
    dir
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "{}", stderr(&o));
    stderr(&o)
}

#[test]
fn four_processes_bake_one_key_once() {
    let dir = scene_dir();
    let d = dir.path();
    let cache = d.join("cache");
    let children: Vec<_> = (0..4)
        .map(|i| render(d, &cache, &format!("out{i}.png")).spawn().unwrap())
        .collect();
    let logs: Vec<String> = children
        .into_iter()
        .map(|c| ok(c.wait_with_output().unwrap()))
        .collect();
    let count = |s: &str| logs.iter().filter(|l| l.contains(s)).count();
    assert_eq!(count("bakes: 1 computed, 0 from cache"), 1, "{logs:#?}");
    assert_eq!(count("bakes: 0 computed, 1 from cache"), 3, "{logs:#?}");
    let first = std::fs::read(d.join("out0.png")).unwrap();
    for i in 1..4 {
        assert!(
            std::fs::read(d.join(format!("out{i}.png"))).unwrap() == first,
            "out{i}.png differs"
        );
    }
    let left = files(&cache);
    assert!(
        left.len() == 1 && left[0].ends_with(".ktx2"),
        "stray files in the cache: {left:?}"
    );
}

#[test]
fn an_unwritable_cache_bakes_in_memory_and_a_read_only_one_is_read() {
    let dir = scene_dir();
    let d = dir.path();
    let cache = d.join("cache");
    ok(render(d, &cache, "ref.png").output().unwrap());
    let reference = std::fs::read(d.join("ref.png")).unwrap();

    // A cache directory that cannot be created (its parent is a file).
    std::fs::write(d.join("file"), b"x").unwrap();
    let err = ok(render(d, &d.join("file/cache"), "mem.png")
        .output()
        .unwrap());
    assert!(
        err.contains("warning: bake cache")
            && err.contains("not writable")
            && err.contains("baking in memory"),
        "{err}"
    );
    assert!(err.contains("bakes: 1 computed"), "{err}");
    assert!(std::fs::read(d.join("mem.png")).unwrap() == reference);

    // A read-only cache that holds the entry: read, no lock needed.
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&cache, std::fs::Permissions::from_mode(0o555)).unwrap();
    let err = ok(render(d, &cache, "ro.png").output().unwrap());
    assert!(
        err.contains("0 computed, 1 from cache") && !err.contains("warning"),
        "{err}"
    );
    assert!(std::fs::read(d.join("ro.png")).unwrap() == reference);

    // An empty read-only directory: baked in memory with a warning (root
    // writes through the mode bits, so there only where they hold).
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::set_permissions(&empty, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::write(empty.join("probe"), b"x").is_err() {
        let err = ok(render(d, &empty, "ro2.png").output().unwrap());
        assert!(err.contains("not writable"), "{err}");
        assert!(files(&empty).is_empty());
    }
    std::fs::set_permissions(&cache, std::fs::Permissions::from_mode(0o755)).unwrap();
}
