//! Golden images: small renders of seed scenes compared with the stored
//! references in `tests/golden` by mean and 99th-percentile FLIP
//! (`displace_testkit::golden` says how they are judged, stored and blessed).
//!
//! The references are regenerated only on request:
//! `DISPLACE_BLESS=1 cargo test -p displace-render --test golden`.

mod common;

use common::*;
use displace_render::film::output::srgb8;
use displace_render::{render, RenderOptions, Scene, SceneOptions};
use displace_testkit::golden::{self, assert_percentile_catches_a_patch, Thresholds};
use std::path::Path;

/// The FLIP allowed. Mean 0.01: renders are deterministic on one platform
/// (0 there); this leaves room for other CPUs' libm and FMA differences,
/// far below the 0.05-0.1 of a visibly wrong shadow or a missing stud.
/// 99th percentile 0.1: the worst 1% of the pixels (52 of the 72x72) may
/// differ by rounding, not by a feature.
const LIMITS: Thresholds = Thresholds {
    mean: 0.01,
    p99: 0.1,
};
const SIZE: u32 = 72;

/// The seed scene `name` at `SIZE x SIZE` and `spp`, as sRGB RGB8.
fn render_rgb(name: &str, spp: u32) -> Vec<u8> {
    let scene = Scene::load(
        &scenes_dir().join(format!("{name}.toml")),
        &SceneOptions {
            spp: Some(spp),
            size: Some([SIZE, SIZE]),
            ..opts()
        },
    )
    .unwrap();
    srgb8(&render(&scene, &RenderOptions::default()).unwrap().image)
}

fn check(name: &str, spp: u32) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
    golden::check(&dir, name, [SIZE; 2], &render_rgb(name, spp), LIMITS);
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
    let soft = render_rgb("cornell_studded_shadows", 4);
    let hard = golden::flip([SIZE; 2], &soft, &render_rgb("cornell_studded", 4));
    assert!(hard.mean > LIMITS.mean, "mean FLIP {}", hard.mean);
    assert_percentile_catches_a_patch([SIZE; 2], &soft, LIMITS);
}
