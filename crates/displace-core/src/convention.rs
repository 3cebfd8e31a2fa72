//! The one source of truth for the conventions that CPU and GPU share
//! (`docs/architecture.md`, "Conventions", says where each is used and
//! which test checks it).
//!
//! **Map space.** `x` runs along the face tangent (texture `u`), `y` along the
//! bitangent (`v`), `z` along the normal. Lengths are measured in units of the
//! shell depth, so the shell of one tile is the box
//! `[0, ax] x [0, ay] x [0, 1]` where `(ax, ay) = extent.aspect()`, and the
//! displaced surface is `z = h(x / ax, y / ay)`. A step `p += d * dir` with a
//! stored distance `d` is safe when `dir` is unit length in this metric: this
//! is Donnelly's "normalization factor" (section 8.5.2) made explicit.
//!
//! **Texel centres.** Height texel `(i, j)` of a `W x H` map sits at texture
//! coordinate `((i + 0.5) / W, (j + 0.5) / H)`; distance voxel `(i, j, k)` at
//! `((i + 0.5) / W, (j + 0.5) / H, (k + 0.5) / D)`. Interpolation is bilinear
//! (height) and trilinear (distance) between those centres, exactly as a GPU's
//! linear sampler does it, with clamp-to-edge or repeat addressing.

use crate::{Error, Result};

/// Texture addressing outside `[0, 1]`, as a GPU sampler's address mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Address {
    /// Clamp to the edge texel: the face is one tile and the surface stops at
    /// its border.
    #[default]
    Clamp,
    /// The height map tiles; the distance map is baked periodic so that rays
    /// crossing a tile border are traced as safely as anywhere else.
    Repeat,
}

impl Address {
    /// Index of texel `i` in a row of `n` texels under this addressing.
    #[inline]
    pub fn texel_index(self, i: i64, n: usize) -> usize {
        match self {
            Address::Clamp => i.clamp(0, n as i64 - 1) as usize,
            Address::Repeat => i.rem_euclid(n as i64) as usize,
        }
    }

    /// The name [`str::parse`] accepts (`clamp` or `repeat`), as KTX2's
    /// `displace.addressing` key stores it.
    pub fn name(self) -> &'static str {
        match self {
            Address::Clamp => "clamp",
            Address::Repeat => "repeat",
        }
    }
}

impl std::str::FromStr for Address {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let choices = [Address::Clamp, Address::Repeat].map(|a| (a.name(), a));
        crate::names::parse_choice("addressing", s, &choices).map_err(Error::UnknownName)
    }
}

/// Physical size of one displaced tile: width `sx` (along `u`), height `sy`
/// (along `v`) and displacement depth `sz`, in any one unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// Width of the tile along `u`.
    pub sx: f32,
    /// Height of the tile along `v`.
    pub sy: f32,
    /// Displacement depth: the height of a texel of value 1 above the base.
    pub sz: f32,
}

impl Extent {
    /// Refuses zero, negative and non-finite sizes.
    pub fn new(sx: f32, sy: f32, sz: f32) -> Result<Self> {
        for (name, v) in [("width", sx), ("height", sy), ("depth", sz)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidExtent(format!(
                    "{name} must be a positive finite number, got {v}"
                )));
            }
        }
        let aspect = (sx / sz).max(sy / sz);
        if aspect > 1.0e6 || (sz / sx.min(sy)) > 1.0e6 {
            return Err(Error::InvalidExtent(format!(
                "proportions {sx}:{sy}:{sz} are too extreme (ratio above 1e6)"
            )));
        }
        Ok(Self { sx, sy, sz })
    }

    /// Width and height of one tile in units of the shell depth.
    #[inline]
    pub fn aspect(&self) -> [f32; 2] {
        [self.sx / self.sz, self.sy / self.sz]
    }
}

/// Texture coordinate of texel centre `i` of `n`.
#[inline]
pub fn texel_centre(i: usize, n: usize) -> f32 {
    (i as f32 + 0.5) / n as f32
}

/// Splits a texture coordinate into the lower texel index of the bilinear
/// footprint and the interpolation weight of the upper one, for `n` texels.
#[inline]
pub fn texel_lerp(t: f32, n: usize) -> (i64, f32) {
    let x = t * n as f32 - 0.5;
    let i = floor_i64(x);
    (i, x - i as f32)
}

/// The sRGB transfer function, decoded (IEC 61966-2-1): colour textures
/// and 8-bit colours in scene files are sRGB, while both renderers shade in
/// linear RGB.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function, encoded (IEC 61966-2-1), clamped to
/// `[0, 1]`: PNG output and the GPU's 8-bit colour texels are sRGB.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// `floor` as an integer without a libm call (baseline x86-64 has no
/// rounding instruction, and this sits in every texture fetch). Values
/// beyond the `i64` range saturate, which no texel index reaches.
#[inline]
pub fn floor_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i - 1
    } else {
        i
    }
}

