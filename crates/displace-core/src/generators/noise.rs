//! `noise`: fractal Perlin (gradient) noise, the sum of `octaves` layers of
//! doubling frequency and amplitude falling by `gain`, rescaled so that the
//! map spans exactly `[0, 1]` (the whole displacement depth is used).
//!
//! Under repeat addressing the gradient lattice of every octave wraps with a
//! period of one map, so the noise continues across opposite edges and the
//! map tiles seamlessly, as a repeat-baked distance map needs.

use super::params::Params;
use super::Grid;
use crate::{Address, HeightMap, Result};
use std::f64::consts::FRAC_1_SQRT_2 as S;

/// The eight gradient directions of 2D Perlin noise: axes and diagonals.
const GRADIENTS: [(f64, f64); 8] = [
    (1.0, 0.0),
    (-1.0, 0.0),
    (0.0, 1.0),
    (0.0, -1.0),
    (S, S),
    (-S, S),
    (S, -S),
    (-S, -S),
];

pub(super) fn noise(query: Option<&str>, grid: Grid) -> Result<HeightMap> {
    let p = Params::parse("noise", query, &["seed", "octaves", "frequency", "gain"])?;
    let seed = p.whole("seed", 0, 0, u64::MAX)?;
    let octaves = p.whole("octaves", 5, 1, 16)? as u32;
    // Lattice cells across the map's width for the first octave.
    let fx = p.number("frequency", 4.0, 1e-3, 1e6)?;
    let gain = p.number("gain", 0.5, 0.0, 1.0)?;
    let periodic = grid.address == Address::Repeat;
    if periodic && fx.fract() != 0.0 {
        return Err(p.error(
            "frequency",
            format!(
                "`{fx}` must be a whole number under repeat addressing, so that the noise tiles"
            ),
        ));
    }
    // Square lattice cells in texels; a whole number of them under repeat.
    let mut fy = fx * grid.height as f64 / grid.width as f64;
    if periodic {
        fy = fy.round().max(1.0);
    }
    let fractal = Fractal {
        seed,
        octaves,
        gain,
        periodic,
    };
    let raw = grid.fill(|i, j| {
        let (u, v) = grid.uv(i, j);
        fractal.at(u * fx, v * fy, fx, fy) as f32
    });
    grid.map(normalise(raw))
}

struct Fractal {
    seed: u64,
    octaves: u32,
    gain: f64,
    periodic: bool,
}

