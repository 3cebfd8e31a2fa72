#define_import_path displace::techniques
#import displace::convention::{BIG, HIT_NONE}
#import displace::bindings::params
#import displace::surface::{WALK_HIT, WALK_INSIDE, clip_shell, height_sample, trace_map, walk}

// The per-pixel displacement techniques engines ship (displace_core::techniques), in map space,
// operation for operation as displace_core::techniques does them, with the
// same budgets and the same fetch counting: one bilinear height sample = 1,
// one trilinear distance sample = 1, one cone or pyramid texel = 1, one
// bilinear patch solved exactly = 1. The papers' texture-space depth is
// `1 - z` here.

// Technique codes, in the order of displace_core::techniques::Technique::ALL.
const TECH_PARALLAX: u32 = 0u;
const TECH_STEEP: u32 = 1u;
const TECH_POM: u32 = 2u;
const TECH_BEVY_OCCLUSION: u32 = 3u;
const TECH_BEVY_RELIEF: u32 = 4u;
const TECH_RELIEF: u32 = 5u;
const TECH_CONE: u32 = 6u;
const TECH_RELAXED_CONE: u32 = 7u;
const TECH_MAX_MIP: u32 = 8u;
const TECH_DISTANCE_FIXED: u32 = 9u;
const TECH_DISTANCE: u32 = 10u;

// linear.rs: binary-search steps of relief mapping and relaxed cones, and of
// Bevy's `Relief { max_steps: 5 }`.
const BINARY_STEPS: u32 = 6u;
const BEVY_RELIEF_STEPS: u32 = 5u;

// Cone ratios per height texel (R32Float, nearest) and the max pyramid as
// the mip chain of a power-of-two texture (level l holds the CPU's level l in
// its top-left corner).
@group(1) @binding(3) var cone_tex: texture_2d<f32>;
@group(1) @binding(4) var relaxed_tex: texture_2d<f32>;
@group(1) @binding(5) var pyramid_tex: texture_2d<f32>;

// techniques/mod.rs `Segment`: from where the ray enters the shell to where
// it would reach the floor.
struct Segment {
    o: vec3f,
    d: vec3f,
    t_in: f32,
    t_out: f32,
    z_in: f32,
}

struct Traced {
    found: bool,
    t: f32,
    fetches: u32,
}

fn seg_at(s: Segment, t: f32) -> vec3f {
    return s.o + s.d * t;
}

fn seg_t_at_depth(s: Segment, depth: f32) -> f32 {
    return s.t_in + ((1.0 - depth) - s.z_in) / s.d.z;
}

fn seg_depth_in(s: Segment) -> f32 {
    return 1.0 - s.z_in;
}

fn seg_height_at(p: vec3f) -> f32 {
    return height_sample(p.x / params.aspect.x, p.y / params.aspect.y);
}

// A hit past the side the ray leaves through is off the face: a miss.
fn seg_hit_at(s: Segment, t: f32, fetches: u32) -> Traced {
    return Traced(t <= s.t_out * (1.0 + 1e-6) + 1e-6, t, fetches);
}

struct Probe {
    t: f32,
    gap: f32,
}

fn seg_probe(s: Segment, t: f32) -> Probe {
    let p = seg_at(s, t);
    return Probe(t, p.z - seg_height_at(p));
}

struct Bracket {
    above: Probe,
    below: Probe,
    fetches: u32,
}

// Layers of `layer_depth` down from the entry, at most `layers`, none below
// the floor (linear.rs `layer_search_fraction`).
fn layer_search_fraction(s: Segment, layer_depth: f32, layers: u32) -> Bracket {
    let d0 = seg_depth_in(s);
    var above = seg_probe(s, s.t_in);
    if (above.gap <= 0.0) {
        return Bracket(above, above, 1u);
    }
    var fetches = 1u;
    for (var i = 1u; i <= layers; i++) {
        let d = min(d0 + layer_depth * f32(i), 1.0);
        let below = seg_probe(s, seg_t_at_depth(s, d));
        fetches += 1u;
        if (below.gap <= 0.0) {
            return Bracket(above, below, fetches);
        }
        above = below;
    }
    return Bracket(above, above, fetches);
}

fn layer_search(s: Segment, layers: u32) -> Bracket {
    return layer_search_fraction(s, (1.0 - seg_depth_in(s)) / f32(layers), layers);
}

// Tatarchuk 2006's line intersection between the last two samples.
fn interpolate(b: Bracket) -> f32 {
    let denom = b.above.gap - b.below.gap;
    if (denom <= 0.0) {
        return b.below.t;
    }
    return b.above.t + (b.below.t - b.above.t) * (b.above.gap / denom);
}

