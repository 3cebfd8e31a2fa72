#define_import_path displace::bindings
#import displace::convention::MapParams

// displace-gpu's group 0 for the filtered distance lookups
// (distance_filtered.wgsl): as bindings_load.wgsl, plus the linear sampler.
@group(0) @binding(0) var<uniform> params: MapParams;
@group(0) @binding(1) var height_tex: texture_2d<f32>;
@group(0) @binding(2) var distance_tex: texture_3d<f32>;
@group(0) @binding(3) var distance_sampler: sampler;
