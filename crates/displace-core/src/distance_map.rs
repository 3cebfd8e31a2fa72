//! The conservative 3D distance map (Donnelly section 8.4, made safe for the
//! continuous surface; `docs/architecture.md`, "Conventions"): for every
//! point `p` of the shell, the trilinear interpolation of the stored values is
//! at most the true signed distance from `p` to the continuous bilinear
//! surface, so a sphere-tracing step can never cross the surface.
//!
//! Values are signed distances in units of the shell depth (negative under
//! the surface), over map space as [`crate::convention`] defines it.
//!
//! # Why the stored values are safe
//! The bake ([`crate::bake::bake`]) proves it in two steps:
//! 1. **Lower bound at voxel centres.** Column `(i, j)` of the map covers a
//!    footprint of `hx x hy`; over it the surface spans exactly
//!    `[hmin, hmax]` ([`crate::HeightMap::range`]). The transform gives the exact
//!    distance `D` from a voxel centre `c` to the set of vertical segments
//!    `{column centre} x [hmin, hmax]`. Every surface point lies within
//!    `r = |(hx, hy)| / 2` of one of those segments and every segment point
//!    within `r` of the surface, so `D - r <= dist(c) <= D + r`.
//! 2. **Trilinear slack.** The signed distance is 1-Lipschitz, and for
//!    trilinear weights `sum w_c |p - c| <= |(hx, hy, hz)| / 2` (Jensen, with
//!    `sum w_c (p - c)_x^2 = x (1 - x) hx^2 <= hx^2 / 4`). Subtracting that
//!    half diagonal from every lower bound makes the interpolant a lower bound
//!    everywhere.
//!
//! Both margins together keep the stored value within about one voxel
//! diagonal of the truth ([`DistanceMap::max_underestimate`]).

use crate::convention::{check_allocation, floor_i64, texel_lerp, Address};
use crate::{Error, Result};
use glam::Vec3;
use rayon::prelude::*;

/// Storage format of a distance map in a texture file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Format {
    /// 8-bit unsigned normalised, decoded with the map's [`R8Range`].
    /// Donnelly's 256x256x16 maps were 8-bit.
    #[default]
    R8,
    /// IEEE half float, depth units.
    R16F,
    /// IEEE single float, depth units.
    R32F,
}

impl Format {
    /// The name [`str::parse`] accepts (`r8`, `r16f`, `r32f`).
    pub fn name(self) -> &'static str {
        match self {
            Format::R8 => "r8",
            Format::R16F => "r16f",
            Format::R32F => "r32f",
        }
    }
    /// Bytes one voxel takes in this format.
    pub fn bytes_per_voxel(self) -> usize {
        match self {
            Format::R8 => 1,
            Format::R16F => 2,
            Format::R32F => 4,
        }
    }
}

impl std::str::FromStr for Format {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let choices = [Format::R8, Format::R16F, Format::R32F].map(|f| (f.name(), f));
        crate::names::parse_choice("distance format", s, &choices).map_err(Error::UnknownName)
    }
}

/// Decoding of an R8 map: `value = min + code / 255 * (max - min)` in depth
/// units. `min` is the map's lowest value (so nothing is clamped upwards,
/// which would break conservativeness) and the span is [`R8_SPAN`]: larger
/// distances clamp down to `max`, which stays safe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct R8Range {
    /// The value of code 0, in depth units.
    pub min: f32,
    /// The value of code 255, in depth units (`min + R8_SPAN`).
    pub max: f32,
}

/// Span of an R8 map in depth units: a step of up to about three shell
/// depths, with a resolution of 1/64 depth.
pub const R8_SPAN: f32 = 4.0;

impl R8Range {
    /// The range for a map's values: its minimum, rounded down to 1/64.
    pub fn for_values(values: &[f32]) -> Self {
        let lo = values
            .par_iter()
            .copied()
            .reduce(|| f32::INFINITY, f32::min);
        Self::for_min(lo)
    }

