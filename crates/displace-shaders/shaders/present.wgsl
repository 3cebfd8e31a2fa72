// The viewer's present pass: the rendered frame copied texel for texel to
// the window's surface, then the text overlay drawn over it as a quad with
// premultiplied alpha blending.

struct Present {
    // Overlay rectangle in pixels: x, y, width, height.
    rect: vec4f,
    // Output size in pixels.
    out_size: vec2f,
    // 1 when the output format stores raw values (a non-sRGB surface): the
    // shader encodes sRGB itself.
    encode_srgb: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> present: Present;
@group(0) @binding(1) var frame_tex: texture_2d<f32>;
@group(0) @binding(2) var overlay_tex: texture_2d<f32>;

fn encode(c: vec3f) -> vec3f {
    if (present.encode_srgb == 0u) {
        return c;
    }
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3f(1.0 / 2.4)) - 0.055;
    return select(hi, lo, c <= vec3f(0.0031308));
}

@vertex
fn vs_frame(@builtin(vertex_index) i: u32) -> @builtin(position) vec4f {
    // One triangle that covers the viewport.
    let c = vec2f(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4f(c * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_frame(@builtin(position) pos: vec4f) -> @location(0) vec4f {
    let c = textureLoad(frame_tex, vec2i(pos.xy), 0);
    return vec4f(encode(c.rgb), 1.0);
}

@vertex
fn vs_overlay(@builtin(vertex_index) i: u32) -> @builtin(position) vec4f {
    // A triangle strip over the rectangle.
    let c = vec2f(f32(i & 1u), f32((i >> 1u) & 1u));
    let px = present.rect.xy + c * present.rect.zw;
    return vec4f(px.x / present.out_size.x * 2.0 - 1.0, 1.0 - px.y / present.out_size.y * 2.0, 0.0, 1.0);
}

@fragment
fn fs_overlay(@builtin(position) pos: vec4f) -> @location(0) vec4f {
    let c = textureLoad(overlay_tex, vec2i(pos.xy - present.rect.xy), 0);
    return vec4f(encode(c.rgb), c.a);
}
