//! The shading textures a displaced draw samples beside its distance map:
//! the colour map (Donnelly's checkerboard, or one texel of a scene
//! material's albedo) and the normal map, with every mip level given on the
//! host so the GPU filters exactly what the CPU renderer would.

use crate::descriptors::{linear_sampler, texture_2d_descriptor, write_level};
use crate::GpuContext;
use displace_core::convention::linear_to_srgb;
use displace_core::DisplacementMap;

/// Donnelly's checkerboard colour texture (RGBA8 sRGB, `size` texels with
/// `cells` squares a side) and its box-filtered mips down to 1x1, so
/// derivative-driven sampling (section 8.5.3) has levels to choose from:
/// the colour map of [`super::Renderer::new`], public so that another
/// renderer of the same face (displace-bevy's comparison test) samples the
/// very same texels.
pub fn checker_mips(size: u32, cells: u32) -> Vec<Vec<u8>> {
    let cell = size / cells;
    let mut level: Vec<u8> = (0..size * size)
        .flat_map(|k| {
            let (x, y) = (k % size, k / size);
            if ((x / cell) + (y / cell)).is_multiple_of(2) {
                [225, 200, 160, 255]
            } else {
                [150, 90, 60, 255]
            }
        })
        .collect();
    let mut out = Vec::new();
    let mut n = size;
    loop {
        out.push(level.clone());
        if n == 1 {
            return out;
        }
        let m = n / 2;
        level = (0..m * m)
            .flat_map(|k| {
                let (x, y) = ((k % m) * 2, (k / m) * 2);
                let at = |dx: u32, dy: u32, c: usize| {
                    level[(((y + dy) * n + x + dx) * 4) as usize + c] as u32
                };
                let mut px = [0u8; 4];
                for (c, p) in px.iter_mut().enumerate() {
                    *p = ((at(0, 0, c) + at(1, 0, c) + at(0, 1, c) + at(1, 1, c) + 2) / 4) as u8;
                }
                px
            })
            .collect();
        n = m;
    }
}

/// One 8-bit sRGB texel of the linear colour `albedo`, each channel clamped
/// to `[0, 1]`.
pub(super) fn albedo_texel(albedo: [f32; 3]) -> Vec<u8> {
    let e = |c: f32| (linear_to_srgb(c) * 255.0).round() as u8;
    vec![e(albedo[0]), e(albedo[1]), e(albedo[2]), 255]
}

/// `map`'s normals as RGBA8 texels, each component moved from `[-1, 1]`
/// to `[0, 255]`.
pub(super) fn normal_texels(map: &DisplacementMap) -> Vec<u8> {
    map.normals
        .data
        .iter()
        .flat_map(|n| {
            let e = |c: f32| ((c * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
            [e(n.x), e(n.y), e(n.z), 255]
        })
        .collect()
}

/// The trilinear sampler of the normal and colour maps, addressed as `map`
/// is (a repeat-baked map tiles its shading too).
pub(super) fn shading_sampler(ctx: &GpuContext, map: &DisplacementMap) -> wgpu::Sampler {
    let trilinear = wgpu::MipmapFilterMode::Linear;
    linear_sampler(ctx, "shading", map.address(), trilinear)
}

/// A 2D texture with every mip level given in full (4 bytes per texel).
pub(crate) fn texture_2d(
    ctx: &GpuContext,
    label: &str,
    [w, h]: [u32; 2],
    format: wgpu::TextureFormat,
    mips: &[Vec<u8>],
) -> wgpu::TextureView {
    let texture = ctx.device.create_texture(&texture_2d_descriptor(
        label,
        [w, h],
        mips.len() as u32,
        format,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    ));
    for (level, data) in mips.iter().enumerate() {
        let (lw, lh) = ((w >> level).max(1), (h >> level).max(1));
        write_level(ctx, &texture, level as u32, data, [lw, lh, 1], 4);
    }
    texture.create_view(&Default::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIGHT: [u8; 4] = [225, 200, 160, 255];
    const DARK: [u8; 4] = [150, 90, 60, 255];

    fn texel(level: &[u8], n: u32, x: u32, y: u32) -> [u8; 4] {
        let at = ((y * n + x) * 4) as usize;
        level[at..at + 4].try_into().unwrap()
    }

    #[test]
    fn checker_levels_halve_down_to_one_texel() {
        let mips = checker_mips(16, 4);
        let sizes: Vec<usize> = mips.iter().map(Vec::len).collect();
        assert_eq!(sizes, [16 * 16 * 4, 8 * 8 * 4, 4 * 4 * 4, 2 * 2 * 4, 4]);
    }

    #[test]
    fn checker_cells_alternate_from_a_light_corner() {
        let top = &checker_mips(16, 4)[0];
        assert_eq!(texel(top, 16, 0, 0), LIGHT);
        assert_eq!(texel(top, 16, 3, 3), LIGHT);
        assert_eq!(texel(top, 16, 4, 0), DARK);
        assert_eq!(texel(top, 16, 0, 4), DARK);
        assert_eq!(texel(top, 16, 4, 4), LIGHT);
        assert_eq!(texel(top, 16, 15, 15), LIGHT);
    }

    #[test]
    fn checker_mips_box_filter_with_rounding() {
        let mips = checker_mips(16, 4);
        // Cells of 4 texels stay uniform for two levels (one texel a cell
        // at level 2); each texel of level 3 averages two light and two
        // dark cells, rounded to nearest.
        assert_eq!(texel(&mips[2], 4, 0, 0), LIGHT);
        assert_eq!(texel(&mips[2], 4, 1, 0), DARK);
        let mean = |a: u8, b: u8| ((2 * a as u32 + 2 * b as u32 + 2) / 4) as u8;
        let mixed: [u8; 4] = std::array::from_fn(|c| mean(LIGHT[c], DARK[c]));
        assert_eq!(mixed, [188, 145, 110, 255]);
        assert_eq!(texel(&mips[3], 2, 0, 0), mixed);
        assert_eq!(texel(&mips[3], 2, 1, 1), mixed);
        assert_eq!(mips[4], mixed);
    }

    #[test]
    fn albedo_texels_are_srgb_encoded_and_clamped() {
        assert_eq!(albedo_texel([0.0, 1.0, 2.0]), [0, 255, 255, 255]);
        // Linear 0.5 is sRGB 0.735 (188 of 255), not 128.
        assert_eq!(albedo_texel([0.5, -1.0, 0.5]), [188, 0, 188, 255]);
    }
}
