//! The raster path: one displaced planar face drawn as its shell box with
//! Donnelly's vertex and fragment stages (`shaders/raster.wgsl`), or a mesh
//! drawn as the shells of its triangles ([`crate::mesh`],
//! `shaders/mesh.wgsl`), and a scene's non-displaced shapes as plain
//! triangles ([`crate::plain`], `shaders/plain.wgsl`) in the same depth
//! buffer, rendered offscreen, with a UV AOV (uv, hit kind, t) beside the
//! colour so renders can be checked against the CPU trace pixel by pixel.

use crate::descriptors::{
    bind_group, bind_group_layout, buffer_of, cleared_attachment, color_target, empty_buffer,
    extent_2d, frame_uniform_entry, pipeline_layout, render_pipeline, sampler_entry, shader_module,
    texture_2d_descriptor, texture_entry, uniform_buffer, RenderStages,
};
use crate::gpu_map::{GpuMap, MapParams};
use crate::mesh::{ShellMesh, ShellVertex};
use crate::plain::{PlainFrame, PlainMesh, PLAIN_VERTEX_LAYOUT};
use crate::shaders::{mesh_source, plain_source, raster_source, DistanceTexture};
use crate::{Error, GpuContext, Result};
use bytemuck::{Pod, Zeroable};
use displace_core::convention::linear_to_srgb;
use displace_core::names::parse_choice;
use displace_core::{Address, DisplacementMap, MapRay, Method, TraceOptions};
use glam::{Mat4, Vec2, Vec3};

/// Largest image edge accepted before anything is allocated.
pub const MAX_IMAGE_EDGE: u32 = 16384;

/// Self-shadowing variant (a second march towards the light).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shadows {
    /// No self-shadowing: the light reaches every point (the cheapest frame).
    None,
    /// Hard occlusion: a second march from the hit towards the light through
    /// the same distance map (the ray tracer's shadow ray, which Donnelly's
    /// shaders leave out).
    #[default]
    Hard,
    /// Hard occlusion plus the distance field's penumbra estimate.
    Soft,
}

impl std::str::FromStr for Shadows {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let choices = [
            ("none", Self::None),
            ("hard", Self::Hard),
            ("soft", Self::Soft),
        ];
        parse_choice("shadows", s, &choices).map_err(Error::InvalidOption)
    }
}

/// A displaced planar face, a pinhole camera and a point light: the built-in
/// scene of `displace gpu-render`. The face spans `origin + [0,1] t + [0,1]
/// b` with its shell `depth` high along `normal`. A mesh renderer
/// ([`Renderer::for_mesh`]) takes the camera, light, shading and `depth`
/// from it and its faces from the mesh: `origin`, `tangent`, `bitangent`,
/// `tiles` and `mirrored` are not used there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneScene {
    /// Image size in pixels.
    pub size: [u32; 2],
    /// Camera position.
    pub eye: Vec3,
    /// The point the camera looks at.
    pub target: Vec3,
    /// Camera up direction.
    pub up: Vec3,
    /// Vertical field of view.
    pub fov_y_degrees: f32,
    /// Point light position.
    pub light: Vec3,
    /// Light intensity (see `falloff`).
    pub light_intensity: f32,
    /// Corner of the face at texture coordinate `(0, 0)`.
    pub origin: Vec3,
    /// Edge of one tile along `u`.
    pub tangent: Vec3,
    /// Edge of one tile along `v`.
    pub bitangent: Vec3,
    /// Shell depth: world height of a texel of value 1.
    pub depth: f32,
    /// How the fragment stage traces (listing 8-2's fixed loop, ours, exact).
    pub method: Method,
    /// Most sphere-tracing steps per ray.
    pub iterations: u32,
    /// Self-shadowing mode.
    pub shadows: Shadows,
    /// Sharpness of the soft penumbra: the visibility is
    /// `min(k * distance / t)` along the shadow march.
    pub penumbra_k: f32,
    /// Ambient term added to the albedo, so unlit parts are not black.
    pub ambient: f32,
    /// Blinn-Phong specular weight.
    pub specular: f32,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Divide the light by the squared world distance (a point light of
    /// radiant intensity `light_intensity`, as the CPU renderer lights);
    /// off, the light is a constant irradiance (the built-in scene's look).
    pub falloff: bool,
    /// Near and far planes; `None` picks them from this face alone. Faces
    /// drawn into one depth buffer must share them.
    pub depth_range: Option<[f32; 2]>,
    /// How many tiles of the map the face spans along `tangent` and
    /// `bitangent` (each of those is one tile); other than `[1, 1]` only for
    /// a map baked with repeat addressing.
    pub tiles: [f32; 2],
    /// The face's frame is left-handed: its normal is `bitangent x tangent`
    /// (a scene quad with `flip_v`, whose `v` runs back along its edge).
    /// Drawn only by a renderer made with the same handedness.
    pub mirrored: bool,
    /// A mesh draw: the world box `[min, max]` holding the mesh's base
    /// surface (its shell lies within `depth` of it). `None` for a face.
    pub bounds: Option<[Vec3; 2]>,
}

