#import displace::convention::HIT_PLAIN
#import displace::lighting::blinn_phong

// Non-displaced scene shapes (walls, boxes, spheres, plain meshes, visible
// area-light quads) drawn as ordinary triangles into the targets the
// displaced faces use (raster.rs): the same view_proj, so the rasterised
// depth of a wall and the exact depth a displaced fragment writes (listing
// 8-2's hit, projected) compare in one depth buffer, both ways round.
// Lit by the displaced faces' single point light with the terms of
// shade_hit (shade.wgsl) without its map-space parts: Lambert plus
// normalised Blinn-Phong, 1 / r^2 falloff, no shadows. Surfaces are
// two-sided as the CPU renderer's (its integrator turns normals to the
// viewer); an emitter glows only on its front, as the CPU's area light.

struct PlainFrame {
    view_proj: mat4x4f,
    eye: vec4f,
    light: vec4f,
    ambient: f32,
    light_intensity: f32,
    // 1: 1 / r^2 falloff (a point light of radiant intensity light_intensity).
    falloff: u32,
    _pad: f32,
}

@group(0) @binding(0) var<uniform> plain: PlainFrame;

// World-space corner with its material: diffuse already holds the CPU's
// diffuse / pi (times the light's colour), specular the Blinn-Phong weight.
struct PlainVertex {
    @location(0) position: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
    @location(3) diffuse: vec3f,
    @location(4) specular: f32,
    @location(5) emission: vec3f,
    @location(6) shininess: f32,
}

struct PlainVsOut {
    @builtin(position) clip: vec4f,
    @location(0) world: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
    @location(3) diffuse: vec3f,
    @location(4) specular: f32,
    @location(5) emission: vec3f,
    @location(6) shininess: f32,
}

struct PlainOut {
    @location(0) color: vec4f,
    @location(1) uv: vec4f,
}

@vertex
fn vs_plain(v: PlainVertex) -> PlainVsOut {
    var out: PlainVsOut;
    out.clip = plain.view_proj * vec4f(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.uv = v.uv;
    out.diffuse = v.diffuse;
    out.specular = v.specular;
    out.emission = v.emission;
    out.shininess = v.shininess;
    return out;
}

@fragment
fn fs_plain(in: PlainVsOut) -> PlainOut {
    let to_eye = plain.eye.xyz - in.world;
    let v = normalize(to_eye);
    let front = dot(in.normal, to_eye) > 0.0;
    let n = select(-1.0, 1.0, front) * normalize(in.normal);
    let to_light = plain.light.xyz - in.world;
    let l = normalize(to_light);
    var lit = max(dot(n, l), 0.0);
    if (plain.falloff == 1u) {
        lit = lit / max(dot(to_light, to_light), 1e-20);
    }
    let half_vec = normalize(l + v);
    var rgb = blinn_phong(in.diffuse, n, half_vec, lit, plain.ambient, plain.light_intensity, in.specular, in.shininess);
    if (front) {
        rgb += in.emission;
    }
    var out: PlainOut;
    out.color = vec4f(rgb, 1.0);
    out.uv = vec4f(in.uv, f32(HIT_PLAIN), length(to_eye));
    return out;
}
