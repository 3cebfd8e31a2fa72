//! Displacement over curved meshes in Bevy: [`CurvedMappedMaterial`] draws
//! any Bevy mesh with vertex normals and texture coordinates as the
//! displaced surface `S = P + depth h(uv) N` that `displace render` and
//! `displace gpu-render` draw (the vertex normals interpolated, the
//! surface pbrt-v4 and Cycles draw when they subdivide a mesh and move its
//! vertices).
//!
//! Donnelly's polygon is the top of a flat shell (GPU Gems 2 ch. 8,
//! section 8.3), which on a curved mesh shows every triangle's facet: the
//! shells break at the edges, pinch at a sphere's pole and leave seam lines
//! where neighbouring triangles disagree. Here each triangle's shell runs
//! along its vertex normals instead, `X(b, l) = P(b) + l N(b)`, with sides
//! shared bit for bit with its neighbours (the CPU renderer's shells,
//! [`displace_scene::mesh_shells`]). [`CurvedShellMesh::new`] turns the
//! user's mesh into
//! - the shells as a storage buffer of prisms with their neighbours
//!   ([`displace_shaders::curved_prisms`], the buffer displace-gpu binds),
//! - and the shells' outer boundary as the mesh Bevy rasterises (each
//!   vertex carries its prism in its texture coordinate),
//!
//! and the fragment stage walks from the prism where its ray enters to the
//! first hit (`displace::curved_walk`, the WGSL displace-gpu runs), in the
//! main pass, the depth and normal prepass and every shadow pass, as the
//! flat material does. The shells are built in the mesh's own space, so the
//! entity's `Transform` moves, turns and scales the displaced object as it
//! does any mesh.

use crate::{filtered_handles, Encoding, Error, Output};
use bevy::asset::{uuid_handle, RenderAssetUsages};
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::pbr::{ExtendedMaterial, MaterialExtension};
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType};
use bevy::render::storage::ShaderBuffer;
use bevy::shader::{Shader, ShaderRef};
use displace_core::{DisplacementMap, Method, TraceOptions};
use displace_scene::mesh::MeshTriangle;
use displace_scene::mesh_shells::MeshShells;
use displace_shaders::curved_prisms::CurvedShells;
use displace_shaders::MapParams;

/// The material of a curved displaced object: Bevy's `StandardMaterial`
/// (its colour, metallic-roughness, emissive and occlusion maps at the
/// displaced texture coordinate, its lighting and shadows) with the
/// curved-shell extension.
pub type CurvedMappedMaterial = ExtendedMaterial<StandardMaterial, CurvedMapping>;

/// `displace::curved_bindings` of the material's group: the prisms.
pub(crate) const CURVED_BINDINGS: &str = include_str!("curved_bindings.wgsl");
/// The curved material's fragment stage (main pass and prepass).
pub(crate) const CURVED_MATERIAL: &str = include_str!("curved_mapping.wgsl");

/// The curved material's fragment shader, for [`MaterialExtension`].
pub const CURVED_SHADER_HANDLE: Handle<Shader> =
    uuid_handle!("6a1c0e52-5b1f-4a5e-9d0c-3f0b6c1d2e06");

/// The extension's second uniform: mirror of WGSL `CurvedMappingSettings`
/// (`curved_mapping.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Reflect, ShaderType)]
pub struct CurvedMappingSettings {
    /// Added to the map-window coordinate of a hit to give the mesh's own
    /// texture coordinate in tiles (the window starts at a whole tile).
    pub uv_shift: Vec2,
    /// How far behind a fragment an orthographic ray (a directional
    /// light's shadow map) starts, in the mesh's units: the diagonal of the
    /// shells' box, so the start lies outside them.
    pub reach: f32,
    /// 0 shaded, 1 the hit as data, 2 the world normal (`Output`).
    pub output: u32,
}

