//! The raster path: one displaced planar face drawn as its shell box with
//! Donnelly's vertex and fragment stages (`shaders/raster.wgsl`), or a mesh
//! drawn as the shells of its triangles ([`crate::mesh`],
//! `shaders/mesh.wgsl`), and a scene's non-displaced shapes as plain
//! triangles ([`crate::plain`], `shaders/plain.wgsl`) in the same depth
//! buffer, rendered offscreen, with a UV AOV (uv, hit kind, t) beside the
//! colour so renders can be checked against the CPU trace pixel by pixel.
//!
//! One job a module: what a draw shows (`scene`: a face or a mesh's
//! bounds, its trace and shading) and the camera and light a frame's draws
//! share (`camera`), its uniforms as the WGSL lays them
//! out (`uniforms`), the pipelines and their per-map resources
//! (`pipelines`), a draw's bind groups (`bindings`), the passes
//! (`passes`), the render targets and their readback (`targets`), the
//! shading textures (`textures`) and a mesh shell's vertex layout
//! (`vertex`).

mod bindings;
mod camera;
mod passes;
mod pipelines;
mod scene;
mod targets;
mod textures;
mod uniforms;
mod vertex;

pub use camera::View;
pub use passes::{encode_faces, render_faces, shared_depth_range};
pub use pipelines::Renderer;
pub(crate) use pipelines::{Colour, Shape as RasterShape};
pub use scene::{Draw, DrawShape, Face, PlaneScene, Shadows, MAX_IMAGE_EDGE};
pub(crate) use targets::copy_to_readback;
pub use targets::{Image, Targets, COLOR_FORMAT, DEVICE_BYTES_PER_PIXEL, READBACK_BYTES_PER_PIXEL};
pub use textures::checker_mips;
pub(crate) use textures::texture_2d;
pub use uniforms::FrameUniform;
