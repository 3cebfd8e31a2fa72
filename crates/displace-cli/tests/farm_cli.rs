//! The render farm end to end: a scene rendered as 4 and as 7 tiles and
//! merged is byte-identical to the single render (PNG and EXR), whatever
//! the thread count of each tile; `merge` refuses missing, duplicate,
//! foreign (other scene, seed or override) and truncated tiles, names each
//! and writes nothing; `--tile auto/N` takes the scheduler's index and
//! refuses to guess without one.

mod cli_common;

use cli_common::{displace_env as run, files, floor_scene, ok, small_bake, stderr};
use std::path::Path;
use std::process::Output;

/// The scene: 32 x 112 pixels, 7 rows of render tiles.
fn scene() -> String {
    scene_of_seed(7)
}

fn scene_of_seed(seed: u64) -> String {
    floor_scene(32, 112, seed, &small_bake("gen:studded"))
}

fn scene_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), scene()).unwrap();
    dir
}

/// Renders tile `i` of `n` of `scene` to `out`.
fn tile(dir: &Path, scene: &str, i: u32, n: u32, out: &str, extra: &[&str]) -> Output {
    let t = format!("{i}/{n}");
    let mut args = vec!["render", "-q", scene, "--tile", &t, "-o", out];
    args.extend_from_slice(extra);
    run(&args, dir, &[])
}

fn bytes(dir: &Path, f: &str) -> Vec<u8> {
    std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"))
}

#[test]
fn four_and_seven_tiles_merge_byte_identical_to_one_render() {
    let dir = scene_dir();
    let d = dir.path();
    ok(run(&["render", "-q", "s.toml", "-o", "one.png"], d, &[]));
    ok(run(&["render", "-q", "s.toml", "-o", "one.exr"], d, &[]));
    for n in [4u32, 7] {
        let mut tiles = Vec::new();
        // Tiles in reverse order, alternately on 1 and 2 threads.
        for i in (0..n).rev() {
            let name = format!("t{n}_{i}.exr");
            let threads = if i % 2 == 0 { "1" } else { "2" };
            ok(tile(d, "s.toml", i, n, &name, &["--threads", threads]));
            tiles.push(name);
        }
        for out in [format!("m{n}.png"), format!("m{n}.exr")] {
            let mut args = vec!["merge", "-o", &out];
            args.extend(tiles.iter().map(String::as_str));
            let o = ok(run(&args, d, &[]));
            assert!(
                stderr(&o).contains(&format!("merged {n} tiles")),
                "{}",
                stderr(&o)
            );
            let single = if out.ends_with("png") {
                "one.png"
            } else {
                "one.exr"
            };
            assert!(
                bytes(d, &out) == bytes(d, single),
                "{out} differs from {single}"
            );
        }
    }
    assert!(
        files(d).iter().all(|f| !f.ends_with(".tmp")),
        "{:?}",
        files(d)
    );
}

/// `merge ARGS` must fail, say every string of `expect`, and write nothing.
fn refused(d: &Path, tiles: &[&str], expect: &[&str]) {
    let before = files(d);
    let mut args = vec!["merge", "-o", "out.png"];
    args.extend_from_slice(tiles);
    let o = run(&args, d, &[]);
    let err = stderr(&o);
    assert!(!o.status.success(), "merged {tiles:?}: {err}");
    assert!(err.contains("nothing written"), "{err}");
    for e in expect {
        assert!(err.contains(e), "`{e}` not in: {err}");
    }
    assert_eq!(files(d), before, "merge left files behind");
}

