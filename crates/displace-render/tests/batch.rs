//! The batch queries (`Scene::intersect_many`, `occluded_many`) against the
//! one-ray ones on the scenes of `scenes/`: every ray's nearest hit (primitive,
//! distance, position, normals) and any-hit answer are the same.

mod common;

use common::{opts, scenes_dir};
use displace_core::random::SplitMix64;
use displace_render::geometry::Ray;
use displace_render::scene::batch::Batch;
use displace_render::Scene;
use glam::{Vec2, Vec3};

/// Camera rays through random film points, and from their hits rays in
/// random directions (the shadow and reflection rays of a render), with
/// random length limits.
fn rays(scene: &Scene, n: usize, seed: u64) -> Vec<(Ray, f32)> {
    let mut rng = SplitMix64::new(seed);
    let mut out = Vec::new();
    while out.len() < n {
        let film = Vec2::new(rng.next_f32(), rng.next_f32());
        let ray = scene.camera().ray(film, Vec2::splat(0.5));
        let limit = if rng.next_f32() < 0.3 {
            rng.next_f32() * 4.0
        } else {
            f32::INFINITY
        };
        out.push((ray, limit));
        if let Some(hit) = scene.intersect(&ray, 0.0, f32::INFINITY) {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let n = if hit.geometric_normal.dot(ray.dir) > 0.0 {
                -hit.geometric_normal
            } else {
                hit.geometric_normal
            };
            let dir = if d.dot(n) < 0.0 {
                d - 2.0 * d.dot(n) * n
            } else {
                d
            };
            if dir.length() > 1e-3 {
                out.push((Ray::new(hit.position + n * 1e-4, dir), rng.next_f32() * 2.0));
            }
        }
    }
    out
}

#[test]
fn batches_answer_as_the_one_ray_queries_do() {
    for name in [
        "cornell_studded_shadows.toml",
        "cornell_gaussian.toml",
        "gpu_meshes.toml",
    ] {
        let mut o = opts();
        o.size = Some([48, 48]);
        let scene = Scene::load(&scenes_dir().join(name), &o).unwrap();
        let rays = rays(&scene, 600, 11);
        let (world, limits): (Vec<Ray>, Vec<f32>) = rays.iter().copied().unzip();
        let mut batch = Batch::default();
        let mut hits = Vec::new();
        let mut geometry = Vec::new();
        let mut blocked = Vec::new();
        // Batches of uneven sizes, the scratch reused between them.
        let mut start = 0;
        let mut found = 0;
        for size in [1usize, 7, 8, 9, 64, 200].iter().cycle() {
            if start >= world.len() {
                break;
            }
            let end = (start + size).min(world.len());
            let (w, l, b) = (&world[start..end], &limits[start..end], &mut batch);
            scene.intersect_many(w, 0.0, l, b, &mut hits);
            scene.intersect_geometry_many(w, 0.0, l, b, &mut geometry);
            scene.occluded_many(w, 0.0, l, b, &mut blocked);
            for (k, r) in (start..end).enumerate() {
                let one = scene.intersect_primitive(&world[r], 0.0, limits[r]);
                match (&hits[k], &one) {
                    (Some((pa, a)), Some((pb, b))) => {
                        assert_eq!(pa, pb, "{name} ray {r}: primitive");
                        assert_eq!(a.t, b.t, "{name} ray {r}: t");
                        assert_eq!(a.position, b.position, "{name} ray {r}");
                        assert_eq!(a.geometric_normal, b.geometric_normal, "{name} ray {r}");
                        assert_eq!(a.shading_normal, b.shading_normal, "{name} ray {r}");
                        assert_eq!(a.uv, b.uv, "{name} ray {r}");
                        let g = geometry[k].expect("the geometric query finds the hit");
                        assert_eq!((g.prim, g.t), (*pb, b.t), "{name} ray {r}: geometry");
                        assert_eq!(g.position, b.position, "{name} ray {r}: geometry");
                        assert_eq!(g.normal, b.geometric_normal, "{name} ray {r}: geometry");
                        found += 1;
                    }
                    (None, None) => assert!(geometry[k].is_none(), "{name} ray {r}"),
                    (a, b) => panic!("{name} ray {r}: batch {a:?} one ray {b:?}"),
                }
                assert_eq!(
                    blocked[k],
                    scene.occluded(&world[r], 0.0, limits[r]),
                    "{name} ray {r}: any-hit"
                );
            }
            start = end;
        }
        assert!(found > rays.len() / 4, "{name}: only {found} hits");
    }
}