impl PlaneScene {
    /// Corners of a box holding all this draw can put on screen: the face's
    /// shell box, or a mesh's bounds grown by the shell depth.
    pub fn shell_corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|c| {
            let bit = |k: usize| ((c >> k) & 1) as f32;
            match self.bounds {
                Some([lo, hi]) => {
                    let grow = Vec3::splat(self.depth.abs());
                    let (lo, hi) = (lo - grow, hi + grow);
                    lo + (hi - lo) * Vec3::new(bit(0), bit(1), bit(2))
                }
                None => {
                    self.origin
                        + self.tangent * (bit(0) * self.tiles[0])
                        + self.bitangent * (bit(1) * self.tiles[1])
                        + self.normal() * (self.depth * bit(2))
                }
            }
        })
    }

    /// The face of `map`'s extent at the origin in the xy plane (z up),
    /// seen obliquely, lit from above one corner.
    pub fn for_map(map: &DisplacementMap, size: [u32; 2]) -> Self {
        let e = map.extent;
        let centre = Vec3::new(e.sx * 0.5, e.sy * 0.5, 0.0);
        let reach = e.sx.max(e.sy);
        Self {
            size,
            eye: centre + Vec3::new(-0.35, -1.0, 0.8) * reach,
            target: centre,
            up: Vec3::Z,
            fov_y_degrees: 45.0,
            light: centre + Vec3::new(-1.0, 0.4, 1.2) * reach,
            light_intensity: 1.0,
            origin: Vec3::ZERO,
            tangent: Vec3::new(e.sx, 0.0, 0.0),
            bitangent: Vec3::new(0.0, e.sy, 0.0),
            depth: e.sz,
            method: Method::Sphere,
            iterations: 64,
            shadows: Shadows::Hard,
            penumbra_k: 8.0,
            ambient: 0.15,
            specular: 0.25,
            shininess: 32.0,
            falloff: false,
            depth_range: None,
            tiles: [1.0, 1.0],
            mirrored: false,
            bounds: None,
        }
    }

    /// Unit face normal, `tangent x bitangent` (reversed for a mirrored face).
    pub fn normal(&self) -> Vec3 {
        let n = self.tangent.cross(self.bitangent).normalize();
        if self.mirrored {
            -n
        } else {
            n
        }
    }

    /// The camera's view-projection matrix, with near and far planes from
    /// `depth_range` or from this face's shell.
    pub fn view_proj(&self) -> Mat4 {
        let aspect = self.size[0] as f32 / self.size[1] as f32;
        let reach = (self.eye - self.target).length()
            + self.tangent.length() * self.tiles[0]
            + self.bitangent.length() * self.tiles[1];
        let [near, far] = self.depth_range.unwrap_or([reach * 1e-3, reach * 4.0]);
        Mat4::perspective_rh(self.fov_y_degrees.to_radians(), aspect, near, far)
            * Mat4::look_at_rh(self.eye, self.target, self.up)
    }

    /// The camera ray through the centre of pixel `(x, y)` in map space
    /// (depth units), as the rasteriser samples it.
    pub fn pixel_ray(&self, map: &DisplacementMap, x: u32, y: u32) -> MapRay {
        let inv = self.view_proj().inverse();
        let ndc_x = (x as f32 + 0.5) / self.size[0] as f32 * 2.0 - 1.0;
        let ndc_y = 1.0 - (y as f32 + 0.5) / self.size[1] as f32 * 2.0;
        let far = inv.project_point3(Vec3::new(ndc_x, ndc_y, 1.0));
        let to_map = |v: Vec3| {
            let [ax, ay] = map.aspect();
            Vec3::new(
                v.dot(self.tangent) / self.tangent.length_squared() * ax,
                v.dot(self.bitangent) / self.bitangent.length_squared() * ay,
                v.dot(self.normal()) / self.depth,
            )
        };
        MapRay::new(to_map(self.eye - self.origin), to_map(far - self.eye))
    }

    /// The shell's depth (displaced draws only: a plain draw has none).
    fn check_depth(&self) -> Result<()> {
        if !(self.depth.is_finite() && self.depth > 0.0) {
            return Err(Error::InvalidOption(
                "scene vectors must be finite and the depth positive".into(),
            ));
        }
        Ok(())
    }

    /// The face's own checks (box renderers only).
    fn check_face(&self) -> Result<()> {
        if !(self.origin.is_finite() && self.tangent.is_finite() && self.bitangent.is_finite()) {
            return Err(Error::InvalidOption("face vectors must be finite".into()));
        }
        if self.tangent.cross(self.bitangent).length_squared() == 0.0 {
            return Err(Error::InvalidOption("degenerate face".into()));
        }
        Ok(())
    }

    fn check(&self) -> Result<()> {
        let [w, h] = self.size;
        if w == 0 || h == 0 || w > MAX_IMAGE_EDGE || h > MAX_IMAGE_EDGE {
            return Err(Error::InvalidOption(format!(
                "image size {w}x{h} (each side must be 1..={MAX_IMAGE_EDGE})"
            )));
        }
        let vecs = [self.eye, self.target, self.up, self.light];
        if !vecs.iter().all(|v| v.is_finite()) {
            return Err(Error::InvalidOption("scene vectors must be finite".into()));
        }
        if (self.eye - self.target).length_squared() == 0.0 {
            return Err(Error::InvalidOption("degenerate camera".into()));
        }
        if let Some([near, far]) = self.depth_range {
            if !(near > 0.0 && far > near && far.is_finite()) {
                return Err(Error::InvalidOption(format!(
                    "depth range {near}..{far} (need 0 < near < far)"
                )));
            }
        }
        if !(self.fov_y_degrees > 0.0 && self.fov_y_degrees < 180.0) {
            return Err(Error::InvalidOption(format!(
                "field of view {} degrees",
                self.fov_y_degrees
            )));
        }
        Ok(())
    }
}

