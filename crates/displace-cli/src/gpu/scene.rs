//! `displace gpu-render SCENE`: the CPU renderer's scene file drawn by the
//! GPU raster path ("the same scene TOML as the CPU renderer, with
//! the same camera conventions, so one scene renders on both and can be
//! compared").
//!
//! The scene is loaded and validated by `displace_render` itself, so every
//! error (file:line:column, unknown keys, missing height files) is the CPU
//! renderer's, and every displaced face gets the bake the CPU renderer would
//! use (the same in-memory sharing and on-disk cache). What the GPU draws of
//! it: each displaced parallelogram (tiled or not), as its own shell box with
//! Donnelly's shaders, and each displaced triangle and mesh (OBJ or
//! built-in) as the shells of its triangles in their MikkTSpace frames
//! (`displace_gpu::mesh`, which says where that differs from the CPU's
//! prisms), lit by one point light (the first point light, else the centre
//! of the first area light) with the CPU's point-light falloff and Lambert /
//! normalised Blinn-Phong terms. Every other shape (quads, boxes, spheres,
//! triangles and meshes without displacement, visible area-light quads with
//! their radiance) is drawn as plain triangles (`displace_gpu::plain`) in
//! the same depth buffer, lit by the same light and terms without shadows.
//! Everything else is left out and reported: textures, reflections, other
//! lights, shadows cast by one face onto another (each face shadows only
//! itself) and shadows on the plain shapes.

use anyhow::{bail, Context, Result};
use displace_core::Method;
use displace_gpu::raster::{render_faces, shared_depth_range};
use displace_gpu::{
    DistanceTexture, GpuContext, Image, MeshTriangle, PlainMaterial, PlainMesh, PlaneScene,
    Renderer, Shadows, ShellMesh,
};
use displace_render::light::Light;
use displace_render::material::Material;
use displace_render::scene::{SceneMesh, Shape};
use displace_render::{Scene, SceneOptions};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::path::Path;

/// A rendered scene and what of it was not drawn.
pub struct SceneImage {
    pub image: Image,
    /// Displaced faces and meshes drawn.
    pub faces: usize,
    pub plain_triangles: usize,
    pub left_out: Vec<String>,
}

/// Loads `path` exactly as `displace render` does.
pub fn load(path: &Path, size: Option<[u32; 2]>, no_cache: bool) -> Result<Scene> {
    let opts = SceneOptions {
        size,
        cache_dir: if no_cache {
            None
        } else {
            displace_render::default_cache_dir()
        },
        ..SceneOptions::default()
    };
    Ok(Scene::load(path, &opts)?)
}

/// The light the GPU path uses: position and radiant intensity (RGB) of
/// the scene's strongest light. An area light becomes a point at its centre
/// with its on-axis intensity `L A` (radiance times area), so an area-lit
/// scene with a dim point fill (the seed scenes' Cornell boxes) is lit by
/// its area light, not by the fill.
fn pick_light(scene: &Scene) -> Option<(Vec3, Vec3)> {
    scene
        .lights()
        .iter()
        .map(|l| match l {
            Light::Point {
                position,
                intensity,
            } => (*position, *intensity),
            Light::Area { quad, radiance } => (
                quad.origin + 0.5 * (quad.edge_u + quad.edge_v),
                *radiance * quad.edge_u.cross(quad.edge_v).length(),
            ),
        })
        .fold(None, |best: Option<(Vec3, Vec3)>, l| match best {
            Some(b) if b.1.element_sum() >= l.1.element_sum() => Some(b),
            _ => Some(l),
        })
}

/// The camera and light every draw shares.
struct View {
    size: [u32; 2],
    eye: Vec3,
    forward: Vec3,
    up: Vec3,
    fov_y_degrees: f32,
    light: Vec3,
    shadows: Shadows,
}

impl View {
    /// A [`PlaneScene`] with this view and `shading`; its face is a unit
    /// square at the origin until the caller places it (a mesh renderer
    /// takes its faces from the mesh).
    fn with(&self, shading: &Shading) -> PlaneScene {
        PlaneScene {
            size: self.size,
            eye: self.eye,
            target: self.eye + self.forward,
            up: self.up,
            fov_y_degrees: self.fov_y_degrees,
            light: self.light,
            light_intensity: shading.strength,
            origin: Vec3::ZERO,
            tangent: Vec3::X,
            bitangent: Vec3::Y,
            depth: 1.0,
            method: Method::Sphere,
            iterations: 64,
            shadows: self.shadows,
            penumbra_k: 8.0,
            ambient: 0.0,
            specular: shading.specular,
            shininess: shading.shininess,
            falloff: true,
            depth_range: None,
            tiles: [1.0, 1.0],
            mirrored: false,
            bounds: None,
        }
    }
}

