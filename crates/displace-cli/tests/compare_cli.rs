//! `displace compare --quick` end to end: the CSV has the expected columns
//! and one row per map, elevation, technique and budget with sane values;
//! plots and grid are valid PNGs; bad input fails cleanly.

mod cli_common;

use cli_common::displace;

const COLUMNS: &str = "map,elevation_deg,technique,budget,rays,wrong_fraction,mean_error_texels,p99_error_texels,fetches_per_ray,ns_per_ray,gpu_ns_per_ray";

#[test]
fn quick_compare_writes_csv_plots_and_grid() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A user height map beside the generators.
    let img =
        image::GrayImage::from_fn(24, 24, |x, y| image::Luma([((x * 7 + y * 3) % 256) as u8]));
    img.save(d.join("mine.png")).unwrap();
    let o = displace(
        &["compare", "--quick", "--out", "out", "--height", "mine.png"],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(d.join("out/compare.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(COLUMNS));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 7 maps x 2 elevations x (10 techniques x 2 budgets + parallax once).
    assert_eq!(rows.len(), 7 * 2 * 21);
    let maps: std::collections::BTreeSet<&str> = rows.iter().map(|r| r[0]).collect();
    for m in [
        "flat", "gaussian", "studded", "grating", "text", "noise", "mine",
    ] {
        assert!(maps.contains(m), "{m} missing from {maps:?}");
    }
    for r in &rows {
        assert_eq!(r.len(), 11);
        assert_eq!(r[10], "", "no GPU timing without --gpu: {r:?}");
        let wrong: f64 = r[5].parse().unwrap();
        let p99: f64 = r[7].parse().unwrap();
        let fetches: f64 = r[8].parse().unwrap();
        assert!(
            (0.0..=1.0).contains(&wrong) && p99 >= 0.0 && fetches >= 1.0,
            "{r:?}"
        );
    }
    // Ours is exact everywhere; steep parallax at 4 layers is not.
    let worst = |tech: &str, budget: &str| {
        rows.iter()
            .filter(|r| r[2] == tech && r[3] == budget)
            .map(|r| r[7].parse::<f64>().unwrap() + r[5].parse::<f64>().unwrap())
            .fold(0.0, f64::max)
    };
    assert!(worst("distance", "4") < 1e-3);
    assert!(worst("steep", "4") > 0.5);
    // One equal-error row per map, elevation and technique; distance
    // mapping always reaches the bound at the smallest budget.
    let equal = std::fs::read_to_string(d.join("out/equal_error.csv")).unwrap();
    assert_eq!(equal.lines().count(), 1 + 7 * 2 * 11);
    assert!(equal
        .lines()
        .filter(|l| l.split(',').nth(2) == Some("distance"))
        .all(|l| l.split(',').nth(3) == Some("4")));
    let pre = std::fs::read_to_string(d.join("out/precompute.csv")).unwrap();
    assert!(pre.starts_with("map,precomputation,seconds,bytes"));
    assert_eq!(pre.lines().count(), 1 + 7 * 4);
    for m in &maps {
        let p = d.join(format!("out/plot_{m}.png"));
        let img = image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(img.width() > 100 && img.height() > 100);
    }
    let grid = image::open(d.join("out/grid.png")).unwrap();
    assert_eq!(grid.width(), 12 * 48);
}

/// A quick comparison on the studded map alone.
const QUICK_STUDDED: [&str; 5] = [
    "compare",
    "--quick",
    "--only-given",
    "--height",
    "gen:studded",
];

/// `--gpu` times every technique and budget on the GPU (lavapipe in CI,
/// where a missing adapter fails this test): every row gets a positive
/// GPU time per ray, the CPU columns are unchanged by it.
#[cfg(feature = "gpu")]
#[test]
fn gpu_timing_fills_its_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let common = [
        QUICK_STUDDED.as_slice(),
        &["--techniques", "distance,pom,relief,max-mip"],
    ]
    .concat();
    let mut with_gpu = common.to_vec();
    with_gpu.extend([
        "--out",
        "gpu",
        "--gpu",
        "--gpu-rays",
        "2048",
        "--gpu-frames",
        "1",
    ]);
    let o = displace(&with_gpu, d);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("GPU: "));
    let mut without = common.to_vec();
    without.extend(["--out", "cpu"]);
    let o = displace(&without, d);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap();
    let (gpu, cpu) = (read("gpu/compare.csv"), read("cpu/compare.csv"));
    // 1 map x 2 elevations x 4 techniques x 2 budgets.
    assert_eq!(gpu.lines().count(), 1 + 16);
    for (g, c) in gpu.lines().skip(1).zip(cpu.lines().skip(1)) {
        let g: Vec<&str> = g.split(',').collect();
        let c: Vec<&str> = c.split(',').collect();
        let ns: f64 = g[10].parse().unwrap_or_else(|_| panic!("{g:?}"));
        assert!(ns > 0.0 && ns.is_finite(), "{g:?}");
        assert_eq!(c[10], "");
        // Same rays, same answers: only the timings differ.
        assert_eq!(g[..9], c[..9]);
    }
    let zero: Vec<&str> = with_gpu
        .iter()
        .map(|&a| if a == "2048" { "0" } else { a })
        .collect();
    let o = displace(&zero, d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--gpu-rays"));
}

/// `compare --quick --out out EXTRA...` fails without a panic, naming
/// `needle` (in any case), and writes no CSV.
fn refuses(extra: &[&str], needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let args = [&["compare", "--quick", "--out", "out"], extra].concat();
    let o = displace(&args, dir.path());
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} succeeded");
    assert!(!msg.contains("panicked"), "{msg}");
    assert!(
        msg.to_lowercase().contains(&needle.to_lowercase()),
        "`{needle}` not in {msg}"
    );
    assert!(!dir.path().join("out/compare.csv").exists());
}

#[test]
fn bad_input_is_refused() {
    refuses(&["--techniques", "pom,warp"], "unknown technique `warp`");
    refuses(&["--budgets", "4,x"], "--budgets");
    refuses(&["--budgets", "0"], "out of range");
    refuses(&["--elevations", "95"], "--elevations");
    refuses(&["--height", "missing.png"], "missing.png");
    refuses(&["--height", "gen:bogus"], "bogus");
}

/// The CSVs, plots and grid land together: when the last output cannot be
/// written (here a directory where grid.png goes), none of them is left.
#[test]
fn outputs_land_together_or_not_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("out/grid.png")).unwrap();
    let args = [
        QUICK_STUDDED.as_slice(),
        &["--techniques", "distance,pom", "--out", "out"],
    ]
    .concat();
    let o = displace(&args, d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("grid.png"), "{err}");
    let left: Vec<_> = std::fs::read_dir(d.join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["grid.png"], "{err}");
}

/// `--out` naming a file (or a path under one) is refused before the work,
/// saying it is a file; the file is left as it was.
#[test]
fn an_output_that_is_a_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("taken"), b"keep me").unwrap();
    for out in ["taken", "taken/sub"] {
        let o = displace(&["compare", "--quick", "--out", out], d);
        let msg = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "--out {out} succeeded");
        assert!(msg.contains("taken is a file, not a directory"), "{msg}");
        assert_eq!(std::fs::read(d.join("taken")).unwrap(), b"keep me");
    }
}
