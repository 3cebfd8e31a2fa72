//! Distance mapping (William Donnelly, *Per-Pixel Displacement Mapping with
//! Distance Functions*, GPU Gems 2 ch. 8) as a Bevy material:
//! [`DistanceMappedMaterial`] is `ExtendedMaterial<StandardMaterial,
//! DistanceMapping>`.
//!
//! Bevy's own `ParallaxMappingMethod` (parallax occlusion and relief
//! mapping) offsets the texture coordinate only: depth, shadows and the
//! silhouette stay those of the flat mesh. This extension's fragment stage
//! marches the conservative distance map of section 8.4 from the mesh's
//! point on the shell (section 8.5, listing 8-2) with the exact refinement
//! on the bilinear height surface that `displace-gpu` runs (the same WGSL
//! modules of `displace-shaders`, `displace::convention`,
//! `displace::distance`, `displace::surface`, and the same `MapParams`), then writes the displaced point's depth in the main
//! pass, the prepass and every shadow pass, discards rays that leave the
//! shell through its sides, and hands the displaced point and texture
//! coordinate to Bevy's PBR lighting (section 8.5.3 for the derivatives).
//!
//! A flat shell shows every triangle of a curved mesh as a facet, with
//! seams where neighbours disagree; [`CurvedMappedMaterial`] ([`curved`])
//! draws curved meshes through shells along their vertex normals instead,
//! walked per fragment by the same WGSL as `displace gpu-render`'s.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use displace_bevy::{DistanceMappedMaterial, DistanceMapping, DistanceMappingPlugin, Encoding};
//! # fn setup(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>,
//! #     mut images: ResMut<Assets<Image>>, mut materials: ResMut<Assets<DistanceMappedMaterial>>) {
//! let height = displace_core::io::height::load("gen:studded", &Default::default()).unwrap();
//! let mapping = DistanceMapping::bake(&height, &Default::default(), Encoding::R8, &mut images).unwrap();
//! commands.spawn((
//!     Mesh3d(meshes.add(Plane3d::default().mesh().size(1.0, 1.0))),
//!     MeshMaterial3d(materials.add(DistanceMappedMaterial { base: StandardMaterial::default(), extension: mapping })),
//! ));
//! # }
//! App::new().add_plugins((DefaultPlugins, DistanceMappingPlugin)).add_systems(Startup, setup).run();
//! ```

#![warn(missing_docs)]

pub mod curved;
pub mod headless;

pub use curved::{CurvedMappedMaterial, CurvedMapping, CurvedShellMesh};

use bevy::asset::{uuid_handle, RenderAssetUsages};
use bevy::image::{
    CompressedImageFormats, ImageAddressMode, ImageFilterMode, ImageSampler,
    ImageSamplerDescriptor, ImageType, TextureError,
};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, ShaderType, TextureDimension, TextureFormat,
};
use bevy::shader::{Shader, ShaderRef};
use displace_core::distance_map::{FilteredTexels, Format};
use displace_core::BakeOptions;
use displace_core::{Address, DisplacementMap, DistanceMap, HeightMap, Method};
use displace_shaders::{cell_cap, method_code, wgsl, Decode, BIG};

/// The material a Bevy user puts on a mesh: Bevy's `StandardMaterial` (its
/// maps, lighting and shadows) with the distance-mapping extension.
pub type DistanceMappedMaterial = ExtendedMaterial<StandardMaterial, DistanceMapping>;

/// `displace::bindings`: the material bind group's view of the map.
const BINDINGS: &str = include_str!("bindings.wgsl");
/// The extension's fragment stage (main pass and prepass).
const MATERIAL: &str = include_str!("distance_mapping.wgsl");
/// `displace::displaced_outputs`: what both materials write for a
/// displaced point (depth, prepass normal and motion, colour).
const OUTPUTS: &str = include_str!("displaced_outputs.wgsl");

