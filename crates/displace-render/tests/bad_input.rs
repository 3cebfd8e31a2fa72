//! Adversarial scene input (docs/reliability.md): vectors with extra components, counts past
//! their bounds, coordinates that overflow, textures named by their key,
//! and the deepest reflection the bound allows rendered without
//! overflowing the stack.

mod common;

use common::scene_toml::SceneToml;
use common::*;
use displace_render::scene::{MAX_DEPTH, MAX_SHADOW_SAMPLES, MAX_SPP};

/// A lit sphere, 4 x 4 pixels at 1 spp.
fn sphere() -> SceneToml {
    SceneToml::new(4, 4, 1)
        .camera("[0, 0, -4]", 40.0)
        .lambert("[0.5, 0.5, 0.5]")
        .point_light("[0, 3, -3]", "[10, 10, 10]")
        .shape("type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1")
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
        with(
            "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
            &format!(
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
    let e = scene_err(&with(
        "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
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
    let e = scene_err(&with(
        "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
        "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
         displacement = { height = \"gen:gaussian\", depth = 0.1, address = \"mirror\" }",
    ));
    assert!(
        e.contains("address") && e.contains("mirror") && !e.contains("invalid size"),
        "{e}"
    );
}
