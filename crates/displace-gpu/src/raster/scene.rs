//! What one draw of the raster path shows ([`Draw`]: where its shell lies,
//! as a planar [`Face`] or a mesh's bounds, and how its fragments trace and
//! shade), whether they march a second time towards the light
//! ([`Shadows`]), and the built-in scene of one face under its camera
//! ([`PlaneScene`]).

use super::View;
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

/// A displaced planar face: it spans `origin + [0, tiles.x] tangent +
/// [0, tiles.y] bitangent`, its shell rising along [`Face::normal`]. The
/// frame listing 8-1 turns the eye vector into texture space with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Face {
    /// Corner of the face at texture coordinate `(0, 0)`.
    pub origin: Vec3,
    /// Edge of one tile along `u`.
    pub tangent: Vec3,
    /// Edge of one tile along `v`.
    pub bitangent: Vec3,
    /// How many tiles of the map the face spans along `tangent` and
    /// `bitangent` (each of those is one tile); other than `[1, 1]` only for
    /// a map baked with repeat addressing.
    pub tiles: [f32; 2],
    /// The face's frame is left-handed: its normal is `bitangent x tangent`
    /// (a scene quad with `flip_v`, whose `v` runs back along its edge).
    /// Drawn only by a renderer made with the same handedness.
    pub mirrored: bool,
}

impl Face {
    /// Unit face normal, `tangent x bitangent` (reversed for a mirrored face).
    pub fn normal(&self) -> Vec3 {
        let n = self.tangent.cross(self.bitangent).normalize();
        if self.mirrored {
            -n
        } else {
            n
        }
    }

    /// The face's own checks (box renderers only).
    pub(super) fn check(&self) -> Result<()> {
        if !(self.origin.is_finite() && self.tangent.is_finite() && self.bitangent.is_finite()) {
            return Err(Error::InvalidOption("face vectors must be finite".into()));
        }
        if self.tangent.cross(self.bitangent).length_squared() == 0.0 {
            return Err(Error::InvalidOption("degenerate face".into()));
        }
        Ok(())
    }
}

/// Where a draw's shell lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DrawShape {
    /// A planar face, drawn as its shell box (`shaders/raster.wgsl`).
    Face(Face),
    /// A mesh, drawn as the shells of its triangles or as plain triangles:
    /// the world box `[min, max]` holding its base surface (a displaced
    /// mesh's shell lies within [`Draw::depth`] of it). The triangles are
    /// the renderer's own; the box only places the draw in the frame's
    /// depth range.
    Mesh {
        /// World box `[min, max]` of the mesh's base surface.
        bounds: [Vec3; 2],
    },
}

/// One draw of a frame: where its shell lies, how deep it is, how its
/// fragments trace (section 8.5's loop) and how they shade at the hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Draw {
    /// The face or the mesh's bounds.
    pub shape: DrawShape,
    /// Shell depth: world height of a texel of value 1 (zero for a plain
    /// draw, which has no shell).
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
    /// What the renderer's 8-bit albedo is multiplied by, with the light's
    /// [`View::light_intensity`]: a scene material's colour (its diffuse
    /// times the light's intensity over pi) can pass 1, and is split into
    /// an albedo in `[0, 1]` and this scale. 1 for the built-in face.
    pub albedo_scale: f32,
    /// Blinn-Phong specular weight.
    pub specular: f32,
    /// Blinn-Phong exponent.
    pub shininess: f32,
}

impl Draw {
    /// The face, for a face draw.
    pub fn face(&self) -> Option<&Face> {
        match &self.shape {
            DrawShape::Face(face) => Some(face),
            DrawShape::Mesh { .. } => None,
        }
    }

