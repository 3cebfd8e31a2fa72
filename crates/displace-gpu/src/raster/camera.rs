//! The per-frame half of a raster draw ([`View`]: the image, the camera,
//! its depth range and the light). Faces drawn into one depth buffer must
//! share one projection, so a frame of many draws is one `View` and a list
//! of [`super::Draw`]s ([`super::render_faces`]), not a camera copied into
//! each draw and compared afterwards.

use super::MAX_IMAGE_EDGE;
use crate::{Error, Result};
use glam::{Mat4, Vec3};

/// A frame's image, camera and light: what every draw of one frame shares.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
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
    /// Near and far planes; `None` picks them from the one draw a
    /// [`super::PlaneScene`] holds ([`super::Draw::reach`]). Draws of one
    /// frame need them set ([`super::shared_depth_range`]).
    pub depth_range: Option<[f32; 2]>,
    /// Point light position.
    pub light: Vec3,
    /// Light intensity (see `falloff`).
    pub light_intensity: f32,
    /// Divide the light by the squared world distance (a point light of
    /// radiant intensity `light_intensity`, as the CPU renderer lights);
    /// off, the light is a constant irradiance (the built-in scene's look).
    pub falloff: bool,
}

impl View {
    /// The camera's view-projection matrix, with near and far planes from
    /// `depth_range` or, without one, from a draw reaching the two lengths
    /// `reach` past the target ([`super::Draw::reach`]).
    pub fn view_proj(&self, reach: [f32; 2]) -> Mat4 {
        let aspect = self.size[0] as f32 / self.size[1] as f32;
        let reach = (self.eye - self.target).length() + reach[0] + reach[1];
        let [near, far] = self.depth_range.unwrap_or([reach * 1e-3, reach * 4.0]);
        Mat4::perspective_rh(self.fov_y_degrees.to_radians(), aspect, near, far)
            * Mat4::look_at_rh(self.eye, self.target, self.up)
    }

    /// Unit direction the camera looks along.
    pub fn forward(&self) -> Vec3 {
        (self.target - self.eye).normalize()
    }

    /// The image's and the camera's checks, run before anything is
    /// allocated: a bad size is refused as an option error rather than as
    /// a device allocation failure.
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
mod tests {
    use super::super::scene::tests::scene;
    use super::*;

    #[test]
    fn the_camera_looks_at_its_target_between_its_planes() {
        let s = scene();
        let m = s.view_proj();
        let centre = m.project_point3(s.view.target);
        assert!(centre.x.abs() < 1e-5 && centre.y.abs() < 1e-5, "{centre}");
        assert!(centre.z > 0.0 && centre.z < 1.0, "{centre}");
        // A point far past the shell lies beyond the far plane.
        let beyond = m.project_point3(s.view.eye + s.view.forward() * 1e3);
        assert!(beyond.z > 1.0, "{beyond}");
    }

    #[test]
    fn a_given_depth_range_sets_the_planes() {
        let v = View {
            depth_range: Some([1.0, 10.0]),
            ..scene().view
        };
        // The draw's reach is not used once the planes are given.
        let m = v.view_proj([123.0, 4.0]);
        let near = m.project_point3(v.eye + v.forward() * 1.0);
        let far = m.project_point3(v.eye + v.forward() * 10.0);
        assert!(near.z.abs() < 1e-5, "{near}");
        assert!((far.z - 1.0).abs() < 1e-5, "{far}");
    }

    #[test]
    fn the_aspect_follows_the_image_size() {
        // A 2:1 image: a point one unit right of the target lands half as
        // far across as one unit up.
        let s = scene();
        let m = s.view_proj();
        let v = s.view;
        let view = Mat4::look_at_rh(v.eye, v.target, v.up).inverse();
        let right = view.transform_vector3(Vec3::X);
        let up = view.transform_vector3(Vec3::Y);
        let x = m.project_point3(v.target + right * 0.1).x;
        let y = m.project_point3(v.target + up * 0.1).y;
        assert!((x * 2.0 - y).abs() < 1e-4, "{x} {y}");
    }

    #[test]
    fn checks_refuse_bad_sizes_and_cameras() {
        let v = scene().view;
        assert!(v.check().is_ok());
        for size in [[0, 8], [8, 0], [MAX_IMAGE_EDGE + 1, 8]] {
            assert!(View { size, ..v }.check().is_err());
        }
        assert!(View { eye: v.target, ..v }.check().is_err());
        assert!(View {
            fov_y_degrees: 180.0,
            ..v
        }
        .check()
        .is_err());
        let backwards = Some([2.0, 1.0]);
        assert!(View {
            depth_range: backwards,
            ..v
        }
        .check()
        .is_err());
        assert!(View {
            light: Vec3::NAN,
            ..v
        }
        .check()
        .is_err());
    }
}
