//! The raster path's pipelines and the resources each keeps ([`Renderer`]):
//! a displaced face's shell box (section 8.5: listing 8-1's vertex stage,
//! listing 8-2's fragment stage), a mesh's shells (section 8.4), or a
//! scene's plain triangles, all writing the same colour, AOV and depth
//! targets with one depth test, so that the nearest surface wins whichever
//! pipeline drew it.

use super::targets::{AOV_FORMAT, COLOR_FORMAT, DEPTH_FORMAT};
use super::textures::{albedo_texel, checker_mips, normal_texels, shading_sampler, texture_2d};
use super::vertex::{CURVED_VERTEX_LAYOUT, SHELL_VERTEX_LAYOUT};
use crate::curved::CurvedShells;
use crate::descriptors::{
    bind_group, bind_group_layout, buffer_of, color_target, frame_uniform_entry, pipeline_layout,
    render_pipeline, sampler_entry, shader_module, storage_entry_in, texture_entry, RenderStages,
};
use crate::gpu_map::GpuMap;
use crate::mesh::ShellMesh;
use crate::plain::{PlainMesh, PLAIN_VERTEX_LAYOUT};
use crate::shaders::{curved_source, mesh_source, plain_source, raster_source, DistanceTexture};
use crate::{Error, GpuContext, Result};
use displace_core::DisplacementMap;
use glam::Vec2;

/// What a renderer draws.
pub(super) enum Geometry {
    /// The planar face's shell box, placed by its draw's [`super::Face`].
    ShellBox { mirrored: bool },
    /// A mesh's shell, in world space ([`ShellMesh`]), or a curved mesh's
    /// shells ([`CurvedShells`]) with their prisms bound as group 2.
    Mesh {
        vertices: wgpu::Buffer,
        count: u32,
        uv_shift: Vec2,
        tiles: [f32; 2],
        prisms: Option<wgpu::BindGroup>,
    },
}

/// A pipeline and what it draws: one displacement map's face or mesh, or
/// the plain (non-displaced) triangles of a scene ([`Renderer::plain`]).
/// Built once per map and reused for every frame, as its textures and
/// pipeline do not depend on the camera.
pub struct Renderer {
    pub(super) pipeline: wgpu::RenderPipeline,
    pub(super) kind: Kind,
}

/// A displaced draw or a plain one.
pub(super) enum Kind {
    Displaced {
        shading: Box<MapShading>,
        geometry: Geometry,
    },
    /// [`PlainMesh`] triangles: group 0 is their [`crate::plain::PlainFrame`].
    Plain {
        vertices: wgpu::Buffer,
        count: u32,
        frame_layout: wgpu::BindGroupLayout,
    },
}

/// The map, normal map, colour texture and sampler a displaced draw binds.
pub(super) struct MapShading {
    pub(super) map: GpuMap,
    pub(super) shade_group: wgpu::BindGroupLayout,
    pub(super) normal_view: wgpu::TextureView,
    pub(super) color_view: wgpu::TextureView,
    pub(super) sampler: wgpu::Sampler,
}

/// The surface colour of a displaced draw.
#[derive(Clone, Copy)]
pub(crate) enum Colour {
    /// Donnelly's checkerboard ([`checker_mips`]).
    Checker,
    /// One constant linear colour.
    Albedo([f32; 3]),
}

