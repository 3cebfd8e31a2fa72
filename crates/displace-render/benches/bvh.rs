//! Our BVH (binned SAH, front-to-back traversal: `displace_render::bvh`)
//! against a maintained crate, `obvhs` (PLOC build, compressed wide BVH
//! traversal), on a mesh of about a million triangles: the `gaussian` height
//! field tessellated at 708x708 vertices, the kind of mesh a tessellating
//! renderer would build from our height maps. Both trace the same 512x512
//! camera rays (45 degrees down onto the mesh, every ray a hit) with their
//! own Möller-Trumbore test; build time and first hits per second on one
//! thread.
//!
//!     cargo bench -p displace-render --bench bvh

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use displace_core::{generators, Address};
use displace_render::bvh::Bvh;
use displace_render::camera::Camera;
use displace_render::geometry::Ray;
use displace_render::shapes::Triangle;
use glam::{Vec2, Vec3};
use glam034 as g34;
use obvhs::ray::RayHit;
use std::hint::black_box;
use std::time::Duration;

const VERTS: usize = 708;
const RAYS: usize = 512;

/// The height field `z = 0.3 h(x, y)` on the unit square as triangles.
fn mesh() -> Vec<Triangle> {
    let h = generators::generate("gen:gaussian", VERTS, VERTS, Address::Clamp).expect("height");
    let p = |i: usize, j: usize| {
        let n = (VERTS - 1) as f32;
        Vec3::new(i as f32 / n, j as f32 / n, 0.3 * h.data()[j * VERTS + i])
    };
    let mut tris = Vec::with_capacity(2 * (VERTS - 1) * (VERTS - 1));
    for j in 0..VERTS - 1 {
        for i in 0..VERTS - 1 {
            tris.push(Triangle::new(p(i, j), p(i + 1, j), p(i + 1, j + 1)));
            tris.push(Triangle::new(p(i, j), p(i + 1, j + 1), p(i, j + 1)));
        }
    }
    tris
}

/// Pinhole camera rays (the renderer's own camera) 45 degrees down onto
/// the centre of the square, 20 degree field of view.
fn rays() -> Vec<Ray> {
    let centre = Vec3::new(0.5, 0.5, 0.0);
    let s = 0.5f32.sqrt();
    let pos = centre + 1.2 * Vec3::new(0.0, -s, s);
    let camera = Camera::new(pos, centre, Vec3::Z, 20.0, 1.0, 0.0, None).expect("camera");
    (0..RAYS * RAYS)
        .map(|k| {
            let film = Vec2::new(
                ((k % RAYS) as f32 + 0.5) / RAYS as f32,
                ((k / RAYS) as f32 + 0.5) / RAYS as f32,
            );
            camera.ray(film, Vec2::splat(0.5))
        })
        .collect()
}

fn ours(tris: &[Triangle]) -> Bvh {
    Bvh::build(&tris.iter().map(Triangle::bounds).collect::<Vec<_>>())
}

fn ours_hit(bvh: &Bvh, tris: &[Triangle], ray: &Ray) -> Option<f32> {
    let mut best = None;
    bvh.traverse(ray, 0.0, f32::INFINITY, false, |i, t_max| {
        let (t, _) = tris[i as usize].intersect(ray, 0.0, t_max)?;
        best = Some(t);
        Some(t)
    });
    best
}

fn theirs_tris(tris: &[Triangle]) -> Vec<obvhs::triangle::Triangle> {
    let v = |p: Vec3| g34::Vec3A::new(p.x, p.y, p.z);
    tris.iter()
        .map(|t| obvhs::triangle::Triangle {
            v0: v(t.p0),
            v1: v(t.p0 + t.e1),
            v2: v(t.p0 + t.e2),
        })
        .collect()
}

fn theirs(tris: &[obvhs::triangle::Triangle]) -> obvhs::cwbvh::CwBvh {
    obvhs::cwbvh::builder::build_cwbvh_from_tris(
        tris,
        obvhs::BvhBuildParams::medium_build(),
        &mut Duration::default(),
    )
}

fn theirs_hit(
    bvh: &obvhs::cwbvh::CwBvh,
    tris: &[obvhs::triangle::Triangle],
    ray: &Ray,
) -> Option<f32> {
    let v = |p: Vec3| g34::Vec3A::new(p.x, p.y, p.z);
    let r = obvhs::ray::Ray::new(v(ray.origin), v(ray.dir), 0.0, f32::INFINITY);
    let mut hit = RayHit::none();
    bvh.ray_traverse(r, &mut hit, |r, id| {
        tris[bvh.primitive_indices[id] as usize].intersect(r)
    })
    .then_some(hit.t)
}

fn bvh(c: &mut Criterion) {
    let tris = mesh();
    let obv = theirs_tris(&tris);
    let rays = rays();
    let (a, b) = (ours(&tris), theirs(&obv));
    // Same hits from both before anything is timed.
    let agree = rays
        .iter()
        .filter(
            |r| match (ours_hit(&a, &tris, r), theirs_hit(&b, &obv, r)) {
                (Some(x), Some(y)) => (x - y).abs() < 1e-4,
                (None, None) => true,
                _ => false,
            },
        )
        .count();
    println!(
        "bvh: {} triangles, {} rays, {agree} with the same first hit",
        tris.len(),
        rays.len()
    );
    let mut build = c.benchmark_group("bvh-build");
    build.sample_size(10);
    build.throughput(Throughput::Elements(tris.len() as u64));
    build.bench_function("ours", |bch| bch.iter(|| ours(black_box(&tris))));
    build.bench_function("obvhs-cwbvh", |bch| bch.iter(|| theirs(black_box(&obv))));
    build.finish();
    let mut trace = c.benchmark_group("bvh-first-hit");
    trace.sample_size(10);
    trace.throughput(Throughput::Elements(rays.len() as u64));
    trace.bench_function("ours", |bch| {
        bch.iter(|| {
            rays.iter()
                .filter(|r| ours_hit(&a, &tris, black_box(r)).is_some())
                .count()
        })
    });
    trace.bench_function("obvhs-cwbvh", |bch| {
        bch.iter(|| {
            rays.iter()
                .filter(|r| theirs_hit(&b, &obv, black_box(r)).is_some())
                .count()
        })
    });
    trace.finish();
}

criterion_group!(benches, bvh);
criterion_main!(benches);
