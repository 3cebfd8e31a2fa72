//! The scene file as written (TOML), before validation. Every table denies
//! unknown keys: a misspelt key is an error, never silently ignored.
//! `docs/scenes.md` documents each key, its units and its default.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer};
use std::collections::BTreeMap;

pub type V3 = [f32; 3];

/// Exactly `[x, y, z]`. A fixed-size array read straight from a TOML array
/// stops after its three elements and ignores the rest, so `[1, 2, 3, 4]`
/// (or `[1, 2, 3, "junk"]`) would pass as `[1, 2, 3]`; the tables of tagged
/// enums (materials, lights, shapes) are buffered first and already refuse
/// extra elements, the plain tables (`[image]`, `[camera]`) need this.
fn exact3<'de, D: Deserializer<'de>>(d: D) -> Result<V3, D::Error> {
    let v = Vec::<f32>::deserialize(d)?;
    V3::try_from(v.as_slice())
        .map_err(|_| D::Error::invalid_length(v.len(), &"exactly 3 numbers [x, y, z]"))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    pub image: ImageSpec,
    pub camera: CameraSpec,
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    #[serde(default)]
    pub shapes: Vec<ShapeSpec>,
    /// Frames over which the camera and a light move (docs/scenes.md).
    pub animation: Option<AnimationSpec>,
}

/// `[animation]`: checked by [`super::animation::Animation::new`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnimationSpec {
    pub frames: i64,
    /// Frames per second, for whoever encodes the frames into a video.
    #[serde(default = "default_fps")]
    pub fps: f32,
    /// `"linear"` or `"catmull-rom"`.
    #[serde(default = "default_interpolation")]
    pub interpolation: String,
    /// Camera keyframes, in increasing frame order.
    #[serde(default)]
    pub camera: Vec<CameraKeySpec>,
    /// Which `[[lights]]` entry `light_path` moves.
    #[serde(default)]
    pub light: i64,
    /// Keyframes of that light's position (area lights: their origin).
    #[serde(default)]
    pub light_path: Vec<PathKeySpec>,
}

fn default_fps() -> f32 {
    24.0
}
fn default_interpolation() -> String {
    "linear".into()
}

/// A camera keyframe; a key may set the position, the look-at or both.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKeySpec {
    pub frame: i64,
    #[serde(default, deserialize_with = "exact3_opt")]
    pub position: Option<V3>,
    #[serde(default, deserialize_with = "exact3_opt")]
    pub look_at: Option<V3>,
}

/// A keyframe of a light's position.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathKeySpec {
    pub frame: i64,
    #[serde(deserialize_with = "exact3")]
    pub position: V3,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSpec {
    pub width: i64,
    pub height: i64,
    #[serde(default = "default_spp")]
    pub spp: i64,
    #[serde(default = "default_max_depth")]
    pub max_depth: i64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_shadow_samples")]
    pub shadow_samples: i64,
    /// `None` when the file leaves it out (black, unless `environment`).
    #[serde(default, deserialize_with = "exact3_opt")]
    pub background: Option<V3>,
    /// `"whitted"` (the default) or `"path"`.
    #[serde(default = "default_integrator")]
    pub integrator: String,
    /// The path integrator's estimators: `"mis"` (the default), `"light"`
    /// or `"bsdf"`.
    #[serde(default = "default_sampling")]
    pub sampling: String,
    /// An equirectangular, linear OpenEXR environment map, relative to the
    /// scene file.
    pub environment: Option<String>,
}

/// [`exact3`] for an optional key.
fn exact3_opt<'de, D: Deserializer<'de>>(d: D) -> Result<Option<V3>, D::Error> {
    exact3(d).map(Some)
}

fn default_integrator() -> String {
    "whitted".into()
}
fn default_sampling() -> String {
    "mis".into()
}

