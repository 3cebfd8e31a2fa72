#import displace::bindings::params
#import displace::distance::distance_at

// The roofline of distance mapping on a GPU (`bench gpu`, BENCHMARKS.md): per
// pixel, N dependent trilinear fetches of the distance texture and nothing
// else, through the filtered lookup (distance_filtered.wgsl).

struct Loop {
    width: u32,
    height: u32,
    steps: u32,
    _pad: u32,
}

@group(1) @binding(0) var<uniform> fetch_loop: Loop;
@group(1) @binding(1) var<storage, read_write> fetch_out: array<f32>;

@compute @workgroup_size(8, 8)
fn fetch_main(@builtin(global_invocation_id) gid: vec3u) {
    if (gid.x >= fetch_loop.width || gid.y >= fetch_loop.height) {
        return;
    }
    let uv = (vec2f(gid.xy) + 0.5) / vec2f(f32(fetch_loop.width), f32(fetch_loop.height));
    var p = vec3f(uv * params.aspect, 1.0);
    let dir = normalize(vec3f(0.3, 0.2, -1.0));
    for (var i = 0u; i < fetch_loop.steps; i++) {
        p += dir * distance_at(p);
    }
    fetch_out[gid.y * fetch_loop.width + gid.x] = p.z;
}