// Policarpo et al. 2005's binary search, one fetch per halving; the answer
// is the bracket's midpoint.
fn bisect(s: Segment, bracket: Bracket, steps: u32) -> Traced {
    var b = bracket;
    for (var i = 0u; i < steps; i++) {
        let mid = seg_probe(s, 0.5 * (b.above.t + b.below.t));
        b.fetches += 1u;
        if (mid.gap > 0.0) {
            b.above = mid;
        } else {
            b.below = mid;
        }
    }
    return seg_hit_at(s, 0.5 * (b.above.t + b.below.t), b.fetches);
}

// Rust's `f32::round` (half away from zero) for x >= 0; WGSL's rounds half
// to even.
fn round_half_up(x: f32) -> f32 {
    let f = floor(x);
    return select(round(x), f + 1.0, x - f == 0.5);
}

fn parallax(s: Segment) -> Traced {
    let h0 = seg_height_at(seg_at(s, s.t_in));
    return seg_hit_at(s, s.t_in + max(s.z_in - h0, 0.0), 1u);
}

fn steep(s: Segment, layers: u32) -> Traced {
    let b = layer_search(s, layers);
    return seg_hit_at(s, b.below.t, b.fetches);
}

fn pom(s: Segment, max_layers: u32) -> Traced {
    let lo = f32(max(max_layers / 4u, 1u));
    let hi = f32(max_layers);
    let layers = u32(max(round_half_up(hi + (lo - hi) * abs(s.d.z)), 1.0));
    let b = layer_search(s, layers);
    return seg_hit_at(s, interpolate(b), b.fetches);
}

// Bevy: `mix(max_layer_count, 1, |V.z|)` fractional layers, then POM's
// interpolation (one extra fetch: Bevy fetches the previous layer again) or
// a binary search.
fn bevy(s: Segment, max_layers: u32, relief: bool) -> Traced {
    let hi = f32(max_layers);
    let layers = max(hi + (1.0 - hi) * abs(s.d.z), 1.0);
    let b = layer_search_fraction(s, 1.0 / layers, u32(ceil(layers)));
    if (relief) {
        return bisect(s, b, BEVY_RELIEF_STEPS);
    }
    return seg_hit_at(s, interpolate(b), b.fetches + 1u);
}

fn relief(s: Segment, layers: u32) -> Traced {
    return bisect(s, layer_search(s, layers), BINARY_STEPS);
}

// cone.rs `ConeMap::ratio_at`: the texel under p, nearest, clamped.
fn cone_ratio(relaxed: bool, p: vec3f) -> f32 {
    let n = vec2i(params.height_size);
    let texel = params.aspect / vec2f(params.height_size);
    let i = clamp(i32(p.x / texel.x), 0, n.x - 1);
    let j = clamp(i32(p.y / texel.y), 0, n.y - 1);
    if (relaxed) {
        return textureLoad(relaxed_tex, vec2i(i, j), 0).x;
    }
    return textureLoad(cone_tex, vec2i(i, j), 0).x;
}

// Dummer's step `c (z - h) / (c s_v + s_h)`; relaxed cones end with a binary
// search once a step lands under the surface.
fn cone_step(s: Segment, relaxed: bool, budget: u32) -> Traced {
    let s_v = -s.d.z;
    let s_h = sqrt(s.d.x * s.d.x + s.d.y * s.d.y);
    var t = s.t_in;
    var fetches = 0u;
    var has_above = false;
    var above = Probe(0.0, 0.0);
    for (var k = 0u; k < budget; k++) {
        if (t > s.t_out) {
            return Traced(false, 0.0, fetches);
        }
        let probe = seg_probe(s, t);
        let c = cone_ratio(relaxed, seg_at(s, t));
        fetches += 2u;
        if (probe.gap <= 0.0) {
            if (has_above && relaxed) {
                return bisect(s, Bracket(above, probe, fetches), BINARY_STEPS);
            }
            return seg_hit_at(s, t, fetches);
        }
        has_above = true;
        above = probe;
        t += c * probe.gap / (c * s_v + s_h);
    }
    return seg_hit_at(s, t, fetches);
}

// max_mip.rs `axis_exit`.
fn axis_exit(o: f32, d: f32, lo: f32, hi: f32) -> f32 {
    if (d > 0.0) {
        return (hi - o) / d;
    }
    if (d < 0.0) {
        return (lo - o) / d;
    }
    return BIG;
}

// The next float after t >= 0, so that a walk stuck on a boundary moves on.
fn next_after(t: f32) -> f32 {
    return max(bitcast<f32>(bitcast<u32>(t) + 1u), t + 1e-7);
}

