//! The viewer's orbit camera and light: positions turned about a target
//! point, around the world axis nearest the starting camera's up so that
//! dragging sideways spins the scene about its own vertical.

use glam::{Quat, Vec3};

/// Closest the eye or light may come to the orbit axis, in degrees, so the
/// view never flips over a pole.
const POLE_MARGIN_DEGREES: f32 = 2.0;

/// The world axis (±x, ±y or ±z) nearest `v`.
pub fn nearest_axis(v: Vec3) -> Vec3 {
    let a = v.abs();
    if a.x >= a.y && a.x >= a.z {
        Vec3::X * v.x.signum()
    } else if a.y >= a.z {
        Vec3::Y * v.y.signum()
    } else {
        Vec3::Z * v.z.signum()
    }
}

/// The rotation that turns `offset` (from the target) by `yaw` degrees
/// about `axis` and raises it by `raise` degrees towards `axis`, its angle
/// to the axis kept within `POLE_MARGIN_DEGREES` of either pole. Identity
/// for a zero turn, so an untouched view stays exactly where it started.
pub fn turn(offset: Vec3, axis: Vec3, yaw: f32, raise: f32) -> Quat {
    if yaw == 0.0 && raise == 0.0 {
        return Quat::IDENTITY;
    }
    let spin = Quat::from_axis_angle(axis, yaw.to_radians());
    let spun = spin * offset;
    let side = axis.cross(spun);
    if side.length_squared() <= 1e-12 * spun.length_squared() {
        return spin;
    }
    let polar = spun.normalize().dot(axis).clamp(-1.0, 1.0).acos();
    let margin = POLE_MARGIN_DEGREES.to_radians();
    let wanted = (polar - raise.to_radians()).clamp(margin, std::f32::consts::PI - margin);
    // Rotating about `side` (axis x offset) moves the offset away from the
    // axis: a negative angle raises it.
    Quat::from_axis_angle(side.normalize(), wanted - polar) * spin
}

/// Eye, target and up of a camera that orbits `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orbit {
    /// The point the camera orbits and looks at.
    pub target: Vec3,
    offset: Vec3,
    up: Vec3,
    axis: Vec3,
    start_distance: f32,
}

impl Orbit {
    /// A camera at `eye` looking at `target` with the up vector `up`.
    pub fn new(eye: Vec3, target: Vec3, up: Vec3) -> Self {
        let offset = eye - target;
        Self {
            target,
            offset,
            up,
            axis: nearest_axis(up),
            start_distance: offset.length(),
        }
    }

    /// Camera position.
    pub fn eye(&self) -> Vec3 {
        self.target + self.offset
    }

    /// Camera up direction.
    pub fn up(&self) -> Vec3 {
        self.up
    }

    /// The axis the camera and light spin about.
    pub fn axis(&self) -> Vec3 {
        self.axis
    }

    /// Turns the eye about the target: `yaw` degrees about the axis, `raise`
    /// degrees up towards it.
    pub fn orbit(&mut self, yaw: f32, raise: f32) {
        let q = turn(self.offset, self.axis, yaw, raise);
        self.offset = q * self.offset;
        self.up = q * self.up;
    }

    /// Multiplies the distance to the target by `factor` (below 1 zooms
    /// in), kept within a thousandth and a thousand times the start.
    pub fn zoom(&mut self, factor: f32) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let d = self.offset.length();
        let wanted = (d * factor).clamp(self.start_distance * 1e-3, self.start_distance * 1e3);
        self.offset *= wanted / d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() <= 1e-5 * (1.0 + a.length())
    }

    #[test]
    fn untouched_orbit_is_the_start() {
        let mut o = Orbit::new(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y);
        o.orbit(0.0, 0.0);
        assert_eq!(o.eye(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(o.up(), Vec3::Y);
    }

    #[test]
    fn yaw_keeps_height_and_distance_and_returns_after_a_full_turn() {
        let eye = Vec3::new(0.0, 1.0, 4.0);
        let mut o = Orbit::new(eye, Vec3::ZERO, Vec3::Y);
        o.orbit(90.0, 0.0);
        assert!(close(o.eye(), Vec3::new(4.0, 1.0, 0.0)), "{}", o.eye());
        for _ in 0..3 {
            o.orbit(90.0, 0.0);
        }
        assert!(close(o.eye(), eye));
    }

    #[test]
    fn raising_moves_the_eye_up_and_stops_short_of_the_pole() {
        let mut o = Orbit::new(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y);
        o.orbit(0.0, 30.0);
        let e = o.eye();
        assert!(close(
            e,
            Vec3::new(0.0, 2.0, 4.0 * 30f32.to_radians().cos())
        ));
        // The up vector turns with the eye, staying square to the view.
        assert!(o.up().dot(e).abs() < 1e-5);
        o.orbit(0.0, 500.0);
        let polar = o.eye().normalize().dot(Vec3::Y).acos().to_degrees();
        assert!((polar - POLE_MARGIN_DEGREES).abs() < 1e-3, "{polar}");
        assert!(close(o.eye().length() * Vec3::ONE, 4.0 * Vec3::ONE));
    }

    #[test]
    fn zoom_scales_the_distance_within_bounds() {
        let mut o = Orbit::new(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::Y);
        o.zoom(0.5);
        assert!(close(o.eye(), Vec3::new(0.0, 0.0, 1.0)));
        o.zoom(1e9);
        assert!(close(o.eye(), Vec3::new(0.0, 0.0, 2000.0)));
        o.zoom(f32::NAN);
        assert!(close(o.eye(), Vec3::new(0.0, 0.0, 2000.0)));
    }

    #[test]
    fn nearest_axis_picks_the_largest_component_with_its_sign() {
        assert_eq!(nearest_axis(Vec3::new(0.1, -0.9, 0.3)), -Vec3::Y);
        assert_eq!(nearest_axis(Vec3::new(0.1, 0.2, 0.97)), Vec3::Z);
    }
}
