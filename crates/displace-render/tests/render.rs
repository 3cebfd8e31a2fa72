//! Renderer correctness: analytic radiance, geometry against the exact
//! intersector, equivalences (flat map = raised face, zero depth = plain
//! face), determinism across threads and crops, and refusal of bad scenes.

mod common;

use common::scene_toml::SceneToml;
use common::*;
use displace_core::Method;
use displace_render::{render, Aov, RenderOptions, Scene, SceneOptions};
use std::f32::consts::PI;
use std::path::Path;

/// A Lambertian plane of albedo `a` lit by a point light of intensity `I` at
/// height `h`, seen from straight above through a 1-degree lens: the centre
/// pixel's radiance is `a / pi * I cos(theta) / r^2` (pbrt-v4's analytic
/// test scenes do the same).
#[test]
fn lambertian_plane_under_a_point_light_matches_the_closed_form() {
    for (lx, h, a) in [(0.0f32, 2.0f32, 0.5f32), (1.5, 3.0, 0.8)] {
        let s = scene(
            SceneToml::new(9, 9, 4)
                .camera_above(5.0, 0.5)
                .lambert(&format!("[{a}, {a}, {a}]"))
                .point_light(&format!("[{lx}, {h}, 0]"), "[10, 20, 30]")
                .plane()
                .text(),
        );
        let img = image(&s);
        let centre = img.pixels[4 * 9 + 4];
        let r2 = lx * lx + h * h;
        let cos = h / r2.sqrt();
        for (c, i) in [(centre.x, 10.0), (centre.y, 20.0), (centre.z, 30.0)] {
            let want = a / PI * i * cos / r2;
            assert!((c - want).abs() < 1e-3 * want, "{c} vs {want}");
        }
    }
}

/// A small square area light far above a plane: the irradiance approaches
/// `L A / r^2` (the point-light limit), within the light's angular size.
#[test]
fn small_area_light_approaches_its_point_limit() {
    let s = scene(
        SceneToml::new(9, 9, 4)
            .with("shadow_samples = 16")
            .camera_above(5.0, 0.5)
            .lambert("[1, 1, 1]")
            .light(
                "type = \"area\"\norigin = [-0.05, 10, -0.05]\nedge_u = [0.1, 0, 0]\n\
                 edge_v = [0, 0, 0.1]\nradiance = [1000, 1000, 1000]\nvisible = false",
            )
            .plane()
            .text(),
    );
    let c = image(&s).pixels[40].x;
    let want = 1.0 / PI * 1000.0 * 0.01 / 100.0;
    assert!((c - want).abs() < 1e-3 * want, "{c} vs {want}");
}

/// The ray-tracer paper's hardest map: sharp-edged studs (its section 4).
const STUDS: &str = "gen:studded?period=8";

/// The body of a `[shapes.displacement]` table: `height` a quarter of the
/// quad's width deep.
fn displacement(height: &str) -> String {
    format!("height = \"{height}\"\nheight_size = [64, 64]\ndepth = 0.25\nmap_size = [32, 32, 8]")
}

/// A `size` x `size` view of the 2 x 2 quad's place from above and aside,
/// lit from above, before any shape.
fn oblique_view(size: u32) -> SceneToml {
    SceneToml::new(size, size, 1)
        .camera("[0.3, 1.6, -2.2]", 45.0)
        .lambert("[0.7, 0.7, 0.7]")
        .point_light("[1, 3, -1]", "[5, 5, 5]")
}

/// The quad displaced by `map`, sphere traced, seen obliquely.
fn studded_scene(map: &str, size: u32) -> String {
    oblique_view(size)
        .quad(0.0)
        .displaced(&displacement(map))
        .with("method = \"sphere\"")
        .text()
        .to_string()
}

fn depth_aov(text: &str, method: Option<Method>) -> Vec<f32> {
    let s = Scene::from_toml(
        text,
        Path::new("t.toml"),
        Path::new("."),
        &SceneOptions { method, ..opts() },
    )
    .unwrap();
    scene_depth(&s)
}