/// A material as the GPU shades it under a light of radiant intensity
/// `intensity`.
struct Shading {
    albedo: Vec3,
    strength: f32,
    specular: f32,
    shininess: f32,
    textured: bool,
    reflects: bool,
}

impl Shading {
    /// Reports what of the material is left out.
    fn note(&self, skip: &mut impl FnMut(&str)) {
        if self.textured {
            skip("material textures");
        }
        if self.reflects {
            skip("reflections");
        }
    }
}

fn material_shading(mat: &Material, intensity: Vec3) -> Shading {
    // The CPU's direct term is `diffuse / pi * I / r^2 * cos`: the GPU's
    // is `albedo * light_intensity * cos / r^2`, its albedo a [0, 1]
    // texture, so the largest channel of `diffuse I / pi` becomes the
    // light's strength and the rest the albedo.
    let rgb = mat.diffuse * intensity / PI;
    let strength = rgb.max_element();
    let strength = if strength > 0.0 { strength } else { 1.0 };
    // Normalised Blinn-Phong (displace_render::material::brdf) with the
    // mean of its specular colour and the light's (the GPU highlight is
    // white).
    let mean = |v: Vec3| (v.x + v.y + v.z) / 3.0;
    let specular = if mat.shininess > 0.0 && mat.specular != Vec3::ZERO {
        mean(mat.specular) * (mat.shininess + 8.0) / (8.0 * PI) * mean(intensity) / strength
    } else {
        0.0
    };
    Shading {
        albedo: rgb / strength,
        strength,
        specular,
        shininess: mat.shininess.max(1.0),
        textured: mat.texture.is_some(),
        reflects: mat.reflects(),
    }
}

/// The plain-draw material of `mat` under a light of radiant intensity
/// `intensity`: the weights [`material_shading`] splits between albedo and
/// light strength, multiplied back together (a vertex attribute need not be
/// an 8-bit texel), and `emission` for a visible area-light quad.
fn plain_material(
    mat: &Material,
    intensity: Vec3,
    emission: Vec3,
    skip: &mut impl FnMut(&str),
) -> PlainMaterial {
    let shading = material_shading(mat, intensity);
    shading.note(skip);
    PlainMaterial {
        diffuse: shading.albedo * shading.strength,
        specular: shading.specular * shading.strength,
        shininess: shading.shininess,
        emission,
    }
}

/// Appends a non-displaced primitive's triangles: a quad (a box is six)
/// as two, a sphere tessellated, a lone triangle flat with its
/// barycentric coordinates as uv (the CPU's parameters).
fn add_plain(plain: &mut PlainMesh, shape: &Shape, m: &PlainMaterial) {
    match shape {
        Shape::Quad(q) => plain.quad(q.origin, q.edge_u, q.edge_v, m),
        Shape::Sphere(s) => plain.sphere(s.center, s.radius, m),
        Shape::Triangle { tri, .. } => {
            let p = [tri.p0, tri.p0 + tri.e1, tri.p0 + tri.e2];
            let n = flat_normal(p);
            let uv = [Vec2::ZERO, Vec2::X, Vec2::Y];
            plain.triangle(std::array::from_fn(|c| (p[c], n, uv[c])), m);
        }
        // Drawn by its own renderer, not here.
        Shape::Displaced(_) => {}
    }
}

/// Unit normal of the triangle `p` by its winding; zero for a degenerate
/// one (which covers no pixel; a shell refuses it).
fn flat_normal(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
}

/// A triangle's vertex normals as a rasteriser needs them: the scene's
/// (unit, turned with the mesh), the flat normal where it gives none or a
/// zero one.
fn vertex_normals(t: &displace_render::mesh::MeshTriangle) -> [Vec3; 3] {
    let flat = flat_normal(t.positions);
    t.normals.map_or([flat; 3], |n| {
        n.map(|v| if v == Vec3::ZERO { flat } else { v })
    })
}

/// The GPU shell of a scene mesh, its texture addressed as its bake is.
fn shell_of(mesh: &SceneMesh, address: displace_core::Address) -> Result<ShellMesh> {
    let tris: Vec<MeshTriangle> = mesh
        .triangles
        .iter()
        .map(|t| MeshTriangle {
            positions: t.positions,
            normals: vertex_normals(t),
            uvs: t.uvs,
        })
        .collect();
    Ok(ShellMesh::new(&tris, address)?)
}

