//! Displaced faces (the ray-tracer paper, sections 2.4 and 3.4, in
//! `docs/architecture.md`'s "References"): the face extruded by its depth
//! along its normal is the shell (a box for a parallelogram, a prism for a
//! triangle). A world ray is carried into the face's map space by the
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
//!
//! This replaces the ray-tracer paper's map translation (its section 3.2),
//! which projected each point onto the face and two of its sides: one
//! matrix each way, and the shell's five extra faces (its section 2.4)
//! become the map box (or prism) that the core's tracer clips against.
//! Donnelly's shaders do the same job on the GPU: the vertex shader carries
//! the eye vector into tangent space (section 8.5.1, listing 8-1) and the
//! fragment shader rescales it by the "normalization factor" `(depth/width,
//! depth/height, 1)` (section 8.5.2, listing 8-2); `M^-1` is both at once.

use crate::geometry::{Aabb, Ray};
use crate::texture::Texture;
use displace_core::sphere_trace::HitKind;
use displace_core::{Address, DisplacementMap, MapHit, MapRay, TraceOptions};
pub use displace_scene::placed::FaceFrame;
use displace_scene::placed::FlatDisplacement;
use glam::{Mat3, Vec2, Vec3};
use std::sync::Arc;

/// A displaced parallelogram or triangle as the renderer's primitive: its
/// shell's bounds for the BVH, its frame to and from map space, and the
/// shared [`DisplacementMap`] it is traced through.
///
/// This is the intersection routine of the ray-tracer paper (section 3.4)
/// recast: a ray that meets the shell is carried into map space and sphere
/// traced through the conservative distance map (Donnelly, section 8.3),
/// so shadow and reflection rays, which use the same routine, see the
/// displaced surface with nothing special (the paper's section 1.2).
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
    /// Base colour texture sampled at the hit's texture coordinate (the
    /// scene's `color_texture`); `None` leaves the material's own albedo.
    pub color: Option<Arc<Texture>>,
    /// A tangent-space normal map (+Y up, OpenGL) given in the scene, which
    /// then stands in for the normals baked from the height map (the
    /// ray-tracer paper's section 2.2 normal map); `None` uses the baked
    /// ones.
    pub normal_map: Option<Arc<Texture>>,
}

/// A world ray carried into a face's map space ([`DisplacedFace::map_query`]).
///
/// It exists so that the transform and the clip happen once, whether the
/// ray is then traced alone ([`DisplacedFace::intersect`]) or with others
/// in a batch, and [`MapQuery::finish`] brings any of those hits back.
#[derive(Clone, Copy, Debug)]
pub struct MapQuery {
    /// The ray in map space, unit direction, ready for the core's tracer.
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
    pub fn finish(&self, hit: MapHit) -> (f32, MapHit) {
        finish(self.entry, self.scale, hit)
    }
}

/// [`MapQuery::finish`] from the query's two fields that it reads, for
/// batches that keep their queries as columns.
#[inline]
pub(crate) fn finish(entry: Option<Vec3>, scale: f32, mut hit: MapHit) -> (f32, MapHit) {
    if hit.kind == HitKind::Wall {
        if let Some(n) = entry {
            hit.normal = n;
        }
    }
    (hit.t / scale, hit)
}

/// Eight values, one per lane of [`DisplacedFace::map_queries8`] and
/// [`DisplacedFace::world_geometry8`].
pub type Lanes8 = [f32; 8];

/// Eight world rays in map space as columns ([`DisplacedFace::map_queries8`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct MapQueries8 {
    /// Map-space origins, `x`, `y`, `z`.
    pub origin: [Lanes8; 3],
    /// Unit map-space directions.
    pub dir: [Lanes8; 3],
    /// `t_map = scale t_world`.
    pub scale: Lanes8,
    /// The clipped range in map units.
    pub t_min: Lanes8,
    /// See [`Self::t_min`].
    pub t_max: Lanes8,
    /// Whether the lane's ray has a map-space length (else no query).
    pub valid: [bool; 8],
}

