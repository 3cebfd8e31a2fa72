//! Pinhole camera with an optional thin lens (depth of field as in Cook,
//! Porter and Carpenter 1984: rays distributed over the lens aperture, all
//! meeting on the plane of focus).

use crate::geometry::{Ray, PACKET};
use crate::sampler::concentric_disk;
use glam::{Vec2, Vec3};

/// A perspective camera: pinhole, or a thin lens focused at a distance.
#[derive(Clone, Debug)]
pub struct Camera {
    position: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    /// `tan(vfov / 2)`.
    tan_half: f32,
    aspect: f32,
    /// Lens radius in world units; 0 is a pinhole.
    lens_radius: f32,
    focus_distance: f32,
}

/// Why a camera cannot be built.
#[derive(Debug, PartialEq)]
pub enum CameraError {
    /// `position` equals `look_at`.
    LooksNowhere,
    /// `up` is zero or parallel to the viewing direction.
    UpParallel,
    /// The vertical field of view is not in `(0, 180)` degrees.
    BadFov(f32),
    /// The aperture or focus distance is negative or not finite.
    BadLens(String),
}

impl std::fmt::Display for CameraError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CameraError::LooksNowhere => write!(
                f,
                "camera.position equals camera.look_at: the camera looks nowhere"
            ),
            CameraError::UpParallel => write!(
                f,
                "camera.up is parallel to the viewing direction (or zero)"
            ),
            CameraError::BadFov(v) => write!(f, "camera.vfov must be in (0, 180) degrees, got {v}"),
            CameraError::BadLens(m) => write!(f, "{m}"),
        }
    }
}

impl Camera {
    /// `vfov` in degrees; `aspect` = width / height of the full image.
    pub fn new(
        position: Vec3,
        look_at: Vec3,
        up: Vec3,
        vfov: f32,
        aspect: f32,
        aperture: f32,
        focus_distance: Option<f32>,
    ) -> Result<Self, CameraError> {
        let view = look_at - position;
        if view.length() <= 1e-6 * (1.0 + position.length()) {
            return Err(CameraError::LooksNowhere);
        }
        let forward = view.normalize();
        let right = forward.cross(up);
        if right.length() <= 1e-6 * up.length().max(1e-30) || up.length() == 0.0 {
            return Err(CameraError::UpParallel);
        }
        let right = right.normalize();
        let up = right.cross(forward);
        if !(vfov > 0.0 && vfov < 180.0) {
            return Err(CameraError::BadFov(vfov));
        }
        let most = crate::build::MAX_COORDINATE;
        if !(aperture >= 0.0 && aperture <= most) {
            return Err(CameraError::BadLens(format!(
                "camera.aperture must be a number from 0 to {most:e}, got {aperture}"
            )));
        }
        let focus_distance = focus_distance.unwrap_or(view.length());
        if !(focus_distance > 0.0 && focus_distance <= most) {
            return Err(CameraError::BadLens(format!(
                "camera.focus_distance must be positive and at most {most:e}, got {focus_distance}"
            )));
        }
        Ok(Self {
            position,
            forward,
            right,
            up,
            tan_half: (vfov.to_radians() * 0.5).tan(),
            aspect,
            lens_radius: 0.5 * aperture,
            focus_distance,
        })
    }

    /// The ray through film point `film` (`[0,1]^2`, y down) and lens sample
    /// `lens` (`[0,1]^2`, ignored by a pinhole).
    pub fn ray(&self, film: Vec2, lens: Vec2) -> Ray {
        let sx = (2.0 * film.x - 1.0) * self.tan_half * self.aspect;
        let sy = (1.0 - 2.0 * film.y) * self.tan_half;
        let dir = self.forward + sx * self.right + sy * self.up;
        if self.lens_radius == 0.0 {
            return Ray::new(self.position, dir);
        }
        let focus = self.position + dir * self.focus_distance;
        let l = concentric_disk(lens) * self.lens_radius;
        let origin = self.position + l.x * self.right + l.y * self.up;
        Ray::new(origin, focus - origin)
    }

    /// [`Camera::ray`] for eight film and lens samples at once, the rays'
    /// normalisation in vector lanes ([`Ray::new8`]): lane `l` is
    /// `ray(film[l], lens[l])` bit for bit. A wavefront renderer generates
    /// its camera rays a packet at a time (Laine, Karras and Aila 2013,
    /// "Megakernels considered harmful", section 4.1).
    pub fn ray8(&self, film: &[Vec2; PACKET], lens: &[Vec2; PACKET]) -> [Ray; PACKET] {
        let dir: [Vec3; PACKET] = std::array::from_fn(|l| {
            let sx = (2.0 * film[l].x - 1.0) * self.tan_half * self.aspect;
            let sy = (1.0 - 2.0 * film[l].y) * self.tan_half;
            self.forward + sx * self.right + sy * self.up
        });
        if self.lens_radius == 0.0 {
            return Ray::new8(&[self.position; PACKET], &dir);
        }
        let origin: [Vec3; PACKET] = std::array::from_fn(|l| {
            let d = concentric_disk(lens[l]) * self.lens_radius;
            self.position + d.x * self.right + d.y * self.up
        });
        let to: [Vec3; PACKET] = std::array::from_fn(|l| {
            let focus = self.position + dir[l] * self.focus_distance;
            focus - origin[l]
        });
        Ray::new8(&origin, &to)
    }

