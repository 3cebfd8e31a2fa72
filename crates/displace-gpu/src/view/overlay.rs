//! The viewer's text overlay and present pass: status lines rasterised by
//! `ab_glyph` with the bundled font (only when the text changes), and the
//! pass that copies the rendered frame to the window's surface and blends
//! the text over it (`shaders/present.wgsl`).

use crate::descriptors::{
    bind_group, bind_group_layout, cleared_attachment, color_target, frame_uniform_entry,
    pipeline_layout, render_pipeline, shader_module, texture_2d_descriptor, texture_entry,
    uniform_buffer, RenderStages,
};
use crate::shaders::PRESENT;
use crate::{GpuContext, Result};
use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;
use wgpu::util::DeviceExt;

/// Text height in pixels.
const TEXT_PX: f32 = 15.0;
/// Panel margin around the text and its offset from the window's corner.
const MARGIN: u32 = 6;
/// Opacity of the dark panel behind the text.
const PANEL_ALPHA: f32 = 0.6;

/// Status lines as a premultiplied-alpha RGBA8 image: white text on a
/// translucent dark panel. Returns width, height and texels.
pub fn rasterise(lines: &[String]) -> Result<(u32, u32, Vec<u8>)> {
    let font = FontRef::try_from_slice(displace_core::generators::FONT)
        .map_err(|e| crate::Error::InvalidOption(format!("the bundled font is unreadable: {e}")))?;
    let scaled = font.as_scaled(PxScale::from(TEXT_PX));
    let line_step = (scaled.height() + scaled.line_gap()).ceil();
    let widest = lines
        .iter()
        .map(|l| {
            l.chars()
                .map(|c| scaled.h_advance(font.glyph_id(c)))
                .sum::<f32>()
        })
        .fold(0.0f32, f32::max);
    let w = widest.ceil() as u32 + 2 * MARGIN;
    let h = (line_step * lines.len() as f32).ceil() as u32 + 2 * MARGIN;
    let mut coverage = vec![0.0f32; (w * h) as usize];
    for (k, line) in lines.iter().enumerate() {
        let baseline = MARGIN as f32 + scaled.ascent() + k as f32 * line_step;
        let mut x = MARGIN as f32;
        for c in line.chars() {
            let id = font.glyph_id(c);
            let glyph = id.with_scale_and_position(TEXT_PX, point(x, baseline));
            x += scaled.h_advance(id);
            let Some(outline) = font.outline_glyph(glyph) else {
                continue;
            };
            let b = outline.px_bounds();
            outline.draw(|gx, gy, cov| {
                let (i, j) = (b.min.x as i64 + gx as i64, b.min.y as i64 + gy as i64);
                if (0..w as i64).contains(&i) && (0..h as i64).contains(&j) {
                    let c = &mut coverage[(j * w as i64 + i) as usize];
                    *c = c.max(cov.clamp(0.0, 1.0));
                }
            });
        }
    }
    let texels = coverage
        .iter()
        .flat_map(|&cov| {
            // White over the panel, premultiplied.
            let a = cov + (1.0 - cov) * PANEL_ALPHA;
            let e = |v: f32| (v * 255.0).round() as u8;
            [e(cov), e(cov), e(cov), e(a)]
        })
        .collect();
    Ok((w, h, texels))
}

/// Mirror of WGSL `Present`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct PresentUniform {
    rect: [f32; 4],
    out_size: [f32; 2],
    encode_srgb: u32,
    pad: u32,
}

/// Where the present pass draws: a view, its format and its size.
#[derive(Clone, Copy)]
pub struct Output<'a> {
    /// The surface's texture view.
    pub view: &'a wgpu::TextureView,
    /// Its format (a pipeline is built per format).
    pub format: wgpu::TextureFormat,
    /// Its size in pixels.
    pub size: [u32; 2],
}

/// Present pipelines (one pair per output format) and the overlay texture.
pub struct Presenter {
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: HashMap<wgpu::TextureFormat, (wgpu::RenderPipeline, wgpu::RenderPipeline)>,
    overlay: Option<(wgpu::TextureView, [u32; 2])>,
    text: Vec<String>,
}

impl Presenter {
    /// Compiles the present shader; pipelines are made per output format on
    /// first use.
    pub fn new(ctx: &GpuContext) -> Result<Self> {
        ctx.checked("building the present pass", || {
            let module = shader_module(ctx, "present", PRESENT);
            let tex = |binding| {
                texture_entry(
                    binding,
                    wgpu::ShaderStages::FRAGMENT,
                    false,
                    wgpu::TextureViewDimension::D2,
                )
            };
            let layout =
                bind_group_layout(ctx, "present", &[frame_uniform_entry(), tex(1), tex(2)]);
            let pipeline_layout = pipeline_layout(ctx, "present", &[&layout]);
            Self {
                module,
                layout,
                pipeline_layout,
                pipelines: HashMap::new(),
                overlay: None,
                text: Vec::new(),
            }
        })
    }