    /// The range for values whose minimum is `lo`.
    pub(crate) fn for_min(lo: f32) -> Self {
        let min = if lo.is_finite() {
            (lo * 64.0).floor() / 64.0
        } else {
            -1.0
        };
        Self {
            min,
            max: min + R8_SPAN,
        }
    }

    /// Code of the largest representable value not above `v` (code 0 when
    /// even that is above `v`).
    pub fn encode(&self, v: f32) -> u8 {
        let x = (v - self.min) / (self.max - self.min) * 255.0;
        settle(guess(x), v, |c| self.decode(c))
    }

    /// [`R8Range::encode`] for many values: the 256 decoded values in a
    /// table, so that a code costs a multiplication and a look-up or two
    /// rather than a division and several decodes.
    pub fn encoder(&self) -> R8Encoder {
        R8Encoder {
            min: self.min,
            scale: 255.0 / (self.max - self.min),
            decoded: std::array::from_fn(|c| self.decode(c as u8)),
        }
    }

    /// The value, in depth units, that code `c` stands for.
    pub fn decode(&self, c: u8) -> f32 {
        self.min + c as f32 / 255.0 * (self.max - self.min)
    }

    /// The step between two codes, in depth units: the most that
    /// [`Self::encode`] rounds a value down by (inside the range).
    pub fn quantum(&self) -> f32 {
        (self.max - self.min) / 255.0
    }
}

/// A distance map as a linearly filtered GPU texture
/// ([`DistanceMap::filtered_texels`]): a fetch `s` of the texture decodes to
/// `offset + scale * s`, a lower bound on the true distance by at most
/// `underestimate` (shell depths).
#[derive(Clone, Debug, PartialEq)]
pub struct FilteredTexels {
    /// Level 0, `[k][j][i]`, little-endian: R8 unorm codes or R16 half floats.
    pub bytes: Vec<u8>,
    /// The texel format of `bytes` (R8 unorm or R16 float).
    pub format: Format,
    /// Depth units per unit of the fetched value (the R8 range's span; 1
    /// for half floats).
    pub scale: f32,
    /// Depth units a fetch of 0 stands for: the R8 range's minimum (0 for
    /// half floats), lowered by the filtering margin so that the decoded
    /// value stays a lower bound.
    pub offset: f32,
    /// How far a decoded, linearly filtered fetch may fall below the true
    /// distance, in shell depths (the stored values' bound plus the
    /// filtering margin): what the tracer's stop band must cover (Donnelly,
    /// GPU Gems 2 ch. 8, section 8.3).
    pub underestimate: f32,
}

/// 2^23: the smallest `f32` whose ulp is 1.
const TWO_23: f32 = 8_388_608.0;

/// See [`R8Range::encoder`]; gives the same codes as [`R8Range::encode`].
pub struct R8Encoder {
    min: f32,
    scale: f32,
    decoded: [f32; 256],
}

impl R8Encoder {
    /// The same code as [`R8Range::encode`] gives for `v`.
    pub fn encode(&self, v: f32) -> u8 {
        settle(guess((v - self.min) * self.scale), v, |c| {
            self.decoded[c as usize]
        })
    }

