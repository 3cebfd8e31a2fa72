//! Curved displaced meshes against the surface they stand for, `S = P +
//! depth h(uv) N` (normals interpolated, then normalised): the ground truth
//! is that surface tessellated to sub-edges of a quarter height texel
//! ([`DisplacedSurface`]) and traced as plain triangles by the same BVH.

mod common;

use displace_core::{bake, Address, BakeOptions, Extent, HeightMap, TraceOptions};
use displace_render::curved_shell::{lambda_for_depth, min_normal_length, CurvedShell};
use displace_render::faces::curved_face::CurvedFace;
use displace_render::faces::displaced_surface::{DisplacedSurface, REFERENCE_EDGE_TEXELS};
use displace_render::geometry::Ray;
use displace_render::scene::Shape;
use displace_render::{Scene, SceneOptions};
use displace_scene::placed::CurvedDisplacement;
use glam::{DVec2, Vec2, Vec3};
use proptest::prelude::*;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

const LIGHT: &str = r#"
[image]
width = 64
height = 64
[camera]
position = [0, 0, -5]
look_at = [0, 0, 0]
[[lights]]
type = "point"
position = [0, 5, -5]
intensity = [10, 10, 10]
[materials.m]
type = "lambert"
color = [0.5, 0.5, 0.5]
"#;

/// A scene of one displaced mesh (`path`, with `extra` keys on the shape)
/// whose displacement reads `height`.
fn mesh_scene(dir: &Path, path: &str, extra: &str, displacement: &str) -> Scene {
    let shape = format!("{extra}\n[shapes.displacement]\n{displacement}\n");
    lit_mesh(dir, path, &shape)
}

/// The scene of [`LIGHT`] and the mesh at `path`, its shape table ending in
/// `rest`.
fn lit_mesh(dir: &Path, path: &str, rest: &str) -> Scene {
    let text = format!(
        "{LIGHT}\n[[shapes]]\ntype = \"mesh\"\npath = \"{path}\"\nmaterial = \"m\"\n{rest}"
    );
    let opts = SceneOptions::default();
    Scene::from_toml(&text, Path::new("curved.toml"), dir, &opts).unwrap()
}

/// Sub-edges of the ground truth, in height texels: under the quarter
/// texel of [`REFERENCE_EDGE_TEXELS`], since flat sub-triangles part from
/// the bilinear patches by up to a 64th of a height step at a quarter
/// texel, which on the studs' steep walls moves hits by 2-5% of the depth
/// (the truth's own error, measured on the torus).
const EDGE_TEXELS: f32 = REFERENCE_EDGE_TEXELS / 2.0;

/// The ground truth of `scene`'s one displaced mesh: its surface `S`
/// tessellated and loaded as a plain mesh.
fn ground_truth(scene: &Scene, dir: &Path) -> Scene {
    let mesh = &scene.meshes()[0];
    let disp = mesh.displacement.as_ref().unwrap();
    let surface =
        DisplacedSurface::new(&mesh.triangles, &disp.map.height, disp.depth, EDGE_TEXELS).unwrap();
    let mut obj = String::new();
    for v in surface.each_vertex() {
        let p = v.position;
        writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
    }
    for [a, b, c] in surface.each_triangle() {
        writeln!(obj, "f {} {} {}", a + 1, b + 1, c + 1).unwrap();
    }
    std::fs::write(dir.join("truth.obj"), obj).unwrap();
    lit_mesh(dir, "truth.obj", "")
}

/// One ray per pixel of an `n x n` pinhole view from `eye` towards the
/// origin over a field of `half` units at unit distance.
fn view(eye: Vec3, n: usize, half: f32) -> Vec<Ray> {
    let fwd = (-eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let mut rays = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let sx = ((i as f32 + 0.5) / n as f32 * 2.0 - 1.0) * half;
            let sy = (1.0 - (j as f32 + 0.5) / n as f32 * 2.0) * half;
            rays.push(Ray::new(eye, fwd + sx * right + sy * up));
        }
    }
    rays
}

