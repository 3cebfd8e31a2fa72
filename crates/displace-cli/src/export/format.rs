//! The mesh files `displace export-mesh` writes: which one an output name
//! asks for, and the least it can take on disk (checked against the free
//! space before any work).

use crate::outputs::check_output_dir;
use anyhow::{bail, Result};

/// A mesh file format.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(crate) enum MeshFile {
    /// Wavefront OBJ: text, with `vt` and `vn`.
    Obj,
    /// Binary little-endian PLY.
    Ply,
}

/// The mesh file `output` names, refused before any work when it is
/// neither, or its directory is missing.
pub(crate) fn mesh_file(output: &std::path::Path) -> Result<MeshFile> {
    let kind = match output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("obj") => MeshFile::Obj,
        Some("ply") => MeshFile::Ply,
        _ => bail!("output {}: write a .obj or a .ply mesh", output.display()),
    };
    check_output_dir(output)?;
    Ok(kind)
}

/// The fewest bytes a mesh of `nu x nv` vertices takes in `kind`: a PLY
/// exactly (its header aside: 32 bytes a vertex, 13 a triangle); an OBJ at
/// least its shortest lines (`v 0 0 0`, `vt 0 0`, `vn 0 0 0`, and faces
/// whose indices have at least the digits of a tenth of the count, as nine
/// in ten do). A lower bound, so that a refusal is sure: the free space is
/// checked against it before the map is loaded.
pub(crate) fn least_bytes(kind: MeshFile, nu: u64, nv: u64) -> u64 {
    let vertices = nu * nv;
    let triangles = 2 * (nu - 1) * (nv - 1);
    match kind {
        MeshFile::Ply => vertices * 32 + triangles * 13,
        MeshFile::Obj => {
            let digits = (vertices / 10).max(1).ilog10() as u64 + 1;
            // `f a/a/a b/b/b c/c/c`: three triples of three indices.
            let face = 2 + 3 * (3 * digits + 3);
            vertices * (8 + 7 + 9) + triangles / 10 * 9 * face
        }
    }
}
