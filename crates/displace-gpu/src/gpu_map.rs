//! A [`DisplacementMap`] on the GPU: the height map (R32Float, read with
//! `textureLoad` for the exact walk), the distance map in the chosen
//! [`DistanceTexture`] format, and the constants every trace needs.

use crate::convention::FILTER_WEIGHT_BITS;
use crate::descriptors::{
    bind_group, bind_group_layout, linear_sampler, sampler_entry, texture_entry, uniform_entry,
    write_level,
};
use crate::shaders::DistanceTexture;
use crate::{Error, GpuContext, Result};
use displace_core::distance_map::{Format, R8Range};
use displace_core::{Address, DisplacementMap, DistanceMap, HeightMap, TraceOptions};
use displace_shaders::Decode;

pub use displace_shaders::MapParams;

/// The map's textures and bind group (group 0 of every pipeline).
pub struct GpuMap {
    /// How the shaders read the distance map (it picks the bindings module).
    pub texture: DistanceTexture,
    /// Layout of bind group 0, which every pipeline tracing this map shares.
    pub layout: wgpu::BindGroupLayout,
    height_view: wgpu::TextureView,
    distance_view: wgpu::TextureView,
    sampler: Option<wgpu::Sampler>,
    base: MapParams,
    address: Address,
}

impl GpuMap {
    /// Uploads `map`. Filtered formats are rounded down
    /// ([`DistanceMap::quantized`]) and widened by the worst filter error, so
    /// the GPU's distances stay conservative.
    pub fn new(ctx: &GpuContext, map: &DisplacementMap, texture: DistanceTexture) -> Result<Self> {
        Self::build(ctx, &map.height, map.aspect(), Some(&map.distance), texture)
    }

    /// Only the height map, for traces that read nothing else (parallax,
    /// POM, relief, cones, pyramids): the distance binding holds a 2x2x2
    /// placeholder that no such trace reads.
    pub fn for_height(ctx: &GpuContext, height: &HeightMap, aspect: [f32; 2]) -> Result<Self> {
        Self::build(ctx, height, aspect, None, DistanceTexture::R32Load)
    }

    /// Refuses a `height`-texel map with a `distance`-voxel distance map
    /// that this device's textures cannot hold: called by [`Self::build`],
    /// and by commands before they bake (from the height map's header and
    /// the asked map size), so that seconds of work and gigabytes are not
    /// spent on a map the GPU then refuses.
    pub fn check_sizes(ctx: &GpuContext, height: [usize; 2], distance: [usize; 3]) -> Result<()> {
        let [w, h, d] = distance;
        let max3 = ctx.limits.max_texture_dimension_3d as usize;
        if w.max(h).max(d) > max3 {
            return Err(Error::Limit {
                what: "distance map".into(),
                size: format!("{w}x{h}x{d}"),
                limit: format!("{max3} texels per side"),
            });
        }
        let [hw, hh] = height;
        let max2 = ctx.limits.max_texture_dimension_2d as usize;
        if hw.max(hh) > max2 {
            return Err(Error::Limit {
                what: "height map".into(),
                size: format!("{hw}x{hh}"),
                limit: format!("{max2} texels per side"),
            });
        }
        Ok(())
    }

    fn build(
        ctx: &GpuContext,
        height: &HeightMap,
        aspect: [f32; 2],
        distance: Option<&DistanceMap>,
        texture: DistanceTexture,
    ) -> Result<Self> {
        let [w, h, d] = distance.map_or([2, 2, 2], DistanceMap::size);
        let (hw, hh) = (height.width(), height.height());
        Self::check_sizes(ctx, [hw, hh], [w, h, d])?;
        let height_tex = upload(
            ctx,
            "height",
            wgpu::TextureDimension::D2,
            [hw, hh, 1],
            wgpu::TextureFormat::R32Float,
            bytemuck::cast_slice(height.data()),
        );
        let (bytes, format, decode, voxel) = match distance {
            Some(map) => {
                let (bytes, format, decode) = encode_distance(map, texture);
                (bytes, format, decode, map.voxel_size())
            }
            None => (
                vec![0u8; 4 * w * h * d],
                wgpu::TextureFormat::R32Float,
                Decode {
                    scale: 1.0,
                    offset: 0.0,
                    underestimate: 0.0,
                },
                glam::Vec3::ONE,
            ),
        };
        let distance_tex = upload(
            ctx,
            "distance",
            wgpu::TextureDimension::D3,
            [w, h, d],
            format,
            &bytes,
        );
        let base = MapParams::for_map(
            aspect,
            [w, h, d],
            voxel,
            height.address(),
            [hw, hh],
            &decode,
        );
        let sampler = texture.filtered().then(|| {
            let label = "distance (linear, no mipmaps)";
            linear_sampler(
                ctx,
                label,
                height.address(),
                wgpu::MipmapFilterMode::Nearest,
            )
        });
        let layout = map_layout(ctx, texture);
        Ok(Self {
            texture,
            layout,
            height_view: height_tex.create_view(&Default::default()),
            distance_view: distance_tex.create_view(&Default::default()),
            sampler,
            base,
            address: height.address(),
        })
    }