    /// [`Self::encode`] of every value, into `codes`. Runs of 32 values are
    /// guessed with straight-line float arithmetic the compiler vectorises
    /// (the table-driven encoder, one code at a time, took 10% of a bake);
    /// in a run where some guess lies too near a code boundary to be sure
    /// of, those values are encoded exactly.
    pub fn encode_into(&self, values: &[f32], codes: &mut [u8]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is present.
            unsafe { self.encode_into_avx2(values, codes) };
            return;
        }
        self.encode_runs(values, codes);
    }

    /// [`Self::encode_runs`] compiled for AVX2: eight guesses an
    /// instruction rather than four, the same operations and codes.
    ///
    /// # Safety
    /// The CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn encode_into_avx2(&self, values: &[f32], codes: &mut [u8]) {
        self.encode_runs(values, codes);
    }

    /// [`Self::encode_into`] inlined into its caller, compiled for the
    /// caller's instruction set: the bake encodes each run of values as it
    /// computes them, inside its AVX2 slice.
    #[inline(always)]
    pub(crate) fn encode_runs(&self, values: &[f32], codes: &mut [u8]) {
        const RUN: usize = 32;
        assert_eq!(values.len(), codes.len());
        for (v, c) in values.chunks(RUN).zip(codes.chunks_mut(RUN)) {
            // Two plain loops (a map, an or-reduction) so that both vectorise.
            for (o, &x) in c.iter_mut().zip(v) {
                *o = ((self.scaled(x).0 + TWO_23).to_bits() & 0xff) as u8;
            }
            let unsure = v.iter().fold(0u32, |a, &x| a | u32::from(!self.sure(x)));
            if unsure != 0 {
                for (o, &x) in c.iter_mut().zip(v) {
                    if !self.sure(x) {
                        *o = self.encode(x);
                    }
                }
            }
        }
    }

    /// The guess `floor` of the scaled value, clamped to a code (as an
    /// `f32`), and the scaled value. Only float arithmetic, so that it
    /// vectorises: comparisons rather than `clamp` (whose NaN rule keeps a
    /// loop scalar), and `floor` from rounding to nearest by adding and
    /// subtracting 2^23 (exact for values below 2^22) instead of a
    /// saturating cast. A NaN becomes code 0 and is never [`Self::sure`];
    /// adding 2^23 to a code puts it in the low byte of the float's bits.
    #[inline(always)]
    fn scaled(&self, v: f32) -> (f32, f32) {
        let x = (v - self.min) * self.scale;
        let c = if x > 0.0 { x } else { 0.0 };
        let c = if c < 255.0 { c } else { 255.0 };
        let r = (c + TWO_23) - TWO_23;
        (if r > c { r - 1.0 } else { r }, x)
    }

    /// Whether the guess of [`Self::scaled`] is surely the answer (the
    /// largest code whose decoded value is not above `v`): it is when the
    /// scaled value is more than [`Self::MARGIN`] from an integer. The scaled
    /// value (two roundings of at most 2^-24 relative, on values up to 255)
    /// is within 5e-5 codes of exact, and a decoded value (two roundings on
    /// values of magnitude below 8, span 4) within 6e-5 codes, so away from
    /// the margin the table's comparisons agree with `floor`. Clamped
    /// guesses (below 0, at or above 255) are left to [`Self::encode`].
    #[inline(always)]
    fn sure(&self, v: f32) -> bool {
        let (c, x) = self.scaled(v);
        let frac = x - c;
        frac > Self::MARGIN && frac < 1.0 - Self::MARGIN
    }

    /// Codes from the nearest boundary, about ten times the rounding above.
    const MARGIN: f32 = 1e-3;
}

/// `floor(x)` clamped to a code: truncation is floor once `x >= 0`, and a
/// `NaN` casts to 0.
fn guess(x: f32) -> u8 {
    x.clamp(0.0, 255.0) as u8
}

/// From a guess within rounding of the answer, the largest code whose
/// decoded value is not above `v`: one step up where the guess rounded low,
/// then down while it decodes above `v`.
fn settle(mut c: u8, v: f32, decode: impl Fn(u8) -> f32) -> u8 {
    if c < 255 && decode(c + 1) <= v {
        c += 1;
    }
    while c > 0 && decode(c) > v {
        c -= 1;
    }
    c
}

/// The largest half float not above `v`.
pub fn f16_round_down(v: f32) -> half::f16 {
    let h = half::f16::from_f32(v);
    if h.to_f32() <= v {
        return h;
    }
    let bits = h.to_bits();
    let down = if bits & 0x7fff == 0 {
        0x8001 // below +-0: the smallest negative subnormal
    } else if bits & 0x8000 == 0 {
        bits - 1
    } else {
        bits + 1
    };
    half::f16::from_bits(down)
}