const CONVENTION_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e01");
const DISTANCE_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e02");
const SURFACE_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e03");
const BINDINGS_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e04");
const CURVED_PRISM_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e07");
const CURVED_BINDINGS_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e08");
const CURVED_WALK_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e09");
const OUTPUTS_HANDLE: Handle<Shader> = uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e0a");
/// The material's fragment shader, for [`MaterialExtension`].
pub const MATERIAL_SHADER_HANDLE: Handle<Shader> =
    uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e05");

pub use displace_shaders::{MapParams, FILTER_WEIGHT_BITS};

/// Registers the shader modules with Bevy's shader assets (naga_oil resolves
/// `#import displace::...` against their `#define_import_path`, as it does
/// Bevy's own `bevy_pbr::...` modules) and the material.
pub struct DistanceMappingPlugin;

impl Plugin for DistanceMappingPlugin {
    fn build(&self, app: &mut App) {
        let mut shaders = app.world_mut().resource_mut::<Assets<Shader>>();
        for (handle, source, path) in [
            (
                &CONVENTION_HANDLE,
                wgsl::CONVENTION,
                "displace/convention.wgsl",
            ),
            (
                &DISTANCE_HANDLE,
                wgsl::DISTANCE_FILTERED,
                "displace/distance_filtered.wgsl",
            ),
            (&SURFACE_HANDLE, wgsl::SURFACE, "displace/surface.wgsl"),
            (&BINDINGS_HANDLE, BINDINGS, "displace/bindings.wgsl"),
            (&OUTPUTS_HANDLE, OUTPUTS, "displace/displaced_outputs.wgsl"),
            (
                &MATERIAL_SHADER_HANDLE,
                MATERIAL,
                "displace/distance_mapping.wgsl",
            ),
            (
                &CURVED_PRISM_HANDLE,
                wgsl::CURVED_PRISM,
                "displace/curved_prism.wgsl",
            ),
            (
                &CURVED_BINDINGS_HANDLE,
                curved::CURVED_BINDINGS,
                "displace/curved_bindings.wgsl",
            ),
            (
                &CURVED_WALK_HANDLE,
                wgsl::CURVED_WALK,
                "displace/curved_walk.wgsl",
            ),
            (
                &curved::CURVED_SHADER_HANDLE,
                curved::CURVED_MATERIAL,
                "displace/curved_mapping.wgsl",
            ),
        ] {
            shaders
                .insert(handle, Shader::from_wgsl(source, path))
                .expect("UUID handles always insert");
        }
        app.add_plugins((
            MaterialPlugin::<DistanceMappedMaterial>::default(),
            MaterialPlugin::<CurvedMappedMaterial>::default(),
        ));
    }
}

/// What the fragment stage writes ([`DistanceMapping::with_output`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum Output {
    /// Bevy's PBR shading of the displaced point.
    #[default]
    Shaded,
    /// The hit as data, unlit: `(displaced u, displaced v, map-space t, 1)`,
    /// for tests against `displace gpu-render`'s UV output (the curved
    /// material writes the world distance to the hit as its third).
    Hit,
    /// The displaced surface's world normal as `n * 0.5 + 0.5`, unlit (the
    /// curved material: seams show as breaks in it).
    Normal,
}

impl Output {
    /// The uniform's code of the output (`OUTPUT_*` in the WGSL).
    pub(crate) fn code(self) -> u32 {
        match self {
            Output::Shaded => 0,
            Output::Hit => 1,
            Output::Normal => 2,
        }
    }
}

/// The extension's second uniform: mirror of WGSL
/// `DistanceMappingSettings` (`distance_mapping.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Reflect, ShaderType)]
pub struct DistanceMappingSettings {
    /// World-space depth of the shell beneath the mesh: listing 8-1's
    /// inverse bump depth factor, inverted; live, as the map is in shell
    /// depths.
    pub depth: f32,
    /// 0 [`Output::Shaded`], 1 [`Output::Hit`], 2 [`Output::Normal`].
    pub output: u32,
    /// Padding to 16 bytes.
    pub pad_a: u32,
    /// Padding to 16 bytes.
    pub pad_b: u32,
}

/// How the march ends (section 8.5.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum MarchMethod {
    /// Sphere tracing with an early out once the distance is under a quarter
    /// voxel, then the exact walk over the band the map cannot resolve: the
    /// exact first hit.
    #[default]
    EarlyOut,
    /// Donnelly's fixed loop of `iterations` steps, refined exactly where it
    /// stops.
    Fixed,
}

