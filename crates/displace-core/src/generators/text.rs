//! `text`: a string as raised letters, the case Donnelly's fig. 8-3 shows
//! because fine detail and thin gaps defeat uniformly spaced sampling.
//!
//! Glyphs come from DejaVu Sans Bold (Bitstream Vera licence, see
//! `crates/displace-core/assets/fonts/LICENSE-DejaVu.txt`), embedded in the library so the binary
//! needs no font file at run time, and are rasterised by `ab_glyph` as exact
//! area coverage: the letter edges ramp over one texel, sharp but not
//! aliased. `%0A` in the text starts a new line; lines are centred.

use super::params::Params;
use super::Grid;
use crate::convention::check_allocation;
use crate::{HeightMap, Result};
use ab_glyph::{point, Font, FontRef, GlyphId, PxScale, ScaleFont};

/// The bundled font's bytes (TrueType), shared with other crates that draw
/// text (the GPU viewer's overlay) so the binary embeds it once.
pub static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-Bold.ttf");

/// Share of the map's width and height that the default size fills.
const FILL: f32 = 0.9;

pub(super) fn text(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("text", query, &["text", "size"])?;
    let text = p.text("text").unwrap_or("displace");
    if text.trim().is_empty() {
        return Err(p.error("text", "is empty: there is nothing to raise".into()));
    }
    let font = FontRef::try_from_slice(FONT)
        .map_err(|e| p.error("text", format!("the bundled font is unreadable: {e}")))?;
    let lines = text
        .split('\n')
        .map(|line| {
            glyph_ids(&font, line)
                .map_err(|c| p.error("text", format!("the bundled font has no glyph for {c:?}")))
        })
        .collect::<Result<Vec<_>>>()?;

    // Letter height in texels, ascender to descender (ab_glyph's pixel scale).
    let size = match p.opt_number("size", 1.0, grid.height as f64)? {
        Some(size) => size as f32,
        None => {
            // Block size at scale 1 (it is linear in the scale).
            let (w1, h1) = block_size(&font, &lines, 1.0);
            (FILL * grid.width as f32 / w1.max(1e-6)).min(FILL * grid.height as f32 / h1.max(1e-6))
        }
    };
    let scaled = font.as_scaled(PxScale::from(size));
    let line_step = scaled.height() + scaled.line_gap();
    let (_, block_h) = block_size(&font, &lines, size);
    let top = (grid.height as f32 - block_h) / 2.0;

    let mut data = vec![0.0f32; grid.width * grid.height];
    for (k, line) in lines.iter().enumerate() {
        let baseline = top + scaled.ascent() + k as f32 * line_step;
        let mut x = (grid.width as f32 - line_width(&font, line, size)) / 2.0;
        for (n, &id) in line.iter().enumerate() {
            if n > 0 {
                x += scaled.kern(line[n - 1], id);
            }
            let glyph = id.with_scale_and_position(size, point(x, baseline));
            x += scaled.h_advance(id);
            let Some(outline) = font.outline_glyph(glyph) else {
                continue; // a space
            };
            let b = outline.px_bounds();
            let (x0, y0) = (b.min.x as i64, b.min.y as i64);
            if b.max.x < 0.0 || b.max.y < 0.0 || x0 >= grid.width as i64 || y0 >= grid.height as i64
            {
                continue; // entirely off the map
            }
            // The rasteriser allocates the glyph's whole box.
            check_allocation(
                "glyph raster",
                &format!("{}x{}", b.width(), b.height()),
                b.width() as u128 * b.height() as u128,
                4,
            )?;
            outline.draw(|gx, gy, coverage| {
                let (i, j) = (x0 + gx as i64, y0 + gy as i64);
                if (0..grid.width as i64).contains(&i) && (0..grid.height as i64).contains(&j) {
                    let h = &mut data[j as usize * grid.width + i as usize];
                    *h = (*h + coverage).clamp(0.0, 1.0);
                }
            });
        }
    }
    grid.map(data)
}

/// The glyphs of `line`, or the first character the font lacks.
fn glyph_ids(font: &FontRef<'_>, line: &str) -> std::result::Result<Vec<GlyphId>, char> {
    line.chars()
        .filter(|c| !c.is_control())
        .map(|c| {
            let id = font.glyph_id(c);
            if id.0 == 0 && !c.is_whitespace() {
                Err(c)
            } else {
                Ok(id)
            }
        })
        .collect()
}

/// Advance width of a line, kerning included.
fn line_width(font: &FontRef<'_>, line: &[GlyphId], size: f32) -> f32 {
    let scaled = font.as_scaled(PxScale::from(size));
    let advances: f32 = line.iter().map(|&id| scaled.h_advance(id)).sum();
    let kerning: f32 = line.windows(2).map(|w| scaled.kern(w[0], w[1])).sum();
    advances + kerning
}