    /// Corners of a box holding all this draw can put on screen: the face's
    /// shell box, or a mesh's bounds grown by the shell depth.
    pub fn shell_corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|c| {
            let bit = |k: usize| ((c >> k) & 1) as f32;
            match &self.shape {
                DrawShape::Mesh { bounds: [lo, hi] } => {
                    let grow = Vec3::splat(self.depth.abs());
                    let (lo, hi) = (*lo - grow, *hi + grow);
                    lo + (hi - lo) * Vec3::new(bit(0), bit(1), bit(2))
                }
                DrawShape::Face(f) => {
                    f.origin
                        + f.tangent * (bit(0) * f.tiles[0])
                        + f.bitangent * (bit(1) * f.tiles[1])
                        + f.normal() * (self.depth * bit(2))
                }
            }
        })
    }

    /// How far past the camera's target this draw may reach, as two
    /// lengths [`View::view_proj`] adds to the camera distance, for the
    /// near and far planes of a view without a depth range: the face's
    /// edges (all its tiles), or a mesh box's sides, whose sum is at least
    /// its diagonal (and for a face's box the same as the face's).
    pub fn reach(&self) -> [f32; 2] {
        match &self.shape {
            DrawShape::Face(f) => [
                f.tangent.length() * f.tiles[0],
                f.bitangent.length() * f.tiles[1],
            ],
            DrawShape::Mesh { bounds: [lo, hi] } => {
                let sides = (*hi - *lo).abs();
                [sides.x + sides.y, sides.z]
            }
        }
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
}

/// One draw under its own view: a displaced planar face, a pinhole camera
/// and a point light, as the built-in scene of `displace gpu-render` is.
/// A frame of several draws is one [`View`] and a list of [`Draw`]s
/// ([`super::render_faces`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneScene {
    /// The image, camera and light.
    pub view: View,
    /// The face (or mesh bounds), its depth, trace and shading.
    pub draw: Draw,
}

impl PlaneScene {
    /// The face of `map`'s extent at the origin in the xy plane (z up),
    /// seen obliquely, lit from above one corner.
    pub fn for_map(map: &DisplacementMap, size: [u32; 2]) -> Self {
        let e = map.extent;
        let centre = Vec3::new(e.sx * 0.5, e.sy * 0.5, 0.0);
        let reach = e.sx.max(e.sy);
        let view = View {
            size,
            eye: centre + Vec3::new(-0.35, -1.0, 0.8) * reach,
            target: centre,
            up: Vec3::Z,
            fov_y_degrees: 45.0,
            depth_range: None,
            light: centre + Vec3::new(-1.0, 0.4, 1.2) * reach,
            light_intensity: 1.0,
            falloff: false,
        };
        let face = Face {
            origin: Vec3::ZERO,
            tangent: Vec3::new(e.sx, 0.0, 0.0),
            bitangent: Vec3::new(0.0, e.sy, 0.0),
            tiles: [1.0, 1.0],
            mirrored: false,
        };
        let draw = Draw {
            shape: DrawShape::Face(face),
            depth: e.sz,
            method: Method::Sphere,
            iterations: 64,
            shadows: Shadows::Hard,
            penumbra_k: 8.0,
            ambient: 0.15,
            albedo_scale: 1.0,
            specular: 0.25,
            shininess: 32.0,
        };
        Self { view, draw }
    }

    /// The camera's view-projection matrix, with near and far planes from
    /// the view's depth range or from this draw's shell.
    pub fn view_proj(&self) -> Mat4 {
        self.view.view_proj(self.draw.reach())
    }

