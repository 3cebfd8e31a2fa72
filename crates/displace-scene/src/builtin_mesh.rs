//! Built-in meshes for scenes and the GPU mesh path (plane, cube, sphere
//! and torus, so a curved shell can be tested without an OBJ file), named `builtin:NAME` where a scene gives an
//! OBJ path. Each is generated with texture coordinates in `[0, 1]` and
//! analytic vertex normals, wound counter-clockwise seen from outside, and
//! parameterised so that `dP/du x dP/dv` points outwards: the tangent frame
//! is right-handed wherever the surface is regular, as a displaced face
//! needs (the shell grows along the normal).
//!
//! Sizes are unit: the plane and the cube span `[-1, 1]` on each axis, the
//! sphere has radius 1, the torus major radius 1 and minor radius
//! [`TORUS_MINOR`]; a scene's `scale`, `rotate_y` and `translate` place them.

use crate::error::{Error, Result};
use crate::mesh::{Mesh, MeshTriangle};
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// The prefix that names a built-in mesh in a scene's `path`.
pub const PREFIX: &str = "builtin:";
/// Every built-in mesh, as named after [`PREFIX`].
pub const NAMES: [&str; 4] = ["plane", "cube", "sphere", "torus"];
/// The torus tube's radius (its ring has radius 1).
pub const TORUS_MINOR: f32 = 0.4;
const SPHERE_SEGMENTS: [usize; 2] = [48, 24];
const TORUS_SEGMENTS: [usize; 2] = [64, 24];

/// The mesh named `builtin:NAME` (`spec` without the prefix), or an error
/// naming the known ones.
pub fn generate(name: &str) -> Result<Mesh> {
    let triangles = match name {
        "plane" => plane(),
        "cube" => cube(),
        "sphere" => grid(SPHERE_SEGMENTS, [true, false], sphere_point),
        "torus" => grid(TORUS_SEGMENTS, [true, true], torus_point),
        other => {
            return Err(Error::Mesh {
                path: format!("{PREFIX}{other}").into(),
                message: format!(
                    "unknown built-in mesh (expected one of {})",
                    NAMES.map(|n| format!("{PREFIX}{n}")).join(", ")
                ),
            })
        }
    };
    Ok(Mesh {
        triangles,
        has_uvs: true,
    })
}

/// A flat quad `corner + u du + v dv` split into two triangles, normal
/// `du x dv`.
fn quad(corner: Vec3, du: Vec3, dv: Vec3) -> [MeshTriangle; 2] {
    let n = du.cross(dv).normalize();
    let at = |u: f32, v: f32| (corner + u * du + v * dv, Vec2::new(u, v));
    let tri = |a: (Vec3, Vec2), b: (Vec3, Vec2), c: (Vec3, Vec2)| MeshTriangle {
        positions: [a.0, b.0, c.0],
        normals: Some([n; 3]),
        uvs: [a.1, b.1, c.1],
    };
    let (p00, p10, p11, p01) = (at(0.0, 0.0), at(1.0, 0.0), at(1.0, 1.0), at(0.0, 1.0));
    [tri(p00, p10, p11), tri(p00, p11, p01)]
}

/// The `y = 0` plane, normal +y: `u` along +x, `v` along -z.
fn plane() -> Vec<MeshTriangle> {
    quad(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -2.0),
    )
    .to_vec()
}

/// Six faces, each its own `[0, 1]` texture square with `du x dv` outwards.
fn cube() -> Vec<MeshTriangle> {
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    let mut out = Vec::with_capacity(12);
    for (k, &n) in axes.iter().enumerate() {
        for n in [n, -n] {
            // Two axes spanning the face, ordered so that du x dv = n.
            let a = axes[(k + 1) % 3];
            let b = axes[(k + 2) % 3];
            let (du, dv) = if a.cross(b).dot(n) > 0.0 {
                (a, b)
            } else {
                (b, a)
            };
            out.extend(quad(n - du - dv, 2.0 * du, 2.0 * dv));
        }
    }
    out
}

/// Unit sphere: `u` = longitude / 2 pi, `v` = colatitude / pi (v = 0 at +y).
fn sphere_point(u: f32, v: f32) -> (Vec3, Vec3) {
    let (phi, theta) = (u * TAU, v * PI);
    let p = Vec3::new(
        theta.sin() * phi.cos(),
        theta.cos(),
        theta.sin() * phi.sin(),
    );
    (p, p)
}

/// Torus around +y: `u` along the ring, `v` around the tube (v = 0 on the
/// outer equator).
fn torus_point(u: f32, v: f32) -> (Vec3, Vec3) {
    let (phi, psi) = (u * TAU, v * TAU);
    let ring = Vec3::new(phi.cos(), 0.0, -phi.sin());
    let n = ring * psi.cos() + Vec3::Y * psi.sin();
    (ring + TORUS_MINOR * n, n)
}

