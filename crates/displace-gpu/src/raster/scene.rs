//! What one draw of the raster path shows: the displaced face, its camera
//! and light, and how its fragments shade ([`PlaneScene`]), and whether they
//! march a second time towards the light ([`Shadows`]).

use crate::{Error, Result};
use displace_core::names::parse_choice;
use displace_core::{DisplacementMap, MapRay, Method};
use glam::{Mat4, Vec3};

/// Largest image edge accepted before anything is allocated: a bad size is
/// refused as an option error rather than as a device allocation failure.
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
/// ([`super::Renderer::for_mesh`]) takes the camera, light, shading and `depth`
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
    pub(super) fn check_depth(&self) -> Result<()> {
        if !(self.depth.is_finite() && self.depth > 0.0) {
            return Err(Error::InvalidOption(
                "scene vectors must be finite and the depth positive".into(),
            ));
        }
        Ok(())
    }

    /// The face's own checks (box renderers only).
    pub(super) fn check_face(&self) -> Result<()> {
        if !(self.origin.is_finite() && self.tangent.is_finite() && self.bitangent.is_finite()) {
            return Err(Error::InvalidOption("face vectors must be finite".into()));
        }
        if self.tangent.cross(self.bitangent).length_squared() == 0.0 {
            return Err(Error::InvalidOption("degenerate face".into()));
        }
        Ok(())
    }

    /// The camera's and the image's checks, run before anything is allocated.
    pub(super) fn check(&self) -> Result<()> {
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

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use displace_core::{bake, Address, BakeOptions, Extent, HeightMap};

    /// The built-in scene over a flat 2 x 1 map, 0.25 deep.
    pub(in crate::raster) fn scene() -> PlaneScene {
        let height = HeightMap::new(4, 4, vec![0.0; 16], Address::Clamp).unwrap();
        let extent = Extent::new(2.0, 1.0, 0.25).unwrap();
        let map = bake(&height, &BakeOptions::new([4, 4, 2], extent)).unwrap();
        PlaneScene::for_map(&map, [64, 32])
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn for_map_spans_the_maps_extent() {
        let s = scene();
        assert_eq!(s.tangent, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(s.bitangent, Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(s.depth, 0.25);
        assert_eq!(s.target, Vec3::new(1.0, 0.5, 0.0));
        assert!(close(s.normal(), Vec3::Z));
    }

    #[test]
    fn a_mirrored_face_turns_its_normal() {
        let s = PlaneScene {
            mirrored: true,
            ..scene()
        };
        assert!(close(s.normal(), -Vec3::Z));
    }

    #[test]
    fn the_face_shell_box_spans_its_tiles_and_depth() {
        let s = PlaneScene {
            tiles: [3.0, 2.0],
            origin: Vec3::new(1.0, 0.0, 0.0),
            ..scene()
        };
        let c = s.shell_corners();
        assert!(close(c[0], s.origin));
        assert!(close(c[1], s.origin + Vec3::new(6.0, 0.0, 0.0)));
        assert!(close(c[2], s.origin + Vec3::new(0.0, 2.0, 0.0)));
        assert!(close(c[4], s.origin + Vec3::new(0.0, 0.0, 0.25)));
        assert!(close(c[7], s.origin + Vec3::new(6.0, 2.0, 0.25)));
    }

    #[test]
    fn mesh_bounds_grow_by_the_shell_depth() {
        let s = PlaneScene {
            bounds: Some([Vec3::ZERO, Vec3::ONE]),
            depth: -0.5,
            ..scene()
        };
        let c = s.shell_corners();
        assert!(close(c[0], Vec3::splat(-0.5)));
        assert!(close(c[7], Vec3::splat(1.5)));
        assert!(close(c[3], Vec3::new(1.5, 1.5, -0.5)));
    }

    #[test]
    fn the_camera_looks_at_its_target_between_its_planes() {
        let s = scene();
        let m = s.view_proj();
        let centre = m.project_point3(s.target);
        assert!(centre.x.abs() < 1e-5 && centre.y.abs() < 1e-5, "{centre}");
        assert!(centre.z > 0.0 && centre.z < 1.0, "{centre}");
        // A point far past the shell lies beyond the far plane.
        let forward = (s.target - s.eye).normalize();
        let beyond = m.project_point3(s.eye + forward * 1e3);
        assert!(beyond.z > 1.0, "{beyond}");
    }

    #[test]
    fn a_given_depth_range_sets_the_planes() {
        let s = PlaneScene {
            depth_range: Some([1.0, 10.0]),
            ..scene()
        };
        let forward = (s.target - s.eye).normalize();
        let m = s.view_proj();
        let near = m.project_point3(s.eye + forward * 1.0);
        let far = m.project_point3(s.eye + forward * 10.0);
        assert!(near.z.abs() < 1e-5, "{near}");
        assert!((far.z - 1.0).abs() < 1e-5, "{far}");
    }

    #[test]
    fn the_aspect_follows_the_image_size() {
        // A 2:1 image: a point one unit right of the target lands half as
        // far across as one unit up.
        let s = scene();
        let m = s.view_proj();
        let view = Mat4::look_at_rh(s.eye, s.target, s.up).inverse();
        let right = view.transform_vector3(Vec3::X);
        let up = view.transform_vector3(Vec3::Y);
        let x = m.project_point3(s.target + right * 0.1).x;
        let y = m.project_point3(s.target + up * 0.1).y;
        assert!((x * 2.0 - y).abs() < 1e-4, "{x} {y}");
    }

    #[test]
    fn checks_refuse_bad_sizes_cameras_and_faces() {
        assert!(scene().check().is_ok());
        for size in [[0, 8], [8, 0], [MAX_IMAGE_EDGE + 1, 8]] {
            assert!(PlaneScene { size, ..scene() }.check().is_err());
        }
        let s = scene();
        assert!(PlaneScene { eye: s.target, ..s }.check().is_err());
        assert!(PlaneScene {
            fov_y_degrees: 180.0,
            ..s
        }
        .check()
        .is_err());
        let backwards = Some([2.0, 1.0]);
        assert!(PlaneScene {
            depth_range: backwards,
            ..s
        }
        .check()
        .is_err());
        assert!(PlaneScene { depth: 0.0, ..s }.check_depth().is_err());
        let flat = PlaneScene {
            bitangent: s.tangent,
            ..s
        };
        assert!(flat.check_face().is_err());
    }
}
