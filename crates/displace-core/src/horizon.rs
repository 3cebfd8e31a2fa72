//! Horizon bounds that let a ray leaving the surface skip its trace.
//!
//! A shadow ray starts on the displaced surface, where every distance the
//! distance map holds is near zero: sphere tracing (Donnelly, GPU Gems 2
//! ch. 8, section 8.3) can only creep away from the start, and the exact
//! walk below its stop band crosses cell after cell until the ray is clear
//! of the bumps around it. Yet most such rays climb towards a light that
//! nothing hides. Horizon mapping (Max 1988, "Horizon mapping: shadows for
//! bump-mapped surfaces"; Sloan and Cohen 2000, "Interactive horizon
//! mapping") answers them at once: it stores, per point and direction, how
//! steeply the surface around rises, and a ray steeper than that horizon
//! cannot meet the surface again.
//!
//! Those papers sample the horizon at texels, in a few directions, which
//! is an approximation. Here each bound holds for *every* point of a height
//! cell (the bilinear patch between four texel centres) and every direction
//! of one of [`SECTORS`] azimuth sectors, so a "clear" answer is a proof.
//! Along a straight path the height gains the integral of the directional
//! derivative, and on a bilinear patch the derivative along a fixed
//! direction is largest at one of its corners. So the largest derivative
//! along the sector's directions over every cell of the sector's wedge (the
//! cell swept along those directions to the map's edge) bounds how steeply
//! the surface can rise ahead of any ray from the cell in that sector. Each
//! wedge is its cell, one neighbour and the wedges of two further
//! neighbours, so one sweep of the grid per sector finds them all (a
//! running maximum, as summed-area tables run sums). The bound is then
//! taken over the cell's 3x3 neighbourhood, so that a start or direction
//! rounded into a neighbouring cell or sector is still covered.
//!
//! The result, rounded up to an 8-bit logarithmic code, is the cell's
//! horizon slope in that sector (height per cell). A ray that starts on or
//! over the surface in that cell and rises more steeply than it stays over
//! the surface for the rest of the height map's box. It is a Lipschitz
//! bound: on a smooth field (a hill, rolling terrain) the slopes a ray
//! leaves downhill or across are small, and most shadow rays clear it; on
//! a field with cliffs in every direction (a photograph, steps) few do, and
//! those rays are traced as before.

use crate::convention::floor_i64;
use crate::HeightMap;
use std::fmt;
use std::sync::LazyLock;

/// Azimuth sectors per cell, each an eighth of the circle (octants of the
/// cell grid: a ray's sector is found from its direction's signs and which
/// of its components is larger, without an arc tangent).
pub const SECTORS: usize = 8;

/// Cells up to which a height map gets horizon bounds (2048 x 2048): larger
/// maps cost more to bound than their shadow rays would save in a render,
/// and the bounds' memory grows with the cells (8 bytes each).
pub const MAX_HORIZON_CELLS: usize = 1 << 22;

/// The share of a map's cells and sectors whose horizon a ray rising at 45
/// degrees must clear for its bounds to be kept and tested
/// ([`HorizonMap::pays_at`]): the test costs every ray it does not answer
/// a few nanoseconds (3-5% of a shadow ray on maps it answers none of).
pub const MIN_SHARE: f64 = 0.25;

/// Codes per factor of two of slope (a code is about 5% above the slope it
/// stands for).
const CODES_PER_OCTAVE: f64 = 14.0;
/// The slope of code 1, as a power of two (codes 1 to 254 span slopes from
/// 2^-17 to about 2.1 heights per cell; 0 is a horizon at or below level,
/// 255 one too steep to prove anything against).
const LOWEST_OCTAVE: f64 = -17.0;
/// Widening of each sector, radians, at the build: a direction that rounds
/// into a neighbouring sector is still inside the widened one.
const SECTOR_SLACK: f64 = 1e-3;

/// Per cell and azimuth sector, the steepest the surface rises as seen from
/// anywhere on the cell: see the module's documentation.
#[derive(Clone)]
pub struct HorizonMap {
    /// Cells across and down: the height map's texels plus one, cells `-1`
    /// and `W - 1` being the half-cells at its borders.
    cells: [usize; 2],
    /// `codes[(k * cells[1] + j) * cells[0] + i]`: sector `k` of cell
    /// `(i - 1, j - 1)`.
    codes: Vec<u8>,
    /// The square of the slope each code stands for (code 255: infinite).
    slopes2: [f32; 256],
    /// `at_most[q]`: how many of the codes are `q` or less.
    at_most: [u64; 256],
}

