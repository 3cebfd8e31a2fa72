//! Plots of hit error against cost, one PNG per height map, drawn with
//! `plotters` into a pixel buffer (its ab_glyph text needs no system font:
//! the project's bundled DejaVu Sans Bold is registered once).

use super::measure::Row;
use anyhow::{anyhow, Result};
use displace_core::generators::FONT;
use displace_core::io::png::write_rgb8_png;
use displace_core::techniques::Technique;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// The family name every text style here uses.
pub const FAMILY: &str = "sans-serif";

/// Registers the bundled font under [`FAMILY`] (once per process).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in; a failure here is a build defect.
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
            .map_err(|_| ())
            .expect("the bundled font parses");
    });
}

/// Errors below this are drawn on it (log axis).
const FLOOR: f64 = 1e-3;
/// Rows with more than 1% wrong hit/miss are drawn here, at the top.
const CEILING: f64 = 100.0;

/// What the plot shows for a row: p99 error, or the ceiling when the row
/// gets hit/miss wrong on more than 1% of rays.
fn plotted(r: &Row) -> f64 {
    if r.wrong > 0.01 {
        CEILING
    } else {
        r.p99_error.clamp(FLOOR, CEILING)
    }
}

/// Colour of technique `k` of the list.
pub fn colour(k: usize) -> RGBColor {
    let c = Palette99::pick(k).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// One plot per map at the lowest elevation compared (grazing is where the
/// techniques differ): p99 error against fetches and against time per ray.
pub fn write_all(dir: &Path, rows: &[Row], techniques: &[Technique]) -> Result<Vec<PathBuf>> {
    register_font();
    let mut maps: Vec<&str> = rows.iter().map(|r| r.map.as_str()).collect();
    maps.dedup();
    let mut out = Vec::new();
    for map in maps {
        let low = rows
            .iter()
            .filter(|r| r.map == map)
            .map(|r| r.elevation)
            .fold(f32::INFINITY, f32::min);
        let sel: Vec<&Row> = rows
            .iter()
            .filter(|r| r.map == map && r.elevation == low)
            .collect();
        let path = dir.join(format!("plot_{map}.png"));
        let (w, h) = (1100usize, 420usize);
        let mut buf = vec![0u8; w * h * 3];
        draw(&mut buf, (w as u32, h as u32), map, low, &sel, techniques)
            .map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
        write_rgb8_png(&path, w, h, &buf)
            .map_err(|e| anyhow!("writing {}: {e}", path.display()))?;
        out.push(path);
    }
    Ok(out)
}

/// What a panel's x axis reads off a row.
type Axis = fn(&Row) -> f64;

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

fn draw(
    buf: &mut [u8],
    size: (u32, u32),
    map: &str,
    elevation: f32,
    rows: &[&Row],
    techniques: &[Technique],
) -> DrawResult {
    let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!(
            "{map}, {elevation} deg: p99 hit error (texels; >1% wrong hit/miss drawn at {CEILING})"
        ),
        (FAMILY, 16),
    )?;
    let (charts, legend) = root.split_horizontally(size.0 - 150);
    let panels = charts.split_evenly((1, 2));
    let axes: [(&str, Axis); 2] = [
        ("texture fetches per ray", |r| r.fetches.max(1.0)),
        ("CPU ns per ray", |r| r.ns_per_ray.max(1.0)),
    ];
    for (panel, (label, x_of)) in panels.iter().zip(axes) {
        let xs: Vec<f64> = rows.iter().map(|r| x_of(r)).collect();
        let x_lo = xs.iter().copied().fold(f64::INFINITY, f64::min).max(0.5) * 0.8;
        let x_hi = xs.iter().copied().fold(1.0, f64::max) * 1.25;
        let mut chart = ChartBuilder::on(panel)
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(48)
            .build_cartesian_2d(
                (x_lo..x_hi).log_scale(),
                (FLOOR * 0.8..CEILING * 1.25).log_scale(),
            )?;
        chart
            .configure_mesh()
            .x_desc(label)
            .y_desc("p99 error (texels)")
            .label_style((FAMILY, 11))
            .light_line_style(TRANSPARENT)
            .x_labels(6)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v}"))
            .draw()?;
        for (k, tech) in techniques.iter().enumerate() {
            // Joined in budget order, so a line shows what more budget buys.
            let mut own: Vec<&&Row> = rows.iter().filter(|r| r.technique == *tech).collect();
            own.sort_by_key(|r| r.budget);
            let pts: Vec<(f64, f64)> = own.iter().map(|r| (x_of(r), plotted(r))).collect();
            if pts.is_empty() {
                continue;
            }
            let c = colour(k);
            chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
            chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, c.filled())))?;
        }
    }
    for (k, tech) in techniques.iter().enumerate() {
        let y = 40 + 20 * k as i32;
        let c = colour(k);
        legend.draw(&PathElement::new(vec![(4, y), (24, y)], c.stroke_width(3)))?;
        legend.draw(&Text::new(tech.name(), (30, y - 6), (FAMILY, 12)))?;
    }
    root.present()?;
    Ok(())
}