    /// The eye (the lens centre).
    pub fn position(&self) -> Vec3 {
        self.position
    }

    /// The orthonormal basis `(forward, right, up)` and `tan(vfov / 2)`, so
    /// another renderer can reproduce [`Camera::ray`]'s pixel mapping.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3, f32) {
        (self.forward, self.right, self.up, self.tan_half)
    }

    /// Lens radius, world units (0: pinhole).
    pub fn lens_radius(&self) -> f32 {
        self.lens_radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square camera at the origin looking down -z at `distance`, +y up.
    fn down_z(distance: f32, vfov: f32, aperture: f32, focus: Option<f32>) -> Camera {
        let target = Vec3::new(0.0, 0.0, -distance);
        Camera::new(Vec3::ZERO, target, Vec3::Y, vfov, 1.0, aperture, focus).unwrap()
    }

    #[test]
    fn centre_ray_looks_at_target() {
        let c = down_z(5.0, 60.0, 0.0, None);
        let r = c.ray(Vec2::splat(0.5), Vec2::ZERO);
        assert!((r.dir - Vec3::NEG_Z).length() < 1e-6);
        // Top edge of the film is vfov/2 above the axis.
        let top = c.ray(Vec2::new(0.5, 0.0), Vec2::ZERO);
        assert!((top.dir.angle_between(Vec3::NEG_Z).to_degrees() - 30.0).abs() < 1e-3);
        assert!(top.dir.y > 0.0);
    }

    #[test]
    fn refuses_degenerate_views() {
        assert_eq!(
            Camera::new(Vec3::ONE, Vec3::ONE, Vec3::Y, 40.0, 1.0, 0.0, None).unwrap_err(),
            CameraError::LooksNowhere
        );
        assert_eq!(
            Camera::new(Vec3::ZERO, Vec3::Y, Vec3::Y, 40.0, 1.0, 0.0, None).unwrap_err(),
            CameraError::UpParallel
        );
        assert!(Camera::new(Vec3::ZERO, Vec3::Z, Vec3::Y, 180.0, 1.0, 0.0, None).is_err());
    }

    /// Eight rays in lanes are the one-ray rays bit for bit, pinhole and
    /// thin lens, on film and lens points from a fixed generator (film
    /// corners and centre included, where the normalisation's inputs are
    /// extreme or round).
    #[test]
    fn eight_rays_in_lanes_are_the_one_ray_rays() {
        let mut rng = crate::sampler::Rng::new(20261207, 7);
        let wide = Camera::new(
            Vec3::new(0.3, -2.0, 1.7),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::Z,
            70.0,
            1.5,
            0.0,
            None,
        )
        .unwrap();
        for cam in [
            down_z(5.0, 60.0, 0.0, None),
            down_z(10.0, 40.0, 1.0, Some(4.0)),
            wide,
        ] {
            for round in 0..500 {
                let mut film: [Vec2; PACKET] = std::array::from_fn(|_| rng.next_2d());
                let lens: [Vec2; PACKET] = std::array::from_fn(|_| rng.next_2d());
                if round == 0 {
                    film[..5].copy_from_slice(&[
                        Vec2::ZERO,
                        Vec2::ONE,
                        Vec2::new(1.0, 0.0),
                        Vec2::new(0.0, 1.0),
                        Vec2::splat(0.5),
                    ]);
                }
                let lanes = cam.ray8(&film, &lens);
                for l in 0..PACKET {
                    let one = cam.ray(film[l], lens[l]);
                    let bits = |r: &Ray| {
                        [r.origin, r.dir, r.inv_dir].map(|v| v.to_array().map(f32::to_bits))
                    };
                    assert_eq!(bits(&lanes[l]), bits(&one), "{:?} {:?}", film[l], lens[l]);
                }
            }
        }
    }

    #[test]
    fn thin_lens_rays_meet_on_the_focal_plane() {
        let c = down_z(10.0, 40.0, 1.0, Some(4.0));
        let film = Vec2::new(0.3, 0.6);
        let a = c.ray(film, Vec2::new(0.1, 0.9));
        let b = c.ray(film, Vec2::new(0.8, 0.2));
        let pa = a.at((-4.0 - a.origin.z) / a.dir.z);
        let pb = b.at((-4.0 - b.origin.z) / b.dir.z);
        assert!((pa - pb).length() < 1e-4, "{pa} {pb}");
    }
}