/// Mirror of WGSL `Frame` (raster.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light: [f32; 4],
    face_origin: [f32; 4],
    face_t: [f32; 4],
    face_b: [f32; 4],
    face_n: [f32; 4],
    inv_bump_depth: f32,
    shadows: u32,
    penumbra_k: f32,
    ambient: f32,
    specular: f32,
    shininess: f32,
    light_intensity: f32,
    falloff: u32,
    uv_shift: [f32; 2],
    _pad: [f32; 2],
}

/// A rendered frame: sRGB colour and the AOV `[u, v, hit kind, t]`
/// (`kind` 0 where nothing was hit; [`crate::convention::HIT_PLAIN`] on a
/// non-displaced shape, whose `t` is the world distance from the eye).
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// sRGB colour, four bytes a pixel, rows top to bottom.
    pub rgba8: Vec<u8>,
    /// The AOV `[u, v, hit kind, t]` per pixel.
    pub uv: Vec<[f32; 4]>,
}

/// Format of the colour target: sRGB-encoded on store, so shading stays in
/// linear RGB.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const AOV_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// What a renderer draws.
enum Geometry {
    /// The planar face's shell box, placed by the [`PlaneScene`].
    ShellBox { mirrored: bool },
    /// A mesh's shell, in world space ([`ShellMesh`]).
    Mesh {
        vertices: wgpu::Buffer,
        count: u32,
        uv_shift: Vec2,
        tiles: [f32; 2],
    },
}

/// A pipeline and what it draws: one displacement map's face or mesh, or
/// the plain (non-displaced) triangles of a scene ([`Renderer::plain`]).
pub struct Renderer {
    pipeline: wgpu::RenderPipeline,
    kind: Kind,
}

enum Kind {
    Displaced {
        shading: Box<MapShading>,
        geometry: Geometry,
    },
    /// [`PlainMesh`] triangles: group 0 is their [`PlainFrame`].
    Plain {
        vertices: wgpu::Buffer,
        count: u32,
        frame_layout: wgpu::BindGroupLayout,
    },
}

/// The map, normal map, colour texture and sampler a displaced draw binds.
struct MapShading {
    map: GpuMap,
    shade_group: wgpu::BindGroupLayout,
    normal_view: wgpu::TextureView,
    color_view: wgpu::TextureView,
    sampler: wgpu::Sampler,
}

