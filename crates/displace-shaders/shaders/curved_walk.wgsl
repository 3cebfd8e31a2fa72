#define_import_path displace::curved_walk
#import displace::bindings::params
#import displace::convention::{BIG, CHORD_TOLERANCE, HIT_SURFACE, HIT_WALL}
#import displace::surface::{height_sample, trace_range}
#import displace::curved_bindings::prisms

// The walk through a curved mesh's shells that every raster host runs per
// fragment (displace-gpu's curved.wgsl, displace-bevy's curved material):
// the displaced surface S = P + depth h(uv) N of the CPU renderer
// (displace-render's curved_shell.rs and curved_face.rs, whose docs derive
// every formula here). Each triangle's shell runs along its vertex
// normals, X(b, l) = P(b) + l N(b) with N(b) unnormalised, from the base
// triangle to the mesh's one top level; its sides are bilinear patches
// shared bit for bit with the neighbours. A host rasterises the outer
// boundary of the shells (tops, bases and the sides no neighbour shares),
// so a fragment is where the eye ray enters a shell; `walk` then goes from
// shell to shell through the shared sides (the prisms' `adj`), tracing
// each stretch of the ray inside a shell as chords of its curve in texture
// space through the distance map (trace_range), refined on the true ray.
// A walk that leaves through a top or a wall finds nothing: the fragment
// where the ray enters again carries on from there.

// One shell, relative to its first corner (curved_shell.rs `CurvedShell`).
struct Shell {
    pa: vec3f,
    eb: vec3f,
    ec: vec3f,
    na: vec3f,
    nb: vec3f,
    nc: vec3f,
    fb: vec3f,
    fc: vec3f,
    ca: vec3f,
    cb: vec3f,
    cc: vec3f,
    depth: f32,
    top: f32,
    ma: vec2f,
    mb: vec2f,
    mc: vec2f,
    adj: vec4i,
}

fn shell_of(i: u32) -> Shell {
    let p = prisms[i];
    var s: Shell;
    s.pa = p.pa.xyz;
    s.eb = p.pb.xyz - p.pa.xyz;
    s.ec = p.pc.xyz - p.pa.xyz;
    s.na = p.na.xyz;
    s.nb = p.nb.xyz;
    s.nc = p.nc.xyz;
    s.fb = p.nb.xyz - p.na.xyz;
    s.fc = p.nc.xyz - p.na.xyz;
    s.ca = cross(s.eb, s.ec);
    s.cb = cross(s.eb, s.fc) + cross(s.fb, s.ec);
    s.cc = cross(s.fb, s.fc);
    s.top = p.pa.w;
    s.depth = p.pb.w;
    s.ma = p.mab.xy;
    s.mb = p.mab.zw;
    s.mc = p.mc.xy;
    s.adj = p.adj;
    return s;
}

struct Roots {
    r: array<f32, 3>,
    n: u32,
}

// Real roots of a x^2 + b x + c, stable form (curved_shell.rs `quadratic_roots`).
fn quadratic_roots(a: f32, b: f32, c: f32) -> Roots {
    var out: Roots;
    out.n = 0u;
    let scale = max(abs(a), max(abs(b), abs(c)));
    if (scale == 0.0) {
        return out;
    }
    if (abs(a) <= 1e-7 * scale) {
        if (b != 0.0) {
            out.r[0] = -c / b;
            out.n = 1u;
        }
        return out;
    }
    let disc = b * b - 4.0 * a * c;
    if (disc < 0.0) {
        return out;
    }
    var sb = 1.0;
    if (b < 0.0) {
        sb = -1.0;
    }
    let q = -0.5 * (b + sb * sqrt(disc));
    if (q == 0.0) {
        out.r[0] = 0.0;
        out.n = 1u;
        return out;
    }
    out.r[0] = q / a;
    out.r[1] = c / q;
    out.n = 2u;
    return out;
}

fn cubic_at(k: vec4f, x: f32) -> f32 {
    return ((k.w * x + k.z) * x + k.y) * x + k.x;
}