impl fmt::Debug for HorizonMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HorizonMap")
            .field("cells", &self.cells)
            .finish_non_exhaustive()
    }
}

/// The slope code `q` stands for.
fn code_slope(q: u8) -> f64 {
    match q {
        0 => 0.0,
        255 => f64::INFINITY,
        q => ((q as f64 - 1.0) / CODES_PER_OCTAVE + LOWEST_OCTAVE).exp2(),
    }
}

/// The slope of every code ([`code_slope`]), worked out once.
static CODE_SLOPES: LazyLock<[f64; 256]> =
    LazyLock::new(|| std::array::from_fn(|q| code_slope(q as u8)));

/// The smallest code whose slope is at least `s`.
fn encode(s: f64) -> u8 {
    if s <= 0.0 {
        return 0;
    }
    if !s.is_finite() {
        return 255;
    }
    let slopes = &*CODE_SLOPES;
    // The code from the slope's logarithm, then corrected against the
    // table (the logarithm rounds, so it is only a first guess).
    let guess = ((s.log2() - LOWEST_OCTAVE) * CODES_PER_OCTAVE + 1.0).floor();
    let mut q = guess.clamp(1.0, 255.0) as u8;
    while q < 255 && slopes[q as usize] < s {
        q += 1;
    }
    while q > 1 && slopes[q as usize - 1] >= s {
        q -= 1;
    }
    q
}

/// The unit vectors at the ends of sector `k`, widened by [`SECTOR_SLACK`].
fn sector_ends(k: usize) -> [[f64; 2]; 2] {
    let step = std::f64::consts::TAU / SECTORS as f64;
    let a0 = k as f64 * step - SECTOR_SLACK;
    let a1 = (k + 1) as f64 * step + SECTOR_SLACK;
    [[a0.cos(), a0.sin()], [a1.cos(), a1.sin()]]
}