    /// The uniform for one trace configuration. Checks `opts` the way the
    /// CPU does ([`DisplacementMap::check_trace`]).
    pub fn params(&self, opts: &TraceOptions) -> Result<MapParams> {
        if !opts.tiles.iter().all(|t| t.is_finite() && *t > 0.0) {
            return Err(Error::InvalidOption(format!(
                "tiles {:?} must be positive",
                opts.tiles
            )));
        }
        if self.address == Address::Clamp && opts.tiles != [1.0, 1.0] {
            return Err(Error::InvalidOption(
                "a clamped map covers exactly one tile; bake with repeat addressing to tile it"
                    .into(),
            ));
        }
        if opts.t_min.is_nan() || opts.t_max.is_nan() {
            return Err(Error::InvalidOption(
                "t_min and t_max must not be NaN".into(),
            ));
        }
        Ok(self.base.with_trace(opts))
    }

    /// Bind group 0 with `params` as its uniform buffer.
    pub fn bind_group(&self, ctx: &GpuContext, params: &wgpu::Buffer) -> wgpu::BindGroup {
        let mut resources = vec![
            params.as_entire_binding(),
            wgpu::BindingResource::TextureView(&self.height_view),
            wgpu::BindingResource::TextureView(&self.distance_view),
        ];
        if let Some(s) = &self.sampler {
            resources.push(wgpu::BindingResource::Sampler(s));
        }
        bind_group(ctx, "map", &self.layout, &resources)
    }
}

/// The texel bytes, the texture format and the decoding of the values the
/// GPU will see (rounded down to the format).
fn encode_distance(
    map: &DistanceMap,
    texture: DistanceTexture,
) -> (Vec<u8>, wgpu::TextureFormat, Decode) {
    let exact = Decode {
        scale: 1.0,
        offset: 0.0,
        underestimate: map.data_underestimate(),
    };
    match texture {
        DistanceTexture::R32Load => (
            bytemuck::cast_slice(map.data()).to_vec(),
            wgpu::TextureFormat::R32Float,
            exact,
        ),
        DistanceTexture::R8Load => {
            // The same range and codes as `DistanceMap::from_raw` makes.
            let r = R8Range::for_values(map.data());
            let codes: Vec<f32> = map.data().iter().map(|&v| r.encode(v) as f32).collect();
            let decode = Decode {
                scale: (r.max - r.min) / 255.0,
                offset: r.min,
                underestimate: map.max_underestimate(),
            };
            (
                bytemuck::cast_slice(&codes).to_vec(),
                wgpu::TextureFormat::R32Float,
                decode,
            )
        }
        DistanceTexture::R16Linear | DistanceTexture::R8Linear => {
            let (format, wgpu_format) = if texture == DistanceTexture::R16Linear {
                (Format::R16F, wgpu::TextureFormat::R16Float)
            } else {
                (Format::R8, wgpu::TextureFormat::R8Unorm)
            };
            let t = map
                .filtered_texels(format, FILTER_WEIGHT_BITS)
                .expect("R16F and R8 filter");
            let decode = Decode {
                scale: t.scale,
                offset: t.offset,
                underestimate: t.underestimate,
            };
            (t.bytes, wgpu_format, decode)
        }
    }
}

pub(crate) fn upload(
    ctx: &GpuContext,
    label: &str,
    dimension: wgpu::TextureDimension,
    size: [usize; 3],
    format: wgpu::TextureFormat,
    bytes: &[u8],
) -> wgpu::Texture {
    let extent = wgpu::Extent3d {
        width: size[0] as u32,
        height: size[1] as u32,
        depth_or_array_layers: size[2] as u32,
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: extent,
        mip_level_count: 1,
        sample_count: 1,
        dimension,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let bpp = format.block_copy_size(None).expect("uncompressed format");
    let [w, h, d] = size.map(|n| n as u32);
    write_level(ctx, &texture, 0, bytes, [w, h, d], bpp);
    texture
}

/// Group 0: params, height, distance (and its sampler when filtered), seen
/// by every stage that traces.
fn map_layout(ctx: &GpuContext, texture: DistanceTexture) -> wgpu::BindGroupLayout {
    let vis = wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::FRAGMENT;
    let mut entries = vec![
        uniform_entry(
            0,
            vis | wgpu::ShaderStages::VERTEX,
            wgpu::BufferSize::new(std::mem::size_of::<MapParams>() as u64),
        ),
        texture_entry(1, vis, false, wgpu::TextureViewDimension::D2),
        texture_entry(2, vis, texture.filtered(), wgpu::TextureViewDimension::D3),
    ];
    if texture.filtered() {
        entries.push(sampler_entry(3, vis));
    }
    bind_group_layout(ctx, "map", &entries)
}
