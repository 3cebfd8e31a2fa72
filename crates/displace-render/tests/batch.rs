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

/// The rays' seed: the suite's fixed one (`PROPTEST_RNG_SEED`, set in
/// `.cargo/config.toml`), or a fresh one from `scripts/explore.sh`, which
/// also scales the ray counts (`DISPLACE_PROPERTY_SCALE`).
fn seed() -> u64 {
    std::env::var("PROPTEST_RNG_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(11)
}

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
        "stone.toml",
    ] {
        let mut o = opts();
        o.size = Some([48, 48]);
        let scene = Scene::load(&scenes_dir().join(name), &o).unwrap();
        let n = displace_core::random::property_cases(600) as usize;
        answers_as_one_ray(name, &scene, &rays(&scene, n, seed()));
    }
}

/// A displaced face with a scene normal map and a colour texture (the
/// hit's shading normal and tint come from files, sampled in the batch's
/// eight-hit resolution as in the one-ray one), clamped and repeating.
#[test]
fn textured_faces_batch_as_one_ray() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64::new(5);
    let mut byte = || (rng.next_f32() * 255.0) as u8;
    let normals = image::RgbImage::from_fn(16, 16, |_, _| image::Rgb([byte(), byte(), 200]));
    normals.save(dir.path().join("n.png")).unwrap();
    let colors = image::RgbImage::from_fn(8, 8, |_, _| image::Rgb([byte(), byte(), byte()]));
    colors.save(dir.path().join("c.png")).unwrap();
    for (address, tiles) in [("clamp", "[1, 1]"), ("repeat", "[3, 2]")] {
        let text = format!(
            r#"
[image]
width = 32
height = 32
[camera]
position = [0.5, -0.6, 1.1]
look_at = [0.5, 0.5, 0.0]
vfov = 50
[materials.m]
type = "lambert"
color = [0.8, 0.8, 0.8]
texture = "c.png"
[[lights]]
type = "point"
position = [0.2, 0.3, 1.0]
intensity = [1, 1, 1]
[[shapes]]
type = "quad"
origin = [0, 0, 0]
edge_u = [1, 0, 0]
edge_v = [0, 1, 0]
material = "m"
[shapes.displacement]
height = "gen:gaussian"
height_size = [64, 64]
depth = 0.2
map_size = [32, 32, 8]
normal_map = "n.png"
address = "{address}"
tiles = {tiles}
"#
        );
        let scene =
            Scene::from_toml(&text, &dir.path().join("t.toml"), dir.path(), &opts()).unwrap();
        // Camera rays onto the middle of the view, nearly all on the face, so
        // that whole packets of eight hits are resolved together; then the
        // mixed set.
        let mut rng = SplitMix64::new(9);
        let mut onto: Vec<(Ray, f32)> = (0..400)
            .map(|_| {
                let film = Vec2::new(0.3 + 0.4 * rng.next_f32(), 0.3 + 0.4 * rng.next_f32());
                (scene.camera().ray(film, Vec2::splat(0.5)), f32::INFINITY)
            })
            .collect();
        let hits = onto
            .iter()
            .filter(|(r, _)| scene.intersect(r, 0.0, f32::INFINITY).is_some())
            .count();
        assert!(
            hits * 100 >= onto.len() * 95,
            "{address}: {hits} middle rays hit"
        );
        onto.extend(rays(&scene, 400, seed()));
        answers_as_one_ray(address, &scene, &onto);
    }
}

/// Every ray's nearest hit (primitive, distance, position, normals,
/// texture coordinate, tint, steps) and any-hit answer from the batch
/// queries, in batches of uneven sizes, against the one-ray queries.
fn answers_as_one_ray(name: &str, scene: &Scene, rays: &[(Ray, f32)]) {
    {
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
                        assert_eq!(a.tint, b.tint, "{name} ray {r}: tint");
                        assert_eq!(a.material, b.material, "{name} ray {r}: material");
                        assert_eq!(a.iterations, b.iterations, "{name} ray {r}: steps");
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
        // Not vacuous: a fair share of the rays hit something (about a
        // quarter on the sparsest scene, the meshes on a dark ground).
        assert!(found > rays.len() / 6, "{name}: only {found} hits");
    }
}
