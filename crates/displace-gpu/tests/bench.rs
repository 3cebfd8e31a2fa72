//! The benchmark machinery measures something: every path and variant of a
//! tiny configuration reports a positive, finite time, and the filled view
//! really puts the face under every pixel.

mod common;

use common::clamped_map;
use displace_core::TraceOptions;
use displace_gpu::bench::{bench_config, filled_view, frame_rays};
use displace_gpu::test_support::test_context;

#[test]
fn every_row_is_timed() {
    let Some(ctx) = test_context() else { return };
    let map = clamped_map(21);
    let rows = bench_config(ctx, &map, [64, 48], 8, 3).unwrap();
    let paths: Vec<&str> = rows.iter().map(|r| r.path.as_str()).collect();
    assert_eq!(
        paths,
        [
            "raster",
            "raster",
            "raster",
            "compute",
            "compute",
            "fetch-loop"
        ]
    );
    for r in &rows {
        assert!(
            r.timing.ms_per_frame.is_finite() && r.timing.ms_per_frame > 0.0,
            "{r:?}"
        );
        assert!(r.gpix_per_s() > 0.0);
    }
}

#[test]
fn filled_view_displaces_every_pixel() {
    let map = clamped_map(22);
    let scene = filled_view(&map, [40, 30]);
    let rays = frame_rays(&map, &scene);
    let hits = rays
        .iter()
        .filter(|r| map.trace(r, &TraceOptions::default()).is_some())
        .count();
    assert_eq!(hits, rays.len());
}