/// The drawable faces and meshes of a scene, each with its renderer and its
/// [`PlaneScene`] (sharing one camera and depth range), and what was left out.
/// `gpu-render` draws them once; `view` every frame.
pub struct SceneFaces {
    /// The displaced draws, then one draw of every plain triangle.
    pub faces: Vec<(Renderer, PlaneScene)>,
    pub plain_triangles: usize,
    pub left_out: Vec<String>,
    /// Linear background colour.
    pub background: [f64; 3],
}

/// Uploads every displaced face and mesh of `scene` that the GPU path draws.
pub fn prepare(
    ctx: &GpuContext,
    scene: &Scene,
    texture: DistanceTexture,
    shadows: Shadows,
) -> Result<SceneFaces> {
    let camera = scene.camera();
    let (forward, _, up, tan_half) = camera.basis();
    let eye = camera.position();
    let mut left_out = Vec::new();
    if camera.lens_radius() > 0.0 {
        left_out.push("depth of field (drawn as a pinhole)".to_string());
    }
    let Some((light, intensity)) = pick_light(scene) else {
        bail!("the scene has no light; gpu-render lights with its strongest point or area light");
    };
    if scene.lights().len() > 1 {
        left_out.push(format!(
            "{} lights besides the strongest",
            scene.lights().len() - 1
        ));
    }
    let view = View {
        size: [scene.width(), scene.height()],
        eye,
        forward,
        up,
        fov_y_degrees: 2.0 * tan_half.atan().to_degrees(),
        light,
        shadows,
    };
    let mut faces = Vec::new();
    let mut plain = PlainMesh::default();
    let mut skip = |what: &str| left_out.push(what.to_string());
    // Triangles and meshes are drawn as meshes, not per primitive.
    let meshed: std::collections::HashSet<usize> = scene
        .meshes()
        .iter()
        .flat_map(|m| m.prims.clone())
        .collect();
    for (k, prim) in scene.primitives().iter().enumerate() {
        if meshed.contains(&k) {
            continue;
        }
        let material = &scene.materials()[prim.material as usize];
        let face = match &prim.shape {
            Shape::Displaced(d) => d,
            other => {
                let emission =
                    prim.emitter
                        .map_or(Vec3::ZERO, |e| match &scene.lights()[e as usize] {
                            Light::Area { radiance, .. } => *radiance,
                            Light::Point { .. } => Vec3::ZERO,
                        });
                let m = plain_material(material, intensity, emission, &mut skip);
                add_plain(&mut plain, other, &m);
                continue;
            }
        };
        let trace = face.trace_options();
        if trace.method == Method::Exact {
            bail!(
                "primitive {k}: method exact is the CPU reference; the GPU traces with sphere or sphere-fixed"
            );
        }
        crate::gpu::check_gpu_iterations(trace.iterations)
            .with_context(|| format!("primitive {k}: displacement.iterations"))?;
        if face.color.is_some() || face.normal_map.is_some() {
            skip("displacement colour textures and normal maps");
        }
        let (origin, m) = face.frame();
        let map = face.map();
        let [ax, ay] = map.aspect();
        let (tangent, bitangent, up_n) = (m.col(0) * ax, m.col(1) * ay, m.col(2));
        // A `flip_v` quad runs `v` back along its edge: a left-handed frame.
        let mirrored = tangent.cross(bitangent).dot(up_n) < 0.0;
        let shading = material_shading(&scene.materials()[prim.material as usize], intensity);
        shading.note(&mut skip);
        let plane = PlaneScene {
            origin,
            tangent,
            bitangent,
            depth: up_n.length(),
            method: trace.method,
            iterations: trace.iterations,
            tiles: trace.tiles,
            mirrored,
            ..view.with(&shading)
        };
        let renderer =
            Renderer::with_albedo(ctx, map, texture, shading.albedo.to_array(), mirrored)
                .with_context(|| format!("uploading displaced face {k}"))?;
        faces.push((renderer, plane));
    }
    for (k, mesh) in scene.meshes().iter().enumerate() {
        let Some(disp) = &mesh.displacement else {
            let material = &scene.materials()[mesh.material as usize];
            let m = plain_material(material, intensity, Vec3::ZERO, &mut skip);
            for t in &mesh.triangles {
                let n = vertex_normals(t);
                plain.triangle(
                    std::array::from_fn(|c| (t.positions[c], n[c], t.uvs[c])),
                    &m,
                );
            }
            continue;
        };
        if disp.trace.method == Method::Exact {
            bail!(
                "mesh {k}: method exact is the CPU reference; the GPU traces with sphere or sphere-fixed"
            );
        }
        crate::gpu::check_gpu_iterations(disp.trace.iterations)
            .with_context(|| format!("mesh {k}: displacement.iterations"))?;
        if disp.textured {
            skip("displacement colour textures and normal maps");
        }
        let shading = material_shading(&scene.materials()[mesh.material as usize], intensity);
        shading.note(&mut skip);
        let shell = shell_of(mesh, disp.map.address())
            .with_context(|| format!("preparing the shell of mesh {k}"))?;
        let bounds = mesh
            .triangles
            .iter()
            .flat_map(|t| t.positions)
            .fold([Vec3::INFINITY, Vec3::NEG_INFINITY], |[lo, hi], p| {
                [lo.min(p), hi.max(p)]
            });
        let plane = PlaneScene {
            depth: disp.depth,
            method: disp.trace.method,
            iterations: disp.trace.iterations,
            bounds: Some(bounds),
            ..view.with(&shading)
        };
        let renderer =
            Renderer::for_mesh(ctx, &disp.map, texture, shading.albedo.to_array(), &shell)
                .with_context(|| format!("uploading displaced mesh {k}"))?;
        faces.push((renderer, plane));
    }
    if let Some(bounds) = plain.bounds() {
        left_out.push("shadows on non-displaced shapes".to_string());
        let renderer =
            Renderer::plain(ctx, &plain).context("uploading the non-displaced shapes")?;
        // Lit with the vertices' own diffuse and specular weights; no shell.
        let unit = Shading {
            albedo: Vec3::ONE,
            strength: 1.0,
            specular: 0.0,
            shininess: 1.0,
            textured: false,
            reflects: false,
        };
        let plane = PlaneScene {
            depth: 0.0,
            bounds: Some(bounds),
            ..view.with(&unit)
        };
        faces.push((renderer, plane));
    }
    left_out.sort();
    left_out.dedup();
    if faces.is_empty() {
        bail!("the scene has nothing gpu-render can draw (left out: {left_out:?})");
    }
    // One depth range for all faces, so their exact fragment depths compare.
    let planes: Vec<PlaneScene> = faces.iter().map(|(_, p)| *p).collect();
    let Some(range) = shared_depth_range(&planes) else {
        bail!("every displaced face is behind the camera");
    };
    for (_, p) in &mut faces {
        p.depth_range = Some(range);
    }
    let bg = scene.background();
    Ok(SceneFaces {
        faces,
        plain_triangles: plain.vertices.len() / 3,
        left_out,
        background: [bg.x as f64, bg.y as f64, bg.z as f64],
    })
}

