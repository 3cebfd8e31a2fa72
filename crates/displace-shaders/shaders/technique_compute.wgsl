#import displace::bindings::params
#import displace::batch::{rays, result_flags}
#import displace::techniques::trace_technique

// Batch query of one technique (displace_core::techniques): one invocation per map-space ray,
// technique and budget from a uniform, so one pipeline serves them all.
// Rust mirrors: `TechniqueParams`, `TechniqueHitOut` (src/techniques.rs).

struct TechniqueParams {
    technique: u32,
    budget: u32,
    _pad0: u32,
    _pad1: u32,
}

struct TechniqueHitOut {
    position: vec3f,
    t: f32,
    uv: vec2f,
    fetches: u32,
    flags: u32,
}

// Bit 0 of `flags`: the technique reports a hit.
const TECHNIQUE_FOUND: u32 = 1u;

@group(1) @binding(1) var<storage, read_write> technique_hits: array<TechniqueHitOut>;
@group(1) @binding(2) var<uniform> technique: TechniqueParams;

@compute @workgroup_size(64)
fn technique_main(@builtin(global_invocation_id) gid: vec3u) {
    let index = gid.x;
    if (index >= arrayLength(&rays)) {
        return;
    }
    let ray = rays[index];
    let h = trace_technique(ray.origin, ray.dir, technique.technique, technique.budget);
    let p = ray.origin + ray.dir * h.t;
    let flags = result_flags(h.found, TECHNIQUE_FOUND);
    technique_hits[index] = TechniqueHitOut(p, h.t, p.xy / params.aspect, h.fetches, flags);
}
