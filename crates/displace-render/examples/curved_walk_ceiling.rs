//! The most a walk from shell to shell could gain on a curved mesh,
//! measured: the same rays traced by the scene's BVH, and traced again
//! handed, by an oracle, exactly the shells whose hulls they enter before
//! their hit, in order (no BVH descent, no box admitted and then missed).
//! A walk through the shells' shared sides (Porumbescu et al. 2005; the
//! GPU's curved shader) finds each next shell for a crossing's cost, so
//! its trace can be no faster than the oracle's.
//!
//! ```text
//! cargo run --release -p displace-render --example curved_walk_ceiling -- \
//!     SCENE.toml RAYS.npy [SHADOW_RAYS.npy] [--every N]
//! ```
//!
//! `RAYS.npy` (and the shadow rays, with their lengths) as `displace trace
//! --scene` reads them; `--every N` keeps one ray in `N` (the oracle's
//! lists are found by testing every shell's hull, a brute force). One
//! thread; each timing is the best of seven passes, the two ways' passes
//! taken in turn.

use displace_core::io::npy;
use displace_render::faces::curved_face::CurvedFace;
use displace_render::geometry::Ray;
use displace_render::scene::queries::{blocked_many, first_hits, world_ray, Scratch, BATCH};
use displace_render::scene::Scene;
use displace_render::scene::SceneOptions;
use displace_render::scene::Shape;
use std::path::Path;
use std::time::Instant;

/// Every `every`th ray of `path`, `(N, 6)` or `(N, 7)` as `displace trace
/// --scene` reads them (a missing `t_max` is infinite).
fn read_rays(path: &str, every: usize) -> Vec<[f32; 7]> {
    let arr = npy::read_file(Path::new(path)).unwrap_or_else(|e| usage(&format!("{path}: {e}")));
    let columns = match arr.shape[..] {
        [_, c @ (6 | 7)] => c,
        _ => usage(&format!(
            "{path}: shape {:?}, not (N, 6) or (N, 7)",
            arr.shape
        )),
    };
    arr.data
        .chunks_exact(columns)
        .step_by(every)
        .map(|r| {
            let t_max = if columns == 7 { r[6] } else { f32::INFINITY };
            [r[0], r[1], r[2], r[3], r[4], r[5], t_max]
        })
        .collect()
}

/// Says what is wrong and how the example is run, and exits with status 2.
fn usage(problem: &str) -> ! {
    eprintln!(
        "curved_walk_ceiling: {problem}\n\
         usage: curved_walk_ceiling SCENE.toml RAYS.npy [SHADOW_RAYS.npy] [--every N]"
    );
    std::process::exit(2)
}

/// Seconds one run of `f` takes.
fn timed(f: impl FnOnce()) -> f64 {
    let start = Instant::now();
    f();
    start.elapsed().as_secs_f64()
}

/// Passes of each way, taken in turn so that a busy moment of a shared
/// machine slows both alike; each way's time is its best pass.
const PASSES: usize = 7;