/// Whether a ray from `start` (cell coordinates: cell `(i, j)` spans
/// `[i, i + 1) x [j, j + 1)` between texel centres) rising `rise` per cell
/// in some direction of the sector from `ends[0]` to `ends[1]` is shown to
/// meet a steeper surface, by marches along the sector's two edges and its
/// middle until they leave the cells `-1 .. cells - 1`: the surface rising
/// faster than `rise` on average between two successive points of a march,
/// or from the start to a point. Either is a lower bound of the wedge's
/// steepest derivative (the points lie in the wedge). Steps of a cell up to
/// 32 cells out, then growing by an eighth.
fn rises_past(
    height: &HeightMap,
    start: [f64; 2],
    ends: [[f64; 2]; 2],
    rise: f64,
    cells: [usize; 2],
) -> bool {
    // The surface at cell coordinates `(x, y)`: texel centre `i` is cell
    // coordinate `i`, texture coordinate `(i + 0.5) / width`.
    let at = |x: f64, y: f64| -> Option<f64> {
        let (ci, cj) = (floor_i64(x as f32), floor_i64(y as f32));
        if ci < -1 || cj < -1 || ci >= cells[0] as i64 - 1 || cj >= cells[1] as i64 - 1 {
            return None;
        }
        let u = (x + 0.5) / height.width() as f64;
        let v = (y + 0.5) / height.height() as f64;
        Some(height.sample(u as f32, v as f32) as f64)
    };
    let Some(h0) = at(start[0], start[1]) else {
        return false;
    };
    let mid = [ends[0][0] + ends[1][0], ends[0][1] + ends[1][1]];
    let len = (mid[0] * mid[0] + mid[1] * mid[1]).sqrt();
    [ends[0], [mid[0] / len, mid[1] / len], ends[1]]
        .iter()
        .any(|d| {
            let (mut t, mut h): (f64, f64) = (0.0, h0);
            loop {
                let dt = if t < 32.0 { 1.0 } else { t / 8.0 };
                let Some(next) = at(start[0] + d[0] * (t + dt), start[1] + d[1] * (t + dt)) else {
                    return false;
                };
                if next - h > rise * dt || next - h0 > rise * (t + dt) {
                    return true;
                }
                (t, h) = (t + dt, next);
            }
        })
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Whether direction `p` lies within the sector from `u0` to `u1`
/// (counter-clockwise, less than half a turn).
fn within(p: [f64; 2], [u0, u1]: [[f64; 2]; 2]) -> bool {
    cross(u0, p) >= 0.0 && cross(p, u1) >= 0.0
}

/// The largest directional derivative over sector `ends` anywhere on the
/// bilinear patch with corners `h00, h10, h01, h11` (height per cell).
fn steepest(corners: [f32; 4], ends: [[f64; 2]; 2]) -> f64 {
    let [h00, h10, h01, h11] = corners.map(f64::from);
    let (a, b, c) = (h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
    // The gradient (a + c y, b + c x) is affine in each of x and y, so the
    // derivative along a fixed direction is largest at a corner; along the
    // sector's directions, at an end or along the gradient itself.
    let mut best = f64::NEG_INFINITY;
    for (fx, fy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        let g = [a + c * fy, b + c * fx];
        let along = if within(g, ends) {
            (g[0] * g[0] + g[1] * g[1]).sqrt()
        } else {
            let [u0, u1] = ends;
            (u0[0] * g[0] + u0[1] * g[1]).max(u1[0] * g[0] + u1[1] * g[1])
        };
        best = best.max(along);
    }
    best
}

impl HorizonMap {
    /// Bytes this map holds.
    pub fn bytes(&self) -> usize {
        self.codes.len()
            + std::mem::size_of_val(&self.slopes2)
            + std::mem::size_of_val(&self.at_most)
    }

    /// The share of cells and sectors whose horizon a ray rising `slope`
    /// heights per cell clears: what a scene's shadow rays can expect of
    /// the test, which costs every ray it does not answer a few
    /// nanoseconds.
    pub fn share_cleared_at(&self, slope: f32) -> f64 {
        let code = encode(slope as f64);
        // Codes under the one `slope` rounds up to stand for slopes below it.
        let below = if code == 0 {
            0
        } else {
            self.at_most[code as usize - 1]
        };
        below as f64 / self.codes.len().max(1) as f64
    }

    /// Bytes [`Self::build`] holds at its peak for `height`: the codes, and
    /// three single-precision planes per sector in flight.
    pub fn build_peak_bytes(height: &HeightMap) -> u128 {
        let cells = (height.width() as u128 + 1) * (height.height() as u128 + 1);
        let in_flight = rayon::current_num_threads().min(SECTORS) as u128;
        cells * SECTORS as u128 + cells * 12 * in_flight
    }

    /// Whether rays rising `rise` heights per cell clear enough of the
    /// bounds ([`MIN_SHARE`]) for testing them to pay.
    pub fn pays_at(&self, rise: f32) -> bool {
        self.share_cleared_at(rise) >= MIN_SHARE
    }

    /// Whether bounds of `height` could pay for rays rising `rise` heights
    /// per cell, judged before building them from a sample of its cells
    /// (every 61st) and all their sectors. Two lower bounds of a cell's
    /// bound in a sector are read there: the derivative on each cell of its
    /// 3x3 neighbourhood, and the average rise between points of marches
    /// from the cell's centre along the sector's edges and middle to the
    /// map's edge (`rises_past`: those points lie in the cell's wedge, and
    /// between two of them the surface rises on average no faster than its
    /// derivative somewhere on the way). Where under half of [`MIN_SHARE`] of the
    /// sampled cells and sectors have both under `rise`, the built bounds
    /// would not pay either, and a busy map (a photograph, steps, noise, a
    /// floor between studs that its wedges all reach) is spared the build.
    /// Maps of at most 4096 cells are built and judged whole. A wrong guess
    /// costs speed, never an answer.
    pub fn could_pay(height: &HeightMap, rise: f32) -> bool {
        let (w, h) = (height.width() + 1, height.height() + 1);
        if w * h <= 4096 {
            // Too few cells to sample, and cheap to build and judge whole.
            return true;
        }
        let ends: [[[f64; 2]; 2]; SECTORS] = std::array::from_fn(sector_ends);
        let rise = rise as f64;
        // Enough open cells and sectors settles it before the sample ends
        // (a smooth map, whose marches run to the edge, stops early).
        let needed = 0.5 * MIN_SHARE * ((w * h).div_ceil(61) * SECTORS) as f64;
        let mut open = 0usize;
        for c in (0..w * h).step_by(61) {
            let (i, j) = ((c % w) as i64 - 1, (c / w) as i64 - 1);
            let mut steepest_near = [f64::NEG_INFINITY; SECTORS];
            for (di, dj) in (-1..=1).flat_map(|dj| (-1..=1).map(move |di| (di, dj))) {
                let (ni, nj) = (i + di, j + dj);
                if ni < -1 || nj < -1 || ni >= w as i64 - 1 || nj >= h as i64 - 1 {
                    continue;
                }
                let corners = height.cell_fast(ni, nj);
                for (k, end) in ends.iter().enumerate() {
                    steepest_near[k] = steepest_near[k].max(steepest(corners, *end));
                }
            }
            let centre = [i as f64 + 0.5, j as f64 + 0.5];
            for (k, end) in ends.iter().enumerate() {
                if steepest_near[k] < rise && !rises_past(height, centre, *end, rise, [w, h]) {
                    open += 1;
                }
            }
            if open as f64 >= needed {
                return true;
            }
        }
        false
    }

    /// The bounds of every cell of `height` (its addressing read at the
    /// border cells), or `None` for maps of more than
    /// [`MAX_HORIZON_CELLS`] cells and where the build's memory
    /// ([`Self::build_peak_bytes`]) is over a limit in force: the bounds
    /// only save time, so a map without them is traced as before.
    pub fn build(height: &HeightMap) -> Option<Self> {
        let (w, h) = (height.width() + 1, height.height() + 1);
        if w * h > MAX_HORIZON_CELLS
            || crate::memory::check("horizon bounds", Self::build_peak_bytes(height)).is_err()
        {
            return None;
        }
        // A refused allocation leaves the map without bounds, as the
        // estimate above does.
        let mut codes: Vec<u8> = crate::memory::zeroed("horizon bounds", w * h * SECTORS).ok()?;
        if rayon::current_thread_index().is_some() {
            // Inside a parallel job (a scene built by one), where waiting
            // on sectors in parallel could steal another job that asks for
            // these same bounds while they are being built.
            for (k, out) in codes.chunks_mut(w * h).enumerate() {
                sector_codes(height, w, h, k, out);
            }
        } else {
            use rayon::prelude::*;
            codes
                .par_chunks_mut(w * h)
                .enumerate()
                .for_each(|(k, out)| sector_codes(height, w, h, k, out));
        }
        let slopes2 = std::array::from_fn(|q| {
            let s = round_up(code_slope(q as u8)) as f64;
            round_up(s * s)
        });
        let mut at_most = [0u64; 256];
        for &q in &codes {
            at_most[q as usize] += 1;
        }
        for q in 1..256 {
            at_most[q] += at_most[q - 1];
        }
        Some(HorizonMap {
            cells: [w, h],
            codes,
            slopes2,
            at_most,
        })
    }

    /// Whether a ray from `(x, y, z)` along `(dx, dy, dz)`, in cell
    /// coordinates across and down (texel centres at integers) and heights,
    /// starting on or over the surface, provably stays over it: it rises
    /// more steeply than the horizon of its cell in its sector.
    #[inline]
    pub fn clears(&self, x: f32, y: f32, dx: f32, dy: f32, dz: f32) -> bool {
        if dz <= 0.0 {
            return false;
        }
        let (ci, cj) = (floor_i64(x) + 1, floor_i64(y) + 1);
        if ci < 0 || cj < 0 || ci as usize >= self.cells[0] || cj as usize >= self.cells[1] {
            return false;
        }
        let (ax, ay) = (dx.abs(), dy.abs());
        // Directions within a ten-thousandth of a radian of a sector's edge
        // are left to the trace, so that rounding never carries a ray into
        // a sector it is not bounded for.
        let (lo, hi) = if ax < ay { (ax, ay) } else { (ay, ax) };
        if (lo > 0.0 && lo < 1e-4 * hi) || hi - lo < 1e-4 * hi {
            return false;
        }
        let k = octant(dx, dy);
        let [w, h] = self.cells;
        let code = self.codes[k * w * h + cj as usize * w + ci as usize];
        // Squared, with a margin over the rounding of the ray's own length.
        dz * dz > self.slopes2[code as usize] * (dx * dx + dy * dy) * (1.0 + 1e-4)
    }
}

/// The octant of direction `(dx, dy)`, counter-clockwise from `+x`.
#[inline(always)]
fn octant(dx: f32, dy: f32) -> usize {
    let steep = dy.abs() > dx.abs();
    match (dx >= 0.0, dy >= 0.0) {
        (true, true) => steep as usize,
        (false, true) => 3 - steep as usize,
        (false, false) => 4 + steep as usize,
        (true, false) => 7 - steep as usize,
    }
}

/// `s` as single precision, rounded up.
fn round_up(s: f64) -> f32 {
    let f = s as f32;
    if (f as f64) < s {
        f.next_up()
    } else {
        f
    }
}

/// The grid steps of sector `k`'s wedge recursion: `(axis, perpendicular)`.
/// The wedge of a cell (the cell swept along the sector's directions) is
/// the cell, its neighbour across `perpendicular`, and the wedges of its
/// neighbours at `axis` and `axis + perpendicular` (worked out for the
/// first octant, `0 <= y <= x`: the wedge of the unit cell is
/// `x >= 0, 0 <= y <= x + 1`, and those of the cells at `(1, 0)` and
/// `(1, 1)` cover all of it with `x >= 1`; the others by symmetry).
fn sector_steps(k: usize) -> ([i64; 2], [i64; 2]) {
    match k {
        0 => ([1, 0], [0, 1]),
        1 => ([0, 1], [1, 0]),
        2 => ([0, 1], [-1, 0]),
        3 => ([-1, 0], [0, 1]),
        4 => ([-1, 0], [0, -1]),
        5 => ([0, -1], [-1, 0]),
        6 => ([0, -1], [1, 0]),
        _ => ([1, 0], [0, -1]),
    }
}

/// Sector `k`'s codes for every cell: the steepest derivative along the
/// sector's directions over the cell's wedge, then over the wedges of its
/// 3x3 neighbourhood, rounded up.
fn sector_codes(height: &HeightMap, w: usize, h: usize, k: usize, out: &mut [u8]) {
    let ends = sector_ends(k);
    let mut own = vec![0.0f32; w * h];
    for (c, v) in own.iter_mut().enumerate() {
        let (i, j) = ((c % w) as i64 - 1, (c / w) as i64 - 1);
        *v = round_up(steepest(height.cell_fast(i, j), ends));
    }
    let (axis, side) = sector_steps(k);
    let diagonal = [axis[0] + side[0], axis[1] + side[1]];
    let at = |v: &[f32], i: i64, j: i64| -> f32 {
        if i < 0 || j < 0 || i >= w as i64 || j >= h as i64 {
            f32::NEG_INFINITY
        } else {
            v[j as usize * w + i as usize]
        }
    };
    // Lines of cells across the axis, the farthest along it first: each
    // cell's wedge needs those of the next line.
    let mut wedge = vec![f32::NEG_INFINITY; w * h];
    let (lines, across) = if axis[0] != 0 { (w, h) } else { (h, w) };
    for n in 0..lines as i64 {
        let line = if axis[0] + axis[1] > 0 {
            lines as i64 - 1 - n
        } else {
            n
        };
        for m in 0..across as i64 {
            let (i, j) = if axis[0] != 0 { (line, m) } else { (m, line) };
            let v = at(&own, i, j)
                .max(at(&own, i + side[0], j + side[1]))
                .max(at(&wedge, i + axis[0], j + axis[1]))
                .max(at(&wedge, i + diagonal[0], j + diagonal[1]));
            wedge[j as usize * w + i as usize] = v;
        }
    }
    // Over the 3x3 neighbourhood: rows (into `own`, no longer needed),
    // then columns.
    for j in 0..h as i64 {
        for i in 0..w as i64 {
            own[j as usize * w + i as usize] =
                at(&wedge, i - 1, j)
                    .max(at(&wedge, i, j))
                    .max(at(&wedge, i + 1, j));
        }
    }
    for j in 0..h as i64 {
        for i in 0..w as i64 {
            let v = at(&own, i, j - 1)
                .max(at(&own, i, j))
                .max(at(&own, i, j + 1));
            out[j as usize * w + i as usize] = encode(v as f64);
        }
    }
}
