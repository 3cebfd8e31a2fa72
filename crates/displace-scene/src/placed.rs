//! What a scene places in the world, renderer-neutral: each shape of the
//! scene file with its material ([`PlacedShape`]), the displaced faces as
//! their frames, maps and trace settings ([`FlatDisplacement`],
//! [`CurvedDisplacement`]), and the meshes as placed ([`SceneMesh`]). The
//! CPU renderer builds its primitives and BVH from these; the GPU's raster
//! path its draws (pbrt-v4's `BasicScene` feeding both its aggregates).

use crate::curved_shell::CurvedShell;
use crate::mesh::MeshTriangle;
use crate::mesh_shells::MeshShells;
use crate::shapes::{Quad, Sphere, Triangle};
use crate::texture::Texture;
use displace_core::{DisplacementMap, TraceOptions};
use glam::{DVec2, Mat3, Vec2, Vec3};
use std::sync::Arc;

/// Where a face sits in the world: its base point at texture coordinate
/// `(0, 0)`, how the world moves per tile of texture coordinate, its unit
/// normal and its displacement depth.
///
/// The scene builder fills one in for each displaced quad and triangle;
/// [`FlatDisplacement::new`] turns it into the affine frame `world = origin
/// + M p` of map space, which the renderers trace in.
#[derive(Clone, Copy, Debug)]
pub struct FaceFrame {
    /// World position of texture coordinate `(0, 0)` on the base surface
    /// (the bottom of the shell, height 0).
    pub origin: Vec3,
    /// World displacement per unit of `u` (one tile along the face's first
    /// edge): `dP/du`, the tangent.
    pub dpdu: Vec3,
    /// World displacement per unit of `v`: `dP/dv`, the bitangent. Need not
    /// be orthogonal to [`Self::dpdu`]: sheared faces trace exactly.
    pub dpdv: Vec3,
    /// Unit normal of the base surface, the direction heights displace
    /// along (the side the shell is extruded towards).
    pub normal: Vec3,
    /// World height of a height-map value of 1: the shell's thickness.
    pub depth: f32,
}

/// A displaced quad or triangle: the prism over it (the ray-tracer paper's
/// extruded box, section 2.4), with the map it is traced through.
#[derive(Clone, Debug)]
pub struct FlatDisplacement {
    frame: FaceFrame,
    /// `M` of `world = origin + M p`: map space's `x`, `y` and `z` axes in
    /// the world (a tile's width per aspect, the depth along the normal).
    to_world: Mat3,
    map: Arc<DisplacementMap>,
    trace: TraceOptions,
    prism_uv: Option<[Vec2; 3]>,
    uv_offset: Vec2,
    /// Base colour texture sampled at the hit's texture coordinate (the
    /// scene's `color_texture`); `None` leaves the material's own albedo.
    pub color: Option<Arc<Texture>>,
    /// A tangent-space normal map (+Y up, OpenGL) given in the scene, which
    /// then stands in for the normals baked from the height map (the
    /// ray-tracer paper's section 2.2 normal map); `None` uses the baked
    /// ones.
    pub normal_map: Option<Arc<Texture>>,
}

impl FlatDisplacement {
    /// The face over `frame`, traced through `map` with `trace`; `None`
    /// when the frame is degenerate (zero or non-finite volume), since the
    /// map-space transform could not be inverted.
    ///
    /// `trace.tiles` is how many tiles of the map the face spans; `prism_uv`
    /// the triangle's texture coordinates (already in `[0, tiles]`) or
    /// `None` for the full parallelogram; `uv_offset` is added back to every
    /// hit's texture coordinate (triangles shifted by whole tiles into the
    /// map's domain).
    pub fn new(
        frame: FaceFrame,
        map: Arc<DisplacementMap>,
        trace: TraceOptions,
        prism_uv: Option<[Vec2; 3]>,
        uv_offset: Vec2,
    ) -> Option<Self> {
        let [ax, ay] = map.aspect();
        let to_world =
            Mat3::from_cols(frame.dpdu / ax, frame.dpdv / ay, frame.normal * frame.depth);
        let det = to_world.determinant();
        if !det.is_finite() || det.abs() <= 1e-30 {
            return None;
        }
        Some(Self {
            frame,
            to_world,
            map,
            trace,
            prism_uv,
            uv_offset,
            color: None,
            normal_map: None,
        })
    }

    /// `(origin, M)` of the frame `world = origin + M p`.
    pub fn frame(&self) -> (Vec3, Mat3) {
        (self.frame.origin, self.to_world)
    }

    /// The displacement map the face is traced through, shared with every
    /// face that uses the same source and aspect (the bake cache).
    pub fn map(&self) -> &Arc<DisplacementMap> {
        &self.map
    }