/// The depth AOV of a render of `s`.
fn scene_depth(s: &Scene) -> Vec<f32> {
    let r = render(
        s,
        &RenderOptions {
            aovs: vec![Aov::Depth],
            ..Default::default()
        },
    )
    .unwrap();
    r.aovs[0].data.clone()
}

/// Sphere tracing and the exact intersector agree on hit/miss for at least
/// 99.9% of pixels and on depth elsewhere; the studded map (whose sharp
/// edges made the ray-tracer paper's renders lose pixels, its section 2.3)
/// has no hole at all.
#[test]
fn sphere_tracing_matches_the_exact_reference() {
    for map in ["gen:studded?period=8", "gen:gaussian", "gen:text?text=ab"] {
        let text = studded_scene(map, 96);
        let sphere = depth_aov(&text, None);
        let exact = depth_aov(&text, Some(Method::Exact));
        let n = sphere.len();
        let mut disagree = 0;
        let mut far = 0;
        let mut holes = 0;
        for (s, e) in sphere.iter().zip(&exact) {
            if s.is_finite() != e.is_finite() {
                disagree += 1;
                if e.is_finite() {
                    holes += 1;
                }
            } else if s.is_finite() && (s - e).abs() > 1e-3 * e.max(1.0) {
                far += 1;
            }
        }
        assert!(
            disagree * 1000 <= n,
            "{map}: {disagree} of {n} pixels disagree on hit/miss"
        );
        assert!(
            far * 1000 <= n,
            "{map}: {far} of {n} pixels differ in depth"
        );
        if map.contains("studded") {
            assert_eq!(holes, 0, "{map}: holes where the exact intersector hits");
        }
    }
}

/// The quad at height `y` seen from above, under a point and an area
/// light, displaced by the `[shapes.displacement]` body `displacement`.
fn flat_scene(displacement: Option<&str>, y: f32) -> Scene {
    let s = SceneToml::new(32, 32, 2)
        .camera_above(4.0, 20.0)
        .material(
            "type = \"phong\"\ncolor = [0.6, 0.5, 0.4]\nspecular = [0.2, 0.2, 0.2]\nshininess = 20",
        )
        .point_light("[0.5, 3, 0.2]", "[5, 5, 5]")
        .light(
            "type = \"area\"\norigin = [-0.5, 2.5, -0.5]\nedge_u = [1, 0, 0]\nedge_v = [0, 0, 1]\n\
             radiance = [2, 2, 2]\nvisible = false",
        )
        .quad(y);
    scene(
        match displacement {
            Some(d) => s.displaced(d),
            None => s,
        }
        .text(),
    )
}

/// A constant height of 1 is the face moved up by the depth (seen from
/// above, where the shell's sides are hidden).
#[test]
fn flat_displacement_equals_the_raised_face() {
    let disp = "height = \"gen:flat\"\nheight_size = [8, 8]\ndepth = 0.3\nmap_size = [8, 8, 4]";
    let a = image(&flat_scene(Some(disp), 0.0));
    let b = image(&flat_scene(None, 0.3));
    let worst = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0, f32::max);
    assert!(worst < 2e-3, "largest difference {worst}");
}

/// Depth 0 means no displacement: bit-identical to the plain face.
#[test]
fn zero_depth_equals_the_plain_face() {
    let disp = "height = \"gen:studded\"\ndepth = 0";
    assert_eq!(
        image(&flat_scene(Some(disp), 0.0)),
        image(&flat_scene(None, 0.0))
    );
}

fn small_default() -> Scene {
    Scene::default_scene(&SceneOptions {
        spp: Some(2),
        size: Some([40, 30]),
        ..opts()
    })
    .unwrap()
}

#[test]
fn parallel_and_single_threaded_renders_are_bit_identical() {
    let s = small_default();
    let a = pool(1).install(|| image(&s));
    let b = pool(3).install(|| image(&s));
    assert_eq!(a, b);
}

