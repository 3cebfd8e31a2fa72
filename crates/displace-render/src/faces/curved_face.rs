//! A triangle of a curved displaced mesh as the renderer's primitive: its
//! shell ([`crate::curved_shell`]) in the world, traced through the
//! triangle's texture space with the same distance map and exact
//! refinement as a flat face ([`crate::faces::displaced`]).
//!
//! Inside the shell the map coordinates `(x, y, w)` are a smooth function
//! of the world position, so a straight world ray is a curve in map space
//! ("curved rays in texture space"). The curve is cut into chords, each
//! bisected until its midpoint lies within [`CHORD_TOLERANCE`] (shell
//! depths) of the curve's in height above the surface (its offset in `w`
//! plus the height field's steepest slope times its offset across the
//! map); each chord is traced by the
//! core's tracer exactly as a flat face's ray is: sphere steps through the
//! conservative distance map (Donnelly, section 8.3), which are safe in map
//! space whatever the world mapping stretches, then the exact walk over the
//! bilinear patches. A hit on a chord is carried back to the world ray and
//! refined there on the true curve (regula falsi on `w - h(uv)`), so the
//! world hit lies on the surface `S = P + depth h(uv) N` to a billionth of
//! its distance (far under single precision, which hits are reported in);
//! the chords' tolerance bounds what they can miss (a bump the curve grazes
//! by less than it).
//!
//! Each face's shell is cut down to the highest the heights over its
//! triangle rise ([`CurvedShell::topped_at`]): rays passing over the local
//! heights then miss its hull, and a stretch ends where the surface can
//! no longer be.
//!
//! A ray entering the shell under the surface hits what it entered
//! through: the base, or a side that no neighbour shares (the mesh's open
//! boundary, creases and texture seams that split the surface), as the
//! flat prisms' walls are hit; a side shared with a neighbour is not a
//! wall (the neighbour's shell continues the same surface), and a ray
//! entering through it under the surface meets the surface there (a hit
//! the neighbour's trace left within rounding of the shared side).

use crate::curved_shell::{normal_to_world, Boundary, Crossing, CurvedShell, Located};
use crate::faces::displaced::{map_shading_direction, DisplacedHit};
use crate::geometry::{Aabb, Ray};
use crate::texture::Texture;
use displace_core::convention::CHORD_TOLERANCE;
use displace_core::sphere_trace::HitKind;
use displace_core::{DisplacementMap, MapRay, TraceOptions};
use displace_scene::placed::CurvedDisplacement;
use glam::{DVec2, DVec3, Vec2, Vec3};
use std::sync::Arc;

/// Grazes (a chord's hit with no root of the curve next to it) a stretch
/// traces past before it takes the next one as its hit.
const MAX_GRAZES: u32 = 8;

/// Deepest halving of one stretch of a ray into chords.
const MAX_CHORD_DEPTH: u32 = 24;

/// A point of the ray located in the shell: its shell coordinates, map
/// point and height above the surface, `w - h` ([`CurvedFace::probe`]).
type Probe = (Located, DVec3, f64);

/// A hit on a curved face before it is shaded: where in the world and in
/// the triangle's shell coordinates.
#[derive(Clone, Copy, Debug)]
pub struct CurvedHit {
    /// World position.
    pub position: Vec3,
    /// Unit geometric normal: the height field's, carried to the world by
    /// the mapping's inverse transpose, or the wall's.
    pub geometric_normal: Vec3,
    /// Shell coordinates of the hit.
    b: DVec2,
    w: f64,
    /// Texture coordinate in tiles within the face's map window.
    local_uv: Vec2,
    /// The wall (base or unshared side) was hit, not the surface.
    pub wall: bool,
    /// Distance-map steps and patches walked over all chords.
    pub iterations: u32,
}

/// What a trace of a curved face is asked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Query {
    /// The first hit, refined, with its normal.
    First,
    /// Whether anything blocks the ray (a shadow ray).
    Any,
}

/// What a trace of a curved face found.
enum Found {
    /// The hit at a world distance.
    Hit(f32, CurvedHit),
    /// A blocker, for [`Query::Any`].
    Blocked,
}

