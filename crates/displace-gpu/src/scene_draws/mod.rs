//! A scene placed in the world ([`displace_scene::World`]) as draws of the
//! raster path: the one scene description both renderers are built from,
//! as pbrt-v4 builds its CPU and GPU aggregates from one `BasicScene`.
//! `displace gpu-render SCENE` draws them once, `displace view` every frame.
//!
//! The scene is loaded and validated by `displace_scene`, as for the CPU
//! renderer, so every error (file:line:column, unknown keys, missing height
//! files) is the same, and every displaced face gets the bake the CPU
//! renderer uses. What the GPU draws of it: each displaced parallelogram (tiled or
//! not) as its own shell box with Donnelly's shaders (GPU Gems 2 ch. 8,
//! listings 8-1 and 8-2), and each displaced triangle and mesh (OBJ or
//! built-in) as the shells of its triangles in their MikkTSpace frames
//! ([`crate::mesh`], which says where that differs from the CPU's prisms),
//! lit by one point light (the strongest light, an area light as a point at
//! its centre) with the CPU's point-light falloff and Lambert / normalised
//! Blinn-Phong terms. Every other shape (quads, boxes, spheres, triangles
//! and meshes without displacement, visible area-light quads with their
//! radiance) is drawn as plain triangles ([`crate::plain`]) in the same
//! depth buffer, lit by the same light and terms without shadows.
//! Everything else is left out and reported ([`SceneDraws::left_out`]):
//! textures, reflections, other lights, shadows cast by one face onto
//! another (each face shadows only itself) and shadows on the plain shapes.

mod shading;
mod shapes;
mod stage;

use crate::convention::check_iterations;
use crate::raster::{render_faces, shared_depth_range, Colour, RasterShape};
use crate::{
    CurvedShells, DistanceTexture, Draw, DrawShape, Error, Face, GpuContext, Image, PlainMesh,
    Renderer, Result, Shadows, View,
};
use displace_core::{Method, TraceOptions};
use displace_scene::light::Light;
use displace_scene::material::Material;
use displace_scene::placed::{FlatDisplacement, MeshDisplacement, Placed, PlacedShape, SceneMesh};
use displace_scene::World;
use glam::Vec3;
use shading::{material_shading, plain_material, Shading};
use stage::Stage;
use std::collections::HashSet;

/// The drawable faces and meshes of a scene, each with its renderer and its
/// [`Draw`], the one [`View`] they are drawn under (its depth range holding
/// them all), and what was left out.
pub struct SceneDraws {
    /// The scene's camera and strongest light.
    pub view: View,
    /// The displaced draws, then one draw of every plain triangle.
    pub draws: Vec<(Renderer, Draw)>,
    /// Plain triangles in the last draw (none: no plain draw).
    pub plain_triangles: usize,
    /// What of the scene is not drawn, sorted, each once.
    pub left_out: Vec<String>,
    /// Linear background colour.
    pub background: [f64; 3],
}

impl SceneDraws {
    /// Displaced faces and meshes drawn (every draw but the plain one).
    pub fn displaced(&self) -> usize {
        self.draws.len() - usize::from(self.plain_triangles > 0)
    }

    /// One frame of every draw, in the scene's background colour.
    pub fn render(&self, ctx: &GpuContext) -> Result<Image> {
        let draws: Vec<(&Renderer, &Draw)> = self.draws.iter().map(|(r, d)| (r, d)).collect();
        render_faces(ctx, &self.view, &draws, self.background)
    }
}