    /// The world corners of the shell (the prism's six, or the box's
    /// eight: base, then top), which bound the displaced surface.
    pub fn shell_corners(&self) -> Vec<Vec3> {
        let [ax, ay] = self.map.aspect();
        let hi = Vec2::new(ax * self.trace.tiles[0], ay * self.trace.tiles[1]);
        let base: Vec<Vec2> = match self.prism_uv {
            Some(t) => t.map(|uv| uv * Vec2::new(ax, ay)).to_vec(),
            None => vec![Vec2::ZERO, Vec2::new(hi.x, 0.0), Vec2::new(0.0, hi.y), hi],
        };
        let (origin, m) = (self.frame.origin, self.to_world);
        base.iter()
            .flat_map(|b| [0.0, 1.0].map(|z| origin + m * b.extend(z)))
            .collect()
    }

    /// The face's trace settings (method, step count, tiles), so that every
    /// renderer traces the face alike.
    pub fn trace_options(&self) -> TraceOptions {
        self.trace
    }

    /// The triangle's texture coordinates (in `[0, tiles]`), or `None` for
    /// a parallelogram.
    pub fn prism_uv(&self) -> Option<[Vec2; 3]> {
        self.prism_uv
    }

    /// What is added back to every hit's texture coordinate.
    pub fn uv_offset(&self) -> Vec2 {
        self.uv_offset
    }
}

/// A displaced triangle of a curved mesh: the shell along its vertex
/// normals ([`crate::curved_shell`]), traced through its texture space.
#[derive(Clone, Debug)]
pub struct CurvedDisplacement {
    shell: CurvedShell,
    map: Arc<DisplacementMap>,
    trace: TraceOptions,
    uv_offset: Vec2,
    shared: [bool; 3],
    /// Corners' texture coordinates in map units (`uv * aspect`).
    corners: [DVec2; 3],
    /// Inverse of the texture triangle's edge matrix: map `xy` to `b`.
    to_bary: [[f64; 2]; 2],
    /// Base colour texture (the scene's `color_texture`).
    pub color: Option<Arc<Texture>>,
    /// Tangent-space normal map standing in for the baked normals.
    pub normal_map: Option<Arc<Texture>>,
}

impl CurvedDisplacement {
    /// The face over `shell`, whose corners have texture coordinates
    /// `local_uv` (tiles, within `[0, trace.tiles]`); `uv_offset` is added
    /// back to every hit's coordinate and `shared` says which sides a
    /// neighbouring shell continues. `None` for degenerate texture
    /// coordinates.
    pub fn new(
        shell: CurvedShell,
        map: Arc<DisplacementMap>,
        trace: TraceOptions,
        local_uv: [Vec2; 3],
        uv_offset: Vec2,
        shared: [bool; 3],
    ) -> Option<Self> {
        let [ax, ay] = map.aspect();
        let aspect = DVec2::new(ax as f64, ay as f64);
        let corners = local_uv.map(|uv| uv.as_dvec2() * aspect);
        let (c1, c2) = (corners[1] - corners[0], corners[2] - corners[0]);
        let det = c1.x * c2.y - c2.x * c1.y;
        if !(det.abs() > 1e-300 && det.is_finite()) {
            return None;
        }
        let to_bary = [[c2.y / det, -c2.x / det], [-c1.y / det, c1.x / det]];
        Some(Self {
            shell,
            map,
            trace,
            uv_offset,
            shared,
            corners,
            to_bary,
            color: None,
            normal_map: None,
        })
    }

    /// The shell.
    pub fn shell(&self) -> &CurvedShell {
        &self.shell
    }

    /// The shared displacement map.
    pub fn map(&self) -> &Arc<DisplacementMap> {
        &self.map
    }

    /// The face's trace settings.
    pub fn trace_options(&self) -> TraceOptions {
        self.trace
    }

    /// What is added back to every hit's texture coordinate.
    pub fn uv_offset(&self) -> Vec2 {
        self.uv_offset
    }

    /// Which sides (edge `k`: corners `k`, `k + 1`) a neighbour shares.
    pub fn shared(&self) -> [bool; 3] {
        self.shared
    }

    /// The corners' texture coordinates in map units (`uv * aspect`, within
    /// the face's map window) and the inverse of their edge matrix (map
    /// `xy` to barycentric `b`).
    pub fn texture_frame(&self) -> ([DVec2; 3], [[f64; 2]; 2]) {
        (self.corners, self.to_bary)
    }
}

