//! The WGSL conventions equal the Rust ones (and through them
//! displace-core's), `MapParams`'s layout matches its WGSL struct byte for
//! byte, and `encase` (Bevy's uniform writer) lays it out as the bytes
//! displace-gpu uploads.

use displace_core::convention::{texel_centre, texel_lerp};
use displace_core::{Address, Method, TraceOptions};
use displace_shaders::codes as rs;
use displace_shaders::wgsl::CONVENTION;
use displace_shaders::{cell_cap, Decode, MapParams};
use std::collections::BTreeMap;

/// `&[(name, offset)]` of a `repr(C)` struct's fields.
macro_rules! offsets {
    ($t:ty { $($field:ident),* $(,)? }) => {
        &[$((stringify!($field), std::mem::offset_of!($t, $field))),*]
    };
}

/// convention.wgsl parsed and validated by naga, its import path line
/// (naga_oil's, not WGSL) left out.
fn convention_module() -> naga::Module {
    let src: String = CONVENTION
        .lines()
        .filter(|l| !l.starts_with("#define_import_path"))
        .collect::<Vec<_>>()
        .join("\n");
    let module = naga::front::wgsl::parse_str(&src)
        .unwrap_or_else(|e| panic!("convention.wgsl: {}", e.emit_to_string(&src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("convention.wgsl: {}", e.emit_to_string(&src)));
    module
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
        ("SHADOWS_NONE", rs::SHADOWS_NONE as f64),
        ("SHADOWS_HARD", rs::SHADOWS_HARD as f64),
        ("SHADOWS_SOFT", rs::SHADOWS_SOFT as f64),
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
    let module = convention_module();
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some("MapParams"))
        .expect("MapParams in WGSL");
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("MapParams is a struct")
    };
    assert_eq!(*span as usize, std::mem::size_of::<MapParams>());
    let rust_offsets: BTreeMap<&str, usize> = offsets!(MapParams {
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

/// `GpuPrism` is laid out as WGSL's `Prism` (`displace::curved_prism`):
/// nine 16-byte members in order, 144 bytes, the storage array's stride,
/// so the prisms displace-gpu and displace-bevy upload read as written.
#[test]
fn prism_layout_matches_wgsl() {
    use displace_shaders::curved_prisms::GpuPrism;
    let src: String = displace_shaders::wgsl::CURVED_PRISM
        .lines()
        .filter(|l| !l.starts_with("#define_import_path"))
        .collect::<Vec<_>>()
        .join("\n");
    let module = naga::front::wgsl::parse_str(&src)
        .unwrap_or_else(|e| panic!("curved_prism.wgsl: {}", e.emit_to_string(&src)));
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some("Prism"))
        .expect("Prism in WGSL");
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("Prism is a struct")
    };
    assert_eq!(*span as usize, std::mem::size_of::<GpuPrism>());
    // Rust's fields: p (3 corners), n (3 normals), m01, m2, adj.
    let rust = [0, 16, 32, 48, 64, 80, 96, 112, 128];
    let names = ["pa", "pb", "pc", "na", "nb", "nc", "mab", "mc", "adj"];
    assert_eq!(members.len(), rust.len());
    for ((m, offset), name) in members.iter().zip(rust).zip(names) {
        assert_eq!(m.name.as_deref(), Some(name));
        assert_eq!(m.offset as usize, offset, "Prism.{name}");
    }
    let p = GpuPrism::default();
    let base = &p as *const GpuPrism as usize;
    assert_eq!(&p.n as *const _ as usize - base, 48);
    assert_eq!(&p.m01 as *const _ as usize - base, 96);
    assert_eq!(&p.m2 as *const _ as usize - base, 112);
    assert_eq!(&p.adj as *const _ as usize - base, 128);
}

/// Bevy uploads `MapParams` with `encase`, displace-gpu with `bytemuck`:
/// the same 80 bytes, for maps of both addressings and every trace option.
#[test]
fn encase_writes_the_bytes_bytemuck_uploads() {
    let decode = Decode {
        scale: 0.0123,
        offset: -0.004,
        underestimate: 0.0071,
    };
    for (address, tiles) in [(Address::Clamp, [1.0, 1.0]), (Address::Repeat, [3.0, 0.5])] {
        let base = MapParams::for_map(
            [4.5, 2.25],
            [64, 32, 16],
            glam::Vec3::new(0.07, 0.07, 1.0 / 16.0),
            address,
            [257, 129],
            &decode,
        );
        let opts = TraceOptions {
            tiles,
            method: Method::SphereFixed,
            iterations: 37,
            t_min: -f32::INFINITY,
            t_max: 2.5,
        };
        let p = base.with_trace(&opts);
        let mut buffer = encase::UniformBuffer::new(Vec::<u8>::new());
        buffer.write(&p).unwrap();
        assert_eq!(buffer.into_inner(), bytemuck::bytes_of(&p));
        assert_eq!(<MapParams as encase::ShaderType>::min_size().get(), 80);
        // The values the shaders read.
        assert_eq!(p.address, rs::address_code(address));
        assert_eq!(p.method, rs::METHOD_SPHERE_FIXED);
        assert_eq!((p.t_min, p.t_max), (-rs::BIG, 2.5));
        assert_eq!(p.tau, rs::TAU_VOXELS * 1.0 / 16.0);
        assert_eq!(p.band, rs::BAND_FACTOR * 0.0071 + p.tau);
        assert_eq!(p.max_cells, cell_cap(p.height_size, tiles));
    }
    // One cell per texel column and row of the face, the borders' half
    // cells, saturating where a repeat would overflow.
    assert_eq!(
        cell_cap(glam::UVec2::new(257, 129), [1.0, 1.0]),
        2 * (257 + 129) + 64
    );
    assert_eq!(cell_cap(glam::UVec2::new(2, 2), [1e30, 1e30]), u32::MAX);
}

/// Every module of the library names its import path on its first line,
/// `displace::` and its file name, as naga_oil and Bevy's cache look them
/// up; entry points have none.
#[test]
fn modules_name_their_import_path() {
    use displace_shaders::wgsl::*;
    for (src, path) in [
        (CONVENTION, "displace::convention"),
        (DISTANCE_LOAD, "displace::distance"),
        (DISTANCE_FILTERED, "displace::distance"),
        (SURFACE, "displace::surface"),
        (BINDINGS_LOAD, "displace::bindings"),
        (BINDINGS_FILTERED, "displace::bindings"),
        (BATCH, "displace::batch"),
        (LIGHTING, "displace::lighting"),
        (SHADE, "displace::shade"),
        (TECHNIQUES, "displace::techniques"),
        (CURVED_PRISM, "displace::curved_prism"),
        (CURVED_BINDINGS, "displace::curved_bindings"),
        (CURVED_WALK, "displace::curved_walk"),
    ] {
        let first = src.lines().next().unwrap_or_default();
        assert_eq!(first, format!("#define_import_path {path}"));
    }
    for entry in [
        TRACE_COMPUTE,
        RASTER,
        MESH,
        CURVED,
        PLAIN,
        FETCH_LOOP,
        PRESENT,
        TECHNIQUE_COMPUTE,
    ] {
        assert!(!entry.contains("#define_import_path"));
    }
}

/// No remainder of a signed integer in the shader library. WGSL's `%`
/// truncates, but naga's GLSL for OpenGL drivers keeps `%`, whose result
/// GLSL leaves undefined for negative operands: a repeating map's texel
/// index wrapped with `%` read the wrong texels left of the first tile on
/// llvmpipe's OpenGL (0.3% of a test's rays changed hit or miss), where
/// Vulkan was right. Checked on naga's typed module for `convention`
/// (where the wrap lives) and on the text of every module: each `%` takes
/// an unsigned literal on its right.
#[test]
fn no_signed_remainders() {
    use naga::{BinaryOperator, Expression, ScalarKind};
    let module = convention_module();
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .expect("convention.wgsl validates");
    for (handle, function) in module.functions.iter() {
        let fi = &info[handle];
        for (e, expr) in function.expressions.iter() {
            if let Expression::Binary {
                op: BinaryOperator::Modulo,
                left,
                ..
            } = expr
            {
                let kind = fi[*left].ty.inner_with(&module.types).scalar_kind();
                assert_ne!(
                    kind,
                    Some(ScalarKind::Sint),
                    "convention.wgsl: `{}` takes the remainder of a signed integer ({e:?})",
                    function.name.as_deref().unwrap_or("?")
                );
            }
        }
    }
    // Every file of the library, read from its directory, so that a module
    // added later is checked without being listed here.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("the shaders directory")
        .map(|e| e.expect("a directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    assert!(
        files.len() >= 18,
        "{} modules in {}",
        files.len(),
        dir.display()
    );
    for path in files {
        let src = std::fs::read_to_string(&path).expect("a WGSL module");
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        for (k, line) in src.lines().enumerate() {
            let code = line.split("//").next().unwrap_or_default();
            for (at, _) in code.match_indices('%') {
                let right: String = code[at + 1..]
                    .trim_start()
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                let unsigned_literal = right.ends_with('u')
                    && right.len() > 1
                    && right[..right.len() - 1].chars().all(|c| c.is_ascii_digit());
                assert!(
                    unsigned_literal,
                    "{name}:{}: `%` by `{right}`: take remainders of unsigned values only \
                     (see this test's notes)\n{line}",
                    k + 1
                );
            }
        }
    }
}
