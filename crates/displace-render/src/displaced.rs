//! Displaced faces (seed 002, sections 2.4 and 3.4): the face extruded by its
//! depth along its normal is the shell (a box for a parallelogram, a prism
//! for a triangle). A world ray is carried into the face's map space by the
//! inverse of the face's affine frame, traced there by the core's sphere
//! tracer, and its hit carried back.
//!
//! Map space ([`displace_core::convention`]): `x` along `u`, `y` along `v`,
//! `z` along the normal, in units of the shell depth, one tile spanning
//! `[0, ax] x [0, ay] x [0, 1]`. A face's frame is
//! `world = origin + M p`, `M = [dP/du / ax, dP/dv / ay, n depth]`. `M` is
//! affine, so intersections (and their order along the ray) are preserved:
//! tracing in map space is exact for any parallelogram or triangle, sheared
//! or not. Only lengths change, by `s = |M^-1 d|` for a unit world
//! direction `d`: `t_map = s t_world`. Normals go back by `M^-T`.

use crate::geometry::{Aabb, Ray};
use crate::texture::Texture;
use displace_core::sphere_trace::HitKind;
use displace_core::{Address, DisplacementMap, MapHit, MapRay, TraceOptions};
use glam::{Mat3, Vec2, Vec3};
use std::sync::Arc;

/// Where a face sits in the world: its base point at texture coordinate
/// `(0, 0)`, how the world moves per tile of texture coordinate, its unit
/// normal and its displacement depth.
#[derive(Clone, Copy, Debug)]
pub struct FaceFrame {
    pub origin: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    pub normal: Vec3,
    pub depth: f32,
}

#[derive(Clone, Debug)]
pub struct DisplacedFace {
    origin: Vec3,
    to_world: Mat3,
    to_map: Mat3,
    /// `M^-T`: carries map-space normals to the world.
    normal_to_world: Mat3,
    map: Arc<DisplacementMap>,
    trace: TraceOptions,
    /// The triangle (map-space `xy`) whose prism bounds the surface; `None`
    /// for a parallelogram, whose shell is the whole map box.
    prism: Option<[Vec2; 3]>,
    bounds: Aabb,
    /// Added to the hit's texture coordinate (triangles whose coordinates
    /// were shifted by whole tiles into the map's domain).
    uv_offset: Vec2,
    pub color: Option<Arc<Texture>>,
    pub normal_map: Option<Arc<Texture>>,
}

/// A world ray carried into a face's map space ([`DisplacedFace::map_query`]).
#[derive(Clone, Copy, Debug)]
pub struct MapQuery {
    pub ray: MapRay,
    /// `t_map = scale t_world`.
    pub scale: f32,
    /// The trace options clipped to the world range (and a triangle's
    /// prism).
    pub opts: TraceOptions,
    /// Outward normal of the prism side the ray enters through.
    pub entry: Option<Vec3>,
}

impl MapQuery {
    /// The world distance and map-space hit of a trace of this query: a
    /// wall hit takes the normal of the prism side it entered through.
    #[inline]
    pub fn finish(&self, mut hit: MapHit) -> (f32, MapHit) {
        if hit.kind == HitKind::Wall {
            if let Some(n) = self.entry {
                hit.normal = n;
            }
        }
        (hit.t / self.scale, hit)
    }
}

/// What the renderer needs of a displaced hit, in world space.
#[derive(Clone, Copy, Debug)]
pub struct DisplacedHit {
    pub position: Vec3,
    pub geometric_normal: Vec3,
    pub shading_normal: Vec3,
    /// Texture coordinate (tiles).
    pub uv: Vec2,
    pub iterations: u32,
    pub wall: bool,
}