// Real roots in [lo, hi] of k.x + k.y x + k.z x^2 + k.w x^3: monotone
// pieces between the derivative's roots, each with a sign change solved by
// Newton's method inside its bracket (curved_shell.rs `real_roots`).
fn cubic_roots(k: vec4f, lo: f32, hi: f32) -> Roots {
    var cuts = array<f32, 4>(lo, hi, hi, hi);
    var m = 1u;
    let crit = quadratic_roots(3.0 * k.w, 2.0 * k.z, k.y);
    var c0 = BIG;
    var c1 = BIG;
    if (crit.n > 0u) {
        c0 = crit.r[0];
    }
    if (crit.n > 1u) {
        c1 = crit.r[1];
    }
    let a0 = min(c0, c1);
    let a1 = max(c0, c1);
    if (a0 > lo && a0 < hi) {
        cuts[m] = a0;
        m += 1u;
    }
    if (a1 > lo && a1 < hi && a1 != a0) {
        cuts[m] = a1;
        m += 1u;
    }
    cuts[m] = hi;
    var out: Roots;
    out.n = 0u;
    for (var p = 0u; p < m; p++) {
        var a = cuts[p];
        var b = cuts[p + 1u];
        var fa = cubic_at(k, a);
        let fb = cubic_at(k, b);
        if (fa == 0.0) {
            out.r[out.n] = a;
            out.n += 1u;
            continue;
        }
        if ((fa > 0.0) == (fb > 0.0)) {
            continue;
        }
        var x = 0.5 * (a + b);
        for (var i = 0u; i < 24u; i++) {
            let fx = cubic_at(k, x);
            if (fx == 0.0) {
                break;
            }
            if ((fx > 0.0) == (fa > 0.0)) {
                a = x;
                fa = fx;
            } else {
                b = x;
            }
            let dfx = (3.0 * k.w * x + 2.0 * k.z) * x + k.y;
            var next = 0.5 * (a + b);
            if (dfx != 0.0) {
                let newton = x - fx / dfx;
                if (newton > a && newton < b) {
                    next = newton;
                }
            }
            if (abs(next - x) <= 1e-7 * (abs(x) + 1e-6)) {
                x = next;
                break;
            }
            x = next;
        }
        out.r[out.n] = x;
        out.n += 1u;
    }
    return out;
}

struct Loc {
    ok: bool,
    b: vec2f,
    lambda: f32,
    w: f32,
    outside: f32,
}

fn outside_of(s: Shell, b: vec2f, lambda: f32) -> f32 {
    let b0 = 1.0 - b.x - b.y;
    let bary = max(max(-b.x, -b.y), max(-b0, 0.0));
    let level = max(max(-lambda, lambda - s.top), 0.0) / s.top;
    return max(bary, level);
}

// Shell coordinates of the point r (relative to the first corner) on
// level l.
fn level_loc(s: Shell, r: vec3f, l: f32) -> Loc {
    let a = r - l * s.na;
    let b1 = s.eb + l * s.fb;
    let b2 = s.ec + l * s.fc;
    let n = cross(b1, b2);
    let nn = dot(n, n);
    var loc: Loc;
    loc.ok = nn > 0.0;
    if (!loc.ok) {
        return loc;
    }
    let b = vec2f(dot(cross(a, b2), n), dot(cross(b1, a), n)) / nn;
    let nb = s.na + b.x * s.fb + b.y * s.fc;
    return Loc(true, b, l, l * length(nb) / s.depth, outside_of(s, b, l));
}

