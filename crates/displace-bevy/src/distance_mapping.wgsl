// Distance mapping (Donnelly, GPU Gems 2 ch. 8) as the fragment stage of a
// StandardMaterial extension, in Bevy's main pass, prepass and shadow
// passes. The mesh's own triangles are the top of the shell (section 8.3:
// the polygon is the top of the displaced volume, the surface lies up to
// `depth` beneath it); the fragment turns its view ray into map space
// (listing 8-1), marches the distance map from its point on the shell and
// refines the hit exactly (listing 8-2 and the shared trace of
// displace::surface), then
// - discards rays that leave the shell through its sides or bottom (a true
//   silhouette at the face's edges),
// - writes the depth of the displaced point, so the depth prepass, SSAO,
//   fog, depth of field, transparency sorting and shadow maps all see the
//   visible surface,
// - samples StandardMaterial's maps at the displaced texture coordinate with
//   the derivatives of the undisplaced one (section 8.5.3) and lights the
//   displaced point with Bevy's PBR lighting (every light, its shadows).

#import displace::convention::{HIT_NONE, BIG}
#import displace::bindings::params
#import displace::surface::trace_map
#import bevy_pbr::mesh_view_bindings::view
#import bevy_pbr::pbr_bindings

#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::VertexOutput
#import displace::displaced_outputs::{PrepassOutput, prepass_output}
#else
#import bevy_pbr::forward_io::VertexOutput
#import displace::displaced_outputs::MainOutput
#import bevy_pbr::pbr_fragment::pbr_input_from_standard_material
#import bevy_pbr::pbr_functions::{alpha_discard, apply_pbr_lighting, main_pass_post_lighting_processing}
#import bevy_pbr::pbr_types
#endif

// Rust: `DistanceMappingSettings` (lib.rs).
struct DistanceMappingSettings {
    // World-space depth of the shell: listing 8-1's 1 / inverse bump depth,
    // live (the map is baked in shell depths).
    depth: f32,
    // OUTPUT_SHADED, OUTPUT_HIT (the hit as data for tests) or
    // OUTPUT_NORMAL.
    output: u32,
    pad_a: u32,
    pad_b: u32,
}

const OUTPUT_SHADED: u32 = 0u;
// Colour = (displaced u, displaced v, map-space t, 1), unlit.
const OUTPUT_HIT: u32 = 1u;
// Colour = (world normal of the displaced surface * 0.5 + 0.5, 1), unlit.
const OUTPUT_NORMAL: u32 = 2u;