impl Renderer {
    /// A renderer whose colour texture is Donnelly's checkerboard.
    pub fn new(ctx: &GpuContext, map: &DisplacementMap, texture: DistanceTexture) -> Result<Self> {
        Self::with_colour(
            ctx,
            map,
            texture,
            &checker_mips(256, 16),
            256,
            Shape::Box { mirrored: false },
        )
    }

    /// A renderer of `mesh`'s shell with Donnelly's checkerboard (as
    /// [`Renderer::new`]).
    pub fn checker_mesh(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        mesh: &ShellMesh,
    ) -> Result<Self> {
        Self::with_colour(
            ctx,
            map,
            texture,
            &checker_mips(256, 16),
            256,
            Shape::Mesh(mesh),
        )
    }

    /// A renderer of `mesh`'s shell in the constant linear `albedo` (as
    /// [`Renderer::with_albedo`]).
    pub fn for_mesh(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        albedo: [f32; 3],
        mesh: &ShellMesh,
    ) -> Result<Self> {
        Self::with_colour(
            ctx,
            map,
            texture,
            &[albedo_texel(albedo)],
            1,
            Shape::Mesh(mesh),
        )
    }

    /// A renderer whose surface colour is the constant linear `albedo`
    /// (a scene material's colour; each channel clamped to `[0, 1]`, stored
    /// as 8-bit sRGB like the checkerboard), for faces of the handedness
    /// `mirrored` ([`PlaneScene::mirrored`]: the shell box's winding flips
    /// with it, so back-face culling must too).
    pub fn with_albedo(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        albedo: [f32; 3],
        mirrored: bool,
    ) -> Result<Self> {
        Self::with_colour(
            ctx,
            map,
            texture,
            &[albedo_texel(albedo)],
            1,
            Shape::Box { mirrored },
        )
    }

    /// A renderer of a scene's plain triangles (`shaders/plain.wgsl`),
    /// drawn two-sided into the same targets and depth buffer as the
    /// displaced faces. Its [`PlaneScene`] gives the camera and light only:
    /// `light_intensity` scales the vertices' `diffuse` and `specular`, and
    /// `depth`, the face vectors and the trace settings are not used (set
    /// [`PlaneScene::bounds`] to the mesh's so [`shared_depth_range`]
    /// holds it).
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

