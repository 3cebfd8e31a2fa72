//! The primitives of a built scene and the two queries the integrator asks
//! of them: nearest hit, and whether anything blocks a segment.

use super::Scene;
use crate::faces::curved_face::{CurvedFace, CurvedHit};
use crate::faces::displaced::DisplacedFace;
use crate::geometry::{Aabb, Ray};
use crate::shapes::Sphere;
use displace_core::{DisplacementMap, MapHit};
pub use displace_scene::placed::NO_ATTR;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// The geometry of a primitive: the scene's shapes with their displaced
/// faces ready to trace.
pub type Shape = displace_scene::placed::Shape<DisplacedFace, CurvedFace>;

/// [`test_cost`] of a displaced or curved face, a lower bound:
/// a ray that misses a displaced face still pays for its transform into
/// map space and the shell clip (about 100 instructions in callgrind,
/// where a quad's whole test is about 80), and one that enters the shell
/// pays for the trace. Anything from 2 to 8 gives the studded Cornell box
/// the same tree (its floor in a box of its own, 7% fewer instructions for
/// a path-traced render than with the floor in the walls' leaf).
const TRACED_TEST_COST: f32 = 2.0;

/// One shape with its material: what the BVH holds.
pub type Primitive = displace_scene::placed::Primitive<Shape>;

/// What testing a ray against `p`'s shape costs, in triangle tests, for the
/// BVH's surface area heuristic ([`crate::bvh::Bvh::build_weighted`]).
pub fn test_cost(p: &Primitive) -> f32 {
    match &p.shape {
        Shape::Displaced(_) | Shape::Curved(_) => TRACED_TEST_COST,
        _ => 1.0,
    }
}

/// The world box of `p`'s shape (a displaced face's whole shell).
pub fn bounds(p: &Primitive) -> Aabb {
    match &p.shape {
        Shape::Quad(q) => q.bounds(),
        Shape::Triangle { tri, .. } => tri.bounds(),
        Shape::Sphere(s) => s.bounds(),
        Shape::Displaced(d) => d.bounds(),
        Shape::Curved(c) => c.bounds(),
    }
}

/// A hit before its surface description is worked out.
#[derive(Clone, Copy, Debug)]
pub(super) enum Local {
    Param(Vec2),
    Sphere,
    Map(MapHit),
    Curved(CurvedHit),
}

/// Everything shading needs at a hit, world space.
#[derive(Clone, Copy, Debug)]
pub struct Interaction {
    /// Distance along the ray.
    pub t: f32,
    /// World position of the hit.
    pub position: Vec3,
    /// Unit, as the shape defines it (not flipped towards the ray).
    pub geometric_normal: Vec3,
    /// Unit normal for shading: interpolated, or from the normal map.
    pub shading_normal: Vec3,
    /// Texture coordinate of the hit (displaced for a displaced face).
    pub uv: Vec2,
    /// Index into [`Scene::materials`].
    pub material: u32,
    /// The light this surface is the visible emitter of, if any.
    pub emitter: Option<u32>,
    /// Map-space tracing cost (0 for plain shapes).
    pub iterations: u32,
    /// Colour of a displaced face's own texture (white when none).
    pub tint: Vec3,
}

impl Scene {
    pub(super) fn hit_prim(
        &self,
        i: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, Local)> {
        match &self.prims[i as usize].shape {
            Shape::Quad(q) => q
                .intersect(ray, t_min, t_max)
                .map(|(t, uv)| (t, Local::Param(uv))),
            Shape::Triangle { tri, .. } => tri
                .intersect(ray, t_min, t_max)
                .map(|(t, b)| (t, Local::Param(b))),
            Shape::Sphere(s) => s.intersect(ray, t_min, t_max).map(|t| (t, Local::Sphere)),
            Shape::Displaced(d) => d
                .intersect(ray, t_min, t_max)
                .map(|(t, h)| (t, Local::Map(h))),
            Shape::Curved(c) => c
                .intersect(ray, t_min, t_max)
                .map(|(t, h)| (t, Local::Curved(h))),
        }
    }

