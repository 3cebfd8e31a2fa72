#define_import_path displace::bindings
#import displace::convention::MapParams

// displace-gpu's group 0 for the textureLoad distance lookups
// (distance_load.wgsl): the map's uniform, the height texture of the exact
// walk and the R32Float distance texture (gpu_map.rs `map_layout`).
@group(0) @binding(0) var<uniform> params: MapParams;
@group(0) @binding(1) var height_tex: texture_2d<f32>;
@group(0) @binding(2) var distance_tex: texture_3d<f32>;
