//! Validation and construction: from a parsed [`SceneSpec`] to a [`Scene`].
//! Every error names the scene file and the key at fault.

use super::spec::{DisplacementSpec, LightSpec, MaterialSpec, SceneSpec, ShapeSpec, V3};
use super::world::{MeshDisplacement, Primitive, SceneMesh, Shape, TriAttr};
use super::{Scene, SceneOptions};
use crate::bake_cache::BakeCache;
use crate::builtin_mesh;
use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::displaced::{DisplacedFace, FaceFrame};
use crate::emitters::Emitters;
use crate::environment::{Environment, EnvironmentMap};
use crate::error::{Error, Result};
use crate::geometry::Aabb;
use crate::light::Light;
use crate::material::Material;
use crate::mesh::MeshTriangle;
use crate::path::Sampling;
use crate::shapes::{box_faces, Quad, Sphere, Triangle};
use crate::texture::Texture;
use displace_core::convention::MAX_TRACE_ITERATIONS;
use displace_core::{Address, Extent, HeightMap, Method, TraceOptions};
use glam::{Mat3, Vec2, Vec3};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Image sizes above this many pixels are refused before allocating.
const MAX_PIXELS: u64 = 1 << 28;

/// Largest magnitude of a coordinate or vector component in a scene. Past
/// it a squared length overflows float32, and a camera at `-3e38` would be
/// reported as looking nowhere instead of as out of range.
pub const MAX_COORDINATE: f32 = 1e18;

/// Bytes per image pixel counted in a scene's memory estimate: the linear
/// film (12), its 8-bit output (3) and room for AOVs (16).
const IMAGE_BYTES_PER_PIXEL: u128 = 31;

/// Most reflection bounces (`image.max_depth`). Bounces are traced
/// recursively, one chain of stack frames per bounce on a worker thread's
/// stack: two facing mirrors at 5000 bounces overflow it, while 64 leaves a
/// wide margin and is far more than any visible contribution needs (each
/// bounce is weighted by the mirror's colour).
pub const MAX_DEPTH: i64 = 64;

/// Most samples per pixel (`image.spp`, `--spp`).
pub const MAX_SPP: i64 = 1 << 16;

/// Most shadow rays per area light at each hit (`image.shadow_samples`).
pub const MAX_SHADOW_SAMPLES: i64 = 1 << 12;

/// Most camera samples of one render (pixels times `spp`): about 6.9e10,
/// hours of work at any speed this renderer reaches, so a typo such as
/// `spp = 4000000000` is refused rather than left to run for years.
pub const MAX_SAMPLES: u64 = 1 << 36;

/// A height source as loaded: the source, its generated size, addressing.
type HeightKey = (String, [usize; 2], Address);

struct Ctx<'a> {
    name: &'a Path,
    base: &'a Path,
    cache: BakeCache,
    heights: HashMap<HeightKey, Arc<HeightMap>>,
    textures: HashMap<(PathBuf, bool), Arc<Texture>>,
    method: Option<Method>,
    /// The bakes counted in `memory`: height source and map size.
    planned: HashSet<(HeightKey, [usize; 3])>,
    /// Estimated bytes the scene holds: its image, its bakes' peaks, its
    /// textures and environment map, all together (each also passes the
    /// one-buffer check, but a scene of many can still exhaust the machine).
    memory: u128,
    /// Every file the scene reads besides itself, for its content hash.
    sources: Vec<PathBuf>,
}

