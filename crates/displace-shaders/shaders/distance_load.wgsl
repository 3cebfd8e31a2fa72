#define_import_path displace::distance
#import displace::convention::{ADDRESS_CLAMP, lerp, texel_lerp, wrap_index}
#import displace::bindings::{params, distance_tex}

// Distance lookups by textureLoad from an R32Float 3D texture, interpolated
// by hand exactly as DistanceMap::sample does it on the CPU: same texel
// centres, same addressing, same order of lerps, then decoded (the identity
// for stored distances; `min + s * quantum` for the CPU tracer's 8-bit codes).

fn distance_voxel(i: i32, j: i32, k: i32) -> f32 {
    return textureLoad(distance_tex, vec3i(i, j, k), 0).x;
}

fn distance_at(p: vec3f) -> f32 {
    let n = params.dist_size;
    let lx = texel_lerp(p.x / params.aspect.x, n.x);
    let ly = texel_lerp(p.y / params.aspect.y, n.y);
    let lz = texel_lerp(p.z, n.z);
    let i0 = wrap_index(i32(lx.x), n.x, params.address);
    let i1 = wrap_index(i32(lx.x) + 1, n.x, params.address);
    let j0 = wrap_index(i32(ly.x), n.y, params.address);
    let j1 = wrap_index(i32(ly.x) + 1, n.y, params.address);
    let k0 = wrap_index(i32(lz.x), n.z, ADDRESS_CLAMP);
    let k1 = wrap_index(i32(lz.x) + 1, n.z, ADDRESS_CLAMP);
    let c00 = lerp(distance_voxel(i0, j0, k0), distance_voxel(i1, j0, k0), lx.y);
    let c10 = lerp(distance_voxel(i0, j1, k0), distance_voxel(i1, j1, k0), lx.y);
    let c01 = lerp(distance_voxel(i0, j0, k1), distance_voxel(i1, j0, k1), lx.y);
    let c11 = lerp(distance_voxel(i0, j1, k1), distance_voxel(i1, j1, k1), lx.y);
    return params.decode_offset + params.decode_scale * lerp(lerp(c00, c10, ly.y), lerp(c01, c11, ly.y), lz.y);
}