/// Uploads every displaced face and mesh of `scene`, and one draw of its
/// plain shapes, with `texture` storing the distances and `shadows` the
/// faces' self-shadowing.
pub fn from_scene(
    ctx: &GpuContext,
    scene: &World,
    texture: DistanceTexture,
    shadows: Shadows,
) -> Result<SceneDraws> {
    let mut left_out = Vec::new();
    let stage = Stage::of(scene, shadows, &mut left_out)?;
    let mut draws = Draws {
        ctx,
        texture,
        stage,
        draws: Vec::new(),
        plain: PlainMesh::default(),
        left_out,
    };
    // Triangles and meshes are drawn as meshes, not per primitive.
    let meshed: HashSet<usize> = scene.meshes.iter().flat_map(|m| m.prims.clone()).collect();
    for (k, prim) in scene.shapes.iter().enumerate() {
        if !meshed.contains(&k) {
            draws.primitive(scene, k, prim)?;
        }
    }
    for (k, mesh) in scene.meshes.iter().enumerate() {
        let material = &scene.materials[mesh.material as usize];
        draws.mesh(k, mesh, material)?;
    }
    let bg = scene.background;
    draws.finish([bg.x as f64, bg.y as f64, bg.z as f64])
}

/// The draws of a scene as they are gathered.
struct Draws<'a> {
    ctx: &'a GpuContext,
    texture: DistanceTexture,
    stage: Stage,
    draws: Vec<(Renderer, Draw)>,
    plain: PlainMesh,
    left_out: Vec<String>,
}