// Shell coordinates of world point x (curved_shell.rs `locate`).
fn locate(s: Shell, x: vec3f, hint: f32) -> Loc {
    let r = x - s.pa;
    let k = vec4f(
        dot(r, s.ca),
        dot(r, s.cb) - dot(s.na, s.ca),
        dot(r, s.cc) - dot(s.na, s.cb),
        -dot(s.na, s.cc),
    );
    // Along a ray the level moves little from one probe to the next:
    // Newton's method from the hint first (a few loop iterations: lavapipe
    // ends an invocation's loops after 65535 iterations in all), the
    // bracketed solve of every root only when it does not settle in the
    // shell.
    var l = hint;
    for (var i = 0u; i < 8u; i++) {
        let f = cubic_at(k, l);
        let df = (3.0 * k.w * l + 2.0 * k.z) * l + k.y;
        if (df == 0.0) {
            break;
        }
        let step = f / df;
        l -= step;
        if (abs(step) <= 1e-6 * s.top) {
            let quick = level_loc(s, r, l);
            if (quick.ok && quick.outside <= 1e-3) {
                return quick;
            }
            break;
        }
    }
    let roots = cubic_roots(k, -0.5 * s.top, 1.5 * s.top);
    var best: Loc;
    best.ok = false;
    best.outside = BIG;
    var best_near = BIG;
    for (var i = 0u; i < roots.n; i++) {
        let loc = level_loc(s, r, roots.r[i]);
        if (!loc.ok) {
            continue;
        }
        let near = abs(loc.lambda - hint);
        if (loc.outside < best.outside - 1e-6 || (loc.outside <= best.outside + 1e-6 && near < best_near)) {
            best = loc;
            best_near = near;
        }
    }
    return best;
}

fn clamp_bary(b: vec2f) -> vec2f {
    let c = max(b, vec2f(0.0));
    let sum = c.x + c.y;
    if (sum > 1.0) {
        return c / sum;
    }
    return c;
}

// Map point (x, y in map units, z = w) of shell coordinates loc.
fn map_point(s: Shell, loc: Loc) -> vec3f {
    let b = clamp_bary(loc.b);
    let xy = s.ma + b.x * (s.mb - s.ma) + b.y * (s.mc - s.ma);
    return vec3f(xy, loc.w);
}

fn above(c: vec3f) -> f32 {
    return c.z - height_sample(c.x / params.aspect.x, c.y / params.aspect.y);
}

struct Probe {
    ok: bool,
    loc: Loc,
    c: vec3f,
    g: f32,
}

fn probe(s: Shell, o: vec3f, d: vec3f, t: f32, hint: f32) -> Probe {
    var p: Probe;
    p.loc = locate(s, o + t * d, hint);
    p.ok = p.loc.ok;
    if (p.ok) {
        p.c = map_point(s, p.loc);
        p.g = above(p.c);
    }
    return p;
}

// Boundary kinds of a crossing: 0 base, 1 top, 2 + k side k.
struct Crossing {
    t: f32,
    kind: u32,
    normal: vec3f,
}

struct Crossings {
    x: array<Crossing, 8>,
    n: u32,
}

fn facing(n: vec3f, d: vec3f) -> vec3f {
    let u = normalize(n);
    if (dot(u, d) > 0.0) {
        return -u;
    }
    return u;
}

struct TriHit {
    ok: bool,
    t: f32,
    n: vec3f,
}

fn ray_triangle(o: vec3f, d: vec3f, a: vec3f, b: vec3f, c: vec3f) -> TriHit {
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    var h: TriHit;
    h.ok = false;
    if (det == 0.0) {
        return h;
    }
    let inv = 1.0 / det;
    let sv = o - a;
    let b1 = dot(sv, p) * inv;
    let q = cross(sv, e1);
    let b2 = dot(d, q) * inv;
    let eps = 1e-6;
    if (b1 < -eps || b2 < -eps || b1 + b2 > 1.0 + eps) {
        return h;
    }
    h.ok = true;
    h.t = dot(e2, q) * inv;
    h.n = cross(e1, e2);
    return h;
}

