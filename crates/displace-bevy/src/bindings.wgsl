#define_import_path displace::bindings
#import displace::convention::MapParams

// What the shared trace (displace-gpu/shaders/surface.wgsl and
// distance_filtered.wgsl) reads, declared in the material's bind group at
// the extension's bindings (DistanceMapping's AsBindGroup, lib.rs): the
// map's uniform, the height texture of the exact walk (R32Float, read with
// textureLoad), and the distance map with its linear sampler (GPU Gems 2
// section 8.5.3: one filtered fetch per step).
@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> params: MapParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var height_tex: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var distance_tex: texture_3d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var distance_sampler: sampler;
