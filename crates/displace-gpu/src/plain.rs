//! Non-displaced geometry for the raster path: a scene's walls, boxes,
//! spheres, plain meshes and visible area-light quads as world-space
//! triangles with their material per vertex, so all of them go in one draw
//! (`shaders/plain.wgsl`, through [`crate::Renderer::plain`]) beside the
//! displaced faces, in the same depth buffer.

use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// How a plain surface shades under the scene's one light: `diffuse` is
/// the CPU's `albedo / pi` times the light's radiant intensity (so the
/// shader's `diffuse cos / r^2` is the CPU's direct term), `specular` the
/// normalised Blinn-Phong weight in the same units, `emission` the radiance
/// of an area light's visible quad (seen from its front only).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlainMaterial {
    /// Diffuse weight: the CPU's `albedo / pi` times the light's intensity.
    pub diffuse: Vec3,
    /// Normalised Blinn-Phong weight, in the units of `diffuse`.
    pub specular: f32,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Radiance of an emitting surface (an area light's visible quad).
    pub emission: Vec3,
}

/// A corner of a plain triangle. Mirror of WGSL `PlainVertex` (plain.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlainVertex {
    /// World position.
    pub position: [f32; 3],
    /// Unit shading normal.
    pub normal: [f32; 3],
    /// The CPU's texture coordinate of the shape here (its uv AOV).
    pub uv: [f32; 2],
    /// The material's `diffuse`.
    pub diffuse: [f32; 3],
    /// The material's `specular`.
    pub specular: f32,
    /// The material's `emission`.
    pub emission: [f32; 3],
    /// The material's `shininess`.
    pub shininess: f32,
}

/// Triangle list of every plain shape of a scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlainMesh {
    /// Three vertices per triangle.
    pub vertices: Vec<PlainVertex>,
}

/// Longitude and latitude steps of a tessellated sphere: round to the eye
/// at 512 x 512 for a sphere filling a good part of the frame.
pub const SPHERE_STEPS: [u32; 2] = [64, 32];

impl PlainMesh {
    /// Adds one triangle, corners `(position, normal, uv)`.
    pub fn triangle(&mut self, corners: [(Vec3, Vec3, Vec2); 3], m: &PlainMaterial) {
        for (p, n, uv) in corners {
            self.vertices.push(PlainVertex {
                position: p.to_array(),
                normal: n.to_array(),
                uv: uv.to_array(),
                diffuse: m.diffuse.to_array(),
                specular: m.specular,
                emission: m.emission.to_array(),
                shininess: m.shininess,
            });
        }
    }

    /// The parallelogram `origin + [0,1] edge_u + [0,1] edge_v` as two
    /// triangles, normal `edge_u x edge_v`, uv its parameters (the CPU
    /// quad's).
    pub fn quad(&mut self, origin: Vec3, edge_u: Vec3, edge_v: Vec3, m: &PlainMaterial) {
        let n = edge_u.cross(edge_v).normalize_or_zero();
        let at = |u: f32, v: f32| (origin + u * edge_u + v * edge_v, n, Vec2::new(u, v));
        self.triangle([at(0.0, 0.0), at(1.0, 0.0), at(1.0, 1.0)], m);
        self.triangle([at(0.0, 0.0), at(1.0, 1.0), at(0.0, 1.0)], m);
    }

    /// A sphere as [`SPHERE_STEPS`] longitude by latitude cells, normals
    /// exact at the corners, uv the CPU's longitude/latitude coordinate
    /// (`displace_scene::shapes::Sphere::uv`: u from atan2(z, x), v from
    /// the angle to +y).
    pub fn sphere(&mut self, centre: Vec3, radius: f32, m: &PlainMaterial) {
        let [nu, nv] = SPHERE_STEPS;
        let at = |i: u32, j: u32| {
            let u = i as f32 / nu as f32;
            let v = j as f32 / nv as f32;
            let (phi, theta) = ((u - 0.5) * TAU, v * PI);
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            (centre + radius * n, n, Vec2::new(u, v))
        };
        for j in 0..nv {
            for i in 0..nu {
                let [a, b, c, d] = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                // The pole rows' cells are triangles.
                if j > 0 {
                    self.triangle([a, b, c], m);
                }
                if j + 1 < nv {
                    self.triangle([a, c, d], m);
                }
            }
        }
    }

    /// World box `[min, max]` of every vertex, `None` when empty.
    pub fn bounds(&self) -> Option<[Vec3; 2]> {
        let mut it = self.vertices.iter().map(|v| Vec3::from_array(v.position));
        let first = it.next()?;
        Some(it.fold([first, first], |[lo, hi], p| [lo.min(p), hi.max(p)]))
    }

