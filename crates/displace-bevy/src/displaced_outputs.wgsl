#define_import_path displace::displaced_outputs

// What both materials' fragment stages write for a displaced point (the
// flat distance_mapping.wgsl and the curved curved_mapping.wgsl): its
// depth in every pass, its normal and motion in the prepass, its colour
// in the main pass. The point is not the mesh's, so every output the mesh
// would give is replaced.

#import bevy_pbr::mesh_view_bindings::view

#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::VertexOutput
#ifdef MOTION_VECTOR_PREPASS
#import bevy_pbr::prepass_bindings::previous_view_uniforms
#endif

struct PrepassOutput {
#ifdef NORMAL_PREPASS
    @location(0) normal: vec4f,
#endif
#ifdef MOTION_VECTOR_PREPASS
    @location(1) motion_vector: vec2f,
#endif
    @builtin(frag_depth) frag_depth: f32,
}

// The prepass's (and the shadow passes') outputs of the displaced point
// `world` (its world `normal`, its `depth` in this view): the motion of
// the mesh's point carried to it.
fn prepass_output(in: VertexOutput, world: vec3f, normal: vec3f, depth: f32) -> PrepassOutput {
    var out: PrepassOutput;
#ifdef NORMAL_PREPASS
    out.normal = vec4f(normal * 0.5 + vec3f(0.5), 1.0);
#endif
#ifdef MOTION_VECTOR_PREPASS
    let clip_now = view.unjittered_clip_from_world * vec4f(world, 1.0);
    let previous_world = in.previous_world_position.xyz + (world - in.world_position.xyz);
    let clip_then = previous_view_uniforms.clip_from_world * vec4f(previous_world, 1.0);
    out.motion_vector = (clip_now.xy / clip_now.w - clip_then.xy / clip_then.w) * vec2f(0.5, -0.5);
#endif
    out.frag_depth = depth;
    return out;
}

#else

struct MainOutput {
    @location(0) color: vec4f,
    @builtin(frag_depth) frag_depth: f32,
}

#endif
