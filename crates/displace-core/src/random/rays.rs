//! Seeded ray sets over one tile in map space, the rays `displace compare`,
//! `displace bench trace` and the trace benchmark measure with: the same
//! seed gives the same rays everywhere, so a figure in BENCHMARKS.md can be
//! measured again. The face is the tile `[0, ax] x [0, ay]` at the base of
//! the shell, whose top is `z = 1` (map space in shell depths, as Donnelly's
//! GPU Gems 2 ch. 8 distance map is addressed: [`crate::convention`]).

use super::SplitMix64;
use crate::MapRay;
use glam::{Vec2, Vec3};

/// Where each ray of a [`tile_rays`] set starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Start {
    /// At a uniformly random point of the tile at height `z` (the shell's
    /// top is 1): the rays a rasterised polygon of the shell starts, some of
    /// which leave the tile through its sides before meeting the surface.
    Above(f32),
    /// At height `z` on the line to a uniformly random point of the base:
    /// every ray meets the surface inside the tile, so a timing counts only
    /// hits.
    Aimed(f32),
}

/// How steep the rays of a [`tile_rays`] set fall, in degrees above the
/// face: grazing rays are where the marching techniques differ most
/// (Policarpo and Oliveira's relief mapping and its cones overshoot there).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Elevation {
    /// Every ray at this elevation.
    Fixed(f32),
    /// Uniform between the two elevations, one drawn per ray.
    Uniform(f32, f32),
}

/// The unit direction `elevation` radians above the face (falling towards
/// it), turned `azimuth` radians from +u towards +v.
pub fn downward(elevation: f32, azimuth: f32) -> Vec3 {
    Vec3::new(
        elevation.cos() * azimuth.cos(),
        elevation.cos() * azimuth.sin(),
        -elevation.sin(),
    )
}

/// `n` rays onto the tile of `aspect` (`Extent::aspect`) from the
/// [`SplitMix64`] stream of `seed`: per ray a point of the tile, an azimuth
/// uniform in `[0, 2 pi)` and, for [`Elevation::Uniform`], an elevation, in
/// that order.
pub fn tile_rays(
    aspect: [f32; 2],
    n: usize,
    seed: u64,
    start: Start,
    elevation: Elevation,
) -> Vec<MapRay> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let point = Vec2::new(rng.next_f32() * aspect[0], rng.next_f32() * aspect[1]);
            let azimuth = rng.next_f32() * std::f32::consts::TAU;
            let degrees = match elevation {
                Elevation::Fixed(d) => d,
                Elevation::Uniform(lo, hi) => lo + rng.next_f32() * (hi - lo),
            };
            let e = degrees.to_radians();
            let dir = downward(e, azimuth);
            match start {
                Start::Above(z) => MapRay::new(point.extend(z), dir),
                Start::Aimed(z) => MapRay::new(point.extend(0.0) - dir * (z / e.sin()), dir),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn elevation(r: &MapRay) -> f32 {
        (-r.dir.z).asin().to_degrees()
    }

    #[test]
    fn random_rays_start_above_the_shell_and_go_down() {
        let set = |seed| {
            tile_rays(
                [10.0, 5.0],
                1000,
                seed,
                Start::Above(1.0 + 1e-3),
                Elevation::Uniform(5.0, 90.0),
            )
        };
        let rays = set(7);
        assert_eq!(rays, set(7));
        assert_ne!(rays, set(8));
        for r in &rays {
            assert!(
                r.origin.z > 1.0
                    && (0.0..=10.0).contains(&r.origin.x)
                    && (0.0..=5.0).contains(&r.origin.y)
            );
            let elevation = elevation(r);
            assert!((4.99..=90.0).contains(&elevation), "{elevation}");
            assert!((r.dir.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn aimed_rays_reach_the_base_inside_the_tile() {
        let rays = tile_rays(
            [2.0, 3.0],
            500,
            1,
            Start::Aimed(1.05),
            Elevation::Fixed(30.0),
        );
        for r in &rays {
            assert!((r.origin.z - 1.05).abs() < 1e-5);
            assert!((elevation(r) - 30.0).abs() < 1e-3);
            let base = r.origin + r.dir * (r.origin.z / -r.dir.z);
            assert!(
                (-1e-4..=2.0001).contains(&base.x) && (-1e-4..=3.0001).contains(&base.y),
                "{base}"
            );
        }
    }
}
