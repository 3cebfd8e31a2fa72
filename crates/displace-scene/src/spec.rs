//! The scene file as written (TOML), before validation. Every table denies
//! unknown keys: a misspelt key is an error, never silently ignored.
//! `docs/scenes.md` documents each key, its units and its default.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer};
use std::collections::BTreeMap;

/// A point, direction or colour as the file writes it, `[x, y, z]`.
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

/// A whole scene file (docs/scenes.md): one table per part.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// `[image]`.
    pub image: ImageSpec,
    /// `[camera]`.
    pub camera: CameraSpec,
    /// `[materials.NAME]`, named by the shapes.
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    /// `[[lights]]`.
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    /// `[[shapes]]`.
    #[serde(default)]
    pub shapes: Vec<ShapeSpec>,
    /// Frames over which the camera and a light move (docs/scenes.md).
    pub animation: Option<AnimationSpec>,
}

/// `[animation]`: checked by [`super::animation::Animation::new`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnimationSpec {
    /// Frame count (1 to 2^20); frames are `0..frames`.
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
    /// The frame this key holds at.
    pub frame: i64,
    /// The eye at that frame.
    #[serde(default, deserialize_with = "exact3_opt")]
    pub position: Option<V3>,
    /// The look-at point at that frame.
    #[serde(default, deserialize_with = "exact3_opt")]
    pub look_at: Option<V3>,
}

/// A keyframe of a light's position.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathKeySpec {
    /// The frame this key holds at.
    pub frame: i64,
    /// The light's position (an area light's origin) at that frame.
    #[serde(deserialize_with = "exact3")]
    pub position: V3,
}

/// `[image]`: size, sampling and light transport.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSpec {
    /// Image width in pixels (at most 2^28 pixels in all).
    pub width: i64,
    /// Image height in pixels.
    pub height: i64,
    /// Samples per pixel (1 to 65536), stratified over the pixel.
    #[serde(default = "default_spp")]
    pub spp: i64,
    /// Whitted: reflection bounces; path: bounces of any kind (0 to 64).
    #[serde(default = "default_max_depth")]
    pub max_depth: i64,
    /// Seed of the per-sample random numbers: a render is a pure function of
    /// the scene and the seed.
    #[serde(default)]
    pub seed: u64,
    /// Whitted: shadow rays per area light at each hit, stratified (Cook,
    /// Porter and Carpenter 1984).
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
    /// The path integrator's numbers: `"sobol"` (the default) or
    /// `"independent"`.
    #[serde(default = "default_sampler")]
    pub sampler: String,
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
fn default_sampler() -> String {
    "sobol".into()
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

/// `[camera]`: a pinhole or thin-lens camera.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// The eye point.
    #[serde(deserialize_with = "exact3")]
    pub position: V3,
    /// The point at the image centre; must differ from `position`.
    #[serde(deserialize_with = "exact3")]
    pub look_at: V3,
    /// Up direction; must not be parallel to the view.
    #[serde(default = "default_up", deserialize_with = "exact3")]
    pub up: V3,
    /// Degrees.
    #[serde(default = "default_vfov")]
    pub vfov: f32,
    /// Lens diameter, world units; 0 is a pinhole.
    #[serde(default)]
    pub aperture: f32,
    /// Distance of the plane in focus (default: `|look_at - position|`).
    pub focus_distance: Option<f32>,
}

fn default_up() -> V3 {
    [0.0, 1.0, 0.0]
}
fn default_vfov() -> f32 {
    40.0
}

/// `[materials.NAME]`, by its `type`.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum MaterialSpec {
    /// Lambertian diffuse.
    Lambert {
        /// Albedo.
        color: V3,
        /// Colour map (sRGB) multiplying `color`.
        texture: Option<String>,
        /// Emitted radiance (both sides).
        #[serde(default)]
        emission: V3,
    },
    /// Lambertian plus an energy-normalised Blinn-Phong highlight.
    Phong {
        /// Albedo.
        color: V3,
        /// Colour map (sRGB) multiplying `color`.
        texture: Option<String>,
        /// Highlight colour, `specular (n + 8) / (8 pi) cos^n`.
        specular: V3,
        /// Blinn-Phong exponent `n`.
        shininess: f32,
        /// Emitted radiance (both sides).
        #[serde(default)]
        emission: V3,
    },
    /// Perfect reflection, Whitted's reflection ray.
    Mirror {
        /// Reflectance.
        #[serde(default = "one")]
        color: V3,
        /// An optional diffuse part.
        #[serde(default)]
        diffuse: V3,
        /// Emitted radiance (both sides).
        #[serde(default)]
        emission: V3,
    },
    /// Distributed reflection (Cook, Porter and Carpenter 1984): one ray per
    /// sample in a Phong lobe around the mirror direction.
    Glossy {
        /// Reflectance.
        #[serde(default = "one")]
        color: V3,
        /// In `(0, 1]`: the lobe's exponent is `2 / roughness^2 - 2`.
        roughness: f32,
        /// An optional diffuse part.
        #[serde(default)]
        diffuse: V3,
        /// Emitted radiance (both sides).
        #[serde(default)]
        emission: V3,
    },
}