#[test]
fn a_crop_equals_the_same_region_of_the_full_render() {
    let s = small_default();
    let full = render_with(
        &s,
        &RenderOptions {
            aovs: vec![Aov::Normal],
            ..Default::default()
        },
    );
    let (crop, part) = render_crop(&s, [7, 5, 21, 17], vec![Aov::Normal]).unwrap();
    for (f, c) in crop_pixels(crop, full.image.width) {
        assert_eq!(full.image.pixels[f], part.image.pixels[c]);
        assert_eq!(
            full.aovs[0].data[3 * f..3 * f + 3],
            part.aovs[0].data[3 * c..3 * c + 3]
        );
    }
    assert!(render_crop(&s, [30, 0, 20, 5], vec![]).is_err());
}

#[test]
fn cancelled_renders_return_cancelled() {
    let s = small_default();
    let flag = std::sync::atomic::AtomicBool::new(true);
    let r = render(
        &s,
        &RenderOptions {
            cancel: Some(&flag),
            ..Default::default()
        },
    );
    assert!(matches!(r, Err(displace_render::Error::Cancelled)));
}

/// Shadow and reflection rays start inside the shell: a displaced mirror
/// seen in another mirror, and the studs' own shadows, need no special
/// case. A point under a stud's shadow is darker than one in the open.
#[test]
fn displaced_surfaces_shadow_themselves() {
    // Light low from +x: the stud at the centre shadows the floor to its -x side.
    let s = scene(
        SceneToml::new(64, 64, 1)
            .camera_above(3.0, 40.0)
            .lambert("[0.7, 0.7, 0.7]")
            .point_light("[3, 0.6, 0]", "[9, 9, 9]")
            .quad(0.0)
            .displaced(
                "height = \"gen:gaussian?scale=6\"\nheight_size = [64, 64]\ndepth = 0.5\nmap_size = [32, 32, 8]",
            )
            .text(),
    );
    let r = render_with(
        &s,
        &RenderOptions {
            aovs: vec![Aov::Position],
            ..Default::default()
        },
    );
    // Screen x runs along world -x (camera up is +z, looking down).
    let at = |wx: f32| {
        let (k, _) = r.aovs[0]
            .data
            .chunks_exact(3)
            .enumerate()
            .filter(|(_, p)| p[2].abs() < 0.02 && p[1] < 0.01)
            .min_by(|a, b| (a.1[0] - wx).abs().total_cmp(&(b.1[0] - wx).abs()))
            .unwrap();
        r.image.pixels[k].x
    };
    let shadowed = at(-0.6);
    let open = at(0.6);
    assert!(shadowed < 0.2 * open, "shadowed {shadowed}, open {open}");
}

#[test]
fn bad_scenes_are_refused_with_clear_messages() {
    let good = studded_scene("gen:gaussian", 8);
    // `good` with its first `from` replaced by `to` is refused, the message
    // holding every needle.
    let refused = |from: &str, to: &str, needles: &[&str]| {
        assert!(good.contains(from), "{from}");
        let e = scene_err(&good.replacen(from, to, 1));
        for needle in needles {
            assert!(e.contains(needle), "{e}");
        }
    };
    // Malformed TOML: file, line and column.
    let bad = good.replacen("width = 8", "width = = 8", 1);
    let line = 1 + bad.lines().position(|l| l == "width = = 8").unwrap();
    let e = scene_err(&bad);
    assert!(e.starts_with(&format!("test.toml:{line}:")), "{e}");
    // Unknown keys anywhere are errors, with their position.
    refused("vfov = 45", "vfov = 45\nfov = 3", &["fov", "test.toml:"]);
    refused("depth = 0.25", "depth = 0.25\ndepht = 1", &["depht"]);
    // Camera looking nowhere; up parallel to the view.
    refused(
        "look_at = [0, 0, 0]",
        "look_at = [0.3, 1.6, -2.2]",
        &["looks nowhere"],
    );
    refused(
        "vfov = 45",
        "vfov = 45\nup = [0.3, 1.6, -2.2]",
        &["parallel"],
    );
    // Zero size, negative samples, NaN.
    refused("width = 8", "width = 0", &["image.width"]);
    refused("spp = 1", "spp = -4", &["image.spp", "-4"]);
    refused(
        "position = [1, 3, -1]",
        "position = [1, nan, -1]",
        &["lights[0].position", "finite"],
    );
    // Missing texture: its path.
    refused(
        "method = \"sphere\"",
        "method = \"sphere\"\ncolor_texture = \"no/such/bricks.png\"",
        &["no/such/bricks.png"],
    );
    // Unknown material, method and generator.
    refused("material = \"m\"", "material = \"gold\"", &["gold"]);
    refused("method = \"sphere\"", "method = \"magic\"", &["magic"]);
    refused("gen:gaussian", "gen:nothing", &["nothing"]);
    // A missing scene file names its path.
    let e = Scene::load(Path::new("/no/such/scene.toml"), &opts())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("/no/such/scene.toml"), "{e}");
}

