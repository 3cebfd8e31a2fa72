#import displace::convention::FLAG_CONVERGED
#import displace::bindings::params
#import displace::surface::trace_map
#import displace::batch::{rays, result_flags}

// Batch ray query: one invocation per map-space ray, the march of
// Donnelly's listing 8-2 as a compute shader. Rust mirrors: `RayIn`, `HitOut`.

struct HitOut {
    position: vec3f,
    t: f32,
    normal: vec3f,
    kind: u32,
    uv: vec2f,
    iterations: u32,
    flags: u32,
}

@group(1) @binding(1) var<storage, read_write> hits: array<HitOut>;

@compute @workgroup_size(64)
fn trace_main(@builtin(global_invocation_id) gid: vec3u) {
    let index = gid.x;
    if (index >= arrayLength(&rays)) {
        return;
    }
    let ray = rays[index];
    let h = trace_map(ray.origin, ray.dir);
    let p = ray.origin + ray.dir * h.t;
    let flags = result_flags(h.converged, FLAG_CONVERGED);
    hits[index] = HitOut(p, h.t, h.normal, h.kind, p.xy / params.aspect, h.iterations, flags);
}