/// What the renderer needs of a displaced hit, in world space.
///
/// The map-space [`MapHit`] carried back by the face's frame
/// ([`DisplacedFace::resolve`]), so that shading, shadow and reflection
/// rays start from it as from any other primitive's hit.
#[derive(Clone, Copy, Debug)]
pub struct DisplacedHit {
    /// World position of the hit on the displaced surface (or the shell's
    /// wall).
    pub position: Vec3,
    /// Unit world normal of the surface actually hit (the bilinear patch or
    /// the wall), carried by `M^-T`: the one that decides which side
    /// secondary rays leave from.
    pub geometric_normal: Vec3,
    /// Unit world normal for lighting: the normal map's (baked or given)
    /// at the hit, or the geometric normal on a wall.
    pub shading_normal: Vec3,
    /// Texture coordinate (tiles).
    pub uv: Vec2,
    /// Distance-map steps plus patches walked to find the hit: the cost
    /// that the `iterations` AOV shows (Donnelly's results, section 8.6,
    /// fix the steps at 16; the early-out tracer takes as many as it needs).
    pub iterations: u32,
    /// Whether the ray hit the shell's wall (the side of the solid slab
    /// under the surface) rather than the displaced surface: walls are lit
    /// by their own flat normal.
    pub wall: bool,
}

/// The face as the scene placed it, with its map-space frame inverted
/// and its shell's bounds found.
impl From<&FlatDisplacement> for DisplacedFace {
    fn from(f: &FlatDisplacement) -> Self {
        let (origin, to_world) = f.frame();
        let map = f.map().clone();
        let trace = f.trace_options();
        let [ax, ay] = map.aspect();
        let to_map = to_world.inverse();
        let prism = f.prism_uv().map(|t| t.map(|uv| uv * Vec2::new(ax, ay)));
        let bounds = Aabb::from_points(f.shell_corners());
        Self {
            origin,
            to_world,
            to_map,
            normal_to_world: to_map.transpose(),
            map,
            trace,
            prism,
            bounds,
            uv_offset: f.uv_offset(),
            color: f.color.clone(),
            normal_map: f.normal_map.clone(),
        }
    }
}

impl DisplacedFace {
    /// World bounds of the whole shell (base and top, with the prism's or
    /// box's corners), which the BVH (pbrt-v4 section 7.3) culls with:
    /// the ray-tracer paper's bounding box (section 2.4) as an AABB.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The displacement map the face is traced through, shared with every
    /// face that uses the same source and aspect (the bake cache); batch
    /// queries group faces by it and the GPU back end uploads it.
    pub fn map(&self) -> &Arc<DisplacementMap> {
        &self.map
    }

    /// `(origin, M)` of the frame `world = origin + M p` (module docs).
    pub fn frame(&self) -> (Vec3, Mat3) {
        (self.origin, self.to_world)
    }

    /// The face's trace settings (method, step count, tiles) before any
    /// clipping to a ray, so that other back ends (the GPU's) trace the face
    /// as this one does.
    pub fn trace_options(&self) -> TraceOptions {
        self.trace
    }

    /// Changes how the face is traced ([`displace_core::Method`]: the
    /// early-out sphere tracer, Donnelly's fixed loop of listing 8-2, or the
    /// exact reference) without rebuilding it, so that one scene can be
    /// rendered by each method and compared.
    pub fn set_method(&mut self, method: displace_core::Method) {
        self.trace.method = method;
    }

    /// First hit with world distance in `[t_min, t_max]`: the world distance
    /// and the map-space hit. A hit the map-space range admits but whose
    /// world distance rounds past `t_max` is dropped, as the batch queries
    /// drop it ([`crate::scene::batch`]): where a displaced face and a plain
    /// shape meet a ray at the same distance within rounding (a ray into
    /// the corner of a displaced floor and a wall), both queries then
    /// answer the same whichever they test first.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, MapHit)> {
        let query = self.map_query(ray, t_min, t_max)?;
        let hit = self.map.trace(&query.ray, &query.opts)?;
        Some(query.finish(hit)).filter(|&(t, _)| t <= t_max)
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

    /// The world position and unit geometric normal of a map-space hit:
    /// where it is, not how it is lit (what [`Self::resolve`] also
    /// reports as `position` and `geometric_normal`, computed alike).
    #[inline]
    pub fn world_geometry(&self, hit: &MapHit) -> (Vec3, Vec3) {
        (
            self.origin + self.to_world * hit.position,
            (self.normal_to_world * hit.normal).normalize(),
        )
    }