// 1e-4 times Rust's `f32::signum` (which is 1 for +0 and -1 for -0).
fn cell_bias(dc: f32) -> f32 {
    return select(1e-4, -1e-4, (bitcast<u32>(dc) >> 31u) == 1u);
}

// Maximum mipmaps (Tevs, Ihrke and Seidel 2008), max_mip.rs `trace`: up a
// level past a node the ray clears, down to its top otherwise, the patch
// solved exactly at level 0; `budget` bounds node visits plus patches.
fn max_mip(s: Segment, budget: u32) -> Traced {
    let w = i32(params.height_size.x);
    let h = i32(params.height_size.y);
    let ax = params.aspect.x;
    let ay = params.aspect.y;
    let sx = f32(params.height_size.x) / ax;
    let sy = f32(params.height_size.y) / ay;
    let d = s.d;
    let top = textureNumLevels(pyramid_tex) - 1u;
    var level = top;
    var t = s.t_in;
    var fetches = 0u;
    while (t <= s.t_out) {
        if (fetches >= budget) {
            return seg_hit_at(s, t, fetches);
        }
        let p = seg_at(s, t);
        let kx = u32(clamp(i32(floor(p.x * sx - 0.5 + cell_bias(d.x))) + 1, 0, w));
        let ky = u32(clamp(i32(floor(p.y * sy - 0.5 + cell_bias(d.y))) + 1, 0, h));
        let i = kx >> level;
        let j = ky >> level;
        let m = textureLoad(pyramid_tex, vec2u(i, j), level).x;
        fetches += 1u;
        let span = 1u << level;
        let x0 = max((f32(i * span) - 0.5) / sx, 0.0);
        let x1 = min((f32((i + 1u) * span) - 0.5) / sx, ax);
        let y0 = max((f32(j * span) - 0.5) / sy, 0.0);
        let y1 = min((f32((j + 1u) * span) - 0.5) / sy, ay);
        let exit_x = axis_exit(s.o.x, d.x, x0, x1);
        let exit_y = axis_exit(s.o.y, d.y, y0, y1);
        let t_exit = max(min(min(exit_x, exit_y), s.t_out), t);
        if (seg_at(s, t_exit).z > m) {
            t = max(t_exit, next_after(t));
            level = min(level + 1u, top);
            continue;
        }
        t = min(max(t, seg_t_at_depth(s, 1.0 - m)), t_exit);
        if (level > 0u) {
            level -= 1u;
            continue;
        }
        let wk = walk(s.o, d, t, t_exit);
        if (wk.kind == WALK_HIT) {
            return seg_hit_at(s, wk.t, fetches + wk.cells);
        }
        if (wk.kind == WALK_INSIDE) {
            return seg_hit_at(s, t, fetches + wk.cells);
        }
        fetches += wk.cells;
        t = max(t_exit, next_after(t));
        level = min(level + 1u, top);
    }
    return Traced(false, 0.0, fetches);
}

// techniques/mod.rs `Technique::trace`. Distance mapping is the project's
// trace (surface.wgsl `trace_map`, method and iterations from `params`); the
// others search the segment from where the ray enters the shell from above.
fn trace_technique(o: vec3f, d: vec3f, technique: u32, budget_in: u32) -> Traced {
    let budget = max(budget_in, 1u);
    if (technique == TECH_DISTANCE_FIXED || technique == TECH_DISTANCE) {
        let h = trace_map(o, d);
        return Traced(h.kind != HIT_NONE, h.t, h.iterations);
    }
    if (d.z >= 0.0) {
        return Traced(false, 0.0, 0u);
    }
    let clip = clip_shell(o, d, vec3f(params.aspect, 1.0), 0.0, BIG);
    if (!clip.ok) {
        return Traced(false, 0.0, 0u);
    }
    let s = Segment(o, d, clip.t_in, clip.t_out, o.z + d.z * clip.t_in);
    switch (technique) {
        case TECH_PARALLAX: {
            return parallax(s);
        }
        case TECH_STEEP: {
            return steep(s, budget);
        }
        case TECH_POM: {
            return pom(s, budget);
        }
        case TECH_BEVY_OCCLUSION, TECH_BEVY_RELIEF: {
            return bevy(s, budget, technique == TECH_BEVY_RELIEF);
        }
        case TECH_RELIEF: {
            return relief(s, budget);
        }
        case TECH_CONE, TECH_RELAXED_CONE: {
            return cone_step(s, technique == TECH_RELAXED_CONE, budget);
        }
        case TECH_MAX_MIP: {
            return max_mip(s, budget);
        }
        default: {
            return Traced(false, 0.0, 0u);
        }
    }
}