#[test]
fn merge_names_missing_duplicate_foreign_and_truncated_tiles() {
    let dir = scene_dir();
    let d = dir.path();
    for i in 0..4 {
        ok(tile(d, "s.toml", i, 4, &format!("t{i}.exr"), &[]));
    }
    // The same scene with another seed, and with an override.
    std::fs::write(d.join("seed.toml"), scene_of_seed(8)).unwrap();
    ok(tile(d, "seed.toml", 2, 4, "seed2.exr", &[]));
    ok(tile(d, "s.toml", 2, 4, "spp2.exr", &["--spp", "3"]));
    ok(tile(d, "s.toml", 2, 7, "of7.exr", &[]));
    let cut = bytes(d, "t3.exr");
    std::fs::write(d.join("cut3.exr"), &cut[..cut.len() - 100]).unwrap();

    refused(
        d,
        &["t0.exr", "t1.exr", "t2.exr"],
        &["tile 3/4 (rows 80..112) is missing"],
    );
    refused(
        d,
        &["t0.exr", "t1.exr", "t2.exr", "t3.exr", "t1.exr"],
        &["tile 1/4 is given twice: t1.exr and t1.exr"],
    );
    std::fs::copy(d.join("t1.exr"), d.join("copy1.exr")).unwrap();
    refused(
        d,
        &["t0.exr", "t1.exr", "copy1.exr", "t2.exr", "t3.exr"],
        &["tile 1/4 is given twice: t1.exr and copy1.exr"],
    );
    for foreign in ["seed2.exr", "spp2.exr"] {
        refused(
            d,
            &["t0.exr", "t1.exr", foreign, "t3.exr"],
            &[
                &format!("{foreign}: a tile of another render: content hash"),
                "tile 2/4 (rows 48..80) is missing",
            ],
        );
    }
    refused(
        d,
        &["t0.exr", "t1.exr", "of7.exr", "t2.exr", "t3.exr"],
        &["of7.exr: a tile of another render: one of 7 tiles, the others of 4"],
    );
    // A tile cut short keeps its header: the set is whole, and the tile is
    // named when its pixels are decoded.
    refused(
        d,
        &["t0.exr", "t1.exr", "t2.exr", "cut3.exr"],
        &["cut3.exr", "not a complete OpenEXR tile"],
    );
    // Cut into its header, it is unreadable and its tile missing: both said.
    std::fs::write(d.join("cut3.exr"), &cut[..200]).unwrap();
    refused(
        d,
        &["t0.exr", "t1.exr", "t2.exr", "cut3.exr"],
        &[
            "cut3.exr",
            "not a complete OpenEXR tile",
            "tile 3/4 (rows 80..112) is missing",
        ],
    );
    // A plain render is not a tile.
    ok(run(&["render", "-q", "s.toml", "-o", "plain.exr"], d, &[]));
    refused(d, &["plain.exr"], &["plain.exr: not a displace tile"]);
    // All four good tiles still merge.
    ok(run(
        &[
            "merge", "-o", "out.png", "t3.exr", "t2.exr", "t1.exr", "t0.exr",
        ],
        d,
        &[],
    ));
}

#[test]
fn auto_tiles_take_the_scheduler_index_and_never_guess() {
    let dir = scene_dir();
    let d = dir.path();
    ok(tile(d, "s.toml", 2, 4, "fixed.exr", &[]));
    for var in ["SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"] {
        let args = [
            "render", "-q", "s.toml", "--tile", "auto/4", "-o", "auto.exr",
        ];
        ok(run(&args, d, &[(var, "2")]));
        assert!(bytes(d, "auto.exr") == bytes(d, "fixed.exr"), "{var}");
    }
    let refuses = |args: &[&str], env: &[(&str, &str)], expect: &str| {
        let before = files(d);
        let o = run(args, d, env);
        assert!(
            !o.status.success() && stderr(&o).contains(expect),
            "{args:?}: {}",
            stderr(&o)
        );
        assert_eq!(files(d), before);
    };
    let auto = ["render", "-q", "s.toml", "--tile", "auto/4", "-o", "x.exr"];
    refuses(&auto, &[], "neither SLURM_ARRAY_TASK_ID");
    refuses(&auto, &[("SLURM_ARRAY_TASK_ID", "4")], "tile 4/4");
    refuses(
        &auto,
        &[("SLURM_ARRAY_TASK_ID", "1"), ("JOB_COMPLETION_INDEX", "2")],
        "disagree",
    );
    let fixed =
        |t: &'static str, out: &'static str| ["render", "-q", "s.toml", "--tile", t, "-o", out];
    refuses(&fixed("1/4", "x.png"), &[], "must be .exr");
    refuses(
        &fixed("7/8", "x.exr"),
        &[],
        "7 rows of 16-pixel render tiles, so 1 to 7",
    );
    refuses(&fixed("1", "x.exr"), &[], "expected I/N");
    refuses(
        &[
            "render", "-q", "s.toml", "--tile", "0/4", "--crop", "0,0,4,4", "-o", "x.exr",
        ],
        &[],
        "--crop",
    );
}
