//! Plain (undisplaced) shapes and their ray intersections.

use crate::geometry::{Aabb, Ray, Rays8, PACKET};
use glam::{Vec2, Vec3};

/// A parallelogram `origin + a edge_u + b edge_v`, `a, b` in `[0, 1]`.
#[derive(Clone, Copy, Debug)]
pub struct Quad {
    /// Corner at parameter `(0, 0)`.
    pub origin: Vec3,
    /// Edge along `u` (texture `u` on a displaced quad).
    pub edge_u: Vec3,
    /// Edge along `v`.
    pub edge_v: Vec3,
    /// Unit normal, `edge_u x edge_v` normalised.
    pub normal: Vec3,
    /// The dual basis of the edges in the quad's plane: with `w = n / (n .
    /// n)`, `n = edge_u x edge_v`, a point `h` from the corner has
    /// parallelogram coordinates `w . (h x edge_v) = h . (edge_v x w)` and
    /// `w . (edge_u x h) = h . (w x edge_u)` (Shirley, "Ray Tracing: The Next
    /// Week", with the triple products turned so that a hit costs two dot
    /// products instead of two cross products and two dot products).
    dual_u: Vec3,
    dual_v: Vec3,
    /// `|edge_u x edge_v|`, kept: light sampling asks for it at every
    /// vertex of every path.
    area: f32,
}

impl Quad {
    /// `None` for a degenerate (zero-area) parallelogram.
    pub fn new(origin: Vec3, edge_u: Vec3, edge_v: Vec3) -> Option<Self> {
        let n = edge_u.cross(edge_v);
        let nn = n.dot(n);
        if !nn.is_finite() || nn <= 0.0 {
            return None;
        }
        Some(Self {
            origin,
            edge_u,
            edge_v,
            normal: n / nn.sqrt(),
            dual_u: edge_v.cross(n / nn),
            dual_v: (n / nn).cross(edge_u),
            area: nn.sqrt(),
        })
    }

    /// Area, for sampling an area light by area.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Bounding box of the four corners.
    pub fn bounds(&self) -> Aabb {
        let (o, u, v) = (self.origin, self.edge_u, self.edge_v);
        Aabb::from_points([o, o + u, o + v, o + u + v])
    }

    /// Distance and parallelogram coordinates of the hit.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, Vec2)> {
        let (denom, t) = self.plane(ray.origin, ray.dir);
        if denom.abs() < 1e-12 {
            return None;
        }
        if !(t >= t_min && t <= t_max) {
            return None;
        }
        let ab = self.coordinates(ray.origin, ray.dir, t);
        Self::inside(ab).then_some((t, ab))
    }

    /// [`Quad::intersect`] of lanes `live` of `rays`, each within its own
    /// `t_max[l]`: the lanes that hit, with their distances and
    /// coordinates in `t` and `ab`. The same arithmetic lane by lane (the
    /// answers are [`Quad::intersect`]'s bit for bit), every lane computed
    /// and the misses masked, so that the compiler runs the lanes in vector
    /// registers.
    #[inline]
    pub fn intersect8(
        &self,
        rays: &Rays8,
        live: u32,
        t_min: f32,
        t_max: &[f32; PACKET],
        t: &mut [f32; PACKET],
        ab: &mut [Vec2; PACKET],
    ) -> u32 {
        let mut hit = [false; PACKET];
        for l in 0..PACKET {
            let v = |c: &[[f32; PACKET]; 3]| Vec3::new(c[0][l], c[1][l], c[2][l]);
            let (o, d) = (v(&rays.origin), v(&rays.dir));
            let (denom, tl) = self.plane(o, d);
            let c = self.coordinates(o, d, tl);
            // A NaN `denom` makes `tl` NaN, which the range refuses, as
            // the one-ray test does.
            hit[l] = denom.abs() >= 1e-12 && tl >= t_min && tl <= t_max[l] && Self::inside(c);
            t[l] = tl;
            ab[l] = c;
        }
        live & hit
            .iter()
            .enumerate()
            .fold(0, |m, (l, &h)| m | (u32::from(h) << l))
    }

    /// `n . d` and the distance to the quad's plane along `d` from `o`.
    #[inline(always)]
    fn plane(&self, o: Vec3, d: Vec3) -> (f32, f32) {
        let denom = self.normal.dot(d);
        (denom, self.normal.dot(self.origin - o) / denom)
    }

    /// Parallelogram coordinates of the ray's point at `t`.
    #[inline(always)]
    fn coordinates(&self, o: Vec3, d: Vec3, t: f32) -> Vec2 {
        let hp = (o + d * t) - self.origin;
        Vec2::new(hp.dot(self.dual_u), hp.dot(self.dual_v))
    }

    #[inline(always)]
    fn inside(ab: Vec2) -> bool {
        (0.0..=1.0).contains(&ab.x) && (0.0..=1.0).contains(&ab.y)
    }

    /// The point at parameter `uv`.
    pub fn point(&self, uv: Vec2) -> Vec3 {
        self.origin + uv.x * self.edge_u + uv.y * self.edge_v
    }
}