/// Hit/miss agreement and the share of common hits within 2% of the depth.
fn agreement(ours: &Scene, truth: &Scene, rays: &[Ray], depth: f32) -> (f64, f64, usize) {
    let (mut agree, mut both, mut close) = (0usize, 0usize, 0usize);
    for ray in rays {
        let a = ours.intersect(ray, 0.0, f32::INFINITY);
        let b = truth.intersect(ray, 0.0, f32::INFINITY);
        agree += usize::from(a.is_some() == b.is_some());
        if let (Some(a), Some(b)) = (a, b) {
            both += 1;
            let ok = (a.position - b.position).length() <= 0.02 * depth;
            close += usize::from(ok);
            if !ok && std::env::var("CURVED_DEBUG").is_ok() {
                eprintln!(
                    "t {} vs {} err/depth {:.3} n {:?} vs {:?} uv {:?} iters {}",
                    a.t,
                    b.t,
                    (a.position - b.position).length() / depth,
                    a.geometric_normal,
                    b.geometric_normal,
                    a.uv,
                    a.iterations
                );
            }
        }
    }
    (
        agree as f64 / rays.len() as f64,
        close as f64 / both.max(1) as f64,
        both,
    )
}

fn curved_count(scene: &Scene) -> usize {
    scene
        .primitives()
        .iter()
        .filter(|p| matches!(p.shape, Shape::Curved(_)))
        .count()
}

/// A coarse UV sphere with analytic normals and texture coordinates, as an
/// OBJ file would give it: 30 degrees between neighbouring normals, far
/// more curvature per triangle than the built-ins.
fn coarse_sphere_obj(segments: usize, rings: usize) -> String {
    let mut s = String::new();
    for j in 0..=rings {
        for i in 0..=segments {
            let (u, v) = (i as f32 / segments as f32, j as f32 / rings as f32);
            let (phi, theta) = (u * std::f32::consts::TAU, v * std::f32::consts::PI);
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            writeln!(s, "v {} {} {}", n.x, n.y, n.z).unwrap();
            writeln!(s, "vn {} {} {}", n.x, n.y, n.z).unwrap();
            writeln!(s, "vt {u} {v}").unwrap();
        }
    }
    let idx = |i: usize, j: usize| j * (segments + 1) + i + 1;
    for j in 0..rings {
        for i in 0..segments {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i, j + 1), idx(i + 1, j + 1));
            // Outward winding: (u, v) runs east and south.
            writeln!(s, "f {a}/{a}/{a} {c}/{c}/{c} {b}/{b}/{b}").unwrap();
            writeln!(s, "f {b}/{b}/{b} {c}/{c}/{c} {d}/{d}/{d}").unwrap();
        }
    }
    s
}

fn check_against_truth(scene: &Scene, dir: &Path, eye: Vec3, half: f32, what: &str) {
    assert!(curved_count(scene) > 0, "{what}: no curved prims");
    let truth = ground_truth(scene, dir);
    let depth = scene.meshes()[0].displacement.as_ref().unwrap().depth;
    let rays = view(eye, 160, half);
    let (agree, close, both) = agreement(scene, &truth, &rays, depth);
    eprintln!("{what}: hit/miss agree {agree:.4}, within 2% of depth {close:.4} of {both}");
    assert!(both > 5000, "{what}: only {both} pixels hit both");
    assert!(agree >= 0.995, "{what}: hit/miss agree on {agree}");
    assert!(
        close >= 0.99,
        "{what}: hits within 2% of the depth on {close}"
    );
}

/// `mesh` displaced by `height` (32 x 32 texels, repeating `tiles` times,
/// `depth` deep) agrees with its tessellated surface as seen from `eye`.
fn matches_tessellation(
    dir: &Path,
    mesh: &str,
    height: &str,
    depth: f32,
    tiles: [u32; 2],
    eye: Vec3,
) {
    let displacement = format!(
        "height = \"{height}\"\nheight_size = [32, 32]\ndepth = {depth}\n\
         map_size = [32, 32, 8]\naddress = \"repeat\"\ntiles = {tiles:?}"
    );
    let scene = mesh_scene(dir, mesh, "", &displacement);
    let half = if mesh == "builtin:torus" { 0.55 } else { 0.36 };
    check_against_truth(&scene, dir, eye, half, mesh);
}

#[test]
fn a_displaced_sphere_matches_its_tessellated_surface() {
    let dir = tempfile::tempdir().unwrap();
    let eye = Vec3::new(0.3, 1.2, -3.5);
    matches_tessellation(dir.path(), "builtin:sphere", "gen:noise", 0.1, [2, 1], eye);
}