/// The minimum of `values` (NaN ignored) and whether any is not finite
/// (NaN or infinite: no distance to a surface inside the shell is). Sixteen
/// independent minima with comparisons rather than `f32::min`, whose NaN
/// handling and one serial chain keep it from vectorising (it cost 7% of a
/// bake).
fn min_and_nonfinite(values: &[f32]) -> (f32, bool) {
    const N: usize = 16;
    let mut lo = [f32::INFINITY; N];
    let mut nan = [false; N];
    let chunks = values.chunks_exact(N);
    let rest = chunks.remainder();
    for c in chunks {
        for i in 0..N {
            lo[i] = if c[i] < lo[i] { c[i] } else { lo[i] };
            nan[i] |= !c[i].is_finite();
        }
    }
    let lo = lo.iter().chain(rest).fold(f32::INFINITY, |a, &b| a.min(b));
    (
        lo,
        nan.iter().any(|&b| b) || rest.iter().any(|v| !v.is_finite()),
    )
}

/// A conservative 3D distance map over one tile's shell (Donnelly, GPU
/// Gems 2 ch. 8, section 8.2; made conservative as the module docs prove):
/// signed distances in depth units on a voxel grid over map space, with the
/// bound the tracer needs on how far the values underestimate the truth.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceMap {
    size: [usize; 3],
    aspect: [f32; 2],
    address: Address,
    data: Vec<f32>,
    max_underestimate: f32,
    /// What the tracer reads: the values rounded down to 8 bits. A quarter of
    /// the memory traffic of `data` (the CPU tracer is bound by cache misses
    /// in the 3D map), and the same precision Donnelly's 8-bit maps had; the
    /// rounding is part of `max_underestimate`.
    codes: Vec<u8>,
    range: R8Range,
    /// Voxels per map-space unit along each axis ([`Self::cell_bound`]).
    cell_scale: [f32; 3],
}

impl DistanceMap {
    /// Wraps stored values (`[k][j][i]`, depth units). `max_underestimate`
    /// bounds `true distance - interpolated value` over the shell; the tracer
    /// uses it to know how far a converged ray may still be from the surface.
    pub fn from_raw(
        size: [usize; 3],
        aspect: [f32; 2],
        address: Address,
        data: Vec<f32>,
        max_underestimate: f32,
    ) -> Result<Self> {
        Self::check_size(size)?;
        if data.len() != size[0] * size[1] * size[2] {
            return Err(Error::InvalidSize(format!(
                "distance map {}x{}x{} needs {} values, got {}",
                size[0],
                size[1],
                size[2],
                size[0] * size[1] * size[2],
                data.len()
            )));
        }
        if !(aspect[0] > 0.0 && aspect[1] > 0.0 && aspect.iter().all(|a| a.is_finite())) {
            return Err(Error::InvalidExtent(format!("aspect {aspect:?}")));
        }
        // The finiteness check and the minimum in one pass over the values.
        let (lo, nan) = data
            .par_chunks(1 << 16)
            .map(min_and_nonfinite)
            .reduce(|| (f32::INFINITY, false), |a, b| (a.0.min(b.0), a.1 | b.1));
        if nan {
            return Err(Error::InvalidSize(
                "distance map holds NaN or infinite values".into(),
            ));
        }
        let range = R8Range::for_min(lo);
        let encoder = range.encoder();
        let mut codes = crate::memory::zeroed::<u8>("the distance map's 8-bit codes", data.len())?;
        codes
            .par_chunks_mut(1 << 16)
            .zip(data.par_chunks(1 << 16))
            .for_each(|(c, v)| encoder.encode_into(v, c));
        Ok(Self {
            size,
            aspect,
            address,
            data,
            max_underestimate: max_underestimate + range.quantum(),
            codes,
            range,
            cell_scale: [
                size[0] as f32 / aspect[0],
                size[1] as f32 / aspect[1],
                size[2] as f32,
            ],
        })
    }