// Every crossing of o + t d with the shell's boundary for t > t_min
// (curved_shell.rs `crossings`), o relative to the shell's first corner.
fn crossings(s: Shell, o: vec3f, d: vec3f, t_min: f32) -> Crossings {
    var out: Crossings;
    out.n = 0u;
    let z = vec3f(0.0);
    let top = s.top;
    let base = ray_triangle(o, d, z, s.eb, s.ec);
    if (base.ok && base.t > t_min) {
        out.x[out.n] = Crossing(base.t, 0u, facing(base.n, d));
        out.n += 1u;
    }
    let lid = ray_triangle(o, d, top * s.na, s.eb + top * s.nb, s.ec + top * s.nc);
    if (lid.ok && lid.t > t_min) {
        out.x[out.n] = Crossing(lid.t, 1u, facing(lid.n, d));
        out.n += 1u;
    }
    var corner = array<vec3f, 3>(z, s.eb, s.ec);
    var normal = array<vec3f, 3>(s.na, s.nb, s.nc);
    for (var k = 0u; k < 3u; k++) {
        let j = (k + 1u) % 3u;
        let a0 = corner[k] - o;
        let a1 = corner[j] - corner[k];
        let b0 = normal[k];
        let b1 = normal[j] - normal[k];
        let q0 = dot(a0, cross(d, b0));
        let q1 = dot(a1, cross(d, b0)) + dot(a0, cross(d, b1));
        let q2 = dot(a1, cross(d, b1));
        let roots = quadratic_roots(q2, q1, q0);
        for (var i = 0u; i < roots.n; i++) {
            let sv = roots.r[i];
            if (sv < -1e-6 || sv > 1.0 + 1e-6) {
                continue;
            }
            let a = corner[k] + sv * a1;
            let b = b0 + sv * b1;
            let dxb = cross(d, b);
            let den = dot(dxb, dxb);
            if (den <= 0.0) {
                continue;
            }
            let r = a - o;
            let t = dot(cross(r, b), dxb) / den;
            let mu = dot(cross(r, d), dxb) / den;
            if (mu < -1e-6 * top || mu > top * (1.0 + 1e-6) || t <= t_min || out.n >= 8u) {
                continue;
            }
            out.x[out.n] = Crossing(t, 2u + k, facing(cross(a1 + mu * b1, b), d));
            out.n += 1u;
        }
    }
    // Sorted by t (insertion sort of at most eight).
    for (var i = 1u; i < out.n; i++) {
        let key = out.x[i];
        var j = i;
        while (j > 0u && out.x[j - 1u].t > key.t) {
            out.x[j] = out.x[j - 1u];
            j -= 1u;
        }
        out.x[j] = key;
    }
    return out;
}

// Columns dX/dx, dX/dy, dX/dz of the map-to-world mapping at (b, w)
// (curved_shell.rs `jacobian`).
fn jacobian(s: Shell, b: vec2f, w: f32) -> mat3x3f {
    let n = s.na + b.x * s.fb + b.y * s.fc;
    let len = length(n);
    let nh = n / len;
    let db1 = s.eb + s.depth * w * (s.fb - nh * dot(nh, s.fb)) / len;
    let db2 = s.ec + s.depth * w * (s.fc - nh * dot(nh, s.fc)) / len;
    // Map xy to b: the inverse of the texture triangle's edge matrix.
    let t1 = s.mb - s.ma;
    let t2 = s.mc - s.ma;
    let det = t1.x * t2.y - t2.x * t1.y;
    let i00 = t2.y / det;
    let i01 = -t2.x / det;
    let i10 = -t1.y / det;
    let i11 = t1.x / det;
    return mat3x3f(db1 * i00 + db2 * i10, db1 * i01 + db2 * i11, s.depth * nh);
}

// Rows of the inverse of j: map-space components of a world vector.
fn inverse_rows(j: mat3x3f) -> mat3x3f {
    let r0 = cross(j[1], j[2]);
    let r1 = cross(j[2], j[0]);
    let r2 = cross(j[0], j[1]);
    let det = dot(j[0], r0);
    return transpose(mat3x3f(r0, r1, r2)) * (1.0 / det);
}

// World normal of map-space normal n (the inverse transpose of j).
fn normal_to_world(j: mat3x3f, n: vec3f) -> vec3f {
    let r0 = cross(j[1], j[2]);
    let r1 = cross(j[2], j[0]);
    let r2 = cross(j[0], j[1]);
    let sign = sign(dot(j[0], r0));
    return normalize((n.x * r0 + n.y * r1 + n.z * r2) * sign);
}

struct CurvedHit {
    found: bool,
    t: f32,
    loc: Loc,
    c: vec3f,
    wall: bool,
    normal: vec3f,
}