#[test]
fn a_displaced_torus_matches_its_tessellated_surface() {
    let dir = tempfile::tempdir().unwrap();
    let eye = Vec3::new(0.0, 2.5, -3.0);
    let studs = "gen:studded?period=8";
    matches_tessellation(dir.path(), "builtin:torus", studs, 0.06, [6, 2], eye);
}

#[test]
fn a_coarse_obj_sphere_matches_its_tessellated_surface() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("coarse.obj"), coarse_sphere_obj(12, 6)).unwrap();
    let eye = Vec3::new(1.0, 0.8, -3.5);
    matches_tessellation(dir.path(), "coarse.obj", "gen:gaussian", 0.15, [3, 2], eye);
}

#[test]
fn planar_meshes_keep_their_flat_prisms() {
    let dir = tempfile::tempdir().unwrap();
    for path in ["builtin:plane", "builtin:cube"] {
        let scene = mesh_scene(
            dir.path(),
            path,
            "",
            "height = \"gen:gaussian\"\nheight_size = [16, 16]\ndepth = 0.1\nmap_size = [16, 16, 4]",
        );
        assert_eq!(curved_count(&scene), 0, "{path}");
        assert!(scene
            .primitives()
            .iter()
            .all(|p| matches!(p.shape, Shape::Displaced(_))));
    }
}

/// Pixels whose normal breaks against both horizontal (or both vertical)
/// neighbours while those two agree: a line of pixels across a smooth
/// surface, the seam a prism wall draws.
fn seams(scene: &Scene, rays: &[Ray], n: usize) -> usize {
    let normals: Vec<Option<Vec3>> = rays
        .iter()
        .map(|r| {
            scene
                .intersect(r, 0.0, f32::INFINITY)
                .map(|h| h.geometric_normal)
        })
        .collect();
    let at = |i: usize, j: usize| normals[j * n + i];
    let break_ = |a: Vec3, b: Vec3| a.dot(b) < 20f32.to_radians().cos();
    let mut count = 0;
    for j in 1..n - 1 {
        for i in 1..n - 1 {
            let Some(c) = at(i, j) else { continue };
            for (a, b) in [(at(i - 1, j), at(i + 1, j)), (at(i, j - 1), at(i, j + 1))] {
                if let (Some(a), Some(b)) = (a, b) {
                    if break_(c, a) && break_(c, b) && !break_(a, b) {
                        count += 1;
                    }
                }
            }
        }
    }
    count
}

#[test]
fn smooth_heights_on_curved_meshes_show_no_seams() {
    let dir = tempfile::tempdir().unwrap();
    for (path, eye) in [
        ("builtin:sphere", Vec3::new(0.3, 1.2, -3.5)),
        ("builtin:torus", Vec3::new(0.0, 2.5, -3.0)),
    ] {
        let scene = mesh_scene(
            dir.path(),
            path,
            "",
            "height = \"gen:flat?level=0.6\"\nheight_size = [16, 16]\ndepth = 0.1\nmap_size = [16, 16, 4]\naddress = \"repeat\"\ntiles = [4, 2]",
        );
        assert!(curved_count(&scene) > 0);
        let n = 200;
        let rays = view(eye, n, 0.5);
        let found = seams(&scene, &rays, n);
        assert_eq!(found, 0, "{path}: {found} seam pixels");
    }
}

/// Vertex normals tilted up to about 35 degrees off the face's `normal`,
/// as far apart as the builder lets a shell be (`min_normal_length` of at
/// least 0.5).
fn tilted(normal: Vec3, next: &mut impl FnMut() -> f32) -> [Vec3; 3] {
    loop {
        let n = [0, 1, 2].map(|_| {
            let tilt = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 1.2;
            (normal + tilt).normalize()
        });
        if min_normal_length(&n).is_some_and(|m| m >= 0.5) {
            break n;
        }
    }
}