@group(#{MATERIAL_BIND_GROUP}) @binding(104) var<uniform> settings: DistanceMappingSettings;

// The shell's frame at a fragment, from screen-space derivatives of the
// interpolated world position and texture coordinate: exact on each planar
// triangle, needs no vertex tangents, and is the same in every pass (the
// depth prepass and shadow passes have no normals or tangents).
struct Shell {
    ok: bool,
    // dP/du, dP/dv: world length of one tile along u and v.
    t: vec3f,
    b: vec3f,
    // Their dual vectors in the plane (t_dual . t = 1, t_dual . b = 0).
    t_dual: vec3f,
    b_dual: vec3f,
    // Unit normal on the viewer's side of the triangle.
    n: vec3f,
    ddx: vec2f,
    ddy: vec2f,
}

// Must run in uniform control flow (derivatives).
fn shell_frame(world: vec3f, uv: vec2f, dir: vec3f) -> Shell {
    let dpx = dpdx(world);
    let dpy = dpdy(world);
    let dux = dpdx(uv);
    let duy = dpdy(uv);
    var s: Shell;
    s.ddx = dux;
    s.ddy = duy;
    let det = dux.x * duy.y - duy.x * dux.y;
    if (abs(det) < 1e-20) {
        s.ok = false;
        return s;
    }
    // [t b] [dux duy] = [dpx dpy]
    s.t = (dpx * duy.y - dpy * dux.y) / det;
    s.b = (dpy * dux.x - dpx * duy.x) / det;
    let g00 = dot(s.t, s.t);
    let g01 = dot(s.t, s.b);
    let g11 = dot(s.b, s.b);
    let gdet = g00 * g11 - g01 * g01;
    if (abs(gdet) < 1e-30) {
        s.ok = false;
        return s;
    }
    s.t_dual = (g11 * s.t - g01 * s.b) / gdet;
    s.b_dual = (g00 * s.b - g01 * s.t) / gdet;
    var n = normalize(cross(s.t, s.b));
    if (dot(n, dir) > 0.0) {
        n = -n;
    }
    s.n = n;
    s.ok = true;
    return s;
}

// World direction of the ray through this fragment: from the view's origin,
// or along its axis for an orthographic view (a directional light's shadow
// map), as pbr_functions::calculate_view.
fn view_ray(world: vec3f) -> vec3f {
    if (view.clip_from_view[3].w == 1.0) {
        return -normalize(vec3f(view.clip_from_world[0].z, view.clip_from_world[1].z, view.clip_from_world[2].z));
    }
    return normalize(world - view.world_position.xyz);
}

struct Displaced {
    found: bool,
    // StandardMaterial's coordinate at the hit (uv_transform applied), and
    // the mesh's own.
    uv: vec2f,
    mesh_uv: vec2f,
    world: vec3f,
    // World normal of the displaced surface.
    normal: vec3f,
    depth: f32,
    t: f32,
    shell: Shell,
}

// Section 8.5: the ray in map space from the fragment's point on the shell
// top (z = 1), traced by displace::surface::trace_map. `mesh_uv` is the
// mesh's coordinate; StandardMaterial's `uv_transform` applies to the map as
// to its own textures (tiling a repeating map over a mesh).
fn displace_fragment(world: vec3f, mesh_uv: vec2f) -> Displaced {
    let uv = (pbr_bindings::material.uv_transform * vec3f(mesh_uv, 1.0)).xy;
    let dir_w = view_ray(world);
    let shell = shell_frame(world, uv, dir_w);
    var out: Displaced;
    out.shell = shell;
    out.found = false;
    if (!shell.ok) {
        return out;
    }
    let depth = max(settings.depth, 1e-6);
    // Repeating maps start in the tile that holds the point (the map
    // addresses by wrapping, and the shell has no sides across); clamped
    // ones span the mesh's [0, 1] texture square.
    var uv_map = uv;
    if (params.tiles.x >= BIG * 0.5) {
        uv_map = uv - floor(uv);
    }
    let origin = vec3f(uv_map * params.aspect, 1.0);
    // Listing 8-1: texture-space components in the map's metric, the
    // normal one divided by the depth; listing 8-2 normalises.
    let dir = normalize(vec3f(
        dot(shell.t_dual, dir_w) * params.aspect.x,
        dot(shell.b_dual, dir_w) * params.aspect.y,
        dot(shell.n, dir_w) / depth,
    ));
    let h = trace_map(origin, dir);
    if (h.kind == HIT_NONE) {
        return out;
    }
    let delta = dir * h.t;
    let duv = delta.xy / params.aspect;
    out.found = true;
    out.t = h.t;
    out.uv = uv + duv;
    let m = pbr_bindings::material.uv_transform;
    let lin = mat2x2f(m[0].xy, m[1].xy);
    let ldet = determinant(lin);
    out.mesh_uv = mesh_uv;
    if (ldet != 0.0) {
        out.mesh_uv = mesh_uv + mat2x2f(vec2f(lin[1].y, -lin[0].y), vec2f(-lin[1].x, lin[0].x)) * duv / ldet;
    }
    out.world = world + duv.x * shell.t + duv.y * shell.b + delta.z * depth * shell.n;
    // Normals map by the inverse transpose of map -> world.
    let nm = h.normal;
    out.normal = normalize(nm.x * params.aspect.x * shell.t_dual + nm.y * params.aspect.y * shell.b_dual + nm.z / depth * shell.n);
    let clip = view.clip_from_world * vec4f(out.world, 1.0);
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}

#ifdef PREPASS_PIPELINE

// Depth prepass, normal prepass and every shadow map: the same march from
// this view, so depth and shadows hold the displaced shape.
@fragment
fn fragment(in: VertexOutput) -> PrepassOutput {
    let d = displace_fragment(in.world_position.xyz, in.uv);
    if (!d.found) {
        discard;
    }
    return prepass_output(in, d.world, d.normal, d.depth);
}

#else

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> MainOutput {
    let d = displace_fragment(in.world_position.xyz, in.uv);
    if (!d.found) {
        discard;
    }
    var out: MainOutput;
    out.frag_depth = d.depth;
    if (settings.output == OUTPUT_HIT) {
        out.color = vec4f(d.uv, d.t, 1.0);
        return out;
    }
    if (settings.output == OUTPUT_NORMAL) {
        out.color = vec4f(d.normal * 0.5 + vec3f(0.5), 1.0);
        return out;
    }

    // Bevy's PBR input at the displaced point: lights, shadow maps, fog and
    // the view vector all see the visible surface.
    var displaced = in;
    displaced.uv = d.mesh_uv;
    displaced.world_position = vec4f(d.world, 1.0);
    displaced.world_normal = d.normal;
    var pbr_input = pbr_input_from_standard_material(displaced, is_front);

    // Section 8.5.3: the maps at the displaced coordinate, with the
    // derivatives of the undisplaced one (the displaced coordinate jumps at
    // occlusion boundaries, where its own derivatives would pick the
    // coarsest mip).
    let m = pbr_bindings::material;
    let uv = d.uv;
    let ddx = d.shell.ddx;
    let ddy = d.shell.ddy;
    var base_color = m.base_color;
    if ((m.flags & pbr_types::STANDARD_MATERIAL_FLAGS_BASE_COLOR_TEXTURE_BIT) != 0u) {
        base_color *= textureSampleGrad(pbr_bindings::base_color_texture, pbr_bindings::base_color_sampler, uv, ddx, ddy);
    }
    pbr_input.material.base_color = alpha_discard(pbr_input.material, base_color);
    if ((m.flags & pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u) {
        var metallic = m.metallic;
        var roughness = m.perceptual_roughness;
        if ((m.flags & pbr_types::STANDARD_MATERIAL_FLAGS_METALLIC_ROUGHNESS_TEXTURE_BIT) != 0u) {
            let mr = textureSampleGrad(pbr_bindings::metallic_roughness_texture, pbr_bindings::metallic_roughness_sampler, uv, ddx, ddy);
            metallic *= mr.b;
            roughness *= mr.g;
        }
        pbr_input.material.metallic = metallic;
        pbr_input.material.perceptual_roughness = roughness;
        var emissive = m.emissive;
        if ((m.flags & pbr_types::STANDARD_MATERIAL_FLAGS_EMISSIVE_TEXTURE_BIT) != 0u) {
            emissive = vec4f(emissive.rgb * textureSampleGrad(pbr_bindings::emissive_texture, pbr_bindings::emissive_sampler, uv, ddx, ddy).rgb, emissive.a);
        }
        pbr_input.material.emissive = emissive;
        if ((m.flags & pbr_types::STANDARD_MATERIAL_FLAGS_OCCLUSION_TEXTURE_BIT) != 0u) {
            let ao = textureSampleGrad(pbr_bindings::occlusion_texture, pbr_bindings::occlusion_sampler, uv, ddx, ddy).r;
            pbr_input.diffuse_occlusion = min(pbr_input.diffuse_occlusion, vec3f(ao));
        }
        // The exact normal of the hit's bilinear patch; a normal map, if
        // the material has one, is the map-space normal map `displace bake`
        // writes (unit normals in the baked proportions, xyz * 0.5 + 0.5).
        var n = d.normal;
#ifdef STANDARD_MATERIAL_NORMAL_MAP
        let nm = textureSampleGrad(pbr_bindings::normal_map_texture, pbr_bindings::normal_map_sampler, uv, ddx, ddy).xyz * 2.0 - 1.0;
        let depth = max(settings.depth, 1e-6);
        n = normalize(nm.x * params.aspect.x * d.shell.t_dual + nm.y * params.aspect.y * d.shell.b_dual + nm.z / depth * d.shell.n);
#endif
        pbr_input.N = n;
        pbr_input.clearcoat_N = n;
        out.color = apply_pbr_lighting(pbr_input);
    } else {
        out.color = pbr_input.material.base_color;
    }
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}

#endif
