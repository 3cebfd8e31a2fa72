//! The precomputations of the techniques ([`crate::techniques`]) as textures: cone maps
//! (R32Float, one ratio per height texel, read nearest with `textureLoad`)
//! and the max pyramid of maximum mipmaps as a real mip chain (Tevs et al.
//! 2008 store it as the height map's mipmaps). A precomputation the maps
//! lack is bound as a 1x1 placeholder; [`TechniqueTextures::has`] says which
//! techniques can run.

use crate::gpu_map::upload;
use crate::raster::texture_2d;
use crate::{Error, GpuContext, Result};
use displace_core::techniques::{ConeMap, Maps, MaxPyramid, Needs};

/// Cone maps and pyramid on the GPU.
pub struct TechniqueTextures {
    pub(crate) cones: wgpu::TextureView,
    pub(crate) relaxed: wgpu::TextureView,
    pub(crate) pyramid: wgpu::TextureView,
    present: [bool; 3],
}

impl TechniqueTextures {
    /// Uploads the precomputations `maps` holds, with placeholders for the rest.
    pub fn new(ctx: &GpuContext, maps: &Maps) -> Result<Self> {
        let size = [maps.height.width(), maps.height.height()];
        let cones = cone_view(ctx, maps.cones.as_ref(), size, "cones")?;
        let relaxed = cone_view(ctx, maps.relaxed.as_ref(), size, "relaxed cones")?;
        let pyramid = match &maps.pyramid {
            Some(p) => pyramid_view(ctx, p, size)?,
            None => placeholder(ctx, "no pyramid"),
        };
        Ok(Self {
            cones,
            relaxed,
            pyramid,
            present: [
                maps.cones.is_some(),
                maps.relaxed.is_some(),
                maps.pyramid.is_some(),
            ],
        })
    }

    /// Whether the textures for `needs` were uploaded (the distance map is
    /// the [`crate::GpuMap`]'s business).
    pub fn has(&self, needs: Needs) -> bool {
        match needs {
            Needs::ConservativeCones => self.present[0],
            Needs::RelaxedCones => self.present[1],
            Needs::Pyramid => self.present[2],
            Needs::Nothing | Needs::DistanceMap => true,
        }
    }
}

fn placeholder(ctx: &GpuContext, label: &str) -> wgpu::TextureView {
    upload(
        ctx,
        label,
        wgpu::TextureDimension::D2,
        [1, 1, 1],
        wgpu::TextureFormat::R32Float,
        &[0; 4],
    )
    .create_view(&Default::default())
}

fn cone_view(
    ctx: &GpuContext,
    cones: Option<&ConeMap>,
    size: [usize; 2],
    label: &str,
) -> Result<wgpu::TextureView> {
    let Some(c) = cones else {
        return Ok(placeholder(ctx, label));
    };
    if [c.width(), c.height()] != size {
        return Err(Error::InvalidOption(format!(
            "{label} are {}x{} but the height map is {}x{}",
            c.width(),
            c.height(),
            size[0],
            size[1]
        )));
    }
    Ok(upload(
        ctx,
        label,
        wgpu::TextureDimension::D2,
        [size[0], size[1], 1],
        wgpu::TextureFormat::R32Float,
        bytemuck::cast_slice(c.data()),
    )
    .create_view(&Default::default()))
}

/// Level sizes of the CPU pyramid of a `w x h` height map: one node per
/// bilinear cell, `(w + 1) x (h + 1)`, halved rounding up to 1x1.
fn pyramid_dims(size: [usize; 2]) -> Vec<[usize; 2]> {
    let mut dims = vec![[size[0] + 1, size[1] + 1]];
    while let Some(&[w, h]) = dims.last().filter(|d| d[0] > 1 || d[1] > 1) {
        dims.push([w.div_ceil(2), h.div_ceil(2)]);
    }
    dims
}

/// Level `l` of the power-of-two texture is at least as large as the CPU's
/// level `l` (`ceil(n / 2^l) <= 2^k / 2^l`), and both chains have
/// `ceil(log2(max(w + 1, h + 1))) + 1` levels; the unused texels are never
/// read (the walk clamps to the cells).
fn pyramid_view(
    ctx: &GpuContext,
    pyramid: &MaxPyramid,
    size: [usize; 2],
) -> Result<wgpu::TextureView> {
    let dims = pyramid_dims(size);
    let padded = [
        dims[0][0].next_power_of_two(),
        dims[0][1].next_power_of_two(),
    ];
    let levels = padded[0].max(padded[1]).trailing_zeros() as usize + 1;
    if pyramid.levels() != dims.len() || levels != dims.len() {
        return Err(Error::InvalidOption(format!(
            "the max pyramid has {} levels, a {}x{} height map needs {}",
            pyramid.levels(),
            size[0],
            size[1],
            dims.len()
        )));
    }
    let max2 = ctx.limits.max_texture_dimension_2d as usize;
    if padded[0].max(padded[1]) > max2 {
        return Err(Error::Limit {
            what: "max pyramid".into(),
            size: format!("{}x{}", padded[0], padded[1]),
            limit: format!("{max2} texels per side"),
        });
    }
    let mips: Vec<Vec<u8>> = dims
        .iter()
        .enumerate()
        .map(|(level, &[w, h])| {
            let pw = (padded[0] >> level).max(1);
            let ph = (padded[1] >> level).max(1);
            let mut texels = vec![f32::MIN; pw * ph];
            for j in 0..h {
                for i in 0..w {
                    texels[j * pw + i] = pyramid.node(level, i, j);
                }
            }
            bytemuck::cast_slice(&texels).to_vec()
        })
        .collect();
    Ok(texture_2d(
        ctx,
        "max pyramid",
        [padded[0] as u32, padded[1] as u32],
        wgpu::TextureFormat::R32Float,
        &mips,
    ))
}

#[cfg(test)]
mod tests {
    use super::pyramid_dims;

    #[test]
    fn pyramid_levels_fit_a_power_of_two_mip_chain() {
        for w in 1..70usize {
            for h in [1usize, 2, 3, 7, 31, 32, 33, 64] {
                let dims = pyramid_dims([w, h]);
                let p = [(w + 1).next_power_of_two(), (h + 1).next_power_of_two()];
                assert_eq!(dims.len(), p[0].max(p[1]).trailing_zeros() as usize + 1);
                for (l, d) in dims.iter().enumerate() {
                    assert!(d[0] <= (p[0] >> l).max(1) && d[1] <= (p[1] >> l).max(1));
                }
                assert_eq!(*dims.last().unwrap(), [1, 1]);
            }
        }
    }
}
