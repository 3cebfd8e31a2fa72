//! How a displaced mesh's triangles become shells, for every renderer that
//! draws them (the CPU's primitives and the GPU's curved draw read the same
//! answer): which triangles are curved, the one top level their shells
//! share, and which triangle continues each side.
//!
//! A triangle is curved when its vertex normals are not all its face
//! normal; a planar one (a flat mesh, a cube's faces, a lone triangle)
//! keeps the flat prism of the ray-tracer paper (section 2.4), whose
//! walls are its face normal's. Normals 75 degrees or more apart within one
//! triangle cannot carry a shell without folding
//! ([`crate::curved_shell::min_normal_length`] under 0.5), nor can a
//! triangle whose normals converge faster than the shell is thick (the
//! concave side of a mesh displaced deeper than it is curved:
//! [`crate::curved_shell::shell_folds`]): such a triangle falls back to
//! the flat prism too.
//!
//! Two triangles continue one another across a side when they share its
//! two corners (positions and shell normals bit for bit, as a mesh's
//! shared vertices are transformed alike) and their texture coordinates
//! there differ alike: not at all on a clamped map, by the same whole
//! tiles on a repeating one (a closed mesh's texture seam). Anywhere else
//! (an open boundary, a crease, a seam that splits the heights) the side
//! is a wall.

use crate::curved_shell::{lambda_for_depth, min_normal_length, shell_folds};
use crate::mesh::MeshTriangle;
use crate::shapes::Triangle;
use displace_core::Address;
use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// The shells of one displaced mesh (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshShells {
    /// Per triangle: whether its shell follows its vertex normals.
    pub curved: Vec<bool>,
    /// Per triangle and side (side `k` joins corners `k` and `k + 1 mod
    /// 3`): the triangle that continues the surface across it.
    pub neighbours: Vec<[Option<u32>; 3]>,
    /// The level (along the unnormalised interpolated normal) every curved
    /// shell is topped at, so that neighbours share their sides; `None`
    /// when no triangle is curved.
    pub top: Option<f64>,
}

impl MeshShells {
    /// The shells of `triangles` displaced by `depth` over a map with
    /// `address`ing.
    pub fn of(triangles: &[MeshTriangle], depth: f32, address: Address) -> Self {
        let top_of = |curved: &[bool]| {
            let min_len = triangles
                .iter()
                .zip(curved)
                .filter(|(_, &c)| c)
                .filter_map(|(t, _)| curvature(t))
                .fold(f64::INFINITY, f64::min);
            min_len
                .is_finite()
                .then(|| lambda_for_depth(depth as f64, min_len))
        };
        let mut curved: Vec<bool> = triangles.iter().map(|t| curvature(t).is_some()).collect();
        // Triangles whose shells would fold at the mesh's top keep flat
        // prisms; the top of those left is no higher, so none of them folds.
        if let Some(top) = top_of(&curved) {
            for (c, t) in curved.iter_mut().zip(triangles) {
                if let (true, Some(n)) = (*c, t.normals) {
                    *c = !shell_folds(&t.positions, &n, top);
                }
            }
        }
        let top = top_of(&curved);
        type Corner = ([u32; 3], [u32; 3]);
        let corners: Vec<[Corner; 3]> = triangles
            .iter()
            .zip(&curved)
            .map(|(t, &c)| {
                let n = shell_normals(t, c);
                [0, 1, 2].map(|i| {
                    (
                        t.positions[i].to_array().map(f32::to_bits),
                        n[i].to_array().map(f32::to_bits),
                    )
                })
            })
            .collect();
        let mut sides: HashMap<(Corner, Corner), Vec<(usize, usize)>> = HashMap::new();
        for (m, c) in corners.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                let key = if a <= b { (a, b) } else { (b, a) };
                sides.entry(key).or_default().push((m, k));
            }
        }
        let mut neighbours = vec![[None; 3]; triangles.len()];
        for users in sides.values() {
            let &[(m1, k1), (m2, k2)] = users.as_slice() else {
                continue;
            };
            if continues(&triangles[m1], k1, &triangles[m2], k2, address) {
                neighbours[m1][k1] = Some(m2 as u32);
                neighbours[m2][k2] = Some(m1 as u32);
            }
        }
        Self {
            curved,
            neighbours,
            top,
        }
    }

    /// Which sides of triangle `m` a neighbour continues.
    pub fn shared(&self, m: usize) -> [bool; 3] {
        self.neighbours[m].map(|n| n.is_some())
    }
}

