#define_import_path displace::surface
#import displace::convention::{BIG, HIT_NONE, HIT_SURFACE, HIT_WALL, INSIDE_EPS, LINEAR_EPS, METHOD_EXACT, METHOD_SPHERE_FIXED, ROOT_EPS, TEXEL_CENTRE, lerp, texel_lerp, wrap_index}
#import displace::bindings::{params, height_tex}
#import displace::distance::distance_at

// The continuous height surface, the exact walk over its bilinear patches
// (exact.rs) and the map-space trace (sphere_trace.rs), in single precision.
// Imports the conventions, the map bindings of its user and one distance
// lookup (displace::distance, distance_*.wgsl).

var<private> cell_cap_reached: bool = false;
// A loop ended where its own exits cannot: the driver cut it short.
// lavapipe (llvmpipe) ends every loop of an invocation once they have run
// 65535 iterations in all (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS); without
// this flag the trace after the cut reads as a miss.
var<private> loop_cut: bool = false;

fn height_texel(i: i32, j: i32) -> f32 {
    let n = params.height_size;
    let ii = wrap_index(i, n.x, params.address);
    let jj = wrap_index(j, n.y, params.address);
    return textureLoad(height_tex, vec2i(ii, jj), 0).x;
}

// h(u, v): bilinear between texel centres (HeightMap::sample).
fn height_sample(u: f32, v: f32) -> f32 {
    let lx = texel_lerp(u, params.height_size.x);
    let ly = texel_lerp(v, params.height_size.y);
    let i = i32(lx.x);
    let j = i32(ly.x);
    let a = lerp(height_texel(i, j), height_texel(i + 1, j), lx.y);
    let b = lerp(height_texel(i, j + 1), height_texel(i + 1, j + 1), lx.y);
    return lerp(a, b, ly.y);
}

// Normal of the bilinear surface at map-space point p (sphere_trace.rs
// `shading_normal`), for hits that have no patch of their own.
fn surface_normal(p: vec3f) -> vec3f {
    let lx = texel_lerp(p.x / params.aspect.x, params.height_size.x);
    let ly = texel_lerp(p.y / params.aspect.y, params.height_size.y);
    let i = i32(lx.x);
    let j = i32(ly.x);
    let h00 = height_texel(i, j);
    let h10 = height_texel(i + 1, j);
    let h01 = height_texel(i, j + 1);
    let h11 = height_texel(i + 1, j + 1);
    let dfx = (h10 - h00) * (1.0 - ly.y) + (h11 - h01) * ly.y;
    let dfy = (h01 - h00) * (1.0 - lx.y) + (h11 - h10) * lx.y;
    let gx = dfx * f32(params.height_size.x);
    let gy = dfy * f32(params.height_size.y);
    return normalize(vec3f(-gx / params.aspect.x, -gy / params.aspect.y, 1.0));
}

struct Root {
    found: bool,
    s: f32,
}

// Smallest root of k0 + k1 s + k2 s^2 in [lo, hi] where the function goes
// from non-negative to non-positive (exact.rs `smallest_root`).
fn smallest_root(k0: f32, k1: f32, k2: f32, lo: f32, hi: f32) -> Root {
    if (k0 <= 0.0) {
        return Root(true, max(0.0, lo));
    }
    let scale = max(abs(k0), max(abs(k1), abs(k2)));
    if (abs(k2) <= LINEAR_EPS * scale) {
        if (k1 >= 0.0) {
            return Root(false, 0.0);
        }
        let s = -k0 / k1;
        return Root(s >= lo && s <= hi, s);
    }
    let disc = k1 * k1 - 4.0 * k2 * k0;
    if (disc < 0.0) {
        return Root(false, 0.0);
    }
    // Numerically stable pair (Numerical Recipes 5.6).
    let q = -0.5 * (k1 + select(-1.0, 1.0, k1 >= 0.0) * sqrt(disc));
    let ra = q / k2;
    var rb = ra;
    if (q != 0.0) {
        rb = k0 / q;
    }
    let r1 = min(ra, rb);
    let r2 = max(ra, rb);
    if (r1 >= lo && r1 <= hi) {
        return Root(true, r1);
    }
    return Root(r2 >= lo && r2 <= hi, r2);
}

struct PatchHit {
    found: bool,
    s: f32,
    normal: vec3f,
}

