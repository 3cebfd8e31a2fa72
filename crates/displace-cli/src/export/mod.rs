//! `displace export-mesh`: the displaced height field as a triangle grid, so
//! that triangle ray tracers (Mitsuba 3, Embree) can render the surface we
//! sphere trace (BENCHMARKS.md).
//!
//! **Which grid.** Vertices sit on the texel-centre grid of the height map
//! refined `--scale` times (`(i + 0.5) / n`, `displace_core::convention`'s texel centres),
//! plus a row and a column at each border (`u, v = 0` and `1`), each at the
//! height of our continuous bilinear surface there. At scale 1 every vertex
//! is a texel value, so the mesh is the height map at its own resolution;
//! each quad of it is split into two triangles, the only difference from the
//! bilinear patch we trace. Higher scales sample the bilinear surface more
//! finely and converge to it. Normals are our shading normals (the
//! central-difference normal map, sampled bilinearly), so shading matches.
//!
//! **Frame.** That of `displace trace`: `x = u SX`, `y = v SY`, `z = h SZ`,
//! with `(u, v)` the texture coordinate written as `vt`. A quad with
//! `origin = [0,0,0]`, `edge_u = [SX,0,0]`, `edge_v = [0,SY,0]` and
//! `depth = SZ` in a scene file is the same surface.
//!
//! **A scene's displaced meshes** (`--scene`): each displaced mesh of the
//! scene (built-in or OBJ, placed in the world as the scene places it) as
//! its displaced surface `P + depth h(uv) N` tessellated finely
//! ([`displace_render::faces::displaced_surface`]), one OBJ object (or all in one
//! PLY) per mesh: the surface pbrt-v4 or Cycles draw when they subdivide
//! the mesh and move its vertices along the interpolated normals, and the
//! ground truth of curved displaced meshes.

mod format;
mod surface;

use crate::args::{load_height, FaceArgs, HeightArgs};
use crate::outputs::check_not_inputs;
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::{Extent, HeightMap, NormalMap};
use format::{least_bytes, mesh_file, MeshFile};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Most vertices written (an OBJ of that many is several GB already).
const MAX_VERTICES: u64 = 1 << 26;

/// Texels of a generated height map when `--height-size` is not given:
/// there is no distance map here to take the size from.
const DEFAULT_HEIGHT_SIZE: [usize; 2] = [256, 256];

// The shared height options' help speaks of the distance map that `bake`
// and `trace` build; this command builds none, so it says what it does.
#[derive(Args, Debug)]
#[command(
    mut_arg("height_size", |a| a.help("Texels of a generated height map (`gen:...`), WxH [default: 256x256]")),
    mut_arg("address", |a| a.help("Texture addressing of the height map (clamp or repeat)")),
)]
pub struct ExportMeshArgs {
    /// Height map: gen:NAME[?...], a PNG, JPEG, TIFF or EXR file
    #[arg(value_name = "HEIGHT", required_unless_present = "scene")]
    pub height: Option<String>,
    #[command(flatten)]
    pub face: FaceArgs,
    /// Vertices per height texel along each axis (1: the height map's own
    /// resolution; 4: sixteen times the triangles, sampled bilinearly)
    #[arg(long, default_value_t = 1)]
    pub scale: u32,
    /// Instead of one height field: every displaced mesh of this scene
    /// file, its displaced surface tessellated (vertices moved along the
    /// interpolated normals)
    #[arg(long, value_name = "SCENE.toml", conflicts_with_all = ["height", "extent"])]
    pub scene: Option<PathBuf>,
    /// With --scene: the longest sub-edge, in height texels (a quarter
    /// texel samples the bilinear surface finely enough to be its ground
    /// truth) [default: 0.25]
    #[arg(long, value_name = "TEXELS")]
    pub edge_texels: Option<f32>,
    /// Output mesh: .obj (text) or .ply (binary little-endian)
    #[arg(short, long, value_name = "MESH")]
    pub output: PathBuf,
}

/// The grid's vertex coordinates along one axis of `n` height texels.
fn axis(n: usize, scale: usize) -> Vec<f32> {
    let m = n * scale;
    std::iter::once(0.0)
        .chain((0..m).map(|i| (i as f32 + 0.5) / m as f32))
        .chain(std::iter::once(1.0))
        .collect()
}

/// A vertex grid `us x vs` over the face, row-major in `v`.
/// The mesh of a height map: its vertices at the grid `us x vs` of
/// texture coordinates, sampled from the heights and their normals, in a
/// tile of `extent`.
struct Grid<'a> {
    us: Vec<f32>,
    vs: Vec<f32>,
    height: &'a HeightMap,
    normals: &'a NormalMap,
    extent: Extent,
}