impl Fractal {
    /// Sum of the octaves at lattice coordinates `(x, y)` of the first one,
    /// whose lattice has `(px, py)` cells across the map.
    fn at(&self, x: f64, y: f64, px: f64, py: f64) -> f64 {
        let mut sum = 0.0;
        let mut amplitude = 1.0;
        let mut scale = 1.0;
        for octave in 0..self.octaves {
            let period = self
                .periodic
                .then_some(((px * scale) as i64, (py * scale) as i64));
            let salt = self.seed ^ (octave as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
            sum += amplitude * perlin(x * scale, y * scale, period, salt);
            amplitude *= self.gain;
            scale *= 2.0;
        }
        sum
    }
}

/// Perlin's gradient noise (quintic fade, as in his 2002 "Improving Noise")
/// at `(x, y)`; lattice indices wrap with `period` when given.
fn perlin(x: f64, y: f64, period: Option<(i64, i64)>, salt: u64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let corner = |dx: i64, dy: i64| {
        let (mut cx, mut cy) = (ix + dx, iy + dy);
        if let Some((px, py)) = period {
            cx = cx.rem_euclid(px);
            cy = cy.rem_euclid(py);
        }
        let (gx, gy) = GRADIENTS[(hash(cx, cy, salt) >> 61) as usize];
        gx * (fx - dx as f64) + gy * (fy - dy as f64)
    };
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (fade(fx), fade(fy));
    let a = lerp(corner(0, 0), corner(1, 0), sx);
    let b = lerp(corner(0, 1), corner(1, 1), sx);
    lerp(a, b, sy)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// A well-mixed 64-bit hash of a lattice point (SplitMix64's finaliser).
fn hash(x: i64, y: i64, salt: u64) -> u64 {
    crate::random::mix64(
        (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ salt,
    )
}

/// Rescales to exactly `[0, 1]`; a constant map (possible only when every
/// texel centre falls on a lattice point) becomes 0.5.
fn normalise(mut data: Vec<f32>) -> Vec<f32> {
    let (lo, hi) = data
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let range = hi - lo;
    for v in &mut data {
        *v = if range > 0.0 {
            ((*v - lo) / range).clamp(0.0, 1.0)
        } else {
            0.5
        };
    }
    data
}

#[cfg(test)]
mod tests {
    use super::super::generate;
    use crate::{Address, Error, HeightMap};

    /// Mean absolute difference between horizontal neighbours: interior
    /// pairs, and the pair across the wrap (last column, first column); the
    /// same for vertical neighbours.
    fn neighbour_differences(m: &HeightMap) -> (f64, f64) {
        let (w, h) = (m.width() as i64, m.height() as i64);
        let (mut interior, mut n_interior, mut wrap, mut n_wrap) = (0.0, 0, 0.0, 0);
        for j in 0..h {
            for i in 0..w - 1 {
                interior += (m.texel(i + 1, j) - m.texel(i, j)).abs() as f64;
                n_interior += 1;
            }
            wrap += (m.texel(0, j) - m.texel(w - 1, j)).abs() as f64;
            n_wrap += 1;
        }
        for i in 0..w {
            for j in 0..h - 1 {
                interior += (m.texel(i, j + 1) - m.texel(i, j)).abs() as f64;
                n_interior += 1;
            }
            wrap += (m.texel(i, 0) - m.texel(i, h - 1)).abs() as f64;
            n_wrap += 1;
        }
        (interior / n_interior as f64, wrap / n_wrap as f64)
    }

    #[test]
    fn repeat_addressed_noise_continues_across_the_edges() {
        for (spec, w, h) in [
            ("gen:noise", 128, 128),
            ("gen:noise?seed=7&octaves=3&frequency=3&gain=0.7", 96, 64),
            ("gen:noise?seed=99&octaves=6&frequency=8", 256, 128),
        ] {
            let tiled = generate(spec, w, h, Address::Repeat).unwrap();
            let (interior, wrap) = neighbour_differences(&tiled);
            assert!(
                wrap < 1.5 * interior,
                "{spec}: across the wrap {wrap:.4} vs interior {interior:.4}"
            );
            // The same noise without a periodic lattice does not tile: the
            // statistic can tell the two apart.
            let clamped = generate(spec, w, h, Address::Clamp).unwrap();
            let (interior, wrap) = neighbour_differences(&clamped);
            assert!(
                wrap > 3.0 * interior,
                "{spec}: clamp {wrap:.4} vs {interior:.4}"
            );
        }
    }

    #[test]
    fn noise_spans_the_unit_range_and_depends_on_the_seed() {
        let a = generate("gen:noise?seed=1", 64, 64, Address::Repeat).unwrap();
        let b = generate("gen:noise?seed=2", 64, 64, Address::Repeat).unwrap();
        let lo = a.data().iter().cloned().fold(f32::INFINITY, f32::min);
        let hi = a.data().iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!((lo, hi), (0.0, 1.0));
        assert_ne!(a, b);
        let mean = a.data().iter().map(|&v| v as f64).sum::<f64>() / 4096.0;
        assert!((0.2..0.8).contains(&mean), "{mean}");
    }

    #[test]
    fn fractional_frequency_cannot_tile() {
        assert!(generate("gen:noise?frequency=2.5", 32, 32, Address::Clamp).is_ok());
        match generate("gen:noise?frequency=2.5", 32, 32, Address::Repeat) {
            Err(Error::GeneratorParameter { message, .. }) => {
                assert!(
                    message.contains("`frequency`") && message.contains("whole"),
                    "{message}"
                )
            }
            other => panic!("{other:?}"),
        }
    }
}