    /// Replaces the overlay's text; re-rasterised only when it changed.
    pub fn set_text(&mut self, ctx: &GpuContext, lines: &[String]) -> Result<()> {
        if self.overlay.is_some() && self.text == lines {
            return Ok(());
        }
        let (w, h, texels) = rasterise(lines)?;
        let texture = ctx.device.create_texture_with_data(
            &ctx.queue,
            &texture_2d_descriptor(
                "overlay text",
                [w, h],
                1,
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            ),
            wgpu::util::TextureDataOrder::LayerMajor,
            &texels,
        );
        self.overlay = Some((texture.create_view(&Default::default()), [w, h]));
        self.text = lines.to_vec();
        Ok(())
    }

    fn pipelines(
        &mut self,
        ctx: &GpuContext,
        format: wgpu::TextureFormat,
    ) -> Result<&(wgpu::RenderPipeline, wgpu::RenderPipeline)> {
        if !self.pipelines.contains_key(&format) {
            let make = |vs: &str, fs: &str, blend, topology| {
                render_pipeline(
                    ctx,
                    fs,
                    &self.pipeline_layout,
                    RenderStages {
                        module: &self.module,
                        vertex: vs,
                        fragment: fs,
                        buffers: &[],
                        targets: &[color_target(format, blend)],
                    },
                    wgpu::PrimitiveState {
                        topology,
                        ..Default::default()
                    },
                    None,
                )
            };
            let pair = ctx.checked("building the present pipelines", || {
                (
                    make(
                        "vs_frame",
                        "fs_frame",
                        None,
                        wgpu::PrimitiveTopology::TriangleList,
                    ),
                    make(
                        "vs_overlay",
                        "fs_overlay",
                        Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                        wgpu::PrimitiveTopology::TriangleStrip,
                    ),
                )
            })?;
            self.pipelines.insert(format, pair);
        }
        Ok(&self.pipelines[&format])
    }

    /// Records the copy of `frame` (a [`crate::raster::COLOR_FORMAT`]
    /// texture of the output's size) into `output`, and the overlay over it
    /// when `overlay` is set.
    pub fn encode(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        frame: &wgpu::TextureView,
        output: &Output,
        overlay: bool,
    ) -> Result<()> {
        let Output { view, format, size } = *output;
        let Some((overlay_view, [ow, oh])) = self.overlay.clone() else {
            return Err(crate::Error::InvalidOption(
                "the overlay has no text yet".into(),
            ));
        };
        let uniform = PresentUniform {
            rect: [MARGIN as f32, MARGIN as f32, ow as f32, oh as f32],
            out_size: [size[0] as f32, size[1] as f32],
            encode_srgb: (!format.is_srgb()) as u32,
            pad: 0,
        };
        let buffer = uniform_buffer(ctx, "present", &uniform);
        let group = bind_group(
            ctx,
            "present",
            &self.layout,
            &[
                buffer.as_entire_binding(),
                wgpu::BindingResource::TextureView(frame),
                wgpu::BindingResource::TextureView(&overlay_view),
            ],
        );
        let (frame_pipe, overlay_pipe) = self.pipelines(ctx, format)?;
        ctx.checked("presenting", || {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("present"),
                color_attachments: &[cleared_attachment(view, wgpu::Color::BLACK)],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &group, &[]);
            pass.set_pipeline(frame_pipe);
            pass.draw(0..3, 0..1);
            if overlay {
                pass.set_pipeline(overlay_pipe);
                pass.draw(0..4, 0..1);
            }
        })
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn present_uniform_matches_wgsl() {
        use super::PresentUniform;
        use crate::shaders::{assert_layout, offsets, PRESENT};
        assert_layout(
            PRESENT,
            "Present",
            std::mem::size_of::<PresentUniform>(),
            offsets!(PresentUniform {
                rect,
                out_size,
                encode_srgb,
                pad
            }),
        );
    }

    use super::*;

    #[test]
    fn text_is_drawn_on_a_translucent_panel() {
        let (w, h, px) = rasterise(&["depth x1.000".to_string(), "m".to_string()]).unwrap();
        assert_eq!(px.len(), (w * h * 4) as usize);
        assert!(w > 60 && h > 2 * TEXT_PX as u32, "{w}x{h}");
        let alphas: Vec<u8> = px.chunks_exact(4).map(|p| p[3]).collect();
        let panel = (PANEL_ALPHA * 255.0).round() as u8;
        // Corners are bare panel; some texels are fully inked.
        assert_eq!(alphas[0], panel);
        assert_eq!(px[0], 0);
        assert!(px.chunks_exact(4).any(|p| p[0] == 255 && p[3] == 255));
        // Premultiplied: colour never exceeds alpha.
        assert!(px.chunks_exact(4).all(|p| p[0] <= p[3]));
        // More text, wider panel.
        let (w2, _, _) = rasterise(&["depth x1.000 and more".to_string()]).unwrap();
        assert!(w2 > w);
    }
}
