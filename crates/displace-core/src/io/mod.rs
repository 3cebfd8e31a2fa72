//! File formats: how height maps come in and how baked maps go out so that
//! other tools (engines, numpy, our own `displace trace`) can use them.
//!
//! Every writer goes through [`atomic::write_atomic`], so a failed or
//! interrupted run never leaves a half-written file behind. Every reader
//! checks sizes against [`crate::convention::MAX_ALLOCATION_BYTES`] from the
//! header, before allocating for the payload.
//!
//! | format | module   | carries                                              |
//! |--------|----------|------------------------------------------------------|
//! | npy    | [`npy`]  | float32 arrays of any shape (physical units)         |
//! | KTX2   | [`ktx2`] | distance map + extent, addressing, encoding, bound   |
//! | DDS    | [`dds`]  | distance map voxels only (extent given by the user)  |
//! | PNG/JPEG/TIFF/EXR| [`height`] | height maps in                           |
//! | PNG    | [`png`]  | normal maps, 16-bit heights and RGB images out       |
//! | TIFF data rasters | `data_tiff` | elevation models in (float, signed samples) |

pub mod atomic;
mod data_tiff;
pub mod dds;
pub mod direct;
pub mod height;
pub mod ktx2;
pub mod npy;
pub mod png;
pub mod stream;

use crate::convention::MAX_ALLOCATION_BYTES;
use crate::distance_map::Format;
use crate::{Address, DistanceMap, Error, Extent, Result};
use std::path::{Path, PathBuf};

/// A malformed file, found by a byte-level reader. Path-level functions turn
/// it into [`Error::Format`] naming the file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The file does not start with the format's identifier (named here).
    #[error("not a {0} file (bad magic bytes)")]
    BadMagic(&'static str),
    /// The file ends before its header or payload says it should.
    #[error("truncated: {0}")]
    Truncated(String),
    /// Well formed, but using a feature this reader does not accept (another
    /// pixel format or dtype, supercompression, column-major order, ...).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// A header or value that breaks the format's specification, or
    /// KTX2 `displace.*` key/value data that does not parse.
    #[error("invalid: {0}")]
    Invalid(String),
    /// A core error (a size refused, an I/O failure) met while decoding.
    #[error(transparent)]
    Core(#[from] Error),
}

impl FormatError {
    /// Names the file the bytes came from.
    pub fn at(self, path: &Path) -> Error {
        match self {
            FormatError::Core(e @ (Error::Format { .. } | Error::Io { .. })) => e,
            other => Error::Format {
                path: path.to_path_buf(),
                message: other.to_string(),
            },
        }
    }
}

/// Largest scene file (TOML) read: scenes are hand-written text, and the
/// biggest seed scene is a few KiB.
pub const MAX_SCENE_FILE_BYTES: u64 = 16 << 20;

/// Largest mesh file (OBJ) read: about the text of
/// `displace_render::mesh::MAX_TRIANGLES` triangles.
pub const MAX_MESH_FILE_BYTES: u64 = 4 << 30;

/// Largest image file (PNG, EXR: height maps and textures) read. Their
/// decoded size is checked separately, from the header, before decoding.
pub const MAX_IMAGE_FILE_BYTES: u64 = 2 << 30;

/// Largest array or map file (npy, KTX2, DDS) read: the largest allocation
/// plus room for a header.
pub const MAX_ARRAY_FILE_BYTES: u64 = (MAX_ALLOCATION_BYTES as u64) + (1 << 20);

/// Checks that `path` is a regular file of at most `limit` bytes before
/// anything reads it: a directory, a FIFO or a device such as `/dev/zero`
/// would otherwise be read until memory runs out (or forever), and an
/// oversized file would be read whole before any format check. `what` names
/// the input in the message ("scene file", "mesh"). Returns the file's size.
pub fn check_input(path: &Path, what: &str, limit: u64) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let refuse = |message: String| Error::Input {
        path: path.to_path_buf(),
        message,
    };
    let kind = meta.file_type();
    if !kind.is_file() {
        use std::os::unix::fs::FileTypeExt;
        let is = if kind.is_dir() {
            "a directory"
        } else if kind.is_fifo() {
            "a FIFO (named pipe)"
        } else if kind.is_char_device() || kind.is_block_device() {
            "a device"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        };
        return Err(refuse(format!(
            "{what} is {is}; only regular files are read"
        )));
    }
    if meta.len() > limit {
        return Err(refuse(format!(
            "{what} is {} bytes, more than the limit of {limit} bytes",
            meta.len()
        )));
    }
    Ok(meta.len())
}