/// Early-out threshold of sphere tracing, as a fraction of the smallest voxel
/// side: below it the stored distance no longer tells the ray from the
/// surface, and the tracer walks the next stretch exactly.
pub const TRACE_STOP_VOXELS: f32 = 0.25;

/// Length of that exact walk, in multiples of the map's underestimate bound
/// (plus the threshold). Any length is correct, since the walk is exact and
/// the ray is above the surface where it ends; this one was fastest on the
/// seed maps (BENCHMARKS.md).
pub const TRACE_BAND_FACTOR: f32 = 1.5;

/// A curved mesh's ray is a curve in its triangles' map space, traced as
/// chords: a chord is halved while its midpoint lies further than this
/// (shell depths) from the curve's, measured in height above the surface
/// (the offset in height plus the height field's steepest slope times the
/// offset across the map). A thousandth of the depth, far under what a
/// render resolves and the tests' thresholds (a hit is refined on the true
/// ray whatever the chord; the tolerance bounds only what a chord can pass
/// over). A ten-thousandth gave the same hits on a displaced sphere's
/// million camera rays (positions within 5e-7) with 1.3x the time: the
/// chords' traces are most of a curved ray's cost. The CPU's curved faces
/// and the GPU's curved shader (`CHORD_TOLERANCE` of convention.wgsl) both
/// read it from here.
pub const CHORD_TOLERANCE: f64 = 1e-3;

/// Most sphere-tracing steps one ray may take (`TraceOptions::iterations`,
/// the fixed count of `sphere-fixed`). Each step is a texture fetch, so a
/// count in the billions would run for hours on one image; no map needs more
/// steps than a few times its largest side, and 65536 covers the largest map
/// [`crate::DistanceMap::check_size`] accepts several times over.
pub const MAX_TRACE_ITERATIONS: u32 = 1 << 16;

/// Most height-map cells a displaced face may span along either axis (its
/// `tiles` times the height map's texels). The exact walk steps cells in
/// single precision (a ray parameter advanced a cell at a time, as
/// Amanatides and Woo's grid traversal does): past 2^24 cells from the ray's
/// origin a step no longer moves it, and well before that the stretches
/// drift. 2^20 cells (a 4096-texel map repeated 256 times) keeps four bits
/// under a cell.
pub const MAX_CELL_SPAN: f64 = (1u64 << 20) as f64;

/// Largest allocation one bake, map or image may ask for. Requests above it
/// are refused before any memory is touched.
pub const MAX_ALLOCATION_BYTES: u128 = 8 << 30;

/// Refuses `count` elements of `bytes_each` when that exceeds
/// [`MAX_ALLOCATION_BYTES`].
pub fn check_allocation(what: &str, size: &str, count: u128, bytes_each: u128) -> Result<()> {
    let bytes = count.saturating_mul(bytes_each);
    if bytes > MAX_ALLOCATION_BYTES {
        return Err(Error::TooLarge {
            what: what.to_string(),
            size: size.to_string(),
            bytes,
            limit: MAX_ALLOCATION_BYTES,
        });
    }
    Ok(())
}

/// Parses `WxH` or `WxHxD` sizes as the CLI and scene files write them.
pub fn parse_size<const N: usize>(s: &str) -> Result<[usize; N]> {
    let parts: Vec<&str> = s.split(['x', 'X']).collect();
    if parts.len() != N {
        return Err(Error::InvalidSize(format!(
            "`{s}`: expected {N} numbers separated by `x`"
        )));
    }
    let mut out = [0usize; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| Error::InvalidSize(format!("`{s}`: `{p}` is not a whole number")))?;
        if *o == 0 {
            return Err(Error::InvalidSize(format!("`{s}`: sizes must be positive")));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_lerp_hits_centres() {
        for n in [2usize, 3, 16] {
            for i in 0..n {
                let (j, w) = texel_lerp(texel_centre(i, n), n);
                assert_eq!(j, i as i64);
                assert!(w.abs() < 1e-5);
            }
        }
    }

    #[test]
    fn sizes_parse_and_refuse() {
        assert_eq!(parse_size::<3>("256x128x16").unwrap(), [256, 128, 16]);
        assert!(parse_size::<3>("256x128").is_err());
        assert!(parse_size::<2>("0x4").is_err());
        assert!(parse_size::<2>("ax4").is_err());
    }

    #[test]
    fn extents_refuse_nonsense() {
        assert!(Extent::new(1.0, 1.0, 0.0).is_err());
        assert!(Extent::new(-1.0, 1.0, 1.0).is_err());
        assert!(Extent::new(f32::NAN, 1.0, 1.0).is_err());
        assert!(Extent::new(1.0, 1.0, 0.1).is_ok());
    }
}
