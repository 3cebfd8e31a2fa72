//! Batch ray queries against a whole scene, the interface Embree's users
//! know (`rtcIntersect` for the first hit, `rtcOccluded` for shadow rays),
//! shared by `displace trace --scene` and the Python package so that both
//! answer the same rays with the same bits.
//!
//! Rays are in the scene's world frame: origin, direction and `t_max`, with
//! `t` measured along the direction *as given* (`hit = origin + t dir`); an
//! infinite `t_max` is unbounded. A first hit is a row `[t, x, y, z, nx,
//! ny, nz, shape]`: `t` (inf on a miss), the hit position, the geometric
//! normal (unit, as the shape defines it, not turned towards the ray) and
//! the index of the shape in the file's `[[shapes]]` list ([`MISS`] on a
//! miss, [`LIGHT`] on a visible area light's quad).

use crate::geometry::{Ray, PACKET};
use crate::scene::batch::{Batch, GeometryHit};
use crate::Scene;
use glam::Vec3;

/// What a miss reports in the shape column.
pub const MISS: f32 = -1.0;
/// What a hit on a visible area light's quad reports in the shape column.
pub const LIGHT: f32 = -2.0;

/// Rays per batch query: enough for the packets of each face to fill.
pub const BATCH: usize = 64;

/// One world ray `[origin, direction, t_max]`: the unit ray and its length limit in world
/// units (`t_max` is given in units of the direction's length).
pub fn world_ray(r: &[f32; 7]) -> (Ray, f32, f32) {
    let dir = Vec3::new(r[3], r[4], r[5]);
    let len = dir.length();
    (
        Ray::from_unit(Vec3::new(r[0], r[1], r[2]), dir / len),
        r[6] * len,
        len,
    )
}

/// [`world_ray`] of eight rays at once, the lengths, the divisions and
/// the reciprocals (a square root and six divisions a ray) as columns in
/// vector lanes: lane `l` is `world_ray(&r[l])` bit for bit, the same
/// operations in the same order.
pub fn world_rays8(r: &[[f32; 7]; PACKET]) -> [(Ray, f32, f32); PACKET] {
    let mut d: [[f32; PACKET]; 3] = std::array::from_fn(|a| r.map(|r| r[3 + a]));
    let mut len = [0.0f32; PACKET];
    for l in 0..PACKET {
        len[l] = (d[0][l] * d[0][l] + d[1][l] * d[1][l] + d[2][l] * d[2][l]).sqrt();
    }
    let mut inv = [[0.0f32; PACKET]; 3];
    for (c, i) in d.iter_mut().zip(&mut inv) {
        for l in 0..PACKET {
            c[l] /= len[l];
            i[l] = 1.0 / c[l];
        }
    }
    std::array::from_fn(|l| {
        let ray = Ray {
            origin: Vec3::new(r[l][0], r[l][1], r[l][2]),
            dir: Vec3::new(d[0][l], d[1][l], d[2][l]),
            inv_dir: Vec3::new(inv[0][l], inv[1][l], inv[2][l]),
        };
        (ray, r[l][6] * len[l], len[l])
    })
}

/// What one thread's batches reuse: the batch queries' buffers, the world
/// rays of a batch ([`world_ray`]: rays, limits, directions' lengths) and
/// their answers, so a batch allocates nothing after the first.
#[derive(Default)]
pub struct Scratch {
    batch: Batch,
    rays: Vec<Ray>,
    limits: Vec<f32>,
    lens: Vec<f32>,
    hits: Vec<Option<GeometryHit>>,
    blocked: Vec<bool>,
}

impl Scratch {
    fn load(&mut self, rays: &[[f32; 7]]) {
        self.rays.clear();
        self.limits.clear();
        self.lens.clear();
        let mut push = |(ray, t_max, len): (Ray, f32, f32)| {
            self.rays.push(ray);
            self.limits.push(t_max);
            self.lens.push(len);
        };
        let mut eights = rays.chunks_exact(PACKET);
        for r in &mut eights {
            world_rays8(r.try_into().expect("chunks of eight"))
                .into_iter()
                .for_each(&mut push);
        }
        eights.remainder().iter().map(world_ray).for_each(push);
    }
}