/// A displaced triangle of a curved mesh (module docs).
#[derive(Clone, Debug)]
pub struct CurvedFace {
    shell: CurvedShell,
    /// Corners' texture coordinates in map units (`uv * aspect`, within the
    /// face's map window).
    corners: [DVec2; 3],
    /// Inverse of the texture triangle's edge matrix: map `xy` to `b`.
    to_bary: [[f64; 2]; 2],
    aspect: DVec2,
    /// The steepest slope of the height field, heights (shell depths) per
    /// map unit across it ([`displace_core::HeightMap::max_steps`]): what
    /// an error in a chord's position costs in its height above the
    /// surface.
    slope: f64,
    map: Arc<DisplacementMap>,
    trace: TraceOptions,
    uv_offset: Vec2,
    /// Which sides (edge `k`: corners `k`, `k + 1`) a neighbour shares.
    shared: [bool; 3],
    bounds: Aabb,
    /// Base colour texture (the scene's `color_texture`).
    pub color: Option<Arc<Texture>>,
    /// Tangent-space normal map standing in for the baked normals.
    pub normal_map: Option<Arc<Texture>>,
}

/// The face as the scene placed it, with its bounds and the height
/// field's steepest slope found.
impl From<&CurvedDisplacement> for CurvedFace {
    fn from(c: &CurvedDisplacement) -> Self {
        let map = c.map().clone();
        let [ax, ay] = map.aspect();
        let aspect = DVec2::new(ax as f64, ay as f64);
        let (corners, to_bary) = c.texture_frame();
        let shell = c
            .shell()
            .topped_at(highest(&map, corners.map(|xy| xy / aspect)));
        let bounds = Aabb::from_points(shell.corners().map(|p| p.as_vec3()));
        let [su, sv] = map.height.max_steps();
        let texel = aspect / DVec2::new(map.height.width() as f64, map.height.height() as f64);
        let slope = DVec2::new(su as f64 / texel.x, sv as f64 / texel.y).length();
        Self {
            shell,
            corners,
            to_bary,
            aspect,
            slope,
            map,
            trace: c.trace_options(),
            uv_offset: c.uv_offset(),
            shared: c.shared(),
            bounds,
            color: c.color.clone(),
            normal_map: c.normal_map.clone(),
        }
    }
}

impl CurvedFace {
    /// World bounds of the shell.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The shared displacement map.
    pub fn map(&self) -> &Arc<DisplacementMap> {
        &self.map
    }

    /// The shell.
    pub fn shell(&self) -> &CurvedShell {
        &self.shell
    }

    /// Changes the map-space tracer (as [`crate::faces::displaced::DisplacedFace::set_method`]).
    pub fn set_method(&mut self, method: displace_core::Method) {
        self.trace.method = method;
    }

    /// Map-space point `(x, y, w)` of shell coordinates `loc`, `b` kept on
    /// the triangle (a point located on its boundary may round outside).
    fn map_point(&self, loc: &Located) -> DVec3 {
        let b = clamp_bary(loc.b);
        let xy = self.corners[0]
            + b.x * (self.corners[1] - self.corners[0])
            + b.y * (self.corners[2] - self.corners[0]);
        xy.extend(loc.w)
    }

    /// Texture coordinate (tiles, the face's window) of a map point.
    fn local_uv(&self, c: DVec3) -> Vec2 {
        Vec2::new((c.x / self.aspect.x) as f32, (c.y / self.aspect.y) as f32)
    }

    /// The height of the surface over map point `c`, and `w - h`.
    fn above(&self, c: DVec3) -> f64 {
        let uv = self.local_uv(c);
        c.z - self.map.height.sample(uv.x, uv.y) as f64
    }

    /// Shell coordinates, map point and `w - h` of the ray at `t`.
    fn probe(&self, o: DVec3, d: DVec3, t: f64, hint: f64) -> Option<Probe> {
        Some(self.probed(self.shell.locate(o + t * d, hint)?))
    }

    /// [`CurvedFace::probe`] at a crossing of the shell's boundary, located
    /// from the crossing itself ([`CurvedShell::locate_crossing`]).
    fn probe_crossing(&self, o: DVec3, d: DVec3, c: Option<Crossing>) -> Option<Probe> {
        let c = c?;
        Some(self.probed(self.shell.locate_crossing(&c, o + c.t * d)?))
    }

    /// The map point and `w - h` of shell coordinates `loc`.
    fn probed(&self, loc: Located) -> Probe {
        let c = self.map_point(&loc);
        (loc, c, self.above(c))
    }

