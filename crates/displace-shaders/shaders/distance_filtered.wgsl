#define_import_path displace::distance
#import displace::bindings::{params, distance_tex, distance_sampler}

// Distance lookups through a linear sampler without mipmaps (GPU Gems 2
// section 8.5.3), from an R16Float or R8Unorm 3D texture. The sampler's
// address mode carries the map's addressing across and clamps in depth.
// `decode_offset` already subtracts the bound on the filter's fixed-point
// weight error, so the decoded value stays conservative.

fn distance_at(p: vec3f) -> f32 {
    let uvw = vec3f(p.x / params.aspect.x, p.y / params.aspect.y, p.z);
    let s = textureSampleLevel(distance_tex, distance_sampler, uvw, 0.0).x;
    return params.decode_offset + params.decode_scale * s;
}
