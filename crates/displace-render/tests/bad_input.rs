//! Adversarial scene input (docs/reliability.md): vectors with extra components, counts past
//! their bounds, coordinates that overflow, textures named by their key,
//! and the deepest reflection the bound allows rendered without
//! overflowing the stack.

mod common;

use common::scene_toml::SceneToml;
use common::*;
use displace_render::scene::{Scene, MAX_DEPTH, MAX_SHADOW_SAMPLES, MAX_SPP};
use displace_testkit::elevation;
use std::path::Path;

/// The sphere's `[[shapes]]` entry in [`sphere`].
const SPHERE: &str = "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1";

/// A lit sphere, 4 x 4 pixels at 1 spp.
fn sphere() -> SceneToml {
    SceneToml::new(4, 4, 1)
        .camera("[0, 0, -4]", 40.0)
        .lambert("[0.5, 0.5, 0.5]")
        .point_light("[0, 3, -3]", "[10, 10, 10]")
        .shape(SPHERE)
}

/// The sphere scene with its sphere replaced by the shape `shape` (the
/// lines of a `[[shapes]]` entry after its header).
fn with_shape(shape: &str) -> String {
    with(SPHERE, shape)
}

/// The sphere scene with `from` replaced by `to`.
fn with(from: &str, to: &str) -> String {
    let text = sphere().text().to_string();
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

#[test]
fn vectors_take_exactly_three_numbers() {
    scene(sphere().text());
    for (from, to) in [
        ("position = [0, 0, -4]", "position = [0, 0, -4, 5]"),
        (
            "position = [0, 0, -4]",
            "position = [0, 0, -4, \"junk\", {a = 1}]",
        ),
        ("look_at = [0, 0, 0]", "look_at = [0, 0, 0, 0]"),
        (
            "look_at = [0, 0, 0]",
            "look_at = [0, 0, 0]\nup = [0, 1, 0, 1]",
        ),
        ("spp = 1", "spp = 1\nbackground = [0.1, 0.1, 0.1, 0.1]"),
    ] {
        let e = scene_err(&with(from, to));
        assert!(e.starts_with("test.toml:") && e.contains("3"), "{to}: {e}");
    }
    // Too few is refused too.
    let e = scene_err(&with("look_at = [0, 0, 0]", "look_at = [0, 0]"));
    assert!(e.contains("test.toml:"), "{e}");
}

#[test]
fn counts_are_bounded_and_say_their_bound() {
    for (key, bound) in [
        ("spp", MAX_SPP),
        ("shadow_samples", MAX_SHADOW_SAMPLES),
        ("max_depth", MAX_DEPTH),
    ] {
        let at = with(
            "spp = 1",
            &format!("spp = 1\n{key} = {bound}").replace("spp = 1\nspp", "spp"),
        );
        scene(&at);
        let past = at.replace(
            &format!("{key} = {bound}"),
            &format!("{key} = {}", bound + 1),
        );
        let e = scene_err(&past);
        assert!(
            e.contains(&format!("image.{key}")) && e.contains(&bound.to_string()),
            "{e}"
        );
    }
    let e = scene_err(&with("spp = 1", "spp = 1\nmax_depth = 5000"));
    assert!(e.contains("image.max_depth"), "{e}");
    let displaced = |iterations: u64| {
        with_shape(&format!(
                "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
                 displacement = {{ height = \"gen:gaussian\", height_size = [8, 8], map_size = [8, 8, 4], \
                 depth = 0.1, method = \"sphere-fixed\", iterations = {iterations} }}"
            ),
        )
    };
    scene(&displaced(65536));
    let e = scene_err(&displaced(4_000_000_000));
    assert!(
        e.contains("shapes[0].displacement.iterations") && e.contains("65536"),
        "{e}"
    );
}

/// A value the checks refuse is placed as a parse error is: the scene
/// file's line and column of the value, then the key (the place is found
/// in the text here, not assumed).
#[test]
fn value_errors_say_the_line_and_column_of_their_key() {
    for (from, to, key) in [
        ("radius = 1", "radius = -1", "shapes[0].radius"),
        ("width = 4", "width = 4294967296", "image.width"),
        ("[0.5, 0.5, 0.5]", "[0.5, -0.5, 0.5]", ".color"),
    ] {
        let text = with(from, to);
        let (line, value) = text
            .lines()
            .enumerate()
            .find_map(|(n, l)| l.find(to).map(|c| (n + 1, l[..c].chars().count() + 1)))
            .unwrap();
        let column = if to.starts_with('[') {
            value
        } else {
            value + to.find('=').unwrap() + 2
        };
        let e = scene_err(&text);
        let at = format!("test.toml:{line}:{column}: ");
        assert!(
            e.starts_with(&at) && e.contains(key),
            "{to}: {e} (want {at}{key})"
        );
    }
    // The 32-bit bound is named, not just "positive".
    let e = scene_err(&with("width = 4", "width = 4294967296"));
    assert!(e.contains("4294967295"), "{e}");
}

/// Two facing mirrors at the deepest bound: every pixel recurses
/// `MAX_DEPTH` times on a worker thread's stack, in this debug build too.
#[test]
fn facing_mirrors_at_the_depth_bound_render() {
    let mirror = |z: i32| {
        format!(
            "type = \"quad\"\norigin = [-10, -10, {z}]\nedge_u = [20, 0, 0]\nedge_v = [0, 20, 0]"
        )
    };
    let text = SceneToml::new(4, 4, 2)
        .with(&format!("max_depth = {MAX_DEPTH}"))
        .camera("[0, 0, -0.5]", 40.0)
        .material("type = \"mirror\"\ncolor = [0.9, 0.9, 0.9]")
        .point_light("[0, 0, 0]", "[1, 1, 1]")
        .shape(&mirror(1))
        .shape(&mirror(-1))
        .text()
        .to_string();
    let img = image(&scene(&text));
    assert!(img.pixels.iter().all(|p| p.is_finite()));
}

#[test]
fn coordinates_that_overflow_are_out_of_range() {
    let e = scene_err(&with("position = [0, 0, -4]", "position = [0, 0, -3e38]"));
    assert!(
        e.contains("camera.position") && e.contains("1e18") && !e.contains("nowhere"),
        "{e}"
    );
    let e = scene_err(&with("center = [0, 0, 0]", "center = [1e30, 0, 0]"));
    assert!(e.contains("shapes[0].center"), "{e}");
}

#[test]
fn texture_errors_name_the_key() {
    let e = scene_err(&with(
        "color = [0.5, 0.5, 0.5]",
        "color = [0.5, 0.5, 0.5]\ntexture = \"no/such/wood.png\"",
    ));
    assert!(
        e.contains("materials.m.texture") && e.contains("no/such/wood.png"),
        "{e}"
    );
    let e = scene_err(&with_shape(
        "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
         displacement = { height = \"gen:gaussian\", height_size = [8, 8], map_size = [8, 8, 4], \
         depth = 0.1, normal_map = \"none.png\" }",
    ));
    assert!(
        e.contains("shapes[0].displacement.normal_map") && e.contains("none.png"),
        "{e}"
    );
}

#[test]
fn unknown_names_are_not_sizes() {
    let e = scene_err(&with_shape(
        "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
         displacement = { height = \"gen:gaussian\", depth = 0.1, address = \"mirror\" }",
    ));
    assert!(
        e.contains("address") && e.contains("mirror") && !e.contains("invalid size"),
        "{e}"
    );
}

/// A displaced face tiled over more height cells than the tracer's single
/// precision walks ([`displace_core::convention::MAX_CELL_SPAN`]) is refused
/// when the scene loads, naming the face: a plane mesh whose texture
/// coordinates spanned 70000 tiles of a 256-texel map rendered forever.
/// The same through a quad's `tiles`; the limit itself loads.
#[test]
fn faces_tiled_past_the_walks_precision_are_refused() {
    let face = |shape: &str, tiles: u32| {
        with_shape(&format!(
                "{shape}\ndisplacement = {{ height = \"gen:noise\", height_size = [256, 256], depth = 0.05, \
                 map_size = [8, 8, 2], address = \"repeat\", tiles = [{tiles}, {tiles}] }}"
            ),
        )
    };
    let plane = "type = \"mesh\"\npath = \"builtin:plane\"";
    let quad = "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]";
    for shape in [plane, quad] {
        let e = scene_err(&face(shape, 70000));
        assert!(
            e.contains("shapes[0]") && e.contains("17920000 x 17920000 height cells"),
            "{e}"
        );
        // 4096 tiles of 256 texels: 2^20 cells a side, the limit.
        scene(&face(shape, 4096));
        assert!(scene_err(&face(shape, 4097)).contains("height cells"));
    }
}

/// Float textures (EXR) with values no texture means are refused naming
/// the key, the file and the texel: NaN in a colour map or a normal map,
/// a negative reflectance in a colour map (each was rendered into NaN or
/// negative pixels). The same files' finite, non-negative twins load.
#[test]
fn float_textures_with_texels_out_of_range_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    let exr = |name: &str, bad: [f32; 3]| {
        let mut img = image::Rgb32FImage::from_pixel(4, 2, image::Rgb([0.5; 3]));
        img.put_pixel(3, 1, image::Rgb(bad));
        image::DynamicImage::ImageRgb32F(img)
            .save(base.join(name))
            .unwrap();
    };
    exr("nan.exr", [0.5, f32::NAN, 0.5]);
    exr("neg.exr", [-1.0, 0.5, 0.5]);
    exr("ok.exr", [1.0, 0.0, 0.25]);
    exr("bright.exr", [1.5, 0.5, 0.5]);
    exr("huge.exr", [1e20, 0.5, 0.5]);
    let load = |text: &str| {
        Scene::from_toml(text, Path::new("test.toml"), base, &opts()).map_err(|e| e.to_string())
    };
    let material = |file: &str| {
        with(
            "color = [0.5, 0.5, 0.5]",
            &format!("color = [0.5, 0.5, 0.5]\ntexture = \"{file}\""),
        )
    };
    let normals = |file: &str| {
        with_shape(&format!(
                "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
                 displacement = {{ height = \"gen:gaussian\", height_size = [8, 8], map_size = [8, 8, 4], \
                 depth = 0.1, normal_map = \"{file}\" }}"
            ),
        )
    };
    for (text, key, file) in [
        (material("nan.exr"), "materials.m.texture", "nan.exr"),
        (material("neg.exr"), "materials.m.texture", "neg.exr"),
        (
            normals("nan.exr"),
            "shapes[0].displacement.normal_map",
            "nan.exr",
        ),
        // A colour map is a reflectance, at most 1; a normal map's
        // squared lengths must fit in single precision.
        (material("bright.exr"), "materials.m.texture", "bright.exr"),
        (
            normals("huge.exr"),
            "shapes[0].displacement.normal_map",
            "huge.exr",
        ),
    ] {
        let Err(e) = load(&text) else {
            panic!("{file} under {key} was accepted")
        };
        assert!(
            e.contains(key) && e.contains(file) && e.contains("texel (3, 1)"),
            "{e}"
        );
    }
    load(&material("ok.exr")).unwrap();
    // A normal map's values are directions, not reflectances: a negative
    // one is what a signed map stores.
    load(&normals("neg.exr")).unwrap();
}

/// An OBJ mesh whose every face has no area (repeated or collinear
/// vertices) is refused naming the file and the shape: it used to load as
/// no primitives and render nothing. One face with an area among them
/// loads.
#[test]
fn meshes_without_a_face_of_any_area_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    let mesh = |name: &str, text: &str| std::fs::write(base.join(name), text).unwrap();
    mesh("point.obj", "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n");
    mesh("line.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 3 2 1\n");
    mesh(
        "one.obj",
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n",
    );
    let text = |file: &str| with_shape(&format!("type = \"mesh\"\npath = \"{file}\""));
    let load = |t: &str| Scene::from_toml(t, Path::new("test.toml"), base, &opts());
    for file in ["point.obj", "line.obj"] {
        let Err(e) = load(&text(file)) else {
            panic!("{file} was accepted")
        };
        let e = e.to_string();
        assert!(
            e.contains(file) && e.contains("shapes[0]") && e.contains("has an area"),
            "{e}"
        );
    }
    assert!(load(&text("one.obj")).is_ok());
}

/// An OBJ's errors name the scene's shape and its line as well as the
/// OBJ's own file, line and column: in a scene of several meshes, the
/// OBJ's message alone did not say which shape reads it.
#[test]
fn mesh_errors_are_placed_at_the_scene_key_that_reads_the_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    let mesh = |name: &str, text: &str| std::fs::write(base.join(name), text).unwrap();
    mesh("good.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    mesh("far.obj", "v 0 0 0\nv 1e30 0 0\nv 0 1 0\nf 1 2 3\n");
    mesh("index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    mesh("novt.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let displaced = "displacement = { height = \"gen:gaussian\", height_size = [8, 8], \
                     map_size = [8, 8, 2], depth = 0.1 }";
    for (file, extra, obj_place, says) in [
        ("far.obj", "", "far.obj:2:3", "out of range"),
        ("index.obj", "", "index.obj:4:7", "does not exist"),
        ("novt.obj", displaced, "novt.obj", "texture coordinates"),
    ] {
        // The bad mesh is the scene's second shape, after a good one.
        let text = with_shape(&format!(
            "type = \"mesh\"\npath = \"good.obj\"\nmaterial = \"m\"\n\n\
             [[shapes]]\ntype = \"mesh\"\npath = \"{file}\"\n{extra}"
        ));
        let line = text
            .lines()
            .position(|l| l == format!("path = \"{file}\""))
            .unwrap()
            + 1;
        let Err(e) = Scene::from_toml(&text, Path::new("s.toml"), base, &opts()) else {
            panic!("{file} was accepted")
        };
        let e = e.to_string();
        assert!(e.starts_with(&format!("s.toml:{line}:")), "{file}: {e}");
        assert!(e.contains(&format!("shapes[1].path = \"{file}\"")), "{e}");
        assert!(e.contains(obj_place) && e.contains(says), "{e}");
    }
}

/// A displaced OBJ mesh whose triangles are too large (coordinates of
/// 1e17, inside the coordinate limit) or too small to measure in single
/// precision is refused saying so: the overflow was reported as a NaN
/// extent, and a 1e-30 triangle as degenerate texture coordinates only.
#[test]
fn displaced_meshes_too_large_or_small_to_measure_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    for (name, s) in [("big.obj", 1e17f32), ("tiny.obj", 1e-30), ("ok.obj", 1.0)] {
        let obj = format!("v 0 0 0\nv {s} 0 0\nv 0 {s} 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n");
        std::fs::write(base.join(name), obj).unwrap();
        let text = with_shape(&format!(
                "type = \"mesh\"\npath = \"{name}\"\n\
                 displacement = {{ height = \"gen:gaussian\", height_size = [8, 8], map_size = [8, 8, 2], depth = 0.1 }}"
            ),
        );
        let loaded = Scene::from_toml(&text, Path::new("test.toml"), base, &opts());
        match (name, loaded) {
            ("ok.obj", r) => assert!(r.is_ok(), "{:?}", r.err().map(|e| e.to_string())),
            (_, Ok(_)) => panic!("{name} was accepted"),
            (_, Err(e)) => {
                let e = e.to_string();
                assert!(
                    e.contains("shapes[0]") && e.contains("too large or too small"),
                    "{e}"
                );
            }
        }
    }
}

/// Sizes past what single precision holds are refused at their keys (a
/// sphere of radius 1e21, a lens of 1e31 or focused at 1e30, a mesh scaled
/// past 1e18), where the shape or the lens vanished from the image; a
/// built-in mesh scaled large but within the bound keeps every face (at a
/// scale of 5e10 the area test overflowed and dropped three faces in four).
#[test]
fn sizes_past_single_precision_are_refused_and_large_meshes_keep_their_faces() {
    let sphere_r = |r: &str| {
        with(
            SPHERE,
            &SPHERE.replace("radius = 1", &format!("radius = {r}")),
        )
    };
    let camera = |extra: &str| with("[camera]", &format!("[camera]\n{extra}"));
    let mesh = |scale: &str| {
        with_shape(&format!(
            "type = \"mesh\"\npath = \"builtin:sphere\"\nscale = {scale}"
        ))
    };
    for (text, key) in [
        (sphere_r("1e21"), "shapes[0].radius"),
        (camera("aperture = 1e31"), "aperture"),
        (
            camera("aperture = 0.1\nfocus_distance = 1e30"),
            "focus_distance",
        ),
        (mesh("2e18"), "shapes[0]"),
    ] {
        let Err(e) = Scene::from_toml(&text, Path::new("s.toml"), Path::new("."), &opts()) else {
            panic!("accepted: {text}")
        };
        let e = e.to_string();
        assert!(e.contains(key) && e.contains("1e18"), "{e}");
    }
    assert!(Scene::from_toml(
        &sphere_r("1e18"),
        Path::new("s.toml"),
        Path::new("."),
        &opts()
    )
    .is_ok());
    let faces = |scale: &str| {
        Scene::from_toml(&mesh(scale), Path::new("s.toml"), Path::new("."), &opts())
            .unwrap()
            .primitive_count()
    };
    let whole = faces("1");
    assert!(whole > 1000, "{whole}");
    for scale in ["5e10", "1e15"] {
        assert_eq!(faces(scale), whole, "scale {scale}");
    }
}

/// A displaced face whose height file is an elevation model (32-bit float
/// metres, as GDAL writes one): refused as stored (heights lie in [0, 1]),
/// naming the key and the file; with `height_range = "auto"`, or the
/// model's own extremes as `[lo, hi]`, it renders exactly as the same
/// heights normalised beforehand; a range that is not one is refused at its
/// line and column.
#[test]
fn elevation_models_render_through_their_height_range() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    let size = [16u32, 16u32];
    let dem = elevation::sampled(size, |x, y| {
        850.0 + 40.0 * (x * 0.7).sin() + 25.0 * (y * 0.5).cos()
    });
    let (lo, hi) = elevation::extremes(&dem);
    let unit = elevation::normalised(&dem);
    elevation::write_float_tiff(&base.join("dem.tif"), size, &dem);
    elevation::write_float_tiff(&base.join("unit.tif"), size, &unit);
    let text = |height: &str, range: &str| {
        SceneToml::new(12, 12, 1)
            .camera("[0.3, 2.5, -1.5]", 50.0)
            .lambert("[0.6, 0.6, 0.6]")
            .point_light("[1, 3, -1]", "[12, 12, 12]")
            .quad(0.0)
            .displaced(&format!(
                "height = \"{height}\"\ndepth = 0.3\nmap_size = [16, 16, 8]{range}"
            ))
            .text()
            .to_string()
    };
    let load = |text: &str| Scene::from_toml(text, Path::new("test.toml"), base, &opts());
    let e = load(&text("dem.tif", "")).err().unwrap().to_string();
    assert!(
        e.contains("shapes[0].displacement.height")
            && e.contains("dem.tif")
            && e.contains("[0, 1]"),
        "{e}"
    );
    let want = image(&load(&text("unit.tif", "")).unwrap()).pixels;
    for range in [
        "\nheight_range = \"auto\"",
        &format!("\nheight_range = [{lo}, {hi}]"),
    ] {
        let got = image(&load(&text("dem.tif", range)).unwrap()).pixels;
        assert_eq!(got, want, "{range}");
    }
    // The flat-lit render is not one colour: the heights reached it.
    assert!(want.iter().any(|p| *p != want[0]));
    for bad in ["\"nope\"", "[5, 1]"] {
        let t = text("dem.tif", &format!("\nheight_range = {bad}"));
        let line = t
            .lines()
            .position(|l| l.starts_with("height_range"))
            .unwrap()
            + 1;
        let e = load(&t).err().unwrap().to_string();
        assert!(
            e.starts_with(&format!("test.toml:{line}:16: "))
                && e.contains("shapes[0].displacement.height_range"),
            "{e}"
        );
    }
}

/// Values the renderer's arithmetic cannot hold are refused at their key,
/// not rendered into infinite or black pixels: a reflectance above 1 (two
/// facing mirrors of colour 1e18 reach infinity in three bounces), light
/// past `MAX_RADIANCE`; the bounds themselves pass.
#[test]
fn colours_and_lights_past_what_single_precision_holds_are_refused() {
    use displace_render::scene::MAX_RADIANCE;
    let load = |text: String| {
        Scene::from_toml(&text, Path::new("test.toml"), Path::new("."), &opts())
            .map_err(|e| e.to_string())
    };
    let grey = "color = [0.5, 0.5, 0.5]";
    let mirror = "type = \"mirror\"\ncolor = [1e18, 1e18, 1e18]";
    for (text, key, why) in [
        (
            with(grey, "color = [1.5, 0.5, 0.5]"),
            "materials.m.color",
            "at most 1",
        ),
        (
            with(&format!("type = \"lambert\"\n{grey}"), mirror),
            "materials.m.color",
            "at most 1",
        ),
        (
            with(grey, &format!("{grey}\nemission = [1e16, 1, 1]")),
            "materials.m.emission",
            "at most 1e15",
        ),
        (
            with("intensity = [10, 10, 10]", "intensity = [1e17, 0, 0]"),
            "lights[0].intensity",
            "at most 1e15",
        ),
    ] {
        let Err(e) = load(text) else {
            panic!("{key}: accepted");
        };
        assert!(e.contains(key) && e.contains(why), "{key}: {e}");
    }
    let at_bounds = format!("intensity = [{MAX_RADIANCE:e}, 0, 0]");
    assert!(load(with(grey, "color = [1, 1, 0]")).is_ok());
    assert!(load(with("intensity = [10, 10, 10]", &at_bounds)).is_ok());
}
