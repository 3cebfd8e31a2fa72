//! Golden images: small renders of seed scenes compared with the stored
//! references by NVIDIA's FLIP (Andersson et al. 2020, crate `nv-flip`, as
//! rend3's tests use it). A mean FLIP above [`MEAN_FLIP`] fails and writes
//! `tests/golden/NAME.diff.png` (FLIP error map, magma) and
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
const SIZE: u32 = 72;

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
    let err = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, stored.as_raw()),
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, &actual),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&err).mean();
    if mean > MEAN_FLIP {
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
        panic!("{name}: mean FLIP {mean} > {MEAN_FLIP}; see tests/golden/{name}.diff.png");
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
    let err = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, &render_rgb("cornell_studded_shadows")),
        nv_flip::FlipImageRgb8::with_data(SIZE, SIZE, &render_rgb("cornell_studded")),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&err).mean();
    assert!(mean > MEAN_FLIP, "mean FLIP {mean}");
}
