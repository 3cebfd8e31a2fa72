//! The analytic maps of the seeds: `flat`, `gaussian` and `studded` (the
//! ray-tracer paper, section 4) and `grating` (Donnelly, fig. 8-6).

use super::params::Params;
use super::Grid;
use crate::{HeightMap, Result};

/// The ray-tracer paper's `flatmap`: the whole face at one height. With the default
/// level 1 the displaced surface is the top of the shell, which is what made
/// it useful for debugging the basic intersection.
pub(super) fn flat(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("flat", query, &["level"])?;
    let level = p.number("level", 1.0, 0.0, 1.0)? as f32;
    grid.map(vec![level; grid.width * grid.height])
}

/// The ray-tracer paper's `gaussian`: `h(x, y) = exp(-pi (x^2 + y^2))`, maximum 1 at the
/// centre of the map, with `x = scale (2u - 1)` and `y = scale (2v - 1)`.
/// The default `scale = 2` (`x, y` in `[-2, 2]`) leaves `exp(-4 pi) = 3.5e-6`
/// at the middle of each edge, so under clamp addressing the bump meets a
/// flat border instead of being cut off, and it is half its height at a
/// radius of about an eighth of the map.
pub(super) fn gaussian(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("gaussian", query, &["scale"])?;
    let scale = p.number("scale", 2.0, 1e-3, 1e3)?;
    grid.map(grid.fill(|i, j| {
        let (u, v) = grid.uv(i, j);
        let (x, y) = (scale * (2.0 * u - 1.0), scale * (2.0 * v - 1.0));
        (-std::f64::consts::PI * (x * x + y * y)).exp() as f32
    }))
}

/// The ray-tracer paper's `studded`: "a modulus function to create alternating areas of
/// maximum and minimum height", i.e. a checkerboard of `period x period`
/// texel squares, `high` at texel (0, 0). Each texel is exactly `low` or
/// `high`, so the continuous surface steps from one to the other within a
/// single texel: the sharp edges that made the brute-force bake of the ray-tracer paper (section 2.3)
/// miss the surface. It tiles under repeat addressing when the map size is a
/// multiple of `2 period`.
pub(super) fn studded(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("studded", query, &["period", "low", "high"])?;
    let default_period = (grid.width as f64 / 8.0).round().max(1.0) as u64;
    let period = p.whole("period", default_period, 1, u32::MAX as u64)? as usize;
    let low = p.number("low", 0.0, 0.0, 1.0)? as f32;
    let high = p.number("high", 1.0, 0.0, 1.0)? as f32;
    grid.map(grid.fill(|i, j| {
        if (i / period + j / period).is_multiple_of(2) {
            high
        } else {
            low
        }
    }))
}

/// Donnelly's grating (fig. 8-6): parallel raised bars along `v`, one every
/// `period` texels (any real number >= 1), raised over the fraction `duty`
/// of each period; with `crossed=true` a second set of bars along `u` makes
/// a grid. Each texel holds the exact fraction of its area that is raised (a
/// box filter), so bar edges are sharp to within one texel even when they
/// fall between texel boundaries. It tiles under repeat addressing when the
/// map size is a whole number of periods.
pub(super) fn grating(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("grating", query, &["period", "duty", "crossed"])?;
    let default_period = (grid.width as f64 / 8.0).max(2.0);
    let period = p.number("period", default_period, 1.0, 1e9)?;
    let duty = p.number("duty", 0.5, 0.0, 1.0)?;
    let crossed = p.flag("crossed", false)?;
    let across: Vec<f64> = (0..grid.width)
        .map(|i| raised_fraction(i, period, duty))
        .collect();
    let along: Vec<f64> = (0..grid.height)
        .map(|j| raised_fraction(j, period, duty))
        .collect();
    grid.map(grid.fill(|i, j| {
        let (a, b) = (across[i], along[j]);
        // Area of the union of the two sets of bars within the texel.
        let h = if crossed { a + b - a * b } else { a };
        h.clamp(0.0, 1.0) as f32
    }))
}

/// Fraction of texel `[i, i + 1)` covered by the raised intervals
/// `[n period, (n + duty) period)`.
fn raised_fraction(i: usize, period: f64, duty: f64) -> f64 {
    // Raised length in [0, x): whole periods plus the part of the last one.
    let raised_below = |x: f64| {
        let n = (x / period).floor();
        n * duty * period + (x - n * period).min(duty * period)
    };
    raised_below(i as f64 + 1.0) - raised_below(i as f64)
}

#[cfg(test)]
mod tests {
    use super::super::generate;
    use crate::Address;