impl DisplacedFace {
    /// `tiles` is how many tiles of the map the face spans; `prism_uv` the
    /// triangle's texture coordinates (already in `[0, tiles]`) or `None` for
    /// the full parallelogram.
    pub fn new(
        frame: FaceFrame,
        map: Arc<DisplacementMap>,
        trace: TraceOptions,
        prism_uv: Option<[Vec2; 3]>,
        uv_offset: Vec2,
    ) -> Option<Self> {
        let [ax, ay] = map.aspect();
        let to_world =
            Mat3::from_cols(frame.dpdu / ax, frame.dpdv / ay, frame.normal * frame.depth);
        let det = to_world.determinant();
        if !det.is_finite() || det.abs() <= 1e-30 {
            return None;
        }
        let to_map = to_world.inverse();
        let hi = Vec2::new(ax * trace.tiles[0], ay * trace.tiles[1]);
        let prism = prism_uv.map(|t| t.map(|uv| uv * Vec2::new(ax, ay)));
        let base: Vec<Vec2> = match prism {
            Some(t) => t.to_vec(),
            None => vec![Vec2::ZERO, Vec2::new(hi.x, 0.0), Vec2::new(0.0, hi.y), hi],
        };
        let bounds = Aabb::from_points(
            base.iter()
                .flat_map(|b| [0.0, 1.0].map(|z| frame.origin + to_world * b.extend(z))),
        );
        Some(Self {
            origin: frame.origin,
            to_world,
            to_map,
            normal_to_world: to_map.transpose(),
            map,
            trace,
            prism,
            bounds,
            uv_offset,
            color: None,
            normal_map: None,
        })
    }

    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    pub fn map(&self) -> &Arc<DisplacementMap> {
        &self.map
    }

    /// `(origin, M)` of the frame `world = origin + M p` (module docs).
    pub fn frame(&self) -> (Vec3, Mat3) {
        (self.origin, self.to_world)
    }

    pub fn trace_options(&self) -> TraceOptions {
        self.trace
    }

    /// Whether the face is a triangle (a prism shell) rather than a
    /// parallelogram (the whole map box).
    pub fn is_triangle(&self) -> bool {
        self.prism.is_some()
    }

    pub fn set_method(&mut self, method: displace_core::Method) {
        self.trace.method = method;
    }