    fn with_colour(
        ctx: &GpuContext,
        map: &DisplacementMap,
        texture: DistanceTexture,
        colour_mips: &[Vec<u8>],
        colour_size: u32,
        shape: Shape,
    ) -> Result<Self> {
        if let Shape::Mesh(mesh) = shape {
            if mesh.vertices.is_empty() {
                return Err(Error::InvalidOption("the mesh has no triangles".into()));
            }
        }
        let gpu_map = GpuMap::new(ctx, map, texture)?;
        let normals: Vec<u8> = map
            .normals
            .data
            .iter()
            .flat_map(|n| {
                let e = |c: f32| ((c * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
                [e(n.x), e(n.y), e(n.z), 255]
            })
            .collect();
        let normal_view = texture_2d(
            ctx,
            "normal map",
            [map.normals.width as u32, map.normals.height as u32],
            wgpu::TextureFormat::Rgba8Unorm,
            &[normals],
        );
        let color_view = texture_2d(
            ctx,
            "colour",
            [colour_size, colour_size],
            wgpu::TextureFormat::Rgba8UnormSrgb,
            colour_mips,
        );
        let address = match map.address() {
            Address::Clamp => wgpu::AddressMode::ClampToEdge,
            Address::Repeat => wgpu::AddressMode::Repeat,
        };
        let sampler = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shading"),
            address_mode_u: address,
            address_mode_v: address,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let (pipeline, shade_group) = ctx.checked("building the raster pipeline", || {
            let source = match shape {
                Shape::Box { .. } => raster_source(texture),
                Shape::Mesh(_) => mesh_source(texture),
            };
            let module = shader_module(ctx, "raster", &source);
            let fragment = wgpu::ShaderStages::FRAGMENT;
            let tex =
                |binding| texture_entry(binding, fragment, true, wgpu::TextureViewDimension::D2);
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
            let layout = pipeline_layout(ctx, "raster", &[&gpu_map.layout, &shade_group]);
            let (vertex, fragment, buffers): (_, _, &[_]) = match shape {
                Shape::Box { .. } => ("vs_main", "fs_main", &[]),
                Shape::Mesh(_) => ("vs_mesh", "fs_mesh", &[SHELL_VERTEX_LAYOUT]),
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
            (pipeline, shade_group)
        })?;
        let geometry = match shape {
            Shape::Box { mirrored } => Geometry::ShellBox { mirrored },
            Shape::Mesh(mesh) => Geometry::Mesh {
                vertices: buffer_of(
                    ctx,
                    "shell vertices",
                    bytemuck::cast_slice(&mesh.vertices),
                    wgpu::BufferUsages::VERTEX,
                ),
                count: mesh.vertices.len() as u32,
                uv_shift: mesh.uv_shift,
                tiles: mesh.tiles,
            },
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

    /// The bind groups of one draw of this renderer with `scene`'s camera
    /// and light, in group order.
    fn uniforms(&self, ctx: &GpuContext, scene: &PlaneScene) -> Result<Vec<wgpu::BindGroup>> {
        scene.check()?;
        match &self.kind {
            Kind::Displaced { shading, geometry } => shading.uniforms(ctx, geometry, scene),
            Kind::Plain { frame_layout, .. } => Ok(vec![plain_uniforms(ctx, frame_layout, scene)]),
        }
    }

    /// Times `frames` renders of `scene` (benchmarks).
    pub fn time(
        &self,
        ctx: &GpuContext,
        scene: &PlaneScene,
        frames: u32,
    ) -> Result<crate::timing::Timing> {
        let groups = self.uniforms(ctx, scene)?;
        let targets = Targets::new(ctx, scene.size);
        crate::timing::time_frames(ctx, frames, |encoder, query| {
            record(
                encoder,
                &targets,
                &[(self, groups.clone())],
                DEFAULT_CLEAR,
                frames.max(1),
                query,
            );
            Ok(())
        })
    }

    /// Renders `scene` offscreen and reads colour and AOV back.
    pub fn render(&self, ctx: &GpuContext, scene: &PlaneScene) -> Result<Image> {
        render_faces(ctx, &[(self, scene)], DEFAULT_CLEAR)
    }
}

impl MapShading {
    fn uniforms(
        &self,
        ctx: &GpuContext,
        geometry: &Geometry,
        scene: &PlaneScene,
    ) -> Result<Vec<wgpu::BindGroup>> {
        scene.check_depth()?;
        let (tiles, uv_shift) = match geometry {
            Geometry::ShellBox { mirrored } => {
                scene.check_face()?;
                if scene.mirrored != *mirrored {
                    return Err(Error::InvalidOption(
                        "the face's handedness differs from the renderer's (PlaneScene::mirrored)"
                            .into(),
                    ));
                }
                (scene.tiles, Vec2::ZERO)
            }
            Geometry::Mesh {
                tiles, uv_shift, ..
            } => (*tiles, *uv_shift),
        };
        let opts = TraceOptions {
            method: scene.method,
            iterations: scene.iterations,
            // The fragment's start point is interpolated: let the clip find
            // the shell's face a hair behind it.
            t_min: -1e-3,
            tiles,
            ..TraceOptions::default()
        };
        let params: MapParams = self.map.params(&opts)?;
        let n = scene.normal();
        let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
        let frame = FrameUniform {
            view_proj: scene.view_proj().to_cols_array_2d(),
            eye: v4(scene.eye, 1.0),
            light: v4(scene.light, 1.0),
            face_origin: v4(scene.origin, 1.0),
            face_t: v4(scene.tangent, 0.0),
            face_b: v4(scene.bitangent, 0.0),
            face_n: v4(n, 0.0),
            inv_bump_depth: 1.0 / scene.depth,
            shadows: crate::convention::shadows_code(scene.shadows),
            penumbra_k: scene.penumbra_k,
            ambient: scene.ambient,
            specular: scene.specular,
            shininess: scene.shininess,
            light_intensity: scene.light_intensity,
            falloff: scene.falloff as u32,
            uv_shift: uv_shift.to_array(),
            _pad: [0.0; 2],
        };
        let params_buf = uniform_buffer(ctx, "raster params", &params);
        let frame_buf = uniform_buffer(ctx, "frame", &frame);
        let map_group = self.map.bind_group(ctx, &params_buf);
        let shade = bind_group(
            ctx,
            "shading",
            &self.shade_group,
            &[
                frame_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&self.normal_view),
                wgpu::BindingResource::TextureView(&self.color_view),
                wgpu::BindingResource::Sampler(&self.sampler),
            ],
        );
        Ok(vec![map_group, shade])
    }
}

/// Group 0 of a plain draw: `scene`'s camera and light.
fn plain_uniforms(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    scene: &PlaneScene,
) -> wgpu::BindGroup {
    let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
    let frame = PlainFrame {
        view_proj: scene.view_proj().to_cols_array_2d(),
        eye: v4(scene.eye, 1.0),
        light: v4(scene.light, 1.0),
        ambient: scene.ambient,
        light_intensity: scene.light_intensity,
        falloff: scene.falloff as u32,
        _pad: 0.0,
    };
    let buffer = uniform_buffer(ctx, "plain frame", &frame);
    bind_group(ctx, "plain frame", layout, &[buffer.as_entire_binding()])
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

/// The built-in scene's background (linear).
const DEFAULT_CLEAR: [f64; 3] = [0.02, 0.02, 0.03];

/// What [`Renderer::with_colour`] builds a pipeline for.
#[derive(Clone, Copy)]
enum Shape<'a> {
    Box { mirrored: bool },
    Mesh(&'a ShellMesh),
}

const SHELL_VERTEX_LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
    array_stride: std::mem::size_of::<ShellVertex>() as u64,
    step_mode: wgpu::VertexStepMode::Vertex,
    attributes: &SHELL_VERTEX_ATTRIBUTES,
};

/// [`ShellVertex`]'s fields at their offsets (the struct pads the normal to
/// 16 bytes, which `vertex_attr_array!` would not know).
const SHELL_VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 6] = {
    use std::mem::offset_of;
    use wgpu::VertexFormat as F;
    const fn at(format: F, offset: usize, shader_location: u32) -> wgpu::VertexAttribute {
        wgpu::VertexAttribute {
            format,
            offset: offset as u64,
            shader_location,
        }
    }
    [
        at(F::Float32x3, offset_of!(ShellVertex, position), 0),
        at(F::Float32, offset_of!(ShellVertex, lift), 1),
        at(F::Float32x3, offset_of!(ShellVertex, normal), 2),
        at(F::Float32x4, offset_of!(ShellVertex, tangent), 3),
        at(F::Float32x2, offset_of!(ShellVertex, uv), 4),
        at(F::Float32x2, offset_of!(ShellVertex, scale), 5),
    ]
};

/// One 8-bit sRGB texel of the linear colour `albedo`, each channel clamped
/// to `[0, 1]`.
fn albedo_texel(albedo: [f32; 3]) -> Vec<u8> {
    let e = |c: f32| (linear_to_srgb(c) * 255.0).round() as u8;
    vec![e(albedo[0]), e(albedo[1]), e(albedo[2]), 255]
}

type Draw<'a> = (&'a Renderer, Vec<wgpu::BindGroup>);

fn record(
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    draws: &[Draw],
    clear: [f64; 3],
    frames: u32,
    timestamps: Option<&wgpu::QuerySet>,
) {
    for f in 0..frames {
        let edge = f == 0 || f + 1 == frames;
        let ts = timestamps
            .filter(|_| edge)
            .map(|q| wgpu::RenderPassTimestampWrites {
                query_set: q,
                beginning_of_pass_write_index: (f == 0).then_some(0),
                end_of_pass_write_index: (f + 1 == frames).then_some(1),
            });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("displace"),
            color_attachments: &[
                cleared_attachment(
                    &targets.color,
                    wgpu::Color {
                        r: clear[0],
                        g: clear[1],
                        b: clear[2],
                        a: 1.0,
                    },
                ),
                cleared_attachment(
                    &targets.aov,
                    wgpu::Color {
                        r: -1.0,
                        g: -1.0,
                        b: 0.0,
                        a: -1.0,
                    },
                ),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: ts,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        for (renderer, groups) in draws {
            pass.set_pipeline(&renderer.pipeline);
            for (k, group) in groups.iter().enumerate() {
                pass.set_bind_group(k as u32, group, &[]);
            }
            match &renderer.kind {
                Kind::Displaced {
                    geometry: Geometry::ShellBox { .. },
                    ..
                } => pass.draw(0..36, 0..1),
                Kind::Displaced {
                    geometry:
                        Geometry::Mesh {
                            vertices, count, ..
                        },
                    ..
                }
                | Kind::Plain {
                    vertices, count, ..
                } => {
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    pass.draw(0..*count, 0..1);
                }
            }
        }
    }
}

/// Draws every `(renderer, face)` into one colour, AOV and depth target (the
/// nearest surface wins per pixel, through the fragments' exact depths),
/// cleared to the linear colour `clear`, and reads them back. All faces must
/// share the image size and camera, including [`PlaneScene::depth_range`].
pub fn render_faces(
    ctx: &GpuContext,
    faces: &[(&Renderer, &PlaneScene)],
    clear: [f64; 3],
) -> Result<Image> {
    let first = check_shared_camera(faces)?;
    // Sizes and vectors are checked before anything is allocated.
    for (r, s) in faces {
        s.check()?;
        if matches!(r.kind, Kind::Displaced { .. }) {
            s.check_depth()?;
        }
    }
    let targets = Targets::new(ctx, first.size);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encode_faces(ctx, &mut encoder, &targets, faces, clear)?;
    let [w, h] = first.size;
    let (cbuf, color_row) = copy_to_readback(ctx, &mut encoder, &targets.color_tex, 4, first.size);
    let (abuf, aov_row) = copy_to_readback(ctx, &mut encoder, &targets.aov_tex, 16, first.size);
    let commands = ctx.checked("finishing the render", || encoder.finish())?;
    ctx.queue.submit([commands]);
    let cbytes = ctx.read_buffer(&cbuf)?;
    let abytes = ctx.read_buffer(&abuf)?;
    let mut rgba8 = Vec::with_capacity((w * h * 4) as usize);
    let mut uv = Vec::with_capacity((w * h) as usize);
    for y in 0..h as usize {
        rgba8.extend_from_slice(&cbytes[y * color_row as usize..][..w as usize * 4]);
        let row: &[f32] = bytemuck::cast_slice(&abytes[y * aov_row as usize..][..w as usize * 16]);
        uv.extend(row.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
    }
    Ok(Image {
        width: w,
        height: h,
        rgba8,
        uv,
    })
}

/// Records a copy of `texture` (`texel_bytes` per texel, `[w, h]`) into a
/// new mappable buffer; returns it and its padded row pitch.
pub(crate) fn copy_to_readback(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    texel_bytes: u32,
    [w, h]: [u32; 2],
) -> (wgpu::Buffer, u32) {
    let row = (w * texel_bytes).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
        * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = empty_buffer(
        ctx,
        "readback",
        row as u64 * h as u64,
        wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
    );
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        extent_2d([w, h]),
    );
    (buffer, row)
}

fn check_shared_camera<'a>(faces: &[(&Renderer, &'a PlaneScene)]) -> Result<&'a PlaneScene> {
    let Some((_, first)) = faces.first() else {
        return Err(Error::InvalidOption("no faces to render".into()));
    };
    if faces
        .iter()
        .any(|(_, s)| s.size != first.size || s.view_proj() != first.view_proj())
    {
        return Err(Error::InvalidOption(
            "faces drawn together must share the image size and camera".into(),
        ));
    }
    Ok(first)
}

