//! Meshes for the raster path: world-space triangles turned into the
//! vertices of their displacement shell, with per-vertex tangent frames by
//! MikkTSpace (`bevy_mikktspace`, the reference algorithm in safe Rust).
//!
//! **The shell of a curved mesh.** Donnelly's technique (GPU Gems 2 ch. 8,
//! section 8.4) draws each polygon and treats the surface under every
//! fragment as locally flat: the ray starts at the fragment's texture
//! coordinate on the top of the shell and is marched through the distance
//! map along the eye vector carried into tangent space by the interpolated
//! frame (listing 8-1). This module draws each triangle as the top of its
//! shell, lifted by the displacement depth along the vertex normals (so a
//! smooth mesh's tops meet without cracks), and as side walls from base to
//! top the edges where the tops part: the mesh's open boundary, and creases
//! (an edge whose two triangles give its ends different normals, as a
//! cube's). Rays enter the shell through them as they do through a
//! displaced quad's box, and one entering under the surface hits the wall. A ray that leaves the map
//! window ([`ShellMesh::tiles`]) sideways or the shell through its bottom is
//! discarded.
//!
//! Scenes draw only meshes whose triangles are all planar this way
//! ([`crate::scene_draws`]): there the frame is exact and this is the CPU's
//! prism. A mesh with curved triangles is drawn through the CPU's own
//! shells along the vertex normals ([`crate::curved`]), since here one
//! fragment's ray stays in the frame it started in (the frame drifts where
//! the surface curves within the ray's walk) and the lateral scale is the
//! MikkTSpace magnitudes `|dP/du|`, `|dP/dv|` of the vertex rather than of
//! the triangle. On an open mesh that covers only part of its map window
//! (a lone triangle), a ray leaving through a boundary wall may find
//! surface beyond the edge, which the CPU's prism would not.

use crate::{Error, Result};
use bevy_mikktspace::{Geometry, TangentSpace};
use bytemuck::{Pod, Zeroable};
use displace_core::Address;
use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// One triangle of a mesh as the raster path takes it: world positions,
/// unit vertex normals and texture coordinates in tiles of the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshTriangle {
    /// World positions of the corners.
    pub positions: [Vec3; 3],
    /// Unit vertex normals: the shell is extruded along them.
    pub normals: [Vec3; 3],
    /// Texture coordinates, in tiles of the map.
    pub uvs: [Vec2; 3],
}

/// A vertex of the shell. Mirror of WGSL `ShellVertex` (mesh.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ShellVertex {
    /// On the undisplaced surface.
    pub position: [f32; 3],
    /// Height in the shell, 0 (base) to 1 (top): the vertex sits at
    /// `position + lift * depth * normal`.
    pub lift: f32,
    /// Unit vertex normal, the direction the shell is extruded in.
    pub normal: [f32; 3],
    /// Pads `normal` to WGSL's `vec3f` alignment.
    pub _pad: f32,
    /// MikkTSpace's unit tangent and bitangent sign:
    /// `bitangent = w * normal x tangent`.
    pub tangent: [f32; 4],
    /// Texture coordinate in tiles, already shifted into the map window.
    pub uv: [f32; 2],
    /// `|dP/du|`, `|dP/dv|` (world units per tile; MikkTSpace's
    /// magnitudes).
    pub scale: [f32; 2],
}

/// The tangent frame MikkTSpace gives one corner of a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentFrame {
    /// Unit tangent along `dP/du`.
    pub tangent: Vec3,
    /// +1 where `normal x tangent` is the bitangent, -1 where the texture is
    /// mirrored.
    pub sign: f32,
    /// `|dP/du|`, `|dP/dv|`: world units per tile, which set the map-space
    /// metric of this corner.
    pub scale: Vec2,
}

struct MikkInput<'a> {
    tris: &'a [MeshTriangle],
    out: Vec<[Option<TangentSpace>; 3]>,
}

impl Geometry for MikkInput<'_> {
    fn num_faces(&self) -> usize {
        self.tris.len()
    }
    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }
    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.tris[face].positions[vert].to_array()
    }
    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.tris[face].normals[vert].to_array()
    }
    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        self.tris[face].uvs[vert].to_array()
    }
    fn set_tangent(&mut self, space: Option<TangentSpace>, face: usize, vert: usize) {
        self.out[face][vert] = space;
    }
}

