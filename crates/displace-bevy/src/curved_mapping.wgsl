// Displacement over a curved mesh as the fragment stage of a
// StandardMaterial extension, in Bevy's main pass, prepass and shadow
// passes. The mesh drawn is the outer boundary of the triangles' shells
// (curved.rs `CurvedShellMesh`), each vertex carrying its prism in uv.x;
// the fragment turns its view ray into the mesh's own space (where the
// shells were built), walks the shells from that prism to the first hit
// (displace::curved_walk, the walk displace-gpu's curved.wgsl runs), then
// - discards rays that leave the shells without a hit (true silhouettes),
// - writes the depth of the displaced point (prepass, SSAO, shadow maps),
// - lights the displaced point with Bevy's PBR lighting, the material's
//   maps sampled at the hit's texture coordinate.

#import displace::bindings::params
#import displace::surface::surface_normal
#import displace::curved_walk::{walk, clamp_bary, jacobian, normal_to_world}
#import bevy_pbr::mesh_view_bindings::view
#import bevy_pbr::mesh_functions

#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::VertexOutput
#import displace::displaced_outputs::{PrepassOutput, prepass_output}
#else
#import bevy_pbr::forward_io::VertexOutput
#import displace::displaced_outputs::MainOutput
#import bevy_pbr::pbr_fragment::pbr_input_from_standard_material
#import bevy_pbr::pbr_functions::{apply_pbr_lighting, main_pass_post_lighting_processing}
#import bevy_pbr::pbr_types
#endif

// Rust: `CurvedMappingSettings` (curved.rs).
struct CurvedMappingSettings {
    // Map-window coordinate + uv_shift = the mesh's coordinate in tiles.
    uv_shift: vec2f,
    // How far behind the fragment an orthographic ray starts (mesh units).
    reach: f32,
    // OUTPUT_SHADED, OUTPUT_HIT or OUTPUT_NORMAL.
    output: u32,
}

const OUTPUT_SHADED: u32 = 0u;
// Colour = (u, v in tiles, world distance to the hit, 1), unlit.
const OUTPUT_HIT: u32 = 1u;
// Colour = (world normal * 0.5 + 0.5, 1), unlit.
const OUTPUT_NORMAL: u32 = 2u;

@group(#{MATERIAL_BIND_GROUP}) @binding(104) var<uniform> settings: CurvedMappingSettings;

// The inverse of an affine transform (Bevy's world_from_local: rotation,
// scale and shear in the 3x3, translation in the last column).
fn affine_inverse(m: mat4x4f) -> mat4x4f {
    let a = mat3x3f(m[0].xyz, m[1].xyz, m[2].xyz);
    let c0 = cross(a[1], a[2]);
    let c1 = cross(a[2], a[0]);
    let c2 = cross(a[0], a[1]);
    let inv_det = 1.0 / dot(a[0], c0);
    // Rows of the inverse are the cofactor columns over the determinant.
    let r = transpose(mat3x3f(c0, c1, c2)) * inv_det;
    let t = -(r * m[3].xyz);
    return mat4x4f(vec4f(r[0], 0.0), vec4f(r[1], 0.0), vec4f(r[2], 0.0), vec4f(t, 1.0));
}

// Whether the view is orthographic (a directional light's shadow map), as
// pbr_functions::calculate_view tells.
fn orthographic() -> bool {
    return view.clip_from_view[3].w == 1.0;
}

struct Curved {
    found: bool,
    // The hit in world space, its world normal and the mesh's texture
    // coordinate there (in tiles of the map).
    world: vec3f,
    normal: vec3f,
    uv: vec2f,
    // World distance from the ray's start to the hit.
    t: f32,
    depth: f32,
}

fn curved_fragment(world: vec3f, prism_coord: f32, instance: u32) -> Curved {
    var out: Curved;
    out.found = false;
    let world_from_local = mesh_functions::get_world_from_local(instance);
    let local_from_world = affine_inverse(world_from_local);
    let frag = (local_from_world * vec4f(world, 1.0)).xyz;
    var eye: vec3f;
    if (orthographic()) {
        let axis_w = -vec3f(view.clip_from_world[0].z, view.clip_from_world[1].z, view.clip_from_world[2].z);
        let axis = normalize((local_from_world * vec4f(axis_w, 0.0)).xyz);
        eye = frag - settings.reach * axis;
    } else {
        eye = (local_from_world * vec4f(view.world_position.xyz, 1.0)).xyz;
    }
    let to = frag - eye;
    let t_frag = length(to);
    if (!(t_frag > 0.0)) {
        return out;
    }
    let d = to / t_frag;
    // The rasterised sides are flat, the shells' bilinear: look for the
    // entry a little before the fragment (as displace-gpu does).
    let w = walk(u32(round(prism_coord)), eye, d, t_frag * (1.0 - 1e-3));
    if (!w.hit.found) {
        return out;
    }
    let hit = w.hit;
    let local = eye + hit.t * d;
    var n_local = hit.normal;
    if (!hit.wall) {
        let j = jacobian(w.shell, clamp_bary(hit.loc.b), hit.loc.w);
        n_local = normal_to_world(j, surface_normal(hit.c));
    }
    out.found = true;
    out.world = (world_from_local * vec4f(local, 1.0)).xyz;
    out.normal = normalize(mesh_functions::mesh_normal_local_to_world(n_local, instance));
    out.uv = hit.c.xy / params.aspect + settings.uv_shift;
    out.t = length(out.world - (world_from_local * vec4f(eye, 1.0)).xyz);
    let clip = view.clip_from_world * vec4f(out.world, 1.0);
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}

#ifdef PREPASS_PIPELINE

// Depth prepass, normal prepass and every shadow map: the same walk from
// this view, so depth and shadows hold the displaced shape.
@fragment
fn fragment(in: VertexOutput) -> PrepassOutput {
    let d = curved_fragment(in.world_position.xyz, in.uv.x, in.instance_index);
    if (!d.found) {
        discard;
    }
    return prepass_output(in, d.world, d.normal, d.depth);
}

#else

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> MainOutput {
    let d = curved_fragment(in.world_position.xyz, in.uv.x, in.instance_index);
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
    // Bevy's PBR input at the displaced point: StandardMaterial's maps at
    // the hit's texture coordinate (their derivatives those of the hit's,
    // which jump only where one bump hides another), lights, shadow maps
    // and fog at the visible surface, and the displaced surface's exact
    // normal (the base material's normal map, made for the undisplaced
    // mesh's tangents, is not applied).
    var displaced = in;
    displaced.uv = d.uv;
    displaced.world_position = vec4f(d.world, 1.0);
    displaced.world_normal = d.normal;
    var pbr_input = pbr_input_from_standard_material(displaced, true);
    if ((pbr_input.material.flags & pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u) {
        pbr_input.N = d.normal;
        pbr_input.clearcoat_N = d.normal;
        out.color = apply_pbr_lighting(pbr_input);
    } else {
        out.color = pbr_input.material.base_color;
    }
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}

#endif