/// Records the draw of every `(renderer, face)` into `targets` on
/// `encoder`, as [`render_faces`] does, without reading anything back (the
/// viewer presents the colour target on the GPU). `targets` must have the
/// faces' image size.
pub fn encode_faces(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    targets: &Targets,
    faces: &[(&Renderer, &PlaneScene)],
    clear: [f64; 3],
) -> Result<()> {
    let first = check_shared_camera(faces)?;
    if first.size != targets.size {
        return Err(Error::InvalidOption(format!(
            "faces of {:?} pixels drawn into targets of {:?}",
            first.size, targets.size
        )));
    }
    let draws = faces
        .iter()
        .map(|(r, s)| r.uniforms(ctx, s).map(|groups| (*r, groups)))
        .collect::<Result<Vec<_>>>()?;
    ctx.checked("rendering", || {
        record(encoder, targets, &draws, clear, 1, None)
    })
}

/// Near and far planes that hold the shell boxes of every face in front of
/// the camera of the first (`None` when all of them lie behind it), for
/// faces drawn into one depth buffer ([`PlaneScene::depth_range`]).
pub fn shared_depth_range(faces: &[PlaneScene]) -> Option<[f32; 2]> {
    let first = faces.first()?;
    let forward = (first.target - first.eye).normalize();
    let far = faces
        .iter()
        .flat_map(PlaneScene::shell_corners)
        .map(|p| (p - first.eye).dot(forward))
        .fold(0.0f32, f32::max);
    (far > 0.0).then_some([far * 1.01 * 1e-4, far * 1.01])
}