    /// First hit with world distance in `[t_min, t_max]`.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, CurvedHit)> {
        match self.trace(ray, t_min, t_max, Query::First)? {
            Found::Hit(t, hit) => Some((t, hit)),
            Found::Blocked => unreachable!("a first-hit query reports its hit"),
        }
    }

    /// Whether the face's solid blocks the ray within `[t_min, t_max]`: a
    /// shadow ray's any-hit query, which stops at the first proof of a
    /// blocker (a chord's hit, before its refinement and normal).
    pub fn occludes(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.trace(ray, t_min, t_max, Query::Any).is_some()
    }

    /// The stretches of the ray inside the shell, in order, until one
    /// finds what `query` asks for within `[t_min, t_max]`.
    ///
    /// A stretch always runs to where the ray leaves the shell, whatever
    /// `t_max`: its chords, and so the hit they find, depend on the shell
    /// alone, and a hit beyond `t_max` is then dropped. Cutting the last
    /// stretch at `t_max` instead cut its chords differently, so a
    /// shortened ray (a shadow ray's any-hit query, or the BVH's closest
    /// hit so far) could meet a chord's false hit, one the curve passes
    /// over within [`CHORD_TOLERANCE`], where the whole ray did not.
    fn trace(&self, ray: &Ray, t_min: f32, t_max: f32, query: Query) -> Option<Found> {
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        let (t_min, t_max) = (t_min as f64, t_max as f64);
        // The hull over all of the ray past `t_min`: a stretch's inside is
        // judged whatever `t_max`.
        let (hull_in, hull_out) = self.shell.hull_span(o, d, t_min, f64::INFINITY)?;
        if hull_in > t_max {
            return None;
        }
        let (mut xs, n) = self.shell.crossings(o, d, t_min, f64::INFINITY);
        let xs = &mut xs[..n];
        xs.sort_unstable_by(|a, b| a.t.total_cmp(&b.t));
        // The stretches between crossings, each inside the shell or not
        // (its midpoint located): rounding at an edge or corner may count
        // one crossing twice, which leaves an empty or outside stretch.
        let end = xs.last()?.t;
        let mut start = (t_min, None::<Crossing>);
        let mut iterations = 0u32;
        for k in 0..=xs.len() {
            let (b, next) = match xs.get(k) {
                Some(c) => (c.t, Some(*c)),
                None => (end, None),
            };
            let (a, entry) = start;
            if a > t_max {
                break;
            }
            if b > a {
                let mid = 0.5 * (a + b);
                // Outside the hull is outside the shell: the stretch
                // before the ray enters needs no point located.
                let inside = if (hull_in..=hull_out).contains(&mid) {
                    self.shell
                        .locate(o + mid * d, 0.5 * self.shell.top())
                        .filter(|loc| self.shell.contains(loc, 1e-9))
                } else {
                    None
                };
                if let Some(mid) = inside {
                    let ends = ((a, entry), (b, next));
                    let found = self.stretch(o, d, ends, mid, t_max, query, &mut iterations);
                    if let Some(found) = found {
                        return Some(found);
                    }
                }
            }
            match next {
                Some(c) => start = (c.t, Some(c)),
                None => break,
            }
        }
        None
    }

    /// The first hit on `[ta, tb]` at most `t_max` (or, for
    /// [`Query::Any`], the proof of one), a stretch inside the shell
    /// entered through `entry` (`None`: the ray starts inside) and left
    /// through `exit` (`None`: it ends inside). Both queries find the same
    /// hit: the any-hit query skips only the refinement when the chord's
    /// hit already lies under the surface before `t_max` (the root then
    /// lies between the stretch's start and it). `mid` is the stretch's
    /// midpoint, located already (it told the stretch inside the shell):
    /// the first chord's halving reuses it.
    #[allow(clippy::too_many_arguments)]
    fn stretch(
        &self,
        o: DVec3,
        d: DVec3,
        ((ta, entry), (tb, exit)): ((f64, Option<Crossing>), (f64, Option<Crossing>)),
        mid: Located,
        t_max: f64,
        query: Query,
        iterations: &mut u32,
    ) -> Option<Found> {
        let hint = match entry.map(|c| c.boundary) {
            Some(Boundary::Top) => self.shell.top(),
            Some(Boundary::Base) => 0.0,
            _ => 0.5 * self.shell.top(),
        };
        let (la, ca, ga) = self
            .probe_crossing(o, d, entry)
            .or_else(|| self.probe(o, d, ta, hint))
            .or_else(|| self.probe(o, d, ta + 1e-9 * (tb - ta), hint))?;
        if ga < 0.0 {
            if query == Query::Any {
                return Some(Found::Blocked);
            }
            // Entered under the surface: the wall entered through, except
            // a shared side (or the top, within rounding), where the
            // surface meets it.
            let wall = match entry {
                Some(Crossing {
                    boundary: Boundary::Side(k),
                    ..
                }) if self.shared[k] => None,
                Some(Crossing {
                    boundary: Boundary::Top,
                    ..
                }) => None,
                Some(c) => Some(self.shell.crossing_normal(&c, d)),
                None => Some(-d),
            };
            return Some(match wall {
                Some(n) => self.hit(o, d, ta, &la, ca, n, true, *iterations),
                None => self.surface_hit(o, d, ta, &la, ca, *iterations),
            });
        }
        let (_, cb, _) = self
            .probe_crossing(o, d, exit)
            .or_else(|| self.probe(o, d, tb, la.lambda))
            .or_else(|| self.probe(o, d, tb - 1e-9 * (tb - ta), la.lambda))?;
        let exit = exit.map(|c| c.boundary);
        // The chords from `from`, a point of the curve above the surface:
        // the stretch's start, then past each graze (a chord's hit that
        // the curve passes over: no root next to it).
        let mut from = (ta, ca, la.lambda);
        let mut mid = Some(mid);
        for graze in 0..=MAX_GRAZES {
            let chords = self.chords(o, d, from, (tb, cb), mid.take(), 0, iterations);
            let Some((t, span)) = chords else {
                // Heights never go below the base: a ray leaving through
                // it has met the surface there
                // (`displace_core::sphere_trace::leaves_through_floor`),
                // where the chords' walks may not resolve the root at
                // their very end.
                if exit != Some(Boundary::Base) || tb > t_max {
                    return None;
                }
                if query == Query::Any {
                    return Some(Found::Blocked);
                }
                let (loc, c, _) = self.probe(o, d, tb, la.lambda)?;
                return Some(self.surface_hit(o, d, tb, &loc, c, *iterations));
            };
            let at_t = self.probe(o, d, t, la.lambda);
            if query == Query::Any && t <= t_max && at_t.is_some_and(|(_, _, g)| g <= 0.0) {
                return Some(Found::Blocked);
            }
            let (t, known) = match self.refine(o, d, (from.0, tb), (t, at_t), span, la.lambda) {
                Some(root) => root,
                None if graze < MAX_GRAZES => {
                    let (l, c, _) = at_t?;
                    from = (t, c, l.lambda);
                    continue;
                }
                // Grazing still: the chord's hit, within the chords'
                // tolerance above the surface, stands.
                None => (t, at_t),
            };
            if t > t_max {
                return None;
            }
            if query == Query::Any {
                return Some(Found::Blocked);
            }
            let (loc, c, _) = known.or_else(|| self.probe(o, d, t, la.lambda))?;
            return Some(self.surface_hit(o, d, t, &loc, c, *iterations));
        }
        None
    }

    /// The first chord hit on the curve from `a` to `b` (ray parameters
    /// and map points), as a ray parameter with the chord's span of ray
    /// parameters: the chord halved while its midpoint strays from the
    /// curve's, then traced by the core. `mid`, when given, is the curve's
    /// point halfway, located already.
    #[allow(clippy::too_many_arguments)]
    fn chords(
        &self,
        o: DVec3,
        d: DVec3,
        a: (f64, DVec3, f64),
        b: (f64, DVec3),
        mid: Option<Located>,
        depth: u32,
        iterations: &mut u32,
    ) -> Option<(f64, f64)> {
        let (ta, ca, hint) = a;
        let (tb, cb) = b;
        if depth < MAX_CHORD_DEPTH {
            let tm = 0.5 * (ta + tb);
            let located = match mid {
                Some(lm) => Some((lm, self.map_point(&lm))),
                None => self.probe(o, d, tm, hint).map(|(lm, cm, _)| (lm, cm)),
            };
            if let Some((lm, cm)) = located {
                if self.chord_error(cm - 0.5 * (ca + cb)) > CHORD_TOLERANCE {
                    let m = (tm, cm, lm.lambda);
                    return self
                        .chords(o, d, a, (tm, cm), None, depth + 1, iterations)
                        .or_else(|| self.chords(o, d, m, b, None, depth + 1, iterations));
                }
            }
        }
        let v = cb - ca;
        let len = v.length();
        if len.is_nan() || len <= 0.0 {
            return None;
        }
        let ray = MapRay {
            origin: ca.as_vec3(),
            dir: (v / len).as_vec3(),
        };
        let mut opts = self.trace;
        opts.t_min = 0.0;
        opts.t_max = len as f32;
        let hit = self.map.trace(&ray, &opts)?;
        *iterations += hit.iterations;
        let f = match hit.kind {
            HitKind::Wall => 0.0,
            HitKind::Surface => (hit.t as f64 / len).clamp(0.0, 1.0),
        };
        Some((ta + f * (tb - ta), tb - ta))
    }

    /// How far a chord that lies `e` (map units) from the curve can be from
    /// it in height above the surface, `w - h`: the offset in `w` itself,
    /// and the surface's steepest slope times the offset across it. A
    /// bound in position alone let the chords of a steep map pass over a
    /// bump that the curve dips into by several times the tolerance.
    fn chord_error(&self, e: DVec3) -> f64 {
        e.z.abs() + self.slope * e.truncate().length()
    }

    /// The root of `w - h` on the true curve near a chord's hit at `t`,
    /// within `[ta, tb]` where `w - h >= 0` at `ta`: regula falsi (the
    /// Illinois variant) on a bracket found next to `t`, its first probe a
    /// thousandth of the chord (`span`) away, since the chord lies within
    /// [`CHORD_TOLERANCE`] of the curve. `None` when the curve stays above
    /// the surface from `t` on for the chord's span (to `tb` at most: a
    /// graze, the chord dipped into a bump that the curve passes over, and
    /// the chords go on from `t`); `t` itself where the curve cannot
    /// be located. `at_t` is the curve's point at `t`, probed already; the
    /// root comes with its probe where the search made one there.
    fn refine(
        &self,
        o: DVec3,
        d: DVec3,
        (ta, tb): (f64, f64),
        (t, at_t): (f64, Option<Probe>),
        span: f64,
        hint: f64,
    ) -> Option<(f64, Option<Probe>)> {
        let probe = |t: f64| self.probe(o, d, t, hint);
        let g = |p: &Option<Probe>| p.map(|(_, _, g)| g);
        let Some((_, _, gt)) = at_t else {
            return Some((t, None));
        };
        if gt == 0.0 {
            return Some((t, at_t));
        }
        // The probe of the bracket's upper end, the root it returns.
        let mut hi_probe = at_t;
        let first = 1e-3 * span.max(1e-12);
        // A bracket: [last point above, first point under].
        let (mut lo, mut hi, mut glo, mut ghi) = if gt < 0.0 {
            // Back towards `ta` (above) in growing steps.
            let mut step = first;
            let mut lo = t;
            let mut glo = gt;
            while glo < 0.0 && lo > ta {
                lo = (t - step).max(ta);
                glo = g(&probe(lo)).unwrap_or(0.0);
                step *= 8.0;
            }
            if glo < 0.0 {
                return Some((t, at_t));
            }
            (lo, t, glo, gt)
        } else {
            // Forward, but no further than the chord's own span: steps
            // growing past it could jump over a dip of the curve under the
            // surface and bracket a later root. Past the span, the hit is
            // a graze, and the chords go on from it.
            let end = (t + span).min(tb);
            let mut step = first;
            let mut hi = t;
            let mut ghi = gt;
            while ghi > 0.0 && hi < end {
                hi = (t + step).min(end);
                hi_probe = probe(hi);
                ghi = g(&hi_probe).unwrap_or(0.0);
                step *= 8.0;
            }
            if ghi > 0.0 {
                return None;
            }
            (t, hi, gt, ghi)
        };
        let mut side = 0i8;
        // To a billionth of the ray parameter: hits are single precision.
        for _ in 0..60 {
            let m = (lo * ghi - hi * glo) / (ghi - glo);
            let m = if m > lo && m < hi { m } else { 0.5 * (lo + hi) };
            let pm = probe(m);
            let Some(gm) = g(&pm) else { break };
            if gm >= 0.0 {
                lo = m;
                glo = gm;
                if side == 1 {
                    ghi *= 0.5;
                }
                side = 1;
            } else {
                hi = m;
                ghi = gm;
                hi_probe = pm;
                if side == -1 {
                    glo *= 0.5;
                }
                side = -1;
            }
            if hi - lo <= 1e-9 * (1.0 + hi.abs()) {
                break;
            }
        }
        // The first point under the surface: never in front of it.
        Some((hi, hi_probe))
    }

    /// The geometric normal of the surface at shell coordinates `loc` and
    /// map point `c`: the bilinear height field's, carried to the world by
    /// the mapping's inverse transpose.
    fn surface_normal(&self, loc: &Located, c: DVec3) -> DVec3 {
        let uv = self.local_uv(c);
        let [gx, gy] = self.map.height.gradient(uv.x, uv.y);
        let n_map = DVec3::new(-gx as f64 / self.aspect.x, -gy as f64 / self.aspect.y, 1.0);
        let j = self.shell.jacobian(clamp_bary(loc.b), loc.w, self.to_bary);
        normal_to_world(&j, n_map)
    }

    /// The hit on the surface at `t` along the ray, at shell coordinates
    /// `loc` and map point `c`, with the height field's normal there.
    fn surface_hit(&self, o: DVec3, d: DVec3, t: f64, loc: &Located, c: DVec3, it: u32) -> Found {
        let n = self.surface_normal(loc, c);
        self.hit(o, d, t, loc, c, n, false, it)
    }

    /// The hit at `t` along the ray, at shell coordinates `loc` and map
    /// point `c`, with geometric normal `n`: on the surface, or on a wall.
    #[allow(clippy::too_many_arguments)]
    fn hit(
        &self,
        o: DVec3,
        d: DVec3,
        t: f64,
        loc: &Located,
        c: DVec3,
        n: DVec3,
        wall: bool,
        iterations: u32,
    ) -> Found {
        Found::Hit(
            t as f32,
            CurvedHit {
                position: (o + t * d).as_vec3(),
                geometric_normal: n.as_vec3(),
                b: clamp_bary(loc.b),
                w: loc.w,
                local_uv: self.local_uv(c),
                wall,
                iterations,
            },
        )
    }

    /// The world description of a hit; with `shading`, the normal map's
    /// (baked or given) normal carried to the world by the mapping's
    /// inverse transpose at the hit, else the geometric normal.
    pub fn resolve(&self, hit: &CurvedHit, shading: bool) -> DisplacedHit {
        let uv = hit.local_uv + self.uv_offset;
        let shading_normal = if hit.wall || !shading {
            hit.geometric_normal
        } else {
            let n_map =
                map_shading_direction(&self.map, self.normal_map.as_deref(), hit.local_uv, uv);
            let j = self.shell.jacobian(hit.b, hit.w, self.to_bary);
            normal_to_world(&j, n_map.as_dvec3()).as_vec3()
        };
        DisplacedHit {
            position: hit.position,
            geometric_normal: hit.geometric_normal,
            shading_normal,
            uv,
            iterations: hit.iterations,
            wall: hit.wall,
        }
    }
}

