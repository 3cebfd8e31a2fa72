//! The shell of one triangle of a curved displaced mesh: the volume its
//! displaced surface `S = P + depth h(uv) N` can occupy, and the mapping
//! between that volume and the triangle's texture space.
//!
//! Both source documents leave curved surfaces as future work: Donnelly
//! (GPU Gems 2, section 8.7) treats the surface under each fragment as
//! locally flat and notes that this "results in distortion in regions of
//! high curvature"; the ray-tracer paper's prisms (its section 2.4) are
//! extruded along the flat face normal, so neighbouring prisms of a smooth
//! mesh neither meet nor follow the interpolated normals. Here a triangle
//! with corners `P_i` and unit vertex normals `N_i` is extruded along the
//! *unnormalised* interpolated normal `N(b) = sum b_i N_i`:
//!
//! ```text
//! X(b, lambda) = P(b) + lambda N(b),   b in the triangle, lambda in [0, top]
//! ```
//!
//! For a fixed `lambda` that is the flat triangle with corners
//! `P_i + lambda N_i`, so the shell is bounded by two flat triangles (the
//! base, `lambda = 0`, and the top) and by three bilinear patches, one over
//! each edge, ruled by the lines `P(s) + lambda N(s)`. A side depends only
//! on its edge's two corners and normals, so two triangles that share an
//! edge (positions and normals) share its side bit for bit: the shells of
//! a smooth mesh tile space without gaps or overlaps (the "shell mapping"
//! of Porumbescu et al. 2005 and Jeschke, Mantler and Wimmer 2007, with
//! bilinear sides).
//!
//! Along each line of the column the normalised normal is the line's own
//! direction, so the point `P(b) + depth w N(b)/|N(b)|` of `S` at height
//! `w` sits at `lambda = depth w / |N(b)|`: a point of the shell has the
//! map coordinates `(uv(b), w)` with `w = lambda |N(b)| / depth`, and the
//! displaced surface is exactly `w = h(uv(b))`, the height field of the
//! planar case in curved coordinates. `|N(b)|^2 = sum b_i b_j N_i . N_j`
//! is at least the smallest `N_i . N_j`, so a top at
//! `depth / sqrt(min N_i . N_j)` holds every height up to 1
//! ([`lambda_for_depth`]).
//!
//! Finding `(b, lambda)` for a world point is a cubic in `lambda`: the point
//! lies in the plane of the level-`lambda` triangle when
//! `det[X - P_0 - lambda N_0, E_1 + lambda F_1, E_2 + lambda F_2] = 0`
//! (`E_k = P_k - P_0`, `F_k = N_k - N_0`), after which `b` is a 2x2 solve.
//! All of it runs in double precision: the cubic's leading terms are small
//! on gently curved meshes.

use glam::{DVec2, DVec3, Vec3};

/// Where a world point sits in a shell: barycentric `(b1, b2)` (the first
/// corner's weight is `1 - b1 - b2`), the level `lambda` along the
/// unnormalised interpolated normal, and the height `w` in depths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// Barycentric weights of corners 1 and 2.
    pub b: DVec2,
    /// Distance along `N(b)` in units of `|N(b)|`.
    pub lambda: f64,
    /// Height above the base in shell depths: `lambda |N(b)| / depth`.
    pub w: f64,
}

/// Which part of a shell's boundary a ray crosses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// The base triangle (`lambda = 0`).
    Base,
    /// The top triangle (`lambda = top`).
    Top,
    /// The bilinear side over edge `k` (corners `k` and `k + 1 mod 3`).
    Side(usize),
}

/// A ray crossing a shell's boundary: where and through what. Its normal
/// ([`CurvedShell::crossing_normal`]) is worked out only for the crossings
/// a ray hits as a wall, which few are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Ray parameter.
    pub t: f64,
    /// The boundary crossed.
    pub boundary: Boundary,
    /// On a side, the edge parameter `s` and the level `mu` of the
    /// crossing (zero on the base and the top).
    at: (f64, f64),
}

/// The shell of one curved triangle (module docs), in double precision.
#[derive(Clone, Copy, Debug)]
pub struct CurvedShell {
    p: [DVec3; 3],
    n: [DVec3; 3],
    /// `E_1, E_2`.
    e: [DVec3; 2],
    /// `F_1, F_2`.
    f: [DVec3; 2],
    /// `(E_1 + l F_1) x (E_2 + l F_2) = c0 + l c1 + l^2 c2`.
    c: [DVec3; 3],
    depth: f64,
    top: f64,
    /// Supporting planes of the six corners' hull (`n . x <= c` inside),
    /// at most ten: a cheap test before the crossings ([`CurvedShell::admits`]).
    hull: [(DVec3, f64); 10],
    hull_planes: usize,
}

/// The smallest length `|N(b)|` the interpolated normal of unit normals
/// `n` can take over the triangle, bounded below by the square root of
/// their smallest pairwise dot product (`|N(b)|^2` is a convex combination
/// of the dot products); `None` when two normals are 90 degrees or more
/// apart, where the interpolated normal can vanish and the shell fold.
pub fn min_normal_length(n: &[Vec3; 3]) -> Option<f64> {
    if n.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let m = least_dot(&n.map(|v| v.as_dvec3()));
    (m > 0.0).then(|| m.sqrt())
}