// First root on bilinear cell (ci, cj) for s in [sa, sb], where the ray is
// c0 + q s in cell coordinates (texel centres at integers) and p0 + d s in
// map space.
// `t0` is the ray parameter at s = 0: the root tolerance scales with the
// absolute parameter of the segment's end, as on the CPU (exact.rs: segment
// ends come from single-precision parameters, and a root a few ulps past the
// end, such as a hit on the shell's floor, belongs to this segment).
fn patch_hit(ci: i32, cj: i32, p0: vec3f, d: vec3f, c0: vec2f, q: vec2f, t0: f32, sa: f32, sb: f32) -> PatchHit {
    let h00 = height_texel(ci, cj);
    let h10 = height_texel(ci + 1, cj);
    let h01 = height_texel(ci, cj + 1);
    let h11 = height_texel(ci + 1, cj + 1);
    let a = h10 - h00;
    let b = h01 - h00;
    let c = h00 - h10 - h01 + h11;
    let pz = p0.z + d.z * sa;
    let px = c0.x + q.x * sa - f32(ci);
    let py = c0.y + q.y * sa - f32(cj);
    let k0 = pz - h00 - a * px - b * py - c * px * py;
    let k1 = d.z - a * q.x - b * q.y - c * (px * q.y + q.x * py);
    let k2 = -c * q.x * q.y;
    let len = sb - sa;
    let eps = ROOT_EPS * (1.0 + abs(t0 + sb));
    let root = smallest_root(k0, k1, k2, -eps, len + eps);
    if (!root.found) {
        return PatchHit(false, 0.0, vec3f(0.0));
    }
    let s = clamp(root.s, 0.0, len);
    let fx = clamp(px + q.x * s, 0.0, 1.0);
    let fy = clamp(py + q.y * s, 0.0, 1.0);
    let sx = f32(params.height_size.x) / params.aspect.x;
    let sy = f32(params.height_size.y) / params.aspect.y;
    let dhdx = (a + c * fy) * sx;
    let dhdy = (b + c * fx) * sy;
    return PatchHit(true, sa + s, normalize(vec3f(-dhdx, -dhdy, 1.0)));
}

const WALK_HIT: u32 = 0u;
const WALK_INSIDE: u32 = 1u;
const WALK_MISS: u32 = 2u;

struct Walk {
    kind: u32,
    t: f32,
    normal: vec3f,
    cells: u32,
}

// First point of o + t d, t in [t0, t1], on the surface: a 2D DDA over the
// bilinear patches (exact.rs `walk`), relative to t0 for precision.
fn walk(o: vec3f, d: vec3f, t0: f32, t1: f32) -> Walk {
    if (t1 < t0) {
        return Walk(WALK_MISS, t0, vec3f(0.0), 0u);
    }
    let p0 = o + d * t0;
    if (p0.z < height_sample(p0.x / params.aspect.x, p0.y / params.aspect.y) - INSIDE_EPS) {
        return Walk(WALK_INSIDE, t0, vec3f(0.0), 0u);
    }
    let sx = f32(params.height_size.x) / params.aspect.x;
    let sy = f32(params.height_size.y) / params.aspect.y;
    let c0 = vec2f(p0.x * sx - TEXEL_CENTRE, p0.y * sy - TEXEL_CENTRE);
    let q = vec2f(d.x * sx, d.y * sy);
    var ci = i32(floor(c0.x));
    var cj = i32(floor(c0.y));
    let step_i = select(-1, 1, q.x > 0.0);
    let step_j = select(-1, 1, q.y > 0.0);
    var tx = BIG;
    var ty = BIG;
    var dtx = BIG;
    var dty = BIG;
    if (q.x != 0.0) {
        tx = (select(f32(ci), f32(ci + 1), q.x > 0.0) - c0.x) / q.x;
        dtx = 1.0 / abs(q.x);
    }
    if (q.y != 0.0) {
        ty = (select(f32(cj), f32(cj + 1), q.y > 0.0) - c0.y) / q.y;
        dty = 1.0 / abs(q.y);
    }
    let len = t1 - t0;
    var sa = 0.0;
    var cells = 0u;
    loop {
        if (cells >= params.max_cells) {
            cell_cap_reached = true;
            return Walk(WALK_MISS, t1, vec3f(0.0), cells);
        }
        let sb = min(min(tx, ty), len);
        cells += 1u;
        let h = patch_hit(ci, cj, p0, d, c0, q, t0, sa, sb);
        if (h.found) {
            return Walk(WALK_HIT, t0 + h.s, h.normal, cells);
        }
        if (sb >= len) {
            return Walk(WALK_MISS, t1, vec3f(0.0), cells);
        }
        sa = sb;
        if (tx < ty) {
            ci += step_i;
            tx += dtx;
        } else {
            cj += step_j;
            ty += dty;
        }
    }
    // Every exit of the loop returns: reaching here means it was cut.
    loop_cut = true;
    return Walk(WALK_MISS, t1, vec3f(0.0), cells);
}

struct Clip {
    ok: bool,
    t_in: f32,
    t_out: f32,
    entry_normal: vec3f,
}