impl Ctx<'_> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::Scene {
            path: self.name.to_path_buf(),
            message: message.into(),
        }
    }

    fn vec(&self, v: V3, what: &str) -> Result<Vec3> {
        if !v.iter().all(|c| c.is_finite()) {
            return Err(self.err(format!(
                "{what} = {v:?}: every component must be a finite number"
            )));
        }
        if v.iter().any(|c| c.abs() > MAX_COORDINATE) {
            return Err(self.err(format!(
                "{what} = {v:?}: components must be at most {MAX_COORDINATE:e} in magnitude (squared lengths must fit in float32)"
            )));
        }
        Ok(Vec3::from_array(v))
    }

    fn color(&self, v: V3, what: &str) -> Result<Vec3> {
        let c = self.vec(v, what)?;
        if c.min_element() < 0.0 {
            return Err(self.err(format!("{what} = {v:?}: colours cannot be negative")));
        }
        Ok(c)
    }

    fn positive(&self, v: i64, what: &str) -> Result<u32> {
        if v <= 0 || v > u32::MAX as i64 {
            return Err(self.err(format!("{what} must be a positive whole number, got {v}")));
        }
        Ok(v as u32)
    }

    /// A whole number in `1..=max`, the bound named in the message.
    fn bounded(&self, v: i64, max: i64, what: &str) -> Result<u32> {
        let n = self.positive(v, what)?;
        if v > max {
            return Err(self.err(format!("{what} = {v} is more than the limit of {max}")));
        }
        Ok(n)
    }

    /// Records a file the scene reads, once.
    fn source(&mut self, path: PathBuf) {
        if !self.sources.contains(&path) {
            self.sources.push(path);
        }
    }

    /// Adds `bytes` for `what` to the scene's memory estimate and refuses
    /// the scene when the whole so far exceeds the limit
    /// ([`displace_core::memory::check`]): called before each large input
    /// is decoded or baked, so the input that tips the scene over is named
    /// and nothing of its size has been allocated.
    fn reserve(&mut self, what: &str, bytes: u128) -> Result<()> {
        self.memory += bytes;
        displace_core::memory::check(
            &format!("{what} (with the scene's image, bakes and textures before it)"),
            self.memory,
        )
        .map_err(|e| self.err(e.to_string()))
    }

    /// The texture `file` that scene key `key` names, counted in the
    /// memory estimate before it is decoded (once per file, as it is
    /// loaded once); a failure to load it names the key as well as the
    /// file.
    fn texture(&mut self, file: &str, srgb: bool, key: &str) -> Result<Arc<Texture>> {
        let path = self.base.join(file);
        if let Some(t) = self.textures.get(&(path.clone(), srgb)) {
            return Ok(t.clone());
        }
        self.source(path.clone());
        let t = Arc::new(self.image(
            key,
            file,
            ("texture", Texture::BYTES_PER_TEXEL),
            Texture::dimensions,
            |p| Texture::load(p, srgb),
        )?);
        self.textures.insert((path, srgb), t.clone());
        Ok(t)
    }

    /// Reads the image input `file` that scene key `key` names, of `kind`
    /// (a texture, an environment map) at `bytes_per_texel` held: its size
    /// from the header by `dimensions`, counted in the memory estimate,
    /// then decoded by `load`. A failure names the key as well as the file.
    fn image<T>(
        &mut self,
        key: &str,
        file: &str,
        (kind, bytes_per_texel): (&str, u128),
        dimensions: fn(&Path) -> Result<[usize; 2]>,
        load: impl FnOnce(&Path) -> Result<T>,
    ) -> Result<T> {
        let path = self.base.join(file);
        let named = |e: Error| format!("{key} = \"{file}\": {e}");
        let [w, h] = dimensions(&path).map_err(|e| self.err(named(e)))?;
        self.reserve(
            &format!("{key} = \"{file}\": a {w}x{h} {kind}"),
            w as u128 * h as u128 * bytes_per_texel,
        )?;
        load(&path).map_err(|e| self.err(named(e)))
    }
}