/// A triangle `p0, p0 + e1, p0 + e2`.
#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    /// First corner.
    pub p0: Vec3,
    /// Edge from `p0` to the second corner.
    pub e1: Vec3,
    /// Edge from `p0` to the third corner.
    pub e2: Vec3,
}

impl Triangle {
    /// The triangle with corners `p0, p1, p2`.
    pub fn new(p0: Vec3, p1: Vec3, p2: Vec3) -> Self {
        Self {
            p0,
            e1: p1 - p0,
            e2: p2 - p0,
        }
    }

    /// Bounding box of the three corners.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points([self.p0, self.p0 + self.e1, self.p0 + self.e2])
    }

    /// Unit normal `e1 x e2` (zero for a degenerate triangle). A large
    /// triangle's cross product (edges past about 1e9) has a squared length
    /// past single precision, and a tiny one's underflows: those are
    /// normalised from the product scaled to its largest component, so a
    /// triangle is degenerate only when its edges are parallel, not when it
    /// is large (a built-in sphere scaled by 5e10 lost three faces in four).
    pub fn normal(&self) -> Vec3 {
        let c = self.e1.cross(self.e2);
        let n = c.normalize_or_zero();
        if n != Vec3::ZERO || c == Vec3::ZERO || !c.is_finite() {
            return n;
        }
        (c / c.abs().max_element()).normalize_or_zero()
    }

    /// Möller-Trumbore: distance and barycentrics `(b1, b2)` of the hit.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, Vec2)> {
        let p = ray.dir.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-20 {
            return None;
        }
        let inv = 1.0 / det;
        let s = ray.origin - self.p0;
        let b1 = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&b1) {
            return None;
        }
        let q = s.cross(self.e1);
        let b2 = ray.dir.dot(q) * inv;
        if b2 < 0.0 || b1 + b2 > 1.0 {
            return None;
        }
        let t = self.e2.dot(q) * inv;
        (t >= t_min && t <= t_max).then_some((t, Vec2::new(b1, b2)))
    }
}

/// A sphere, shaded with its analytic normal.
#[derive(Clone, Copy, Debug)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3,
    /// Radius (positive).
    pub radius: f32,
}

impl Sphere {
    /// Bounding box.
    pub fn bounds(&self) -> Aabb {
        Aabb {
            min: self.center - Vec3::splat(self.radius),
            max: self.center + Vec3::splat(self.radius),
        }
    }

    /// Nearest hit distance within `[t_min, t_max]`, by the stable quadratic
    /// of Haines et al. (Ray Tracing Gems ch. 7), far from the origin too.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
        let oc = ray.origin - self.center;
        let half_b = oc.dot(ray.dir);
        // Hearn-Baker form of the discriminant: stable far from the origin
        // (Haines et al., "Precision Improvements for Ray/Sphere
        // Intersection", Ray Tracing Gems ch. 7).
        let f = oc - half_b * ray.dir;
        let disc = self.radius * self.radius - f.dot(f);
        if disc < 0.0 {
            return None;
        }
        let c = oc.dot(oc) - self.radius * self.radius;
        let q = -half_b - half_b.signum() * disc.sqrt();
        let (mut t0, mut t1) = (c / q, q);
        if q == 0.0 {
            t0 = 0.0;
            t1 = 0.0;
        }
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        [t0, t1].into_iter().find(|&t| t >= t_min && t <= t_max)
    }

    /// Longitude/latitude texture coordinate of unit normal `n`.
    pub fn uv(n: Vec3) -> Vec2 {
        Vec2::new(
            0.5 + n.z.atan2(n.x) / std::f32::consts::TAU,
            n.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI,
        )
    }
}