    /// First hit with world distance in `[t_min, t_max]`: the world distance
    /// and the map-space hit.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, MapHit)> {
        let query = self.map_query(ray, t_min, t_max)?;
        let hit = self.map.trace(&query.ray, &query.opts)?;
        Some(query.finish(hit))
    }

    /// `ray` in map space, as [`Self::intersect`] and [`Self::occludes`]
    /// trace it; batch queries ([`crate::scene::batch`]) gather these and
    /// trace them together.
    #[inline]
    pub fn map_query(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<MapQuery> {
        let (ray, scale, opts, entry) = self.to_map_ray(ray, t_min, t_max)?;
        Some(MapQuery {
            ray,
            scale,
            opts,
            entry,
        })
    }

    /// Whether the face's displaced solid blocks `ray` within `[t_min,
    /// t_max]`: a shadow ray's any-hit query, which stops at the first proof
    /// of a blocker ([`displace_core::cell_trace::occluded`]).
    #[inline]
    pub fn occludes(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.to_map_ray(ray, t_min, t_max)
            .is_some_and(|(map_ray, _, opts, _)| self.map.occluded(&map_ray, &opts))
    }

    /// `ray` in map space: the unit map-space ray, the length scale `s`
    /// (`t_map = s t_world`), the trace options clipped to `[t_min, t_max]`
    /// (and to a triangle's prism), and the outward normal of the prism
    /// side the ray enters through. `None` when the ray misses the prism or
    /// has no map-space length.
    #[inline]
    fn to_map_ray(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(MapRay, f32, TraceOptions, Option<Vec3>)> {
        let origin = self.to_map * (ray.origin - self.origin);
        let d = self.to_map * ray.dir;
        let s = d.length();
        if !(s > 0.0 && s.is_finite()) {
            return None;
        }
        let dir = d * (1.0 / s);
        let mut opts = self.trace;
        opts.t_min = t_min * s;
        opts.t_max = t_max * s;
        let mut entry = None;
        if let Some(tri) = &self.prism {
            let (a, b, n) = clip_prism(origin, dir, tri, opts.t_min, opts.t_max)?;
            opts.t_min = a;
            opts.t_max = b;
            entry = n;
        }
        Some((MapRay { origin, dir }, s, opts, entry))
    }

    /// [`Self::resolve`] without the shading normal (the geometric normal
    /// stands in for it): where a hit is, not how it is lit.
    pub fn resolve_geometry(&self, hit: &MapHit) -> DisplacedHit {
        let geometric_normal = (self.normal_to_world * hit.normal).normalize();
        DisplacedHit {
            position: self.origin + self.to_world * hit.position,
            geometric_normal,
            shading_normal: geometric_normal,
            uv: hit.uv + self.uv_offset,
            iterations: hit.iterations,
            wall: hit.kind == HitKind::Wall,
        }
    }

    /// The world-space description of a map-space hit.
    pub fn resolve(&self, hit: &MapHit) -> DisplacedHit {
        let position = self.origin + self.to_world * hit.position;
        let geometric_normal = (self.normal_to_world * hit.normal).normalize();
        let uv = hit.uv + self.uv_offset;
        let wall = hit.kind == HitKind::Wall;
        let shading_normal = if wall {
            geometric_normal
        } else {
            let n_map = match &self.normal_map {
                Some(tex) => (tex.sample(uv) * 2.0 - Vec3::ONE).normalize_or(Vec3::Z),
                None => {
                    let st = match self.map.address() {
                        Address::Repeat => {
                            Vec2::new(hit.uv.x.rem_euclid(1.0), hit.uv.y.rem_euclid(1.0))
                        }
                        Address::Clamp => hit.uv,
                    };
                    // Normalised once, in the world.
                    self.map.shading_direction(st)
                }
            };
            (self.normal_to_world * n_map).normalize()
        };
        DisplacedHit {
            position,
            geometric_normal,
            shading_normal,
            uv,
            iterations: hit.iterations,
            wall,
        }
    }
}

/// Clips a map-space ray to the prism over triangle `tri` (`z` in `[0,
/// 1]`): the parameter interval inside it and the outward normal of the
/// face it enters through (`None` if it starts inside).
fn clip_prism(
    o: Vec3,
    d: Vec3,
    tri: &[Vec2; 3],
    t_min: f32,
    t_max: f32,
) -> Option<(f32, f32, Option<Vec3>)> {
    let mut t_in = t_min;
    let mut t_out = t_max;
    let mut entry = None;
    let area = (tri[1] - tri[0]).perp_dot(tri[2] - tri[0]);
    let orient = area.signum();
    let mut planes: [(Vec3, f32); 5] = [(Vec3::ZERO, 0.0); 5];
    for k in 0..3 {
        let (a, b) = (tri[k], tri[(k + 1) % 3]);
        let e = b - a;
        // Inward normal of edge a->b for a counter-clockwise triangle.
        let n = Vec2::new(-e.y, e.x) * orient;
        planes[k] = (n.extend(0.0), -n.dot(a));
    }
    planes[3] = (Vec3::Z, 0.0);
    planes[4] = (Vec3::NEG_Z, 1.0);
    for (n, c) in planes {
        // Inside: n . p + c >= 0.
        let f0 = n.dot(o) + c;
        let fd = n.dot(d);
        if fd == 0.0 {
            if f0 < 0.0 {
                return None;
            }
            continue;
        }
        let t = -f0 / fd;
        if fd > 0.0 {
            if t > t_in {
                t_in = t;
                entry = Some(-n.normalize());
            }
        } else {
            t_out = t_out.min(t);
        }
    }
    (t_in <= t_out).then_some((t_in, t_out, entry))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prism_clip_enters_through_the_right_face() {
        let tri = [Vec2::ZERO, Vec2::new(2.0, 0.0), Vec2::new(0.0, 2.0)];
        // From -y into the edge y = 0.
        let (a, b, n) =
            clip_prism(Vec3::new(0.5, -1.0, 0.5), Vec3::Y, &tri, 0.0, f32::INFINITY).unwrap();
        assert!((a - 1.0).abs() < 1e-6 && (b - 2.5).abs() < 1e-6, "{a} {b}");
        assert_eq!(n, Some(Vec3::NEG_Y));
        // Outside the hypotenuse, parallel to it: misses.
        assert!(clip_prism(
            Vec3::new(2.0, 2.0, 0.5),
            Vec3::new(1.0, -1.0, 0.0).normalize(),
            &tri,
            0.0,
            10.0
        )
        .is_none());
        // Clockwise triangles clip the same.
        let cw = [tri[0], tri[2], tri[1]];
        let (a2, b2, _) =
            clip_prism(Vec3::new(0.5, -1.0, 0.5), Vec3::Y, &cw, 0.0, f32::INFINITY).unwrap();
        assert!((a2 - a).abs() < 1e-6 && (b2 - b).abs() < 1e-6);
    }
}
