//! The camera rays of a pixel's samples: each sample's film and lens
//! positions from its own seeded generator (`(seed, x, y, sample)`), so a
//! render does not depend on thread count or tiling, and the same rays
//! whichever integrator traces them (the benchmarks' ray sets replay them).

use crate::geometry::Ray;
use crate::scene::Scene;
use crate::shading::sampler::{jittered, Rng};
use glam::Vec2;

/// The camera ray of sample `s` of pixel `(x, y)` and the generator the
/// rest of that sample's path draws from.
pub fn camera_sample(scene: &Scene, x: u32, y: u32, s: u32) -> (Ray, Rng) {
    let mut rng = Rng::for_sample(scene.seed, x, y, s);
    let j = jittered(s, scene.spp, &mut rng);
    let lens = rng.next_2d();
    (camera_ray(scene, x, y, j, lens), rng)
}

/// The camera ray through offset `jitter` (in `[0, 1)^2`) of pixel `(x, y)`
/// and point `lens` of the lens.
pub fn camera_ray(scene: &Scene, x: u32, y: u32, jitter: Vec2, lens: Vec2) -> Ray {
    let film = Vec2::new(
        (x as f32 + jitter.x) / scene.width as f32,
        (y as f32 + jitter.y) / scene.height as f32,
    );
    scene.camera.ray(film, lens)
}
