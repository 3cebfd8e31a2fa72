//! The camera rays of a pixel's samples: each sample's film and lens
//! positions from its own seeded generator (`(seed, x, y, sample)`), so a
//! render does not depend on thread count or tiling, and the same rays
//! whichever integrator traces them (the benchmarks' ray sets replay them).

use crate::geometry::{Ray, PACKET};
use crate::scene::Scene;
use crate::shading::sampler::{jittered, strata, Rng};
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

/// [`camera_sample`] of eight samples `(x, y, s)` at once: each sample's
/// generator drawn from as in the one-sample call, then the strata's
/// divisions and [`camera_rays8`] as columns in vector lanes. Lane `l`
/// is `camera_sample(scene, x, y, s)` of `samples[l]` bit for bit, its
/// generator left in the same state.
pub fn camera_samples8(
    scene: &Scene,
    samples: &[(u32, u32, u32); PACKET],
) -> ([Ray; PACKET], [Rng; PACKET]) {
    let (nx, ny) = strata(scene.spp);
    let (nx_f, ny_f) = (nx as f32, ny as f32);
    let mut rngs: [Rng; PACKET] = std::array::from_fn(|l| {
        let (x, y, s) = samples[l];
        Rng::for_sample(scene.seed, x, y, s)
    });
    // `jittered`'s arithmetic, column by column.
    let mut jx = [0.0f32; PACKET];
    let mut jy = [0.0f32; PACKET];
    let mut lens = [Vec2::ZERO; PACKET];
    for (l, rng) in rngs.iter_mut().enumerate() {
        let s = samples[l].2;
        let j = rng.next_2d();
        lens[l] = rng.next_2d();
        jx[l] = (s % nx) as f32 + j.x;
        jy[l] = ((s / nx) % ny) as f32 + j.y;
    }
    for l in 0..PACKET {
        jx[l] /= nx_f;
        jy[l] /= ny_f;
    }
    let jitter = std::array::from_fn(|l| Vec2::new(jx[l], jy[l]));
    let pixels = samples.map(|(x, y, _)| (x, y));
    (camera_rays8(scene, &pixels, &jitter, &lens), rngs)
}

/// [`camera_ray`] of eight pixels' film offsets `jitter` and lens points
/// `lens` at once, the film's divisions and the rays' normalisation as
/// columns in vector lanes: lane `l` is `camera_ray(scene, x, y,
/// jitter[l], lens[l])` of `pixels[l]` bit for bit. For samplers that draw
/// their offsets otherwise ([`camera_samples8`] draws strata).
pub fn camera_rays8(
    scene: &Scene,
    pixels: &[(u32, u32); PACKET],
    jitter: &[Vec2; PACKET],
    lens: &[Vec2; PACKET],
) -> [Ray; PACKET] {
    let (w, h) = (scene.width as f32, scene.height as f32);
    let mut fx = [0.0f32; PACKET];
    let mut fy = [0.0f32; PACKET];
    for l in 0..PACKET {
        fx[l] = (pixels[l].0 as f32 + jitter[l].x) / w;
        fy[l] = (pixels[l].1 as f32 + jitter[l].y) / h;
    }
    let film = std::array::from_fn(|l| Vec2::new(fx[l], fy[l]));
    scene.camera.ray8(&film, lens)
}
