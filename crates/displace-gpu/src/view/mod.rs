//! `displace view`: the raster path of section 8.5 in a window, every frame
//! drawn by the same [`Renderer`] as the headless renders, with an orbit
//! camera and live controls over what Donnelly's shaders take as run-time
//! inputs: the inverse bump depth factor of listing 8-1 (depth changes
//! without a re-bake), the iteration count, fixed or early-out marching and
//! self-shadowing.
//!
//! [`ViewState`] is the part without a window (controls applied to the
//! scene's faces), [`overlay`] draws text and presents, [`window`] runs the
//! event loop.

pub mod controls;
pub mod orbit;
pub mod overlay;
pub mod window;

use crate::raster::shared_depth_range;
use crate::{Draw, Error, Renderer, Result, Shadows, View};
use controls::{Action, MAX_ITERATIONS};
use displace_core::Method;
use glam::Vec3;
use orbit::{turn, Orbit};

/// What the viewer draws: the scene's camera and light, each face with its
/// renderer and its draw as the scene file gives it, and the linear
/// background colour.
pub struct ViewScene {
    /// The scene's camera and light, where the orbit starts.
    pub view: View,
    /// Each face: its compiled renderer and its draw.
    pub draws: Vec<(Renderer, Draw)>,
    /// Linear RGB clear colour.
    pub background: [f64; 3],
}

/// The live settings, shown on the overlay and in the title.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Times each face's own displacement depth.
    pub depth_scale: f32,
    /// Sphere-tracing steps per ray.
    pub iterations: u32,
    /// Trace method.
    pub method: Method,
    /// Self-shadowing mode.
    pub shadows: Shadows,
    /// Whether the overlay is drawn.
    pub hud: bool,
}

/// Camera, light and settings of the view of one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewState {
    /// The camera.
    pub orbit: Orbit,
    /// Light position minus the orbit target.
    light_offset: Vec3,
    /// The live settings.
    pub settings: Settings,
    start: Box<(Orbit, Vec3, Settings)>,
}

impl ViewState {
    /// The view the scene describes: its camera and light, and the trace
    /// settings of its first face; the orbit target is the point on the
    /// view axis nearest the centre of all shell boxes.
    pub fn new(view: &View, faces: &[Draw]) -> Result<Self> {
        let Some(first) = faces.first() else {
            return Err(Error::InvalidOption("the view has no faces".into()));
        };
        let centre =
            faces.iter().flat_map(Draw::shell_corners).sum::<Vec3>() / (8 * faces.len()) as f32;
        let forward = view.forward();
        let along = (centre - view.eye).dot(forward);
        let reach = if along > 0.0 {
            along
        } else {
            (centre - view.eye).length().max(1e-6)
        };
        let target = view.eye + forward * reach;
        let orbit = Orbit::new(view.eye, target, view.up);
        let settings = Settings {
            depth_scale: 1.0,
            iterations: first.iterations,
            method: first.method,
            shadows: first.shadows,
            hud: true,
        };
        let light_offset = view.light - target;
        Ok(Self {
            orbit,
            light_offset,
            settings,
            start: Box::new((orbit, light_offset, settings)),
        })
    }

    /// Light position: it follows the orbit target.
    pub fn light(&self) -> Vec3 {
        self.orbit.target + self.light_offset
    }

    /// Applies `action`; true when it asks to quit.
    pub fn apply(&mut self, action: Action) -> bool {
        let s = &mut self.settings;
        match action {
            Action::Orbit { yaw, raise } => self.orbit.orbit(yaw, raise),
            Action::Zoom(f) => self.orbit.zoom(f),
            Action::Depth(v) => s.depth_scale = clamp_depth(v, s.depth_scale),
            Action::DepthBy(f) => s.depth_scale = clamp_depth(s.depth_scale * f, s.depth_scale),
            Action::Iterations(n) => s.iterations = n.clamp(1, MAX_ITERATIONS),
            Action::IterationsStep(up) => {
                s.iterations = if up {
                    s.iterations.saturating_mul(2)
                } else {
                    s.iterations / 2
                }
                .clamp(1, MAX_ITERATIONS)
            }
            Action::Method(m) => s.method = m,
            Action::ToggleMethod => {
                s.method = match s.method {
                    Method::SphereFixed => Method::Sphere,
                    _ => Method::SphereFixed,
                }
            }
            Action::Shadows(sh) => s.shadows = sh,
            Action::CycleShadows => {
                s.shadows = match s.shadows {
                    Shadows::None => Shadows::Hard,
                    Shadows::Hard => Shadows::Soft,
                    Shadows::Soft => Shadows::None,
                }
            }
            Action::Light { yaw, raise } => {
                self.light_offset =
                    turn(self.light_offset, self.orbit.axis(), yaw, raise) * self.light_offset
            }
            Action::Hud(on) => s.hud = on,
            Action::ToggleHud => s.hud = !s.hud,
            Action::Reset => {
                let (orbit, light, settings) = *self.start;
                self.orbit = orbit;
                self.light_offset = light;
                self.settings = settings;
            }
            Action::Quit => return true,
            // The window's business.
            Action::Resize(_) | Action::AfterFrame(_) => {}
        }
        false
    }