#[test]
fn every_scene_of_the_repository_loads() {
    let mut n = 0;
    for e in std::fs::read_dir(scenes_dir()).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let scene = Scene::load(
                &p,
                &SceneOptions {
                    size: Some([8, 8]),
                    ..opts()
                },
            )
            .unwrap_or_else(|e| panic!("{e}"));
            // No area light faces away from its room.
            assert!(
                scene.warnings().is_empty(),
                "{}: {:?}",
                p.display(),
                scene.warnings()
            );
            n += 1;
        }
    }
    assert!(n >= 12, "{n} scenes");
}

/// A scene file that starts with a UTF-8 byte-order mark (as editors on
/// Windows save it) loads as the same file without one.
#[test]
fn a_scene_file_may_start_with_a_byte_order_mark() {
    let dir = tempfile::tempdir().unwrap();
    let text = displace_render::scene::DEFAULT_SCENE;
    let (plain, marked) = (dir.path().join("plain.toml"), dir.path().join("bom.toml"));
    std::fs::write(&plain, text).unwrap();
    std::fs::write(&marked, format!("\u{feff}{text}")).unwrap();
    let o = SceneOptions {
        size: Some([8, 8]),
        ..opts()
    };
    let (a, b) = (
        Scene::load(&plain, &o).unwrap(),
        Scene::load(&marked, &o).unwrap(),
    );
    assert_eq!(image(&a), image(&b));
    assert_eq!(a.primitive_count(), b.primitive_count());
}

/// An area light whose lit side (`edge_u x edge_v`) faces away from the
/// scene is warned about, naming the light and the way to turn it, visible
/// or not; the same light turned round is not, nor is the point light.
#[test]
fn an_area_light_facing_away_from_the_scene_is_warned_about() {
    let room = |edges: &str, extra: &str| {
        format!(
            "[image]\nwidth = 8\nheight = 8\nspp = 1\n[camera]\nposition = [0, 1, -4]\nlook_at = [0, 1, 0]\n\
             [materials.m]\ntype = \"lambert\"\ncolor = [0.5, 0.5, 0.5]\n\
             [[shapes]]\ntype = \"quad\"\norigin = [-2, 0, -2]\nedge_u = [0, 0, 4]\nedge_v = [4, 0, 0]\nmaterial = \"m\"\n\
             [[shapes]]\ntype = \"sphere\"\ncenter = [0, 0.5, 0]\nradius = 0.5\nmaterial = \"m\"\n\
             [[lights]]\ntype = \"point\"\nposition = [0, 1, -2]\nintensity = [1, 1, 1]\n\
             [[lights]]\ntype = \"area\"\norigin = [-0.5, 3, -0.5]\n{edges}\nradiance = [4, 4, 4]\n{extra}"
        )
    };
    // Emitting up, above everything: warned.
    let up = scene(&room("edge_u = [0, 0, 1]\nedge_v = [1, 0, 0]", ""));
    let w = up.warnings();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("lights[1]")
            && w[0].contains("faces away")
            && w[0].contains("swap edge_u and edge_v"),
        "{w:?}"
    );
    // Turned round, emitting down: not warned.
    let down = scene(&room("edge_u = [1, 0, 0]\nedge_v = [0, 0, 1]", ""));
    assert!(down.warnings().is_empty(), "{:?}", down.warnings());
    // Invisible or not, the same test.
    let hidden = scene(&room(
        "edge_u = [0, 0, 1]\nedge_v = [1, 0, 0]",
        "visible = false",
    ));
    assert_eq!(hidden.warnings().len(), 1, "{:?}", hidden.warnings());
}