fn one() -> V3 {
    [1.0; 3]
}

/// `[[lights]]`, by its `type`.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum LightSpec {
    /// A point light: hard shadows.
    Point {
        /// Where it is.
        position: V3,
        /// Radiant intensity (W/sr per channel).
        intensity: V3,
        /// As for area lights.
        #[serde(default)]
        fill: bool,
    },
    /// A one-sided parallelogram: soft shadows from stratified shadow rays.
    Area {
        /// Corner.
        origin: V3,
        /// First edge.
        edge_u: V3,
        /// Second edge; the light shines towards `edge_u x edge_v`.
        edge_v: V3,
        /// Emitted radiance.
        radiance: V3,
        /// Whether the camera and reflections see the light's quad.
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

/// `[[shapes]]`, by its `type`.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ShapeSpec {
    /// A parallelogram `origin + a edge_u + b edge_v`, texture coordinate
    /// `(a, b)`.
    Quad {
        /// Corner at `(0, 0)`.
        origin: V3,
        /// Edge along `u`.
        edge_u: V3,
        /// Edge along `v`.
        edge_v: V3,
        /// Name of its material.
        material: String,
        /// Its displacement, if any.
        displacement: Option<DisplacementSpec>,
    },
    /// A triangle, displaced as the prism over it.
    Triangle {
        /// Corners.
        vertices: [V3; 3],
        /// Texture coordinates of the corners (`[[0,0],[1,0],[0,1]]`).
        uvs: Option<[[f32; 2]; 3]>,
        /// Name of its material.
        material: String,
        /// Its displacement, if any.
        displacement: Option<DisplacementSpec>,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: V3,
        /// Radius.
        radius: f32,
        /// Name of its material.
        material: String,
    },
    /// An axis-aligned box of six quads, turned about its vertical centre line.
    Box {
        /// Lower corner.
        min: V3,
        /// Upper corner.
        max: V3,
        /// Turn about the vertical, degrees.
        #[serde(default)]
        rotate_y: f32,
        /// Name of its material.
        material: String,
    },
    /// An OBJ mesh or a built-in (`builtin:plane`, `cube`, `sphere`, `torus`).
    Mesh {
        /// The OBJ file, relative to the scene file, or `builtin:NAME`.
        path: String,
        /// Moved by this after scaling and turning.
        #[serde(default)]
        translate: V3,
        /// Uniform scale.
        #[serde(default = "unit_scale")]
        scale: f32,
        /// Turn about the vertical, degrees.
        #[serde(default)]
        rotate_y: f32,
        /// Name of its material.
        material: String,
        /// Its displacement, if any (the mesh needs texture coordinates).
        displacement: Option<DisplacementSpec>,
        /// For an OBJ without normals: neighbouring faces meeting at up to
        /// this angle (degrees) share smooth vertex normals; steeper edges
        /// stay creases ([`crate::vertex_normals`]).
        #[serde(default = "default_crease_angle")]
        crease_angle: f32,
    },
}

fn unit_scale() -> f32 {
    1.0
}

fn default_crease_angle() -> f32 {
    crate::vertex_normals::DEFAULT_CREASE_DEGREES
}

/// `height_range` of a displacement: a name (`"auto"`) or `[lo, hi]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum HeightRangeSpec {
    /// `"auto"` (or `"lo,hi"`).
    Named(String),
    /// `[lo, hi]` in the file's values.
    Span([f64; 2]),
}

/// `displacement = { ... }` of a quad, triangle or mesh.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplacementSpec {
    /// A height file (PNG, JPEG, TIFF or EXR, relative to the scene file) or a generator
    /// (`gen:studded?period=8`).
    pub height: String,
    /// Texels of a generated height map.
    #[serde(default = "default_height_size")]
    pub height_size: [i64; 2],
    /// World units along the face normal; 0 means no displacement.
    pub depth: f32,
    /// Distance-map resolution `[w, h, d]` voxels.
    #[serde(default = "default_map_size")]
    pub map_size: [i64; 3],
    /// `"clamp"` or `"repeat"` (needed for `tiles` other than 1).
    #[serde(default = "default_address")]
    pub address: String,
    /// Which of the file's values become heights 0 and 1: `"auto"` (its
    /// lowest and highest) or `[lo, hi]` (an elevation model's metres);
    /// absent, as stored (8/16-bit codes by their full scale, floats in
    /// [0, 1]).
    pub height_range: Option<HeightRangeSpec>,
    /// Tiles of the map across the face (meshes: multiplies their coordinates).
    #[serde(default = "default_tiles")]
    pub tiles: [f32; 2],
    /// `"sphere"`, `"sphere-fixed"` (Donnelly's fixed loop, listing 8-2) or
    /// `"exact"`.
    #[serde(default = "default_method")]
    pub method: String,
    /// Sphere-tracing steps (the fixed count of `sphere-fixed`).
    #[serde(default = "default_iterations")]
    pub iterations: i64,
    /// Colour map (sRGB) at the displaced texture coordinate.
    pub color_texture: Option<String>,
    /// Replaces the computed normal map: RGB `0.5 n + 0.5`, map space, +Y up.
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
