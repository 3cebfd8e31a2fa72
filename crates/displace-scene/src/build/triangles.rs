//! Triangles and meshes: a lone `triangle` and a `mesh` (OBJ or built-in)
//! are each placed in world space as a list of triangles, the scene's one
//! description of them ([`SceneMesh`]: what a rasteriser draws, pbrt-v4's
//! `TriangleMesh` of its `BasicScene`), and the CPU's primitives are made
//! from that list by one path ([`add`]): a flat triangle with its vertex
//! attributes, or the prism over it when displaced (the shell along its
//! vertex normals when they curve, [`crate::mesh_shells`]).
//!
//! A lone triangle is not read as a one-triangle mesh: its keys are checked
//! one by one (`vertices[i]`, `uvs`), a zero-area one is refused rather
//! than skipped, `tiles` does not scale its coordinates, and its bake is
//! made for that triangle's own proportions (a mesh's area-weighted mean,
//! `e * a / a`, can differ from them in the last bit, and with it the bake).

use super::super::spec::{DisplacementSpec, V3};
use super::ctx::{Ctx, MAX_COORDINATE};
use super::displacement::{displacement_of, triangle_frame, DispBuild};
use super::shapes::Geometry;
use crate::builtin_mesh;
use crate::error::Result;
use crate::mesh::MeshTriangle;
use crate::mesh_shells::MeshShells;
use crate::placed::{Placed, SceneMesh, TriAttr};
use crate::shapes::Triangle;
use glam::{Mat3, Vec2, Vec3};
use std::path::PathBuf;

/// World-space triangles, none of zero area, each with its index in the
/// shape (errors name it), and their displacement.
pub(super) struct PlacedMesh {
    triangles: Vec<(usize, MeshTriangle)>,
    displacement: Option<DispBuild>,
    /// What an error at triangle `k` of shape `what` calls it.
    name: fn(&str, usize) -> String,
}

/// How a mesh is placed: scaled, turned about the vertical, then moved.
pub(super) struct Placement {
    pub(super) translate: V3,
    pub(super) scale: f32,
    pub(super) rotate_y: f32,
}

/// A lone triangle: its corners, its texture coordinates (the barycentric
/// `(0, 0), (1, 0), (0, 1)` by default) and its displacement, checked.
pub(super) fn lone(
    cx: &mut Ctx,
    vertices: &[V3; 3],
    uvs: &Option<[[f32; 2]; 3]>,
    displacement: &Option<DisplacementSpec>,
    what: &str,
) -> Result<PlacedMesh> {
    let p: Vec<Vec3> = vertices
        .iter()
        .enumerate()
        .map(|(i, v)| cx.vec(*v, &format!("{what}.vertices[{i}]")))
        .collect::<Result<_>>()?;
    let tri = Triangle::new(p[0], p[1], p[2]);
    if tri.normal() == Vec3::ZERO {
        return Err(cx.err(format!("{what}: the triangle is degenerate (zero area)")));
    }
    let uv = match uvs {
        Some(u) => {
            if u.iter().flatten().any(|c| !c.is_finite()) {
                return Err(cx.err(format!("{what}.uvs: every component must be finite")));
            }
            u.map(Vec2::from_array)
        }
        None => [Vec2::ZERO, Vec2::X, Vec2::Y],
    };
    let displacement = match displacement_of(cx, displacement, what)? {
        None => None,
        Some(d) if d.flip_v => {
            return Err(cx.err(format!(
                "{what}.displacement.flip_v applies to quads only; give the triangle's uvs instead"
            )));
        }
        Some(d) => {
            let (map_extent, _) = triangle_frame(&tri, &uv)
                .ok_or_else(|| cx.err(format!("{what}.uvs: degenerate texture coordinates")))?;
            Some(DispBuild::new(cx, d, map_extent, what)?)
        }
    };
    Ok(PlacedMesh {
        triangles: vec![(
            0,
            MeshTriangle {
                positions: [p[0], p[1], p[2]],
                normals: None,
                uvs: uv,
            },
        )],
        displacement,
        name: |what, _| what.to_string(),
    })
}