/// The colour (sRGB), AOV and depth targets of one image size.
pub struct Targets {
    size: [u32; 2],
    color_tex: wgpu::Texture,
    aov_tex: wgpu::Texture,
    color: wgpu::TextureView,
    aov: wgpu::TextureView,
    depth: wgpu::TextureView,
}

impl Targets {
    /// Allocates the three targets at `w x h`.
    pub fn new(ctx: &GpuContext, [w, h]: [u32; 2]) -> Self {
        let make = |format, usage| {
            ctx.device
                .create_texture(&texture_2d_descriptor("target", [w, h], 1, format, usage))
        };
        let rt = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let color_tex = make(COLOR_FORMAT, rt | wgpu::TextureUsages::TEXTURE_BINDING);
        let aov_tex = make(AOV_FORMAT, rt);
        let depth = make(DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT)
            .create_view(&Default::default());
        Self {
            size: [w, h],
            color: color_tex.create_view(&Default::default()),
            aov: aov_tex.create_view(&Default::default()),
            color_tex,
            aov_tex,
            depth,
        }
    }

    /// Size of the targets in pixels.
    pub fn size(&self) -> [u32; 2] {
        self.size
    }

    /// The colour view ([`COLOR_FORMAT`], also bindable as a texture).
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color
    }
}