impl Draws<'_> {
    /// Primitive `k`: a displaced face drawn by its own renderer, any
    /// other shape added to the plain triangles.
    fn primitive(&mut self, scene: &World, k: usize, prim: &PlacedShape) -> Result<()> {
        let material = &scene.materials[prim.material as usize];
        let Placed::Displaced(face) = &prim.shape else {
            let emission = prim
                .emitter
                .map_or(Vec3::ZERO, |e| match &scene.lights[e as usize] {
                    Light::Area { radiance, .. } => *radiance,
                    Light::Point { .. } => Vec3::ZERO,
                });
            let m = plain_material(material, self.stage.intensity, emission, &mut self.left_out);
            shapes::add_plain(&mut self.plain, &prim.shape, &m);
            return Ok(());
        };
        self.face(k, face, material)
    }

    /// A displaced parallelogram or triangle: its shell box in its frame.
    fn face(&mut self, k: usize, face: &FlatDisplacement, material: &Material) -> Result<()> {
        let trace = face.trace_options();
        check_trace(&trace, || format!("primitive {k}"))?;
        if face.color.is_some() || face.normal_map.is_some() {
            self.left_out
                .push("displacement colour textures and normal maps".to_string());
        }
        let (origin, m) = face.frame();
        let map = face.map();
        let [ax, ay] = map.aspect();
        let (tangent, bitangent, up_n) = (m.col(0) * ax, m.col(1) * ay, m.col(2));
        // A `flip_v` quad runs `v` back along its edge: a left-handed frame.
        let mirrored = tangent.cross(bitangent).dot(up_n) < 0.0;
        let shading = material_shading(material, self.stage.intensity);
        shading.note(&mut self.left_out);
        let shape = DrawShape::Face(Face {
            origin,
            tangent,
            bitangent,
            tiles: trace.tiles,
            mirrored,
        });
        let draw = Draw {
            depth: up_n.length(),
            method: trace.method,
            iterations: trace.iterations,
            ..self.stage.draw(shape, &shading)
        };
        let renderer = Renderer::with_albedo(
            self.ctx,
            map,
            self.texture,
            shading.albedo.to_array(),
            mirrored,
        )
        .map_err(step(format!("uploading displaced face {k}")))?;
        self.draws.push((renderer, draw));
        Ok(())
    }

    /// Scene mesh `k` (a mesh or a lone triangle): plain triangles, or the
    /// shells of its triangles under its displacement.
    fn mesh(&mut self, k: usize, mesh: &SceneMesh, material: &Material) -> Result<()> {
        let Some(disp) = &mesh.displacement else {
            let m = plain_material(
                material,
                self.stage.intensity,
                Vec3::ZERO,
                &mut self.left_out,
            );
            shapes::add_mesh(&mut self.plain, mesh, &m);
            return Ok(());
        };
        self.displaced_mesh(k, mesh, disp, material)
    }

    fn displaced_mesh(
        &mut self,
        k: usize,
        mesh: &SceneMesh,
        disp: &MeshDisplacement,
        material: &Material,
    ) -> Result<()> {
        check_trace(&disp.trace, || format!("mesh {k}"))?;
        if disp.textured {
            self.left_out
                .push("displacement colour textures and normal maps".to_string());
        }
        let shading = material_shading(material, self.stage.intensity);
        shading.note(&mut self.left_out);
        let curved = CurvedShells::new(
            &mesh.triangles,
            &disp.shells,
            disp.depth,
            disp.map.aspect(),
            disp.map.address(),
        )
        .map_err(|e| Error::InvalidOption(e.to_string()))
        .map_err(step(format!("preparing the shells of mesh {k}")))?;
        let albedo = shading.albedo.to_array();
        let (bounds, renderer) = match &curved {
            Some(shells) => (
                shells.bounds,
                Renderer::with_colour(
                    self.ctx,
                    &disp.map,
                    self.texture,
                    Colour::Albedo(albedo),
                    RasterShape::Curved(shells),
                ),
            ),
            None => {
                let shell = shapes::shell_of(mesh, disp.map.address())
                    .map_err(step(format!("preparing the shell of mesh {k}")))?;
                (
                    shapes::bounds(mesh),
                    Renderer::with_colour(
                        self.ctx,
                        &disp.map,
                        self.texture,
                        Colour::Albedo(albedo),
                        RasterShape::Mesh(&shell),
                    ),
                )
            }
        };
        let renderer = renderer.map_err(step(format!("uploading displaced mesh {k}")))?;
        let draw = Draw {
            depth: disp.depth,
            method: disp.trace.method,
            iterations: disp.trace.iterations,
            ..self.stage.draw(DrawShape::Mesh { bounds }, &shading)
        };
        self.draws.push((renderer, draw));
        Ok(())
    }

    /// Adds the plain draw (lit with its vertices' own weights, no shell),
    /// sorts what was left out, and gives every draw one depth range, so
    /// their exact fragment depths compare.
    fn finish(mut self, background: [f64; 3]) -> Result<SceneDraws> {
        if let Some(bounds) = self.plain.bounds() {
            self.left_out
                .push("shadows on non-displaced shapes".to_string());
            let renderer = Renderer::plain(self.ctx, &self.plain)
                .map_err(step("uploading the non-displaced shapes".into()))?;
            let draw = Draw {
                depth: 0.0,
                ..self.stage.draw(DrawShape::Mesh { bounds }, &Shading::UNIT)
            };
            self.draws.push((renderer, draw));
        }
        let mut left_out = self.left_out;
        left_out.sort();
        left_out.dedup();
        if self.draws.is_empty() {
            return Err(Error::Scene(format!(
                "the scene has nothing gpu-render can draw (left out: {left_out:?})"
            )));
        }
        let mut view = self.stage.view();
        let Some(range) = shared_depth_range(&view, self.draws.iter().map(|(_, d)| d)) else {
            return Err(Error::Scene(
                "every displaced face is behind the camera".into(),
            ));
        };
        view.depth_range = Some(range);
        Ok(SceneDraws {
            view,
            draws: self.draws,
            plain_triangles: self.plain.vertices.len() / 3,
            left_out,
            background,
        })
    }
}

/// Refuses what the raster path cannot trace: the exact method (the CPU's
/// reference) and step counts past [`crate::convention::MAX_GPU_ITERATIONS`];
/// `what` names the face or mesh.
fn check_trace(trace: &TraceOptions, what: impl Fn() -> String) -> Result<()> {
    if trace.method == Method::Exact {
        return Err(Error::Scene(format!(
            "{}: method exact is the CPU reference; the GPU traces with sphere or sphere-fixed",
            what()
        )));
    }
    check_iterations(trace.iterations).map_err(step(format!("{}: displacement.iterations", what())))
}

/// Wraps an error of the step `during` ([`Error::SceneStep`]).
fn step(during: String) -> impl FnOnce(Error) -> Error {
    move |source| Error::SceneStep {
        during,
        source: Box::new(source),
    }
}