/// The curved extension of `StandardMaterial`: the map (as the flat
/// [`crate::DistanceMapping`] binds it), the shell's settings and the
/// prisms the fragment stage walks.
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone)]
pub struct CurvedMapping {
    /// The trace's constants (binding 100), tiled over the mesh's map
    /// window.
    #[uniform(100)]
    #[reflect(ignore, clone)]
    pub map: MapParams,
    /// The height map, R32Float, read with `textureLoad` by the exact walk.
    #[texture(101, sample_type = "float", filterable = false)]
    pub height: Handle<Image>,
    /// The distance map: a filtered 3D texture (section 8.5.3).
    #[texture(102, dimension = "3d")]
    #[sampler(103)]
    pub distance: Handle<Image>,
    /// Texture window, reach and output (binding 104).
    #[uniform(104)]
    pub settings: CurvedMappingSettings,
    /// The prisms, one per triangle of the source mesh (binding 105).
    #[storage(105, read_only)]
    pub prisms: Handle<ShaderBuffer>,
}

impl MaterialExtension for CurvedMapping {
    fn fragment_shader() -> ShaderRef {
        CURVED_SHADER_HANDLE.into()
    }
    /// The same walk in the depth/normal prepass and the shadow passes.
    fn prepass_fragment_shader() -> ShaderRef {
        CURVED_SHADER_HANDLE.into()
    }
    /// As [`crate::DistanceMapping`]: marked as discarding, so the prepass
    /// and shadow passes run the fragment stage (the boundary mesh is not
    /// the surface; its fragments only start the walk).
    fn alpha_mode() -> Option<AlphaMode> {
        Some(AlphaMode::Mask(0.5))
    }
}

impl CurvedMapping {
    /// Most sphere-tracing steps of each chord's trace before the exact
    /// refinement takes over.
    pub fn with_iterations(mut self, iterations: u32) -> Self {
        self.map.iterations = iterations.max(1);
        self
    }

    /// What the fragment writes: shading, the hit as data, or its normal.
    pub fn with_output(mut self, output: Output) -> Self {
        self.settings.output = output.code();
        self
    }
}

/// A curved displaced object ready to spawn: the mesh to draw (the shells'
/// outer boundary) and the material extension that walks the shells.
pub struct CurvedShellMesh {
    /// The shells' tops, bases and unshared sides, each vertex's texture
    /// coordinate `(prism, 0)`: spawn it with `Mesh3d`.
    pub mesh: Mesh,
    /// The extension to put beside a `StandardMaterial` in
    /// [`CurvedMappedMaterial`].
    pub mapping: CurvedMapping,
    /// The shells' box in the mesh's space (for culling and framing).
    pub bounds: [Vec3; 2],
}

impl CurvedShellMesh {
    /// The shells of `source` (a triangle list with positions, normals and
    /// texture coordinates; indexed or not) displaced `depth` deep in the
    /// mesh's units by `map` (encoded as `encoding` on the GPU), its
    /// texture coordinates scaled by `uv_scale` into tiles of the map. A
    /// mesh without what the shells need, or with no curved triangle (a
    /// flat mesh: [`crate::DistanceMappedMaterial`] draws it), is an error.
    pub fn new(
        source: &Mesh,
        uv_scale: Vec2,
        map: &DisplacementMap,
        depth: f32,
        encoding: Encoding,
        images: &mut Assets<Image>,
        buffers: &mut Assets<ShaderBuffer>,
    ) -> Result<Self, Error> {
        if !(depth.is_finite() && depth > 0.0) {
            return Err(Error::Invalid(format!(
                "the displacement depth must be positive and finite, not {depth}"
            )));
        }
        if !uv_scale.is_finite() || uv_scale.cmple(Vec2::ZERO).any() {
            return Err(Error::Invalid(format!(
                "the texture scale must be positive and finite, not {uv_scale}"
            )));
        }
        let triangles = triangles_of(source, uv_scale)?;
        let address = map.distance.address();
        let shells = MeshShells::of(&triangles, depth, address);
        let shells = CurvedShells::new(&triangles, &shells, depth, map.aspect(), address)
            .map_err(|e| Error::Invalid(e.to_string()))?
            .ok_or_else(|| {
                Error::Invalid(
                    "no triangle of the mesh is curved (its vertex normals are its faces'): \
                     DistanceMappedMaterial draws flat faces"
                        .into(),
                )
            })?;
        let (distance, height, base) = filtered_handles(map, encoding, images)?;
        let opts = TraceOptions {
            method: Method::Sphere,
            // The fragment's start point is interpolated, as displace-gpu's.
            t_min: -1e-3,
            tiles: shells.tiles,
            ..TraceOptions::default()
        };
        let bytes: Vec<u8> = bytemuck::cast_slice(&shells.prisms).to_vec();
        let prisms = buffers.add(ShaderBuffer::new(&bytes, RenderAssetUsages::RENDER_WORLD));
        let [lo, hi] = shells.bounds.map(|v| Vec3::from_array(v.to_array()));
        let mapping = CurvedMapping {
            map: base.with_trace(&opts),
            height,
            distance,
            settings: CurvedMappingSettings {
                uv_shift: Vec2::from_array(shells.uv_shift.to_array()),
                reach: (hi - lo).length().max(depth),
                output: Output::Shaded.code(),
            },
            prisms,
        };
        Ok(Self {
            mesh: boundary_mesh(&shells),
            mapping,
            bounds: [lo, hi],
        })
    }
}