/// A random curved shell over a random height map, and its face.
fn random_face(seed: u64) -> (CurvedFace, Arc<displace_core::DisplacementMap>) {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f32 / (1u64 << 53) as f32
    };
    let p = [
        Vec3::new(next(), next(), next()) * 0.3,
        Vec3::new(1.0 + next() * 0.3, next() * 0.3, next() * 0.3),
        Vec3::new(next() * 0.3, 1.0 + next() * 0.3, next() * 0.3),
    ];
    let normal = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
    let mut normals = tilted(normal, &mut next);
    let texels: Vec<f32> = (0..16 * 16).map(|_| next()).collect();
    let height = HeightMap::new(16, 16, texels, Address::Clamp).unwrap();
    let depth = 0.1 + 0.3 * next();
    let map = Arc::new(
        bake(
            &height,
            &BakeOptions::new([16, 16, 8], Extent::new(1.0, 1.0, depth).unwrap()),
        )
        .unwrap(),
    );
    // A shell that folds over itself (`shell_folds`: normals converging
    // faster than the shell is thick) is no shell, and the builder keeps a
    // flat prism there: other normals, then.
    let shell = loop {
        let top = lambda_for_depth(depth as f64, min_normal_length(&normals).unwrap());
        if let Some(shell) = CurvedShell::new(p, normals, depth, top) {
            break shell;
        }
        normals = tilted(normal, &mut next);
    };
    let uv = [
        Vec2::new(0.05, 0.1),
        Vec2::new(0.95, 0.2),
        Vec2::new(0.2, 0.9),
    ];
    let face = CurvedDisplacement::new(
        shell,
        map.clone(),
        TraceOptions::default(),
        uv,
        Vec2::ZERO,
        [false; 3],
    )
    .map(|c| CurvedFace::from(&c))
    .unwrap();
    (face, map)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(256)))]

    /// The step bound: between the ray's entry into the shell and its
    /// reported hit, no point of the ray lies under the surface (beyond
    /// the chords' tolerance), and the hit itself lies on it.
    #[test]
    fn rays_never_cross_the_surface_before_their_hit(
        seed in any::<u64>(),
        ox in -0.5f32..1.5, oy in -0.5f32..1.5,
        tx in 0.0f32..1.0, ty in 0.0f32..1.0,
    ) {
        let (face, map) = random_face(seed);
        let shell = *face.shell();
        let target = shell.point(DVec2::new(tx as f64 * 0.5, ty as f64 * 0.5), 0.3).as_vec3();
        let origin = Vec3::new(ox, oy, 1.5);
        let ray = Ray::new(origin, target - origin);
        let first = face.intersect(&ray, 0.0, f32::INFINITY);
        // The any-hit query (shadow rays) stops at the first proof of a
        // blocker, and agrees with the first hit.
        prop_assert_eq!(face.occludes(&ray, 0.0, f32::INFINITY), first.is_some());
        if let Some((t, _)) = first {
            prop_assert!(!face.occludes(&ray, 0.0, t * 0.999), "blocked before the hit at {}", t);
            // A shortened ray (a shadow ray to a light, the BVH's closest
            // hit so far) sees the whole ray's hit, or nothing.
            for f in [0.25f32, 0.999, 1.001, 4.0] {
                let t_max = t * f;
                prop_assert_eq!(face.occludes(&ray, 0.0, t_max), f > 1.0, "t_max {} of the hit at {}", t_max, t);
                let bounded = face.intersect(&ray, 0.0, t_max).map(|(tb, _)| tb);
                prop_assert_eq!(bounded, (f > 1.0).then_some(t), "t_max {} of the hit at {}", t_max, t);
            }
        }
        let Some((t_hit, hit)) = first else {
            return Ok(());
        };
        // The hit lies on the surface (or on a wall), its shell
        // coordinates within rounding of the shell; the points before it
        // are checked where they lie in the shell itself (a ray may run
        // along a wall just outside it, under the surface's level there).
        let uv_of = |p: Vec3, tol: f64| -> Option<(f64, f64)> {
            let loc = shell.locate(p.as_dvec3(), 0.5 * shell.top())?;
            if !shell.contains(&loc, tol) {
                return None;
            }
            let b = loc.b;
            let uv = Vec2::new(0.05, 0.1) * (1.0 - b.x - b.y) as f32
                + Vec2::new(0.95, 0.2) * b.x as f32
                + Vec2::new(0.2, 0.9) * b.y as f32;
            Some((loc.w, map.height.sample(uv.x, uv.y) as f64))
        };
        if !hit.wall {
            let (w, h) = uv_of(hit.position, 1e-5).expect("the hit lies in its shell");
            prop_assert!((w - h).abs() < 1e-4, "hit at w {w}, surface {h}");
        }
        for k in 0..400 {
            let t = t_hit * k as f32 / 400.0;
            if let Some((w, h)) = uv_of(ray.at(t), 0.0) {
                prop_assert!(w >= h - 2e-3, "at t {t} of {t_hit}: w {w} under h {h}");
            }
        }
    }
}
