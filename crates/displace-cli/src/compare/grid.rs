//! The image grid: one view of the displaced face rendered by each
//! technique at (about) equal cost, beside the exact render, with a heat
//! map of each technique's hit error underneath.
//!
//! The view is the face as a rasteriser draws it: one pixel per point of
//! the polygon (the shell's top), every pixel's ray in the same direction
//! (an orthographic camera), shaded from the baked normal map at the uv
//! each technique returns, tinted by height.

use super::measure::{exact_hits, texel_error};
use super::plot::{register_font, FAMILY};
use anyhow::{anyhow, Result};
use displace_core::io::png::write_rgb8_png;
use displace_core::random::rays::downward;
use displace_core::techniques::{Maps, Technique};
use displace_core::MapRay;
use glam::{Vec2, Vec3};
use plotters::prelude::*;
use std::path::Path;

/// View direction: 25 degrees above the face, from its upper left in the image
/// (rays travel towards +u and +v: right and down).
const ELEVATION_DEG: f32 = 25.0;
const AZIMUTH_DEG: f32 = 35.0;
/// Height of the label band above each row, pixels.
const LABEL: usize = 28;

/// One ray per pixel of an `s x s` view.
fn view_rays(aspect: [f32; 2], s: usize) -> Vec<MapRay> {
    let (e, a) = (ELEVATION_DEG.to_radians(), AZIMUTH_DEG.to_radians());
    let dir = downward(e, a);
    (0..s * s)
        .map(|k| {
            let (i, j) = (k % s, k / s);
            let x = (i as f32 + 0.5) / s as f32 * aspect[0];
            // Image rows go down as the height map's rows do (row 0 at
            // v = 0), so a map of text reads as it does in its image.
            let y = (j as f32 + 0.5) / s as f32 * aspect[1];
            MapRay::new(Vec3::new(x, y, 1.0), dir)
        })
        .collect()
}

fn shade(maps: &Maps, uv: Option<Vec2>) -> [u8; 3] {
    let Some(uv) = uv else {
        return [24, 24, 28];
    };
    let map = maps.displacement.as_ref().expect("always baked");
    let n = map.shading_normal(uv);
    let l = Vec3::new(-0.4, -0.5, 0.77).normalize();
    let lit = 0.2 + 0.8 * n.dot(l).max(0.0);
    let h = maps.height.sample(uv.x, uv.y);
    let low = Vec3::new(0.25, 0.45, 0.8);
    let high = Vec3::new(0.95, 0.85, 0.6);
    let c = (low + (high - low) * h) * lit * 255.0;
    [c.x as u8, c.y as u8, c.z as u8]
}

/// Black at 0, yellow at half a texel, red from 2 texels; magenta where
/// hit and miss disagree, dark grey where both miss.
fn heat(err: Option<Option<f32>>) -> [u8; 3] {
    match err {
        None => [255, 0, 255],
        Some(None) => [40, 40, 40],
        Some(Some(e)) => {
            let a = (e / 0.5).min(1.0);
            let b = ((e - 0.5) / 1.5).clamp(0.0, 1.0);
            [(255.0 * a) as u8, (255.0 * a * (1.0 - b)) as u8, 0]
        }
    }
}

/// The largest budget whose mean fetches per ray on `rays` stays within
/// `target` (the smallest budget when none does).
fn equal_cost_budget(
    maps: &Maps,
    tech: Technique,
    budgets: &[u32],
    rays: &[MapRay],
    target: f64,
) -> Result<u32> {
    if !tech.uses_budget() {
        return Ok(1);
    }
    let mut sorted = budgets.to_vec();
    sorted.sort_unstable();
    let mut pick = sorted[0];
    for &b in &sorted {
        let mut fetches = 0u64;
        for r in rays {
            fetches += tech.trace(maps, r, b)?.fetches as u64;
        }
        if fetches as f64 / rays.len() as f64 <= target {
            pick = b;
        }
    }
    Ok(pick)
}

/// Renders and writes the grid; returns the budget each technique got.
pub fn write(
    path: &Path,
    maps: &Maps,
    techniques: &[Technique],
    budgets: &[u32],
    target_fetches: f64,
    s: usize,
) -> Result<Vec<(Technique, u32)>> {
    let rays = view_rays(maps.aspect, s);
    let exact = exact_hits(maps, &rays);
    let size = [maps.height.width(), maps.height.height()];
    let cols = techniques.len() + 1;
    let (w, h) = (cols * s, 2 * (s + LABEL));
    let mut buf = vec![0u8; w * h * 3];
    let mut put = |col: usize, row: usize, k: usize, c: [u8; 3]| {
        let (x, y) = (col * s + k % s, row * (s + LABEL) + LABEL + k / s);
        buf[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&c);
    };
    for (k, uv) in exact.iter().enumerate() {
        put(0, 0, k, shade(maps, *uv));
    }
    let mut picked = Vec::new();
    let mut labels = vec![(0usize, "exact".to_string(), String::new())];
    for (c, &tech) in techniques.iter().enumerate() {
        let budget = equal_cost_budget(maps, tech, budgets, &rays, target_fetches)?;
        picked.push((tech, budget));
        let cost = if tech.uses_budget() {
            format!("budget {budget}")
        } else {
            String::new()
        };
        labels.push((c + 1, tech.name().to_string(), cost));
        for (k, (ray, want)) in rays.iter().zip(&exact).enumerate() {
            let got = tech.trace(maps, ray, budget)?.hit.map(|h| h.uv);
            put(c + 1, 0, k, shade(maps, got));
            put(c + 1, 1, k, heat(texel_error(size, *want, got)));
        }
    }
    register_font();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w as u32, h as u32)).into_drawing_area();
        let style = (FAMILY, 11).into_font().color(&WHITE);
        for (col, name, cost) in &labels {
            for (line, text) in [name, cost].into_iter().enumerate() {
                let at = ((col * s + 3) as i32, 2 + 13 * line as i32);
                root.draw(&Text::new(text.clone(), at, style.clone()))
                    .map_err(|e| anyhow!("labelling the grid: {e}"))?;
            }
        }
        let legend = [
            "hit error:",
            "black 0",
            "yellow 0.5 texel",
            "red >= 2 texels",
            "magenta: wrong",
            "hit or miss",
        ];
        for (line, text) in legend.into_iter().enumerate() {
            let at = (3, (s + LABEL + 2 + 13 * line) as i32);
            root.draw(&Text::new(text, at, style.clone()))
                .map_err(|e| anyhow!("labelling the grid: {e}"))?;
        }
        root.present()
            .map_err(|e| anyhow!("labelling the grid: {e}"))?;
    }
    write_rgb8_png(path, w, h, &buf).map_err(|e| anyhow!("writing {}: {e}", path.display()))?;
    Ok(picked)
}