pub fn build(spec: SceneSpec, name: &Path, base: &Path, opts: &SceneOptions) -> Result<Scene> {
    let mut cx = Ctx {
        name,
        base,
        cache: BakeCache::new(opts.cache_dir.clone()),
        heights: HashMap::new(),
        textures: HashMap::new(),
        method: opts.method,
        planned: HashSet::new(),
        memory: 0,
        sources: Vec::new(),
    };
    let img = &spec.image;
    let (width, height) = match opts.size {
        Some([w, h]) => (
            cx.positive(w as i64, "--size width")?,
            cx.positive(h as i64, "--size height")?,
        ),
        None => (
            cx.positive(img.width, "image.width")?,
            cx.positive(img.height, "image.height")?,
        ),
    };
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(cx.err(format!(
            "image {width}x{height} has more than {MAX_PIXELS} pixels"
        )));
    }
    // The film and its AOVs: at most a few colour-sized buffers.
    cx.memory = width as u128 * height as u128 * IMAGE_BYTES_PER_PIXEL;
    let spp = match opts.spp {
        Some(s) => cx.bounded(s as i64, MAX_SPP, "--spp")?,
        None => cx.bounded(img.spp, MAX_SPP, "image.spp")?,
    };
    let samples = width as u64 * height as u64 * spp as u64;
    if samples > MAX_SAMPLES {
        return Err(cx.err(format!(
            "{width}x{height} pixels at {spp} spp is {samples} camera samples, more than the limit of {MAX_SAMPLES}; lower image.spp or the size"
        )));
    }
    let shadow_samples = cx.bounded(
        img.shadow_samples,
        MAX_SHADOW_SAMPLES,
        "image.shadow_samples",
    )?;
    if !(0..=MAX_DEPTH).contains(&img.max_depth) {
        return Err(cx.err(format!(
            "image.max_depth must be 0..={MAX_DEPTH} (bounces are traced recursively), got {}",
            img.max_depth
        )));
    }
    let integrator = match opts.integrator {
        Some(i) => i,
        None => img
            .integrator
            .parse()
            .map_err(|e: Error| cx.err(format!("image.integrator: {e}")))?,
    };
    let sampling: Sampling = img
        .sampling
        .parse()
        .map_err(|e: Error| cx.err(format!("image.sampling: {e}")))?;
    let background = match img.background {
        Some(b) => cx.color(b, "image.background")?,
        None => Vec3::ZERO,
    };
    let environment = match &img.environment {
        None => Environment::Constant(background),
        Some(file) => {
            if img.background.is_some() {
                return Err(cx.err(
                    "image.background and image.environment both give the light of escaping rays: give one",
                ));
            }
            let map = cx.image(
                "image.environment",
                file,
                ("environment map", EnvironmentMap::BYTES_PER_TEXEL),
                EnvironmentMap::dimensions,
                EnvironmentMap::load,
            )?;
            cx.source(cx.base.join(file));
            Environment::Map(Arc::new(map))
        }
    };

    let c = &spec.camera;
    let position = cx.vec(c.position, "camera.position")?;
    let look_at = cx.vec(c.look_at, "camera.look_at")?;
    let up = cx.vec(c.up, "camera.up")?;
    let camera = Camera::new(
        position,
        look_at,
        up,
        c.vfov,
        width as f32 / height as f32,
        c.aperture,
        c.focus_distance,
    )
    .map_err(|e| cx.err(e.to_string()))?;

    let mut materials = Vec::new();
    let mut material_index = HashMap::new();
    for (key, m) in &spec.materials {
        material_index.insert(key.clone(), materials.len() as u32);
        materials.push(material(&mut cx, key, m)?);
    }
    let light_material = materials.len() as u32;
    materials.push(Material::default());

    let mut prims = Vec::new();
    let mut lights = Vec::new();
    let mut fill = Vec::new();
    for (k, l) in spec.lights.iter().enumerate() {
        let what = format!("lights[{k}]");
        match l {
            LightSpec::Point {
                position,
                intensity,
                fill: f,
            } => {
                lights.push(Light::Point {
                    position: cx.vec(*position, &format!("{what}.position"))?,
                    intensity: cx.color(*intensity, &format!("{what}.intensity"))?,
                });
                fill.push(*f);
            }
            LightSpec::Area {
                origin,
                edge_u,
                edge_v,
                radiance,
                visible,
                fill: f,
            } => {
                if *f && *visible {
                    return Err(cx.err(format!(
                        "{what}: a fill light needs visible = false (the path integrator leaves it out, and its quad would still block rays)"
                    )));
                }
                fill.push(*f);
                let quad = quad(&cx, *origin, *edge_u, *edge_v, &what)?;
                let radiance = cx.color(*radiance, &format!("{what}.radiance"))?;
                if *visible {
                    prims.push(Primitive {
                        shape: Shape::Quad(quad),
                        material: light_material,
                        emitter: Some(lights.len() as u32),
                        shape_index: None,
                    });
                }
                lights.push(Light::Area { quad, radiance });
            }
        }
    }

    let mut attrs = Vec::new();
    let mut meshes = Vec::new();
    for (k, s) in spec.shapes.iter().enumerate() {
        let what = format!("shapes[{k}]");
        let mat_name = match s {
            ShapeSpec::Quad { material, .. }
            | ShapeSpec::Triangle { material, .. }
            | ShapeSpec::Sphere { material, .. }
            | ShapeSpec::Box { material, .. }
            | ShapeSpec::Mesh { material, .. } => material,
        };
        let material = *material_index
            .get(mat_name)
            .ok_or_else(|| cx.err(format!("{what}.material: no material named `{mat_name}`")))?;
        let first_prim = prims.len();
        let mut push = |shape| {
            prims.push(Primitive {
                shape,
                material,
                emitter: None,
                shape_index: Some(k as u32),
            })
        };
        match s {
            ShapeSpec::Quad {
                origin,
                edge_u,
                edge_v,
                displacement,
                ..
            } => {
                let q = quad(&cx, *origin, *edge_u, *edge_v, &what)?;
                match displacement_of(&cx, displacement, &what)? {
                    None => push(Shape::Quad(q)),
                    Some(d) => push(Shape::Displaced(Box::new(displaced_quad(
                        &mut cx, &q, d, &what,
                    )?))),
                }
            }
            ShapeSpec::Triangle {
                vertices,
                uvs,
                displacement,
                ..
            } => {
                let p: Vec<Vec3> = vertices
                    .iter()
                    .enumerate()
                    .map(|(i, v)| cx.vec(*v, &format!("{what}.vertices[{i}]")))
                    .collect::<Result<_>>()?;
                let tri = Triangle::new(p[0], p[1], p[2]);
                if tri.normal() == Vec3::ZERO {
                    return Err(cx.err(format!("{what}: the triangle is degenerate (zero area)")));
                }
                let uv = match uvs {
                    Some(u) => {
                        if u.iter().flatten().any(|c| !c.is_finite()) {
                            return Err(
                                cx.err(format!("{what}.uvs: every component must be finite"))
                            );
                        }
                        u.map(Vec2::from_array)
                    }
                    None => [Vec2::ZERO, Vec2::X, Vec2::Y],
                };
                let shared = match displacement_of(&cx, displacement, &what)? {
                    None => {
                        attrs.push(TriAttr {
                            normals: None,
                            uvs: uv,
                        });
                        push(Shape::Triangle {
                            tri,
                            attr: attrs.len() as u32 - 1,
                        });
                        None
                    }
                    Some(d) if d.flip_v => {
                        return Err(cx.err(format!("{what}.displacement.flip_v applies to quads only; give the triangle's uvs instead")));
                    }
                    Some(d) => {
                        let (map_extent, _) = triangle_frame(&tri, &uv).ok_or_else(|| {
                            cx.err(format!("{what}.uvs: degenerate texture coordinates"))
                        })?;
                        let dm = DispBuild::new(&mut cx, d, map_extent, &what)?;
                        push(Shape::Displaced(Box::new(
                            dm.triangle(&cx, &tri, &uv, &what)?,
                        )));
                        Some(dm.shared())
                    }
                };
                meshes.push(SceneMesh {
                    triangles: vec![MeshTriangle {
                        positions: [tri.p0, tri.p0 + tri.e1, tri.p0 + tri.e2],
                        normals: Some([tri.normal(); 3]),
                        uvs: uv,
                    }],
                    material,
                    displacement: shared,
                    prims: first_prim..prims.len(),
                });
            }
            ShapeSpec::Sphere { center, radius, .. } => {
                let center = cx.vec(*center, &format!("{what}.center"))?;
                if !(*radius > 0.0 && radius.is_finite()) {
                    return Err(cx.err(format!("{what}.radius must be positive, got {radius}")));
                }
                push(Shape::Sphere(Sphere {
                    center,
                    radius: *radius,
                }))
            }
            ShapeSpec::Box {
                min, max, rotate_y, ..
            } => {
                let lo = cx.vec(*min, &format!("{what}.min"))?;
                let hi = cx.vec(*max, &format!("{what}.max"))?;
                if !(hi.cmpgt(lo).all()) || !rotate_y.is_finite() {
                    return Err(cx.err(format!(
                        "{what}: max must exceed min on every axis and rotate_y be finite"
                    )));
                }
                for q in box_faces(lo, hi, *rotate_y) {
                    push(Shape::Quad(q));
                }
            }
            ShapeSpec::Mesh {
                path,
                translate,
                scale,
                rotate_y,
                displacement,
                ..
            } => {
                let t = cx.vec(*translate, &format!("{what}.translate"))?;
                if !(*scale > 0.0 && scale.is_finite() && rotate_y.is_finite()) {
                    return Err(cx.err(format!(
                        "{what}: scale must be positive and rotate_y finite"
                    )));
                }
                let (file, mut mesh) = match path.strip_prefix(builtin_mesh::PREFIX) {
                    Some(name) => (PathBuf::from(path), builtin_mesh::generate(name)?),
                    None => {
                        let file = cx.base.join(path);
                        let mesh = crate::mesh::load(&file)?;
                        cx.source(file.clone());
                        (file, mesh)
                    }
                };
                let rot = Mat3::from_rotation_y(rotate_y.to_radians());
                let xf = |p: Vec3| rot * (p * *scale) + t;
                let disp = displacement_of(&cx, displacement, &what)?;
                let mut builder = None;
                if let Some(d) = disp {
                    if d.flip_v {
                        return Err(
                            cx.err(format!("{what}.displacement.flip_v applies to quads only"))
                        );
                    }
                    if !mesh.has_uvs {
                        return Err(Error::Mesh {
                            path: file,
                            message: "a displaced mesh needs texture coordinates (vt)".into(),
                        });
                    }
                    // `tiles` repeats the map over the mesh's coordinates.
                    let tiles = Vec2::from_array(d.tiles);
                    for t in &mut mesh.triangles {
                        t.uvs = t.uvs.map(|uv| uv * tiles);
                    }
                    let extent = mesh_extent(&mesh.triangles, &xf).ok_or_else(|| {
                        cx.err(format!(
                            "{what}: the mesh's texture coordinates are degenerate"
                        ))
                    })?;
                    builder = Some(DispBuild::new(&mut cx, d, extent, &what)?);
                }
                let mut world_tris = Vec::with_capacity(mesh.triangles.len());
                for (k, tri) in mesh.triangles.iter().enumerate() {
                    let p = tri.positions.map(xf);
                    let tr = Triangle::new(p[0], p[1], p[2]);
                    if tr.normal() == Vec3::ZERO {
                        continue;
                    }
                    world_tris.push(MeshTriangle {
                        positions: p,
                        normals: Some(match tri.normals {
                            Some(n) => n.map(|v| (rot * v).normalize_or(tr.normal())),
                            None => [tr.normal(); 3],
                        }),
                        uvs: tri.uvs,
                    });
                    match &builder {
                        Some(b) => {
                            let face =
                                b.triangle(&cx, &tr, &tri.uvs, &format!("{what} triangle {k}"))?;
                            push(Shape::Displaced(Box::new(face)));
                        }
                        None => {
                            attrs.push(TriAttr {
                                normals: tri
                                    .normals
                                    .map(|n| n.map(|v| (rot * v).normalize_or_zero())),
                                uvs: tri.uvs,
                            });
                            push(Shape::Triangle {
                                tri: tr,
                                attr: attrs.len() as u32 - 1,
                            });
                        }
                    }
                }
                meshes.push(SceneMesh {
                    triangles: world_tris,
                    material,
                    displacement: builder.as_ref().map(DispBuild::shared),
                    prims: first_prim..prims.len(),
                });
            }
        }
    }
    let bounds: Vec<Aabb> = prims.iter().map(Primitive::bounds).collect();
    let bvh = Bvh::build(&bounds);
    let world = bvh.bounds();
    let diag = if world.is_empty() {
        1.0
    } else {
        (world.max - world.min).length()
    };
    let emitters = Emitters::new(&lights, &fill, &prims, &materials, &environment, 0.5 * diag);
    Ok(Scene {
        camera,
        width,
        height,
        spp,
        max_depth: img.max_depth as u32,
        seed: img.seed,
        shadow_samples,
        background,
        environment,
        integrator,
        sampling,
        emitters,
        prims,
        attrs,
        bvh,
        materials,
        lights,
        epsilon: 5e-5 * diag.max(1e-3),
        meshes,
        cache_stats: cx.cache.stats(),
        sources: cx.sources,
        content_hash: 0,
        warnings: cx.cache.warnings(),
    })
}

