//! The WGSL of the shader library ([`displace_shaders::wgsl`], naga_oil's
//! `#define_import_path` and `#import`: WGSL itself has no include),
//! composed per entry point by [`compose`]. The shared modules
//! (`convention`, `distance_*`, `surface`) are also registered by
//! displace-bevy with Bevy's own naga_oil composer, so both crates run the
//! one trace; each crate supplies its `displace::bindings`.

pub use displace_shaders::wgsl::*;

/// How the shaders read the distance map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DistanceTexture {
    /// R32Float, interpolated by hand from `textureLoad` with the CPU's
    /// texel centres, addressing and order of operations: the stored values
    /// at full precision, on any GPU (R32Float need not be filterable).
    #[default]
    R32Load,
    /// The CPU tracer's own 8-bit codes ([`displace_core::DistanceMap::sample`]),
    /// stored as R32Float, interpolated by `textureLoad` in its order of
    /// operations and decoded as it decodes them: bit for bit the distances
    /// the CPU reads, so Donnelly's fixed loop stops where the CPU's does
    /// (`displace compare` runs the CPU and WGSL techniques side by side).
    R8Load,
    /// R16Float rounded down, through a linear sampler (Donnelly's way).
    R16Linear,
    /// R8Unorm rounded down over the map's range, through a linear sampler:
    /// the 8-bit maps of GPU Gems 2 section 8.6.
    R8Linear,
}

impl DistanceTexture {
    /// Every variant, in the order benchmarks print them.
    pub const ALL: [DistanceTexture; 4] =
        [Self::R32Load, Self::R8Load, Self::R16Linear, Self::R8Linear];

    /// The name [`str::parse`] accepts, as the CLI's `--texture` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::R32Load => "r32-load",
            Self::R8Load => "r8-load",
            Self::R16Linear => "r16-linear",
            Self::R8Linear => "r8-linear",
        }
    }

    /// Whether the texture is read through a linear sampler, which needs the
    /// filter-error allowance of [`crate::convention::FILTER_WEIGHT_BITS`].
    pub fn filtered(self) -> bool {
        matches!(self, Self::R16Linear | Self::R8Linear)
    }
}

impl std::str::FromStr for DistanceTexture {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        let choices = Self::ALL.map(|d| (d.name(), d));
        displace_core::names::parse_choice("distance texture", s, &choices)
            .map_err(crate::Error::InvalidOption)
    }
}

/// The shader modules an entry point may import, in the order naga_oil needs
/// them (each after the modules it imports), with the `displace::bindings`
/// and `displace::distance` of one distance-lookup flavour.
fn library(texture: DistanceTexture) -> [(&'static str, &'static str); 11] {
    let (bindings, distance) = if texture.filtered() {
        (
            ("bindings_filtered.wgsl", BINDINGS_FILTERED),
            ("distance_filtered.wgsl", DISTANCE_FILTERED),
        )
    } else {
        (
            ("bindings_load.wgsl", BINDINGS_LOAD),
            ("distance_load.wgsl", DISTANCE_LOAD),
        )
    };
    [
        ("convention.wgsl", CONVENTION),
        bindings,
        distance,
        ("surface.wgsl", SURFACE),
        ("curved_prism.wgsl", CURVED_PRISM),
        ("curved_bindings.wgsl", CURVED_BINDINGS),
        ("curved_walk.wgsl", CURVED_WALK),
        ("lighting.wgsl", LIGHTING),
        ("shade.wgsl", SHADE),
        ("batch.wgsl", BATCH),
        ("techniques.wgsl", TECHNIQUES),
    ]
}

/// The composer of one distance-lookup flavour with every module of
/// [`library`] added, built once per process: each module is parsed once,
/// not once per entry point.
fn with_composer<R>(
    texture: DistanceTexture,
    f: impl FnOnce(&mut naga_oil::compose::Composer) -> R,
) -> R {
    use naga_oil::compose::{ComposableModuleDescriptor, Composer, ShaderLanguage};
    use std::sync::{Mutex, OnceLock, PoisonError};
    static LOAD: OnceLock<Mutex<Composer>> = OnceLock::new();
    static FILTERED: OnceLock<Mutex<Composer>> = OnceLock::new();
    let cell = if texture.filtered() { &FILTERED } else { &LOAD };
    let composer = cell.get_or_init(|| {
        let mut composer = Composer::default();
        for (path, src) in library(texture) {
            if let Err(e) = composer.add_composable_module(ComposableModuleDescriptor {
                source: src,
                file_path: path,
                language: ShaderLanguage::Wgsl,
                ..Default::default()
            }) {
                panic!("shader module {path}: {}", e.emit_to_string(&composer));
            }
        }
        Mutex::new(composer)
    });
    f(&mut composer.lock().unwrap_or_else(PoisonError::into_inner))
}

/// One entry-point file composed with the modules it `#import`s (naga_oil,
/// as Bevy's shader cache composes the same modules), validated, and
/// written back as one WGSL source for `wgpu`. Items of imported modules
/// keep their names with naga_oil's module suffix ([`undecorated`] strips
/// it). The sources are this crate's own files, so a failure here is a
/// defect of the crate, caught by the test that composes every module.
pub fn compose(file: &str, source: &str, texture: DistanceTexture) -> String {
    use naga_oil::compose::{NagaModuleDescriptor, ShaderType};
    let module = with_composer(texture, |composer| {
        composer
            .make_naga_module(NagaModuleDescriptor {
                source,
                file_path: file,
                shader_type: ShaderType::Wgsl,
                ..Default::default()
            })
            .unwrap_or_else(|e| panic!("shader {file}: {}", e.emit_to_string(composer)))
    });
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("shader {file}: {e}"));
    naga::back::wgsl::write_string(&module, &info, naga::back::wgsl::WriterFlags::empty())
        .unwrap_or_else(|e| panic!("shader {file}: writing WGSL: {e}"))
}