/// Width and height of the block of lines at `size`.
fn block_size(font: &FontRef<'_>, lines: &[Vec<GlyphId>], size: f32) -> (f32, f32) {
    let scaled = font.as_scaled(PxScale::from(size));
    let width = lines
        .iter()
        .map(|l| line_width(font, l, size))
        .fold(0.0, f32::max);
    let height = lines.len() as f32 * (scaled.height() + scaled.line_gap()) - scaled.line_gap();
    (width, height)
}

#[cfg(test)]
mod tests {
    use super::super::generate;
    use crate::{Address, Error, HeightMap};

    /// Bounding box `(i0, j0, i1, j1)` of texels above half height.
    fn ink_box(m: &HeightMap) -> (usize, usize, usize, usize) {
        let (mut i0, mut j0, mut i1, mut j1) = (usize::MAX, usize::MAX, 0, 0);
        for j in 0..m.height() {
            for i in 0..m.width() {
                if m.texel(i as i64, j as i64) > 0.5 {
                    (i0, j0, i1, j1) = (i0.min(i), j0.min(j), i1.max(i), j1.max(j));
                }
            }
        }
        (i0, j0, i1, j1)
    }

    #[test]
    fn letters_are_raised_centred_and_fill_the_map_by_default() {
        let m = generate("gen:text?text=HI", 128, 64, Address::Clamp).unwrap();
        let (i0, j0, i1, j1) = ink_box(&m);
        // Centred to within a couple of texels (H and I have equal side
        // bearings), and the default size fills most of the height.
        assert!(((i0 + i1) as f64 / 2.0 - 63.5).abs() < 3.0, "{i0}..{i1}");
        assert!(((j0 + j1) as f64 / 2.0 - 31.5).abs() < 8.0, "{j0}..{j1}");
        assert!(j1 - j0 > 25, "{j0}..{j1}");
        // Corners are background, and some texels are fully raised.
        assert_eq!(m.texel(0, 0), 0.0);
        assert!(m.data().iter().filter(|&&v| v == 1.0).count() > 200);
        // Shapes: near the top the two stems of the H and the I are three
        // separate runs; at mid height the crossbar joins the H's stems.
        let runs = |j: usize| {
            let raised: Vec<bool> = (0..m.width())
                .map(|i| m.texel(i as i64, j as i64) > 0.5)
                .collect();
            raised.windows(2).filter(|w| !w[0] && w[1]).count()
        };
        assert_eq!(runs(j0 + (j1 - j0) / 5), 3);
        assert_eq!(runs((j0 + j1) / 2), 2);
    }

    #[test]
    fn the_first_row_is_the_top_of_the_letters() {
        // `T` is raised across its top and only in the middle at its foot.
        let m = generate("gen:text?text=T", 64, 64, Address::Clamp).unwrap();
        let (i0, j0, i1, j1) = ink_box(&m);
        let row = |j: usize| {
            (i0..=i1)
                .filter(|&i| m.texel(i as i64, j as i64) > 0.5)
                .count()
        };
        assert!(
            row(j0 + 1) > 3 * row(j1 - 1),
            "{} vs {}",
            row(j0 + 1),
            row(j1 - 1)
        );
    }

    #[test]
    fn size_spaces_and_lines() {
        let small = generate("gen:text?text=a%20b&size=10", 128, 64, Address::Clamp).unwrap();
        let big = generate("gen:text?text=a%20b&size=40", 128, 64, Address::Clamp).unwrap();
        let ink = |m: &HeightMap| m.data().iter().map(|&v| v as f64).sum::<f64>();
        // Area grows with the square of the size.
        let ratio = ink(&big) / ink(&small);
        assert!((10.0..22.0).contains(&ratio), "{ratio}");
        let two = generate("gen:text?text=A%0AB", 64, 128, Address::Clamp).unwrap();
        let (_, j0, _, j1) = ink_box(&two);
        assert!(j1 - j0 > 64, "two lines should stack: {j0}..{j1}");
    }

    #[test]
    fn refuses_empty_text_missing_glyphs_and_huge_sizes() {
        for spec in [
            "gen:text?text=",
            "gen:text?text=%20",
            "gen:text?text=%F0%9F%A6%80",
            "gen:text?size=65",
        ] {
            match generate(spec, 64, 64, Address::Clamp) {
                Err(Error::GeneratorParameter { generator, .. }) => assert_eq!(generator, "text"),
                other => panic!("{spec}: {other:?}"),
            }
        }
    }
}