/// The smallest pairwise dot product of three normals, whose square root
/// bounds `|N(b)|` below ([`min_normal_length`]).
fn least_dot(n: &[DVec3; 3]) -> f64 {
    n[0].dot(n[1]).min(n[1].dot(n[2])).min(n[2].dot(n[0]))
}

/// Whether the shell over corners `p` with unit normals `n`, topped at
/// `top`, folds over itself: where a triangle's normals converge (the
/// concave side of a curved mesh) faster than the shell is thick, its
/// levels turn inside out and one point of space lies at two places of the
/// shell, two heights at once, so no trace of it can be right. Such a
/// triangle keeps the flat prism ([`crate::mesh_shells`]).
pub fn shell_folds(p: &[Vec3; 3], n: &[Vec3; 3], top: f64) -> bool {
    let (_, n, _, _, c) = frame(p, n);
    folds(&n, &c, top)
}

/// The corners `p` and unit normals `n` in double precision, the edges
/// `e` and normal differences `f` from corner 0, and the coefficients `c`
/// of a level's triangle normal `c0 + l c1 + l^2 c2` (`(e0 + l f0) x (e1 +
/// l f1)`): what [`CurvedShell::new`] keeps and [`shell_folds`] checks, and
/// what a tracer that locates points in vector lanes reads.
#[allow(clippy::type_complexity)]
pub fn frame(
    p: &[Vec3; 3],
    n: &[Vec3; 3],
) -> ([DVec3; 3], [DVec3; 3], [DVec3; 2], [DVec3; 2], [DVec3; 3]) {
    let p = p.map(|v| v.as_dvec3());
    let n = n.map(|v| v.as_dvec3().normalize());
    let e = [p[1] - p[0], p[2] - p[0]];
    let f = [n[1] - n[0], n[2] - n[0]];
    let c = [
        e[0].cross(e[1]),
        e[0].cross(f[1]) + f[0].cross(e[1]),
        f[0].cross(f[1]),
    ];
    (p, n, e, f, c)
}

/// [`shell_folds`] from the unit normals and the coefficients `c` of the
/// level's triangle normal `c0 + l c1 + l^2 c2`. The map `(b, l) -> P(b) +
/// l N(b)` has Jacobian determinant `N(b) . (c0 + l c1 + l^2 c2)`, linear
/// in `b` at each level, so at its extremes at a corner: the shell is
/// folded unless each corner's quadratic in `l` keeps one strict sign on
/// `[0, top]` (checked at both ends and at its vertex), the same for all
/// three (either sign: the triangle's winding need not follow its normals).
fn folds(n: &[DVec3; 3], c: &[DVec3; 3], top: f64) -> bool {
    let (mut least, mut most) = (f64::INFINITY, f64::NEG_INFINITY);
    for nk in n {
        let (a0, a1, a2) = (nk.dot(c[0]), nk.dot(c[1]), nk.dot(c[2]));
        let q = |l: f64| a0 + l * (a1 + l * a2);
        let vertex = if a2 != 0.0 { -a1 / (2.0 * a2) } else { -1.0 };
        for l in [0.0, top, vertex] {
            if (0.0..=top).contains(&l) {
                least = least.min(q(l));
                most = most.max(q(l));
            }
        }
    }
    !(least > 0.0 || most < 0.0)
}

/// The top level `lambda` a shell needs so that every height up to 1 lies
/// under it, for a mesh whose triangles' [`min_normal_length`] is at least
/// `min_length`: shells that share sides must share it, so a mesh uses one.
pub fn lambda_for_depth(depth: f64, min_length: f64) -> f64 {
    // A hair over the bound, so the surface at height 1 is never cut by
    // the top's rounding.
    depth / min_length * (1.0 + 1e-9)
}

/// Supporting planes `(n, c)` (inside: `n . x <= c`) of the hull of a
/// shell's six corners: every plane through three corners of the base, of
/// the top or of one side that has all six on its inner side, pushed out by
/// a hair of the corners' scale. Each kept plane bounds the hull whether or
/// not it is one of its facets, so the test stays conservative.
fn hull_planes(p: &[DVec3; 3], n: &[DVec3; 3], top: f64) -> ([(DVec3, f64); 10], usize) {
    let q: [DVec3; 6] = [
        p[0],
        p[1],
        p[2],
        p[0] + top * n[0],
        p[1] + top * n[1],
        p[2] + top * n[2],
    ];
    let centre = q.iter().copied().sum::<DVec3>() / 6.0;
    let scale = q
        .iter()
        .map(|v| v.abs().max_element())
        .fold(0.0, f64::max)
        .max(1e-300);
    let size = q.iter().map(|v| (*v - centre).length()).fold(0.0, f64::max);
    let mut out = [(DVec3::ZERO, 0.0f64); 10];
    let mut count = 0;
    // The base and the top, then the sides' planes in turn, so that every
    // side has one in before the array is full.
    let side = |m: usize, k: usize| {
        let (i, j) = (k, (k + 1) % 3);
        [
            [i, j, 3 + j],
            [i, 3 + j, 3 + i],
            [i, j, 3 + i],
            [j, 3 + j, 3 + i],
        ][m]
    };
    let sides = (0..4).flat_map(|m| (0..3).map(move |k| side(m, k)));
    for [a, b, c] in [[0, 1, 2], [3, 4, 5]].into_iter().chain(sides) {
        let normal = (q[b] - q[a]).cross(q[c] - q[a]);
        let len = normal.length();
        if len.is_nan() || len <= 1e-12 * size * size {
            continue;
        }
        let mut normal = normal / len;
        if normal.dot(centre - q[a]) > 0.0 {
            normal = -normal;
        }
        let pad = 1e-9 * (scale + size);
        let offset = normal.dot(q[a]) + pad;
        if !q.iter().all(|v| normal.dot(*v) <= offset) {
            continue;
        }
        // A side whose four corners lie in one plane (every side of a
        // sphere's shells) gives that plane four times: keep it once, at
        // the tighter offset, or the duplicates fill the array and leave a
        // side out of the hull.
        if let Some(kept) = out[..count]
            .iter_mut()
            .find(|(n, _)| n.dot(normal) > 1.0 - 1e-12)
        {
            kept.1 = kept.1.min(offset);
        } else if count < out.len() {
            out[count] = (normal, offset);
            count += 1;
        }
    }
    (out, count)
}

