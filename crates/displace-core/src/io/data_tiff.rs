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
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Layout {
    /// Stored width and height (before any orientation).
    pub stored: [usize; 2],
    /// The colour type as the file declares it.
    pub color: ColorType,
    /// Whether the samples are unsigned, signed or floating point.
    pub format: SampleFormat,
    /// The orientation tag (1: as stored).
    pub orientation: u8,
    /// GDAL's no-data value (`GDAL_NODATA`), where the file names one.
    pub nodata: Option<f64>,
}

impl Layout {
    /// Whether the `image` crate decodes this file: unsigned samples of at
    /// most 16 bits (grey, grey and alpha, RGB, RGBA, palette, 1-bit
    /// masks); everything else is a data raster read here, and so is a
    /// one-band 8- or 16-bit elevation model that names a no-data value,
    /// so that its holes are found.
    pub fn is_image(&self) -> bool {
        let bits = self.color.bit_depth();
        let model = matches!(self.color, ColorType::Gray(8 | 16)) && self.nodata.is_some();
        self.format == SampleFormat::Uint && bits <= 16 && !model
    }

    /// The full scale of unsigned 8- and 16-bit samples (whose codes are
    /// normalised as an image's are), else `None` (values as stored).
    pub fn full_scale(&self) -> Option<f32> {
        match (self.format, self.color.bit_depth()) {
            (SampleFormat::Uint, 8) => Some(255.0),
            (SampleFormat::Uint, 16) => Some(65535.0),
            _ => None,
        }
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

/// The decoder of `path`, its first directory read within the `tiff`
/// crate's default limits (a tag's values at most 1 MiB): a hostile header
/// cannot make it allocate what it claims.
type TiffDecoder = Decoder<BufReader<std::fs::File>>;

fn open(path: &Path) -> Result<TiffDecoder> {
    let file = std::fs::File::open(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Decoder::new(BufReader::new(file))
        .map_err(|e| Error::image(path, format!("cannot read TIFF: {e}")))
}

fn layout_of(path: &Path, d: &mut TiffDecoder) -> Result<Layout> {
    let bad = |e: tiff::TiffError| Error::image(path, format!("cannot read TIFF: {e}"));
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
    let nodata = d
        .find_tag(Tag::GdalNodata)
        .ok()
        .flatten()
        .and_then(|v| v.into_string().ok())
        .and_then(|s| s.trim().trim_end_matches('\0').trim().parse::<f64>().ok());
    Ok(Layout {
        stored: [w as usize, h as usize],
        color,
        format,
        orientation,
        nodata,
    })
}

/// A checked TIFF file opened, its header read: its layout, and the
/// decoder that [`read`] goes on with (so that a data raster's file is
/// opened and its directory parsed once).
pub(super) struct Probe {
    /// How its samples are stored.
    pub layout: Layout,
    decoder: TiffDecoder,
}

/// The header of a checked TIFF file.
pub(super) fn probe(path: &Path) -> Result<Probe> {
    super::check_input(path, "height map", super::MAX_IMAGE_FILE_BYTES)?;
    if std::fs::metadata(path).is_ok_and(|m| m.len() == 0) {
        return Err(Error::image(path, "the file is empty"));
    }
    let mut decoder = open(path)?;
    let layout = layout_of(path, &mut decoder)?;
    Ok(Probe { layout, decoder })
}

/// The refusal of samples wider than 32 bits, which would need twice the
/// memory the estimate allows for decoding.
fn too_wide(path: &Path, bits: u8) -> Error {
    Error::image(
        path,
        format!(
            "has {bits}-bit samples: convert the heights to 32-bit float first \
             (e.g. gdal_translate -ot Float32)"
        ),
    )
}

/// The values of a probed data TIFF (not [`Layout::is_image`]) as stored,
/// one per texel, row-major as its orientation shows them
/// ([`Layout::shown`]). `check_size` is called with the shown size before
/// anything is decoded, and the decoder may then allocate the samples of
/// that size and no more.
pub(super) fn read(
    path: &Path,
    probe: Probe,
    check_size: impl FnOnce([usize; 2]) -> Result<()>,
) -> Result<Vec<f32>> {
    let Probe { layout, decoder } = probe;
    let samples = match layout.color {
        ColorType::Gray(_) => 1,
        ColorType::Multiband { num_samples, .. } => num_samples,
        other => {
            return Err(Error::image(
                path,
                format!(
                    "a {other:?} TIFF of {:?} samples: heights are read from one band",
                    layout.format
                ),
            ))
        }
    };
    if samples != 1 {
        return Err(Error::image(
            path,
            format!(
                "has {samples} bands of {:?} samples: heights are read from one band \
                 (extract it first, e.g. gdal_translate -b 1)",
                layout.format
            ),
        ));
    }
    let bits = layout.color.bit_depth();
    if bits > 32 {
        return Err(too_wide(path, bits));
    }
    if !matches!(bits, 8 | 16 | 32) {
        return Err(Error::image(
            path,
            format!(
                "has {bits}-bit {:?} samples: heights are read from 8, 16 or 32 bits",
                layout.format
            ),
        ));
    }
    check_size(layout.shown())?;
    let [w, h] = layout.stored;
    // The samples, and what a strip or tile is decoded through, within
    // the checked size.
    let bytes = w * h * usize::from(bits / 8);
    // With the values in `f32` and their oriented copy, against the memory
    // limit before the decoder allocates.
    crate::memory::check(
        &format!("decoding {} ({w}x{h} {bits}-bit samples)", path.display()),
        bytes as u128 + (w * h) as u128 * 8,
    )?;
    let mut limits = Limits::default();
    limits.decoding_buffer_size = bytes;
    limits.intermediate_buffer_size = limits.intermediate_buffer_size.max(bytes);
    let mut d = decoder.with_limits(limits);
    let image = d
        .read_image()
        .map_err(|e| Error::image(path, format!("cannot decode TIFF: {e}")))?;
    let (values, nodata_at) = to_f32(path, image, layout.nodata)?;
    if values.len() != w * h {
        return Err(Error::image(
            path,
            format!("decoded {} samples for {w}x{h} texels", values.len()),
        ));
    }
    let bad = nodata_at.or_else(|| values.iter().position(|v| !v.is_finite()));
    if let Some(k) = bad {
        let (i, j) = (k % w, k / w);
        return Err(Error::image(
            path,
            if nodata_at.is_some() {
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

/// One `f32` per sample, and the first sample equal to `nodata`, compared
/// in the sample's own type (an unsigned 32-bit 4294967295 or a float
/// -9999.99 would not survive a round trip through the other).
fn to_f32(
    path: &Path,
    image: DecodingResult,
    nodata: Option<f64>,
) -> Result<(Vec<f32>, Option<usize>)> {
    use rayon::prelude::*;
    fn each<T: Copy + Send + Sync>(
        v: Vec<T>,
        is_nodata: impl Fn(T) -> bool + Sync + Send,
        f: impl Fn(T) -> f32 + Sync + Send,
    ) -> (Vec<f32>, Option<usize>) {
        let at = v.par_iter().position_first(|&x| is_nodata(x));
        (v.par_iter().map(|&x| f(x)).collect(), at)
    }
    // Integers: equal as numbers (every one of them is an exact f64).
    let n = nodata.unwrap_or(f64::NAN);
    let int = move |x: f64| x == n;
    let float = move |x: f32| x == n as f32;
    Ok(match image {
        DecodingResult::F32(v) => {
            let at = v.par_iter().position_first(|&x| float(x));
            (v, at)
        }
        DecodingResult::F16(v) => each(v, |x| float(f32::from(x)), f32::from),
        DecodingResult::I8(v) => each(v, |x| int(f64::from(x)), f32::from),
        DecodingResult::I16(v) => each(v, |x| int(f64::from(x)), f32::from),
        DecodingResult::I32(v) => each(v, |x| int(f64::from(x)), |x| x as f32),
        DecodingResult::U32(v) => each(v, |x| int(f64::from(x)), |x| x as f32),
        DecodingResult::U8(v) => each(v, |x| int(f64::from(x)), f32::from),
        DecodingResult::U16(v) => each(v, |x| int(f64::from(x)), f32::from),
        // 64-bit samples, refused before decoding by `read`.
        _ => return Err(too_wide(path, 64)),
    })
}

/// The stored raster turned as its orientation tag asks (TIFF 6.0's
/// Orientation, the same eight cases as EXIF's).
fn orient(values: Vec<f32>, layout: Layout) -> Vec<f32> {
    let [w, h] = layout.stored;
    if layout.orientation == 1 {
        return values;
    }
    let [sw, sh] = layout.shown();
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
    out
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
            nodata: None,
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
            let got = orient(stored.clone(), layout(o));
            assert_eq!(layout(o).shown(), size, "orientation {o}");
            assert_eq!(got, want, "orientation {o}");
        }
    }
}