fn material(cx: &mut Ctx, key: &str, m: &MaterialSpec) -> Result<Material> {
    let what = format!("materials.{key}");
    let key = format!("{what}.texture");
    let tex = |cx: &mut Ctx, t: &Option<String>| {
        t.as_ref().map(|f| cx.texture(f, true, &key)).transpose()
    };
    let emission = match m {
        MaterialSpec::Lambert { emission, .. }
        | MaterialSpec::Phong { emission, .. }
        | MaterialSpec::Mirror { emission, .. }
        | MaterialSpec::Glossy { emission, .. } => {
            cx.color(*emission, &format!("{what}.emission"))?
        }
    };
    let material = match m {
        MaterialSpec::Lambert { color, texture, .. } => Material {
            diffuse: cx.color(*color, &format!("{what}.color"))?,
            texture: tex(cx, texture)?,
            ..Material::default()
        },
        MaterialSpec::Phong {
            color,
            texture,
            specular,
            shininess,
            ..
        } => {
            if !(*shininess > 0.0 && shininess.is_finite()) {
                return Err(cx.err(format!(
                    "{what}.shininess must be positive, got {shininess}"
                )));
            }
            Material {
                diffuse: cx.color(*color, &format!("{what}.color"))?,
                texture: tex(cx, texture)?,
                specular: cx.color(*specular, &format!("{what}.specular"))?,
                shininess: *shininess,
                ..Material::default()
            }
        }
        MaterialSpec::Mirror { color, diffuse, .. } => Material {
            diffuse: cx.color(*diffuse, &format!("{what}.diffuse"))?,
            reflect: cx.color(*color, &format!("{what}.color"))?,
            ..Material::default()
        },
        MaterialSpec::Glossy {
            color,
            roughness,
            diffuse,
            ..
        } => {
            if !(*roughness > 0.0 && *roughness <= 1.0) {
                return Err(cx.err(format!(
                    "{what}.roughness must be in (0, 1], got {roughness}"
                )));
            }
            Material {
                diffuse: cx.color(*diffuse, &format!("{what}.diffuse"))?,
                reflect: cx.color(*color, &format!("{what}.color"))?,
                roughness: *roughness,
                ..Material::default()
            }
        }
    };
    Ok(Material {
        emission,
        ..material
    })
}

