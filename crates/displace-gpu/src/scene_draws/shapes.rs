//! The geometry the raster path derives from a scene's shapes: plain
//! primitives and undisplaced meshes as plain triangles, and a displaced
//! mesh's shell triangles with their vertex normals (`crate::mesh` builds
//! their MikkTSpace frames). Pure functions of the scene's description.

use crate::{MeshTriangle, PlainMaterial, PlainMesh, Result, ShellMesh};
use displace_core::Address;
use displace_scene::placed::{Placed, SceneMesh};
use glam::Vec3;

/// Appends a non-displaced primitive's triangles: a quad (a box is six)
/// as two, a sphere tessellated. Triangles are drawn from their scene mesh
/// ([`add_mesh`]), displaced faces by their own renderers.
pub(super) fn add_plain(plain: &mut PlainMesh, shape: &Placed, m: &PlainMaterial) {
    match shape {
        Placed::Quad(q) => plain.quad(q.origin, q.edge_u, q.edge_v, m),
        Placed::Sphere(s) => plain.sphere(s.center, s.radius, m),
        Placed::Triangle { .. } | Placed::Displaced(_) | Placed::Curved(_) => {}
    }
}

/// Appends an undisplaced mesh's (or lone triangle's) triangles, smooth
/// where the scene gives vertex normals.
pub(super) fn add_mesh(plain: &mut PlainMesh, mesh: &SceneMesh, m: &PlainMaterial) {
    for t in &mesh.triangles {
        let n = vertex_normals(t);
        plain.triangle(std::array::from_fn(|c| (t.positions[c], n[c], t.uvs[c])), m);
    }
}

/// The GPU shell of a displaced scene mesh, its texture addressed as its
/// bake is.
pub(super) fn shell_of(mesh: &SceneMesh, address: Address) -> Result<ShellMesh> {
    let tris: Vec<MeshTriangle> = mesh
        .triangles
        .iter()
        .map(|t| MeshTriangle {
            positions: t.positions,
            normals: vertex_normals(t),
            uvs: t.uvs,
        })
        .collect();
    ShellMesh::new(&tris, address)
}

/// World box of a mesh's corners.
pub(super) fn bounds(mesh: &SceneMesh) -> [Vec3; 2] {
    mesh.triangles
        .iter()
        .flat_map(|t| t.positions)
        .fold([Vec3::INFINITY, Vec3::NEG_INFINITY], |[lo, hi], p| {
            [lo.min(p), hi.max(p)]
        })
}

/// A triangle's vertex normals as a rasteriser needs them: the scene's
/// (unit, turned with the mesh), the flat normal where it gives none or a
/// zero one.
fn vertex_normals(t: &displace_scene::mesh::MeshTriangle) -> [Vec3; 3] {
    let flat = flat_normal(t.positions);
    t.normals.map_or([flat; 3], |n| {
        n.map(|v| if v == Vec3::ZERO { flat } else { v })
    })
}

/// Unit normal of the triangle `p` by its winding; zero for a degenerate
/// one (which covers no pixel; a shell refuses it).
fn flat_normal(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    /// The flat normal stands in where the scene gives no normals (a lone
    /// triangle, an OBJ without `vn`) and for a zero one among those given.
    #[test]
    fn missing_and_zero_normals_fall_back_to_the_flat_one() {
        let t = |normals| displace_scene::mesh::MeshTriangle {
            positions: [Vec3::ZERO, Vec3::X, Vec3::Y],
            normals,
            uvs: [Vec2::ZERO; 3],
        };
        assert_eq!(vertex_normals(&t(None)), [Vec3::Z; 3]);
        let given = [Vec3::X, Vec3::ZERO, Vec3::Y];
        assert_eq!(vertex_normals(&t(Some(given))), [Vec3::X, Vec3::Z, Vec3::Y]);
    }
}
