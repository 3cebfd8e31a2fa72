//! Triangle meshes from Wavefront OBJ files (via `tobj`).

use crate::error::{Error, Result};
use glam::{Vec2, Vec3};
use std::path::Path;

/// Triangles above this count are refused before building anything.
pub const MAX_TRIANGLES: usize = 1 << 26;

#[derive(Clone, Copy, Debug)]
pub struct MeshTriangle {
    pub positions: [Vec3; 3],
    pub normals: Option<[Vec3; 3]>,
    /// `(0, 0)` everywhere when the file has none.
    pub uvs: [Vec2; 3],
}

#[derive(Clone, Debug)]
pub struct Mesh {
    pub triangles: Vec<MeshTriangle>,
    pub has_uvs: bool,
}

pub fn load(path: &Path) -> Result<Mesh> {
    if !path.exists() {
        return Err(Error::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "mesh file not found"),
        });
    }
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..tobj::LoadOptions::default()
    };
    let (models, _materials) = tobj::load_obj(path, &opts).map_err(|e| Error::Mesh {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    if total > MAX_TRIANGLES {
        return Err(Error::Mesh {
            path: path.to_path_buf(),
            message: format!("{total} triangles is more than the limit of {MAX_TRIANGLES}"),
        });
    }
    let mut triangles = Vec::with_capacity(total);
    let mut has_uvs = !models.is_empty();
    for m in &models {
        let mesh = &m.mesh;
        let nv = mesh.positions.len() / 3;
        let v3 = |a: &[f32], i: usize| Vec3::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
        let with_normals = mesh.normals.len() == mesh.positions.len();
        let with_uvs = mesh.texcoords.len() / 2 == nv;
        has_uvs &= with_uvs;
        for (f, idx) in mesh.indices.chunks_exact(3).enumerate() {
            let idx = [idx[0] as usize, idx[1] as usize, idx[2] as usize];
            if idx.iter().any(|&i| i >= nv) {
                return Err(Error::Mesh {
                    path: path.to_path_buf(),
                    message: format!("model `{}` face {f} indexes a missing vertex", m.name),
                });
            }
            let positions = idx.map(|i| v3(&mesh.positions, i));
            if positions.iter().any(|p| !p.is_finite()) {
                return Err(Error::Mesh {
                    path: path.to_path_buf(),
                    message: format!("model `{}` face {f} has a non-finite vertex", m.name),
                });
            }
            triangles.push(MeshTriangle {
                positions,
                normals: with_normals.then(|| idx.map(|i| v3(&mesh.normals, i))),
                uvs: if with_uvs {
                    idx.map(|i| Vec2::new(mesh.texcoords[2 * i], mesh.texcoords[2 * i + 1]))
                } else {
                    [Vec2::ZERO; 3]
                },
            });
        }
    }
    Ok(Mesh { triangles, has_uvs })
}