// The ray against the shell's box (sphere_trace.rs `clip`).
fn clip_shell(o: vec3f, d: vec3f, hi: vec3f, t_min: f32, t_max: f32) -> Clip {
    var t_in = t_min;
    var t_out = t_max;
    var entry = vec3f(0.0);
    for (var a = 0; a < 3; a++) {
        if (d[a] == 0.0) {
            if (o[a] < 0.0 || o[a] > hi[a]) {
                return Clip(false, 0.0, 0.0, entry);
            }
            continue;
        }
        var t0 = (0.0 - o[a]) / d[a];
        var t1 = (hi[a] - o[a]) / d[a];
        var n = vec3f(0.0);
        n[a] = -1.0;
        if (t0 > t1) {
            let tmp = t0;
            t0 = t1;
            t1 = tmp;
            n[a] = 1.0;
        }
        if (t0 > t_in) {
            t_in = t0;
            entry = n;
        }
        t_out = min(t_out, t1);
    }
    return Clip(t_in <= t_out, t_in, t_out, entry);
}

struct TraceHit {
    kind: u32,
    t: f32,
    normal: vec3f,
    iterations: u32,
    converged: bool,
}

// A miss still reports what it cost (sphere_trace.rs `trace_counted`).
fn trace_miss(iterations: u32) -> TraceHit {
    return TraceHit(HIT_NONE, 0.0, vec3f(0.0), iterations, false);
}

fn surface_at(o: vec3f, d: vec3f, t: f32, iterations: u32, converged: bool) -> TraceHit {
    return TraceHit(HIT_SURFACE, t, surface_normal(o + d * t), iterations, converged);
}

// First hit of the map-space ray o + t d (d unit length in map space):
// sphere tracing with the early out and the exact walk over the band the map
// cannot resolve, Donnelly's fixed loop, or the exact walk alone, as
// displace_core::sphere_trace::trace does it.
fn trace_map(o: vec3f, d: vec3f) -> TraceHit {
    return trace_range(o, d, params.t_min, params.t_max);
}

// trace_map over the hits with t in [t_min, t_max] (a curved mesh's
// chords, curved.wgsl).
fn trace_range(o: vec3f, d: vec3f, t_min: f32, t_max: f32) -> TraceHit {
    let hi = vec3f(params.aspect.x * params.tiles.x, params.aspect.y * params.tiles.y, 1.0);
    let clip = clip_shell(o, d, hi, t_min, t_max);
    if (!clip.ok) {
        return trace_miss(0u);
    }
    // Under the surface where the ray enters: the wall of the slab.
    let entry = o + d * clip.t_in;
    if (entry.z < height_sample(entry.x / params.aspect.x, entry.y / params.aspect.y)) {
        var n = clip.entry_normal;
        if (all(n == vec3f(0.0))) {
            n = -d;
        }
        return TraceHit(HIT_WALL, clip.t_in, n, 0u, true);
    }
    if (params.method == METHOD_EXACT) {
        let w = walk(o, d, clip.t_in, clip.t_out);
        if (w.kind == WALK_HIT) {
            return TraceHit(HIT_SURFACE, w.t, w.normal, w.cells, true);
        }
        return trace_miss(w.cells);
    }
    let fixed = params.method == METHOD_SPHERE_FIXED;
    let max_steps = max(params.iterations, 1u);
    var t = clip.t_in;
    var iterations = 0u;
    var steps = 0u;
    while (t <= clip.t_out) {
        if (steps >= max_steps) {
            if (fixed) {
                // Donnelly's loop ends here: refine what the map can no
                // longer resolve; otherwise the hit is unconverged.
                let w = walk(o, d, t, min(t + params.band, clip.t_out));
                if (w.kind == WALK_HIT) {
                    return TraceHit(HIT_SURFACE, w.t, w.normal, iterations + w.cells, true);
                }
                return surface_at(o, d, t, iterations + w.cells, false);
            }
            // Out of steps: finish exactly, which is always right.
            let w = walk(o, d, t, clip.t_out);
            if (w.kind == WALK_HIT) {
                return TraceHit(HIT_SURFACE, w.t, w.normal, iterations + w.cells, true);
            }
            if (w.kind == WALK_INSIDE) {
                return surface_at(o, d, t, iterations + w.cells, true);
            }
            return trace_miss(iterations + w.cells);
        }
        let s = distance_at(o + d * t);
        steps += 1u;
        iterations += 1u;
        if (!fixed && s < params.tau) {
            let t1 = min(t + params.band, clip.t_out);
            let w = walk(o, d, t, t1);
            if (w.kind == WALK_HIT) {
                return TraceHit(HIT_SURFACE, w.t, w.normal, iterations + w.cells, true);
            }
            if (w.kind == WALK_INSIDE) {
                return surface_at(o, d, t, iterations + w.cells, true);
            }
            iterations += w.cells;
            if (t1 >= clip.t_out) {
                return trace_miss(iterations);
            }
            t = t1;
        } else {
            // A negative value steps back over points known to be free.
            t = max(t + s, clip.t_in);
        }
    }
    if (t <= clip.t_out) {
        // The loop's condition still holds: the driver ended it.
        loop_cut = true;
    }
    return trace_miss(iterations);
}