/// The first hits of a batch of world rays, each `[t, x, y, z, nx, ny,
/// nz, shape]`, into `out` (8 values a ray).
pub fn first_hits(scene: &Scene, rays: &[[f32; 7]], sc: &mut Scratch, out: &mut [f32]) {
    sc.load(rays);
    scene.intersect_geometry_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.hits);
    // Rows as arrays: a slice copy of eight values is a call to `memcpy`.
    for ((o, hit), &len) in out.chunks_exact_mut(8).zip(&sc.hits).zip(&sc.lens) {
        let o: &mut [f32; 8] = o.try_into().expect("rows of eight values");
        *o = row(scene, hit, len);
    }
}

/// Whether anything blocks each of a batch of world rays within `(0,
/// t_max)`: 1 or 0 each, into `out`.
pub fn blocked_many(scene: &Scene, rays: &[[f32; 7]], sc: &mut Scratch, out: &mut [f32]) {
    sc.load(rays);
    scene.occluded_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.blocked);
    for (o, &b) in out.iter_mut().zip(&sc.blocked) {
        *o = f32::from(u8::from(b));
    }
}

/// A hit as a row of the hits file.
pub fn row(scene: &Scene, hit: &Option<GeometryHit>, len: f32) -> [f32; 8] {
    match hit {
        Some(hit) => {
            let (p, n) = (hit.position, hit.normal);
            let shape = scene.shape_of(hit.prim).map_or(LIGHT, |k| k as f32);
            [hit.t / len, p.x, p.y, p.z, n.x, n.y, n.z, shape]
        }
        None => [
            f32::INFINITY,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            MISS,
        ],
    }
}

/// [`first_hits`] for any number of rays on the current rayon pool: batches
/// of [`BATCH`] rays in order, each traced eight at a time through the
/// displaced faces. A ray's answer is the one-ray query's whatever its
/// batch, so `out` (8 values a ray) does not depend on the thread count.
pub fn first_hits_all(scene: &Scene, rays: &[[f32; 7]], out: &mut [f32]) {
    use rayon::prelude::*;
    out.par_chunks_mut(8 * BATCH)
        .zip(rays.par_chunks(BATCH))
        .for_each_init(Scratch::default, |b, (o, r)| first_hits(scene, r, b, o));
}

/// [`blocked_many`] for any number of rays on the current rayon pool, as
/// [`first_hits_all`] runs them: 1 or 0 a ray into `out`.
pub fn blocked_all(scene: &Scene, rays: &[[f32; 7]], out: &mut [f32]) {
    use rayon::prelude::*;
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .for_each_init(Scratch::default, |b, (o, r)| blocked_many(scene, r, b, o));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::sampler::Rng;

    /// Eight world rays in lanes are the one-ray ones bit for bit, on
    /// directions of every length from a thousandth to a thousand and
    /// along the axes (where a reciprocal is infinite).
    #[test]
    fn eight_world_rays_in_lanes_are_the_one_ray_ones() {
        let mut rng = Rng::new(20261207, 11);
        let mut u = || 2.0 * rng.next_f32() - 1.0;
        for round in 0..2000 {
            let rays: [[f32; 7]; PACKET] = std::array::from_fn(|l| {
                let scale = 10f32.powf(3.0 * u());
                let mut r = [
                    u(),
                    u(),
                    u(),
                    u() * scale,
                    u() * scale,
                    u() * scale,
                    1.0 + u(),
                ];
                if round % 7 == 0 && l < 3 {
                    r[3..6].copy_from_slice(&[0.0; 3]);
                    r[3 + l] = scale;
                }
                r
            });
            let bits = |(r, t, len): (Ray, f32, f32)| {
                let v = [r.origin, r.dir, r.inv_dir].map(|v| v.to_array().map(f32::to_bits));
                (v, t.to_bits(), len.to_bits())
            };
            for (lane, ray) in world_rays8(&rays).into_iter().zip(&rays) {
                assert_eq!(bits(lane), bits(world_ray(ray)), "{ray:?}");
            }
        }
    }
}