/// MikkTSpace tangent frames of every corner of `tris`. A corner the
/// algorithm leaves without a frame (a degenerate triangle with no
/// neighbour to borrow from) is an error naming the triangle.
pub fn tangent_frames(tris: &[MeshTriangle]) -> Result<Vec<[TangentFrame; 3]>> {
    let mut input = MikkInput {
        tris,
        out: vec![[None; 3]; tris.len()],
    };
    bevy_mikktspace::generate_tangents(&mut input)
        .map_err(|e| Error::InvalidOption(format!("MikkTSpace: {e}")))?;
    input
        .out
        .iter()
        .enumerate()
        .map(|(face, corners)| {
            let mut frames = [TangentFrame {
                tangent: Vec3::X,
                sign: 1.0,
                scale: Vec2::ONE,
            }; 3];
            for (f, c) in frames.iter_mut().zip(corners) {
                let s = c.ok_or_else(|| {
                    Error::InvalidOption(format!(
                        "mesh triangle {face} has no tangent frame (degenerate positions or texture coordinates)"
                    ))
                })?;
                let [x, y, z, w] = s.tangent_encoded();
                *f = TangentFrame {
                    tangent: Vec3::new(x, y, z),
                    sign: w,
                    scale: Vec2::new(s.tangent_magnitude(), s.bi_tangent_magnitude()),
                };
            }
            Ok(frames)
        })
        .collect()
}

/// The vertices of a mesh's shell ready to draw, and the window of map
/// tiles its rays are traced in.
#[derive(Clone, Debug, PartialEq)]
pub struct ShellMesh {
    /// Triangle list: the base triangle, its top and the walls.
    pub vertices: Vec<ShellVertex>,
    /// Subtracted from the mesh's texture coordinates to put them in the
    /// window; added back to report a hit's coordinate.
    pub uv_shift: Vec2,
    /// The window's size in tiles: `[1, 1]` for a clamped map, the tiles the
    /// coordinates touch for a repeating one, plus one tile all round when
    /// the mesh is closed (so rays cross its texture seams).
    pub tiles: [f32; 2],
    /// Triangle edges drawn as walls (boundary and crease edges).
    pub walls: usize,
}

impl ShellMesh {
    /// Builds the shell of `tris` (tangent frames from MikkTSpace, walls on
    /// boundary and crease edges), refusing empty meshes and non-finite or
    /// degenerate triangles.
    pub fn new(tris: &[MeshTriangle], address: Address) -> Result<Self> {
        if tris.is_empty() {
            return Err(Error::InvalidOption("the mesh has no triangles".into()));
        }
        for (k, t) in tris.iter().enumerate() {
            let finite = t.positions.iter().all(|p| p.is_finite())
                && t.normals.iter().all(|n| n.is_finite() && n.length() > 0.5)
                && t.uvs.iter().all(|u| u.is_finite());
            if !finite {
                return Err(Error::InvalidOption(format!(
                    "mesh triangle {k}: positions and texture coordinates must be finite and normals unit length"
                )));
            }
        }
        // The shell grows along the winding's normal, as the CPU's prisms
        // do: a vertex normal pointing the other way is turned round.
        let oriented: Vec<MeshTriangle> = tris
            .iter()
            .map(|t| {
                let face = (t.positions[1] - t.positions[0]).cross(t.positions[2] - t.positions[0]);
                MeshTriangle {
                    normals: t.normals.map(|n| if n.dot(face) < 0.0 { -n } else { n }),
                    ..*t
                }
            })
            .collect();
        let tris = &oriented[..];
        let frames = tangent_frames(tris)?;
        let closed = open_edges(tris, false).is_empty();
        let walls = open_edges(tris, true);
        let lo = tris
            .iter()
            .flat_map(|t| t.uvs)
            .fold(Vec2::splat(f32::INFINITY), Vec2::min);
        let hi = tris
            .iter()
            .flat_map(|t| t.uvs)
            .fold(Vec2::splat(f32::NEG_INFINITY), Vec2::max);
        let (uv_shift, tiles) = match address {
            Address::Clamp => {
                if lo.min_element() < -1e-6 || hi.max_element() > 1.0 + 1e-6 {
                    return Err(Error::InvalidOption(format!(
                        "mesh texture coordinates span {lo}..{hi}, outside [0, 1], but the map clamps; bake it with repeat addressing"
                    )));
                }
                (Vec2::ZERO, Vec2::ONE)
            }
            Address::Repeat => {
                let margin = if closed { 1.0 } else { 0.0 };
                let start = lo.floor() - Vec2::splat(margin);
                let end = hi.ceil().max(lo.floor() + Vec2::ONE) + Vec2::splat(margin);
                (start, end - start)
            }
        };
        let vertex = |t: &MeshTriangle, f: &TangentFrame, k: usize, lift: f32| ShellVertex {
            position: t.positions[k].to_array(),
            lift,
            normal: t.normals[k].to_array(),
            _pad: 0.0,
            tangent: f.tangent.extend(f.sign).to_array(),
            uv: (t.uvs[k] - uv_shift).to_array(),
            scale: f.scale.to_array(),
        };
        let mut vertices = Vec::with_capacity(3 * tris.len() + 6 * walls.len());
        for (t, f) in tris.iter().zip(&frames) {
            for (k, corner) in f.iter().enumerate() {
                vertices.push(vertex(t, corner, k, 1.0));
            }
        }
        for &(tri, k) in &walls {
            // Edge a -> b runs counter-clockwise round the top, so the quad
            // a0 b0 b1 a1 faces out of the mesh.
            let (t, f) = (&tris[tri], &frames[tri]);
            let (a, b) = (k, (k + 1) % 3);
            let [a0, b0, b1, a1] = [
                vertex(t, &f[a], a, 0.0),
                vertex(t, &f[b], b, 0.0),
                vertex(t, &f[b], b, 1.0),
                vertex(t, &f[a], a, 1.0),
            ];
            vertices.extend([a0, b0, b1, a0, b1, a1]);
        }
        Ok(Self {
            vertices,
            uv_shift,
            tiles: tiles.to_array(),
            walls: walls.len(),
        })
    }
}