    /// Nearest hit with `t` in `[t_min, t_max]`.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Interaction> {
        self.intersect_primitive(ray, t_min, t_max)
            .map(|(_, hit)| hit)
    }

    /// Nearest hit and the index of the primitive it lies on (benchmarks
    /// sort rays by what they hit, see [`Scene::is_displaced`]).
    pub fn intersect_primitive(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(u32, Interaction)> {
        let mut best: Option<(u32, f32, Local)> = None;
        self.bvh.traverse(ray, t_min, t_max, false, |i, t_max| {
            let (t, local) = self.hit_prim(i, ray, t_min, t_max)?;
            best = Some((i, t, local));
            Some(t)
        });
        let (i, t, local) = best?;
        Some((i, self.resolve(i, ray, t, local)))
    }

    /// The `[[shapes]]` entry primitive `i` was built from, `None` for a
    /// visible area light (what `displace trace --scene` reports per hit).
    pub fn shape_of(&self, i: u32) -> Option<u32> {
        self.prims.get(i as usize).and_then(|p| p.shape_index)
    }

    /// Bytes held by the scene's distinct displacement maps
    /// ([`DisplacementMap::memory_bytes`]; faces sharing a map count it
    /// once).
    pub fn map_bytes(&self) -> usize {
        let mut seen: Vec<*const DisplacementMap> = Vec::new();
        let mut bytes = 0;
        for p in &self.prims {
            let map = match &p.shape {
                Shape::Displaced(d) => Some(d.map()),
                Shape::Curved(c) => Some(c.map()),
                _ => None,
            };
            if let Some(map) = map {
                let ptr = Arc::as_ptr(map);
                if !seen.contains(&ptr) {
                    seen.push(ptr);
                    bytes += map.memory_bytes();
                }
            }
        }
        bytes
    }

    /// Whether primitive `i` is a displaced face (flat or curved).
    pub fn is_displaced(&self, i: u32) -> bool {
        matches!(
            self.prims.get(i as usize).map(|p| &p.shape),
            Some(Shape::Displaced(_) | Shape::Curved(_))
        )
    }

    /// Whether anything lies on the ray within `[t_min, t_max]`.
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.bvh.traverse(ray, t_min, t_max, true, |i, t_max| {
            match &self.prims[i as usize].shape {
                // Any blocker ends the query: the value only has to be a
                // distance within the range.
                Shape::Displaced(d) => d.occludes(ray, t_min, t_max).then_some(t_min),
                Shape::Curved(c) => c.occludes(ray, t_min, t_max).then_some(t_min),
                _ => self.hit_prim(i, ray, t_min, t_max).map(|(t, _)| t),
            }
        })
    }

    pub(super) fn resolve(&self, i: u32, ray: &Ray, t: f32, local: Local) -> Interaction {
        self.resolve_with(i, ray, t, local, true)
    }

    /// [`Self::resolve`]; without `shading`, a displaced hit's shading
    /// normal is its geometric one and its texture is not sampled (what a
    /// geometric query such as `displace trace --scene` reports needs
    /// neither, and the normal map's sample is a fifth of a hit's cost).
    pub(super) fn resolve_with(
        &self,
        i: u32,
        ray: &Ray,
        t: f32,
        local: Local,
        shading: bool,
    ) -> Interaction {
        let prim = &self.prims[i as usize];
        let mut out = Interaction {
            t,
            position: ray.at(t),
            geometric_normal: Vec3::Z,
            shading_normal: Vec3::Z,
            uv: Vec2::ZERO,
            material: prim.material,
            emitter: prim.emitter,
            iterations: 0,
            tint: Vec3::ONE,
        };
        match (&prim.shape, local) {
            (Shape::Quad(q), Local::Param(uv)) => {
                out.position = q.point(uv);
                out.geometric_normal = q.normal;
                out.shading_normal = q.normal;
                out.uv = uv;
            }
            (Shape::Triangle { tri, attr }, Local::Param(b)) => {
                let n = tri.normal();
                out.position = tri.p0 + b.x * tri.e1 + b.y * tri.e2;
                out.geometric_normal = n;
                out.shading_normal = n;
                let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
                if *attr != NO_ATTR {
                    let a = &self.attrs[*attr as usize];
                    out.uv = a.uvs[0] * w.x + a.uvs[1] * w.y + a.uvs[2] * w.z;
                    if let Some(ns) = a.normals {
                        let s = (ns[0] * w.x + ns[1] * w.y + ns[2] * w.z).normalize_or_zero();
                        if s != Vec3::ZERO {
                            // Keep the interpolated normal on the geometric side.
                            out.shading_normal = if s.dot(n) < 0.0 { -s } else { s };
                        }
                    }
                } else {
                    out.uv = b;
                }
            }
            (Shape::Sphere(s), Local::Sphere) => {
                let n = (out.position - s.center) / s.radius;
                out.geometric_normal = n;
                out.shading_normal = n;
                out.uv = Sphere::uv(n);
            }
            (Shape::Displaced(_), Local::Map(_)) | (Shape::Curved(_), Local::Curved(_)) => {
                let (r, color) = match (&prim.shape, local) {
                    (Shape::Displaced(d), Local::Map(h)) if shading => (d.resolve(&h), &d.color),
                    (Shape::Displaced(d), Local::Map(h)) => (d.resolve_geometry(&h), &d.color),
                    (Shape::Curved(c), Local::Curved(h)) => (c.resolve(&h, shading), &c.color),
                    _ => unreachable!("matched above"),
                };
                return self.displaced_interaction(i, t, &r, color.as_deref(), shading);
            }
            _ => unreachable!("a hit is resolved by the shape that produced it"),
        }
        out
    }

    /// The interaction of a displaced (or curved) face's hit `r` on
    /// primitive `i` at distance `t`, its colour texture sampled when
    /// `shading`: shared by the one-hit [`Self::resolve_with`] and the
    /// eight-hit batches.
    pub(super) fn displaced_interaction(
        &self,
        i: u32,
        t: f32,
        r: &crate::faces::displaced::DisplacedHit,
        color: Option<&crate::texture::Texture>,
        shading: bool,
    ) -> Interaction {
        let prim = &self.prims[i as usize];
        Interaction {
            t,
            position: r.position,
            geometric_normal: r.geometric_normal,
            shading_normal: r.shading_normal,
            uv: r.uv,
            material: prim.material,
            emitter: prim.emitter,
            iterations: r.iterations,
            tint: match (shading, color) {
                (true, Some(tex)) => tex.sample(r.uv),
                _ => Vec3::ONE,
            },
        }
    }
}
