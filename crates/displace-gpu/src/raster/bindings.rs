//! The bind groups of one draw: a [`Renderer`]'s resources and a
//! [`Draw`]'s uniforms under the frame's [`View`], in group order. Made per
//! draw because the uniforms change with every camera, light and face.

use super::pipelines::{Geometry, Kind, MapShading, Renderer};
use super::uniforms::{plain_frame, FrameUniform};
use super::{Draw, View};
use crate::descriptors::{bind_group, uniform_buffer};
use crate::gpu_map::MapParams;
use crate::{Error, GpuContext, Result};
use displace_core::TraceOptions;
use glam::Vec2;

impl Renderer {
    /// The bind groups of `draw` by this renderer with `view`'s camera and
    /// light, in group order; the view and the depth are checked once per
    /// frame before (`passes::check_frame`).
    pub(super) fn uniforms(
        &self,
        ctx: &GpuContext,
        view: &View,
        draw: &Draw,
    ) -> Result<Vec<wgpu::BindGroup>> {
        match &self.kind {
            Kind::Displaced { shading, geometry } => shading.uniforms(ctx, geometry, view, draw),
            Kind::Plain { frame_layout, .. } => {
                Ok(vec![plain_uniforms(ctx, frame_layout, view, draw)])
            }
        }
    }
}

impl MapShading {
    fn uniforms(
        &self,
        ctx: &GpuContext,
        geometry: &Geometry,
        view: &View,
        draw: &Draw,
    ) -> Result<Vec<wgpu::BindGroup>> {
        let (tiles, uv_shift) = match geometry {
            Geometry::ShellBox { mirrored } => {
                let Some(face) = draw.face() else {
                    return Err(Error::InvalidOption(
                        "a face renderer draws a face, not a mesh's bounds (DrawShape::Face)"
                            .into(),
                    ));
                };
                face.check()?;
                if face.mirrored != *mirrored {
                    return Err(Error::InvalidOption(
                        "the face's handedness differs from the renderer's (Face::mirrored)".into(),
                    ));
                }
                (face.tiles, Vec2::ZERO)
            }
            Geometry::Mesh {
                tiles, uv_shift, ..
            } => (*tiles, *uv_shift),
        };
        let prisms = match geometry {
            Geometry::Mesh {
                prisms: Some(group),
                ..
            } => Some(group.clone()),
            _ => None,
        };
        let opts = TraceOptions {
            method: draw.method,
            iterations: draw.iterations,
            // The fragment's start point is interpolated: let the clip find
            // the shell's face a hair behind it.
            t_min: -1e-3,
            tiles,
            ..TraceOptions::default()
        };
        let params: MapParams = self.map.params(&opts)?;
        let frame = FrameUniform::new(view, draw, uv_shift);
        let params_buf = uniform_buffer(ctx, "raster params", &params);
        let frame_buf = uniform_buffer(ctx, "frame", &frame);
        let map_group = self.map.bind_group(ctx, &params_buf);
        let shade = bind_group(
            ctx,
            "shading",
            &self.shade_group,
            &[
                frame_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&self.normal_view),
                wgpu::BindingResource::TextureView(&self.color_view),
                wgpu::BindingResource::Sampler(&self.sampler),
            ],
        );
        Ok([map_group, shade].into_iter().chain(prisms).collect())
    }
}

/// Group 0 of a plain draw: `view`'s camera and light.
fn plain_uniforms(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    view: &View,
    draw: &Draw,
) -> wgpu::BindGroup {
    let buffer = uniform_buffer(ctx, "plain frame", &plain_frame(view, draw));
    bind_group(ctx, "plain frame", layout, &[buffer.as_entire_binding()])
}