/// The normals a triangle's shell is extruded along: its vertex normals
/// when it is curved, else its face normal at every corner.
pub fn shell_normals(t: &MeshTriangle, curved: bool) -> [Vec3; 3] {
    match (curved, t.normals) {
        (true, Some(n)) => n,
        _ => [Triangle::new(t.positions[0], t.positions[1], t.positions[2]).normal(); 3],
    }
}

/// Whether triangle `a`'s side `ka` and `b`'s side `kb` (the same two
/// corners) carry the same heights: their texture coordinates at the two
/// corners, matched by position, differ alike.
fn continues(a: &MeshTriangle, ka: usize, b: &MeshTriangle, kb: usize, address: Address) -> bool {
    let (ia, ja) = (ka, (ka + 1) % 3);
    let (ib, jb) = if a.positions[ia] == b.positions[kb] {
        (kb, (kb + 1) % 3)
    } else {
        ((kb + 1) % 3, kb)
    };
    let (da, db) = (a.uvs[ia] - b.uvs[ib], a.uvs[ja] - b.uvs[jb]);
    let near = |v: Vec2| v.abs().max_element() <= 1e-6;
    match address {
        Address::Clamp => near(da) && near(db),
        Address::Repeat => near(da - db) && near(da - da.round()),
    }
}

/// The [`min_normal_length`] of a curved triangle (module docs); `None`
/// for a planar one or one whose normals cannot carry a shell.
fn curvature(t: &MeshTriangle) -> Option<f64> {
    let normals = t.normals?;
    let face = Triangle::new(t.positions[0], t.positions[1], t.positions[2]).normal();
    if normals.iter().all(|n| n.dot(face) >= 1.0 - 1e-6) {
        return None;
    }
    min_normal_length(&normals).filter(|&m| m >= 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_strip(bent: bool) -> Vec<MeshTriangle> {
        // Two triangles sharing the diagonal (1, 2) of a unit square.
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
        let n = |i: usize| {
            if bent {
                Vec3::new(p[i].x - 0.5, p[i].y - 0.5, 2.0).normalize()
            } else {
                Vec3::Z
            }
        };
        let uv = |i: usize| p[i].truncate();
        vec![
            MeshTriangle {
                positions: [p[0], p[1], p[2]],
                normals: Some([n(0), n(1), n(2)]),
                uvs: [uv(0), uv(1), uv(2)],
            },
            MeshTriangle {
                positions: [p[2], p[1], p[3]],
                normals: Some([n(2), n(1), n(3)]),
                uvs: [uv(2), uv(1), uv(3)],
            },
        ]
    }

    #[test]
    fn neighbours_share_the_diagonal_and_nothing_else() {
        let s = MeshShells::of(&quad_strip(true), 0.1, Address::Clamp);
        assert_eq!(s.curved, [true, true]);
        assert_eq!(s.neighbours[0], [None, Some(1), None]);
        assert_eq!(s.neighbours[1], [Some(0), None, None]);
        assert!(s.top.unwrap() > 0.1);
        let flat = MeshShells::of(&quad_strip(false), 0.1, Address::Clamp);
        assert_eq!(flat.curved, [false, false]);
        assert_eq!(flat.top, None);
    }

    #[test]
    fn texture_seams_split_sides_unless_whole_tiles_apart_on_a_repeating_map() {
        let mut t = quad_strip(true);
        t[1].uvs = t[1].uvs.map(|uv| uv + Vec2::new(1.0, 0.0));
        let repeat = MeshShells::of(&t, 0.1, Address::Repeat);
        assert_eq!(repeat.neighbours[0][1], Some(1));
        let clamp = MeshShells::of(&t, 0.1, Address::Clamp);
        assert_eq!(clamp.neighbours[0][1], None);
        t[1].uvs[0].x += 0.25;
        let split = MeshShells::of(&t, 0.1, Address::Repeat);
        assert_eq!(split.neighbours[0][1], None);
    }
}