/// A two-tone checkerboard (`cells` squares a side) and its box-filtered
/// mip chain, so derivative-driven sampling (section 8.5.3) has levels to
/// choose from.
/// Donnelly's checkerboard colour texture (RGBA8 sRGB, `size` texels with
/// `cells` squares a side) and its box-filtered mips down to 1x1: the
/// colour map of [`Renderer::new`], public so that another renderer of the
/// same face (displace-bevy's comparison test) samples the very same texels.
pub fn checker_mips(size: u32, cells: u32) -> Vec<Vec<u8>> {
    let cell = size / cells;
    let mut level: Vec<u8> = (0..size * size)
        .flat_map(|k| {
            let (x, y) = (k % size, k / size);
            if ((x / cell) + (y / cell)) % 2 == 0 {
                [225, 200, 160, 255]
            } else {
                [150, 90, 60, 255]
            }
        })
        .collect();
    let mut out = Vec::new();
    let mut n = size;
    loop {
        out.push(level.clone());
        if n == 1 {
            return out;
        }
        let m = n / 2;
        level = (0..m * m)
            .flat_map(|k| {
                let (x, y) = ((k % m) * 2, (k / m) * 2);
                let at = |dx: u32, dy: u32, c: usize| {
                    level[(((y + dy) * n + x + dx) * 4) as usize + c] as u32
                };
                let mut px = [0u8; 4];
                for (c, p) in px.iter_mut().enumerate() {
                    *p = ((at(0, 0, c) + at(1, 0, c) + at(0, 1, c) + at(1, 1, c) + 2) / 4) as u8;
                }
                px
            })
            .collect();
        n = m;
    }
}

/// A 2D texture with every mip level given in full (4 bytes per texel).
pub(crate) fn texture_2d(
    ctx: &GpuContext,
    label: &str,
    [w, h]: [u32; 2],
    format: wgpu::TextureFormat,
    mips: &[Vec<u8>],
) -> wgpu::TextureView {
    let texture = ctx.device.create_texture(&texture_2d_descriptor(
        label,
        [w, h],
        mips.len() as u32,
        format,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    ));
    for (level, data) in mips.iter().enumerate() {
        let (lw, lh) = ((w >> level).max(1), (h >> level).max(1));
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: level as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(lw * 4),
                rows_per_image: Some(lh),
            },
            extent_2d([lw, lh]),
        );
    }
    texture.create_view(&Default::default())
}

#[cfg(test)]
mod layout_tests {
    #[test]
    fn frame_uniform_matches_wgsl() {
        use super::FrameUniform;
        use crate::shaders::{assert_layout, offsets, raster_source, DistanceTexture};
        assert_layout(
            &raster_source(DistanceTexture::R8Linear),
            "Frame",
            std::mem::size_of::<FrameUniform>(),
            offsets!(FrameUniform {
                view_proj,
                eye,
                light,
                face_origin,
                face_t,
                face_b,
                face_n,
                inv_bump_depth,
                shadows,
                penumbra_k,
                ambient,
                specular,
                shininess,
                light_intensity,
                falloff,
                uv_shift,
                _pad
            }),
        );
    }
}
