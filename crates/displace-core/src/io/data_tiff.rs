//! TIFF rasters of measured heights: one sample a texel, stored as floats
//! or as signed or 32-bit integers, the way digital elevation models are
//! written (a GDAL GeoTIFF of `Float32` metres, an SRTM tile of `Int16`).
//! The `image` crate decodes 8- and 16-bit unsigned samples only; these
//! are read with the `tiff` crate it decodes with.
//!
//! Their values are measurements in the file's own units, not codes of a
//! full scale, so they are kept as stored and the caller maps them to the
//! shell's `[0, 1]` ([`super::height::HeightRange`]). A texel holding the
//! file's no-data value (GDAL's `GDAL_NODATA` tag) or a non-finite value is
//! refused, named, rather than baked as a pit or a spike.

use crate::{Error, Result};
use std::io::BufReader;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::{SampleFormat, Tag};
use tiff::ColorType;

/// How a TIFF's samples are stored, from its header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Layout {
    /// Stored width and height (before any orientation).
    pub stored: [usize; 2],
    /// The colour type as the file declares it.
    pub color: ColorType,
    /// Whether the samples are unsigned, signed or floating point.
    pub format: SampleFormat,
    /// The orientation tag (1: as stored).
    pub orientation: u8,
}

impl Layout {
    /// Whether the `image` crate decodes this file: unsigned samples of 8
    /// or 16 bits (grey, grey and alpha, RGB, RGBA); everything else is a
    /// data raster read here.
    pub fn is_image(&self) -> bool {
        self.format == SampleFormat::Uint && matches!(self.color.bit_depth(), 8 | 16)
    }

    /// The size as the orientation shows it.
    pub fn shown(&self) -> [usize; 2] {
        let [w, h] = self.stored;
        if (5..=8).contains(&self.orientation) {
            [h, w]
        } else {
            [w, h]
        }
    }
}

fn err(path: &Path, what: impl std::fmt::Display) -> Error {
    Error::Image {
        path: path.to_path_buf(),
        message: what.to_string(),
    }
}