fn det(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    a.dot(b.cross(c))
}

impl CurvedShell {
    /// The shell over corners `p` with unit normals `n`, `depth` world
    /// units per height 1, topped at `top` ([`lambda_for_depth`]); `None`
    /// for a degenerate triangle or normals that cannot carry a shell
    /// ([`min_normal_length`], [`shell_folds`]).
    pub fn new(p: [Vec3; 3], n: [Vec3; 3], depth: f32, top: f64) -> Option<Self> {
        min_normal_length(&n)?;
        let (p, n, e, f, c) = frame(&p, &n);
        let area = c[0].length();
        if !(area > 0.0 && area.is_finite() && depth > 0.0 && top > 0.0) {
            return None;
        }
        if folds(&n, &c, top) {
            return None;
        }
        let (hull, hull_planes) = hull_planes(&p, &n, top);
        Some(Self {
            p,
            n,
            e,
            f,
            c,
            depth: depth as f64,
            top,
            hull,
            hull_planes,
        })
    }

    /// Whether the ray `o + t d` may meet the shell for `t` in `[t_min,
    /// t_max]`: false when it misses the hull of the six corners, which
    /// holds the shell (a point `P(b) + l N(b)` is a convex combination of
    /// the corners `P_i + l N_i` of its level, each one of `P_i` and `P_i +
    /// top N_i`). A BVH's boxes around the thin, slanted shells of a curved
    /// mesh overlap; this drops most of the shells a box admits before
    /// their five crossings are solved.
    pub fn admits(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> bool {
        self.hull_span(o, d, t_min, t_max).is_some()
    }

    /// The part of `[t_min, t_max]` where the ray `o + t d` is inside the
    /// hull of the six corners ([`CurvedShell::admits`]), `None` where it
    /// misses it: outside that span the ray is outside the shell, which a
    /// tracer then knows without locating a point there.
    pub fn hull_span(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (t_min, t_max);
        for &(n, c) in &self.hull[..self.hull_planes] {
            let f0 = n.dot(o) - c;
            let fd = n.dot(d);
            if fd == 0.0 {
                if f0 > 0.0 {
                    return None;
                }
                continue;
            }
            let t = -f0 / fd;
            if fd < 0.0 {
                lo = lo.max(t);
            } else {
                hi = hi.min(t);
            }
            if lo > hi {
                return None;
            }
        }
        Some((lo, hi))
    }

    /// The same shell cut down to the levels that can hold heights up to
    /// `height` (depths): its own top where that is lower. A point at
    /// height `w` sits at level `depth w / |N(b)|`, at most `depth w /
    /// min |N|` ([`min_normal_length`]), so the cut shell holds the
    /// surface wherever the heights over its triangle stay under `height`,
    /// and the space it leaves out lies above the surface. Its sides are
    /// the same ruled surfaces, only shorter, so a neighbour's shell still
    /// continues the surface across them. Projective Displacement Mapping
    /// (Hoetzlein 2025) bounds each prism by its own height range the same
    /// way; a CPU ray admitted by a shell's box wastes its crossings where
    /// it passes over the local heights.
    pub fn topped_at(&self, height: f64) -> Self {
        let least = least_dot(&self.n);
        // Never thinner than a hundredth of the full shell: the crossings
        // and the hull stay well conditioned over a flat patch.
        let height = height.clamp(0.01, 1.0);
        let top = lambda_for_depth(self.depth * height, least.sqrt()).min(self.top);
        if !(top > 0.0 && top < self.top) {
            return *self;
        }
        let (hull, hull_planes) = hull_planes(&self.p, &self.n, top);
        Self {
            top,
            hull,
            hull_planes,
            ..*self
        }
    }

    /// The top level of the shell.
    pub fn top(&self) -> f64 {
        self.top
    }

    /// The six corners of the shell (base, then top), which bound it: the
    /// sides are bilinear patches, inside the hull of their corners.
    pub fn corners(&self) -> [DVec3; 6] {
        let t = self.top;
        [
            self.p[0],
            self.p[1],
            self.p[2],
            self.p[0] + t * self.n[0],
            self.p[1] + t * self.n[1],
            self.p[2] + t * self.n[2],
        ]
    }

    /// The interpolated, unnormalised normal `N(b)`.
    pub fn normal_at(&self, b: DVec2) -> DVec3 {
        self.n[0] + b.x * self.f[0] + b.y * self.f[1]
    }

    /// The world point at barycentric `b` and height `w` (depths): `P(b) +
    /// depth w N(b)/|N(b)|`, a point of `S` when `w = h(uv(b))`.
    pub fn point(&self, b: DVec2, w: f64) -> DVec3 {
        let n = self.normal_at(b);
        self.p[0] + b.x * self.e[0] + b.y * self.e[1] + (self.depth * w / n.length()) * n
    }

    /// The coefficients of `det[x - P_0 - l N_0, E_1 + l F_1, E_2 + l
    /// F_2]`, lowest power first.
    fn cubic(&self, x: DVec3) -> [f64; 4] {
        let r = x - self.p[0];
        let n0 = self.n[0];
        let [c0, c1, c2] = self.c;
        [
            r.dot(c0),
            r.dot(c1) - n0.dot(c0),
            r.dot(c2) - n0.dot(c1),
            -n0.dot(c2),
        ]
    }

    /// `b` of world point `x` on level `lambda` (the plane of the
    /// level-`lambda` triangle is assumed to hold `x`).
    fn barycentric(&self, x: DVec3, lambda: f64) -> Option<DVec2> {
        let a = x - self.p[0] - lambda * self.n[0];
        let b1 = self.e[0] + lambda * self.f[0];
        let b2 = self.e[1] + lambda * self.f[1];
        let n = b1.cross(b2);
        let nn = n.dot(n);
        if nn.is_nan() || nn <= 0.0 {
            return None;
        }
        Some(DVec2::new(a.cross(b2).dot(n), b1.cross(a).dot(n)) / nn)
    }

    /// The shell coordinates of world point `x` on level `lambda`.
    fn at_level(&self, x: DVec3, lambda: f64) -> Option<Located> {
        Some(self.located(self.barycentric(x, lambda)?, lambda))
    }

    /// The shell coordinates at barycentric `b` and level `lambda`, with
    /// the height they give.
    fn located(&self, b: DVec2, lambda: f64) -> Located {
        let w = lambda * self.normal_at(b).length() / self.depth;
        Located { b, lambda, w }
    }

    /// How far `b` and `lambda` lie outside the shell's ranges (0 inside):
    /// the larger of the barycentric overshoot and the level's, in
    /// barycentric units and units of `top`.
    pub fn outside(&self, loc: &Located) -> f64 {
        let b0 = 1.0 - loc.b.x - loc.b.y;
        let bary = (-loc.b.x).max(-loc.b.y).max(-b0).max(0.0);
        let level = (-loc.lambda).max(loc.lambda - self.top).max(0.0) / self.top;
        bary.max(level)
    }

    /// The shell coordinates of world point `x`: of the roots of the cubic
    /// near the shell's levels, the one inside the shell (or least outside
    /// it), nearest `hint` among equals. `None` where no level's plane
    /// holds `x` near the shell.
    ///
    /// Newton's method comes first, from the level that the distance to
    /// the base plane gives (below); every root of the cubic is isolated
    /// only when that does not settle inside the shell.
    pub fn locate(&self, x: DVec3, hint: f64) -> Option<Located> {
        let k = self.cubic(x);
        // The distance to the base plane, `(x - P_0) . c0 = l sum_i b_i
        // (c0 . N_i)`, gives the level through the mean of the `c0 . N_i`
        // (the slices of Projective Displacement Mapping, Hoetzlein 2025):
        // on a smooth mesh they differ by thousandths, and one Newton step
        // from there is usually the last.
        let scale = self.c[0].dot(self.n[0] + self.n[1] + self.n[2]) / 3.0;
        let guess = k[0] / scale;
        let mut lambda = if guess.is_finite() { guess } else { hint };
        for _ in 0..8 {
            let f = ((k[3] * lambda + k[2]) * lambda + k[1]) * lambda + k[0];
            let df = (3.0 * k[3] * lambda + 2.0 * k[2]) * lambda + k[1];
            if df == 0.0 || !df.is_finite() {
                break;
            }
            let step = f / df;
            lambda -= step;
            // Newton's error squares with each step: after a step of
            // 1e-7 tops the level is within about 1e-14 tops.
            if step.abs() <= 1e-7 * self.top {
                if let Some(loc) = self.at_level(x, lambda) {
                    if self.outside(&loc) <= 1e-3 {
                        return Some(loc);
                    }
                }
                break;
            }
        }
        let (lo, hi) = (-0.5 * self.top, 1.5 * self.top);
        let mut best: Option<(f64, f64, Located)> = None;
        for lambda in real_roots(k, lo, hi) {
            let Some(loc) = self.at_level(x, lambda) else {
                continue;
            };
            let out = self.outside(&loc);
            let near = (lambda - hint).abs();
            let better = match &best {
                None => true,
                Some((o, d, _)) => out < *o - 1e-12 || (out <= *o + 1e-12 && near < *d),
            };
            if better {
                best = Some((out, near, loc));
            }
        }
        best.map(|(_, _, loc)| loc)
    }

    /// Whether `loc` lies in the shell, within `tol` (barycentric units and
    /// fractions of the top).
    pub fn contains(&self, loc: &Located, tol: f64) -> bool {
        self.outside(loc) <= tol
    }

    /// Every crossing of the ray `o + t d` with the shell's boundary for
    /// `t` in `(t_min, t_max)`, unsorted: at most eight (the base, the top,
    /// two per side), the first `count` of the array.
    pub fn crossings(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> ([Crossing; 8], usize) {
        let none = Crossing {
            t: f64::INFINITY,
            boundary: Boundary::Base,
            at: (0.0, 0.0),
        };
        let mut out = [none; 8];
        let mut count = 0;
        let mut push = |c: Crossing| {
            if c.t > t_min && c.t < t_max && count < 8 {
                out[count] = c;
                count += 1;
            }
        };
        let top = self.top;
        let lifted = [0, 1, 2].map(|i| self.p[i] + top * self.n[i]);
        for (corners, boundary) in [(self.p, Boundary::Base), (lifted, Boundary::Top)] {
            if let Some(t) = ray_triangle(o, d, corners) {
                push(Crossing {
                    t,
                    boundary,
                    at: (0.0, 0.0),
                });
            }
        }
        // `d x N_i`, from which `d x B(s)` of every side is linear in `s`.
        let dn = self.n.map(|n| d.cross(n));
        for k in 0..3 {
            let (i, j) = (k, (k + 1) % 3);
            let (a0, a1) = (self.p[i] - o, self.p[j] - self.p[i]);
            let b1 = self.n[j] - self.n[i];
            let (g0, g1) = (dn[i], dn[j] - dn[i]);
            // The ray meets the ruling at `s` when (A(s) - o) . (d x B(s)) = 0.
            let q0 = a0.dot(g0);
            let q1 = a1.dot(g0) + a0.dot(g1);
            let q2 = a1.dot(g1);
            for s in quadratic_roots(q2, q1, q0) {
                if !(-1e-12..=1.0 + 1e-12).contains(&s) {
                    continue;
                }
                let b = self.n[i] + s * b1;
                let dxb = g0 + s * g1;
                let den = dxb.dot(dxb);
                if den.is_nan() || den <= 0.0 {
                    continue;
                }
                let r = a0 + s * a1;
                let t = r.cross(b).dot(dxb) / den;
                if !(t > t_min && t < t_max) {
                    continue;
                }
                let mu = r.dot(d.cross(dxb)) / den;
                if !(mu >= -1e-12 * top && mu <= top * (1.0 + 1e-12)) {
                    continue;
                }
                push(Crossing {
                    t,
                    boundary: Boundary::Side(k),
                    at: (s, mu),
                });
            }
        }
        (out, count)
    }

    /// The shell coordinates of crossing `c`, at world point `x` on it:
    /// from the level alone on the base and the top, and with no solve at
    /// all on a side, whose crossing knows its edge parameter and level.
    /// What a tracer locates at each end of a stretch, for less than
    /// [`CurvedShell::locate`]. `None` where those coordinates do not give
    /// back `x` to within a billionth of the shell's scale: a ray that
    /// grazes a side meets it at an edge parameter that is ill-conditioned
    /// though its `t` is not, and only [`CurvedShell::locate`] finds that
    /// point's coordinates.
    pub fn locate_crossing(&self, c: &Crossing, x: DVec3) -> Option<Located> {
        let loc = match c.boundary {
            Boundary::Base => self.at_level(x, 0.0)?,
            Boundary::Top => self.at_level(x, self.top)?,
            Boundary::Side(k) => {
                let (s, lambda) = c.at;
                let b = match k {
                    0 => DVec2::new(s, 0.0),
                    1 => DVec2::new(1.0 - s, s),
                    _ => DVec2::new(0.0, 1.0 - s),
                };
                self.located(b, lambda)
            }
        };
        let (b, lambda) = (loc.b, loc.lambda);
        let back = self.p[0] + b.x * self.e[0] + b.y * self.e[1] + lambda * self.normal_at(b);
        let scale = self.p[0].abs().max_element() + self.e[0].length() + self.top;
        let off = (back - x).length();
        if off.is_nan() || off > 1e-9 * scale {
            return None;
        }
        Some(loc)
    }

    /// The unit normal of the boundary at crossing `c` of a ray along `d`,
    /// turned to face the ray's origin side.
    pub fn crossing_normal(&self, c: &Crossing, d: DVec3) -> DVec3 {
        let n = match c.boundary {
            Boundary::Base => self.c[0],
            Boundary::Top => {
                let l = self.top;
                (self.e[0] + l * self.f[0]).cross(self.e[1] + l * self.f[1])
            }
            Boundary::Side(k) => {
                let (i, j) = (k, (k + 1) % 3);
                let (s, mu) = c.at;
                let b1 = self.n[j] - self.n[i];
                (self.p[j] - self.p[i] + mu * b1).cross(self.n[i] + s * b1)
            }
        };
        facing(n, d)
    }

    /// The columns `dX/dx, dX/dy, dX/dz` of the mapping from map space
    /// (`x, y` the texture coordinate in map units through `to_bary`, the
    /// inverse of the texture triangle's edge matrix; `z = w`) to the
    /// world at `(b, w)`: what carries map-space normals to the world
    /// (by its inverse transpose).
    pub fn jacobian(&self, b: DVec2, w: f64, to_bary: [[f64; 2]; 2]) -> [DVec3; 3] {
        let n = self.normal_at(b);
        let len = n.length();
        let nh = n / len;
        let dx = |k: usize| {
            let dn = (self.f[k] - nh * nh.dot(self.f[k])) / len;
            self.e[k] + self.depth * w * dn
        };
        let (db1, db2) = (dx(0), dx(1));
        [
            db1 * to_bary[0][0] + db2 * to_bary[1][0],
            db1 * to_bary[0][1] + db2 * to_bary[1][1],
            self.depth * nh,
        ]
    }
}

/// The world normal of map-space normal `n` under a mapping with columns
/// `j` (its inverse transpose, up to scale), unit.
pub fn normal_to_world(j: &[DVec3; 3], n: DVec3) -> DVec3 {
    let (c0, c1, c2) = (j[0], j[1], j[2]);
    let sign = det(c0, c1, c2).signum();
    ((n.x * c1.cross(c2) + n.y * c2.cross(c0) + n.z * c0.cross(c1)) * sign).normalize()
}

/// `n` turned against `d` (the side a ray through it comes from), unit.
fn facing(n: DVec3, d: DVec3) -> DVec3 {
    let n = n.normalize();
    if n.dot(d) > 0.0 {
        -n
    } else {
        n
    }
}

/// Möller-Trumbore in double precision, edges included: the ray parameter.
fn ray_triangle(o: DVec3, d: DVec3, c: [DVec3; 3]) -> Option<f64> {
    let (e1, e2) = (c[1] - c[0], c[2] - c[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - c[0];
    let b1 = s.dot(p) * inv;
    let q = s.cross(e1);
    let b2 = d.dot(q) * inv;
    let eps = 1e-12;
    if b1 < -eps || b2 < -eps || b1 + b2 > 1.0 + eps {
        return None;
    }
    Some(e2.dot(q) * inv)
}

/// Real roots of `a x^2 + b x + c` (a linear or constant one when `a`
/// vanishes against the others), by the stable form.
fn quadratic_roots(a: f64, b: f64, c: f64) -> impl Iterator<Item = f64> {
    let mut out = [f64::NAN; 2];
    let scale = a.abs().max(b.abs()).max(c.abs());
    if scale == 0.0 || !scale.is_finite() {
        // No equation: no roots.
    } else if a.abs() <= 1e-14 * scale {
        if b != 0.0 {
            out[0] = -c / b;
        }
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc >= 0.0 {
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            if q != 0.0 {
                out[0] = q / a;
                out[1] = c / q;
            } else {
                out[0] = 0.0;
            }
        }
    }
    out.into_iter().filter(|x: &f64| x.is_finite())
}

/// The real roots in `[lo, hi]` of the cubic with coefficients `k`
/// (lowest power first): the interval cut where the derivative vanishes
/// into monotone pieces, and each piece whose ends differ in sign solved
/// by Newton's method kept inside its bracket (bisection when a step would
/// leave it).
pub fn real_roots(k: [f64; 4], lo: f64, hi: f64) -> impl Iterator<Item = f64> {
    let f = |x: f64| ((k[3] * x + k[2]) * x + k[1]) * x + k[0];
    let df = |x: f64| (3.0 * k[3] * x + 2.0 * k[2]) * x + k[1];
    let mut cuts = [lo, hi, hi, hi];
    let mut m = 1;
    let mut crit: Vec<f64> = quadratic_roots(3.0 * k[3], 2.0 * k[2], k[1])
        .filter(|x| *x > lo && *x < hi)
        .collect();
    crit.sort_by(f64::total_cmp);
    for c in crit {
        cuts[m] = c;
        m += 1;
    }
    cuts[m] = hi;
    let mut roots = [f64::NAN; 3];
    for p in 0..m {
        let (mut a, mut b) = (cuts[p], cuts[p + 1]);
        let (mut fa, fb) = (f(a), f(b));
        if fa == 0.0 {
            roots[p] = a;
            continue;
        }
        if fb == 0.0 {
            roots[p] = b;
            continue;
        }
        if (fa > 0.0) == (fb > 0.0) {
            continue;
        }
        let mut x = 0.5 * (a + b);
        for _ in 0..100 {
            let fx = f(x);
            if fx == 0.0 {
                break;
            }
            if (fx > 0.0) == (fa > 0.0) {
                a = x;
                fa = fx;
            } else {
                b = x;
            }
            let d = df(x);
            let newton = x - fx / d;
            let next = if d != 0.0 && newton > a && newton < b {
                newton
            } else {
                0.5 * (a + b)
            };
            if (next - x).abs() <= 1e-15 * (1.0 + x.abs()) {
                x = next;
                break;
            }
            x = next;
        }
        roots[p] = x;
    }
    roots.into_iter().filter(|x: &f64| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A triangle on a sphere of radius `r` about the origin, its normals
    /// the sphere's, outward or (the concave side) inward.
    fn on_sphere(r: f32, inward: bool, flip_winding: bool) -> ([Vec3; 3], [Vec3; 3]) {
        let mut dirs = [
            Vec3::new(0.1, 0.1, 1.0).normalize(),
            Vec3::new(0.4, 0.1, 1.0).normalize(),
            Vec3::new(0.1, 0.4, 1.0).normalize(),
        ];
        if flip_winding {
            dirs.swap(1, 2);
        }
        let sign = if inward { -1.0 } else { 1.0 };
        (dirs.map(|d| d * r), dirs.map(|d| d * sign))
    }

    #[test]
    fn shells_thicker_than_a_concave_curvature_fold() {
        for flip in [false, true] {
            // Outward normals diverge: no thickness folds the shell.
            let (p, n) = on_sphere(1.0, false, flip);
            assert!(!shell_folds(&p, &n, 5.0));
            // Inward, the levels shrink to a point at the centre, a
            // radius in: thinner is a shell, thicker folds.
            let (p, n) = on_sphere(1.0, true, flip);
            assert!(!shell_folds(&p, &n, 0.9));
            assert!(shell_folds(&p, &n, 1.1));
            assert!(CurvedShell::new(p, n, 0.5, 1.1).is_none());
            assert!(CurvedShell::new(p, n, 0.5, 0.9).is_some());
        }
    }

    fn bent() -> CurvedShell {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let n = [
            Vec3::new(-0.2, -0.1, 1.0).normalize(),
            Vec3::new(0.3, 0.0, 1.0).normalize(),
            Vec3::new(0.0, 0.25, 1.0).normalize(),
        ];
        let top = lambda_for_depth(0.2, min_normal_length(&n).unwrap());
        CurvedShell::new(p, n, 0.2, top).unwrap()
    }

    #[test]
    fn cubic_roots_are_found_in_their_interval() {
        // (x - 1)(x - 2)(x + 3) = x^3 - 7x + 6.
        let mut r: Vec<f64> = real_roots([6.0, -7.0, 0.0, 1.0], -10.0, 10.0).collect();
        r.sort_by(f64::total_cmp);
        assert_eq!(r.len(), 3);
        for (a, b) in r.iter().zip([-3.0, 1.0, 2.0]) {
            assert!((a - b).abs() < 1e-12, "{r:?}");
        }
        // A nearly linear cubic, as on a gently curved mesh.
        let r: Vec<f64> = real_roots([-0.5, 1.0, 1e-9, 1e-12], -1.0, 2.0).collect();
        assert_eq!(r.len(), 1);
        assert!((r[0] - 0.5).abs() < 1e-9);
    }

    #[test]
    fn locate_inverts_point() {
        let s = bent();
        for i in 0..=10 {
            for j in 0..=(10 - i) {
                for w in [0.0, 0.3, 1.0] {
                    let b = DVec2::new(i as f64 / 10.0, j as f64 / 10.0);
                    let x = s.point(b, w);
                    let loc = s.locate(x, 0.0).unwrap();
                    assert!((loc.b - b).length() < 1e-9, "{b} {loc:?}");
                    assert!((loc.w - w).abs() < 1e-9, "{w} {loc:?}");
                    assert!(s.contains(&loc, 1e-9));
                }
            }
        }
    }

    #[test]
    fn a_cut_shell_holds_every_height_under_its_cut() {
        let s = bent();
        let cut = s.topped_at(0.4);
        assert!(cut.top() < 0.5 * s.top(), "{} of {}", cut.top(), s.top());
        let mut above = 0;
        for i in 0..=10 {
            for j in 0..=(10 - i) {
                let b = DVec2::new(i as f64 / 10.0, j as f64 / 10.0);
                for w in [0.0, 0.2, 0.4] {
                    let loc = cut.locate(s.point(b, w), 0.0).unwrap();
                    assert!(cut.contains(&loc, 1e-9), "{b} {w} {loc:?}");
                }
                // Well over the cut is out of the cut shell, and in the
                // whole one.
                let loc = cut.locate(s.point(b, 0.6), 0.0).unwrap();
                above += usize::from(!cut.contains(&loc, 1e-9));
                assert!(s.contains(&s.locate(s.point(b, 0.6), 0.0).unwrap(), 1e-9));
            }
        }
        assert_eq!(above, 66);
        // The hull shrinks with it: a ray over the cut misses.
        let o = s.point(DVec2::new(0.3, 0.3), 0.8);
        assert!(s.admits(o - DVec3::X, DVec3::X, 0.0, 2.0));
        assert!(!cut.admits(o - DVec3::X, DVec3::X, 0.0, 2.0));
        // Never above the whole shell, nor thinner than a hundredth of it.
        assert_eq!(s.topped_at(2.0).top(), s.top());
        assert!(s.topped_at(0.0).top() >= 0.01 * s.top());
    }

    #[test]
    fn planar_sides_each_bound_the_hull() {
        // A sphere's shells have planar sides (through its centre), which
        // give the same plane four times: each side must bound the hull,
        // not the first two sides fill it and leave the third out.
        let (p, n) = on_sphere(1.0, false, false);
        let top = lambda_for_depth(0.1, min_normal_length(&n).unwrap());
        let s = CurvedShell::new(p, n, 0.1, top).unwrap();
        assert_eq!(s.hull_planes, 5);
        // Rays along each side, just outside it, miss; just inside, meet.
        let b = |k: usize, out: f64| match k {
            0 => DVec2::new(0.5, -out),
            1 => DVec2::new(0.5 + out / 2.0, 0.5 + out / 2.0),
            _ => DVec2::new(-out, 0.5),
        };
        for k in 0..3 {
            let d = s.p[(k + 1) % 3] - s.p[k];
            for (out, admitted) in [(1e-3, false), (-1e-3, true)] {
                let x = s.point(b(k, out), 0.5);
                assert_eq!(s.admits(x - d, d, 0.0, 2.0), admitted, "side {k}, {out}");
            }
        }
    }

    #[test]
    fn crossings_locate_where_points_do() {
        let s = bent();
        let mut seen = [0usize; 3];
        for i in 0..12 {
            for j in 0..12 {
                // Rays from above through a grid, tilted across the sides.
                let target = s.point(DVec2::new(i as f64 / 11.0, j as f64 / 11.0) * 0.8, 0.5);
                let o = DVec3::new(-0.4 + 0.1 * i as f64, 1.2 - 0.1 * j as f64, 2.0);
                let d = (target - o).normalize();
                let (out, n) = s.crossings(o, d, 0.0, f64::INFINITY);
                for c in &out[..n] {
                    let x = o + c.t * d;
                    let at = s.locate_crossing(c, x).unwrap();
                    let loc = s.locate(x, 0.5 * s.top()).unwrap();
                    assert!((at.b - loc.b).length() < 1e-9, "{c:?}: {at:?} {loc:?}");
                    assert!((at.w - loc.w).abs() < 1e-9, "{c:?}: {at:?} {loc:?}");
                    // The point the crossing locates is the crossing's.
                    assert!((s.point(at.b, at.w) - x).length() < 1e-9, "{c:?}");
                    seen[match c.boundary {
                        Boundary::Base => 0,
                        Boundary::Top => 1,
                        Boundary::Side(_) => 2,
                    }] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&k| k > 10), "{seen:?}");
    }

    #[test]
    fn a_vertical_ray_crosses_top_and_base() {
        let s = bent();
        let o = DVec3::new(0.3, 0.3, 5.0);
        let (out, n) = s.crossings(o, DVec3::NEG_Z, 0.0, f64::INFINITY);
        let mut out = out[..n].to_vec();
        out.sort_by(|a, b| a.t.total_cmp(&b.t));
        let kinds: Vec<Boundary> = out.iter().map(|c| c.boundary).collect();
        assert_eq!(kinds, [Boundary::Top, Boundary::Base]);
        assert!((out[1].t - 5.0).abs() < 1e-12);
        assert!(out
            .iter()
            .all(|c| s.crossing_normal(c, DVec3::NEG_Z).z > 0.0));
    }

    #[test]
    fn sides_are_met_where_their_rulings_are() {
        let s = bent();
        // A point on the side over edge 0 (corners 0 and 1), half way up.
        let b = DVec2::new(0.4, 0.0);
        let x = s.point(b, 0.5);
        let d = DVec3::new(0.1, -1.0, 0.05).normalize();
        let o = x - 2.0 * d;
        let (out, n) = s.crossings(o, d, 0.0, 10.0);
        let side = out[..n]
            .iter()
            .find(|c| c.boundary == Boundary::Side(0))
            .expect("crosses side 0");
        assert!((side.t - 2.0).abs() < 1e-9, "{side:?}");
        assert!(s.crossing_normal(side, d).dot(d) < 0.0);
    }

    #[test]
    fn the_hull_admits_every_ray_through_the_shell() {
        let s = bent();
        assert!(s.hull_planes >= 5, "{}", s.hull_planes);
        let mut k = 7u32;
        let mut next = || {
            k = k.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (k >> 8) as f64 / (1u32 << 24) as f64
        };
        let mut rejected = 0;
        for _ in 0..4000 {
            let (u, v) = (next(), next());
            let b = if u + v > 1.0 {
                DVec2::new(1.0 - u, 1.0 - v)
            } else {
                DVec2::new(u, v)
            };
            // Anywhere up to the top level (w can exceed 1 there).
            let w_top = s.top * s.normal_at(b).length() / s.depth;
            let x = s.point(b, next() * w_top);
            let d = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            let t = 0.5 + next();
            assert!(s.admits(x - t * d, d, 0.0, 10.0), "{x} {d}");
            // The same ray shifted well off the shell's side is refused.
            let off = DVec3::new(3.0, 3.0, 0.0);
            rejected += usize::from(!s.admits(
                x - t * d + off,
                d.with_z(0.0).normalize_or(DVec3::X),
                0.0,
                0.5,
            ));
        }
        assert!(rejected > 3000, "{rejected}");
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let s = bent();
        // Texture triangle (map units): corners at (0,0), (3,0), (0,2).
        let m = [DVec2::ZERO, DVec2::new(3.0, 0.0), DVec2::new(0.0, 2.0)];
        let t = [
            [m[1].x - m[0].x, m[2].x - m[0].x],
            [m[1].y - m[0].y, m[2].y - m[0].y],
        ];
        let det = t[0][0] * t[1][1] - t[0][1] * t[1][0];
        let inv = [
            [t[1][1] / det, -t[0][1] / det],
            [-t[1][0] / det, t[0][0] / det],
        ];
        let to_b = |xy: DVec2| {
            let r = xy - m[0];
            DVec2::new(
                inv[0][0] * r.x + inv[0][1] * r.y,
                inv[1][0] * r.x + inv[1][1] * r.y,
            )
        };
        let (xy, w) = (DVec2::new(0.7, 0.5), 0.6);
        let j = s.jacobian(to_b(xy), w, inv);
        let h = 1e-6;
        let fd = [
            (s.point(to_b(xy + DVec2::X * h), w) - s.point(to_b(xy - DVec2::X * h), w)) / (2.0 * h),
            (s.point(to_b(xy + DVec2::Y * h), w) - s.point(to_b(xy - DVec2::Y * h), w)) / (2.0 * h),
            (s.point(to_b(xy), w + h) - s.point(to_b(xy), w - h)) / (2.0 * h),
        ];
        for k in 0..3 {
            assert!((j[k] - fd[k]).length() < 1e-7, "{k}: {} {}", j[k], fd[k]);
        }
    }
}
