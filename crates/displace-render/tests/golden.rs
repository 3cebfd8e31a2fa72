//! Golden images: small renders of seed scenes compared with the stored
//! references by NVIDIA's FLIP (Andersson et al. 2020, crate `nv-flip`, as
//! rend3's tests use it), with two thresholds as rend3's `ThresholdSet`
//! has them: a mean FLIP above [`MEAN_FLIP`] (an error spread over the
//! image) or a 99th-percentile FLIP above [`P99_FLIP`] (an error in a small
//! region: a stud or a shadow edge gone, which the mean dilutes) fails and
//! writes `tests/golden/NAME.diff.png` (FLIP error map, magma) and
//! `NAME.actual.png` next to the reference.
//!
//! The references are regenerated only on request:
//! `DISPLACE_BLESS=1 cargo test -p displace-render --test golden`.

mod common;

use common::*;
use displace_render::output::{srgb8, write_png_rgb8};
use displace_render::{render, RenderOptions, Scene, SceneOptions};
use std::path::{Path, PathBuf};

/// Mean FLIP allowed. Renders are deterministic on one platform (0 there);
/// this leaves room for other CPUs' libm and FMA differences, far below
/// the 0.05-0.1 of a visibly wrong shadow or a missing stud.
const MEAN_FLIP: f32 = 0.01;
/// 99th-percentile FLIP allowed: the worst 1% of the pixels (52 of the
/// 72x72) may differ by rounding, not by a feature.
const P99_FLIP: f32 = 0.1;
const SIZE: u32 = 72;

/// Mean and 99th-percentile FLIP between two sRGB images of `SIZE`.
fn flip_stats(reference: &[u8], actual: &[u8]) -> (nv_flip::FlipImageFloat, f32, f32) {
    let err = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, reference),
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, actual),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mut pool = nv_flip::FlipPool::from_image(&err);
    let (mean, p99) = (pool.mean(), pool.get_percentile(0.99, false));
    (err, mean, p99)
}

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn check(name: &str, spp: u32) {
    let scene = Scene::load(
        &scenes_dir().join(format!("{name}.toml")),
        &SceneOptions {
            spp: Some(spp),
            size: Some([SIZE, SIZE]),
            ..opts()
        },
    )
    .unwrap();
    let img = render(&scene, &RenderOptions::default()).unwrap().image;
    let actual = srgb8(&img);
    let reference = golden_dir().join(format!("{name}.png"));
    if std::env::var_os("DISPLACE_BLESS").is_some() {
        write_png_rgb8(&reference, SIZE, SIZE, &actual).unwrap();
        return;
    }
    let stored = image::open(&reference)
        .unwrap_or_else(|e| panic!("{}: {e} (bless with DISPLACE_BLESS=1)", reference.display()))
        .to_rgb8();
    assert_eq!(
        (stored.width(), stored.height()),
        (SIZE, SIZE),
        "{}",
        reference.display()
    );
    let (err, mean, p99) = flip_stats(stored.as_raw(), &actual);
    if mean > MEAN_FLIP || p99 > P99_FLIP {
        let diff = err.apply_color_lut(&nv_flip::magma_lut());
        write_png_rgb8(
            &golden_dir().join(format!("{name}.diff.png")),
            SIZE,
            SIZE,
            &diff.to_vec(),
        )
        .unwrap();
        write_png_rgb8(
            &golden_dir().join(format!("{name}.actual.png")),
            SIZE,
            SIZE,
            &actual,
        )
        .unwrap();
        panic!(
            "{name}: mean FLIP {mean} (allowed {MEAN_FLIP}), 99th percentile {p99} (allowed \
             {P99_FLIP}); see tests/golden/{name}.diff.png"
        );
    }
}

#[test]
fn cornell_studded_shadows() {
    check("cornell_studded_shadows", 4);
}

#[test]
fn cornell_stud_reflection() {
    check("cornell_stud_reflection", 4);
}

#[test]
fn cornell_crossing() {
    check("cornell_crossing", 4);
}

#[test]
fn grating() {
    check("grating", 4);
}

/// The threshold is meaningful: hard shadows instead of soft ones (the
/// studded scene under a point light) fail it.
#[test]
fn threshold_catches_a_wrong_shadow() {
    let render_rgb = |name: &str| {
        let s = Scene::load(
            &scenes_dir().join(format!("{name}.toml")),
            &SceneOptions {
                spp: Some(4),
                size: Some([SIZE, SIZE]),
                ..opts()
            },
        )
        .unwrap();
        srgb8(&render(&s, &RenderOptions::default()).unwrap().image)
    };
    let soft = render_rgb("cornell_studded_shadows");
    let (_, mean, _) = flip_stats(&soft, &render_rgb("cornell_studded"));
    assert!(mean > MEAN_FLIP, "mean FLIP {mean}");
    // A small local error (a 5x5 patch painted black: 0.5% of the pixels)
    // passes the mean and fails the percentile.
    let mut patched = soft.clone();
    for y in 30..35 {
        for x in 30..35 {
            let k = 3 * (y * SIZE as usize + x);
            patched[k..k + 3].fill(0);
        }
    }
    let (_, mean, p99) = flip_stats(&soft, &patched);
    assert!(
        mean <= MEAN_FLIP && p99 > P99_FLIP,
        "local error: mean {mean}, p99 {p99}"
    );
}