impl Grid<'_> {
    fn vertices(&self) -> usize {
        self.us.len() * self.vs.len()
    }
    fn triangles(&self) -> usize {
        2 * (self.us.len() - 1) * (self.vs.len() - 1)
    }
    /// Every vertex as (position, normal, uv), row by row.
    fn each_vertex(&self) -> impl Iterator<Item = ([f32; 3], [f32; 3], [f32; 2])> + '_ {
        let (height, normals, extent) = (self.height, self.normals, self.extent);
        self.vs.iter().flat_map(move |&v| {
            self.us.iter().map(move |&u| {
                let h = height.sample(u, v);
                let n = normals.sample(u, v);
                (
                    [u * extent.sx, v * extent.sy, h * extent.sz],
                    n.to_array(),
                    [u, v],
                )
            })
        })
    }
    /// Two counter-clockwise (seen from +z) triangles per grid cell,
    /// 0-based vertex indices.
    fn each_triangle(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        let nu = self.us.len() as u32;
        (0..self.vs.len() as u32 - 1).flat_map(move |j| {
            (0..nu - 1).flat_map(move |i| {
                let a = j * nu + i;
                let (b, c, d) = (a + 1, a + nu, a + nu + 1);
                [[a, b, d], [a, d, c]]
            })
        })
    }
}

pub fn run(args: ExportMeshArgs) -> Result<()> {
    // Installed before any file is created (see `write_interruptible`).
    crate::progress::cancel_flag();
    let kind = mesh_file(&args.output)?;
    if let Some(scene) = &args.scene {
        check_not_inputs(&[("-o", &args.output)], &[("--scene", scene)])?;
        if args.scale != 1 {
            bail!("--scale sets the height-field grid; with --scene the sub-edges are set by --edge-texels");
        }
        let edge = args
            .edge_texels
            .unwrap_or(displace_render::faces::displaced_surface::REFERENCE_EDGE_TEXELS);
        return surface::run(scene, edge, kind, &args.output);
    }
    if args.edge_texels.is_some() {
        bail!("--edge-texels sets the sub-edges of a --scene's meshes; a height field's grid is set by --scale");
    }
    let (Some(source), Some(extent)) = (args.height.clone(), args.face.extent) else {
        bail!("give a HEIGHT map and its --extent, or a --scene");
    };
    if args.scale == 0 {
        bail!("--scale must be at least 1");
    }
    check_not_inputs(
        &[("-o", &args.output)],
        &[("height map", Path::new(&source))],
    )?;
    let [w, h] = check_memory(&source, &args.face.height)?;
    let scale = args.scale as u64;
    // Checked: a large --scale times a long side overflows 64 bits.
    let side = |n: usize| (n as u64).checked_mul(scale).and_then(|m| m.checked_add(2));
    let sides = side(w).zip(side(h));
    let count = sides.and_then(|(nu, nv)| nu.checked_mul(nv));
    let (nu, nv) = match (sides, count) {
        (Some(sides), Some(count)) if count <= MAX_VERTICES => sides,
        _ => bail!(
            "{w}x{h} texels at --scale {} is {} vertices; at most {MAX_VERTICES} are written",
            args.scale,
            count.map_or("more than 2^64".to_string(), |c| c.to_string())
        ),
    };
    displace_core::io::atomic::check_free_space(&args.output, least_bytes(kind, nu, nv))?;
    let height = load_height(&source, &args.face.height, DEFAULT_HEIGHT_SIZE)?;
    let normals = NormalMap::from_height(&height, extent)?;
    let grid = Grid {
        us: axis(height.width(), args.scale as usize),
        vs: axis(height.height(), args.scale as usize),
        height: &height,
        normals: &normals,
        extent,
    };
    let write = |w: &mut dyn Write| match kind {
        MeshFile::Obj => write_obj(w, &grid),
        MeshFile::Ply => write_ply(w, &grid),
    };
    crate::progress::write_interruptible(&args.output, write)?;
    println!(
        "{} ({}x{} texels) at scale {}: {} vertices, {} triangles -> {}",
        source,
        height.width(),
        height.height(),
        args.scale,
        grid.vertices(),
        grid.triangles(),
        args.output.display()
    );
    Ok(())
}

/// Bytes the command holds at its peak per height texel: the heights
/// (`f32`) and the normal map built from them (`Vec3`); the mesh itself is
/// streamed to the file, vertex by vertex.
const BYTES_PER_TEXEL: u128 = 4 + 12;

