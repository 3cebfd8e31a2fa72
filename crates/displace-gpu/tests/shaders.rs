//! Every shader module validates under naga, the WGSL conventions equal the
//! Rust ones (and through them displace-core's), and the uniform's layout
//! matches its Rust mirror byte for byte.

use displace_core::convention::{texel_centre, texel_lerp};
use displace_core::{Address, Method};
use displace_gpu::convention as rs;
use displace_gpu::shaders::{all_modules, undecorated, CONVENTION};
use displace_gpu::{MapParams, Shadows};
use std::collections::BTreeMap;

fn validate(name: &str, src: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    module
}

#[test]
fn every_module_validates() {
    let modules = all_modules();
    assert!(!modules.is_empty());
    for (name, src) in &modules {
        validate(name, src);
    }
}

/// `const NAME: TYPE = VALUE;` lines of convention.wgsl.
fn wgsl_constants() -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for line in CONVENTION.lines() {
        let Some(rest) = line.trim().strip_prefix("const ") else {
            continue;
        };
        let (name, rest) = rest.split_once(':').expect("typed constant");
        let (_, value) = rest.split_once('=').expect("constant value");
        let value = value.trim().trim_end_matches(';').trim_end_matches('u');
        out.insert(
            name.trim().to_string(),
            value
                .parse::<f64>()
                .unwrap_or_else(|_| panic!("{name} = {value}")),
        );
    }
    out
}

#[test]
fn convention_constants_match_rust() {
    let wgsl = wgsl_constants();
    let rust: BTreeMap<&str, f64> = [
        ("TEXEL_CENTRE", rs::TEXEL_CENTRE as f64),
        ("ADDRESS_CLAMP", rs::address_code(Address::Clamp) as f64),
        ("ADDRESS_REPEAT", rs::address_code(Address::Repeat) as f64),
        ("METHOD_SPHERE", rs::method_code(Method::Sphere) as f64),
        (
            "METHOD_SPHERE_FIXED",
            rs::method_code(Method::SphereFixed) as f64,
        ),
        ("METHOD_EXACT", rs::method_code(Method::Exact) as f64),
        ("SHADOWS_NONE", rs::shadows_code(Shadows::None) as f64),
        ("SHADOWS_HARD", rs::shadows_code(Shadows::Hard) as f64),
        ("SHADOWS_SOFT", rs::shadows_code(Shadows::Soft) as f64),
        ("HIT_NONE", rs::HIT_NONE as f64),
        ("HIT_SURFACE", rs::HIT_SURFACE as f64),
        ("HIT_WALL", rs::HIT_WALL as f64),
        ("HIT_PLAIN", rs::HIT_PLAIN as f64),
        ("FLAG_CONVERGED", rs::FLAG_CONVERGED as f64),
        ("FLAG_CELL_CAP", rs::FLAG_CELL_CAP as f64),
        ("FLAG_LOOP_CUT", rs::FLAG_LOOP_CUT as f64),
        ("INSIDE_EPS", rs::INSIDE_EPS as f64),
        ("ROOT_EPS", rs::ROOT_EPS as f64),
        ("LINEAR_EPS", rs::LINEAR_EPS as f64),
        ("BIG", rs::BIG as f64),
        ("CHORD_TOLERANCE", rs::CHORD_TOLERANCE as f64),
    ]
    .into_iter()
    .collect();
    let names: Vec<&str> = wgsl.keys().map(String::as_str).collect();
    let expected: Vec<&str> = rust.keys().copied().collect();
    assert_eq!(
        names, expected,
        "every WGSL convention constant needs a Rust mirror and vice versa"
    );
    for (name, want) in &rust {
        let got = wgsl[*name];
        // Compare at f32 precision: the shader's constants are f32 or u32.
        assert_eq!(
            got as f32, *want as f32,
            "{name}: WGSL {got} vs Rust {want}"
        );
    }
    // The Rust mirrors against displace-core's own functions.
    for n in [1usize, 2, 7, 256] {
        for i in [0usize, 1, n / 2, n - 1] {
            assert_eq!(texel_centre(i, n), (i as f32 + rs::TEXEL_CENTRE) / n as f32);
            let (j, w) = texel_lerp(texel_centre(i, n), n);
            assert_eq!((j, w), (i as i64, 0.0));
        }
    }
    assert_ne!(rs::ADDRESS_CLAMP, rs::ADDRESS_REPEAT);
}

#[test]
fn map_params_layout_matches_wgsl() {
    let (_, src) = &all_modules()[0];
    let module = validate("layout", src);
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref().map(undecorated) == Some("MapParams"))
        .expect("MapParams in WGSL");
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("MapParams is a struct")
    };
    assert_eq!(*span as usize, std::mem::size_of::<MapParams>());
    let rust_offsets: BTreeMap<&str, usize> = displace_gpu::field_offsets!(MapParams {
        aspect,
        tiles,
        dist_size,
        address,
        height_size,
        tau,
        band,
        decode_scale,
        decode_offset,
        max_cells,
        method,
        iterations,
        t_min,
        t_max,
        pad_end,
    })
    .iter()
    .copied()
    .collect();
    assert_eq!(members.len(), rust_offsets.len());
    for m in members {
        let name = m.name.as_deref().unwrap();
        assert_eq!(m.offset as usize, rust_offsets[name], "MapParams.{name}");
    }
}

/// `TECH_NAME` in techniques.wgsl for each technique: its name upper-cased.
#[test]
fn technique_constants_match_rust() {
    use displace_core::techniques::Technique;
    use displace_gpu::shaders::TECHNIQUES;
    let wgsl: BTreeMap<String, u32> = TECHNIQUES
        .lines()
        .filter_map(|l| l.trim().strip_prefix("const TECH_"))
        .map(|rest| {
            let (name, rest) = rest.split_once(':').expect("typed constant");
            let (_, value) = rest.split_once('=').expect("constant value");
            let value = value.trim().trim_end_matches(';').trim_end_matches('u');
            (name.trim().to_string(), value.parse().expect("u32 code"))
        })
        .collect();
    assert_eq!(wgsl.len(), Technique::ALL.len());
    for t in Technique::ALL {
        let name = t.name().to_uppercase().replace('-', "_");
        assert_eq!(
            wgsl.get(&name),
            Some(&rs::technique_code(t)),
            "TECH_{name} in techniques.wgsl"
        );
    }
}