/// Reads a whole array or map file, naming it on failure, after
/// [`check_input`] with [`MAX_ARRAY_FILE_BYTES`].
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    check_input(path, "the file", MAX_ARRAY_FILE_BYTES)?;
    std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The distance-map file types, chosen by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapFile {
    /// Khronos KTX 2.0 (`.ktx2`): one 3D level, with the extent, addressing
    /// and underestimate bound as key/value data.
    Ktx2,
    /// DirectDraw Surface (`.dds`) with the DX10 header: a volume texture.
    Dds,
    /// NumPy `.npy`: a C-order `(D, H, W)` float32 array in physical units,
    /// with no metadata; for Python tools.
    Npy,
}

impl MapFile {
    /// From the extension of `path` (`.ktx2`, `.dds`, `.npy`, any case).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("ktx2") => Ok(MapFile::Ktx2),
            Some("dds") => Ok(MapFile::Dds),
            Some("npy") => Ok(MapFile::Npy),
            _ => Err(Error::Format {
                path: path.to_path_buf(),
                message: "unknown distance-map file type (expected .ktx2, .dds or .npy)".into(),
            }),
        }
    }
}

/// Writes `map` (one tile of `extent`) to `path` in the file type its
/// extension names. `format` applies to KTX2 and DDS; npy is always float32
/// in the physical units of `extent` (the layout Python tools read,
/// `numpy.load`), so asking for another format there is refused rather than ignored.
pub fn write_distance_map(
    path: &Path,
    map: &DistanceMap,
    extent: Extent,
    format: Format,
) -> Result<()> {
    match MapFile::from_path(path)? {
        MapFile::Ktx2 => ktx2::write(path, map, extent, format),
        MapFile::Dds => dds::write(path, map, format),
        MapFile::Npy => {
            if format != Format::R32F {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "npy stores float32 in physical units; format {} applies only to .ktx2 and .dds",
                        format.name()
                    ),
                });
            }
            npy::write_distance_map(path, map, extent)
        }
    }
}

/// Reads a distance map written by [`write_distance_map`]. KTX2 files carry
/// their extent and addressing (and must agree with `extent` and `address`
/// up to scale); DDS and npy files take them from the caller.
pub fn read_distance_map(path: &Path, extent: Extent, address: Address) -> Result<DistanceMap> {
    match MapFile::from_path(path)? {
        MapFile::Ktx2 => {
            let (map, stored) = ktx2::read_distance_map(path)?;
            check_same_proportions(path, stored, extent)?;
            if map.address() != address {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "the map was baked with {} addressing but {} was asked for",
                        map.address().name(),
                        address.name()
                    ),
                });
            }
            Ok(map)
        }
        MapFile::Dds => dds::read(path, extent, address),
        MapFile::Npy => npy::read_distance_map(path, extent, address),
    }
}

/// A map is valid for one aspect (the metric of [`crate::convention`]): using it for another
/// would make its distances wrong, and unsafe.
fn check_same_proportions(path: &Path, stored: Extent, wanted: Extent) -> Result<()> {
    let (a, b) = (stored.aspect(), wanted.aspect());
    let close = |x: f32, y: f32| (x - y).abs() <= 1e-4 * x.abs().max(y.abs());
    if close(a[0], b[0]) && close(a[1], b[1]) {
        Ok(())
    } else {
        Err(Error::Format {
            path: PathBuf::from(path),
            message: format!(
                "the map was baked for extent {},{},{} (aspect {:?}) but extent {},{},{} (aspect {:?}) was given; \
                 distances are only valid for the proportions they were baked for",
                stored.sx, stored.sy, stored.sz, a, wanted.sx, wanted.sy, wanted.sz, b
            ),
        })
    }
}

/// The bound on `true distance - stored value` that [`crate::bake`](fn@crate::bake) proves
/// for a map of `size` voxels over a tile of `aspect` (the two margins of
/// [`crate::distance_map`]'s proof: the column radius `|(hx, hy)| / 2` and the
/// trilinear half diagonal `|(hx, hy, hz)| / 2`, each counted on both sides),
/// plus `quantum` for rounding down to a storage format. Used for files that
/// carry no bound of their own (DDS, npy).
pub fn bake_underestimate(size: [usize; 3], aspect: [f32; 2], quantum: f32) -> f32 {
    let h = glam::Vec3::new(
        aspect[0] / size[0] as f32,
        aspect[1] / size[1] as f32,
        1.0 / size[2] as f32,
    );
    h.truncate().length() + h.length() + quantum
}

/// Refuses decoded voxels of a map of `size` that hold NaN, naming the
/// first by its `(x, y, z)`: no reader hands a NaN distance to a tracer.
pub(crate) fn check_no_nan(data: &[f32], size: [usize; 3]) -> Result<(), FormatError> {
    match data.iter().position(|v| v.is_nan()) {
        None => Ok(()),
        Some(i) => Err(FormatError::Invalid(format!(
            "voxel ({}, {}, {}) is NaN",
            i % size[0],
            (i / size[0]) % size[1],
            i / (size[0] * size[1])
        ))),
    }
}