/// Refuses a height map whose heights and normals would not fit in memory
/// ([`displace_core::memory`]), from the file's header alone, before
/// anything is decoded; the map's size.
fn check_memory(source: &str, a: &HeightArgs) -> Result<[usize; 2]> {
    let size = match &a.height_size {
        Some(s) => displace_core::convention::parse_size::<2>(s)
            .with_context(|| format!("--height-size {s}"))?,
        None => DEFAULT_HEIGHT_SIZE,
    };
    let opts = a.options(size);
    let [w, h] = displace_core::io::height::dimensions(source, &opts)
        .with_context(|| format!("loading height map `{source}`"))?;
    displace_core::memory::check(
        &format!("export-mesh of a {w}x{h} height map"),
        w as u128 * h as u128 * BYTES_PER_TEXEL,
    )?;
    Ok([w, h])
}

fn write_obj(w: &mut dyn Write, g: &Grid) -> std::io::Result<()> {
    writeln!(
        w,
        "# displace export-mesh: {} vertices, {} triangles",
        g.vertices(),
        g.triangles()
    )?;
    // Three passes rather than a copy of every vertex in memory.
    for (p, _, _) in g.each_vertex() {
        writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
    }
    for (_, _, t) in g.each_vertex() {
        writeln!(w, "vt {} {}", t[0], t[1])?;
    }
    for (_, nn, _) in g.each_vertex() {
        writeln!(w, "vn {} {} {}", nn[0], nn[1], nn[2])?;
    }
    for [a, b, c] in g.each_triangle() {
        let (a, b, c) = (a + 1, b + 1, c + 1);
        writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?;
    }
    Ok(())
}

fn write_ply(w: &mut dyn Write, g: &Grid) -> std::io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment displace export-mesh\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float u\nproperty float v\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        g.vertices(),
        g.triangles()
    )?;
    for (p, nn, t) in g.each_vertex() {
        for c in p.into_iter().chain(nn).chain(t) {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    for tri in g.each_triangle() {
        w.write_all(&[3])?;
        for i in tri {
            w.write_all(&(i as i32).to_le_bytes())?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_core::Address;

    /// Scale 1 puts a vertex on every texel centre with the texel's value,
    /// and the border rows repeat the clamped edge values.
    #[test]
    fn scale_one_vertices_are_the_texels() {
        let data: Vec<f32> = (0..6).map(|k| k as f32 / 8.0).collect();
        let h = HeightMap::new(3, 2, data.clone(), Address::Clamp).unwrap();
        let e = Extent::new(2.0, 1.0, 0.5).unwrap();
        let n = NormalMap::from_height(&h, e).unwrap();
        let g = Grid {
            us: axis(3, 1),
            vs: axis(2, 1),
            height: &h,
            normals: &n,
            extent: e,
        };
        assert_eq!((g.vertices(), g.triangles()), (5 * 4, 2 * 4 * 3));
        let verts: Vec<_> = g.each_vertex().collect();
        for j in 0..2 {
            for i in 0..3 {
                let (p, _, uv) = verts[(j + 1) * 5 + i + 1];
                assert_eq!(uv, [(i as f32 + 0.5) / 3.0, (j as f32 + 0.5) / 2.0]);
                assert!((p[2] - data[j * 3 + i] * 0.5).abs() < 1e-6);
            }
        }
        assert_eq!(verts[0].0[2], verts[6].0[2]);
        assert!(g
            .each_triangle()
            .flatten()
            .all(|i| (i as usize) < g.vertices()));
    }

    /// The free-space bound is a lower bound on what is written, exact for
    /// a PLY's body, close for an OBJ, on maps of many sizes and scales.
    #[test]
    fn the_least_bytes_bound_what_is_written() {
        for (w, hgt, scale) in [(2, 2, 1), (3, 5, 2), (17, 9, 3), (40, 31, 1), (64, 64, 2)] {
            let data: Vec<f32> = (0..w * hgt).map(|k| (k % 7) as f32 / 7.0).collect();
            let h = HeightMap::new(w, hgt, data, Address::Clamp).unwrap();
            let e = Extent::new(1.0, 1.0, 0.1).unwrap();
            let n = NormalMap::from_height(&h, e).unwrap();
            let g = Grid {
                us: axis(w, scale),
                vs: axis(hgt, scale),
                height: &h,
                normals: &n,
                extent: e,
            };
            let (nu, nv) = ((w * scale + 2) as u64, (hgt * scale + 2) as u64);
            let (mut ply, mut obj) = (Vec::new(), Vec::new());
            write_ply(&mut ply, &g).unwrap();
            write_obj(&mut obj, &g).unwrap();
            let header = ply.windows(11).position(|b| b == b"end_header\n").unwrap() + 11;
            assert_eq!(
                (ply.len() - header) as u64,
                least_bytes(MeshFile::Ply, nu, nv)
            );
            let least = least_bytes(MeshFile::Obj, nu, nv);
            assert!(least <= obj.len() as u64, "{w}x{hgt}x{scale}");
            assert!(
                least * 3 >= obj.len() as u64,
                "{w}x{hgt}x{scale}: {least} of {}",
                obj.len()
            );
        }
    }
}