fn open(path: &Path) -> Result<Decoder<BufReader<std::fs::File>>> {
    let file = std::fs::File::open(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // The map's size is checked against this crate's limits
    // (`HeightMap::check_size`, the caller's memory estimate) instead.
    Decoder::new(BufReader::new(file))
        .map(|d| d.with_limits(Limits::unlimited()))
        .map_err(|e| err(path, format!("cannot read TIFF: {e}")))
}

fn layout_of(path: &Path, d: &mut Decoder<BufReader<std::fs::File>>) -> Result<Layout> {
    let bad = |e: tiff::TiffError| err(path, format!("cannot read TIFF: {e}"));
    let (w, h) = d.dimensions().map_err(bad)?;
    let color = d.colortype().map_err(bad)?;
    let format = d
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(bad)?
        .and_then(|v| v.first().copied())
        .map_or(SampleFormat::Uint, SampleFormat::from_u16_exhaustive);
    let orientation = d
        .find_tag_unsigned::<u8>(Tag::Orientation)
        .ok()
        .flatten()
        .filter(|o| (1..=8).contains(o))
        .unwrap_or(1);
    Ok(Layout {
        stored: [w as usize, h as usize],
        color,
        format,
        orientation,
    })
}

/// The layout of a checked TIFF file, from its header alone.
pub(super) fn layout(path: &Path) -> Result<Layout> {
    super::check_input(path, "height map", super::MAX_IMAGE_FILE_BYTES)?;
    if std::fs::metadata(path).is_ok_and(|m| m.len() == 0) {
        return Err(err(path, "the file is empty"));
    }
    layout_of(path, &mut open(path)?)
}

/// The values of a data TIFF (not [`Layout::is_image`]) as stored, one per
/// texel, row-major as its orientation shows them, and the shown size.
/// `check_size` is called with the shown size before anything is decoded.
pub(super) fn read(
    path: &Path,
    check_size: impl FnOnce([usize; 2]) -> Result<()>,
) -> Result<(Vec<f32>, [usize; 2])> {
    let mut d = open(path)?;
    let layout = layout_of(path, &mut d)?;
    let samples = match layout.color {
        ColorType::Gray(_) => 1,
        ColorType::Multiband { num_samples, .. } => num_samples,
        other => {
            return Err(err(
                path,
                format!(
                    "a {other:?} TIFF of {:?} samples: heights are read from one band",
                    layout.format
                ),
            ))
        }
    };
    if samples != 1 {
        return Err(err(
            path,
            format!(
                "has {samples} bands of {:?} samples: heights are read from one band \
                 (extract it first, e.g. gdal_translate -b 1)",
                layout.format
            ),
        ));
    }
    check_size(layout.shown())?;
    let nodata = d
        .find_tag(Tag::GdalNodata)
        .ok()
        .flatten()
        .and_then(|v| v.into_string().ok())
        .and_then(|s| s.trim().trim_end_matches('\0').parse::<f64>().ok());
    let image = d
        .read_image()
        .map_err(|e| err(path, format!("cannot decode TIFF: {e}")))?;
    let values = to_f32(path, image)?;
    let [w, h] = layout.stored;
    if values.len() != w * h {
        return Err(err(
            path,
            format!("decoded {} samples for {w}x{h} texels", values.len()),
        ));
    }
    if let Some(k) = values
        .iter()
        .position(|v| !v.is_finite() || nodata.is_some_and(|n| f64::from(*v) == n))
    {
        let (i, j) = (k % w, k / w);
        return Err(err(
            path,
            if values[k].is_finite() {
                format!(
                    "stored texel ({i}, {j}) holds the file's no-data value {} (GDAL_NODATA): \
                     fill the holes first (e.g. gdal_fillnodata.py)",
                    values[k]
                )
            } else {
                format!(
                    "stored texel ({i}, {j}) is {}: heights must be finite",
                    values[k]
                )
            },
        ));
    }
    Ok(orient(values, layout))
}

/// One `f32` per sample; 64-bit samples are refused (they would need
/// twice the memory the estimate allows for decoding).
fn to_f32(path: &Path, image: DecodingResult) -> Result<Vec<f32>> {
    use rayon::prelude::*;
    fn each<T: Copy + Send + Sync>(v: Vec<T>, f: impl Fn(T) -> f32 + Sync + Send) -> Vec<f32> {
        v.par_iter().map(|&x| f(x)).collect()
    }
    Ok(match image {
        DecodingResult::F32(v) => v,
        DecodingResult::F16(v) => each(v, f32::from),
        DecodingResult::I8(v) => each(v, f32::from),
        DecodingResult::I16(v) => each(v, f32::from),
        DecodingResult::I32(v) => each(v, |x| x as f32),
        DecodingResult::U32(v) => each(v, |x| x as f32),
        DecodingResult::U8(v) => each(v, f32::from),
        DecodingResult::U16(v) => each(v, f32::from),
        _ => {
            return Err(err(
                path,
                "has 64-bit samples: convert the heights to 32-bit float first \
                 (e.g. gdal_translate -ot Float32)",
            ))
        }
    })
}

/// The stored raster turned as its orientation tag asks (TIFF 6.0's
/// Orientation, the same eight cases as EXIF's).
fn orient(values: Vec<f32>, layout: Layout) -> (Vec<f32>, [usize; 2]) {
    let [w, h] = layout.stored;
    let shown = layout.shown();
    if layout.orientation == 1 {
        return (values, shown);
    }
    let [sw, sh] = shown;
    let mut out = vec![0.0f32; w * h];
    for y in 0..sh {
        for x in 0..sw {
            // The stored texel shown at (x, y).
            let (i, j) = match layout.orientation {
                2 => (w - 1 - x, y),
                3 => (w - 1 - x, h - 1 - y),
                4 => (x, h - 1 - y),
                5 => (y, x),
                6 => (y, h - 1 - x),
                7 => (w - 1 - y, h - 1 - x),
                8 => (w - 1 - y, x),
                _ => (x, y),
            };
            out[y * sw + x] = values[j * w + i];
        }
    }
    (out, shown)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(orientation: u8) -> Layout {
        Layout {
            stored: [3, 2],
            color: ColorType::Gray(32),
            format: SampleFormat::IEEEFP,
            orientation,
        }
    }

    /// The eight orientations against their definitions (TIFF 6.0, tag
    /// 274): where the stored first row and column are shown.
    #[test]
    fn orientations_show_the_stored_raster_as_tagged() {
        // Stored: 0 1 2 / 3 4 5.
        let stored: Vec<f32> = (0..6).map(|v| v as f32).collect();
        let cases: [(u8, [usize; 2], [f32; 6]); 8] = [
            (1, [3, 2], [0., 1., 2., 3., 4., 5.]),
            (2, [3, 2], [2., 1., 0., 5., 4., 3.]),
            (3, [3, 2], [5., 4., 3., 2., 1., 0.]),
            (4, [3, 2], [3., 4., 5., 0., 1., 2.]),
            (5, [2, 3], [0., 3., 1., 4., 2., 5.]),
            (6, [2, 3], [3., 0., 4., 1., 5., 2.]),
            (7, [2, 3], [5., 2., 4., 1., 3., 0.]),
            (8, [2, 3], [2., 5., 1., 4., 0., 3.]),
        ];
        for (o, size, want) in cases {
            let (got, shown) = orient(stored.clone(), layout(o));
            assert_eq!(shown, size, "orientation {o}");
            assert_eq!(got, want, "orientation {o}");
        }
    }
}