    /// Refuses empty sizes and sizes whose allocation would exceed
    /// [`crate::convention::MAX_ALLOCATION_BYTES`], before allocating.
    pub fn check_size(size: [usize; 3]) -> Result<()> {
        if size.iter().any(|&n| n < 2) {
            return Err(Error::InvalidSize(format!(
                "distance map {}x{}x{}: every dimension needs at least 2 voxels",
                size[0], size[1], size[2]
            )));
        }
        let n = size.iter().map(|&n| n as u128).product::<u128>();
        check_allocation(
            "distance map",
            &format!("{}x{}x{}", size[0], size[1], size[2]),
            n,
            4,
        )
    }

    /// Voxels along `u`, `v` and depth: `[width, height, depth]`.
    pub fn size(&self) -> [usize; 3] {
        self.size
    }
    /// The tile's width and height in depth units (`[sx / sz, sy / sz]` of
    /// its [`crate::Extent`]): the map-space extent of `u` and `v`.
    pub fn aspect(&self) -> [f32; 2] {
        self.aspect
    }
    /// How the map continues past the tile's edges: clamped or repeating,
    /// as the height map it was baked from.
    pub fn address(&self) -> Address {
        self.address
    }
    /// Voxels per map-space unit along each axis: what
    /// [`Self::cell_bound`] scales a point by (the packet tracer repeats
    /// that arithmetic in vector lanes).
    pub(crate) fn cell_scale(&self) -> [f32; 3] {
        self.cell_scale
    }
    /// The stored values at full precision, `[k][j][i]` (depth slice `k`
    /// outermost), in depth units.
    pub fn data(&self) -> &[f32] {
        &self.data
    }
    /// Bound on `true signed distance - sample(p)` over the shell, the
    /// 8-bit rounding included.
    pub fn max_underestimate(&self) -> f32 {
        self.max_underestimate
    }

    /// The stored values' own bound, without the tracer's 8-bit rounding:
    /// what a file written from [`DistanceMap::data`] promises.
    pub fn data_underestimate(&self) -> f32 {
        self.max_underestimate - self.range.quantum()
    }

    /// Voxel spacing in map space (depth units).
    pub fn voxel_size(&self) -> Vec3 {
        Vec3::new(
            self.aspect[0] / self.size[0] as f32,
            self.aspect[1] / self.size[1] as f32,
            1.0 / self.size[2] as f32,
        )
    }

    /// The stored value of voxel `(i, j, k)`, in depth units, without
    /// addressing: each index must be below its [`Self::size`].
    #[inline]
    pub fn voxel(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[(k * self.size[1] + j) * self.size[0] + i]
    }