fn quad(cx: &Ctx, origin: V3, edge_u: V3, edge_v: V3, what: &str) -> Result<Quad> {
    let o = cx.vec(origin, &format!("{what}.origin"))?;
    let u = cx.vec(edge_u, &format!("{what}.edge_u"))?;
    let v = cx.vec(edge_v, &format!("{what}.edge_v"))?;
    Quad::new(o, u, v)
        .ok_or_else(|| cx.err(format!("{what}: edge_u and edge_v are parallel or zero")))
}

/// The displacement of a shape, or `None` when there is none or its depth is
/// 0 (a zero-depth displacement is the plain face).
fn displacement_of<'a>(
    cx: &Ctx,
    d: &'a Option<DisplacementSpec>,
    what: &str,
) -> Result<Option<&'a DisplacementSpec>> {
    let Some(d) = d else { return Ok(None) };
    if !(d.depth >= 0.0 && d.depth.is_finite()) {
        return Err(cx.err(format!(
            "{what}.displacement.depth must be a finite number >= 0, got {}",
            d.depth
        )));
    }
    Ok((d.depth > 0.0).then_some(d))
}

/// `(|dP/du|, |dP/dv|)` and `(dP/du, dP/dv)` of a triangle's texture
/// parameterisation, or `None` if its coordinates are degenerate.
fn triangle_frame(tri: &Triangle, uv: &[Vec2; 3]) -> Option<(Vec2, (Vec3, Vec3))> {
    let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
    let det = d1.x * d2.y - d2.x * d1.y;
    if det.abs() < 1e-12 || !det.is_finite() {
        return None;
    }
    let dpdu = (d2.y * tri.e1 - d1.y * tri.e2) / det;
    let dpdv = (-d2.x * tri.e1 + d1.x * tri.e2) / det;
    Some((Vec2::new(dpdu.length(), dpdv.length()), (dpdu, dpdv)))
}

