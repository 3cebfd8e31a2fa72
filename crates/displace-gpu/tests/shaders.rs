//! Every shader module this crate composes validates under naga, and the
//! technique codes equal the Rust ones. The conventions and `MapParams`'s
//! layout are displace-shaders' own tests.

use displace_gpu::convention as rs;
use displace_gpu::shaders::all_modules;
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