/// The boundary triangles as a Bevy mesh: positions, the faces' normals
/// (Bevy's pipelines want normals; the lit normal is the hit's) and the
/// prism in `uv.x` (exact in `f32` below 2^24 triangles, which
/// [`MAX_TRIANGLES`] keeps far below).
fn boundary_mesh(shells: &CurvedShells) -> Mesh {
    let positions: Vec<[f32; 3]> = shells.vertices.iter().map(|v| v.position).collect();
    let normals: Vec<[f32; 3]> = positions
        .chunks(3)
        .flat_map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(Vec3::from_array);
            [(b - a).cross(c - a).normalize_or_zero().to_array(); 3]
        })
        .collect();
    let uvs: Vec<[f32; 2]> = shells
        .vertices
        .iter()
        .map(|v| [v.prism as f32, 0.0])
        .collect();
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
}

/// Most bytes of prisms one material binds: WebGPU's default
/// `max_storage_buffer_binding_size` (128 MiB), the limit wgpu grants on
/// every adapter. Bigger meshes are refused before anything is built.
pub const MAX_PRISM_BYTES: usize = 128 << 20;

/// Most triangles a curved mesh may have: its prisms within
/// [`MAX_PRISM_BYTES`] (932 067 triangles; their index, in the boundary's
/// texture coordinate, is exact far beyond).
pub const MAX_TRIANGLES: usize =
    MAX_PRISM_BYTES / std::mem::size_of::<displace_shaders::curved_prisms::GpuPrism>();