/// Area-weighted mean tile size of a mesh: the proportions its one shared
/// bake is made for.
fn mesh_extent(tris: &[crate::mesh::MeshTriangle], xf: &dyn Fn(Vec3) -> Vec3) -> Option<Vec2> {
    let mut sum = Vec2::ZERO;
    let mut weight = 0.0;
    for t in tris {
        let tr = Triangle::new(xf(t.positions[0]), xf(t.positions[1]), xf(t.positions[2]));
        if let Some((e, _)) = triangle_frame(&tr, &t.uvs) {
            let a = tr.e1.cross(tr.e2).length();
            sum += e * a;
            weight += a;
        }
    }
    (weight > 0.0).then(|| sum / weight)
}

/// A validated displacement with its bake, ready to make faces.
struct DispBuild {
    map: Arc<displace_core::DisplacementMap>,
    depth: f32,
    trace: TraceOptions,
    address: Address,
    color: Option<Arc<Texture>>,
    normal_map: Option<Arc<Texture>>,
}

impl DispBuild {
    /// `tile` is the world size of one tile (`|dP/du|`, `|dP/dv|`).
    fn new(cx: &mut Ctx, d: &DisplacementSpec, tile: Vec2, what: &str) -> Result<Self> {
        let what = format!("{what}.displacement");
        let address: Address = d
            .address
            .parse()
            .map_err(|e: displace_core::Error| cx.err(format!("{what}.address: {e}")))?;
        let method: Method = d
            .method
            .parse()
            .map_err(|e: displace_core::Error| cx.err(format!("{what}.method: {e}")))?;
        let hs = d.height_size;
        if hs.iter().any(|&n| !(2..=1 << 16).contains(&n)) {
            return Err(cx.err(format!(
                "{what}.height_size must be 2..65536 texels per side, got {hs:?}"
            )));
        }
        let ms = d.map_size;
        if ms.iter().any(|&n| !(2..=1 << 14).contains(&n)) {
            return Err(cx.err(format!(
                "{what}.map_size must be 2..16384 voxels per side, got {ms:?}"
            )));
        }
        let iterations = cx.bounded(
            d.iterations,
            MAX_TRACE_ITERATIONS.into(),
            &format!("{what}.iterations"),
        )?;
        if d.tiles.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(cx.err(format!("{what}.tiles must be positive, got {:?}", d.tiles)));
        }
        if address == Address::Clamp && d.tiles != [1.0, 1.0] {
            return Err(cx.err(format!(
                "{what}.tiles: a clamped map covers one tile; use address = \"repeat\" to tile it"
            )));
        }
        let size = [hs[0] as usize, hs[1] as usize];
        let key = (d.height.clone(), size, address);
        let map_size = [ms[0] as usize, ms[1] as usize, ms[2] as usize];
        let core_err = |cx: &Ctx, e: Error| match e {
            Error::Core(c) => cx.err(format!("{what}.height `{}`: {c}", d.height)),
            other => other,
        };
        if cx.planned.insert((key.clone(), map_size)) {
            // A new bake: its peak on top of what the scene holds already.
            let texels = crate::heights::dimensions(&d.height, size, address, cx.base)
                .map_err(|e| core_err(cx, e))?;
            cx.reserve(
                &format!(
                    "{what}: baking the {}x{} height map into {}x{}x{} voxels",
                    texels[0], texels[1], map_size[0], map_size[1], map_size[2]
                ),
                displace_core::memory::bake_peak_bytes(texels, map_size, false),
            )?;
        }
        let height = match cx.heights.get(&key) {
            Some(h) => h.clone(),
            None => {
                let h = Arc::new(
                    crate::heights::load(&d.height, size, address, cx.base)
                        .map_err(|e| core_err(cx, e))?,
                );
                if !d.height.starts_with("gen:") {
                    let file = cx.base.join(&d.height);
                    cx.source(file);
                }
                cx.heights.insert(key, h.clone());
                h
            }
        };
        let extent =
            Extent::new(tile.x, tile.y, d.depth).map_err(|e| cx.err(format!("{what}: {e}")))?;
        let map = cx.cache.get(&height, map_size, extent)?;
        let color = d
            .color_texture
            .as_ref()
            .map(|f| cx.texture(f, true, &format!("{what}.color_texture")))
            .transpose()?;
        let normal_map = d
            .normal_map
            .as_ref()
            .map(|f| cx.texture(f, false, &format!("{what}.normal_map")))
            .transpose()?;
        Ok(Self {
            map,
            depth: d.depth,
            trace: TraceOptions {
                method: cx.method.unwrap_or(method),
                iterations,
                tiles: d.tiles,
                ..TraceOptions::default()
            },
            address,
            color,
            normal_map,
        })
    }

    /// What every face of this displacement shares, for [`SceneMesh`].
    fn shared(&self) -> MeshDisplacement {
        MeshDisplacement {
            map: self.map.clone(),
            depth: self.depth,
            trace: self.trace,
            textured: self.color.is_some() || self.normal_map.is_some(),
        }
    }

    fn finish(&self, face: Option<DisplacedFace>, cx: &Ctx, what: &str) -> Result<DisplacedFace> {
        let mut face =
            face.ok_or_else(|| cx.err(format!("{what}: the displaced face is degenerate")))?;
        face.color = self.color.clone();
        face.normal_map = self.normal_map.clone();
        Ok(face)
    }

    fn triangle(
        &self,
        cx: &Ctx,
        tri: &Triangle,
        uv: &[Vec2; 3],
        what: &str,
    ) -> Result<DisplacedFace> {
        let (_, (dpdu, dpdv)) = triangle_frame(tri, uv)
            .ok_or_else(|| cx.err(format!("{what}: degenerate texture coordinates")))?;
        let lo = uv[0].min(uv[1]).min(uv[2]);
        let hi = uv[0].max(uv[1]).max(uv[2]);
        let mut trace = self.trace;
        let shift = match self.address {
            Address::Clamp => {
                if lo.min_element() < -1e-6 || hi.max_element() > 1.0 + 1e-6 {
                    return Err(cx.err(format!(
                        "{what}: texture coordinates leave [0, 1] but the displacement clamps; use address = \"repeat\""
                    )));
                }
                Vec2::ZERO
            }
            Address::Repeat => {
                let s = lo.floor();
                let t = (hi - s).ceil().max(Vec2::ONE);
                trace.tiles = [t.x, t.y];
                s
            }
        };
        let local =
            uv.map(|c| (c - shift).clamp(Vec2::ZERO, Vec2::new(trace.tiles[0], trace.tiles[1])));
        let frame = FaceFrame {
            origin: tri.p0 - local[0].x * dpdu - local[0].y * dpdv,
            dpdu,
            dpdv,
            normal: tri.normal(),
            depth: self.depth,
        };
        let face = DisplacedFace::new(frame, self.map.clone(), trace, Some(local), shift);
        self.finish(face, cx, what)
    }
}

fn displaced_quad(
    cx: &mut Ctx,
    q: &Quad,
    d: &DisplacementSpec,
    what: &str,
) -> Result<DisplacedFace> {
    let tiles = Vec2::from_array(d.tiles);
    let tile = Vec2::new(q.edge_u.length(), q.edge_v.length()) / tiles.max(Vec2::splat(1e-30));
    let b = DispBuild::new(cx, d, tile, what)?;
    let (origin, dpdv) = if d.flip_v {
        (q.origin + q.edge_v, -q.edge_v / tiles.y)
    } else {
        (q.origin, q.edge_v / tiles.y)
    };
    let frame = FaceFrame {
        origin,
        dpdu: q.edge_u / tiles.x,
        dpdv,
        normal: q.normal,
        depth: b.depth,
    };
    let face = DisplacedFace::new(frame, b.map.clone(), b.trace, None, Vec2::ZERO);
    b.finish(face, cx, what)
}
