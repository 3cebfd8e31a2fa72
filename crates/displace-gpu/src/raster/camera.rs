//! The per-frame half of a [`PlaneScene`] ([`View`]: the camera, its depth
//! range and the light). Faces drawn into one depth buffer must share one
//! camera ([`super::render_faces`]), so a frame of many draws is one `View`
//! put on every draw ([`PlaneScene::with_view`]), rather than the same
//! camera fields copied into each by hand.

use super::PlaneScene;
use glam::Vec3;

/// A frame's camera and light (each field as [`PlaneScene`]'s of the same
/// name): what every draw of one frame shares.
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
    /// Near and far planes ([`PlaneScene::depth_range`]: one pair for every
    /// face of the frame, as [`super::shared_depth_range`] picks it).
    pub depth_range: Option<[f32; 2]>,
    /// Point light position.
    pub light: Vec3,
    /// Light intensity ([`PlaneScene::light_intensity`]).
    pub light_intensity: f32,
    /// Inverse-square falloff of the light ([`PlaneScene::falloff`]).
    pub falloff: bool,
}

impl PlaneScene {
    /// This draw's camera and light.
    pub fn view(&self) -> View {
        View {
            size: self.size,
            eye: self.eye,
            target: self.target,
            up: self.up,
            fov_y_degrees: self.fov_y_degrees,
            depth_range: self.depth_range,
            light: self.light,
            light_intensity: self.light_intensity,
            falloff: self.falloff,
        }
    }

    /// This draw (its face, trace and shading) seen through `view`'s camera
    /// and lit by its light.
    pub fn with_view(&self, view: &View) -> Self {
        Self {
            size: view.size,
            eye: view.eye,
            target: view.target,
            up: view.up,
            fov_y_degrees: view.fov_y_degrees,
            depth_range: view.depth_range,
            light: view.light,
            light_intensity: view.light_intensity,
            falloff: view.falloff,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::scene::tests::scene;
    use super::super::Shadows;
    use super::*;

    /// A view whose every field differs from [`scene`]'s.
    fn other_view() -> View {
        View {
            size: [3, 5],
            eye: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::new(4.0, 5.0, 6.0),
            up: Vec3::new(0.0, 0.0, 7.0),
            fov_y_degrees: 8.0,
            depth_range: Some([9.0, 10.0]),
            light: Vec3::new(11.0, 12.0, 13.0),
            light_intensity: 14.0,
            falloff: true,
        }
    }

    #[test]
    fn a_draw_keeps_its_own_view() {
        let s = PlaneScene {
            shadows: Shadows::Soft,
            ..scene()
        };
        assert_eq!(s.with_view(&s.view()), s);
    }

    #[test]
    fn a_new_view_moves_the_camera_and_light_and_nothing_else() {
        let s = scene();
        let v = other_view();
        let moved = s.with_view(&v);
        assert_eq!(moved.view(), v);
        assert_ne!(moved.view(), s.view());
        // Faces put under one view share its camera, as a frame needs.
        let elsewhere = PlaneScene {
            origin: Vec3::ONE,
            ..s
        };
        assert_eq!(elsewhere.with_view(&v).view_proj(), moved.view_proj());
        // The face, trace and shading are the draw's own.
        let back = moved.with_view(&s.view());
        assert_eq!(back, s);
    }
}
