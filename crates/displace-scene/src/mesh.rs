//! Triangle meshes from Wavefront OBJ files (via `tobj`).

use crate::error::{Error, Result};
use displace_core::Error as CoreError;
use glam::{Vec2, Vec3};
use std::path::Path;

/// Triangles above this count are refused before building anything.
pub const MAX_TRIANGLES: usize = 1 << 26;

/// One triangle of an OBJ mesh, in the file's coordinates.
#[derive(Clone, Copy, Debug)]
pub struct MeshTriangle {
    /// Corner positions.
    pub positions: [Vec3; 3],
    /// Vertex normals, when the file has them; a scene gives a file
    /// without them smooth ones ([`crate::vertex_normals`]), and a
    /// degenerate triangle has none (its flat normal is used).
    pub normals: Option<[Vec3; 3]>,
    /// `(0, 0)` everywhere when the file has none.
    pub uvs: [Vec2; 3],
}

/// The triangles of an OBJ file, every object and group together.
#[derive(Clone, Debug)]
pub struct Mesh {
    /// The triangles.
    pub triangles: Vec<MeshTriangle>,
    /// Whether the file gives texture coordinates (a displaced mesh needs them).
    pub has_uvs: bool,
}

/// Reads an OBJ file, refusing files that are not regular, too large, have
/// indices out of range or more than [`MAX_TRIANGLES`] triangles; errors
/// name the line and column where `tobj` says.
pub fn load(path: &Path) -> Result<Mesh> {
    displace_core::io::check_input(path, "mesh", displace_core::io::MAX_MESH_FILE_BYTES)?;
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..tobj::LoadOptions::default()
    };
    check_face_indices(path)?;
    let file = std::fs::File::open(path).map_err(|e| CoreError::io(path, e))?;
    // Material libraries (`mtllib`) are not read: materials come from the
    // scene, and a library path is one more file (a FIFO, `/dev/zero`)
    // that could be read for ever.
    let no_materials = |_: &Path| Err(tobj::LoadError::OpenFileFailed);
    let mut reader = std::io::BufReader::new(file);
    skip_byte_order_mark(&mut reader).map_err(|e| CoreError::io(path, e))?;
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &opts, no_materials).map_err(|e| {
            let bytes = std::fs::read(path).unwrap_or_default();
            let text = match std::str::from_utf8(&bytes) {
                Ok(text) => text,
                Err(bad) => {
                    // The parser reads lines as UTF-8 and says only "read
                    // error" at the first byte that is not: name it.
                    let good = std::str::from_utf8(&bytes[..bad.valid_up_to()]).unwrap_or_default();
                    let (line, column) = crate::error::line_column(good, good.len());
                    return Error::Parse {
                        path: path.to_path_buf(),
                        line,
                        column,
                        message: format!(
                            "byte 0x{:02X} is not UTF-8 text (an OBJ file is text; save it as UTF-8 or ASCII)",
                            bytes[bad.valid_up_to()]
                        ),
                    };
                }
            };
            let located = locate(text, &e);
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
    if total == 0 {
        // An empty or face-less file would render as nothing, silently.
        return Err(Error::Mesh {
            path: path.to_path_buf(),
            message: "the file has no faces (`f` lines): nothing to render".into(),
        });
    }
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
            let normals = with_normals.then(|| idx.map(|i| v3(&mesh.normals, i)));
            let uvs = if with_uvs {
                idx.map(|i| Vec2::new(mesh.texcoords[2 * i], mesh.texcoords[2 * i + 1]))
            } else {
                [Vec2::ZERO; 3]
            };
            // A NaN normal or coordinate would pass through every later
            // step as a shell or a texel that silently matches nothing.
            let bad = if normals.is_some_and(|n| n.iter().any(|v| !v.is_finite())) {
                Some("normal (vn)")
            } else if uvs.iter().any(|uv| !uv.is_finite()) {
                Some("texture coordinate (vt)")
            } else {
                None
            };
            if let Some(what) = bad {
                return Err(Error::Mesh {
                    path: path.to_path_buf(),
                    message: format!("model `{}` face {f} has a non-finite {what}", m.name),
                });
            }
            triangles.push(MeshTriangle {
                positions,
                normals,
                uvs,
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
                match bad_corner(&corners, &counts) {
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

/// The first corner of a face (the words after `f`) that does not parse or
/// indexes past the `v`, `vt` and `vn` statements before it (`counts`),
/// relative indices counting back from those.
fn bad_corner<'a>(corners: &[&'a str], counts: &[usize; 3]) -> Option<&'a str> {
    corners.iter().copied().find(|c| {
        c.split('/').enumerate().any(|(k, part)| {
            !part.is_empty()
                && part
                    .parse::<i64>()
                    // A corner has at most v/vt/vn: a fourth part is bad.
                    .map_or(true, |i| {
                        i == 0 || counts.get(k).is_none_or(|&n| i.unsigned_abs() as usize > n)
                    })
        }) || c.split('/').next().is_none_or(str::is_empty)
    })
}

/// Refuses, with its line and column, a finite coordinate past
/// [`crate::build::MAX_COORDINATE`], and a face corner
/// that indexes outside
/// the vertices, texture coordinates or normals declared before it, before
/// `tobj` reads the file: `tobj` multiplies such an index unchecked (a `vt`
/// of 2^63 overflows in its `add_vertex`; found by tests/fuzz.rs). Streams
/// the file, holding one line at a time.
fn check_face_indices(path: &Path) -> Result<()> {
    use std::io::BufRead;
    let io_err = |e| Error::from(CoreError::io(path, e));
    let file = std::fs::File::open(path).map_err(io_err)?;
    let mut counts = [0usize; 3];
    let mut reader = std::io::BufReader::new(file);
    skip_byte_order_mark(&mut reader).map_err(io_err)?;
    for (n, line) in reader.split(b'\n').enumerate() {
        let line = line.map_err(io_err)?;
        // Not UTF-8: tobj refuses the file itself.
        let Ok(line) = std::str::from_utf8(&line) else {
            continue;
        };
        let mut words = line.split_whitespace();
        let head = words.next();
        if let Some("v" | "vt" | "vn") = head {
            // A finite value past what single precision measures (1e30)
            // would otherwise be blamed later on collinear vertices or a
            // zero extent (NaN and infinities are named as non-finite
            // where the file is read).
            let far = words.clone().find(|w| {
                w.parse::<f32>()
                    .is_ok_and(|x| x.is_finite() && x.abs() > crate::build::MAX_COORDINATE)
            });
            if let Some(w) = far {
                return Err(Error::Parse {
                    path: path.to_path_buf(),
                    line: n + 1,
                    column: w.as_ptr() as usize - line.as_ptr() as usize + 1,
                    message: format!(
                        "`{w}` is out of range: coordinates are at most {:e} in size (their squared lengths must fit in single precision)",
                        crate::build::MAX_COORDINATE
                    ),
                });
            }
        }
        match head {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f" | "l") => {
                let corners: Vec<&str> = words.collect();
                if let Some(c) = bad_corner(&corners, &counts) {
                    return Err(Error::Parse {
                        path: path.to_path_buf(),
                        line: n + 1,
                        column: c.as_ptr() as usize - line.as_ptr() as usize + 1,
                        message: format!(
                            "face corner `{c}` indexes a vertex, texture coordinate or normal that does not exist"
                        ),
                    });
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Steps over a UTF-8 byte-order mark at the start of `reader`, which
/// editors on Windows write: `tobj` would read `\u{feff}v ...` as an unknown
/// statement and drop the first vertex, shifting every index after it.
fn skip_byte_order_mark(reader: &mut impl std::io::BufRead) -> std::io::Result<()> {
    const BOM: &[u8] = b"\xEF\xBB\xBF";
    if reader.fill_buf()?.starts_with(BOM) {
        reader.consume(BOM.len());
    }
    Ok(())
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
        // Found by tests/fuzz.rs: a corner of five parts indexed past v/vt/vn.
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1/2/1 2 3\n";
        assert_eq!(locate(text, &tobj::LoadError::FaceParseError), Some((6, 3)));
        let text = "v 0 0 0\nv 1 0 0\nf 1 2\n";
        assert_eq!(locate(text, &tobj::LoadError::InvalidPolygon), Some((3, 6)));
        assert_eq!(locate(text, &tobj::LoadError::ReadError), None);
    }

    #[test]
    fn huge_face_indices_are_refused_before_tobj_reads_them() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.obj");
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/9223372036854775807 3/1\n";
        std::fs::write(&path, text).unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("big.obj:5:7:"), "{e}");
        // A material library is never opened.
        std::fs::write(
            &path,
            "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        )
        .unwrap();
        assert_eq!(load(&path).unwrap().triangles.len(), 1);
    }

    #[test]
    fn non_finite_vertices_normals_and_coordinates_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let quad = |v: &str, vt: &str, vn: &str| {
            format!(
                "v {v}\nv 1 0 0\nv 0 1 0\nvt {vt}\nvt 1 0\nvt 0 1\nvn {vn}\nvn 0 0 1\nvn 0 0 1\nf 1/1/1 2/2/2 3/3/3\n"
            )
        };
        for (name, text, what) in [
            ("v.obj", quad("nan 0 0", "0 0", "0 0 1"), "vertex"),
            ("vn.obj", quad("0 0 0", "0 0", "nan 0 1"), "normal (vn)"),
            (
                "vt.obj",
                quad("0 0 0", "inf 0", "0 0 1"),
                "texture coordinate (vt)",
            ),
        ] {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            let e = load(&path).unwrap_err().to_string();
            assert!(
                e.contains(&format!("non-finite {what}")) && e.contains(name),
                "{e}"
            );
        }
        let ok = dir.path().join("ok.obj");
        std::fs::write(&ok, quad("0 0 0", "0 0", "0 0 1")).unwrap();
        assert_eq!(load(&ok).unwrap().triangles.len(), 1);
    }

    #[test]
    fn a_mesh_without_faces_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        for (name, text) in [("empty.obj", ""), ("points.obj", "v 0 0 0\nv 1 0 0\n")] {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            let e = load(&path).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("no faces"), "{e}");
        }
    }

    #[test]
    fn a_malformed_file_names_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.obj");
        std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("bad.obj:3:"), "{e}");
        let e = load(&dir.path().join("none.obj")).unwrap_err().to_string();
        assert!(e.contains("none.obj") && e.contains("No such file"), "{e}");
        // A byte that is not UTF-8 (a Latin-1 comment), named where it is.
        let latin1 = dir.path().join("latin1.obj");
        std::fs::write(&latin1, b"v 0 0 0\n# caf\xe9\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let e = load(&latin1).unwrap_err().to_string();
        assert!(e.contains("latin1.obj:2:6") && e.contains("0xE9"), "{e}");
    }

    /// A file that starts with a UTF-8 byte-order mark reads as the same
    /// file without it: its first vertex kept, its indices unshifted.
    #[test]
    fn a_byte_order_mark_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n";
        let (plain, marked) = (dir.path().join("plain.obj"), dir.path().join("bom.obj"));
        std::fs::write(&plain, text).unwrap();
        std::fs::write(
            &marked,
            [b"\xEF\xBB\xBF".as_slice(), text.as_bytes()].concat(),
        )
        .unwrap();
        let (a, b) = (load(&plain).unwrap(), load(&marked).unwrap());
        let corners =
            |m: &Mesh| -> Vec<[Vec3; 3]> { m.triangles.iter().map(|t| t.positions).collect() };
        assert_eq!(corners(&a), corners(&b));
        assert_eq!(corners(&b)[0], [Vec3::ZERO, Vec3::X, Vec3::Y]);
        // The index check reads past the mark too: `f 1 2 4` with four
        // vertices is in range.
        std::fs::write(
            &marked,
            "\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 4\n",
        )
        .unwrap();
        assert_eq!(load(&marked).unwrap().triangles.len(), 1);
    }

    /// Coordinates past what single precision measures are named at their
    /// line and column (they were blamed on collinear vertices, or on a
    /// zero width), and coordinates at the bound load.
    #[test]
    fn coordinates_out_of_range_are_named_where_they_are() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.obj");
        for (text, line, column, word) in [
            ("v 0 0 0\nv 1e30 0 0\nv 0 1 0\nf 1 2 3\n", 2, 3, "1e30"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 1e30\nf 1 2 3\n",
                4,
                6,
                "1e30",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 -2e20\nf 1 2 3\n",
                4,
                8,
                "-2e20",
            ),
            ("v 0 0 0\nv 1 0 0\nv 0 -3e38 0\nf 1 2 3\n", 3, 5, "-3e38"),
        ] {
            std::fs::write(&p, text).unwrap();
            let e = load(&p).unwrap_err().to_string();
            assert!(e.contains(&format!("m.obj:{line}:{column}")), "{e}");
            assert!(e.contains(&format!("`{word}` is out of range")), "{e}");
        }
        std::fs::write(&p, "v 0 0 0\nv 1e18 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(load(&p).unwrap().triangles.len(), 1);
    }
}