// The root of w - h near the chord hit t, within [ta, tb] where the ray
// is above at ta, the bracket's first probe a thousandth of the chord
// (span) away (curved_face.rs `refine`, regula falsi).
fn refine(s: Shell, o: vec3f, d: vec3f, ta: f32, tb: f32, t: f32, span: f32, hint: f32) -> f32 {
    let pt = probe(s, o, d, t, hint);
    if (!pt.ok || pt.g == 0.0) {
        return t;
    }
    var lo = t;
    var hi = t;
    var glo = pt.g;
    var ghi = pt.g;
    var step = 1e-3 * max(span, 1e-9);
    if (pt.g < 0.0) {
        for (var i = 0u; i < 12u && glo < 0.0 && lo > ta; i++) {
            lo = max(t - step, ta);
            let p = probe(s, o, d, lo, hint);
            glo = select(0.0, p.g, p.ok);
            step *= 8.0;
        }
        if (glo < 0.0) {
            return t;
        }
    } else {
        for (var i = 0u; i < 12u && ghi > 0.0 && hi < tb; i++) {
            hi = min(t + step, tb);
            let p = probe(s, o, d, hi, hint);
            ghi = select(0.0, p.g, p.ok);
            step *= 8.0;
        }
        if (ghi > 0.0) {
            return t;
        }
    }
    var side = 0;
    for (var i = 0u; i < 16u; i++) {
        var m = (lo * ghi - hi * glo) / (ghi - glo);
        if (!(m > lo && m < hi)) {
            m = 0.5 * (lo + hi);
        }
        let p = probe(s, o, d, m, hint);
        if (!p.ok) {
            break;
        }
        if (p.g >= 0.0) {
            lo = m;
            glo = p.g;
            if (side == 1) {
                ghi *= 0.5;
            }
            side = 1;
        } else {
            hi = m;
            ghi = p.g;
            if (side == -1) {
                glo *= 0.5;
            }
            side = -1;
        }
        if (hi - lo <= 1e-7 * (1.0 + abs(hi))) {
            break;
        }
    }
    return hi;
}

const MAX_CHORD_DEPTH: u32 = 16u;

// The first hit on [ta, tb], a stretch inside shell s entered through
// boundary `entry` (its outward normal `entry_normal`; 99: the ray starts
// inside), as curved_face.rs `stretch` finds it: chords of the curve in
// texture space, halved while their midpoints stray, each traced through
// the distance map.
fn stretch(s: Shell, o: vec3f, d: vec3f, ta: f32, tb: f32, entry: u32, entry_normal: vec3f, exit: u32) -> CurvedHit {
    var hit: CurvedHit;
    hit.found = false;
    var hint = 0.5 * s.top;
    if (entry == 1u) {
        hint = s.top;
    } else if (entry == 0u) {
        hint = 0.0;
    }
    var pa = probe(s, o, d, ta, hint);
    if (!pa.ok) {
        pa = probe(s, o, d, ta + 1e-6 * (tb - ta), hint);
        if (!pa.ok) {
            return hit;
        }
    }
    if (pa.g < 0.0) {
        // Entered under the surface: the wall entered through, except a
        // shared side or the top, where the surface meets it.
        var wall = true;
        var n = entry_normal;
        if (entry == 1u || (entry >= 2u && entry < 5u && s.adj[entry - 2u] >= 0)) {
            wall = false;
        }
        if (entry == 99u) {
            n = -d;
        }
        hit = CurvedHit(true, ta, pa.loc, pa.c, wall, n);
        return hit;
    }
    var pb = probe(s, o, d, tb, pa.loc.lambda);
    if (!pb.ok) {
        pb = probe(s, o, d, tb - 1e-6 * (tb - ta), pa.loc.lambda);
        if (!pb.ok) {
            return hit;
        }
    }
    // Depth-first halving with an explicit stack of pending right ends.
    var stack_t: array<f32, 16>;
    var stack_c: array<vec3f, 16>;
    var sp = 0u;
    var at = ta;
    var ac = pa.c;
    var bt = tb;
    var bc = pb.c;
    let hint2 = pa.loc.lambda;
    for (var guard = 0u; guard < 512u; guard++) {
        if (sp < MAX_CHORD_DEPTH) {
            let tm = 0.5 * (at + bt);
            let pm = probe(s, o, d, tm, hint2);
            if (pm.ok && length(pm.c - 0.5 * (ac + bc)) > CHORD_TOLERANCE) {
                stack_t[sp] = bt;
                stack_c[sp] = bc;
                sp += 1u;
                bt = tm;
                bc = pm.c;
                continue;
            }
        }
        let v = bc - ac;
        let len = length(v);
        if (len > 0.0) {
            let th = trace_range(ac, v / len, 0.0, len);
            if (th.kind == HIT_SURFACE || th.kind == HIT_WALL) {
                var f = 0.0;
                if (th.kind == HIT_SURFACE) {
                    f = clamp(th.t / len, 0.0, 1.0);
                }
                let t = refine(s, o, d, ta, tb, at + f * (bt - at), bt - at, hint2);
                let p = probe(s, o, d, t, hint2);
                if (p.ok) {
                    hit = CurvedHit(true, t, p.loc, p.c, false, vec3f(0.0));
                    return hit;
                }
            }
        }
        if (sp == 0u) {
            // Heights never go below the base: a ray leaving through it
            // has met the surface there (sphere_trace.rs
            // `leaves_through_floor`), where the chords' walks may not
            // resolve the root at their very end.
            if (exit == 0u) {
                let p = probe(s, o, d, tb, hint2);
                if (p.ok) {
                    hit = CurvedHit(true, tb, p.loc, p.c, false, vec3f(0.0));
                }
            }
            break;
        }
        sp -= 1u;
        at = bt;
        ac = bc;
        bt = stack_t[sp];
        bc = stack_c[sp];
    }
    return hit;
}