/// The six faces of an axis-aligned box `[min, max]`, rotated by `rotate_y`
/// degrees about its vertical centre line, each as a quad with an outward
/// normal.
pub fn box_faces(min: Vec3, max: Vec3, rotate_y: f32) -> Vec<Quad> {
    let c = 0.5 * (min + max);
    let rot = glam::Mat3::from_rotation_y(rotate_y.to_radians());
    let e = max - min;
    let (x, y, z) = (Vec3::X * e.x, Vec3::Y * e.y, Vec3::Z * e.z);
    let faces = [
        (min, z, y),     // -x
        (min + x, y, z), // +x
        (min, x, z),     // -y
        (min + y, z, x), // +y
        (min, y, x),     // -z
        (min + z, x, y), // +z
    ];
    faces
        .iter()
        .filter_map(|&(o, u, v)| Quad::new(c + rot * (o - c), rot * u, rot * v))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quad test in lanes answers as [`Quad::intersect`] does, lane by
    /// lane and bit for bit: hits, grazing rays, rays past their limits.
    #[test]
    fn quad_tests_in_lanes_are_the_one_ray_tests() {
        let mut rng = crate::sampler::Rng::new(21, 3);
        let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
        let mut hits = 0;
        for round in 0..3000 {
            let q = Quad::new(v() * 4.0, v() * 3.0, v() * 3.0).expect("an area");
            let rays: Vec<Ray> = (0..PACKET)
                .map(|l| {
                    let o = v() * 6.0;
                    // Some rays run in the quad's plane.
                    let mut d = q.point(Vec2::new(0.5, 0.5)) + v() * 2.0 - o;
                    if l == 3 {
                        d = q.edge_u + q.edge_v * 0.25;
                    }
                    Ray::new(o, d)
                })
                .collect();
            let index: Vec<u32> = (0..PACKET as u32).collect();
            let packet = Rays8::gather(&rays, &index);
            let limits: [f32; PACKET] = std::array::from_fn(|l| 0.5 + l as f32);
            let live = 0xff & !(1 << (round % PACKET));
            let (mut t, mut ab) = ([0.0; PACKET], [Vec2::ZERO; PACKET]);
            let m = q.intersect8(&packet, live, 0.01, &limits, &mut t, &mut ab);
            for (l, r) in rays.iter().enumerate() {
                let one = q
                    .intersect(r, 0.01, limits[l])
                    .filter(|_| live & (1 << l) != 0);
                assert_eq!(m & (1 << l) != 0, one.is_some(), "round {round} lane {l}");
                if let Some((t1, ab1)) = one {
                    assert_eq!((t[l].to_bits(), ab[l]), (t1.to_bits(), ab1));
                    hits += 1;
                }
            }
        }
        assert!(hits > 1500, "{hits}");
    }

    #[test]
    fn quad_hit_coordinates() {
        let q = Quad::new(
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 4.0, 0.0),
        )
        .unwrap();
        let r = Ray::new(Vec3::new(1.0, 1.0, 3.0), Vec3::NEG_Z);
        let (t, uv) = q.intersect(&r, 0.0, 10.0).unwrap();
        assert!((t - 3.0).abs() < 1e-6 && (uv - Vec2::new(0.5, 0.25)).length() < 1e-6);
        assert!(q
            .intersect(&Ray::new(Vec3::new(3.0, 1.0, 3.0), Vec3::NEG_Z), 0.0, 10.0)
            .is_none());
    }

    #[test]
    fn triangle_and_sphere() {
        let tri = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let (t, b) = tri
            .intersect(&Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::NEG_Z), 0.0, 5.0)
            .unwrap();
        assert!((t - 1.0).abs() < 1e-6 && (b - Vec2::splat(0.25)).length() < 1e-6);
        let s = Sphere {
            center: Vec3::ZERO,
            radius: 2.0,
        };
        let r = Ray::new(Vec3::new(0.0, 0.0, 10.0), Vec3::NEG_Z);
        assert!((s.intersect(&r, 0.0, 100.0).unwrap() - 8.0).abs() < 1e-5);
        let inside = Ray::new(Vec3::ZERO, Vec3::X);
        assert!((s.intersect(&inside, 1e-4, 100.0).unwrap() - 2.0).abs() < 1e-5);
    }

    #[test]
    fn box_faces_point_outwards() {
        let faces = box_faces(Vec3::ZERO, Vec3::ONE, 30.0);
        assert_eq!(faces.len(), 6);
        let c = Vec3::splat(0.5);
        for f in faces {
            let centre = f.point(Vec2::splat(0.5));
            assert!(f.normal.dot(centre - c) > 0.0);
        }
    }
}
