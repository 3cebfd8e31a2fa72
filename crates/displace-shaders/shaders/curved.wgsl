#import displace::bindings::params
#import displace::convention::{HIT_SURFACE, HIT_WALL}
#import displace::surface::TraceHit
#import displace::curved_walk::{walk, clamp_bary, jacobian, inverse_rows, normal_to_world}
#import displace::shade::{FsOut, color_tex, frame, normal_tex, shade_sampler, shadow, shell_out}
#import displace::lighting::blinn_phong

// The raster path of displace-gpu for curved meshes: the outer boundary of
// the shells is drawn (tops, bases and the sides no neighbour shares), each
// vertex with its prism, so a fragment is where the eye ray enters a
// shell; displace::curved_walk finds the first hit from there, and the hit
// is shaded as the CPU renderer's direct light shades it.

struct CurvedVertex {
    @location(0) position: vec3f,
    @location(1) prism: u32,
}

struct CurvedVsOut {
    @builtin(position) clip: vec4f,
    @location(0) world: vec3f,
    @location(1) @interpolate(flat) prism: u32,
}

@vertex
fn vs_curved(v: CurvedVertex) -> CurvedVsOut {
    var out: CurvedVsOut;
    out.clip = frame.view_proj * vec4f(v.position, 1.0);
    out.world = v.position;
    out.prism = v.prism;
    return out;
}

@fragment
fn fs_curved(in: CurvedVsOut) -> FsOut {
    let eye = frame.eye.xyz;
    let to = in.world - eye;
    let t_frag = length(to);
    let d = to / t_frag;
    // The rasterised sides are flat, the shells' bilinear: look for the
    // entry a little before the fragment.
    let found = walk(in.prism, eye, d, t_frag * (1.0 - 1e-3));
    let hit = found.hit;
    let s = found.shell;
    if (!hit.found) {
        discard;
    }
    let world = eye + hit.t * d;
    let uv_local = hit.c.xy / params.aspect;
    let j = jacobian(s, clamp_bary(hit.loc.b), hit.loc.w);
    var n_map = vec3f(0.0, 0.0, 1.0);
    var n = hit.normal;
    var kind = HIT_WALL;
    if (!hit.wall) {
        kind = HIT_SURFACE;
        n_map = normalize(textureSampleLevel(normal_tex, shade_sampler, uv_local, 0.0).xyz * 2.0 - 1.0);
        n = normal_to_world(j, n_map);
    } else {
        n_map = normalize(inverse_rows(j) * n);
    }
    let to_light = frame.light.xyz - world;
    let l = normalize(to_light);
    // Self-shadowing along the hit's local frame: the light direction in
    // map space, marched straight from the hit.
    let inv = inverse_rows(j);
    let l_map_v = inv * to_light;
    let l_map = normalize(l_map_v);
    var lit = max(dot(n, l), 0.0) * shadow(hit.c + n_map * params.tau, l_map, length(l_map_v));
    if (frame.falloff == 1u) {
        let r = length(to_light);
        lit = lit / max(r * r, 1e-20);
    }
    let albedo = textureSampleLevel(color_tex, shade_sampler, uv_local, 0.0).rgb;
    let half_vec = normalize(l - d);
    let rgb = blinn_phong(albedo, n, half_vec, lit, frame.ambient, frame.light_intensity, frame.specular, frame.shininess);
    return shell_out(rgb, uv_local + frame.uv_shift, TraceHit(kind, hit.t, n_map, 0u, true), world);
}