/// `(triangle, k)` for every edge from corner `k` to `k + 1` that no other
/// triangle shares, corners matched by position (texture seams do not open
/// a mesh), and with `normals` also by normal (so a crease is open too).
/// Positions match within about 1e-6 of the mesh's size and normals within
/// about 1e-4, so corners computed twice (a seam's `cos 0` and `cos 2 pi`)
/// still meet.
fn open_edges(tris: &[MeshTriangle], normals: bool) -> Vec<(usize, usize)> {
    type Corner = [i64; 6];
    let size = tris
        .iter()
        .flat_map(|t| t.positions)
        .fold(0.0f32, |m, p| m.max(p.abs().max_element()))
        .max(f32::MIN_POSITIVE);
    let key = |t: &MeshTriangle, k: usize| -> Corner {
        let n = if normals { t.normals[k] } else { Vec3::ZERO };
        let p = (t.positions[k] / size * 1e6).round();
        let n = (n * 1e4).round();
        [p.x, p.y, p.z, n.x, n.y, n.z].map(|c| c as i64)
    };
    let mut count: HashMap<(Corner, Corner), u32> = HashMap::new();
    let edge = |t: &MeshTriangle, k: usize| {
        let (a, b) = (key(t, k), key(t, (k + 1) % 3));
        if a <= b {
            (a, b)
        } else {
            (b, a)
        }
    };
    for t in tris {
        for k in 0..3 {
            *count.entry(edge(t, k)).or_default() += 1;
        }
    }
    let mut out = Vec::new();
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            if count[&edge(t, k)] == 1 {
                out.push((i, k));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Vec<MeshTriangle> {
        let p = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let uv = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        [[0, 1, 2], [0, 2, 3]]
            .into_iter()
            .map(|i| MeshTriangle {
                positions: i.map(|k| p[k]),
                normals: [Vec3::Z; 3],
                uvs: i.map(|k| uv[k]),
            })
            .collect()
    }

    #[test]
    fn a_flat_square_gets_its_exact_frame_and_four_walls() {
        let m = ShellMesh::new(&square(), Address::Clamp).unwrap();
        assert_eq!(m.walls, 4);
        assert_eq!(m.vertices.len(), 6 + 4 * 6);
        for v in &m.vertices {
            assert!((Vec3::from_slice(&v.tangent[..3]) - Vec3::X).length() < 1e-6);
            assert_eq!(v.tangent[3], 1.0);
            assert!((v.scale[0] - 2.0).abs() < 1e-5 && (v.scale[1] - 1.0).abs() < 1e-5);
        }
        // Every wall faces out of the square.
        for w in m.vertices[6..].chunks_exact(3) {
            let p: Vec<Vec3> = w
                .iter()
                .map(|v| Vec3::from_array(v.position) + v.lift * Vec3::Z)
                .collect();
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let centre = (p[0] + p[1] + p[2]) / 3.0 - Vec3::new(1.0, 0.5, 0.0);
            assert!(n.dot(centre) > 0.0, "{p:?}");
        }
    }

    #[test]
    fn bad_meshes_are_refused() {
        assert!(ShellMesh::new(&[], Address::Clamp).is_err());
        let mut t = square();
        t[0].uvs[1] = Vec2::new(1.5, 0.0);
        let e = ShellMesh::new(&t, Address::Clamp).unwrap_err().to_string();
        assert!(e.contains("repeat"), "{e}");
        let r = ShellMesh::new(&t, Address::Repeat).unwrap();
        assert_eq!(r.tiles, [2.0, 1.0]);
        // Normals against the winding are turned to follow it.
        let mut flipped = square();
        flipped[0].normals = [Vec3::NEG_Z; 3];
        let f = ShellMesh::new(&flipped, Address::Clamp).unwrap();
        assert!(f.vertices.iter().all(|v| v.normal == [0.0, 0.0, 1.0]));
        t[1].positions[0] = Vec3::NAN;
        assert!(ShellMesh::new(&t, Address::Repeat).is_err());
    }
}
