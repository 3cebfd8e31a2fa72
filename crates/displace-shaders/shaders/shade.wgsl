#define_import_path displace::shade
#import displace::convention::{HIT_NONE, HIT_SURFACE, SHADOWS_HARD, SHADOWS_NONE}
#import displace::bindings::params
#import displace::distance::distance_at
#import displace::surface::{TraceHit, clip_shell, trace_map}
#import displace::lighting::blinn_phong

// Shading shared by the raster entry points (GPU Gems 2 ch. 8, section
// 8.5): the frame uniform, self-shadowing by a second march, and the
// normal-mapped lighting of a hit with the colour texture sampled with the
// derivatives of the undisplaced texture coordinates (8.5.3).

struct Frame {
    view_proj: mat4x4f,
    eye: vec4f,
    light: vec4f,
    // The face: origin, tangent and bitangent spanning one tile (their
    // lengths are the tile's size), unit normal.
    face_origin: vec4f,
    face_t: vec4f,
    face_b: vec4f,
    face_n: vec4f,
    // Listing 8-1's factor: 1 / displacement depth, so depth can change live.
    inv_bump_depth: f32,
    // 0: none, 1: hard, 2: soft (penumbra from the distance field).
    shadows: u32,
    penumbra_k: f32,
    ambient: f32,
    specular: f32,
    shininess: f32,
    light_intensity: f32,
    // 1: the light is a point of radiant intensity light_intensity, falling
    // off with the squared world distance (the CPU renderer's point light).
    falloff: u32,
    // Mesh draws: subtracted from the mesh's texture coordinates to put
    // them in the map window (mesh.rs), added back for the UV output.
    uv_shift: vec2f,
    _pad: vec2f,
}

@group(1) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(1) var normal_tex: texture_2d<f32>;
@group(1) @binding(2) var color_tex: texture_2d<f32>;
@group(1) @binding(3) var shade_sampler: sampler;

// Light visibility from map-space point p towards direction l, dist away:
// a second trace towards the light; the soft variant also keeps the
// smallest distance-to-travel ratio seen (the distance field's penumbra).
fn shadow(p: vec3f, l: vec3f, dist: f32) -> f32 {
    if (frame.shadows == SHADOWS_NONE) {
        return 1.0;
    }
    let occluder = trace_map(p, l);
    if (occluder.kind != HIT_NONE && occluder.t < dist) {
        return 0.0;
    }
    if (frame.shadows == SHADOWS_HARD) {
        return 1.0;
    }
    let hi = vec3f(params.aspect.x * params.tiles.x, params.aspect.y * params.tiles.y, 1.0);
    let clip = clip_shell(p, l, hi, params.t_min, min(dist, params.t_max));
    var vis = 1.0;
    // Within `band` of the start the stored distance says nothing (the map
    // underestimates by up to that much): the ratio would read every lit
    // point as fully in penumbra. The hard trace above has cleared it.
    var t = max(clip.t_in, params.band);
    for (var i = 0u; i < max(params.iterations, 1u) && t < clip.t_out; i++) {
        let s = distance_at(p + l * t);
        vis = min(vis, clamp(frame.penumbra_k * s / t, 0.0, 1.0));
        t += max(s, params.tau);
    }
    return vis;
}

struct FsOut {
    @location(0) color: vec4f,
    @location(1) uv: vec4f,
    @builtin(frag_depth) depth: f32,
}

// Colour of hit h of the map-space ray start + t dir. to_light_start runs
// from start to the light in the physical tangent frame (world lengths along
// the unit tangent, bitangent and normal); to_phys scales map units to that
// frame per axis. Map space is the tangent frame scaled by the baked
// proportions across and by the live depth along the normal; the two agree
// only at the baked depth, and the live factor of listing 8-1 stretches the
// normal axis alone, so lighting is done in the physical frame. dx, dy are
// the derivatives of the undisplaced texture coordinate.
fn shade_hit(h: TraceHit, start: vec3f, dir: vec3f, to_light_start: vec3f, to_phys: vec3f, dx: vec2f, dy: vec2f) -> vec3f {
    let p = start + dir * h.t;
    let uv = p.xy / params.aspect;
    // The light vector at the hit: the vertex's, moved from the shell point
    // to the hit (an orthogonal frame).
    let to_light = to_light_start - (p - start) * to_phys;
    let l = normalize(to_light);
    // The shadow march runs in map space; its direction and length map back.
    let l_map = normalize(to_light / to_phys);
    var n_map = h.normal;
    if (h.kind == HIT_SURFACE) {
        n_map = normalize(textureSampleGrad(normal_tex, shade_sampler, uv, dx, dy).xyz * 2.0 - 1.0);
    }
    // The normal map holds the baked proportions (the ray-tracer paper, section 2.2: normals
    // change with depth); normals map by the inverse transpose of to_phys.
    let n = normalize(n_map / to_phys);
    let albedo = textureSampleGrad(color_tex, shade_sampler, uv, dx, dy).rgb;
    var lit = max(dot(n, l), 0.0) * shadow(p + n_map * params.tau, l_map, length(to_light / to_phys));
    if (frame.falloff == 1u) {
        let r = length(to_light);
        lit = lit / max(r * r, 1e-20);
    }
    let half_vec = normalize(l - normalize(dir * to_phys));
    return blinn_phong(albedo, n, half_vec, lit, frame.ambient, frame.light_intensity, frame.specular, frame.shininess);
}

// What both fragment stages (raster.wgsl, mesh.wgsl) begin with, from the
// map-space shell point map_pos and the interpolated eye vector tan_eye:
// the derivatives of the undisplaced texture coordinate, taken before any
// branch (section 8.5.3: the displaced ones jump at occlusions); listing
// 8-2's normalisation, unit length in the map's metric (the texture-space
// offset times (depth/width, depth/height, 1)); and the ray's hit. A ray
// that hits nothing leaves the shell through its sides or bottom (a true
// silhouette, or out of the map window): its fragment is discarded.
struct ShellMarch {
    dir: vec3f,
    hit: TraceHit,
    dx: vec2f,
    dy: vec2f,
}

fn march_shell(map_pos: vec3f, tan_eye: vec3f) -> ShellMarch {
    let base_uv = map_pos.xy / params.aspect;
    var m: ShellMarch;
    m.dx = dpdx(base_uv);
    m.dy = dpdy(base_uv);
    m.dir = normalize(tan_eye);
    m.hit = trace_map(map_pos, m.dir);
    if (m.hit.kind == HIT_NONE) {
        discard;
    }
    return m;
}

// What both fragment stages write for hit h: the shaded colour rgb, the uv
// AOV (texture coordinate uv, hit kind, t) and the exact depth of the hit
// at world position world, so it meets other draws in one depth buffer.
fn shell_out(rgb: vec3f, uv: vec2f, h: TraceHit, world: vec3f) -> FsOut {
    var out: FsOut;
    out.color = vec4f(rgb, 1.0);
    out.uv = vec4f(uv, f32(h.kind), h.t);
    let clip = frame.view_proj * vec4f(world, 1.0);
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}
