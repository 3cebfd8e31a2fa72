//! The vertex buffer layout of a mesh's shell ([`ShellVertex`]): what the
//! mesh pipeline's vertex stage (section 8.4) reads per prism corner.

use crate::curved::CurvedVertex;
use crate::mesh::ShellVertex;

/// One [`CurvedVertex`] per vertex: a world position and its prism.
pub(super) const CURVED_VERTEX_LAYOUT: wgpu::VertexBufferLayout<'static> =
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<CurvedVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32],
    };

/// One [`ShellVertex`] per vertex, tightly strided.
pub(super) const SHELL_VERTEX_LAYOUT: wgpu::VertexBufferLayout<'static> =
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<ShellVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &SHELL_VERTEX_ATTRIBUTES,
    };

/// [`ShellVertex`]'s fields at their offsets (the struct pads the normal to
/// 16 bytes, which `vertex_attr_array!` would not know).
const SHELL_VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 6] = {
    use std::mem::offset_of;
    use wgpu::VertexFormat as F;
    const fn at(format: F, offset: usize, shader_location: u32) -> wgpu::VertexAttribute {
        wgpu::VertexAttribute {
            format,
            offset: offset as u64,
            shader_location,
        }
    }
    [
        at(F::Float32x3, offset_of!(ShellVertex, position), 0),
        at(F::Float32, offset_of!(ShellVertex, lift), 1),
        at(F::Float32x3, offset_of!(ShellVertex, normal), 2),
        at(F::Float32x4, offset_of!(ShellVertex, tangent), 3),
        at(F::Float32x2, offset_of!(ShellVertex, uv), 4),
        at(F::Float32x2, offset_of!(ShellVertex, scale), 5),
    ]
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attributes_lie_inside_the_vertex_in_location_order() {
        let stride = SHELL_VERTEX_LAYOUT.array_stride;
        assert_eq!(stride, std::mem::size_of::<ShellVertex>() as u64);
        for (k, a) in SHELL_VERTEX_ATTRIBUTES.iter().enumerate() {
            assert_eq!(a.shader_location, k as u32);
            assert!(a.offset + a.format.size() <= stride, "{a:?}");
        }
        let mut by_offset = SHELL_VERTEX_ATTRIBUTES.map(|a| (a.offset, a.format.size()));
        by_offset.sort();
        for w in by_offset.windows(2) {
            assert!(w[0].0 + w[0].1 <= w[1].0, "attributes overlap: {w:?}");
        }
    }
}
