//! The per-draw uniforms of the raster path, laid out as the WGSL reads
//! them: a [`View`] and one [`Draw`] become the `Frame` of
//! `shaders/raster.wgsl` and `shaders/mesh.wgsl` (listing 8-1's and 8-2's
//! inputs: the matrices, the eye and light, the face's tangent frame) or
//! the [`PlainFrame`] of `shaders/plain.wgsl`.

use super::{Draw, View};
use crate::plain::PlainFrame;
use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};

/// Mirror of WGSL `Frame` (raster.wgsl): the camera, the light and the
/// face's tangent frame that the vertex stage (listing 8-1) needs to place
/// the shell and turn the eye vector into texture space, and the shading
/// the fragment stage (listing 8-2) applies at the hit.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light: [f32; 4],
    face_origin: [f32; 4],
    face_t: [f32; 4],
    face_b: [f32; 4],
    face_n: [f32; 4],
    inv_bump_depth: f32,
    shadows: u32,
    penumbra_k: f32,
    ambient: f32,
    specular: f32,
    shininess: f32,
    light_intensity: f32,
    falloff: u32,
    uv_shift: [f32; 2],
    _pad: [f32; 2],
}

/// A point (`w` 1) or direction (`w` 0) as WGSL's `vec4<f32>`.
fn v4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

impl FrameUniform {
    /// The frame of `draw` under `view` for a displaced draw whose texture
    /// coordinates are shifted by `uv_shift` (a mesh's; zero for a face).
    /// A mesh draw has no face frame: `mesh.wgsl` does not read it, and it
    /// is left zero.
    pub(super) fn new(view: &View, draw: &Draw, uv_shift: Vec2) -> Self {
        let (origin, t, b, n) = match draw.face() {
            Some(f) => (f.origin, f.tangent, f.bitangent, f.normal()),
            None => (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO),
        };
        Self {
            view_proj: view.view_proj(draw.reach()).to_cols_array_2d(),
            eye: v4(view.eye, 1.0),
            light: v4(view.light, 1.0),
            face_origin: v4(origin, 1.0),
            face_t: v4(t, 0.0),
            face_b: v4(b, 0.0),
            face_n: v4(n, 0.0),
            inv_bump_depth: 1.0 / draw.depth,
            shadows: crate::convention::shadows_code(draw.shadows),
            penumbra_k: draw.penumbra_k,
            ambient: draw.ambient,
            specular: draw.specular,
            shininess: draw.shininess,
            light_intensity: view.light_intensity * draw.albedo_scale,
            falloff: view.falloff as u32,
            uv_shift: uv_shift.to_array(),
            _pad: [0.0; 2],
        }
    }
}

/// The camera and light of `view` for the plain draw `draw`.
pub(super) fn plain_frame(view: &View, draw: &Draw) -> PlainFrame {
    PlainFrame {
        view_proj: view.view_proj(draw.reach()).to_cols_array_2d(),
        eye: v4(view.eye, 1.0),
        light: v4(view.light, 1.0),
        ambient: draw.ambient,
        light_intensity: view.light_intensity * draw.albedo_scale,
        falloff: view.falloff as u32,
        _pad: 0.0,
    }
}

#[cfg(test)]
mod layout_tests {
    #[test]
    fn frame_uniform_matches_wgsl() {
        use super::FrameUniform;
        use crate::shaders::{assert_layout, offsets, raster_source, DistanceTexture};
        assert_layout(
            &raster_source(DistanceTexture::R8Linear),
            "Frame",
            std::mem::size_of::<FrameUniform>(),
            offsets!(FrameUniform {
                view_proj,
                eye,
                light,
                face_origin,
                face_t,
                face_b,
                face_n,
                inv_bump_depth,
                shadows,
                penumbra_k,
                ambient,
                specular,
                shininess,
                light_intensity,
                falloff,
                uv_shift,
                _pad
            }),
        );
    }
}