    /// [`Self::map_query`] for eight rays at once, each with its own
    /// range, as columns (`Lanes8`): the same arithmetic in the same order,
    /// written lane by lane over arrays so that the compiler keeps the
    /// eight in vector registers (the square roots and divisions of one
    /// ray's query are a chain of latencies; eight of them overlap).
    /// `None` for a triangle, whose prism clip stays one ray at a time.
    ///
    /// Lane `l` of the answer is `map_query(rays[l], t_min[l], t_max[l])`'s
    /// map ray, scale and clipped range when `valid[l]`, else `None` there.
    #[inline]
    pub fn map_queries8(
        &self,
        rays: &[&Ray; 8],
        t_min: &Lanes8,
        t_max: &Lanes8,
    ) -> Option<MapQueries8> {
        if self.prism.is_some() {
            return None;
        }
        let (rows, c) = (rows_of(&self.to_map), self.origin);
        let mut q = MapQueries8::default();
        let mut d = [[0.0f32; 8]; 3];
        for l in 0..8 {
            let v = rays[l].origin - c;
            let w = rays[l].dir;
            for a in 0..3 {
                let (x, y, z) = rows[a];
                q.origin[a][l] = x * v.x + y * v.y + z * v.z;
                d[a][l] = x * w.x + y * w.y + z * w.z;
            }
        }
        for l in 0..8 {
            let s = (d[0][l] * d[0][l] + d[1][l] * d[1][l] + d[2][l] * d[2][l]).sqrt();
            let inv = 1.0 / s;
            q.valid[l] = s > 0.0 && s.is_finite();
            q.scale[l] = s;
            for (dir, d) in q.dir.iter_mut().zip(&d) {
                dir[l] = d[l] * inv;
            }
            q.t_min[l] = t_min[l] * s;
            q.t_max[l] = t_max[l] * s;
        }
        Some(q)
    }

    /// The trace options of a query of [`Self::map_queries8`]'s lane `l`.
    #[inline]
    pub fn lane_options(&self, q: &MapQueries8, l: usize) -> TraceOptions {
        let mut opts = self.trace;
        opts.t_min = q.t_min[l];
        opts.t_max = q.t_max[l];
        opts
    }

    /// [`Self::world_geometry`] for eight hits at once (columns of their
    /// map-space positions and normals), lane by lane in the same order of
    /// operations, so the answers are the one-hit ones bit for bit.
    #[inline]
    pub fn world_geometry8(
        &self,
        position: &[Lanes8; 3],
        normal: &[Lanes8; 3],
    ) -> [[Lanes8; 3]; 2] {
        let pm = rows_of(&self.to_world);
        let base = self.origin.to_array();
        let mut p = [[0.0f32; 8]; 3];
        for l in 0..8 {
            for a in 0..3 {
                let (x, y, z) = pm[a];
                p[a][l] = base[a] + (x * position[0][l] + y * position[1][l] + z * position[2][l]);
            }
        }
        [p, self.normals_to_world8(normal)]
    }

    /// `(normal_to_world * n).normalize()` for eight map-space directions
    /// (columns), in glam's order of operations, lane by lane.
    #[inline]
    fn normals_to_world8(&self, normal: &[Lanes8; 3]) -> [Lanes8; 3] {
        let nm = rows_of(&self.normal_to_world);
        let mut n = [[0.0f32; 8]; 3];
        for l in 0..8 {
            for a in 0..3 {
                let (x, y, z) = nm[a];
                n[a][l] = x * normal[0][l] + y * normal[1][l] + z * normal[2][l];
            }
        }
        let mut out = [[0.0f32; 8]; 3];
        for l in 0..8 {
            let len = (n[0][l] * n[0][l] + n[1][l] * n[1][l] + n[2][l] * n[2][l]).sqrt();
            let inv = 1.0 / len;
            for a in 0..3 {
                out[a][l] = n[a][l] * inv;
            }
        }
        out
    }

