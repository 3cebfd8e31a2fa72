//! Where the raster passes draw and how a frame comes back to the host:
//! the colour, AOV and depth targets of one image size ([`Targets`]) and
//! their readback into an [`Image`].

use crate::descriptors::{empty_buffer, extent_2d, texel_layout, texture_2d_descriptor};
use crate::{GpuContext, Result};

/// Format of the colour target: sRGB-encoded on store, so shading stays in
/// linear RGB.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Format of the AOV target: full floats, so `t` and the texture
/// coordinates compare with the CPU trace's without quantisation.
pub(super) const AOV_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// Format of the depth target that the fragments' exact depths are tested in.
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Bytes a frame holds on the device per pixel: the colour (4), AOV (16)
/// and depth (4) targets and the colour and AOV readback buffers (4 + 16).
/// On a software adapter (lavapipe) these are the host's memory too.
pub const DEVICE_BYTES_PER_PIXEL: u128 = 44;

/// Bytes the host holds per pixel while a frame comes back
/// ([`Targets::read`]): the mapped readbacks (20) and their unpadded copies
/// in the [`Image`] (20).
pub const READBACK_BYTES_PER_PIXEL: u128 = 40;

/// A rendered frame: sRGB colour and the AOV `[u, v, hit kind, t]`
/// (`kind` 0 where nothing was hit; [`crate::convention::HIT_PLAIN`] on a
/// non-displaced shape, whose `t` is the world distance from the eye). The
/// AOV is what lets a render be checked against the CPU trace pixel by
/// pixel, as the colour alone cannot say where a ray hit.
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// sRGB colour, four bytes a pixel, rows top to bottom.
    pub rgba8: Vec<u8>,
    /// The AOV `[u, v, hit kind, t]` per pixel.
    pub uv: Vec<[f32; 4]>,
}

/// The colour (sRGB), AOV and depth targets of one image size: allocated
/// apart from any [`super::Renderer`], so that every draw of a frame shares
/// one depth buffer and the viewer keeps one set across frames, presenting
/// the colour view on the GPU ([`super::encode_faces`]).
pub struct Targets {
    pub(super) size: [u32; 2],
    color_tex: wgpu::Texture,
    aov_tex: wgpu::Texture,
    pub(super) color: wgpu::TextureView,
    pub(super) aov: wgpu::TextureView,
    pub(super) depth: wgpu::TextureView,
}

impl Targets {
    /// Refuses a `w x h` frame this device cannot hold, before anything is
    /// allocated: a side past its 2D texture limit, or an AOV readback
    /// larger than its largest buffer (a 16384x16384 frame's is 4 GiB,
    /// which wgpu would answer with a panic of the default error handler).
    pub fn check(ctx: &GpuContext, [w, h]: [u32; 2]) -> Result<()> {
        let max2 = ctx.limits.max_texture_dimension_2d;
        if w.max(h) > max2 {
            return Err(crate::Error::Limit {
                what: "frame".into(),
                size: format!("{w}x{h}"),
                limit: format!("{max2} pixels per side"),
            });
        }
        let aov = u64::from(readback_pitch(w, 16)) * u64::from(h);
        if aov > ctx.limits.max_buffer_size {
            return Err(crate::Error::Limit {
                what: "frame".into(),
                size: format!("{w}x{h}"),
                limit: format!(
                    "{} bytes a buffer: its AOV readback needs {aov} bytes",
                    ctx.limits.max_buffer_size
                ),
            });
        }
        Ok(())
    }

    /// Allocates the three targets at `w x h`.
    pub fn new(ctx: &GpuContext, [w, h]: [u32; 2]) -> Self {
        let make = |format, usage| {
            ctx.device
                .create_texture(&texture_2d_descriptor("target", [w, h], 1, format, usage))
        };
        let rt = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let color_tex = make(COLOR_FORMAT, rt | wgpu::TextureUsages::TEXTURE_BINDING);
        let aov_tex = make(AOV_FORMAT, rt);
        let depth = make(DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT)
            .create_view(&Default::default());
        Self {
            size: [w, h],
            color: color_tex.create_view(&Default::default()),
            aov: aov_tex.create_view(&Default::default()),
            color_tex,
            aov_tex,
            depth,
        }
    }

    /// Size of the targets in pixels.
    pub fn size(&self) -> [u32; 2] {
        self.size
    }

    /// The colour view ([`COLOR_FORMAT`], also bindable as a texture).
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color
    }

    /// Finishes `encoder` with copies of the colour and AOV targets,
    /// submits it and reads both back, rows unpadded.
    pub(super) fn read(
        &self,
        ctx: &GpuContext,
        mut encoder: wgpu::CommandEncoder,
    ) -> Result<Image> {
        let [w, h] = self.size;
        let ((cbuf, color_row), (abuf, aov_row)) =
            ctx.checked("allocating the readback", || {
                (
                    copy_to_readback(ctx, &mut encoder, &self.color_tex, 4, self.size),
                    copy_to_readback(ctx, &mut encoder, &self.aov_tex, 16, self.size),
                )
            })?;
        let commands = ctx.checked("finishing the render", || encoder.finish())?;
        ctx.queue.submit([commands]);
        let cbytes = ctx.read_buffer(&cbuf)?;
        let abytes = ctx.read_buffer(&abuf)?;
        let mut rgba8 = Vec::with_capacity((w * h * 4) as usize);
        let mut uv = Vec::with_capacity((w * h) as usize);
        for y in 0..h as usize {
            rgba8.extend_from_slice(&cbytes[y * color_row as usize..][..w as usize * 4]);
            let row: &[f32] =
                bytemuck::cast_slice(&abytes[y * aov_row as usize..][..w as usize * 16]);
            uv.extend(row.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
        }
        Ok(Image {
            width: w,
            height: h,
            rgba8,
            uv,
        })
    }
}

/// Records a copy of `texture` (`texel_bytes` per texel, `[w, h]`) into a
/// new mappable buffer; returns it and its padded row pitch.
pub(crate) fn copy_to_readback(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    texel_bytes: u32,
    [w, h]: [u32; 2],
) -> (wgpu::Buffer, u32) {
    let row = readback_pitch(w, texel_bytes);
    let buffer = empty_buffer(
        ctx,
        "readback",
        row as u64 * h as u64,
        wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
    );
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: texel_layout(row, h),
        },
        extent_2d([w, h]),
    );
    (buffer, row)
}

/// The row pitch of a texture-to-buffer copy of `w` texels of
/// `texel_bytes`: wgpu wants every row to start on a
/// [`wgpu::COPY_BYTES_PER_ROW_ALIGNMENT`] boundary.
fn readback_pitch(w: u32, texel_bytes: u32) -> u32 {
    (w * texel_bytes).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
        * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

#[cfg(test)]
mod tests {
    use super::readback_pitch;

    #[test]
    fn readback_rows_are_padded_to_the_copy_alignment() {
        assert_eq!(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT, 256);
        assert_eq!(readback_pitch(64, 4), 256);
        assert_eq!(readback_pitch(65, 4), 512);
        assert_eq!(readback_pitch(1, 16), 256);
        assert_eq!(readback_pitch(17, 16), 512);
    }
}