    #[test]
    fn flat_is_one_level() {
        let m = generate("gen:flat", 5, 4, Address::Clamp).unwrap();
        assert!(m.data().iter().all(|&v| v == 1.0));
        let m = generate("gen:flat?level=0.25", 5, 4, Address::Clamp).unwrap();
        assert!(m.data().iter().all(|&v| v == 0.25));
    }

    #[test]
    fn gaussian_is_the_ray_tracer_papers_formula_centred() {
        let (w, h) = (65, 33);
        let m = generate("gen:gaussian", w, h, Address::Clamp).unwrap();
        // Odd sizes put a texel centre at the middle of the map: exactly 1.
        assert_eq!(m.texel(32, 16), 1.0);
        for (i, j) in [(0usize, 0usize), (10, 20), (64, 5), (40, 16)] {
            let x = 2.0 * (2.0 * (i as f64 + 0.5) / w as f64 - 1.0);
            let y = 2.0 * (2.0 * (j as f64 + 0.5) / h as f64 - 1.0);
            let expected = (-std::f64::consts::PI * (x * x + y * y)).exp();
            assert!((m.texel(i as i64, j as i64) as f64 - expected).abs() < 1e-6);
        }
        // The default leaves the edges nearly flat.
        assert!(m.texel(0, 16) < 1e-4 && m.texel(32, 0) < 1e-4);
        // A smaller scale widens the bump.
        let wide = generate("gen:gaussian?scale=1", w, h, Address::Clamp).unwrap();
        assert!(wide.texel(16, 16) > m.texel(16, 16));
    }

    #[test]
    fn studded_has_two_levels_and_sharp_steps() {
        for (period, w, h) in [(4usize, 32usize, 24usize), (3, 31, 17), (1, 8, 8)] {
            let spec = format!("gen:studded?period={period}&low=0.2&high=0.9");
            let m = generate(&spec, w, h, Address::Repeat).unwrap();
            assert!(m.data().iter().all(|&v| v == 0.2 || v == 0.9), "{spec}");
            for j in 0..h as i64 {
                for i in 0..w as i64 - 1 {
                    // A step exactly at each square boundary and nowhere else.
                    let boundary = (i + 1) % period as i64 == 0;
                    assert_eq!(
                        m.texel(i, j) != m.texel(i + 1, j),
                        boundary,
                        "{spec} ({i}, {j})"
                    );
                }
            }
            for i in 0..w as i64 {
                for j in 0..h as i64 - 1 {
                    let boundary = (j + 1) % period as i64 == 0;
                    assert_eq!(
                        m.texel(i, j) != m.texel(i, j + 1),
                        boundary,
                        "{spec} ({i}, {j})"
                    );
                }
            }
        }
        // Default: 8 squares across.
        let m = generate("gen:studded", 64, 64, Address::Clamp).unwrap();
        let steps = (0..63)
            .filter(|&i| m.texel(i, 0) != m.texel(i + 1, 0))
            .count();
        assert_eq!(steps, 7);
    }

    #[test]
    fn grating_covers_the_duty_fraction_with_one_texel_edges() {
        let m = generate("gen:grating?period=8&duty=0.25", 64, 16, Address::Repeat).unwrap();
        for j in 0..16 {
            for i in 0..64 {
                let expected = if i % 8 < 2 { 1.0 } else { 0.0 };
                assert_eq!(m.texel(i, j), expected);
            }
        }
        // A fractional period: each period's raised area is exact, and every
        // texel is full, empty, or one partly covered texel at an edge.
        let (period, duty) = (6.4f64, 0.5f64);
        let m = generate(
            &format!("gen:grating?period={period}&duty={duty}"),
            64,
            4,
            Address::Repeat,
        )
        .unwrap();
        let row: Vec<f64> = (0..64).map(|i| m.texel(i, 0) as f64).collect();
        assert!((row.iter().sum::<f64>() - 64.0 * duty).abs() < 1e-4);
        for p in 0..10 {
            let start = (p as f64 * period).ceil() as usize;
            let end = ((p + 1) as f64 * period).floor() as usize;
            let partial = row[start..end]
                .iter()
                .filter(|v| **v > 1e-6 && **v < 1.0 - 1e-6)
                .count();
            assert!(partial <= 1, "period {p}: {:?}", &row[start..end]);
        }
        // Crossed: raised wherever either set of bars is.
        let c = generate(
            "gen:grating?period=8&duty=0.25&crossed=true",
            32,
            32,
            Address::Repeat,
        )
        .unwrap();
        for j in 0..32 {
            for i in 0..32 {
                let expected = if i % 8 < 2 || j % 8 < 2 { 1.0 } else { 0.0 };
                assert_eq!(c.texel(i, j), expected);
            }
        }
    }
}