/// The geometry of a shape, over how a renderer holds its displaced faces:
/// the scene places [`FlatDisplacement`] and [`CurvedDisplacement`]
/// ([`Placed`]), and a renderer swaps in its own traceable faces with
/// [`Shape::map_faces`] (pbrt-v4 likewise builds each renderer's shapes from
/// one scene description), so the plain shapes are described once.
#[derive(Clone, Debug)]
pub enum Shape<D, C> {
    /// A plain parallelogram.
    Quad(Quad),
    /// A plain triangle; `attr` indexes its [`TriAttr`] ([`NO_ATTR`]: none).
    Triangle {
        /// The triangle.
        tri: Triangle,
        /// Index of its [`TriAttr`], or [`NO_ATTR`].
        attr: u32,
    },
    /// A sphere.
    Sphere(Sphere),
    /// A displaced quad or triangle: the prism over it, traced in map space.
    Displaced(Box<D>),
    /// A displaced triangle of a curved mesh: the shell along its vertex
    /// normals, traced through its texture space.
    Curved(Box<C>),
}

impl<D, C> Shape<D, C> {
    /// The same shape with its displaced faces made by `flat` and `curved`
    /// (the plain shapes as they are).
    pub fn map_faces<D2, C2>(
        self,
        flat: impl FnOnce(D) -> D2,
        curved: impl FnOnce(C) -> C2,
    ) -> Shape<D2, C2> {
        match self {
            Shape::Quad(q) => Shape::Quad(q),
            Shape::Triangle { tri, attr } => Shape::Triangle { tri, attr },
            Shape::Sphere(s) => Shape::Sphere(s),
            Shape::Displaced(f) => Shape::Displaced(Box::new(flat(*f))),
            Shape::Curved(c) => Shape::Curved(Box::new(curved(*c))),
        }
    }
}

/// The geometry the scene places.
pub type Placed = Shape<FlatDisplacement, CurvedDisplacement>;

/// One shape of the scene in the world, with its material: in file order
/// (a mesh counts its triangles; a visible area light adds its quad), the
/// order in which every renderer numbers them. `S` is the shape's geometry
/// as the holder keeps it ([`Placed`] in the scene).
#[derive(Clone, Debug)]
pub struct Primitive<S> {
    /// Its geometry.
    pub shape: S,
    /// Index into [`crate::World::materials`].
    pub material: u32,
    /// Index of the light this shape is the visible emitter of.
    pub emitter: Option<u32>,
    /// Index of the `[[shapes]]` entry of the scene file this shape was
    /// built from (`None` for a visible area light's quad).
    pub shape_index: Option<u32>,
}

impl<S> Primitive<S> {
    /// The same primitive with its geometry made by `f`.
    pub fn map_shape<T>(self, f: impl FnOnce(S) -> T) -> Primitive<T> {
        Primitive {
            shape: f(self.shape),
            material: self.material,
            emitter: self.emitter,
            shape_index: self.shape_index,
        }
    }
}

/// A shape of the scene as placed.
pub type PlacedShape = Primitive<Placed>;

/// A triangle without per-vertex attributes (flat normal, no texture
/// coordinates).
pub const NO_ATTR: u32 = u32::MAX;

/// Per-triangle attributes of meshes and textured triangles.
#[derive(Clone, Copy, Debug)]
pub struct TriAttr {
    /// Vertex normals for smooth shading, when the mesh has them.
    pub normals: Option<[Vec3; 3]>,
    /// Texture coordinates of the corners.
    pub uvs: [Vec2; 3],
}

/// A `mesh` or `triangle` of the scene file as placed in the world: the
/// scene's one description of it (pbrt-v4's `TriangleMesh` in its
/// `BasicScene`), from which the CPU made its primitives (`prims`) and from
/// which a rasteriser derives its own draws (the GPU path's shells follow
/// the vertex normals, which the CPU's per-triangle prisms do not keep).
/// World-space triangles, none of zero area, with their vertex normals as
/// the file gives them (unit, turned with the mesh; zero where the file's
/// is zero, `None` where it gives none: the flat normal is meant) and their
/// texture coordinates in tiles (a mesh's scaled by its displacement's
/// `tiles`).
#[derive(Clone, Debug)]
pub struct SceneMesh {
    /// World-space triangles, in the file's order.
    pub triangles: Vec<MeshTriangle>,
    /// Index into [`crate::World::materials`].
    pub material: u32,
    /// The displacement, for a displaced mesh.
    pub displacement: Option<MeshDisplacement>,
    /// The range of [`crate::World::shapes`] the CPU built of it.
    pub prims: std::ops::Range<usize>,
}

/// The displacement shared by every triangle of a [`SceneMesh`].
#[derive(Clone, Debug)]
pub struct MeshDisplacement {
    /// The baked maps (shared through the bake cache).
    pub map: Arc<DisplacementMap>,
    /// World units along the normal.
    pub depth: f32,
    /// The scene's method and iterations (`tiles` as the file gave them).
    pub trace: TraceOptions,
    /// The displacement has its own colour texture or normal map.
    pub textured: bool,
    /// Which triangles are curved, their shells' top level and each side's
    /// neighbour: the answer the CPU's primitives were built from, for any
    /// other renderer to draw the same shells.
    pub shells: MeshShells,
}