/// The triangles of a Bevy triangle list, their texture coordinates scaled
/// by `uv_scale`, in displace-scene's types (its glam is not Bevy's:
/// through arrays).
fn triangles_of(mesh: &Mesh, uv_scale: Vec2) -> Result<Vec<MeshTriangle>, Error> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(Error::Invalid(format!(
            "a curved mesh must be a triangle list, not {:?}",
            mesh.primitive_topology()
        )));
    }
    let attribute = |id, name: &str| -> Result<&[[f32; 3]], Error> {
        match mesh.attribute(id) {
            Some(VertexAttributeValues::Float32x3(v)) => Ok(v.as_slice()),
            Some(other) => Err(Error::Invalid(format!(
                "the mesh's {name} are {other:?}-typed, not Float32x3",
                other = other.enum_variant_name()
            ))),
            None => Err(Error::Invalid(format!(
                "the mesh has no {name}: the shells run along the vertex normals over the texture coordinates"
            ))),
        }
    };
    let positions = attribute(Mesh::ATTRIBUTE_POSITION, "positions")?;
    let normals = attribute(Mesh::ATTRIBUTE_NORMAL, "normals")?;
    let uvs =
        match mesh.attribute(Mesh::ATTRIBUTE_UV_0) {
            Some(VertexAttributeValues::Float32x2(v)) => v.as_slice(),
            _ => return Err(Error::Invalid(
                "the mesh has no Float32x2 texture coordinates (UV_0): the map is laid over them"
                    .into(),
            )),
        };
    let indices: Vec<usize> = match mesh.indices() {
        Some(Indices::U16(i)) => i.iter().map(|&k| k as usize).collect(),
        Some(Indices::U32(i)) => i.iter().map(|&k| k as usize).collect(),
        None => (0..positions.len()).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(Error::Invalid(format!(
            "{} indices do not make whole triangles",
            indices.len()
        )));
    }
    if indices.len() / 3 > MAX_TRIANGLES {
        return Err(Error::Invalid(format!(
            "{} triangles: a curved mesh holds at most {MAX_TRIANGLES} (its prisms, 144 bytes each, \
             must fit one storage buffer binding of {MAX_PRISM_BYTES} bytes)",
            indices.len() / 3
        )));
    }
    let count = positions.len().min(normals.len()).min(uvs.len());
    if let Some(bad) = indices.iter().find(|&&k| k >= count) {
        return Err(Error::Invalid(format!(
            "index {bad} is past the mesh's {count} vertices"
        )));
    }
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if let Some(k) =
        (0..count).find(|&k| !(finite(&positions[k]) && finite(&normals[k]) && finite(&uvs[k])))
    {
        return Err(Error::Invalid(format!(
            "vertex {k} has a NaN or infinite position, normal or texture coordinate"
        )));
    }
    let (positions, normals) = welded(&positions[..count], &normals[..count]);
    Ok(indices
        .chunks(3)
        .map(|t| {
            let corner = |k: usize| {
                (
                    positions[t[k]],
                    normals[t[k]],
                    glam::Vec2::new(uvs[t[k]][0] * uv_scale.x, uvs[t[k]][1] * uv_scale.y),
                )
            };
            let c = [corner(0), corner(1), corner(2)];
            let normals: [glam::Vec3; 3] = c.map(|c| c.1);
            MeshTriangle {
                positions: c.map(|c| c.0),
                // A zero normal leaves the triangle its face's (flat) shell,
                // as displace-scene treats a file's degenerate normals.
                normals: normals
                    .iter()
                    .all(|n| *n != glam::Vec3::ZERO)
                    .then_some(normals),
                uvs: c.map(|c| c.2),
            }
        })
        .collect())
}