/// For each ray, the curved faces whose hull it enters before `until`
/// (its hit, or its end), with where it enters them, in that order: what a
/// walk would visit. The entries are the oracle's too, so that the timed
/// walk tests no hull to know when to stop.
fn oracle(faces: &[&CurvedFace], rays: &[(Ray, f32, f32)], until: &[f32]) -> Vec<Vec<(f64, u32)>> {
    rays.iter()
        .zip(until)
        .map(|((ray, _, _), &end)| {
            let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let mut met: Vec<(f64, u32)> = faces
                .iter()
                .enumerate()
                .filter_map(|(i, f)| {
                    let (t_in, _) = f.shell().hull_span(o, d, 0.0, end as f64 * 1.0001)?;
                    Some((t_in, i as u32))
                })
                .collect();
            met.sort_by(|a, b| a.0.total_cmp(&b.0));
            met
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let every = args
        .iter()
        .position(|a| a == "--every")
        .map(
            |i| match args.get(i + 1).and_then(|n| n.parse::<usize>().ok()) {
                Some(n) if n > 0 => n,
                _ => usage("--every takes a whole number of rays, 1 or more"),
            },
        )
        .unwrap_or(1);
    let files: Vec<&String> = args
        .iter()
        .enumerate()
        .filter(|(i, a)| !a.starts_with("--") && (*i == 0 || args[i - 1] != "--every"))
        .map(|(_, a)| a)
        .collect();
    if files.len() < 2 {
        usage("a scene and at least one ray file are needed");
    }
    let opts = SceneOptions {
        no_image: true,
        ..Default::default()
    };
    let scene =
        Scene::load(Path::new(files[0]), &opts).unwrap_or_else(|e| usage(&format!("{e:#}")));
    let faces: Vec<&CurvedFace> = scene
        .primitives()
        .iter()
        .filter_map(|p| match &p.shape {
            Shape::Curved(c) => Some(&**c),
            _ => None,
        })
        .collect();
    println!(
        "{} curved faces of {} primitives",
        faces.len(),
        scene.primitive_count()
    );
    let mut sc = Scratch::default();
    for (k, path) in files[1..].iter().enumerate() {
        let shadow = k == 1;
        let rays = read_rays(path, every);
        let world: Vec<(Ray, f32, f32)> = rays.iter().map(world_ray).collect();
        // The BVH's answers, which also give the oracle each ray's end.
        let mut out = vec![0.0f32; rays.len() * if shadow { 1 } else { 8 }];
        let mut through_bvh = |out: &mut [f32]| {
            for (r, o) in rays
                .chunks(BATCH)
                .zip(out.chunks_mut(BATCH * if shadow { 1 } else { 8 }))
            {
                if shadow {
                    blocked_many(&scene, r, &mut sc, o)
                } else {
                    first_hits(&scene, r, &mut sc, o)
                }
            }
        };
        through_bvh(&mut out);
        let until: Vec<f32> = if shadow {
            world.iter().map(|(_, t_max, _)| *t_max).collect()
        } else {
            out.chunks_exact(8)
                .zip(&world)
                .map(|(row, (_, _, len))| row[0] * len)
                .collect()
        };
        let lists = oracle(&faces, &world, &until);
        let visits: usize = lists.iter().map(Vec::len).sum();
        let walk = || {
            let mut found = 0usize;
            for ((ray, t_max, _), list) in world.iter().zip(&lists) {
                if shadow {
                    if list
                        .iter()
                        .any(|&(_, i)| faces[i as usize].occludes(ray, 0.0, *t_max))
                    {
                        found += 1;
                    }
                } else {
                    let mut best = *t_max;
                    let mut hit = false;
                    for &(t_in, i) in list {
                        let f = faces[i as usize];
                        if t_in > best as f64 {
                            break;
                        }
                        if let Some((t, h)) = f.intersect(ray, 0.0, best) {
                            best = t;
                            hit = true;
                            std::hint::black_box(f.resolve(&h, false));
                        }
                    }
                    found += usize::from(hit);
                }
            }
            found
        };
        let (mut bvh, mut walked, mut found) = (f64::INFINITY, f64::INFINITY, 0);
        for _ in 0..PASSES {
            bvh = bvh.min(timed(|| through_bvh(&mut out)));
            walked = walked.min(timed(|| found = walk()));
        }
        let bvh_found = if shadow {
            out.iter().filter(|&&b| b > 0.0).count()
        } else {
            out.chunks_exact(8).filter(|r| r[0].is_finite()).count()
        };
        let n = rays.len() as f64;
        println!(
            "{path}: {} rays ({}), {:.2} shells a ray handed by the oracle; \
             BVH {:.3} s ({:.2} Mrays/s, {bvh_found} found), oracle walk {:.3} s \
             ({:.2} Mrays/s, {found} found): the walk's ceiling {:.2}x",
            rays.len(),
            if shadow { "any hit" } else { "first hits" },
            visits as f64 / n,
            bvh,
            n / bvh / 1e6,
            walked,
            n / walked / 1e6,
            bvh / walked
        );
    }
}