    /// The face's camera ray through the centre of pixel `(x, y)` in map
    /// space (depth units), as the rasteriser samples it; `None` for a mesh
    /// draw, which has no one texture-space frame.
    pub fn pixel_ray(&self, map: &DisplacementMap, x: u32, y: u32) -> Option<MapRay> {
        let face = self.draw.face()?;
        let [w, h] = self.view.size;
        let inv = self.view_proj().inverse();
        let ndc_x = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
        let ndc_y = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
        let far = inv.project_point3(Vec3::new(ndc_x, ndc_y, 1.0));
        let [ax, ay] = map.aspect();
        let n = face.normal();
        let to_map = |v: Vec3| {
            Vec3::new(
                v.dot(face.tangent) / face.tangent.length_squared() * ax,
                v.dot(face.bitangent) / face.bitangent.length_squared() * ay,
                v.dot(n) / self.draw.depth,
            )
        };
        let eye = self.view.eye;
        Some(MapRay::new(to_map(eye - face.origin), to_map(far - eye)))
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

    /// `scene()`'s face.
    pub(in crate::raster) fn face() -> Face {
        *scene().draw.face().unwrap()
    }

    /// `scene()`'s draw with `face` in place of its own.
    pub(in crate::raster) fn draw_of(face: Face) -> Draw {
        Draw {
            shape: DrawShape::Face(face),
            ..scene().draw
        }
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn for_map_spans_the_maps_extent() {
        let s = scene();
        let f = face();
        assert_eq!(f.tangent, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(f.bitangent, Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(s.draw.depth, 0.25);
        assert_eq!(s.view.target, Vec3::new(1.0, 0.5, 0.0));
        assert!(close(f.normal(), Vec3::Z));
    }

    #[test]
    fn a_mirrored_face_turns_its_normal() {
        let f = Face {
            mirrored: true,
            ..face()
        };
        assert!(close(f.normal(), -Vec3::Z));
    }

    #[test]
    fn the_face_shell_box_spans_its_tiles_and_depth() {
        let f = Face {
            tiles: [3.0, 2.0],
            origin: Vec3::new(1.0, 0.0, 0.0),
            ..face()
        };
        let c = draw_of(f).shell_corners();
        assert!(close(c[0], f.origin));
        assert!(close(c[1], f.origin + Vec3::new(6.0, 0.0, 0.0)));
        assert!(close(c[2], f.origin + Vec3::new(0.0, 2.0, 0.0)));
        assert!(close(c[4], f.origin + Vec3::new(0.0, 0.0, 0.25)));
        assert!(close(c[7], f.origin + Vec3::new(6.0, 2.0, 0.25)));
    }

    #[test]
    fn mesh_bounds_grow_by_the_shell_depth() {
        let d = Draw {
            shape: DrawShape::Mesh {
                bounds: [Vec3::ZERO, Vec3::ONE],
            },
            depth: -0.5,
            ..scene().draw
        };
        let c = d.shell_corners();
        assert!(close(c[0], Vec3::splat(-0.5)));
        assert!(close(c[7], Vec3::splat(1.5)));
        assert!(close(c[3], Vec3::new(1.5, 1.5, -0.5)));
        assert!(d.face().is_none());
    }

    /// A face and a mesh of its box reach as far, so the one projection a
    /// view without depth range gets does not depend on how it is drawn.
    #[test]
    fn a_face_and_its_box_reach_alike() {
        let s = scene();
        let f = face();
        let corners = s.draw.shell_corners();
        let lo = corners.iter().fold(Vec3::INFINITY, |a, &c| a.min(c));
        let hi = corners.iter().fold(Vec3::NEG_INFINITY, |a, &c| a.max(c));
        let flat = Draw {
            shape: DrawShape::Mesh {
                bounds: [lo, hi - f.normal() * s.draw.depth],
            },
            ..s.draw
        };
        let sum = |r: [f32; 2]| r[0] + r[1];
        assert_eq!(sum(flat.reach()), sum(s.draw.reach()));
        assert_eq!(s.draw.reach(), [2.0, 1.0]);
    }

    #[test]
    fn pixel_rays_start_at_the_eye_in_map_space() {
        let s = scene();
        let height = HeightMap::new(4, 4, vec![0.0; 16], Address::Clamp).unwrap();
        let extent = Extent::new(2.0, 1.0, 0.25).unwrap();
        let map = bake(&height, &BakeOptions::new([4, 4, 2], extent)).unwrap();
        let ray = s.pixel_ray(&map, 32, 16).unwrap();
        let [ax, ay] = map.aspect();
        let e = s.view.eye;
        let want = Vec3::new(e.x / 2.0 * ax, e.y * ay, e.z / 0.25);
        assert!(close(ray.origin, want), "{:?}", ray.origin);
        let mesh = PlaneScene {
            draw: Draw {
                shape: DrawShape::Mesh {
                    bounds: [Vec3::ZERO, Vec3::ONE],
                },
                ..s.draw
            },
            ..s
        };
        assert!(mesh.pixel_ray(&map, 0, 0).is_none());
    }

    #[test]
    fn checks_refuse_bad_depths_and_faces() {
        let d = scene().draw;
        assert!(d.check_depth().is_ok());
        assert!(Draw { depth: 0.0, ..d }.check_depth().is_err());
        assert!(Draw {
            depth: f32::NAN,
            ..d
        }
        .check_depth()
        .is_err());
        let f = face();
        assert!(f.check().is_ok());
        let flat = Face {
            bitangent: f.tangent,
            ..f
        };
        assert!(flat.check().is_err());
        let lost = Face {
            origin: Vec3::INFINITY,
            ..f
        };
        assert!(lost.check().is_err());
    }
}