/// A mesh file or built-in placed in the scene: its triangles in world
/// space (zero-area ones dropped), unit normals turned with it (smooth
/// ones under `crease_degrees` for a file without them), texture
/// coordinates scaled by the displacement's `tiles`, and the one bake every
/// triangle shares, made for the mesh's mean tile proportions.
pub(super) fn mesh(
    cx: &mut Ctx,
    path: &str,
    placement: Placement,
    crease_degrees: f32,
    displacement: &Option<DisplacementSpec>,
    what: &str,
) -> Result<PlacedMesh> {
    let Placement {
        translate,
        scale,
        rotate_y,
    } = placement;
    let t = cx.vec(translate, &format!("{what}.translate"))?;
    if !(scale > 0.0 && scale.is_finite() && rotate_y.is_finite()) {
        return Err(cx.err(format!(
            "{what}: scale must be positive and rotate_y finite"
        )));
    }
    if !(crease_degrees.is_finite() && (0.0..=180.0).contains(&crease_degrees)) {
        return Err(cx.err(format!(
            "{what}.crease_angle must be 0 to 180 degrees, got {crease_degrees}"
        )));
    }
    let (file, mut mesh) = match path.strip_prefix(builtin_mesh::PREFIX) {
        Some(name) => (
            PathBuf::from(path),
            builtin_mesh::generate(name).map_err(|e| cx.err(format!("{what}.path: {e}")))?,
        ),
        None => {
            let file = cx.base.join(path);
            // The OBJ's own error (its file, line and column) placed at the
            // scene's key too: a scene of many meshes says which shape.
            let mesh = crate::mesh::load(&file)
                .map_err(|e| cx.err(format!("{what}.path = {path:?}: {e}")))?;
            cx.source(file.clone());
            (file, mesh)
        }
    };
    crate::vertex_normals::smooth_normals(&mut mesh.triangles, crease_degrees);
    let rot = Mat3::from_rotation_y(rotate_y.to_radians());
    let xf = |p: Vec3| rot * (p * scale) + t;
    // Placed coordinates past the bound every scene coordinate keeps
    // (squared lengths must fit in single precision): the mesh's scale or
    // translation, not its file, is what to change.
    let reach = mesh
        .triangles
        .iter()
        .flat_map(|tri| tri.positions)
        .map(|p| xf(p).abs().max_element())
        .fold(
            0.0f32,
            |a, b| if b.is_nan() { f32::INFINITY } else { a.max(b) },
        );
    if reach > MAX_COORDINATE {
        return Err(cx.err(format!(
            "{what}: placed by scale {scale:e} and translate {t}, the mesh's coordinates reach {reach:e}: at most {MAX_COORDINATE:e} (squared lengths must fit in single precision)"
        )));
    }
    let mut builder = None;
    if let Some(d) = displacement_of(cx, displacement, what)? {
        if d.flip_v {
            return Err(cx.err(format!("{what}.displacement.flip_v applies to quads only")));
        }
        if !mesh.has_uvs {
            return Err(cx.err(format!(
                "{what}.path = {path:?}: {}: a displaced mesh needs texture coordinates (vt)",
                file.display()
            )));
        }
        // `tiles` repeats the map over the mesh's coordinates.
        let tiles = Vec2::from_array(d.tiles);
        for t in &mut mesh.triangles {
            t.uvs = t.uvs.map(|uv| uv * tiles);
        }
        let extent = mesh_extent(&mesh.triangles, &xf).ok_or_else(|| {
            cx.err(format!(
                "{what}: the mesh's texture coordinates are degenerate, or its triangles too large or too small to measure in single precision (scale it nearer to 1)"
            ))
        })?;
        builder = Some(DispBuild::new(cx, d, extent, what)?);
    }
    let triangles = mesh
        .triangles
        .iter()
        .enumerate()
        .filter_map(|(k, tri)| {
            let positions = tri.positions.map(xf);
            let area = Triangle::new(positions[0], positions[1], positions[2]);
            (area.normal() != Vec3::ZERO).then(|| {
                let normals = tri
                    .normals
                    .map(|n| n.map(|v| (rot * v).normalize_or_zero()));
                (
                    k,
                    MeshTriangle {
                        positions,
                        normals,
                        uvs: tri.uvs,
                    },
                )
            })
        })
        .collect::<Vec<_>>();
    if triangles.is_empty() {
        // Every face was a point or a line (two indices, repeated or
        // collinear vertices, coordinates that overflow when placed): a
        // mesh that would render as nothing, silently.
        return Err(cx.err(format!(
            "{what}.path = {path:?}: {}: none of its {} faces has an area once placed (repeated or collinear vertices?): nothing to render",
            file.display(),
            mesh.triangles.len()
        )));
    }
    Ok(PlacedMesh {
        triangles,
        displacement: builder,
        name: |what, k| format!("{what} triangle {k}"),
    })
}