/// Refuses decoded voxels (shell depths) of a map of `size` over a tile of
/// `aspect` that no conservative distance map of a height field can hold:
/// with them every ray would miss, or stop where it starts. Two invariants
/// hold for every bake, whatever its format's rounding (always down):
///
/// 1. a voxel of the lowest slice lies `z_0 = 0.5 / d` above the floor and
///    no height goes below the floor, so its value is at most `z_0` (a map
///    in other units, or an R8 range whose low end is above zero, breaks
///    this first);
/// 2. no point of the tile's box is farther from the surface than the
///    box's diagonal, `sqrt(ax^2 + ay^2 + 1)` shell depths.
pub(crate) fn check_plausible(
    data: &[f32],
    size: [usize; 3],
    aspect: [f32; 2],
) -> Result<(), FormatError> {
    let [w, h, d] = size;
    let at = |i: usize| (i % w, (i / w) % h, i / (w * h));
    let z0 = crate::convention::texel_centre(0, d);
    // Single-precision rounding of values near z_0, and of the diagonal.
    let slack = 1e-4;
    if let Some(i) = data[..(w * h).min(data.len())]
        .iter()
        .position(|&v| v > z0 + slack)
    {
        let (x, y, _) = at(i);
        return Err(FormatError::Invalid(format!(
            "voxel ({x}, {y}, 0) holds {} shell depths, but the lowest slice's voxels lie {z0} \
             above the floor, which no height goes below: not a conservative distance map of \
             a height field (values in other units? a range that starts above zero?)",
            data[i]
        )));
    }
    let [ax, ay] = aspect;
    let diagonal = (ax * ax + ay * ay + 1.0).sqrt();
    if let Some(i) = data
        .iter()
        .position(|&v| v > diagonal * (1.0 + slack) + slack)
    {
        let (x, y, z) = at(i);
        return Err(FormatError::Invalid(format!(
            "voxel ({x}, {y}, {z}) holds {} shell depths, farther than any point of the tile \
             is from its surface (the box's diagonal, {diagonal}): not a conservative distance \
             map of this extent",
            data[i]
        )));
    }
    Ok(())
}

/// Asserts that the reader `err` (bytes to its error message) refuses
/// `bytes` with a message holding every one of `needles`: the malformed
/// file tests of each format.
#[cfg(test)]
pub(crate) fn assert_refused(err: &dyn Fn(&[u8]) -> String, bytes: &[u8], needles: &[&str]) {
    let message = err(bytes);
    for needle in needles {
        assert!(message.contains(needle), "no `{needle}` in: {message}");
    }
}

#[cfg(test)]
mod plausible_tests {
    use super::*;
    use crate::{bake, generators, Address, BakeOptions, Extent};

    /// Every bake is plausible, and the maps no bake makes are not: every
    /// voxel 1e30, values raised by an R8 range whose low end is above zero,
    /// a value past the tile's diagonal; the readers refuse them (npy, end
    /// to end).
    #[test]
    fn implausible_maps_are_refused_and_bakes_are_not() {
        let extent = Extent::new(1.0, 0.5, 0.125).unwrap();
        for (name, address) in [
            ("gen:studded", Address::Clamp),
            ("gen:noise", Address::Repeat),
        ] {
            let height = generators::generate(name, 20, 12, address).unwrap();
            let map = bake(&height, &BakeOptions::new([10, 6, 4], extent))
                .unwrap()
                .distance;
            check_plausible(map.data(), map.size(), map.aspect()).unwrap();
        }
        let size = [10, 6, 4];
        let aspect = extent.aspect();
        let e = check_plausible(&vec![1e30; 240], size, aspect)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("voxel (0, 0, 0)") && e.contains("lowest slice"),
            "{e}"
        );
        // A range starting at 0.2 lifts every value by at least that much.
        let height = generators::generate("gen:gaussian", 20, 12, Address::Clamp).unwrap();
        let map = bake(&height, &BakeOptions::new(size, extent))
            .unwrap()
            .distance;
        let lifted: Vec<f32> = map.data().iter().map(|v| v.max(0.0) + 0.2).collect();
        let e = check_plausible(&lifted, size, aspect)
            .unwrap_err()
            .to_string();
        assert!(e.contains("range that starts above zero"), "{e}");
        // Far values above the lowest slice: past the box's diagonal.
        let mut far = map.data().to_vec();
        far[3 * 60 + 7] = 50.0;
        let e = check_plausible(&far, size, aspect).unwrap_err().to_string();
        assert!(
            e.contains("voxel (7, 0, 3)") && e.contains("diagonal"),
            "{e}"
        );
        // End to end: an npy volume of 1e30 is refused by its reader, named.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("far.npy");
        npy::write_file(&p, &[4, 6, 10], &vec![1e30f32; 240]).unwrap();
        let e = npy::read_distance_map(&p, extent, Address::Clamp)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("far.npy") && e.contains("not a conservative distance map"),
            "{e}"
        );
    }
}