const MAX_SHELLS: u32 = 64u;

// What `walk` found: the hit (if any) and the shell it lies in.
struct Walk {
    hit: CurvedHit,
    shell: Shell,
}

// The first hit of the ray eye + t d (d unit) beyond t_from, starting in
// the shell `first` whose boundary the fragment lies on.
fn walk(first: u32, eye: vec3f, d: vec3f, t_from_start: f32) -> Walk {
    var prism = first;
    var t_from = t_from_start;
    var out: Walk;
    out.hit.found = false;
    out.shell = shell_of(prism);
    // The rasteriser gives a pixel on the edge between two tops (or
    // bases) to one of them by its own rule, the ray-triangle test of
    // `crossings` to either by rounding: where the fragment's shell finds
    // no stretch, its neighbours across its three sides are tried before
    // the ray is given up (else a lone pixel of a closed mesh shows the
    // far side through a hole).
    let beside = out.shell.adj;
    var tried = 0u;
    var entered = false;
    for (var step = 0u; step < MAX_SHELLS; step++) {
        let s = shell_of(prism);
        out.shell = s;
        let o = eye - s.pa;
        let xs = crossings(s, o, d, 0.0);
        // The first stretch inside the shell that ends after t_from.
        var a = 0.0;
        var entry = 99u;
        var entry_n = vec3f(0.0);
        var exit = 99u;
        var found_stretch = false;
        var sa = 0.0;
        var sb = 0.0;
        var s_entry = 99u;
        var s_entry_n = vec3f(0.0);
        for (var k = 0u; k < xs.n; k++) {
            let b = xs.x[k].t;
            if (b > a && b > t_from + 1e-6 * (1.0 + t_from)) {
                let mid_w = locate(s, eye + 0.5 * (a + b) * d, 0.5 * s.top);
                if (mid_w.ok && mid_w.outside <= 1e-5) {
                    found_stretch = true;
                    sa = max(a, 0.0);
                    sb = b;
                    s_entry = entry;
                    s_entry_n = entry_n;
                    exit = xs.x[k].kind;
                    break;
                }
            }
            a = b;
            entry = xs.x[k].kind;
            entry_n = xs.x[k].normal;
        }
        if (!found_stretch) {
            if (entered) {
                return out;
            }
            while (tried < 3u && beside[tried] < 0) {
                tried++;
            }
            if (tried == 3u) {
                return out;
            }
            prism = u32(beside[tried]);
            tried++;
            continue;
        }
        entered = true;
        out.hit = stretch(s, eye, d, sa, sb, s_entry, s_entry_n, exit);
        if (out.hit.found) {
            return out;
        }
        if (exit >= 2u && exit < 5u && s.adj[exit - 2u] >= 0) {
            prism = u32(s.adj[exit - 2u]);
            t_from = sb;
            continue;
        }
        return out;
    }
    return out;
}