/// Adds the CPU's primitives of `placed` (shape `index` of the file, named
/// `what`) and its [`SceneMesh`]: each triangle flat with its normals and
/// texture coordinates, or the prism over it in its texture frame.
pub(super) fn add(
    cx: &Ctx,
    placed: PlacedMesh,
    what: &str,
    material: u32,
    index: u32,
    geo: &mut Geometry,
) -> Result<()> {
    let first = geo.prims.len();
    let triangles: Vec<MeshTriangle> = placed.triangles.iter().map(|(_, t)| *t).collect();
    let shells = placed
        .displacement
        .as_ref()
        .map(|b| MeshShells::of(&triangles, b.depth, b.address));
    for (m, (k, t)) in placed.triangles.iter().enumerate() {
        let [p0, p1, p2] = t.positions;
        let tri = Triangle::new(p0, p1, p2);
        let name = || (placed.name)(what, *k);
        let shape = match (&placed.displacement, &shells) {
            (Some(b), Some(c)) => match c.top {
                Some(top) if c.curved[m] => {
                    let face = b.curved_triangle(cx, t, top, c.shared(m), &name())?;
                    Placed::Curved(Box::new(face))
                }
                _ => Placed::Displaced(Box::new(b.triangle(cx, &tri, &t.uvs, &name())?)),
            },
            _ => {
                geo.attrs.push(TriAttr {
                    normals: t.normals,
                    uvs: t.uvs,
                });
                Placed::Triangle {
                    tri,
                    attr: geo.attrs.len() as u32 - 1,
                }
            }
        };
        geo.push(shape, material, None, Some(index));
    }
    geo.meshes.push(SceneMesh {
        triangles,
        material,
        displacement: placed
            .displacement
            .as_ref()
            .zip(shells)
            .map(|(b, s)| b.shared(s)),
        prims: first..geo.prims.len(),
    });
    Ok(())
}

/// Area-weighted mean tile size of a mesh: the proportions its one shared
/// bake is made for.
fn mesh_extent(tris: &[MeshTriangle], xf: &dyn Fn(Vec3) -> Vec3) -> Option<Vec2> {
    let mut sum = Vec2::ZERO;
    let mut weight = 0.0;
    for t in tris {
        let tr = Triangle::new(xf(t.positions[0]), xf(t.positions[1]), xf(t.positions[2]));
        if let Some((e, _)) = triangle_frame(&tr, &t.uvs) {
            let a = tr.e1.cross(tr.e2).length();
            sum += e * a;
            weight += a;
        }
    }
    // Coordinates near the limit overflow the areas' products (1e17 squared
    // twice): no extent rather than an infinite or NaN one.
    let extent = sum / weight;
    (weight > 0.0 && weight.is_finite() && extent.is_finite()).then_some(extent)
}