    /// [`Self::resolve`] for eight hits at once: the world positions and
    /// both normals as columns (the baked normals' blend and its carry to
    /// the world in lanes, [`displace_core::NormalMap::blend8`]), in the
    /// one-hit order of operations, so lane `l` is `resolve(hits[l])` bit
    /// for bit. A scene's normal map is sampled hit by hit.
    pub fn resolve8(&self, hits: &[&MapHit; 8]) -> [DisplacedHit; 8] {
        let column = |f: fn(&MapHit) -> Vec3| -> [Lanes8; 3] {
            let v = hits.map(f);
            [v.map(|p| p.x), v.map(|p| p.y), v.map(|p| p.z)]
        };
        let [p, ng] = self.world_geometry8(&column(|h| h.position), &column(|h| h.normal));
        let uv = hits.map(|h| h.uv + self.uv_offset);
        let ns = match self.normal_map.as_deref() {
            Some(tex) => {
                let n: [Vec3; 8] = std::array::from_fn(|l| {
                    (tex.sample(uv[l]) * 2.0 - Vec3::ONE).normalize_or(Vec3::Z)
                });
                self.normals_to_world8(&[n.map(|v| v.x), n.map(|v| v.y), n.map(|v| v.z)])
            }
            None => {
                let st = hits.map(|h| match self.map.address() {
                    Address::Repeat => Vec2::new(h.uv.x.rem_euclid(1.0), h.uv.y.rem_euclid(1.0)),
                    Address::Clamp => h.uv,
                });
                let n = self.map.normals.blend8(&st.map(|s| s.x), &st.map(|s| s.y));
                self.normals_to_world8(&n)
            }
        };
        let at = |v: &[Lanes8; 3], l: usize| Vec3::new(v[0][l], v[1][l], v[2][l]);
        std::array::from_fn(|l| {
            let wall = hits[l].kind == HitKind::Wall;
            let geometric_normal = at(&ng, l);
            DisplacedHit {
                position: at(&p, l),
                geometric_normal,
                shading_normal: if wall { geometric_normal } else { at(&ns, l) },
                uv: uv[l],
                iterations: hits[l].iterations,
                wall,
            }
        })
    }

    /// [`Self::resolve`] without the shading normal (the geometric normal
    /// stands in for it): where a hit is, not how it is lit.
    pub fn resolve_geometry(&self, hit: &MapHit) -> DisplacedHit {
        let (position, geometric_normal) = self.world_geometry(hit);
        DisplacedHit {
            position,
            geometric_normal,
            shading_normal: geometric_normal,
            uv: hit.uv + self.uv_offset,
            iterations: hit.iterations,
            wall: hit.kind == HitKind::Wall,
        }
    }

    /// The world-space description of a map-space hit.
    pub fn resolve(&self, hit: &MapHit) -> DisplacedHit {
        let (position, geometric_normal) = self.world_geometry(hit);
        let uv = hit.uv + self.uv_offset;
        let wall = hit.kind == HitKind::Wall;
        let shading_normal = if wall {
            geometric_normal
        } else {
            let n_map = map_shading_direction(&self.map, self.normal_map.as_deref(), hit.uv, uv);
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

/// The map-space shading normal of a hit at texture coordinate `local_uv`
/// (tiles of the face's map window; `uv` with the window's offset added):
/// the scene's normal map at `uv` (+Y up, the ray-tracer paper's section
/// 2.2), else the baked normals' blend, not yet renormalised (the caller
/// carries it to the world and normalises there).
pub(crate) fn map_shading_direction(
    map: &DisplacementMap,
    normal_map: Option<&Texture>,
    local_uv: Vec2,
    uv: Vec2,
) -> Vec3 {
    match normal_map {
        Some(tex) => (tex.sample(uv) * 2.0 - Vec3::ONE).normalize_or(Vec3::Z),
        None => {
            let st = match map.address() {
                Address::Repeat => {
                    Vec2::new(local_uv.x.rem_euclid(1.0), local_uv.y.rem_euclid(1.0))
                }
                Address::Clamp => local_uv,
            };
            map.shading_direction(st)
        }
    }
}

/// The rows of `m`: `(m * v)[a]` is `x v.x + y v.y + z v.z` with `(x, y,
/// z) = rows_of(m)[a]`, summed left to right as glam's `Mat3 * Vec3` sums
/// its columns, so lane-by-lane code gives its answers bit for bit.
fn rows_of(m: &Mat3) -> [(f32, f32, f32); 3] {
    [
        (m.x_axis.x, m.y_axis.x, m.z_axis.x),
        (m.x_axis.y, m.y_axis.y, m.z_axis.y),
        (m.x_axis.z, m.y_axis.z, m.z_axis.z),
    ]
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