fn default_spp() -> i64 {
    16
}
fn default_max_depth() -> i64 {
    4
}
fn default_shadow_samples() -> i64 {
    16
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    #[serde(deserialize_with = "exact3")]
    pub position: V3,
    #[serde(deserialize_with = "exact3")]
    pub look_at: V3,
    #[serde(default = "default_up", deserialize_with = "exact3")]
    pub up: V3,
    /// Degrees.
    #[serde(default = "default_vfov")]
    pub vfov: f32,
    /// Lens diameter, world units; 0 is a pinhole.
    #[serde(default)]
    pub aperture: f32,
    pub focus_distance: Option<f32>,
}

fn default_up() -> V3 {
    [0.0, 1.0, 0.0]
}
fn default_vfov() -> f32 {
    40.0
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum MaterialSpec {
    Lambert {
        color: V3,
        texture: Option<String>,
        #[serde(default)]
        emission: V3,
    },
    Phong {
        color: V3,
        texture: Option<String>,
        specular: V3,
        shininess: f32,
        #[serde(default)]
        emission: V3,
    },
    Mirror {
        #[serde(default = "one")]
        color: V3,
        #[serde(default)]
        diffuse: V3,
        #[serde(default)]
        emission: V3,
    },
    Glossy {
        #[serde(default = "one")]
        color: V3,
        roughness: f32,
        #[serde(default)]
        diffuse: V3,
        #[serde(default)]
        emission: V3,
    },
}

fn one() -> V3 {
    [1.0; 3]
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum LightSpec {
    Point {
        position: V3,
        intensity: V3,
        /// As for area lights.
        #[serde(default)]
        fill: bool,
    },
    Area {
        origin: V3,
        edge_u: V3,
        edge_v: V3,
        radiance: V3,
        #[serde(default = "yes")]
        visible: bool,
        /// A fill light standing in for indirect light: the path
        /// integrator, which computes indirect light, leaves it out.
        #[serde(default)]
        fill: bool,
    },
}

fn yes() -> bool {
    true
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ShapeSpec {
    Quad {
        origin: V3,
        edge_u: V3,
        edge_v: V3,
        material: String,
        displacement: Option<DisplacementSpec>,
    },
    Triangle {
        vertices: [V3; 3],
        uvs: Option<[[f32; 2]; 3]>,
        material: String,
        displacement: Option<DisplacementSpec>,
    },
    Sphere {
        center: V3,
        radius: f32,
        material: String,
    },
    Box {
        min: V3,
        max: V3,
        #[serde(default)]
        rotate_y: f32,
        material: String,
    },
    Mesh {
        path: String,
        #[serde(default)]
        translate: V3,
        #[serde(default = "unit_scale")]
        scale: f32,
        #[serde(default)]
        rotate_y: f32,
        material: String,
        displacement: Option<DisplacementSpec>,
    },
}

fn unit_scale() -> f32 {
    1.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplacementSpec {
    /// A height file (PNG/EXR, relative to the scene file) or a generator
    /// (`gen:studded?period=8`).
    pub height: String,
    /// Texels of a generated height map.
    #[serde(default = "default_height_size")]
    pub height_size: [i64; 2],
    /// World units along the face normal; 0 means no displacement.
    pub depth: f32,
    #[serde(default = "default_map_size")]
    pub map_size: [i64; 3],
    #[serde(default = "default_address")]
    pub address: String,
    #[serde(default = "default_tiles")]
    pub tiles: [f32; 2],
    #[serde(default = "default_method")]
    pub method: String,
    #[serde(default = "default_iterations")]
    pub iterations: i64,
    pub color_texture: Option<String>,
    pub normal_map: Option<String>,
    /// Quads only: run `v` from the far edge back to `origin`, so that an
    /// image (row 0 = `v = 0`, the top row) reads unmirrored on a face whose
    /// normal points at the viewer.
    #[serde(default)]
    pub flip_v: bool,
}

fn default_height_size() -> [i64; 2] {
    [256, 256]
}
fn default_map_size() -> [i64; 3] {
    [128, 128, 16]
}
fn default_address() -> String {
    "clamp".into()
}
fn default_tiles() -> [f32; 2] {
    [1.0, 1.0]
}
fn default_method() -> String {
    "sphere".into()
}
fn default_iterations() -> i64 {
    64
}
