//! The wgpu descriptors every pipeline of this crate spells the same way:
//! shader modules, bind group layout entries, pipeline layouts, bind groups
//! numbered in order, buffers made from host data and 2D texture sizes. One
//! spelling each, so the compute queries, the raster path, the benchmarks
//! and the viewer cannot drift apart in the details (dynamic offsets,
//! multisampling, mip counts) they all leave at the same values.

use crate::GpuContext;
use bytemuck::Pod;
use wgpu::util::DeviceExt;

/// Compiles the WGSL `source` as one module.
pub(crate) fn shader_module(ctx: &GpuContext, label: &str, source: &str) -> wgpu::ShaderModule {
    ctx.device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        })
}

/// A pipeline layout of `layouts`, group 0 first.
pub(crate) fn pipeline_layout(
    ctx: &GpuContext,
    label: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::PipelineLayout {
    let layouts: Vec<_> = layouts.iter().map(|l| Some(*l)).collect();
    ctx.device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &layouts,
            immediate_size: 0,
        })
}

/// A bind group layout of `entries`.
pub(crate) fn bind_group_layout(
    ctx: &GpuContext,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    ctx.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries,
        })
}

/// A bind group layout entry of any binding type, without an array count.
pub(crate) fn layout_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty,
        count: None,
    }
}

/// A uniform-buffer entry; `min_size` is the struct's size where the layout
/// checks it at creation, `None` where it is checked at draw time.
pub(crate) fn uniform_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    min_size: Option<wgpu::BufferSize>,
) -> wgpu::BindGroupLayoutEntry {
    let ty = buffer(wgpu::BufferBindingType::Uniform, min_size);
    layout_entry(binding, visibility, ty)
}

/// Binding 0 of the raster passes' own groups: the frame's uniform, read by
/// both the vertex and the fragment stage, its size checked at draw time.
pub(crate) fn frame_uniform_entry() -> wgpu::BindGroupLayoutEntry {
    uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT, None)
}

/// A storage-buffer entry of a compute bind group layout.
pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    storage_entry_in(binding, read_only, wgpu::ShaderStages::COMPUTE)
}

/// A storage-buffer entry visible to `stages`.
pub(crate) fn storage_entry_in(
    binding: u32,
    read_only: bool,
    stages: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    let ty = buffer(wgpu::BufferBindingType::Storage { read_only }, None);
    layout_entry(binding, stages, ty)
}

/// A buffer binding without dynamic offsets.
fn buffer(
    ty: wgpu::BufferBindingType,
    min_binding_size: Option<wgpu::BufferSize>,
) -> wgpu::BindingType {
    wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size,
    }
}

/// A single-sampled float texture entry of `dimension`.
pub(crate) fn texture_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    filterable: bool,
    dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    layout_entry(
        binding,
        visibility,
        wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: dimension,
            multisampled: false,
        },
    )
}

/// A filtering sampler's entry.
pub(crate) fn sampler_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    layout_entry(
        binding,
        visibility,
        wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
    )
}

/// A bind group whose `resources` take bindings 0, 1, 2, ... in order, as
/// every layout of this crate numbers them.
pub(crate) fn bind_group(
    ctx: &GpuContext,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource],
) -> wgpu::BindGroup {
    let entries: Vec<_> = resources
        .iter()
        .enumerate()
        .map(|(binding, resource)| wgpu::BindGroupEntry {
            binding: binding as u32,
            resource: resource.clone(),
        })
        .collect();
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// A uniform buffer holding `value`.
pub(crate) fn uniform_buffer<T: Pod>(ctx: &GpuContext, label: &str, value: &T) -> wgpu::Buffer {
    buffer_of(
        ctx,
        label,
        bytemuck::bytes_of(value),
        wgpu::BufferUsages::UNIFORM,
    )
}

/// A buffer of `usage` initialised with `contents`.
pub(crate) fn buffer_of(
    ctx: &GpuContext,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
}

/// An uninitialised buffer of `size` bytes for `usage` (results, readback).
pub(crate) fn empty_buffer(
    ctx: &GpuContext,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}

/// The size of one 2D layer of `[w, h]` texels.
pub(crate) fn extent_2d([w, h]: [u32; 2]) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width: w,
        height: h,
        depth_or_array_layers: 1,
    }
}

