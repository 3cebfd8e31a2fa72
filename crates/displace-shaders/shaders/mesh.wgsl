#import displace::bindings::params
#import displace::shade::{FsOut, frame, march_shell, shade_hit, shell_out}

// The raster path for meshes (GPU Gems 2 ch. 8, section 8.4): each triangle
// is drawn as the top of its shell and each open boundary edge as a wall
// (mesh.rs). The vertex stage carries the eye and light vectors into the
// vertex's MikkTSpace frame (listing 8-1), scaled to the map's metric; the
// fragment stage marches from the fragment's shell point along the
// interpolated vector (listing 8-2), treating the surface under it as
// locally flat, and shades the hit (shade.wgsl).

struct ShellVertex {
    @location(0) position: vec3f,
    @location(1) lift: f32,
    @location(2) normal: vec3f,
    @location(3) tangent: vec4f,
    @location(4) uv: vec2f,
    @location(5) scale: vec2f,
}

struct MeshVsOut {
    @builtin(position) clip: vec4f,
    @location(0) map_pos: vec3f,
    @location(1) tan_eye: vec3f,
    @location(2) tan_light: vec3f,
    @location(3) world: vec3f,
    @location(4) normal: vec3f,
    @location(5) tangent: vec4f,
    @location(6) scale: vec2f,
}

// Tangent-space components of a world vector v in the map's metric: along
// the tangent and bitangent per tile, times the tile's map width, and along
// the normal per depth (listing 8-1 with the inverse bump depth).
fn to_map_metric(v: vec3f, t: vec3f, b: vec3f, n: vec3f, scale: vec2f) -> vec3f {
    return vec3f(
        dot(t, v) / scale.x * params.aspect.x,
        dot(b, v) / scale.y * params.aspect.y,
        dot(n, v) * frame.inv_bump_depth,
    );
}

@vertex
fn vs_mesh(v: ShellVertex) -> MeshVsOut {
    let depth = 1.0 / frame.inv_bump_depth;
    let n = normalize(v.normal);
    let t = normalize(v.tangent.xyz);
    let b = v.tangent.w * cross(n, t);
    let world = v.position + v.lift * depth * n;
    var out: MeshVsOut;
    out.clip = frame.view_proj * vec4f(world, 1.0);
    out.map_pos = vec3f(v.uv * params.aspect, v.lift);
    out.tan_eye = to_map_metric(world - frame.eye.xyz, t, b, n, v.scale);
    let light_vec = frame.light.xyz - world;
    out.tan_light = vec3f(dot(t, light_vec), dot(b, light_vec), dot(n, light_vec));
    out.world = world;
    out.normal = n;
    out.tangent = vec4f(t, v.tangent.w);
    out.scale = v.scale;
    return out;
}

@fragment
fn fs_mesh(in: MeshVsOut) -> FsOut {
    // Derivatives, listing 8-2's normalisation and the hit, or a discarded
    // fragment (shade.wgsl).
    let m = march_shell(in.map_pos, in.tan_eye);
    let depth = 1.0 / frame.inv_bump_depth;
    let to_phys = vec3f(in.scale / params.aspect, depth);
    let rgb = shade_hit(m.hit, in.map_pos, m.dir, in.tan_light, to_phys, m.dx, m.dy);
    let p = in.map_pos + m.dir * m.hit.t;
    // The hit back in the world through the fragment's frame.
    let n = normalize(in.normal);
    let t = normalize(in.tangent.xyz);
    let b = in.tangent.w * cross(n, t);
    let d = p - in.map_pos;
    let world = in.world + t * (d.x / params.aspect.x * in.scale.x)
        + b * (d.y / params.aspect.y * in.scale.y) + n * (d.z * depth);
    return shell_out(rgb, p.xy / params.aspect + frame.uv_shift, m.hit, world);
}
