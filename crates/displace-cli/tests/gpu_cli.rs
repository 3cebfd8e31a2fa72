//! `displace gpu-render` and `displace bench gpu` end to end, on whatever
//! adapter the machine has (lavapipe in CI; see displace-gpu's
//! `test_support` for the no-adapter policy).
#![cfg(feature = "gpu")]

mod cli_common;

use cli_common::{failed, gpu_scratch_dir};
use displace_gpu::test_support::test_context;
use std::process::Command;

fn displace() -> Command {
    Command::new(env!("CARGO_BIN_EXE_displace"))
}

#[test]
fn gpu_render_writes_a_png_of_the_displaced_plane() {
    let Some(dir) = gpu_scratch_dir() else {
        return;
    };
    let out = dir.path().join("plane.png");
    let status = displace()
        .args([
            "gpu-render",
            "--size",
            "64x64",
            "--map-size",
            "64x64x8",
            "--shadows",
            "soft",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (64, 64));
    // The background corner and the lit face differ, and the face is not
    // one flat colour.
    let corner = *img.get_pixel(0, 0);
    let centre = *img.get_pixel(32, 40);
    assert_ne!(corner, centre);
    let distinct: std::collections::BTreeSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 50, "{}", distinct.len());
    // Nothing else was left in the directory (the write is atomic).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn gpu_render_refuses_bad_input_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bad.png");
    for (args, needle) in [
        (vec!["--size", "0x4"], "--size"),
        (vec!["--size", "100000x4"], "--size"),
        (vec!["--map-size", "1x8x8"], "--map-size"),
        (vec!["--height", "/nonexistent/h.png"], "/nonexistent/h.png"),
        (vec!["--extent", "1,1,0"], "extent"),
        (vec!["--method", "exact"], "exact"),
        (vec!["--distance", "r4"], "r4"),
    ] {
        let o = displace()
            .arg("gpu-render")
            .args(&args)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        failed(&o, &[needle], &[]);
        assert!(!out.exists(), "{args:?}");
    }
}

/// Frames and maps past what the device holds are refused before any work
/// and without a panic: a 16384x16384 frame (a size `--size` accepts; wgpu's
/// default error handler panicked allocating it), and a distance map wider
/// than the device's 3D textures, by `gpu-render` and by `trace --backend
/// gpu` (which baked it first, then refused it).
#[test]
fn frames_and_maps_past_the_device_are_refused_before_any_work() {
    let Some(ctx) = test_context() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |args: &[&str]| {
        displace()
            .args(args)
            .current_dir(d)
            .env("DISPLACE_CACHE", "")
            .output()
            .unwrap()
    };
    let o = run(&[
        "gpu-render",
        "--size",
        "16384x16384",
        "--map-size",
        "16x16x4",
        "-o",
        "big.png",
    ]);
    failed(&o, &["16384x16384"], &["panicked"]);
    let wide = format!("{}x16x4", ctx.limits.max_texture_dimension_3d + 1);
    let o = run(&["gpu-render", "--map-size", &wide, "-o", "wide.png"]);
    failed(&o, &[&wide, "exceeds this GPU's limit"], &["panicked"]);
    let rays: Vec<f32> = [0.5, 0.5, 2.0, 0.0, 0.0, -1.0].repeat(4);
    displace_core::io::npy::write_file(&d.join("rays.npy"), &[4, 6], &rays).unwrap();
    let o = run(&[
        "trace",
        "--backend",
        "gpu",
        "--height",
        "gen:gaussian",
        "--extent",
        "1,1,0.1",
        "--size",
        &wide,
        "--rays",
        "rays.npy",
        "-o",
        "hits.npy",
    ]);
    failed(
        &o,
        &["--backend gpu", &wide, "exceeds this GPU's limit"],
        &["panicked"],
    );
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["rays.npy"]);
}

#[test]
fn bench_gpu_prints_a_row_per_path_and_variant() {
    if test_context().is_none() {
        return;
    }
    let o = displace()
        .args([
            "bench",
            "gpu",
            "--frame",
            "64x48",
            "--iterations",
            "4",
            "--frames",
            "1",
            "--map-size",
            "32x32x4",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("| ") && l.contains("64x48"))
        .collect();
    assert_eq!(rows.len(), 6, "{stdout}");
    for r in rows {
        let ms: f64 = r.split('|').nth(6).unwrap().trim().parse().unwrap();
        assert!(ms > 0.0 && ms.is_finite(), "{r}");
    }
}

/// `-o out.exr` writes an EXR (it wrote PNG bytes): the linear values of
/// the frame the PNG holds, each within rounding of the PNG's sRGB bytes.
#[test]
fn gpu_render_writes_a_linear_exr() {
    let Some(dir) = gpu_scratch_dir() else {
        return;
    };
    for name in ["f.png", "f.exr"] {
        let o = displace()
            .args([
                "gpu-render",
                "--size",
                "32x32",
                "--map-size",
                "32x32x8",
                "-o",
            ])
            .arg(dir.path().join(name))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let bytes = std::fs::read(dir.path().join("f.exr")).unwrap();
    assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "not an EXR");
    let exr = image::open(dir.path().join("f.exr")).unwrap().to_rgb32f();
    let png = image::open(dir.path().join("f.png")).unwrap().to_rgb8();
    assert_eq!(exr.dimensions(), png.dimensions());
    let srgb = |c: f32| {
        let c = c.clamp(0.0, 1.0);
        let s = if c <= 0.003_130_8 {
            12.92 * c
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round()
    };
    let mut mid = 0;
    for (e, p) in exr.pixels().zip(png.pixels()) {
        for c in 0..3 {
            assert!((srgb(e[c]) - p[c] as f32).abs() <= 1.0, "{e:?} vs {p:?}");
            // Linear, not the sRGB bytes scaled: mid greys sit well below them.
            if p[c] > 100 && p[c] < 200 {
                assert!(e[c] < p[c] as f32 / 255.0 - 0.1, "{e:?} vs {p:?}");
                mid += 1;
            }
        }
    }
    assert!(mid > 0);
}
