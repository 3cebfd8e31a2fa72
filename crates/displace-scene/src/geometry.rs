//! Rays, boxes and small vector helpers shared by every shape.

use glam::Vec3;

/// A ray `origin + t dir`, with the reciprocal direction the slab test needs.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Where the ray starts.
    pub origin: Vec3,
    /// Unit length.
    pub dir: Vec3,
    /// `1 / dir` per component (infinite where `dir` is 0), for [`Aabb::hit`].
    pub inv_dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here).
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self::from_unit(origin, dir.normalize())
    }

    /// A ray whose direction is already unit length (normalising it again
    /// would cost a square root and a division a ray).
    #[inline]
    pub fn from_unit(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            inv_dir: dir.recip(),
        }
    }

    /// [`Ray::new`] of eight rays at once: the normalisation and the
    /// reciprocals (a square root and four divisions a ray, a long
    /// dependent chain when done one ray at a time) as columns, so that
    /// they run in vector lanes (Wald et al. 2001, section 3, on coherent
    /// rays as packets). Lane `l` is `Ray::new(origin[l], dir[l])` bit for
    /// bit: the same operations in the same order.
    pub fn new8(origin: &[Vec3; PACKET], dir: &[Vec3; PACKET]) -> [Ray; PACKET] {
        let mut d: [[f32; PACKET]; 3] = [dir.map(|v| v.x), dir.map(|v| v.y), dir.map(|v| v.z)];
        let mut inv_len = [0.0f32; PACKET];
        for l in 0..PACKET {
            let dot = d[0][l] * d[0][l] + d[1][l] * d[1][l] + d[2][l] * d[2][l];
            inv_len[l] = 1.0 / dot.sqrt();
        }
        let mut inv = [[0.0f32; PACKET]; 3];
        for (c, i) in d.iter_mut().zip(&mut inv) {
            for l in 0..PACKET {
                c[l] *= inv_len[l];
                i[l] = 1.0 / c[l];
            }
        }
        std::array::from_fn(|l| Ray {
            origin: origin[l],
            dir: Vec3::new(d[0][l], d[1][l], d[2][l]),
            inv_dir: Vec3::new(inv[0][l], inv[1][l], inv[2][l]),
        })
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Rays per packet of [`Rays8`].
pub const PACKET: usize = 8;

/// Up to eight rays as columns (structure of arrays): what the packet
/// walk of a BVH and the lane tests of plain shapes read, one component
/// of every ray at a time, so that a box or a quad is tested against all
/// eight rays in vector lanes (Wald, Slusallek, Benthin and Wagner 2001,
/// "Interactive rendering with coherent ray tracing", section 3).
///
/// Lanes past the rays given repeat the first ray; a packet's mask says
/// which lanes are real.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rays8 {
    /// Origins, `[axis][lane]`.
    pub origin: [[f32; PACKET]; 3],
    /// Unit directions, `[axis][lane]`.
    pub dir: [[f32; PACKET]; 3],
    /// Reciprocal directions, `[axis][lane]`.
    pub inv_dir: [[f32; PACKET]; 3],
}

impl Rays8 {
    /// The rays `rays[index[l]]` as lanes `l` (at most eight, at least one).
    pub fn gather(rays: &[Ray], index: &[u32]) -> Self {
        debug_assert!(!index.is_empty() && index.len() <= PACKET);
        let mut r = Rays8::default();
        for l in 0..PACKET {
            let ray = &rays[index[l.min(index.len() - 1)] as usize];
            for (a, (o, (d, i))) in r
                .origin
                .iter_mut()
                .zip(r.dir.iter_mut().zip(r.inv_dir.iter_mut()))
                .enumerate()
            {
                o[l] = ray.origin[a];
                d[l] = ray.dir[a];
                i[l] = ray.inv_dir[a];
            }
        }
        r
    }