    /// The scene's `view` and `faces` as this view draws them at `size`
    /// pixels: the orbit's camera, the turned light and one depth range for
    /// all, and each face at the live depth and trace settings.
    pub fn frame(&self, view: &View, faces: &[Draw], size: [u32; 2]) -> (View, Vec<Draw>) {
        let s = &self.settings;
        let draws: Vec<Draw> = faces
            .iter()
            .map(|f| Draw {
                depth: f.depth * s.depth_scale,
                method: s.method,
                iterations: s.iterations,
                shadows: s.shadows,
                ..*f
            })
            .collect();
        let mut view = View {
            size,
            eye: self.orbit.eye(),
            target: self.orbit.target,
            up: self.orbit.up(),
            light: self.light(),
            ..*view
        };
        // With every face behind the camera nothing is drawn, and any valid
        // range will do.
        view.depth_range = Some(shared_depth_range(&view, &draws).unwrap_or([1e-3, 1.0]));
        (view, draws)
    }

    /// The settings in a few short lines, with the frame time.
    pub fn status_lines(&self, frame_ms: Option<f64>) -> Vec<String> {
        let s = &self.settings;
        let method = match s.method {
            Method::SphereFixed => "fixed",
            _ => "early-out",
        };
        let shadows = match s.shadows {
            Shadows::None => "off",
            Shadows::Hard => "hard",
            Shadows::Soft => "soft",
        };
        let frame = match frame_ms {
            Some(ms) => format!("frame {ms:.1} ms ({:.0} fps)", 1000.0 / ms.max(1e-3)),
            None => "frame -".to_string(),
        };
        vec![
            frame,
            format!("depth x{:.3}  [ ]", s.depth_scale),
            format!("iterations {}  , .", s.iterations),
            format!("method {method}  m"),
            format!("shadows {shadows}  s"),
            "light j l i k".to_string(),
        ]
    }
}

/// Depth scales are kept positive and finite (the shell must have a
/// height); an out-of-range request leaves the scale where it was.
fn clamp_depth(wanted: f32, current: f32) -> f32 {
    if wanted.is_finite() && wanted > 0.0 {
        wanted.clamp(1e-3, 1e3)
    } else {
        current
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PlaneScene;
    use displace_core::{bake, Address, BakeOptions, Extent, HeightMap};

    fn plane() -> PlaneScene {
        let h = HeightMap::new(4, 4, vec![0.5; 16], Address::Clamp).unwrap();
        let map = bake(
            &h,
            &BakeOptions::new([4, 4, 2], Extent::new(1.0, 1.0, 0.1).unwrap()),
        )
        .unwrap();
        PlaneScene::for_map(&map, [64, 48])
    }

    #[test]
    fn the_untouched_view_is_the_scene() {
        let PlaneScene { view: fv, draw: f } = plane();
        let v = ViewState::new(&fv, &[f]).unwrap();
        let (pv, p) = v.frame(&fv, &[f], fv.size);
        assert_eq!(pv.eye, fv.eye);
        assert_eq!(pv.light, fv.light);
        assert_eq!(p[0].depth, f.depth);
        // The view direction is the scene's (the target may sit elsewhere
        // on the axis).
        let d = |a: Vec3, b: Vec3| (a - b).normalize();
        assert!((d(pv.target, pv.eye) - d(fv.target, fv.eye)).length() < 1e-6);
        assert_eq!(pv.depth_range, shared_depth_range(&fv, &[f]));
    }

    #[test]
    fn controls_change_the_planes_and_reset_restores_them() {
        let PlaneScene { view: fv, draw: f } = plane();
        let mut v = ViewState::new(&fv, &[f]).unwrap();
        let start = v.clone();
        v.apply(Action::Depth(0.5));
        v.apply(Action::IterationsStep(false));
        v.apply(Action::ToggleMethod);
        v.apply(Action::CycleShadows);
        v.apply(Action::Light {
            yaw: 90.0,
            raise: 0.0,
        });
        v.apply(Action::Orbit {
            yaw: 10.0,
            raise: 0.0,
        });
        let (pv, p) = v.frame(&fv, &[f], fv.size);
        let p = p[0];
        assert_eq!(p.depth, f.depth * 0.5);
        assert_eq!(p.iterations, f.iterations / 2);
        assert_eq!(p.method, Method::SphereFixed);
        assert_eq!(p.shadows, Shadows::Soft);
        // The light keeps its distance to the target.
        let t = v.orbit.target;
        assert!(((pv.light - t).length() - (fv.light - t).length()).abs() < 1e-4);
        assert!((pv.light - fv.light).length() > 1e-2);
        assert!((pv.eye - fv.eye).length() > 1e-2);
        v.apply(Action::Depth(-1.0));
        assert_eq!(v.settings.depth_scale, 0.5);
        v.apply(Action::Reset);
        assert_eq!(v, start);
        assert!(v.apply(Action::Quit));
    }
}