    /// A lower bound on the signed distance from `p` to the surface, from
    /// the one voxel whose box contains `p` (no interpolation): a single
    /// load where [`Self::sample`] needs eight.
    ///
    /// Why it is safe: the bake stores at each voxel centre `c` a lower bound
    /// `L(c)` of the distance minus the voxel's half diagonal `e` (the slack
    /// that makes the trilinear interpolant conservative, module docs). For
    /// `p` in the voxel's box `|p - c| <= e`, and the distance is
    /// 1-Lipschitz, so `dist(p) >= L(c) - |p - c| >= value(c)`: every stored
    /// value bounds the distance over its whole voxel ("cell-conservative").
    /// It reads the full-precision values, not the 8-bit codes the
    /// trilinear [`Self::sample`] reads: one load a step either way, and
    /// without the codes' rounding the tracer stops closer to the surface
    /// (fewer patches walked, the same cache misses measured by cachegrind
    /// on the benchmark faces). Points outside the shell are clamped
    /// to the nearest voxel in depth and in a clamped map's plane, which
    /// the tracer only does within rounding of the box.
    #[inline(always)]
    pub fn cell_bound(&self, p: Vec3) -> f32 {
        let [w, h, d] = self.size;
        let [sx, sy, sz] = self.cell_scale;
        // Clamping in floats, then truncating: floor-then-clamp for every
        // value, in three instructions (comparisons that send NaN to 0,
        // and a cast that needs no saturation).
        let clamped = |x: f32, n: usize| {
            let hi = (n - 1) as f32;
            let x = if x > 0.0 { x } else { 0.0 };
            let x = if x < hi { x } else { hi };
            // SAFETY: `x` is finite and in `[0, n - 1]`.
            unsafe { x.to_int_unchecked::<u32>() as usize }
        };
        let (i, j) = match self.address {
            Address::Clamp => (clamped(p.x * sx, w), clamped(p.y * sy, h)),
            Address::Repeat => (
                Address::Repeat.texel_index(floor_i64(p.x * sx), w),
                Address::Repeat.texel_index(floor_i64(p.y * sy), h),
            ),
        };
        let k = clamped(p.z * sz, d);
        debug_assert!(i < w && j < h && k < d);
        // SAFETY: `i < w`, `j < h`, `k < d` (clamped or wrapped above), and
        // `data` holds `w * h * d` values (`from_raw`).
        unsafe { *self.data.get_unchecked((k * h + j) * w + i) }
    }