/// The vertices with every near-copy of one (a position within a
/// millionth of the mesh's size, a normal within a tenth of a degree)
/// made the very same bits, normals normalised. Neighbouring shells share
/// a side only where their corners agree bit for bit
/// ([`MeshShells`]); a generated mesh's seam vertices (a torus's first
/// and last ring, `cos 2 pi` against `cos 0`) differ in the last bits, and
/// would leave walls along the seams. Vertices at one place with normals
/// apart (a crease) stay apart.
fn welded(positions: &[[f32; 3]], normals: &[[f32; 3]]) -> (Vec<glam::Vec3>, Vec<glam::Vec3>) {
    use std::collections::HashMap;
    let p: Vec<glam::Vec3> = positions
        .iter()
        .map(|&v| glam::Vec3::from_array(v))
        .collect();
    let mut n: Vec<glam::Vec3> = normals
        .iter()
        .map(|&v| glam::Vec3::from_array(v).normalize_or_zero())
        .collect();
    let (lo, hi) = p.iter().fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(lo, hi), &v| (lo.min(v), hi.max(v)),
    );
    let eps = (hi - lo).length() * 1e-6;
    if !(eps > 0.0 && eps.is_finite()) {
        return (p, n);
    }
    let cos_tol = 0.1f32.to_radians().cos();
    let cell = |v: glam::Vec3| (v / eps).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<usize>> = HashMap::new();
    let mut out = p.clone();
    for k in 0..p.len() {
        let c = cell(p[k]);
        let mut found = None;
        'search: for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(reps) = grid.get(&(c + glam::IVec3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for &r in reps {
                        if p[r].distance(p[k]) <= eps && n[r].dot(n[k]) >= cos_tol {
                            found = Some(r);
                            break 'search;
                        }
                    }
                }
            }
        }
        match found {
            Some(r) => {
                out[k] = out[r];
                n[k] = n[r];
            }
            None => grid.entry(c).or_default().push(k),
        }
    }
    (out, n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_core::Address;

    fn map() -> DisplacementMap {
        let height = displace_core::io::height::load(
            "gen:noise",
            &displace_core::io::height::HeightOptions {
                size: [16, 16],
                address: Address::Repeat,
                ..Default::default()
            },
        )
        .unwrap();
        displace_core::bake(
            &height,
            &displace_core::BakeOptions {
                size: [16, 16, 4],
                ..Default::default()
            },
        )
        .unwrap()
    }

    fn build(mesh: &Mesh, depth: f32) -> Result<CurvedShellMesh, Error> {
        let mut images = Assets::<Image>::default();
        let mut buffers = Assets::<ShaderBuffer>::default();
        CurvedShellMesh::new(
            mesh,
            Vec2::new(4.0, 2.0),
            &map(),
            depth,
            Encoding::R8,
            &mut images,
            &mut buffers,
        )
    }

    /// Bevy's own meshes build: one prism a triangle, the boundary of a
    /// closed torus its tops and bases, each vertex naming a prism.
    #[test]
    fn bevy_meshes_build_their_shells() {
        let torus = Torus::new(0.25, 0.55).mesh().build();
        let triangles = torus.indices().unwrap().len() / 3;
        let shells = build(&torus, 0.05).unwrap();
        let Some(VertexAttributeValues::Float32x2(uvs)) =
            shells.mesh.attribute(Mesh::ATTRIBUTE_UV_0)
        else {
            panic!("the boundary has texture coordinates")
        };
        assert_eq!(uvs.len(), triangles * 6);
        assert!(uvs
            .iter()
            .all(|uv| uv[0] >= 0.0 && (uv[0] as usize) < triangles && uv[0].fract() == 0.0));
        let sphere = Sphere::new(0.6).mesh().uv(32, 16);
        assert!(build(&sphere, 0.04).is_ok());
    }

    /// What the shells cannot be built from is an error naming it, never
    /// a panic.
    #[test]
    fn bad_meshes_are_refused_by_name() {
        let torus = || Torus::new(0.25, 0.55).mesh().build();
        let refused = |mesh: &Mesh, depth: f32, what: &str| {
            let e = build(mesh, depth).err().expect(what).to_string();
            assert!(e.contains(what), "{e:?} should name {what:?}");
        };
        let mut no_normals = torus();
        no_normals.remove_attribute(Mesh::ATTRIBUTE_NORMAL);
        refused(&no_normals, 0.05, "normals");
        let mut no_uvs = torus();
        no_uvs.remove_attribute(Mesh::ATTRIBUTE_UV_0);
        refused(&no_uvs, 0.05, "texture coordinates");
        let mut nan = torus();
        if let Some(VertexAttributeValues::Float32x3(p)) =
            nan.attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            p[3][1] = f32::NAN;
        }
        refused(&nan, 0.05, "vertex 3");
        let mut past = torus();
        past.insert_indices(Indices::U32(vec![0, 1, 100_000]));
        refused(&past, 0.05, "index 100000");
        let mut ragged = torus();
        ragged.insert_indices(Indices::U32(vec![0, 1, 2, 3]));
        refused(&ragged, 0.05, "whole triangles");
        let lines = Mesh::new(PrimitiveTopology::LineList, RenderAssetUsages::RENDER_WORLD);
        refused(&lines, 0.05, "triangle list");
        refused(&torus(), 0.0, "depth");
        refused(&torus(), f32::INFINITY, "depth");
        // A plane's vertex normals are its face's: nothing is curved.
        let plane = Plane3d::default().mesh().size(1.0, 1.0).build();
        refused(&plane, 0.05, "curved");
    }
}