/// Storage of the distance map on the GPU (section 8.6 used 8 bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Encoding {
    /// R8Unorm codes over the map's range (a quarter of the memory of R32).
    #[default]
    R8,
    /// R16Float.
    R16F,
}

impl Encoding {
    fn format(self) -> Format {
        match self {
            Encoding::R8 => Format::R8,
            Encoding::R16F => Format::R16F,
        }
    }
}

/// Why a [`DistanceMapping`] could not be built.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The bake, the height source or our own KTX2 parser refused the input.
    #[error(transparent)]
    Core(#[from] displace_core::Error),
    /// Our KTX2 parser refused the file (malformed or not a distance map).
    #[error("KTX2: {0}")]
    Ktx2(#[from] displace_core::io::FormatError),
    /// Bevy's image loader refused the file.
    #[error("Bevy's KTX2 loader: {0}")]
    Bevy(#[from] TextureError),
    /// A file or option the material cannot use.
    #[error("{0}")]
    Invalid(String),
}

/// The extension of `StandardMaterial`: the 3D distance map (section 8.4),
/// the height texture for the exact refinement, the shell's depth, the
/// iteration budget and the method.
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone)]
pub struct DistanceMapping {
    /// The trace's constants (binding 100): displace-shaders' `MapParams`,
    /// which knows nothing of Bevy, so reflection sees it as opaque (cloned,
    /// not inspected).
    #[uniform(100)]
    #[reflect(ignore, clone)]
    pub map: MapParams,
    /// The height map, R32Float, read with `textureLoad` by the exact walk.
    #[texture(101, sample_type = "float", filterable = false)]
    pub height: Handle<Image>,
    /// The distance map: a 3D R8Unorm or R16Float texture with a linear
    /// sampler (clamped in depth, the map's addressing across).
    #[texture(102, dimension = "3d")]
    #[sampler(103)]
    pub distance: Handle<Image>,
    /// Depth and output (binding 104).
    #[uniform(104)]
    pub settings: DistanceMappingSettings,
}

impl MaterialExtension for DistanceMapping {
    fn fragment_shader() -> ShaderRef {
        MATERIAL_SHADER_HANDLE.into()
    }
    /// The same march in the depth/normal prepass and the shadow passes.
    fn prepass_fragment_shader() -> ShaderRef {
        MATERIAL_SHADER_HANDLE.into()
    }
    /// Alpha-mask mode marks the pipelines as discarding (Bevy's
    /// `MAY_DISCARD`), which is what makes the prepass and shadow passes run
    /// the material's fragment stage at all (with depth-only opaque
    /// materials they skip it): those passes must write the displaced depth
    /// and drop rays that leave the shell. The base material's own alpha
    /// mode still decides how its alpha is used.
    fn alpha_mode() -> Option<AlphaMode> {
        Some(AlphaMode::Mask(0.5))
    }
}

/// The sampler of the distance texture: linear, no mipmaps (section 8.5.3),
/// clamped in depth and addressed across as the map was baked.
pub fn distance_sampler(address: Address) -> ImageSampler {
    let across = match address {
        Address::Clamp => ImageAddressMode::ClampToEdge,
        Address::Repeat => ImageAddressMode::Repeat,
    };
    ImageSampler::Descriptor(ImageSamplerDescriptor {
        label: Some("displace distance (linear, no mipmaps)".into()),
        address_mode_u: across,
        address_mode_v: across,
        address_mode_w: ImageAddressMode::ClampToEdge,
        mag_filter: ImageFilterMode::Linear,
        min_filter: ImageFilterMode::Linear,
        mipmap_filter: ImageFilterMode::Nearest,
        ..default()
    })
}

/// The height map as the R32Float texture the exact walk reads texel by
/// texel (no sampler: it interpolates by hand, as the CPU does).
pub fn height_image(height: &HeightMap) -> Image {
    texel_image(height, TextureFormat::R32Float, |v| {
        v.to_le_bytes().to_vec()
    })
}