    /// Lane `l` as a [`Ray`].
    #[inline]
    pub fn lane(&self, l: usize) -> Ray {
        let v = |c: &[[f32; PACKET]; 3]| Vec3::new(c[0][l], c[1][l], c[2][l]);
        Ray {
            origin: v(&self.origin),
            dir: v(&self.dir),
            inv_dir: v(&self.inv_dir),
        }
    }
}

/// An axis-aligned box, the bounding volume of the BVH.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Aabb {
    /// The box of nothing: the identity of [`Aabb::union`] and [`Aabb::grow`].
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The smallest box holding `points`.
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, Self::grow)
    }

    /// This box grown to hold `p`.
    #[inline]
    pub fn grow(self, p: Vec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    #[inline]
    pub fn union(self, o: Aabb) -> Self {
        Self {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Centre of the box, which the SAH bins by.
    #[inline]
    pub fn centroid(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Surface area, the cost model of the SAH.
    #[inline]
    pub fn area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3::ZERO);
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// True for [`Aabb::EMPTY`] (and any box with `min > max`).
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    /// Entry distance of `ray` into the box if it meets it within
    /// `[t_min, t_max]` (slab test; NaN-safe through `min`/`max` ordering).
    #[inline]
    pub fn hit(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
        let (t_in, t_out) = self.slab(ray.origin, ray.inv_dir, t_min, t_max);
        (t_in <= t_out).then_some(t_in)
    }

    /// [`Aabb::hit`] of each lane of `rays`: bit `l` set where lane `l`
    /// meets the box with `t` in `[t_min, t_max[l]]`. The same slab test
    /// ([`Aabb::slab`]) lane by lane, so the answers are [`Aabb::hit`]'s
    /// bit for bit; written over columns so that the compiler runs the
    /// lanes in vector registers.
    #[inline]
    pub fn hit8(&self, rays: &Rays8, t_min: f32, t_max: &[f32; PACKET]) -> u32 {
        let mut inside = [false; PACKET];
        for (l, inside) in inside.iter_mut().enumerate() {
            let v = |c: &[[f32; PACKET]; 3]| Vec3::new(c[0][l], c[1][l], c[2][l]);
            let (t_in, t_out) = self.slab(v(&rays.origin), v(&rays.inv_dir), t_min, t_max[l]);
            *inside = t_in <= t_out;
        }
        inside
            .iter()
            .enumerate()
            .fold(0, |m, (l, &b)| m | (u32::from(b) << l))
    }

    /// Where a ray from `origin` with reciprocal direction `inv_dir`
    /// enters and leaves the box within `[t_min, t_max]` (Kay and Kajiya's
    /// slabs; it misses where the entry lies past the exit).
    #[inline(always)]
    fn slab(&self, origin: Vec3, inv_dir: Vec3, t_min: f32, t_max: f32) -> (f32, f32) {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        let tn = t0.min(t1);
        let tf = t0.max(t1);
        (tn.max_element().max(t_min), tf.min_element().min(t_max))
    }
}

/// An orthonormal basis around unit `n` (Duff et al., "Building an
/// Orthonormal Basis, Revisited", JCGT 2017).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// `d` mirrored about unit normal `n` (Whitted's reflection ray).
#[inline]
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::X, Vec3::NEG_Z, Vec3::new(0.3, -0.4, 0.5).normalize()] {
            let (t, b) = basis(n);
            assert!(t.dot(n).abs() < 1e-6 && b.dot(n).abs() < 1e-6 && t.dot(b).abs() < 1e-6);
            assert!((t.length() - 1.0).abs() < 1e-6 && (b.length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn box_slab_test() {
        let b = Aabb::from_points([Vec3::ZERO, Vec3::ONE]);
        let r = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
        assert_eq!(b.hit(&r, 0.0, 10.0), Some(1.0));
        assert_eq!(b.hit(&r, 0.0, 0.5), None);
        let axis = Ray::new(Vec3::new(0.5, 2.0, -1.0), Vec3::Z);
        assert_eq!(b.hit(&axis, 0.0, 10.0), None);
    }
}
