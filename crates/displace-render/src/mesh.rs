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
    let (models, _materials) = tobj::load_obj(path, &opts).map_err(|e| {
        let located = std::fs::read_to_string(path)
            .ok()
            .and_then(|text| locate(&text, &e));
        match located {
            Some((line, column)) => Error::Parse {
                path: path.to_path_buf(),
                line,
                column,
                message: e.to_string(),
            },
            None => Error::Mesh {
                path: path.to_path_buf(),
                message: e.to_string(),
            },
        }
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

/// Where in an OBJ file `err` comes from: the 1-based line and column of the
/// first statement of the kind tobj complains about that does not read
/// (tobj reports no position). `None` for errors not tied to a statement.
fn locate(text: &str, err: &tobj::LoadError) -> Option<(usize, usize)> {
    use tobj::LoadError as E;
    let keyword = match err {
        E::PositionParseError | E::ScalingByZeroError => "v",
        E::NormalParseError => "vn",
        E::TexcoordParseError => "vt",
        E::FaceParseError
        | E::InvalidPolygon
        | E::FaceVertexOutOfBounds
        | E::FaceTexCoordOutOfBounds
        | E::FaceNormalOutOfBounds => "f",
        _ => return None,
    };
    // Counts of v, vt, vn so far: what a face may index.
    let mut counts = [0usize; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(head) = words.next() else { continue };
        let column = |w: &str| w.as_ptr() as usize - line.as_ptr() as usize + 1;
        let numbers = |need: usize| -> Option<usize> {
            let args: Vec<&str> = line.split_whitespace().skip(1).collect();
            match args.iter().find(|w| w.parse::<f32>().is_err()) {
                Some(bad) => Some(column(bad)),
                None if args.len() < need => Some(line.len() + 1),
                None => None,
            }
        };
        let bad = match head {
            "v" | "vt" | "vn" => {
                let (k, need) = match head {
                    "v" => (0, 3),
                    "vt" => (1, 1),
                    _ => (2, 3),
                };
                counts[k] += 1;
                if head != keyword {
                    continue;
                }
                numbers(need)
            }
            "f" if keyword == "f" => {
                let corners: Vec<&str> = words.collect();
                let bad_corner = corners.iter().find(|c| {
                    c.split('/').enumerate().any(|(k, part)| {
                        !part.is_empty()
                            && part
                                .parse::<i64>()
                                .map_or(true, |i| i == 0 || i.unsigned_abs() as usize > counts[k])
                    }) || c.split('/').next().is_none_or(str::is_empty)
                });
                match bad_corner {
                    Some(c) => Some(column(c)),
                    None if corners.len() < 3 => Some(line.len() + 1),
                    None => None,
                }
            }
            _ => None,
        };
        if let Some(col) = bad {
            return Some((n + 1, col));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_statements_are_located() {
        let text = "# q\nv 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n";
        assert_eq!(
            locate(text, &tobj::LoadError::PositionParseError),
            Some((3, 7))
        );
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\nf 1 2 9\n";
        assert_eq!(
            locate(text, &tobj::LoadError::FaceVertexOutOfBounds),
            Some((6, 7))
        );
        let text = "v 0 0 0\nv 1 0 0\nf 1 2\n";
        assert_eq!(locate(text, &tobj::LoadError::InvalidPolygon), Some((3, 6)));
        assert_eq!(locate(text, &tobj::LoadError::ReadError), None);
    }

    #[test]
    fn a_malformed_file_names_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.obj");
        std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("bad.obj:3:"), "{e}");
        let e = load(&dir.path().join("none.obj")).unwrap_err().to_string();
        assert!(e.contains("none.obj") && e.contains("not found"), "{e}");
    }
}