/// The highest the surface rises over the triangle with texture
/// coordinates `uv` (tiles), or more: the largest texel of every bilinear
/// cell that the triangle's bounding rectangle touches (a bilinear patch
/// stays within its corners), the rectangle widened by more than the
/// rounding of the single-precision coordinates the trace samples at. One
/// pass over those texels, not the exact maximum's interpolations
/// ([`displace_core::HeightMap::range`]), which cost a mesh's set-up a
/// third more.
fn highest(map: &DisplacementMap, uv: [DVec2; 3]) -> f64 {
    let heights = &map.height;
    let size = DVec2::new(heights.width() as f64, heights.height() as f64);
    let pad = |v: DVec2| 1e-6 * (DVec2::ONE + v.abs());
    let lo = uv[0].min(uv[1]).min(uv[2]);
    let hi = uv[0].max(uv[1]).max(uv[2]);
    // Cell `i` (sampling's `floor(u W - 0.5)`) spans texels `i` and `i + 1`.
    let first = ((lo - pad(lo)) * size - 0.5).floor();
    let last = ((hi + pad(hi)) * size - 0.5).floor() + 1.0;
    let count = (last - first + 1.0).max(DVec2::ZERO);
    let cells = count.x * count.y;
    let top = if cells.is_nan() || cells > size.x * size.y {
        // Wider than the map (or not a number): every texel is under it.
        heights
            .data()
            .iter()
            .copied()
            .fold(f32::NEG_INFINITY, f32::max)
    } else {
        let (i0, i1, j0, j1) = (first.x as i64, last.x as i64, first.y as i64, last.y as i64);
        (j0..=j1)
            .flat_map(|j| (i0..=i1).map(move |i| heights.texel(i, j)))
            .fold(f32::NEG_INFINITY, f32::max)
    };
    if top.is_finite() {
        top as f64
    } else {
        1.0
    }
}

/// `b` moved onto the triangle (weights non-negative, summing to at most 1).
fn clamp_bary(b: DVec2) -> DVec2 {
    let b = b.max(DVec2::ZERO);
    let s = b.x + b.y;
    if s > 1.0 {
        b / s
    } else {
        b
    }
}
