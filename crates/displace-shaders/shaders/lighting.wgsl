#define_import_path displace::lighting

// The lighting every raster entry point shares, the displaced hits of
// shade.wgsl and the plain triangles of plain.wgsl alike: Lambert plus
// normalised Blinn-Phong under the scene's single point light, so the two
// kinds of surface cannot drift apart in one frame.

// Colour of a surface of `albedo` with unit normal `n` and unit half vector
// `half_vec`: `lit` is the cosine term with falloff and shadowing already
// applied (no highlight where it is 0), `ambient` the ambient level,
// `intensity` the light's, `specular` and `shininess` the Blinn-Phong weight
// and exponent.
fn blinn_phong(albedo: vec3f, n: vec3f, half_vec: vec3f, lit: f32, ambient: f32, intensity: f32, specular: f32, shininess: f32) -> vec3f {
    let spec = select(0.0, pow(max(dot(n, half_vec), 0.0), shininess), lit > 0.0) * specular * lit;
    return albedo * (ambient + intensity * lit) + vec3f(spec * intensity);
}