/// The studded quad of `studded_scene` as two displaced triangles with
/// the quad's texture coordinates.
fn two_triangles() -> String {
    let mut s = oblique_view(64);
    for (verts, uvs) in [
        (
            "[[-1, 0, -1], [-1, 0, 1], [1, 0, 1]]",
            "[[0, 0], [1, 0], [1, 1]]",
        ),
        (
            "[[-1, 0, -1], [1, 0, 1], [1, 0, -1]]",
            "[[0, 0], [1, 1], [0, 1]]",
        ),
    ] {
        s = s
            .shape(&format!(
                "type = \"triangle\"\nvertices = {verts}\nuvs = {uvs}"
            ))
            .displaced(&displacement(STUDS));
    }
    s.text().to_string()
}

/// A displaced triangle is the prism over it (the ray-tracer paper has only
/// quads):
/// the quad cut into two displaced triangles renders the same surface,
/// with the same silhouette.
#[test]
fn two_displaced_triangles_equal_the_displaced_quad() {
    let quad = depth_aov(&studded_scene(STUDS, 64), None);
    let tris = depth_aov(&two_triangles(), None);
    let mut differ = 0;
    for (a, b) in quad.iter().zip(&tris) {
        if a.is_finite() != b.is_finite() || (a.is_finite() && (a - b).abs() > 1e-3) {
            differ += 1;
        }
    }
    // Pixels whose ray grazes the shared diagonal may land on either prism's wall.
    assert!(
        differ * 200 <= quad.len(),
        "{differ} of {} pixels differ",
        quad.len()
    );
}

/// OBJ meshes go through the BVH; a displaced mesh of the same two
/// triangles is the displaced quad again.
#[test]
fn obj_meshes_load_and_displace() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("q.obj");
    std::fs::write(
        &obj,
        "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
    )
    .unwrap();
    let base = studded_scene(STUDS, 64);
    let text = oblique_view(64)
        .shape("type = \"mesh\"\npath = \"q.obj\"")
        .displaced(&displacement(STUDS))
        .text()
        .to_string();
    std::fs::write(dir.path().join("s.toml"), &text).unwrap();
    let s = Scene::load(&dir.path().join("s.toml"), &opts()).unwrap();
    assert_eq!(s.primitive_count(), 2);
    let mesh = scene_depth(&s);
    let quad = depth_aov(&base, None);
    let differ = quad
        .iter()
        .zip(&mesh)
        .filter(|(a, b)| {
            a.is_finite() != b.is_finite() || (a.is_finite() && (*a - *b).abs() > 1e-3)
        })
        .count();
    assert!(differ * 200 <= quad.len(), "{differ} pixels differ");
    // A missing mesh names its path.
    std::fs::write(dir.path().join("t.toml"), text.replace("q.obj", "gone.obj")).unwrap();
    let e = Scene::load(&dir.path().join("t.toml"), &opts())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("gone.obj"), "{e}");
}