    /// Every position, normal and material finite.
    pub fn check(&self) -> Result<()> {
        if self.vertices.is_empty() {
            return Err(Error::InvalidOption("no plain triangles to draw".into()));
        }
        for (k, v) in self.vertices.iter().enumerate() {
            let values = v
                .position
                .iter()
                .chain(&v.normal)
                .chain(&v.uv)
                .chain(&v.diffuse)
                .chain(&v.emission)
                .chain([&v.specular, &v.shininess]);
            if !values.into_iter().all(|c| c.is_finite()) {
                return Err(Error::InvalidOption(format!(
                    "plain triangle {}: positions, normals and materials must be finite",
                    k / 3
                )));
            }
        }
        Ok(())
    }
}

/// Mirror of WGSL `PlainFrame` (plain.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct PlainFrame {
    pub view_proj: [[f32; 4]; 4],
    pub eye: [f32; 4],
    pub light: [f32; 4],
    pub ambient: f32,
    pub light_intensity: f32,
    pub falloff: u32,
    pub _pad: f32,
}

pub(crate) const PLAIN_VERTEX_LAYOUT: wgpu::VertexBufferLayout<'static> =
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<PlainVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x3,
            4 => Float32, 5 => Float32x3, 6 => Float32
        ],
    };

#[cfg(test)]
mod tests {
    #[test]
    fn plain_frame_matches_wgsl() {
        use super::PlainFrame;
        use crate::shaders::{assert_layout, offsets, plain_source};
        assert_layout(
            &plain_source(),
            "PlainFrame",
            std::mem::size_of::<PlainFrame>(),
            offsets!(PlainFrame {
                view_proj,
                eye,
                light,
                ambient,
                light_intensity,
                falloff,
                _pad
            }),
        );
    }

    use super::*;

    fn area(m: &PlainMesh) -> f32 {
        m.vertices
            .chunks_exact(3)
            .map(|t| {
                let p = t
                    .iter()
                    .map(|v| Vec3::from_array(v.position))
                    .collect::<Vec<_>>();
                0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
            })
            .sum()
    }

    #[test]
    fn a_quad_is_two_triangles_facing_its_normal() {
        let mut m = PlainMesh::default();
        let mat = PlainMaterial::default();
        m.quad(
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
            &mat,
        );
        assert_eq!(m.vertices.len(), 6);
        assert!((area(&m) - 6.0).abs() < 1e-5);
        for t in m.vertices.chunks_exact(3) {
            let p: Vec<Vec3> = t.iter().map(|v| Vec3::from_array(v.position)).collect();
            assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(Vec3::Z) > 0.0);
            assert!(t.iter().all(|v| v.normal == [0.0, 0.0, 1.0]));
        }
        assert_eq!(m.bounds(), Some([Vec3::ZERO, Vec3::new(2.0, 3.0, 0.0)]));
    }

    #[test]
    fn a_sphere_is_closed_outward_and_close_to_round() {
        let mut m = PlainMesh::default();
        let c = Vec3::new(1.0, -2.0, 0.5);
        m.sphere(c, 2.0, &PlainMaterial::default());
        let [nu, nv] = SPHERE_STEPS;
        assert_eq!(m.vertices.len() as u32, 3 * 2 * nu * (nv - 1));
        // The inscribed polyhedron's area is within 1% of the sphere's.
        let exact = 4.0 * PI * 4.0;
        assert!((area(&m) - exact).abs() < 0.01 * exact, "{}", area(&m));
        for t in m.vertices.chunks_exact(3) {
            let p: Vec<Vec3> = t.iter().map(|v| Vec3::from_array(v.position)).collect();
            let centroid = (p[0] + p[1] + p[2]) / 3.0 - c;
            assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(centroid) > 0.0);
            for v in t {
                let p = Vec3::from_array(v.position) - c;
                assert!((p.length() - 2.0).abs() < 1e-5);
                assert!((p / 2.0 - Vec3::from_array(v.normal)).length() < 1e-5);
            }
        }
    }

    #[test]
    fn non_finite_input_is_refused() {
        let mut m = PlainMesh::default();
        assert!(m.check().is_err());
        let mat = PlainMaterial {
            diffuse: Vec3::new(f32::NAN, 0.0, 0.0),
            ..Default::default()
        };
        m.quad(Vec3::ZERO, Vec3::X, Vec3::Y, &mat);
        let e = m.check().unwrap_err().to_string();
        assert!(e.contains("plain triangle 0"), "{e}");
    }
}
