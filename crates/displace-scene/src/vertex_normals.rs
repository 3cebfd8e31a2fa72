//! Smooth vertex normals for mesh triangles that have none (an OBJ without
//! `vn`): at each corner, the area-weighted mean of the face normals of the
//! triangles that share the corner's position and meet this triangle at no
//! more than the crease angle, so a curved mesh shades and displaces
//! smoothly while its creases (a cube's edges, a blade's rim) stay sharp.
//! The displaced surface `P + depth h(uv) N` of a mesh is defined by these
//! normals, so without them every triangle would lift along its own face
//! normal and the surface would part at every edge.
//!
//! Area weighting (the unnormalised cross product summed) is what most
//! tools apply by default; the angle test against the corner's own face is
//! the auto-smooth rule of Blender and Maya.

use crate::mesh::MeshTriangle;
use glam::Vec3;
use std::collections::HashMap;

/// A mesh's crease angle when its scene does not give one, in degrees.
pub const DEFAULT_CREASE_DEGREES: f32 = 30.0;

/// A position as a key: its bits, with `-0.0` taken as `0.0` so the two
/// weld.
fn key(p: Vec3) -> [u32; 3] {
    p.to_array()
        .map(|c| if c == 0.0 { 0u32 } else { c.to_bits() })
}

/// Gives every triangle of `triangles` without normals (and with area)
/// smooth ones: corners at bit-identical positions are one vertex, and a
/// neighbour's face counts towards a corner where its normal is within
/// `crease_degrees` of this triangle's. Triangles with normals keep them
/// (and lend their faces to their neighbours' means); degenerate ones stay
/// without.
pub fn smooth_normals(triangles: &mut [MeshTriangle], crease_degrees: f32) {
    // A mesh that gives its normals (every built-in, most OBJs) needs no
    // welding: nothing is built for it.
    if triangles.iter().all(|t| t.normals.is_some()) {
        return;
    }
    let faces: Vec<Vec3> = triangles
        .iter()
        .map(|t| (t.positions[1] - t.positions[0]).cross(t.positions[2] - t.positions[0]))
        .collect();
    let units: Vec<Vec3> = faces.iter().map(|f| f.normalize_or_zero()).collect();
    let mut around: HashMap<[u32; 3], Vec<u32>> = HashMap::new();
    for (k, t) in triangles.iter().enumerate() {
        for (c, p) in t.positions.iter().enumerate() {
            // A corner repeated in a degenerate triangle counts it once.
            if t.positions[..c].contains(p) {
                continue;
            }
            around.entry(key(*p)).or_default().push(k as u32);
        }
    }
    let cos_crease = crease_degrees.to_radians().cos();
    for (k, t) in triangles.iter_mut().enumerate() {
        if t.normals.is_some() || units[k] == Vec3::ZERO {
            continue;
        }
        let corner = |p: Vec3| {
            let sum: Vec3 = around[&key(p)]
                .iter()
                .map(|&f| f as usize)
                .filter(|&f| units[f].dot(units[k]) >= cos_crease)
                .map(|f| faces[f])
                .sum();
            sum.try_normalize().unwrap_or(units[k])
        };
        t.normals = Some(t.positions.map(corner));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin_mesh;
    use glam::Vec2;

    fn without_normals(tris: &[MeshTriangle]) -> Vec<MeshTriangle> {
        tris.iter()
            .map(|t| MeshTriangle {
                normals: None,
                ..*t
            })
            .collect()
    }

    fn angle(a: Vec3, b: Vec3) -> f32 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// The built-in sphere's normals are radial: its triangles stripped of
    /// them get back normals within a fraction of its 7.5-degree faces.
    #[test]
    fn a_sphere_gets_its_radial_normals_back() {
        let sphere = builtin_mesh::generate("sphere").unwrap().triangles;
        let mut tris = without_normals(&sphere);
        smooth_normals(&mut tris, DEFAULT_CREASE_DEGREES);
        let mut worst = 0.0f32;
        for t in &tris {
            if units_zero(t) {
                assert!(t.normals.is_none());
                continue;
            }
            for (n, p) in t.normals.unwrap().iter().zip(&t.positions) {
                worst = worst.max(angle(*n, p.normalize()));
            }
        }
        // Away from the texture seam and the poles (where the built-in
        // repeats positions that differ in their last bits) the corners
        // weld; the worst is one face's own tilt, under 7.5 degrees.
        assert!(worst < 7.5, "{worst}");
        // Area weighting tilts a corner towards the larger of the faces
        // round it (the rings nearer the equator): a little off radial at
        // high latitudes, on the radial at the equator.
        let offs: Vec<f32> = tris
            .iter()
            .filter(|t| t.normals.is_some())
            .flat_map(|t| t.normals.unwrap().into_iter().zip(t.positions))
            .map(|(n, p)| angle(n, p.normalize()))
            .collect();
        let mean = offs.iter().sum::<f32>() / offs.len() as f32;
        eprintln!("mean {mean}, worst {worst}");
        assert!(mean < 1.0, "{mean}");
    }

    fn units_zero(t: &MeshTriangle) -> bool {
        (t.positions[1] - t.positions[0])
            .cross(t.positions[2] - t.positions[0])
            .length_squared()
            == 0.0
    }

    /// A cube's faces meet at 90 degrees: under the default crease angle
    /// every corner keeps its face's normal; past 90 degrees the corners
    /// average the three faces that meet there.
    #[test]
    fn creases_stay_sharp_below_their_angle() {
        let cube = builtin_mesh::generate("cube").unwrap().triangles;
        let mut sharp = without_normals(&cube);
        smooth_normals(&mut sharp, DEFAULT_CREASE_DEGREES);
        for t in &sharp {
            let face = (t.positions[1] - t.positions[0])
                .cross(t.positions[2] - t.positions[0])
                .normalize();
            for n in t.normals.unwrap() {
                assert!(angle(n, face) < 1e-3, "{n} against {face}");
            }
        }
        let mut round = without_normals(&cube);
        smooth_normals(&mut round, 91.0);
        for t in &round {
            for (n, p) in t.normals.unwrap().iter().zip(&t.positions) {
                // Each corner of the cube is (+-1, +-1, +-1): the mean of
                // the three faces' triangles there points into its octant,
                // away from every face.
                assert!((*n * p.signum()).min_element() > 0.3, "{n} at {p}");
            }
        }
    }

    /// Given normals are kept, degenerate triangles get none, and `-0.0`
    /// welds with `0.0`.
    #[test]
    fn given_normals_and_degenerate_triangles_are_left_alone() {
        let tri = |positions: [Vec3; 3], normals| MeshTriangle {
            positions,
            normals,
            uvs: [Vec2::ZERO; 3],
        };
        let z = Vec3::new(0.0, 0.0, 1.0);
        let mut tris = vec![
            tri([Vec3::ZERO, Vec3::X, Vec3::Y], None),
            tri(
                [
                    Vec3::new(-0.0, 0.0, 0.0),
                    Vec3::Y,
                    Vec3::new(-1.0, 0.0, 0.5),
                ],
                None,
            ),
            tri([Vec3::X, Vec3::X, Vec3::Y], None),
            tri(
                [Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
                Some([Vec3::X; 3]),
            ),
        ];
        smooth_normals(&mut tris, 60.0);
        assert_eq!(tris[3].normals, Some([Vec3::X; 3]));
        assert_eq!(tris[2].normals, None);
        // The origin corner of the first two is one vertex: both get the
        // same mean of their faces (about 24 degrees apart).
        let a = tris[0].normals.unwrap()[0];
        let b = tris[1].normals.unwrap()[0];
        assert_eq!(a, b);
        assert!(angle(a, z) > 1.0 && angle(a, z) < 24.0, "{a}");
        // Corner X of the first triangle is shared only with the fourth
        // (whose face is +z too) and the degenerate third.
        assert!(angle(tris[0].normals.unwrap()[1], z) < 1e-4);
    }
}
