// The raster path (GPU Gems 2 ch. 8, section 8.5): the shell box of one
// displaced face is drawn; the vertex stage moves the eye and light vectors
// into tangent space (listing 8-1), the fragment stage marches the distance
// map from the fragment's point on the shell (listing 8-2), refines to the
// exact hit, and shades with the normal map and the colour texture sampled
// with the derivatives of the undisplaced texture coordinates (8.5.3).
// Needs convention.wgsl, one distance_*.wgsl and surface.wgsl before it.

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
}

@group(1) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(1) var normal_tex: texture_2d<f32>;
@group(1) @binding(2) var color_tex: texture_2d<f32>;
@group(1) @binding(3) var shade_sampler: sampler;

struct VsOut {
    @builtin(position) clip: vec4f,
    // Map-space point on the shell: the ray's start (Donnelly's texCoord,
    // in depth units).
    @location(0) map_pos: vec3f,
    @location(1) tan_eye: vec3f,
    @location(2) tan_light: vec3f,
}

// Corner (u, v, w) of the shell box for each of the 36 vertices of its six
// faces, wound counter-clockwise seen from outside.
fn box_corner(index: u32) -> vec3f {
    var faces = array<vec4u, 6>(
        vec4u(4u, 5u, 7u, 6u), // top, w = 1
        vec4u(0u, 2u, 3u, 1u), // bottom, w = 0
        vec4u(0u, 1u, 5u, 4u), // v = 0
        vec4u(2u, 6u, 7u, 3u), // v = 1
        vec4u(0u, 4u, 6u, 2u), // u = 0
        vec4u(1u, 3u, 7u, 5u), // u = 1
    );
    var tri = array<u32, 6>(0u, 1u, 2u, 0u, 2u, 3u);
    let c = faces[index / 6u][tri[index % 6u]];
    return vec3f(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u));
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VsOut {
    // The box spans every tile of the face (params.tiles; 1 x 1 unless the
    // map repeats).
    let uvw = box_corner(index) * vec3f(params.tiles, 1.0);
    let depth = 1.0 / frame.inv_bump_depth;
    let t = frame.face_t.xyz;
    let b = frame.face_b.xyz;
    let n = frame.face_n.xyz;
    let obj = frame.face_origin.xyz + uvw.x * t + uvw.y * b + uvw.z * depth * n;
    var out: VsOut;
    out.clip = frame.view_proj * vec4f(obj, 1.0);
    out.map_pos = vec3f(uvw.x * params.aspect.x, uvw.y * params.aspect.y, uvw.z);
    // Listing 8-1, as the direction of travel (the listing's eyeVec points
    // back at the eye): texture-space components scaled to the map's metric,
    // the normal component by the inverse bump depth.
    let eye_vec = obj - frame.eye.xyz;
    out.tan_eye = vec3f(
        dot(t, eye_vec) / dot(t, t) * params.aspect.x,
        dot(b, eye_vec) / dot(b, b) * params.aspect.y,
        dot(n, eye_vec) * frame.inv_bump_depth,
    );
    let light_vec = frame.light.xyz - obj;
    out.tan_light = vec3f(dot(normalize(t), light_vec), dot(normalize(b), light_vec), dot(n, light_vec));
    return out;
}

// Light visibility from map-space point p towards direction l, dist away:
// a second trace towards the light; the soft variant also keeps the
// smallest distance-to-travel ratio seen (the distance field's penumbra).
fn shadow(p: vec3f, l: vec3f, dist: f32) -> f32 {
    if (frame.shadows == 0u) {
        return 1.0;
    }
    let occluder = trace_map(p, l);
    if (occluder.kind != HIT_NONE && occluder.t < dist) {
        return 0.0;
    }
    if (frame.shadows == 1u) {
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

@fragment
fn fs_main(in: VsOut) -> FsOut {
    // Derivatives of the undisplaced coordinates, taken before any branch
    // (section 8.5.3: the displaced ones jump at occlusions).
    let base_uv = in.map_pos.xy / params.aspect;
    let dx = dpdx(base_uv);
    let dy = dpdy(base_uv);
    // Listing 8-2's normalisation: unit length in the map's metric, which is
    // the texture-space offset times (depth/width, depth/height, 1).
    let dir = normalize(in.tan_eye);
    let h = trace_map(in.map_pos, dir);
    if (h.kind == HIT_NONE) {
        // The ray leaves the shell through its sides or bottom: a true
        // silhouette.
        discard;
    }
    let p = in.map_pos + dir * h.t;
    let uv = p.xy / params.aspect;
    let depth = 1.0 / frame.inv_bump_depth;
    // Map space is the face's tangent frame scaled per axis: by the baked
    // proportions across and by the live depth along the normal. They agree
    // only at the baked depth; the live factor of listing 8-1 stretches the
    // normal axis alone, so shading works in the physical tangent frame.
    let to_phys = vec3f(length(frame.face_t.xyz) / params.aspect.x, length(frame.face_b.xyz) / params.aspect.y, depth);
    // The light vector at the hit: the vertex's, moved from the shell point
    // to the hit (an orthogonal face frame).
    let to_light = in.tan_light - (p - in.map_pos) * to_phys;
    let l = normalize(to_light);
    // The shadow march runs in map space; its direction and length map back.
    let l_map = normalize(to_light / to_phys);
    var n_map = h.normal;
    if (h.kind == HIT_SURFACE) {
        n_map = normalize(textureSampleGrad(normal_tex, shade_sampler, uv, dx, dy).xyz * 2.0 - 1.0);
    }
    // The normal map holds the baked proportions (seed 002, 2.2: normals
    // change with depth); normals map by the inverse transpose of to_phys.
    let n = normalize(n_map / to_phys);
    let albedo = textureSampleGrad(color_tex, shade_sampler, uv, dx, dy).rgb;
    var lit = max(dot(n, l), 0.0) * shadow(p + n_map * params.tau, l_map, length(to_light / to_phys));
    if (frame.falloff == 1u) {
        let r = length(to_light);
        lit = lit / max(r * r, 1e-20);
    }
    let half_vec = normalize(l - normalize(dir * to_phys));
    let spec = select(0.0, pow(max(dot(n, half_vec), 0.0), frame.shininess), lit > 0.0) * frame.specular * lit;
    let rgb = albedo * (frame.ambient + frame.light_intensity * lit) + vec3f(spec * frame.light_intensity);
    var out: FsOut;
    out.color = vec4f(rgb, 1.0);
    out.uv = vec4f(uv, f32(h.kind), h.t);
    let world = frame.face_origin.xyz + uv.x * frame.face_t.xyz + uv.y * frame.face_b.xyz + p.z * depth * frame.face_n.xyz;
    let clip = frame.view_proj * vec4f(world, 1.0);
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}