/// What [`Renderer::with_colour`] builds a pipeline for.
#[derive(Clone, Copy)]
pub(crate) enum Shape<'a> {
    /// A face's shell box, of the given handedness.
    Box { mirrored: bool },
    /// A mesh's shell in its per-vertex frames.
    Mesh(&'a ShellMesh),
    /// A curved mesh's shells, walked prism to prism per fragment
    /// (`curved.wgsl`).
    Curved(&'a CurvedShells),
}

impl Renderer {
    /// A renderer whose colour texture is Donnelly's checkerboard.
    pub fn new(ctx: &GpuContext, map: &DisplacementMap, texture: DistanceTexture) -> Result<Self> {
        let shape = Shape::Box { mirrored: false };
        Self::with_colour(ctx, map, texture, Colour::Checker, shape)
    }

    /// A renderer of `mesh`'s shell with Donnelly's checkerboard (as
    /// [`Renderer::new`]).
    pub fn checker_mesh(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        mesh: &ShellMesh,
    ) -> Result<Self> {
        Self::with_colour(ctx, map, texture, Colour::Checker, Shape::Mesh(mesh))
    }

    /// A renderer of a curved mesh's `shells` with Donnelly's checkerboard
    /// (as [`Renderer::new`]): what displace-bevy's curved material is
    /// compared with.
    pub fn checker_curved(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        shells: &CurvedShells,
    ) -> Result<Self> {
        Self::with_colour(ctx, map, texture, Colour::Checker, Shape::Curved(shells))
    }

    /// A renderer whose surface colour is the constant linear `albedo`
    /// (a scene material's colour; each channel clamped to `[0, 1]`, stored
    /// as 8-bit sRGB like the checkerboard), for faces of the handedness
    /// `mirrored` ([`super::Face::mirrored`]: the shell box's winding
    /// flips with it, so back-face culling must too).
    pub fn with_albedo(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        albedo: [f32; 3],
        mirrored: bool,
    ) -> Result<Self> {
        let shape = Shape::Box { mirrored };
        Self::with_colour(ctx, map, texture, Colour::Albedo(albedo), shape)
    }

    /// A renderer of a scene's plain triangles (`shaders/plain.wgsl`),
    /// drawn two-sided into the same targets and depth buffer as the
    /// displaced faces. The frame's [`super::View`] gives the camera and
    /// light (its `light_intensity` scales the vertices' `diffuse` and
    /// `specular`); of its [`super::Draw`] only the `ambient` term and the
    /// shape are read, the shape a [`super::DrawShape::Mesh`] of the mesh's
    /// bounds so [`super::shared_depth_range`] holds it.
    pub fn plain(ctx: &GpuContext, mesh: &PlainMesh) -> Result<Self> {
        mesh.check()?;
        let (pipeline, frame_layout) = ctx.checked("building the plain pipeline", || {
            let module = shader_module(ctx, "plain", &plain_source());
            let frame_layout = bind_group_layout(ctx, "plain frame", &[frame_uniform_entry()]);
            let layout = pipeline_layout(ctx, "plain", &[&frame_layout]);
            let pipeline = render_pipeline(
                ctx,
                "plain",
                &layout,
                RenderStages {
                    module: &module,
                    vertex: "vs_plain",
                    fragment: "fs_plain",
                    buffers: &[PLAIN_VERTEX_LAYOUT],
                    targets: &color_targets(),
                },
                // Two-sided, as the CPU renderer's surfaces.
                wgpu::PrimitiveState {
                    cull_mode: None,
                    ..Default::default()
                },
                Some(depth_state()),
            );
            (pipeline, frame_layout)
        })?;
        let vertices = buffer_of(
            ctx,
            "plain vertices",
            bytemuck::cast_slice(&mesh.vertices),
            wgpu::BufferUsages::VERTEX,
        );
        Ok(Self {
            pipeline,
            kind: Kind::Plain {
                vertices,
                count: mesh.vertices.len() as u32,
                frame_layout,
            },
        })
    }

    /// A renderer of `shape` in `colour`: what every constructor builds.
    pub(crate) fn with_colour(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        colour: Colour,
        shape: Shape,
    ) -> Result<Self> {
        if let Shape::Curved(shells) = shape {
            // One storage binding holds every prism: refuse a mesh the
            // device cannot bind before anything is uploaded.
            let bytes = std::mem::size_of_val(shells.prisms.as_slice()) as u64;
            let limit = ctx.limits.max_storage_buffer_binding_size;
            if bytes > limit {
                return Err(Error::InvalidOption(format!(
                    "the curved mesh's {} shells take {bytes} bytes, over this GPU's \
                     {limit}-byte storage binding: use a coarser mesh",
                    shells.prisms.len()
                )));
            }
        }
        let empty = match shape {
            Shape::Mesh(mesh) => mesh.vertices.is_empty(),
            Shape::Curved(shells) => shells.vertices.is_empty(),
            Shape::Box { .. } => false,
        };
        if empty {
            return Err(Error::InvalidOption("the mesh has no triangles".into()));
        }
        let (colour_mips, colour_size) = match colour {
            Colour::Checker => (checker_mips(256, 16), 256),
            Colour::Albedo(albedo) => (vec![albedo_texel(albedo)], 1),
        };
        let gpu_map = GpuMap::new(ctx, map, texture)?;
        let normal_view = texture_2d(
            ctx,
            "normal map",
            [map.normals.width as u32, map.normals.height as u32],
            wgpu::TextureFormat::Rgba8Unorm,
            &[normal_texels(map)],
        );
        let color_view = texture_2d(
            ctx,
            "colour",
            [colour_size, colour_size],
            wgpu::TextureFormat::Rgba8UnormSrgb,
            &colour_mips,
        );
        let sampler = shading_sampler(ctx, map);
        let (pipeline, shade_group, prism_layout) =
            ctx.checked("building the raster pipeline", || {
                let source = match shape {
                    Shape::Box { .. } => raster_source(texture),
                    Shape::Mesh(_) => mesh_source(texture),
                    Shape::Curved(_) => curved_source(texture),
                };
                let module = shader_module(ctx, "raster", &source);
                let fragment = wgpu::ShaderStages::FRAGMENT;
                let tex = |binding| {
                    texture_entry(binding, fragment, true, wgpu::TextureViewDimension::D2)
                };
                let shade_group = bind_group_layout(
                    ctx,
                    "shading",
                    &[
                        frame_uniform_entry(),
                        tex(1),
                        tex(2),
                        sampler_entry(3, fragment),
                    ],
                );
                // Group 2, curved meshes only: their prisms.
                let prism_layout = matches!(shape, Shape::Curved(_)).then(|| {
                    bind_group_layout(
                        ctx,
                        "curved prisms",
                        &[storage_entry_in(0, true, wgpu::ShaderStages::FRAGMENT)],
                    )
                });
                let mut groups = vec![&gpu_map.layout, &shade_group];
                groups.extend(prism_layout.as_ref());
                let layout = pipeline_layout(ctx, "raster", &groups);
                let (vertex, fragment, buffers): (_, _, &[_]) = match shape {
                    Shape::Box { .. } => ("vs_main", "fs_main", &[]),
                    Shape::Mesh(_) => ("vs_mesh", "fs_mesh", &[SHELL_VERTEX_LAYOUT]),
                    Shape::Curved(_) => ("vs_curved", "fs_curved", &[CURVED_VERTEX_LAYOUT]),
                };
                let pipeline = render_pipeline(
                    ctx,
                    "raster",
                    &layout,
                    RenderStages {
                        module: &module,
                        vertex,
                        fragment,
                        buffers,
                        targets: &color_targets(),
                    },
                    wgpu::PrimitiveState {
                        front_face: if matches!(shape, Shape::Box { mirrored: true }) {
                            wgpu::FrontFace::Cw
                        } else {
                            wgpu::FrontFace::Ccw
                        },
                        cull_mode: Some(wgpu::Face::Back),
                        ..Default::default()
                    },
                    Some(depth_state()),
                );
                (pipeline, shade_group, prism_layout)
            })?;
        let mesh = |vertices: &[u8], count: usize, uv_shift, tiles, prisms| Geometry::Mesh {
            vertices: buffer_of(ctx, "shell vertices", vertices, wgpu::BufferUsages::VERTEX),
            count: count as u32,
            uv_shift,
            tiles,
            prisms,
        };
        let geometry = match shape {
            Shape::Box { mirrored } => Geometry::ShellBox { mirrored },
            Shape::Mesh(m) => mesh(
                bytemuck::cast_slice(&m.vertices),
                m.vertices.len(),
                m.uv_shift,
                m.tiles,
                None,
            ),
            Shape::Curved(shells) => {
                let prisms = buffer_of(
                    ctx,
                    "curved prisms",
                    bytemuck::cast_slice(&shells.prisms),
                    wgpu::BufferUsages::STORAGE,
                );
                let layout = prism_layout.as_ref().expect("built for a curved mesh");
                let group = bind_group(ctx, "curved prisms", layout, &[prisms.as_entire_binding()]);
                mesh(
                    bytemuck::cast_slice(&shells.vertices),
                    shells.vertices.len(),
                    shells.uv_shift,
                    shells.tiles,
                    Some(group),
                )
            }
        };
        Ok(Self {
            pipeline,
            kind: Kind::Displaced {
                shading: Box::new(MapShading {
                    map: gpu_map,
                    shade_group,
                    normal_view,
                    color_view,
                    sampler,
                }),
                geometry,
            },
        })
    }
}

/// The colour and AOV targets every pipeline writes.
fn color_targets() -> [Option<wgpu::ColorTargetState>; 2] {
    [COLOR_FORMAT, AOV_FORMAT].map(|format| color_target(format, None))
}

/// One depth test for every draw, so the nearest surface wins whichever
/// pipeline drew it.
fn depth_state() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::LessEqual),
        stencil: Default::default(),
        bias: Default::default(),
    }
}