/// A 2D image of `format` with one texel per height texel, its bytes
/// `texel(h)` of the height `h` there (rows as the height map's, `v = 0`
/// first), with Bevy's default sampler: the height map itself, or what
/// other materials read from it (a colour map, Bevy's parallax depth map).
pub fn texel_image(
    height: &HeightMap,
    format: TextureFormat,
    texel: impl Fn(f32) -> Vec<u8>,
) -> Image {
    let bytes: Vec<u8> = height.data().iter().flat_map(|&h| texel(h)).collect();
    Image::new(
        Extent3d {
            width: height.width() as u32,
            height: height.height() as u32,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        format,
        RenderAssetUsages::RENDER_WORLD,
    )
}

impl DistanceMapping {
    /// Bakes `height` with `displace-core` (section 8.4's distance
    /// transform) and uploads it: for users who have only a height map.
    /// `opts.extent.sz` becomes the world depth of the shell.
    pub fn bake(
        height: &HeightMap,
        opts: &BakeOptions,
        encoding: Encoding,
        images: &mut Assets<Image>,
    ) -> Result<Self, Error> {
        let map = displace_core::bake(height, opts)?;
        Self::from_map(&map, encoding, images)
    }

    /// [`DistanceMapping::bake`] of a height source as `displace bake` reads
    /// it: a 16-bit PNG, an EXR, or a built-in `gen:NAME`.
    pub fn bake_source(
        source: &str,
        address: Address,
        opts: &BakeOptions,
        encoding: Encoding,
        images: &mut Assets<Image>,
    ) -> Result<Self, Error> {
        let height_opts = displace_core::io::height::HeightOptions {
            address,
            ..Default::default()
        };
        let height = displace_core::io::height::load(source, &height_opts)?;
        Self::bake(&height, opts, encoding, images)
    }

    /// A baked map, uploaded as a filtered 3D texture.
    pub fn from_map(
        map: &DisplacementMap,
        encoding: Encoding,
        images: &mut Assets<Image>,
    ) -> Result<Self, Error> {
        let texels = filtered(&map.distance, encoding.format())?;
        let [w, h, d] = map.distance.size();
        let mut image = Image::new(
            Extent3d {
                width: w as u32,
                height: h as u32,
                depth_or_array_layers: d as u32,
            },
            TextureDimension::D3,
            texels.bytes.clone(),
            texture_format(encoding),
            RenderAssetUsages::RENDER_WORLD,
        );
        image.sampler = distance_sampler(map.distance.address());
        let distance = images.add(image);
        let heights = images.add(height_image(&map.height));
        Ok(Self::assemble(
            &map.distance,
            &map.height,
            &texels,
            map.extent.sz,
            distance,
            heights,
        ))
    }

    /// A KTX2 written by `displace bake` (R8 or R16F), decoded by Bevy's own
    /// KTX2 loader into the 3D texture, with the trace's constants from its
    /// `displace.*` key/value data (read by `displace-core`). `height` is the
    /// height map it was baked from (the KTX2 holds only distances). A
    /// malformed file is an error from either parser, never a panic.
    pub fn from_ktx2(
        bytes: &[u8],
        height: &HeightMap,
        images: &mut Assets<Image>,
    ) -> Result<Self, Error> {
        let decoded = displace_core::io::ktx2::from_bytes(bytes)?;
        let encoding = match decoded.format {
            Format::R8 => Encoding::R8,
            Format::R16F => Encoding::R16F,
            Format::R32F => {
                return Err(Error::Invalid(
                    "an r32f distance map is not filterable on every GPU: bake with --format r8 or r16f"
                        .into(),
                ))
            }
        };
        if height.address() != decoded.map.address() {
            return Err(Error::Invalid(format!(
                "the map was baked with {} addressing, the height map has {}",
                decoded.map.address().name(),
                height.address().name()
            )));
        }
        let image = load_ktx2(bytes, decoded.map.address())?;
        let texels = filtered(&decoded.map, encoding.format())?;
        let distance = images.add(image);
        let heights = images.add(height_image(height));
        Ok(Self::assemble(
            &decoded.map,
            height,
            &texels,
            decoded.extent.sz,
            distance,
            heights,
        ))
    }

    fn assemble(
        distance: &DistanceMap,
        height: &HeightMap,
        texels: &FilteredTexels,
        depth: f32,
        distance_image: Handle<Image>,
        height_image: Handle<Image>,
    ) -> Self {
        let repeat = distance.address() == Address::Repeat;
        let decode = Decode {
            scale: texels.scale,
            offset: texels.offset,
            underestimate: texels.underestimate,
        };
        let base = MapParams::for_map(
            distance.aspect(),
            distance.size(),
            distance.voxel_size(),
            distance.address(),
            [height.width(), height.height()],
            &decode,
        );
        Self {
            map: MapParams {
                // A repeating map's shell has no sides to leave through:
                // "infinite" tiles, while the walk's cap stays one tile's
                // (the shader re-enters each tile's cells).
                tiles: if repeat { Vec2::splat(BIG) } else { Vec2::ONE },
                max_cells: cell_cap(base.height_size, [1.0, 1.0]),
                method: method_code(Method::Sphere),
                iterations: 16,
                t_min: 0.0,
                t_max: BIG,
                ..base
            },
            height: height_image,
            distance: distance_image,
            settings: DistanceMappingSettings {
                depth,
                output: 0,
                pad_a: 0,
                pad_b: 0,
            },
        }
    }

    /// The shell's depth in world units (listing 8-1's bump depth), without
    /// a re-bake.
    pub fn with_depth(mut self, depth: f32) -> Self {
        self.settings.depth = depth;
        self
    }

    /// Steps of the march before the exact refinement takes over (early
    /// out) or the loop ends (fixed).
    pub fn with_iterations(mut self, iterations: u32) -> Self {
        self.map.iterations = iterations.max(1);
        self
    }

    /// Early out with exact refinement, or Donnelly's fixed loop.
    pub fn with_method(mut self, method: MarchMethod) -> Self {
        self.map.method = method_code(match method {
            MarchMethod::EarlyOut => Method::Sphere,
            MarchMethod::Fixed => Method::SphereFixed,
        });
        self
    }

    /// What the fragment writes: shading, or the hit as data.
    pub fn with_output(mut self, output: Output) -> Self {
        self.settings.output = output.code();
        self
    }

    /// The method the shader runs.
    pub fn method(&self) -> MarchMethod {
        if self.map.method == method_code(Method::SphereFixed) {
            MarchMethod::Fixed
        } else {
            MarchMethod::EarlyOut
        }
    }
}

/// The distance and height textures of `map` uploaded as the flat
/// material uploads them, and their trace constants (to be given a trace's
/// options with [`MapParams::with_trace`]): what the curved material binds.
pub(crate) fn filtered_handles(
    map: &DisplacementMap,
    encoding: Encoding,
    images: &mut Assets<Image>,
) -> Result<(Handle<Image>, Handle<Image>, MapParams), Error> {
    let m = DistanceMapping::from_map(map, encoding, images)?;
    Ok((m.distance, m.height, m.map))
}

fn texture_format(encoding: Encoding) -> TextureFormat {
    match encoding {
        Encoding::R8 => TextureFormat::R8Unorm,
        Encoding::R16F => TextureFormat::R16Float,
    }
}

fn filtered(map: &DistanceMap, format: Format) -> Result<FilteredTexels, Error> {
    map.filtered_texels(format, FILTER_WEIGHT_BITS)
        .ok_or_else(|| Error::Invalid(format!("{} maps are not filterable", format.name())))
}

/// Our KTX2 through Bevy's image loader (`Image::from_buffer`, what its
/// `ImageLoader` runs on a `.ktx2` asset), linear data (not sRGB) with the
/// distance sampler.
pub fn load_ktx2(bytes: &[u8], address: Address) -> Result<Image, TextureError> {
    Image::from_buffer(
        bytes,
        ImageType::Extension("ktx2"),
        CompressedImageFormats::NONE,
        false,
        distance_sampler(address),
        RenderAssetUsages::RENDER_WORLD,
    )
}
