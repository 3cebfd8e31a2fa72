//! Curved meshes for raster hosts: the shells of the CPU renderer
//! (`displace_scene::mesh_shells`, the triangles' extrusions along their
//! vertex normals) as a storage buffer of prisms with their neighbours,
//! and the outer boundary of those shells as triangles to rasterise; the
//! fragment stage walks the prisms (`displace::curved_walk`). displace-gpu
//! and displace-bevy both build their draws from [`CurvedShells`], so the
//! engine and `displace gpu-render` trace the very shells the CPU traces.
//!
//! Which triangles are curved, the top level and the neighbours come from
//! [`MeshShells`], the one answer the CPU's primitives are built from.

use bytemuck::{Pod, Zeroable};
use displace_core::Address;
use displace_scene::mesh::MeshTriangle;
use displace_scene::mesh_shells::{shell_normals, MeshShells};
use glam::{Vec2, Vec3};

/// Why a mesh's shells could not be laid out for the GPU.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShellsError {
    /// The shells were computed for another mesh.
    #[error("the shells describe {shells} triangles, the mesh has {triangles}")]
    Mismatch {
        /// Triangles the shells describe.
        shells: usize,
        /// Triangles of the mesh.
        triangles: usize,
    },
    /// Neighbours are stored as `i32`.
    #[error("{0} mesh triangles are more than a prism buffer indexes (2^31 - 1)")]
    TooMany(usize),
}

/// One shell. Mirror of WGSL `Prism` (`displace::curved_prism`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuPrism {
    /// Corners; `p[0][3]` is the top level, `p[1][3]` the depth.
    pub p: [[f32; 4]; 3],
    /// Unit shell normals (`w` unused).
    pub n: [[f32; 4]; 3],
    /// Texture corners 0 and 1 in map units within the map window.
    pub m01: [f32; 4],
    /// Texture corner 2 (`zw` unused).
    pub m2: [f32; 4],
    /// The prism across side `k` (corners `k`, `k + 1`), -1 for a wall.
    pub adj: [i32; 4],
}

/// A vertex of the shells' outer boundary (displace-gpu's vertex buffer;
/// displace-bevy puts the prism in the mesh's texture coordinate).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct CurvedVertex {
    /// World position.
    pub position: [f32; 3],
    /// The prism the face belongs to.
    pub prism: u32,
}

/// A curved mesh ready to upload.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvedShells {
    /// One per triangle, in the mesh's order.
    pub prisms: Vec<GpuPrism>,
    /// The outer boundary: every top and base, and the sides no neighbour
    /// shares, wound counter-clockwise seen from outside.
    pub vertices: Vec<CurvedVertex>,
    /// Subtracted from the texture coordinates to put them in the map
    /// window (added back to the UV output).
    pub uv_shift: Vec2,
    /// Tiles the map window spans.
    pub tiles: [f32; 2],
    /// World box of the shells.
    pub bounds: [Vec3; 2],
}