/// A single-sampled 2D texture of `[w, h]` texels with `mips` levels.
pub(crate) fn texture_2d_descriptor<'a>(
    label: &'a str,
    size: [u32; 2],
    mips: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureDescriptor<'a> {
    wgpu::TextureDescriptor {
        label: Some(label),
        size: extent_2d(size),
        mip_level_count: mips,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    }
}

/// A colour attachment cleared to `clear` and stored.
pub(crate) fn cleared_attachment(
    view: &wgpu::TextureView,
    clear: wgpu::Color,
) -> Option<wgpu::RenderPassColorAttachment<'_>> {
    Some(wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(clear),
            store: wgpu::StoreOp::Store,
        },
    })
}

/// A colour target of `format` writing every channel.
pub(crate) fn color_target(
    format: wgpu::TextureFormat,
    blend: Option<wgpu::BlendState>,
) -> Option<wgpu::ColorTargetState> {
    Some(wgpu::ColorTargetState {
        format,
        blend,
        write_mask: wgpu::ColorWrites::ALL,
    })
}

/// The stages of a render pipeline: one module's vertex and fragment entry
/// points, the vertex buffers the first reads and the targets the second
/// writes.
pub(crate) struct RenderStages<'a> {
    pub module: &'a wgpu::ShaderModule,
    pub vertex: &'a str,
    pub fragment: &'a str,
    pub buffers: &'a [wgpu::VertexBufferLayout<'a>],
    pub targets: &'a [Option<wgpu::ColorTargetState>],
}

/// A render pipeline of `stages` over `layout`, single-sampled, with no
/// multiview and no cache.
pub(crate) fn render_pipeline(
    ctx: &GpuContext,
    label: &str,
    layout: &wgpu::PipelineLayout,
    stages: RenderStages,
    primitive: wgpu::PrimitiveState,
    depth_stencil: Option<wgpu::DepthStencilState>,
) -> wgpu::RenderPipeline {
    ctx.device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: Some(layout),
            vertex: wgpu::VertexState {
                module: stages.module,
                entry_point: Some(stages.vertex),
                compilation_options: Default::default(),
                buffers: stages.buffers,
            },
            primitive,
            depth_stencil,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: stages.module,
                entry_point: Some(stages.fragment),
                compilation_options: Default::default(),
                targets: stages.targets,
            }),
            multiview_mask: None,
            cache: None,
        })
}

/// The sampler address mode of a map's addressing: a repeat-baked map's
/// samples wrap across its edges, a clamped one's stop at them.
pub(crate) fn address_mode(address: displace_core::Address) -> wgpu::AddressMode {
    match address {
        displace_core::Address::Clamp => wgpu::AddressMode::ClampToEdge,
        displace_core::Address::Repeat => wgpu::AddressMode::Repeat,
    }
}

/// The buffer side of a texel copy: rows of `row` bytes, `rows` a layer.
pub(crate) fn texel_layout(row: u32, rows: u32) -> wgpu::TexelCopyBufferLayout {
    wgpu::TexelCopyBufferLayout {
        offset: 0,
        bytes_per_row: Some(row),
        rows_per_image: Some(rows),
    }
}

/// Uploads the tightly packed `data` of `[w, h, layers]` texels of
/// `texel_bytes` into mip `level` of `texture`.
pub(crate) fn write_level(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    level: u32,
    data: &[u8],
    [w, h, layers]: [u32; 3],
    texel_bytes: u32,
) {
    ctx.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: level,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        data,
        texel_layout(w * texel_bytes, h),
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: layers,
        },
    );
}

/// A linearly filtering sampler addressed as a map of `address` is across
/// u and v (clamped across w), with `mipmap_filter` between levels.
pub(crate) fn linear_sampler(
    ctx: &GpuContext,
    label: &str,
    address: displace_core::Address,
    mipmap_filter: wgpu::MipmapFilterMode,
) -> wgpu::Sampler {
    let across = address_mode(address);
    ctx.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        address_mode_u: across,
        address_mode_v: across,
        address_mode_w: wgpu::AddressMode::ClampToEdge,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        mipmap_filter,
        ..Default::default()
    })
}
