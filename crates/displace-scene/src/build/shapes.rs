//! `[[shapes]]`: one constructor per kind of shape, as pbrt-v4 gives each
//! shape of its scene description its own `Create`: quads (plain or displaced), spheres and boxes here; triangles and
//! meshes in `triangles`. Every constructor checks its keys and returns
//! the CPU's shapes; the dispatch pushes them as primitives.

use super::super::spec::{DisplacementSpec, ShapeSpec, V3};
use super::ctx::{Ctx, MAX_COORDINATE};
use super::displacement::{displacement_of, DispBuild};
use super::triangles;
use crate::error::Result;
use crate::placed::{FaceFrame, FlatDisplacement};
use crate::placed::{Placed, PlacedShape, SceneMesh, TriAttr};
use crate::shapes::{box_faces, Quad, Sphere};
use glam::Vec2;
use std::collections::HashMap;

/// What the shapes and lights of a scene become: the primitives the BVH
/// holds, the vertex attributes of plain triangles, and the scene's record
/// of every triangle and mesh shape ([`SceneMesh`]).
#[derive(Default)]
pub(super) struct Geometry {
    pub(super) prims: Vec<PlacedShape>,
    pub(super) attrs: Vec<TriAttr>,
    pub(super) meshes: Vec<SceneMesh>,
}

impl Geometry {
    /// Adds one primitive.
    pub(super) fn push(
        &mut self,
        shape: Placed,
        material: u32,
        emitter: Option<u32>,
        shape_index: Option<u32>,
    ) {
        self.prims.push(PlacedShape {
            shape,
            material,
            emitter,
            shape_index,
        });
    }
}

/// Adds `shapes[k]` (`s`), its material looked up in `material_index`.
pub(super) fn shape(
    cx: &mut Ctx,
    k: usize,
    s: &ShapeSpec,
    material_index: &HashMap<String, u32>,
    geo: &mut Geometry,
) -> Result<()> {
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
    let index = k as u32;
    let shapes = match s {
        ShapeSpec::Quad {
            origin,
            edge_u,
            edge_v,
            displacement,
            ..
        } => vec![quad_shape(
            cx,
            [*origin, *edge_u, *edge_v],
            displacement,
            &what,
        )?],
        ShapeSpec::Sphere { center, radius, .. } => vec![sphere(cx, *center, *radius, &what)?],
        ShapeSpec::Box {
            min, max, rotate_y, ..
        } => box_shapes(cx, *min, *max, *rotate_y, &what)?,
        ShapeSpec::Triangle {
            vertices,
            uvs,
            displacement,
            ..
        } => {
            let placed = triangles::lone(cx, vertices, uvs, displacement, &what)?;
            return triangles::add(cx, placed, &what, material, index, geo);
        }
        ShapeSpec::Mesh {
            path,
            translate,
            scale,
            rotate_y,
            displacement,
            crease_angle,
            ..
        } => {
            let placement = triangles::Placement {
                translate: *translate,
                scale: *scale,
                rotate_y: *rotate_y,
            };
            let placed = triangles::mesh(cx, path, placement, *crease_angle, displacement, &what)?;
            return triangles::add(cx, placed, &what, material, index, geo);
        }
    };
    for shape in shapes {
        geo.push(shape, material, None, Some(index));
    }
    Ok(())
}

/// A parallelogram from its corner and edges, refused where they span no
/// area.
pub(super) fn quad(cx: &Ctx, origin: V3, edge_u: V3, edge_v: V3, what: &str) -> Result<Quad> {
    let o = cx.vec(origin, &format!("{what}.origin"))?;
    let u = cx.vec(edge_u, &format!("{what}.edge_u"))?;
    let v = cx.vec(edge_v, &format!("{what}.edge_v"))?;
    Quad::new(o, u, v)
        .ok_or_else(|| cx.err(format!("{what}: edge_u and edge_v are parallel or zero")))
}

/// A quad, displaced when its displacement has depth.
fn quad_shape(
    cx: &mut Ctx,
    [origin, edge_u, edge_v]: [V3; 3],
    displacement: &Option<DisplacementSpec>,
    what: &str,
) -> Result<Placed> {
    let q = quad(cx, origin, edge_u, edge_v, what)?;
    Ok(match displacement_of(cx, displacement, what)? {
        None => Placed::Quad(q),
        Some(d) => Placed::Displaced(Box::new(displaced_quad(cx, &q, d, what)?)),
    })
}

/// The prism over a displaced quad, its map repeated `tiles` times along
/// its edges and run back along `edge_v` with `flip_v`.
fn displaced_quad(
    cx: &mut Ctx,
    q: &Quad,
    d: &DisplacementSpec,
    what: &str,
) -> Result<FlatDisplacement> {
    let tiles = Vec2::from_array(d.tiles);
    let tile = Vec2::new(q.edge_u.length(), q.edge_v.length()) / tiles.max(Vec2::splat(1e-30));
    let b = DispBuild::new(cx, d, tile, what)?;
    b.check_trace(cx, &b.trace, what)?;
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
    let face = FlatDisplacement::new(frame, b.map.clone(), b.trace, None, Vec2::ZERO);
    b.finish(face, cx, what)
}

/// A sphere of positive radius.
fn sphere(cx: &Ctx, center: V3, radius: f32, what: &str) -> Result<Placed> {
    let center = cx.vec(center, &format!("{what}.center"))?;
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(cx.err(format!("{what}.radius must be positive, got {radius}")));
    }
    if radius > MAX_COORDINATE {
        return Err(cx.err(format!(
            "{what}.radius = {radius:e}: at most {MAX_COORDINATE:e} (its square must fit in single precision)"
        )));
    }
    Ok(Placed::Sphere(Sphere { center, radius }))
}

/// The six quads of a box turned `rotate_y` degrees about its vertical
/// centre line.
fn box_shapes(cx: &Ctx, min: V3, max: V3, rotate_y: f32, what: &str) -> Result<Vec<Placed>> {
    let lo = cx.vec(min, &format!("{what}.min"))?;
    let hi = cx.vec(max, &format!("{what}.max"))?;
    if !(hi.cmpgt(lo).all()) || !rotate_y.is_finite() {
        return Err(cx.err(format!(
            "{what}: max must exceed min on every axis and rotate_y be finite"
        )));
    }
    Ok(box_faces(lo, hi, rotate_y)
        .into_iter()
        .map(Placed::Quad)
        .collect())
}