/// A `[nu, nv]` grid of quads over `[0, 1]^2` through `point(u, v) ->
/// (position, normal)`, dropping the triangles a pole collapses. Along an
/// axis that `wraps` (a closed mesh's texture seam) the last column's
/// corners are the first's, bit for bit (`cos(2 pi)` is not `cos(0)` in
/// single precision), with their own texture coordinate one tile on: the
/// two sides of the seam share positions and normals, so their curved
/// shells share their sides ([`crate::mesh_shells`]).
fn grid(
    [nu, nv]: [usize; 2],
    wraps: [bool; 2],
    point: impl Fn(f32, f32) -> (Vec3, Vec3),
) -> Vec<MeshTriangle> {
    let vertex = |i: usize, j: usize| {
        let uv = Vec2::new(i as f32 / nu as f32, j as f32 / nv as f32);
        let (wi, wj) = (
            if wraps[0] { i % nu } else { i },
            if wraps[1] { j % nv } else { j },
        );
        let (p, n) = point(wi as f32 / nu as f32, wj as f32 / nv as f32);
        (p, n, uv)
    };
    let mut out = Vec::with_capacity(2 * nu * nv);
    for j in 0..nv {
        for i in 0..nu {
            let a = vertex(i, j);
            let b = vertex(i + 1, j);
            let c = vertex(i + 1, j + 1);
            let d = vertex(i, j + 1);
            for [x, y, z] in [[a, b, c], [a, c, d]] {
                if (y.0 - x.0).cross(z.0 - x.0).length_squared() < 1e-14 {
                    continue;
                }
                out.push(MeshTriangle {
                    positions: [x.0, y.0, z.0],
                    normals: Some([x.1, y.1, z.1]),
                    uvs: [x.2, y.2, z.2],
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Winding, normals and texture frame agree on every triangle of every
    /// built-in mesh: the geometric normal points the way of the vertex
    /// normals, and `dP/du x dP/dv` the same way (a right-handed frame).
    #[test]
    fn every_builtin_is_wound_outwards_with_a_right_handed_frame() {
        for name in NAMES {
            let mesh = generate(name).unwrap();
            assert!(mesh.triangles.len() >= 2, "{name}");
            for (k, t) in mesh.triangles.iter().enumerate() {
                let [p0, p1, p2] = t.positions;
                let (e1, e2) = (p1 - p0, p2 - p0);
                let face = e1.cross(e2).normalize();
                let vn = t.normals.unwrap();
                for n in vn {
                    assert!((n.length() - 1.0).abs() < 1e-5, "{name} {k}");
                    assert!(face.dot(n) > 0.5, "{name} triangle {k}: {face} vs {n}");
                }
                let (d1, d2) = (t.uvs[1] - t.uvs[0], t.uvs[2] - t.uvs[0]);
                let det = d1.x * d2.y - d2.x * d1.y;
                let dpdu = (d2.y * e1 - d1.y * e2) / det;
                let dpdv = (-d2.x * e1 + d1.x * e2) / det;
                assert!(
                    dpdu.cross(dpdv).dot(face) > 0.0,
                    "{name} triangle {k}: left-handed texture frame"
                );
                for uv in t.uvs {
                    assert!(uv.min_element() >= 0.0 && uv.max_element() <= 1.0);
                }
            }
        }
    }

    #[test]
    fn surfaces_lie_where_their_formulas_put_them() {
        for t in generate("sphere").unwrap().triangles {
            for p in t.positions {
                assert!((p.length() - 1.0).abs() < 1e-5);
            }
        }
        for t in generate("torus").unwrap().triangles {
            for p in t.positions {
                let ring = Vec3::new(p.x, 0.0, p.z).normalize();
                assert!(((p - ring).length() - TORUS_MINOR).abs() < 1e-5);
            }
        }
        for t in generate("cube").unwrap().triangles {
            for p in t.positions {
                assert!((p.abs().max_element() - 1.0).abs() < 1e-6);
            }
        }
        // Closed surfaces: the cube's 12 triangles cover 6 faces of area 4.
        let area: f32 = generate("cube")
            .unwrap()
            .triangles
            .iter()
            .map(|t| {
                0.5 * (t.positions[1] - t.positions[0])
                    .cross(t.positions[2] - t.positions[0])
                    .length()
            })
            .sum();
        assert!((area - 24.0).abs() < 1e-4);
    }

    #[test]
    fn unknown_names_list_the_known_ones() {
        let e = generate("teapot").unwrap_err().to_string();
        assert!(
            e.contains("builtin:teapot") && e.contains("builtin:torus"),
            "{e}"
        );
    }
}
