//! Scene files for tests, built from the parts they share, so that each
//! test states only what it varies. Every scene has one material, `m`,
//! which every shape uses; tables come out in the order they are added.

use std::fmt::Write;

/// The TOML text of a scene under construction.
#[derive(Clone, Debug)]
pub struct SceneToml(String);

impl SceneToml {
    /// `[image]` of `width x height` pixels and `spp` samples per pixel.
    pub fn new(width: u32, height: u32, spp: u32) -> Self {
        Self(format!(
            "[image]\nwidth = {width}\nheight = {height}\nspp = {spp}\n"
        ))
    }

    /// More `key = value` lines for the table added last.
    pub fn with(mut self, lines: &str) -> Self {
        writeln!(self.0, "{lines}").unwrap();
        self
    }

    /// A camera at `position` looking at the origin, with the default up.
    pub fn camera(self, position: &str, vfov: f32) -> Self {
        self.with(&format!(
            "[camera]\nposition = {position}\nlook_at = [0, 0, 0]\nvfov = {vfov}"
        ))
    }

    /// A camera `height` above the origin looking straight down (+y), with
    /// +z up in the image.
    pub fn camera_above(self, height: f32, vfov: f32) -> Self {
        self.with(&format!(
            "[camera]\nposition = [0, {height}, 0]\nlook_at = [0, 0, 0]\nup = [0, 0, 1]\nvfov = {vfov}"
        ))
    }

    /// Material `m`, a table body such as `type = "phong"` and its keys.
    pub fn material(self, body: &str) -> Self {
        self.with(&format!("[materials.m]\n{body}"))
    }

    /// Material `m`: Lambertian of albedo `color` (`[r, g, b]`).
    pub fn lambert(self, color: &str) -> Self {
        self.material(&format!("type = \"lambert\"\ncolor = {color}"))
    }

    /// A light, as the body of a `[[lights]]` table.
    pub fn light(self, body: &str) -> Self {
        self.with(&format!("[[lights]]\n{body}"))
    }

    /// A point light at `position` of `intensity` (`[r, g, b]` each).
    pub fn point_light(self, position: &str, intensity: &str) -> Self {
        self.light(&format!(
            "type = \"point\"\nposition = {position}\nintensity = {intensity}"
        ))
    }

    /// A shape of material `m`, the body of a `[[shapes]]` table without
    /// its material.
    pub fn shape(self, body: &str) -> Self {
        self.with(&format!("[[shapes]]\n{body}\nmaterial = \"m\""))
    }

    /// The 2 x 2 quad over `[-1, 1]` in x and z at height `y`, facing +y,
    /// with u along +z and v along +x.
    pub fn quad(self, y: f32) -> Self {
        self.shape(&format!(
            "type = \"quad\"\norigin = [-1, {y}, -1]\nedge_u = [0, 0, 2]\nedge_v = [2, 0, 0]"
        ))
    }

    /// A 100 x 100 plane through the origin facing +y: the whole view of
    /// a narrow camera above it.
    pub fn plane(self) -> Self {
        self.shape(
            "type = \"quad\"\norigin = [-50, 0, -50]\nedge_u = [0, 0, 100]\nedge_v = [100, 0, 0]",
        )
    }

    /// Displaces the shape added last: `body` is the `[shapes.displacement]`
    /// table's.
    pub fn displaced(self, body: &str) -> Self {
        self.with(&format!("[shapes.displacement]\n{body}"))
    }

    pub fn text(&self) -> &str {
        &self.0
    }
}