/// An OBJ without normals gets smooth ones: the built-in sphere written
/// without its `vn` loads with normals about its radial ones (the mean of
/// its corners within a degree of radial, where flat faces would be 2-3
/// degrees off), under `crease_angle = 0` with its faces' own normals, and
/// an angle outside 0 to 180 is refused by key.
#[test]
fn obj_without_normals_gets_smooth_ones_under_its_crease_angle() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = displace_render::builtin_mesh::generate("sphere").unwrap();
    let mut obj = String::new();
    for t in &sphere.triangles {
        for p in t.positions {
            obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
    }
    for k in 0..sphere.triangles.len() {
        obj += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    std::fs::write(dir.path().join("ball.obj"), obj).unwrap();
    let load = |crease: &str| {
        let text = oblique_view(8)
            .shape(&format!("type = \"mesh\"\npath = \"ball.obj\"\n{crease}"))
            .text()
            .to_string();
        std::fs::write(dir.path().join("s.toml"), &text).unwrap();
        Scene::load(&dir.path().join("s.toml"), &opts())
    };
    let off_radial = |scene: &Scene| {
        let tris = &scene.meshes()[0].triangles;
        let angles: Vec<f32> = tris
            .iter()
            .flat_map(|t| t.normals.expect("normals").into_iter().zip(t.positions))
            .map(|(n, p)| n.dot(p.normalize()).clamp(-1.0, 1.0).acos().to_degrees())
            .collect();
        angles.iter().sum::<f32>() / angles.len() as f32
    };
    let smooth = off_radial(&load("").unwrap());
    assert!(smooth < 1.0, "{smooth}");
    let flat = off_radial(&load("crease_angle = 0").unwrap());
    assert!(flat > 2.0, "{flat}");
    for bad in [
        "crease_angle = 200",
        "crease_angle = -1",
        "crease_angle = nan",
    ] {
        let e = load(bad).err().expect(bad).to_string();
        assert!(e.contains("crease_angle"), "{bad}: {e}");
    }
}

/// A floor of 100 x 100 repeating tiles puts its map coordinates in the
/// thousands of cells, where single precision rounds a cell coordinate to
/// a few ten-thousandths of a cell. Rays aimed at the floor's base (height
/// 0 between the studs) exactly on cell boundaries used to leave the
/// shell through its floor between two cells (the walk's boundary, in
/// single precision, disagreed with the double-precision patch solve) and
/// reach the light under the floor. Every one of these rays must stop on
/// the floor, and all but a few in a thousand where the exact reference's
/// do.
#[test]
fn rays_leaving_the_shell_at_cell_boundaries_of_a_wide_map_hit_it() {
    // A quad under the floor where the light of the path tracer's test is.
    let text = format!(
        "[image]\nwidth = 8\nheight = 8\n{WIDE_STUDDED_FLOOR}\
         [[shapes]]\ntype = \"quad\"\norigin = [-1, -0.5, -1]\nedge_u = [0, 0, 2]\n\
         edge_v = [2, 0, 0]\nmaterial = \"m\"\n"
    );
    let exact = |method| {
        Scene::from_toml(
            &text,
            Path::new("wide.toml"),
            Path::new("."),
            &SceneOptions { method, ..opts() },
        )
        .unwrap()
    };
    let (scene, reference) = (exact(None), exact(Some(Method::Exact)));
    let eye = glam::Vec3::new(0.3, 2.0, -1.5);
    let (mut checked, mut apart) = (0, 0);
    // Texel centres (the patches' shared edges) of one tile, 64 texels in 4
    // units, across world x (the map's v) and across z (its u), each line
    // swept a quarter texel at a time along the other axis.
    // The exits land within single-precision rounding of the edge, so each
    // edge is also aimed at a little to either side (steps of 2e-6 units,
    // about a ten-thousandth of a texel).
    for k in 0..64 {
        for nudge in -10..=10 {
            let edge = (k as f32 + 0.5) / 16.0 - 1.0 + nudge as f32 * 2e-6;
            for i in 0..=64 {
                let along = -1.0 + i as f32 / 16.0;
                for target in [
                    glam::Vec3::new(edge, 0.0, along),
                    glam::Vec3::new(along, 0.0, edge - 1.0),
                ] {
                    let ray = displace_render::geometry::Ray::new(eye, target - eye);
                    let got = scene
                        .intersect(&ray, 0.0, f32::INFINITY)
                        .unwrap_or_else(|| panic!("ray at {target} misses everything"));
                    assert!(
                        got.position.y > -1e-4,
                        "ray at {target} went through the floor to {:?}",
                        got.position
                    );
                    // The exact reference ends at the floor alike.
                    let want = reference
                        .intersect(&ray, 0.0, f32::INFINITY)
                        .unwrap_or_else(|| panic!("the exact reference misses {target}"));
                    assert!(want.position.y > -1e-4, "{target}: {:?}", want.position);
                    if (got.position - want.position).length() >= 1e-3 {
                        apart += 1;
                    }
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 64 * 21 * 65 * 2);
    // Where the two part, the exact walk counts a ray that touches the top
    // edge of a plateau at the shell's top in one point (its root at the
    // start) and the tracer's rounding passes over it: a few in 30,000.
    assert!(apart * 1000 <= checked, "{apart} of {checked} hits differ");
}