    /// Trilinear interpolation at map-space point `p` of the 8-bit values the
    /// tracer reads, as a GPU's linear sampler does it (clamp-to-edge in
    /// depth; the map's addressing across).
    #[inline]
    pub fn sample(&self, p: Vec3) -> f32 {
        let [w, h, d] = self.size;
        let (i, fx) = texel_lerp(p.x / self.aspect[0], w);
        let (j, fy) = texel_lerp(p.y / self.aspect[1], h);
        let (k, fz) = texel_lerp(p.z, d);
        let i0 = self.address.texel_index(i, w);
        let i1 = self.address.texel_index(i + 1, w);
        let j0 = self.address.texel_index(j, h);
        let j1 = self.address.texel_index(j + 1, h);
        let k0 = Address::Clamp.texel_index(k, d);
        let k1 = Address::Clamp.texel_index(k + 1, d);
        let at = |ii: usize, jj: usize, kk: usize| self.codes[(kk * h + jj) * w + ii] as f32;
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(at(i0, j0, k0), at(i1, j0, k0), fx);
        let c10 = lerp(at(i0, j1, k0), at(i1, j1, k0), fx);
        let c01 = lerp(at(i0, j0, k1), at(i1, j0, k1), fx);
        let c11 = lerp(at(i0, j1, k1), at(i1, j1, k1), fx);
        self.range.min
            + lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz)
                * ((self.range.max - self.range.min) / 255.0)
    }

    /// Bound on how much a linear filter with `weight_bits`-bit fixed-point
    /// weights can overshoot the exact trilinear value of this map's values
    /// (GPU Gems 2 section 8.5.3 samples the map through the hardware
    /// filter): each of the three lerps may be off by `2^-bits` of the
    /// difference between neighbouring texels, which is at most the largest
    /// such difference in the map, plus `quantum` per lerp when the values
    /// are stored as codes of that size. A GPU user subtracts it from the
    /// decoded distance so the filtered value stays a lower bound.
    pub fn filter_margin(&self, weight_bits: u32, quantum: f32) -> f32 {
        let [w, h, d] = self.size;
        let mut diff = [0.0f32; 3];
        for k in 0..d {
            for j in 0..h {
                for i in 0..w {
                    let v = self.voxel(i, j, k);
                    let n = [
                        self.voxel(self.address.texel_index(i as i64 + 1, w), j, k),
                        self.voxel(i, self.address.texel_index(j as i64 + 1, h), k),
                        self.voxel(i, j, (k + 1).min(d - 1)),
                    ];
                    for (m, nv) in diff.iter_mut().zip(n) {
                        *m = m.max((nv - v).abs());
                    }
                }
            }
        }
        let weight_error = (-(weight_bits as f32)).exp2();
        weight_error * (diff.iter().sum::<f32>() + 3.0 * quantum)
    }

    /// The texels and decoding of this map for a GPU's linear sampler
    /// (GPU Gems 2 section 8.5.3; section 8.6's 8-bit maps): R16 half floats
    /// or R8 codes, rounded down, with the worst fixed-point filter error of
    /// `weight_bits`-bit weights ([`DistanceMap::filter_margin`]) taken off
    /// the decoding so every filtered value stays a lower bound. `None` for
    /// [`Format::R32F`], which GPUs need not filter.
    pub fn filtered_texels(&self, format: Format, weight_bits: u32) -> Option<FilteredTexels> {
        match format {
            Format::R32F => None,
            Format::R16F => {
                let (q, _) = self.quantized(Format::R16F);
                let bytes = q
                    .data()
                    .iter()
                    .flat_map(|&v| half::f16::from_f32(v).to_bits().to_le_bytes())
                    .collect();
                let margin = q.filter_margin(weight_bits, 0.0);
                Some(FilteredTexels {
                    bytes,
                    format,
                    scale: 1.0,
                    offset: -margin,
                    underestimate: q.data_underestimate() + margin,
                })
            }
            Format::R8 => {
                let (q, range) = self.quantized(Format::R8);
                let r = range.expect("R8 quantisation returns its range");
                let mut bytes = vec![0u8; self.data.len()];
                r.encoder().encode_into(&self.data, &mut bytes);
                // 8-bit filter units (llvmpipe's among them) may round the
                // filtered result to a code as well: one more quantum.
                let margin = q.filter_margin(weight_bits, r.quantum()) + r.quantum();
                Some(FilteredTexels {
                    bytes,
                    format,
                    scale: r.max - r.min,
                    offset: r.min - margin,
                    underestimate: q.data_underestimate() + margin,
                })
            }
        }
    }

    /// The same map rounded down to what `format` can store: still
    /// conservative, with the largest rounding added to the underestimate
    /// bound. For R8 the range used is returned too.
    pub fn quantized(&self, format: Format) -> (Self, Option<R8Range>) {
        let (data, extra, range): (Vec<f32>, f32, _) = match format {
            Format::R32F => (self.data.clone(), 0.0, None),
            Format::R16F => {
                let data: Vec<f32> = self
                    .data
                    .iter()
                    .map(|&v| f16_round_down(v).to_f32())
                    .collect();
                let extra = self
                    .data
                    .iter()
                    .zip(&data)
                    .map(|(a, b)| a - b)
                    .fold(0.0f32, f32::max);
                (data, extra, None)
            }
            Format::R8 => {
                let r = R8Range::for_values(&self.data);
                let data = self.data.iter().map(|&v| r.decode(r.encode(v))).collect();
                (data, r.quantum(), Some(r))
            }
        };
        let map = Self::from_raw(
            self.size,
            self.aspect,
            self.address,
            data,
            self.data_underestimate() + extra,
        )
        .expect("rounding keeps a valid map valid");
        (map, range)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_and_nonfinite_match_a_plain_fold() {
        let mut unit = crate::random::xorshift_unit(7);
        let mut next = || unit() * 8.0 - 3.0;
        for n in [0usize, 1, 15, 16, 17, 100, 1000] {
            let mut v: Vec<f32> = (0..n).map(|_| next()).collect();
            let want = v.iter().copied().fold(f32::INFINITY, f32::min);
            assert_eq!(min_and_nonfinite(&v), (want, false), "n = {n}");
            for at in [0, n / 2, n.saturating_sub(1)] {
                if n > 0 {
                    let keep = v[at];
                    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                        v[at] = bad;
                        assert!(min_and_nonfinite(&v).1, "{bad} at {at} of {n}");
                    }
                    v[at] = keep;
                }
            }
        }
        for bad in [f32::NAN, f32::INFINITY] {
            let data = vec![0.5, bad, 0.25, 1.0, 0.0, 0.0, 0.0, 0.0];
            let err = DistanceMap::from_raw([2, 2, 2], [1.0, 1.0], Address::Clamp, data, 0.0);
            assert!(err.unwrap_err().to_string().contains("NaN or infinite"));
        }
    }

    /// Codes of values on and around every decoded value (where guesses
    /// round either way), far outside the range, and random, in runs.
    #[test]
    fn run_encoding_matches_the_exact_encoder() {
        let r = R8Range {
            min: -0.703125,
            max: -0.703125 + R8_SPAN,
        };
        let e = r.encoder();
        let mut values = Vec::new();
        for c in 0..=255u8 {
            let d = r.decode(c);
            for k in -3i32..=3 {
                values.push(f32::from_bits((d.to_bits() as i32 + k) as u32));
            }
        }
        values.extend([-100.0, r.min - 1.0, r.max, r.max + 1e-3, 1e9, f32::INFINITY]);
        let mut unit = crate::random::xorshift_unit(3);
        values.extend((0..5000).map(|_| r.min - 0.5 + unit() * (R8_SPAN + 1.0)));
        let mut codes = vec![0u8; values.len()];
        e.encode_into(&values, &mut codes);
        for (&v, &c) in values.iter().zip(&codes) {
            assert_eq!(c, r.encode(v), "{v}");
        }
    }

    #[test]
    fn rounding_down_never_rounds_up() {
        let values: Vec<f32> = (0..20000).map(|k| -1.2 + k as f32 * 0.00031).collect();
        let r = R8Range::for_values(&values);
        for &v in &values {
            let q = r.decode(r.encode(v));
            assert!(q <= v, "r8 {v} -> {q}");
            if v <= r.max {
                assert!(v - q <= r.quantum() + 1e-6, "r8 {v} -> {q}");
            }
            assert_eq!(r.encoder().encode(v), r.encode(v), "{v}");
            let mut code = [0u8];
            r.encoder().encode_into(&[v], &mut code);
            assert_eq!(code[0], r.encode(v), "{v}");
            let h = f16_round_down(v).to_f32();
            // One f16 step: 2^-10 relative (2^-24 absolute among subnormals).
            assert!(
                h <= v && v - h <= (v.abs() / 1024.0).max(6e-8),
                "f16 {v} -> {h}"
            );
        }
    }

    /// Every texel `filtered_texels` stores decodes to at most the value it
    /// stands for, by less than the margin it reports; R32F is refused.
    #[test]
    fn filtered_texels_decode_below_the_values() {
        let (w, h, d) = (6usize, 5usize, 4usize);
        let data: Vec<f32> = (0..w * h * d)
            .map(|k| ((k * 7919) % 113) as f32 * 0.01 - 0.3)
            .collect();
        let map =
            DistanceMap::from_raw([w, h, d], [2.0, 2.0], Address::Repeat, data, 0.05).unwrap();
        assert!(map.filtered_texels(Format::R32F, 8).is_none());
        for format in [Format::R8, Format::R16F] {
            let t = map.filtered_texels(format, 8).unwrap();
            assert_eq!(t.format, format);
            assert_eq!(t.bytes.len(), map.data().len() * format.bytes_per_voxel());
            assert!(t.underestimate >= map.data_underestimate());
            for (i, &v) in map.data().iter().enumerate() {
                let s = match format {
                    Format::R8 => t.bytes[i] as f32 / 255.0,
                    _ => half::f16::from_le_bytes([t.bytes[2 * i], t.bytes[2 * i + 1]]).to_f32(),
                };
                let decoded = t.offset + t.scale * s;
                assert!(decoded <= v, "{format:?} voxel {i}: {decoded} > {v}");
                assert!(
                    v - decoded <= t.underestimate,
                    "{format:?} voxel {i}: {v} - {decoded}"
                );
            }
        }
    }
}