impl CurvedShells {
    /// The `shells` of `triangles` (world space, texture coordinates in
    /// tiles; the scene's [`MeshShells`] of them) displaced by `depth` over
    /// a map of tile proportions `aspect` and `address`ing; `None` when no
    /// triangle is curved.
    pub fn new(
        triangles: &[MeshTriangle],
        shells: &MeshShells,
        depth: f32,
        aspect: [f32; 2],
        address: Address,
    ) -> Result<Option<Self>, ShellsError> {
        let Some(top) = shells.top else {
            return Ok(None);
        };
        if shells.curved.len() != triangles.len() {
            return Err(ShellsError::Mismatch {
                shells: shells.curved.len(),
                triangles: triangles.len(),
            });
        }
        if triangles.len() > i32::MAX as usize {
            return Err(ShellsError::TooMany(triangles.len()));
        }
        let (uv_shift, tiles) = window(triangles, address);
        let aspect = Vec2::from_array(aspect);
        let top32 = top as f32;
        let mut prisms = Vec::with_capacity(triangles.len());
        let mut vertices = Vec::new();
        let mut bounds = [Vec3::INFINITY, Vec3::NEG_INFINITY];
        for (m, t) in triangles.iter().enumerate() {
            let n = shell_normals(t, shells.curved[m]);
            let p = t.positions;
            let m_uv = t.uvs.map(|uv| (uv - uv_shift) * aspect);
            let adj = shells.neighbours[m].map(|a| a.map_or(-1, |a| a as i32));
            prisms.push(GpuPrism {
                p: [
                    p[0].extend(top32).to_array(),
                    p[1].extend(depth).to_array(),
                    p[2].extend(0.0).to_array(),
                ],
                n: n.map(|v| v.extend(0.0).to_array()),
                m01: [m_uv[0].x, m_uv[0].y, m_uv[1].x, m_uv[1].y],
                m2: [m_uv[2].x, m_uv[2].y, 0.0, 0.0],
                adj: [adj[0], adj[1], adj[2], -1],
            });
            let lid = [0, 1, 2].map(|i| p[i] + top32 * n[i]);
            for q in p.iter().chain(&lid) {
                bounds = [bounds[0].min(*q), bounds[1].max(*q)];
            }
            let up = n[0] + n[1] + n[2];
            let centre = (p[0] + p[1] + p[2]) / 3.0;
            let prism = m as u32;
            let mut face = |corners: &[Vec3], outward: Vec3| {
                let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
                let flip = normal.dot(outward) < 0.0;
                for k in 1..corners.len() - 1 {
                    let tri = if flip {
                        [corners[0], corners[k + 1], corners[k]]
                    } else {
                        [corners[0], corners[k], corners[k + 1]]
                    };
                    vertices.extend(tri.map(|v| CurvedVertex {
                        position: v.to_array(),
                        prism,
                    }));
                }
            };
            face(&lid, up);
            face(&p, -up);
            for k in 0..3 {
                if shells.neighbours[m][k].is_none() {
                    let j = (k + 1) % 3;
                    let out = 0.5 * (p[k] + p[j]) - centre;
                    face(&[p[k], p[j], lid[j], lid[k]], out);
                }
            }
        }
        Ok(Some(Self {
            prisms,
            vertices,
            uv_shift,
            tiles,
            bounds,
        }))
    }
}

/// The map window of a mesh: one tile for a clamped map; the whole tiles
/// its coordinates touch for a repeating one.
fn window(triangles: &[MeshTriangle], address: Address) -> (Vec2, [f32; 2]) {
    match address {
        Address::Clamp => (Vec2::ZERO, [1.0, 1.0]),
        Address::Repeat => {
            let (lo, hi) = triangles
                .iter()
                .flat_map(|t| t.uvs)
                .fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(lo, hi), uv| {
                    (lo.min(uv), hi.max(uv))
                });
            let shift = lo.floor();
            let tiles = (hi - shift).ceil().max(Vec2::ONE);
            (shift, [tiles.x, tiles.y])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prism_layout_matches_the_wgsl_struct() {
        // Nine vec4 of 16 bytes: the std430 array stride of `Prism`.
        assert_eq!(std::mem::size_of::<GpuPrism>(), 144);
        assert_eq!(std::mem::size_of::<CurvedVertex>(), 16);
    }

    #[test]
    fn a_closed_curved_mesh_draws_tops_and_bases_only() {
        let mesh = displace_scene::builtin_mesh::generate("torus").unwrap();
        let tris: Vec<MeshTriangle> = mesh.triangles;
        let shells = MeshShells::of(&tris, 0.1, Address::Repeat);
        let s = CurvedShells::new(&tris, &shells, 0.1, [10.0, 10.0], Address::Repeat)
            .unwrap()
            .expect("the torus is curved");
        assert_eq!(s.prisms.len(), tris.len());
        // Every side is shared on a closed mesh whose texture seams are
        // whole tiles apart, so only tops and bases are drawn.
        assert_eq!(s.vertices.len(), tris.len() * 6);
        // Tops face away from the tube's centre line (the unit circle in
        // the xz plane), bases towards it.
        for (k, tri) in s.vertices.chunks(3).enumerate() {
            let p: Vec<Vec3> = tri.iter().map(|v| Vec3::from_array(v.position)).collect();
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let c = (p[0] + p[1] + p[2]) / 3.0;
            let axis = Vec3::new(c.x, 0.0, c.z).normalize();
            let out = n.dot(c - axis);
            assert!(if k % 2 == 0 { out > 0.0 } else { out < 0.0 }, "{k}");
        }
    }
}
