//! `displace export-mesh --scene`: every displaced mesh of a scene as its
//! displaced surface, tessellated ([`displace_render::faces::displaced_surface`]),
//! for triangle ray tracers (Embree, Mitsuba 3) and as the ground truth of
//! curved displaced meshes. Each mesh is in the world as the scene places
//! it; its texture coordinates are those the height map is read at (the
//! mesh's own times the displacement's `tiles`).

use super::format::MeshFile;
use anyhow::{bail, Context, Result};
use displace_render::faces::displaced_surface::DisplacedSurface;
use displace_render::{Scene, SceneOptions};
use std::io::Write;
use std::path::Path;

/// Writes the displaced surfaces of `scene`'s displaced meshes, with
/// sub-edges of at most `edge_texels` height texels, to `output`.
pub fn run(scene: &Path, edge_texels: f32, kind: MeshFile, output: &Path) -> Result<()> {
    let opts = SceneOptions {
        cache_dir: displace_render::default_cache_dir(),
        cancel: Some(crate::progress::cancel_flag()),
        no_image: true,
        ..SceneOptions::default()
    };
    let loaded = crate::progress::loaded(Scene::load(scene, &opts))?;
    let written = [("-o".to_string(), output.to_path_buf())];
    crate::outputs::check_not_scene_inputs(&written, loaded.sources(), None)?;
    let surfaces = loaded
        .meshes()
        .iter()
        .enumerate()
        .filter_map(|(k, m)| m.displacement.as_ref().map(|d| (k, m, d)))
        .map(|(k, m, d)| {
            DisplacedSurface::new(&m.triangles, &d.map.height, d.depth, edge_texels)
                .with_context(|| format!("{}: displaced mesh {k}", scene.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    if surfaces.is_empty() {
        bail!(
            "{}: the scene has no displaced mesh (export a height field with HEIGHT --extent)",
            scene.display()
        );
    }
    let vertices: u64 = surfaces.iter().map(DisplacedSurface::vertex_count).sum();
    let triangles: u64 = surfaces.iter().map(DisplacedSurface::triangle_count).sum();
    if kind == MeshFile::Ply && vertices > i32::MAX as u64 {
        bail!("{vertices} vertices do not fit a PLY's 32-bit indices; write fewer (--edge-texels)");
    }
    let write = |w: &mut dyn Write| match kind {
        MeshFile::Obj => write_obj(w, &surfaces),
        MeshFile::Ply => write_ply(w, &surfaces, vertices, triangles),
    };
    crate::progress::write_interruptible(output, write)?;
    let cuts: Vec<String> = surfaces
        .iter()
        .map(|s| s.subdivisions().to_string())
        .collect();
    println!(
        "{} displaced meshes of {} (each triangle cut {} times along its edges): {vertices} \
         vertices, {triangles} triangles -> {}",
        surfaces.len(),
        scene.display(),
        cuts.join(", "),
        output.display()
    );
    Ok(())
}

/// One OBJ object per mesh; `vt` the texture coordinate each vertex was
/// lifted at, written beside its `v` (OBJ counts the two apart, so the
/// surface is generated once, not once per kind of line).
fn write_obj(w: &mut dyn Write, surfaces: &[DisplacedSurface]) -> std::io::Result<()> {
    writeln!(w, "# displace export-mesh --scene: displaced surfaces")?;
    let mut base = 1u64;
    for (k, s) in surfaces.iter().enumerate() {
        writeln!(w, "o displaced_mesh_{k}")?;
        for p in s.each_vertex() {
            let [x, y, z] = p.position.to_array();
            writeln!(w, "v {x} {y} {z}\nvt {} {}", p.uv.x, p.uv.y)?;
        }
        for t in s.each_triangle() {
            let [a, b, c] = t.map(|i| i + base);
            writeln!(w, "f {a}/{a} {b}/{b} {c}/{c}")?;
        }
        base += s.vertex_count();
    }
    Ok(())
}

/// Every mesh in one binary PLY: `x y z u v` per vertex.
fn write_ply(
    w: &mut dyn Write,
    surfaces: &[DisplacedSurface],
    vertices: u64,
    triangles: u64,
) -> std::io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment displace export-mesh --scene\n\
         element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n\
         property float u\nproperty float v\n\
         element face {triangles}\nproperty list uchar int vertex_indices\nend_header\n"
    )?;
    for s in surfaces {
        for p in s.each_vertex() {
            for c in p.position.to_array().into_iter().chain(p.uv.to_array()) {
                w.write_all(&c.to_le_bytes())?;
            }
        }
    }
    let mut base = 0u64;
    for s in surfaces {
        for t in s.each_triangle() {
            w.write_all(&[3])?;
            for i in t {
                w.write_all(&((i + base) as i32).to_le_bytes())?;
            }
        }
        base += s.vertex_count();
    }
    Ok(())
}
