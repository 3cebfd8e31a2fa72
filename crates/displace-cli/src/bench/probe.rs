//! Ray sets for throughput benchmarks (BENCHMARKS.md): the camera
//! rays of a render whose nearest hit lies on a displaced face, and the
//! shadow rays those hits cast, generated exactly as [`displace_render::render()`] and
//! [`displace_render::integrators::whitted`] generate them (same jitter, same light strata, same
//! offsets). Timing [`Scene::intersect`] and [`Scene::occluded`] on them
//! apart from shading gives the speed of the intersection routine on
//! displaced surfaces, as rays per second (the ray-tracer paper reports only
//! whole rendering times, its section 4).

use displace_render::camera_sample::camera_sample;
use displace_render::error::{Error, Result};
use displace_render::geometry::Ray;
use displace_render::integrators::whitted::{facing, shadow_query};
use displace_render::scene::Scene;
use rayon::prelude::*;

/// A shadow ray and the distance past which occluders do not count.
#[derive(Clone, Copy, Debug)]
pub struct ShadowRay {
    /// The ray from the shaded point towards the light.
    pub ray: Ray,
    /// Distance to the light: occluders beyond it do not shadow.
    pub t_max: f32,
}

/// The rays of one render that meet displaced surfaces.
#[derive(Clone, Debug, Default)]
pub struct DisplacedRays {
    /// Camera rays of the render in all (every sample of every pixel).
    pub camera_total: usize,
    /// Camera rays whose nearest hit is on a displaced face.
    pub camera: Vec<Ray>,
    /// The shadow rays cast from those hits (they start inside the shell, so
    /// they exercise the tracer's inside start).
    pub shadow: Vec<ShadowRay>,
}

/// Most camera rays [`displaced_rays`] generates (about 2 GiB of rays kept
/// at worst): a benchmark that asks for more is refused before it allocates.
pub const MAX_CAMERA_RAYS: u64 = 1 << 26;

/// Every camera ray of `scene`'s full image and samples, kept where it meets
/// a displaced face, with the shadow rays shading would cast from there.
/// Runs in the current rayon pool.
pub fn displaced_rays(scene: &Scene) -> Result<DisplacedRays> {
    let total = scene.width() as u64 * scene.height() as u64 * scene.spp() as u64;
    if total > MAX_CAMERA_RAYS {
        return Err(Error::Option(format!(
            "{}x{} pixels at {} spp is {total} camera rays; benchmarks take at most {MAX_CAMERA_RAYS}",
            scene.width(), scene.height(), scene.spp()
        )));
    }
    let rows: Vec<DisplacedRays> = (0..scene.height())
        .into_par_iter()
        .map(|y| {
            let mut out = DisplacedRays::default();
            for x in 0..scene.width() {
                for s in 0..scene.spp() {
                    collect_sample(scene, x, y, s, &mut out);
                }
            }
            out
        })
        .collect();
    let mut all = DisplacedRays {
        camera_total: total as usize,
        ..DisplacedRays::default()
    };
    for r in rows {
        all.camera.extend(r.camera);
        all.shadow.extend(r.shadow);
    }
    Ok(all)
}

/// Replays `integrator::shade`'s direct-light loop for one pixel sample
/// (first hit only: reflection rays are not camera or shadow rays).
fn collect_sample(scene: &Scene, x: u32, y: u32, s: u32, out: &mut DisplacedRays) {
    let (ray, mut rng) = camera_sample(scene, x, y, s);
    let Some((prim, hit)) = scene.intersect_primitive(&ray, 0.0, f32::INFINITY) else {
        return;
    };
    if !scene.is_displaced(prim) {
        return;
    }
    out.camera.push(ray);
    let mat = &scene.materials()[hit.material as usize];
    if mat.albedo(hit.uv, hit.tint) == glam::Vec3::ZERO && mat.specular == glam::Vec3::ZERO {
        return;
    }
    let (ng, ns, p) = facing(scene, &ray, &hit);
    for light in scene.lights() {
        let n = light.samples(scene.shadow_samples());
        for i in 0..n {
            let Some(ls) = light.sample(hit.position, s * n + i, scene.spp() * n, &mut rng) else {
                continue;
            };
            if let Some(q) = shadow_query(scene, hit.position, p, ng, ns, ls.point) {
                out.shadow.push(ShadowRay {
                    ray: q.ray,
                    t_max: q.t_max,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_render::SceneOptions;

    /// The default scene's floor is displaced and lit by one area light:
    /// displaced camera rays exist, are a subset of all camera rays, and
    /// each casts at most `shadow_samples` shadow rays.
    #[test]
    fn default_scene_has_displaced_rays() {
        let scene = Scene::default_scene(&SceneOptions {
            spp: Some(1),
            size: Some([24, 24]),
            ..SceneOptions::default()
        })
        .unwrap();
        let r = displaced_rays(&scene).unwrap();
        assert_eq!(r.camera_total, 24 * 24);
        assert!(!r.camera.is_empty() && r.camera.len() < r.camera_total);
        assert!(!r.shadow.is_empty());
        assert_eq!(scene.lights().len(), 1);
        assert!(r.shadow.len() <= r.camera.len() * scene.shadow_samples() as usize);
        for ray in &r.camera {
            let (i, _) = scene.intersect_primitive(ray, 0.0, f32::INFINITY).unwrap();
            assert!(scene.is_displaced(i));
        }
    }
}