/// A WGSL item's name as its module declares it: naga_oil appends
/// `X_naga_oil_mod_X<module>X` to the items it imports into a composition.
pub fn undecorated(name: &str) -> &str {
    name.split("X_naga_oil_mod_X").next().unwrap_or(name)
}

/// The batch ray query kernel.
pub fn compute_trace_source(texture: DistanceTexture) -> String {
    compose("trace_compute.wgsl", TRACE_COMPUTE, texture)
}

/// The batch query of every technique (`shaders/techniques.wgsl`).
pub fn technique_compute_source(texture: DistanceTexture) -> String {
    compose("technique_compute.wgsl", TECHNIQUE_COMPUTE, texture)
}

/// Donnelly's vertex and fragment stages (fixed-step, early-out and
/// shadowing variants are uniforms of one module).
pub fn raster_source(texture: DistanceTexture) -> String {
    compose("raster.wgsl", RASTER, texture)
}

/// The mesh variant of the raster path: the same fragment work, started
/// from each mesh triangle's shell in its MikkTSpace frame.
pub fn mesh_source(texture: DistanceTexture) -> String {
    compose("mesh.wgsl", MESH, texture)
}

/// The curved-mesh variant of the raster path: the CPU's shells along the
/// vertex normals, walked prism to prism per fragment.
pub fn curved_source(texture: DistanceTexture) -> String {
    compose("curved.wgsl", CURVED, texture)
}

/// Non-displaced triangles beside the displaced draws (no map: the
/// flavour only names the modules it does not import).
pub fn plain_source() -> String {
    compose("plain.wgsl", PLAIN, DistanceTexture::default())
}

/// The bare loop of dependent filtered fetches (benchmarks only).
pub fn fetch_loop_source() -> String {
    compose("fetch_loop.wgsl", FETCH_LOOP, DistanceTexture::R16Linear)
}

/// Every complete shader module this crate builds, by name, for validation.
pub fn all_modules() -> Vec<(String, String)> {
    let mut out = Vec::new();
    for t in DistanceTexture::ALL {
        out.push((
            format!("trace-compute/{}", t.name()),
            compute_trace_source(t),
        ));
        out.push((format!("raster/{}", t.name()), raster_source(t)));
        out.push((format!("mesh/{}", t.name()), mesh_source(t)));
        out.push((format!("curved/{}", t.name()), curved_source(t)));
        out.push((
            format!("technique-compute/{}", t.name()),
            technique_compute_source(t),
        ));
    }
    out.push(("plain".into(), plain_source()));
    out.push(("fetch-loop/filtered".into(), fetch_loop_source()));
    out.push(("present".into(), PRESENT.to_string()));
    out
}

/// Checks a `repr(C)` Rust mirror against the WGSL struct it feeds: the
/// struct's size and every member's offset as naga lays the WGSL out
/// (`rust` lists the WGSL member names with the Rust offsets, in order).
/// `src` may be a composed source ([`compose`]), whose writer (naga's
/// namer) appends `_` to every name ending in a digit: the expected names
/// go through the same rule.
/// Each mirror's module has a test that calls it, so a field added, moved
/// or retyped on one side only fails the build's tests, not a frame.
#[cfg(test)]
pub(crate) fn assert_layout(src: &str, wgsl_name: &str, size: usize, rust: &[(&str, usize)]) {
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{wgsl_name}: {}", e.emit_to_string(src)));
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref().map(undecorated) == Some(wgsl_name))
        .unwrap_or_else(|| panic!("no struct {wgsl_name} in the WGSL"));
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("{wgsl_name} is not a struct")
    };
    assert_eq!(
        *span as usize, size,
        "{wgsl_name}: WGSL size against the Rust mirror's"
    );
    let wgsl: Vec<(String, usize)> = members
        .iter()
        .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
        .collect();
    let composed = src.contains("X_naga_oil_mod_X");
    let written = |name: &str| {
        if composed && name.ends_with(|c: char| c.is_ascii_digit()) {
            format!("{name}_")
        } else {
            name.to_string()
        }
    };
    let rust: Vec<(String, usize)> = rust.iter().map(|&(n, o)| (written(n), o)).collect();
    assert_eq!(wgsl, rust, "{wgsl_name}: member names and offsets");
}

/// [`crate::field_offsets`], for [`assert_layout`].
#[cfg(test)]
pub(crate) use crate::field_offsets as offsets;

#[cfg(test)]
mod tests {
    use super::*;

    /// Every module names its import path on its first line (Bevy's
    /// composer and [`compose`] find it there), and a composed source is
    /// plain WGSL: no directive survives, and imported items are suffixed.
    #[test]
    fn modules_name_their_path_and_compose_to_plain_wgsl() {
        for (name, src) in library(DistanceTexture::R32Load)
            .into_iter()
            .chain(library(DistanceTexture::R8Linear))
        {
            assert!(
                src.lines()
                    .next()
                    .unwrap_or("")
                    .starts_with("#define_import_path displace::"),
                "{name}: first line is its import path"
            );
        }
        let raster = raster_source(DistanceTexture::R32Load);
        assert!(!raster.lines().any(|l| l.trim_start().starts_with('#')));
        assert!(
            raster.contains("fn fs_main"),
            "the entry point keeps its name"
        );
        assert!(
            raster.contains("fn trace_mapX_naga_oil_mod_X"),
            "an imported function is decorated"
        );
        assert_eq!(undecorated("trace_mapX_naga_oil_mod_XMRZXGX"), "trace_map");
        assert_eq!(undecorated("trace_map"), "trace_map");
    }
}