pub fn render(
    ctx: &GpuContext,
    scene: &Scene,
    texture: DistanceTexture,
    shadows: Shadows,
) -> Result<SceneImage> {
    let prepared = prepare(ctx, scene, texture, shadows)?;
    let draws: Vec<(&Renderer, &PlaneScene)> = prepared.faces.iter().map(|(r, p)| (r, p)).collect();
    let image =
        render_faces(ctx, &draws, prepared.background).context("rendering the scene on the GPU")?;
    Ok(SceneImage {
        image,
        faces: draws.len() - usize::from(prepared.plain_triangles > 0),
        plain_triangles: prepared.plain_triangles,
        left_out: prepared.left_out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn lights(toml: &str) -> Option<(Vec3, Vec3)> {
        let text = format!(
            "[image]\nwidth = 8\nheight = 8\n\n[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\n\
             [materials.m]\ntype = \"lambert\"\ncolor = [0.5, 0.5, 0.5]\n\n\
             [[shapes]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"m\"\n\n{toml}"
        );
        let scene = Scene::from_toml(
            &text,
            Path::new("t.toml"),
            Path::new("."),
            &SceneOptions::default(),
        )
        .expect("scene");
        pick_light(&scene)
    }

    /// The strongest light wins, an area light counting as `L A` at its
    /// centre: the seed scenes' area light beats their dim point fill, and a
    /// bright point beats a small area light, whatever their order.
    #[test]
    fn the_strongest_light_is_the_one_drawn() {
        let area = "[[lights]]\ntype = \"area\"\norigin = [0, 4, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 0, 1]\nradiance = [10, 10, 10]\n";
        let dim = "[[lights]]\ntype = \"point\"\nposition = [1, 2, 3]\nintensity = [5, 5, 5]\n";
        let bright =
            "[[lights]]\ntype = \"point\"\nposition = [1, 2, 3]\nintensity = [50, 50, 50]\n";
        let area_wins = (Vec3::new(1.0, 4.0, 0.5), Vec3::splat(20.0));
        let bright_wins = (Vec3::new(1.0, 2.0, 3.0), Vec3::splat(50.0));
        for (point, want) in [(dim, area_wins), (bright, bright_wins)] {
            for toml in [format!("{area}{point}"), format!("{point}{area}")] {
                assert_eq!(lights(&toml), Some(want), "{toml}");
            }
        }
        assert_eq!(lights(""), None);
    }
}
