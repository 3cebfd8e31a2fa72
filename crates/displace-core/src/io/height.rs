//! Height maps in, from a *source string*: a generator spec or a PNG,
//! JPEG, TIFF or EXR path (the maps derived from them go out through
//! [`super::png`]).
//!
//! Heights are data, not colour: PNG, JPEG and TIFF values are used as
//! stored (no sRGB decoding), normalised by the bit depth, 16-bit kept at
//! full precision; an image's orientation tag (EXIF, as cameras write
//! photographs) is applied, so the map is the image as it is shown.
//! Colour images reduce to one value by Rec. 709 luma weights on the stored
//! values, unless a channel is chosen. Float heights (EXR, and TIFF
//! rasters of floats or signed or 32-bit integers, as elevation models are
//! stored: `io::data_tiff`) must already lie in `[0, 1]`: the shell
//! depth is given by the extent, not by the data, so an out-of-range map is
//! refused rather than silently rescaled, unless a [`HeightRange`] says
//! which values are the shell's bottom and top.

use crate::{generators, Address, Error, HeightMap, Result};
use std::path::Path;

/// Which channel of a colour image holds the height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Red.
    R,
    /// Green.
    G,
    /// Blue.
    B,
    /// Alpha.
    A,
}

impl std::str::FromStr for Channel {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let name = s.to_ascii_lowercase();
        let choices = [
            ("r", Channel::R),
            ("g", Channel::G),
            ("b", Channel::B),
            ("a", Channel::A),
        ];
        crate::names::parse_choice("channel", &name, &choices).map_err(Error::InvalidHeightMap)
    }
}

impl Channel {
    fn letter(self) -> &'static str {
        match self {
            Channel::R => "R",
            Channel::G => "G",
            Channel::B => "B",
            Channel::A => "A",
        }
    }
}

/// Which of a map's values become the heights `0` and `1` (the bottom and
/// top of the displacement shell, whose depth the extent sets).
///
/// Why: a height map is a fraction of the shell's depth (Donnelly, GPU
/// Gems 2 section 8.3: the surface lies in the unit-depth slab of the
/// distance map), but measured terrain is stored in metres, an elevation
/// model spanning 212.5 to 3406.0; a photograph used as relief may use a
/// fraction of its codes. The range is the one place that maps them, and
/// is explicit, so that no file is rescaled behind the user's back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum HeightRange {
    /// As stored: an 8- or 16-bit image's codes over their full scale
    /// (255 or 65535); float and other data rasters must already lie in
    /// `[0, 1]`.
    #[default]
    AsStored,
    /// The map's own lowest value to 0 and highest to 1 (a flat map is all
    /// 0).
    Auto,
    /// `lo` to 0 and `hi` to 1, in the file's values (an integer image's
    /// codes, a DEM's metres); a value outside is refused.
    Span(f32, f32),
}

impl std::str::FromStr for HeightRange {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        if s.trim().eq_ignore_ascii_case("auto") {
            return Ok(Self::Auto);
        }
        let bad = || {
            Error::InvalidHeightMap(format!(
                "height range `{s}`: expected auto or LO,HI (finite, LO < HI)"
            ))
        };
        let (lo, hi) = s.split_once(',').ok_or_else(bad)?;
        let lo: f32 = lo.trim().parse().map_err(|_| bad())?;
        let hi: f32 = hi.trim().parse().map_err(|_| bad())?;
        Self::span(lo, hi).map_err(|_| bad())
    }
}

impl HeightRange {
    /// `lo` to 0 and `hi` to 1, checked: both finite, `lo < hi`.
    pub fn span(lo: f32, hi: f32) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(Error::InvalidHeightMap(format!(
                "height range [{lo}, {hi}]: expected finite LO < HI"
            )));
        }
        Ok(Self::Span(lo, hi))
    }
}

/// How to turn a source string into a height map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightOptions {
    /// Channel of a colour image; `None`: luminance (or the only channel).
    pub channel: Option<Channel>,
    /// Texels of a generated map (`gen:...`); files have their own size.
    pub size: [usize; 2],
    /// Addressing of the loaded map: whether the surface repeats.
    pub address: Address,
    /// Which values become heights 0 and 1.
    pub range: HeightRange,
}

impl Default for HeightOptions {
    fn default() -> Self {
        Self {
            channel: None,
            size: [256, 256],
            address: Address::Clamp,
            range: HeightRange::AsStored,
        }
    }
}

/// Rec. 709 luma weights.
const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// What [`load`] accepts besides generators and EXR, for messages.
const FORMATS: &str = "expected gen:NAME, a .png, .jpg/.jpeg, .tif/.tiff or .exr file";

/// The raster format of a height-map file with extension `ext` (lower
/// case): integer samples, read by the `image` crate's decoders.
fn raster_format(ext: &str) -> Option<image::ImageFormat> {
    match ext {
        "png" => Some(image::ImageFormat::Png),
        "jpg" | "jpeg" => Some(image::ImageFormat::Jpeg),
        "tif" | "tiff" => Some(image::ImageFormat::Tiff),
        _ => None,
    }
}

/// Loads the height map `source` names: `gen:NAME?params` (a built-in
/// generator at `opts.size`), a `.png`, `.jpg` or `.tif` (8/16-bit grey or
/// colour), a `.tif` data raster (one band of float or signed samples) or
/// an `.exr` (float) file, its values mapped as `opts.range` says.
pub fn load(source: &str, opts: &HeightOptions) -> Result<HeightMap> {
    if source.starts_with("gen:") {
        let map = generators::generate(source, opts.size[0], opts.size[1], opts.address)?;
        return match opts.range {
            HeightRange::AsStored => Ok(map),
            range => {
                let (path, [w, h]) = (Path::new(source), [map.width(), map.height()]);
                let mut data = map.data().to_vec();
                apply_range(path, &mut data, w, range)?;
                finish(path, w, h, data, opts.address)
            }
        };
    }
    let path = Path::new(source);
    let ext = lower_extension(path).unwrap_or_default();
    if ext == "exr" {
        return load_exr(path, opts);
    }
    if matches!(ext.as_str(), "tif" | "tiff") {
        let probe = super::data_tiff::probe(path)?;
        if !probe.layout.is_image() {
            return load_data_tiff(path, probe, opts);
        }
    }
    match raster_format(&ext) {
        Some(format) => load_raster(path, format, opts),
        None => Err(Error::Image {
            path: path.to_path_buf(),
            message: format!("unsupported height map: {FORMATS}"),
        }),
    }
}

/// The texel size [`load`] would give `source`, from a file's header
/// alone (nothing decoded), so a caller can estimate a job's memory before
/// loading: `opts.size` for a generator.
pub fn dimensions(source: &str, opts: &HeightOptions) -> Result<[usize; 2]> {
    if source.starts_with("gen:") {
        return Ok(opts.size);
    }
    let path = Path::new(source);
    let ext = lower_extension(path).unwrap_or_default();
    if ext == "exr" {
        let size = exr_size(path)?;
        return Ok([size.width(), size.height()]);
    }
    if matches!(ext.as_str(), "tif" | "tiff") {
        let layout = super::data_tiff::probe(path)?.layout;
        if !layout.is_image() {
            return Ok(layout.shown());
        }
    }
    match raster_format(&ext) {
        Some(format) => {
            use image::ImageDecoder;
            let (decoder, orientation) = raster_decoder(path, format)?;
            Ok(shown_size(decoder.dimensions(), orientation))
        }
        // `load` names the problem.
        None => load(source, opts).map(|h| [h.width(), h.height()]),
    }
}

/// The decoder of a checked, non-empty raster file of `format`, its header
/// read, and the orientation its metadata asks for (none where it has no
/// such tag or the tag cannot be read: the image as stored).
fn raster_decoder(
    path: &Path,
    format: image::ImageFormat,
) -> Result<(impl image::ImageDecoder, image::metadata::Orientation)> {
    use image::ImageDecoder;
    super::check_input(path, "height map", super::MAX_IMAGE_FILE_BYTES)?;
    let file = std::fs::File::open(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if file.metadata().is_ok_and(|m| m.len() == 0) {
        return Err(Error::image(path, "the file is empty"));
    }
    let name = format_name(format);
    let mut reader = image::ImageReader::with_format(std::io::BufReader::new(file), format);
    // The map's size is checked against this crate's limits
    // (`HeightMap::check_size`, the caller's memory estimate) instead.
    reader.no_limits();
    let mut decoder = reader
        .into_decoder()
        .map_err(|e| Error::image(path, format!("cannot read {name}: {e}")))?;
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    Ok((decoder, orientation))
}

/// The size of an image of stored size `(w, h)` as `orientation` shows it.
fn shown_size((w, h): (u32, u32), orientation: image::metadata::Orientation) -> [usize; 2] {
    use image::metadata::Orientation::*;
    match orientation {
        Rotate90 | Rotate270 | Rotate90FlipH | Rotate270FlipH => [h as usize, w as usize],
        _ => [w as usize, h as usize],
    }
}

fn format_name(format: image::ImageFormat) -> &'static str {
    match format {
        image::ImageFormat::Jpeg => "JPEG",
        image::ImageFormat::Tiff => "TIFF",
        _ => "PNG",
    }
}

/// The size of the first layer of a checked EXR file, from its header.
fn exr_size(path: &Path) -> Result<exr::math::Vec2<usize>> {
    Ok(exr_header(path)?.0)
}

/// The first layer's size, and the bytes a texel of it takes decoded: every
/// channel at its sample type (the decoder holds all of them at once, full
/// size, before one is chosen).
fn exr_header(path: &Path) -> Result<(exr::math::Vec2<usize>, u128, usize)> {
    super::check_input(path, "height map", super::MAX_IMAGE_FILE_BYTES)?;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::image(path, format!("cannot read EXR: {e}")))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| Error::image(path, "EXR file has no layers"))?;
    let channels = &header.channels.list;
    let texel: u128 = channels
        .iter()
        .map(|c| c.sample_type.bytes_per_sample() as u128)
        .sum();
    Ok((header.layer_size, texel, channels.len()))
}

/// The extension of `path` in lower case, which picks its reader.
fn lower_extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Makes the map, naming the file in any complaint about its texels.
fn finish(path: &Path, w: usize, h: usize, data: Vec<f32>, address: Address) -> Result<HeightMap> {
    HeightMap::new(w, h, data, address).map_err(|e| Error::image(path, e))
}

fn load_raster(path: &Path, format: image::ImageFormat, opts: &HeightOptions) -> Result<HeightMap> {
    use image::{DynamicImage, ImageDecoder};
    let name = format_name(format);
    let (decoder, orientation) = raster_decoder(path, format)?;
    let [w, h] = shown_size(decoder.dimensions(), orientation);
    HeightMap::check_size(w, h).map_err(|e| Error::image(path, e))?;
    // The decoded samples (up to 8 bytes a texel: 16-bit RGBA) and the
    // heights made from them, against the memory limit before the decoder
    // allocates: the header's claim is all there is to go on.
    let texels = w as u128 * h as u128;
    crate::memory::check(
        &format!(
            "decoding {} ({w}x{h} texels, {:?})",
            path.display(),
            decoder.color_type()
        ),
        u128::from(decoder.total_bytes()) + texels * crate::memory::HEIGHT_BYTES_PER_TEXEL,
    )?;
    let mut img = DynamicImage::from_decoder(decoder)
        .map_err(|e| Error::image(path, format!("cannot decode {name}: {e}")))?;
    // A camera's photograph is stored as the sensor read it and shown as
    // its orientation tag says; the map is what the user sees.
    img.apply_orientation(orientation);
    debug_assert_eq!([img.width() as usize, img.height() as usize], [w, h]);
    // Straight from the decoded samples to one height per texel, in
    // parallel, with no intermediate copy of every channel in `f32`: an
    // 8192x8192 16-bit map costs its samples plus the heights. Given a
    // range, the codes themselves, which the range then maps.
    let coded = opts.range == HeightRange::AsStored;
    let full = |top: f32| if coded { [top, 1.0] } else { [1.0, top] };
    let (c8, c16) = (full(255.0), full(65535.0));
    let mut data = match img {
        DynamicImage::ImageLuma8(b) => heights(path, &b.into_raw(), 1, true, opts.channel, c8),
        DynamicImage::ImageLumaA8(b) => heights(path, &b.into_raw(), 2, true, opts.channel, c8),
        DynamicImage::ImageRgb8(b) => heights(path, &b.into_raw(), 3, false, opts.channel, c8),
        DynamicImage::ImageRgba8(b) => heights(path, &b.into_raw(), 4, false, opts.channel, c8),
        DynamicImage::ImageLuma16(b) => heights(path, &b.into_raw(), 1, true, opts.channel, c16),
        DynamicImage::ImageLumaA16(b) => heights(path, &b.into_raw(), 2, true, opts.channel, c16),
        DynamicImage::ImageRgb16(b) => heights(path, &b.into_raw(), 3, false, opts.channel, c16),
        DynamicImage::ImageRgba16(b) => heights(path, &b.into_raw(), 4, false, opts.channel, c16),
        other => {
            return Err(Error::image(
                path,
                format!(
                    "unsupported {name} colour type {:?}: heights are read from 8- or 16-bit \
                     integer samples (float heights: an EXR, or a one-band float TIFF)",
                    other.color()
                ),
            ))
        }
    }?;
    if !coded {
        apply_range(path, &mut data, w, opts.range)?;
    }
    finish(path, w, h, data, opts.address)
}

/// The heights of interleaved integer `samples` (`channels` per texel,
/// `grey` when the colour channels are one grey value), divided by `full`
/// (the largest code, or 1 to keep codes) and at most `cap` (1, or the
/// largest code): the chosen channel, or the grey value, or the Rec. 709
/// luma of the colour channels. Each sample is normalised exactly as
/// before (`code as f32 / full`), so the heights are unchanged.
fn heights<T: Copy + Into<f32> + Sync>(
    path: &Path,
    samples: &[T],
    channels: usize,
    grey: bool,
    channel: Option<Channel>,
    [full, cap]: [f32; 2],
) -> Result<Vec<f32>> {
    use rayon::prelude::*;
    let has_alpha = channels == 2 || channels == 4;
    let norm = |c: T| -> f32 { c.into() / full };
    let pick = |c: usize| -> Vec<f32> {
        samples
            .par_chunks_exact(channels)
            .map(|p| norm(p[c]))
            .collect()
    };
    Ok(match (channel, grey) {
        (Some(Channel::A), _) if !has_alpha => {
            return Err(Error::image(path, "has no alpha channel (--channel a)"));
        }
        (Some(Channel::A), _) => pick(channels - 1),
        // Grey: r, g and b are all the grey value.
        (_, true) => pick(0),
        (Some(c), false) => pick(c as usize),
        (None, false) => samples
            .par_chunks_exact(channels)
            .map(|p| (LUMA[0] * norm(p[0]) + LUMA[1] * norm(p[1]) + LUMA[2] * norm(p[2])).min(cap))
            .collect(),
    })
}

fn load_exr(path: &Path, opts: &HeightOptions) -> Result<HeightMap> {
    use exr::prelude::*;
    let (size, texel, channels) = exr_header(path)?;
    HeightMap::check_size(size.width(), size.height()).map_err(|e| crate::Error::image(path, e))?;
    // A header of a few hundred bytes can claim dozens of full-size
    // channels: their decoded bytes (and the heights made from them) are
    // checked against the memory limit before the decoder allocates any.
    let texels = size.width() as u128 * size.height() as u128;
    crate::memory::check(
        &format!(
            "decoding {} ({channels} channels of {}x{} texels)",
            path.display(),
            size.width(),
            size.height()
        ),
        texels * (texel + crate::memory::HEIGHT_BYTES_PER_TEXEL),
    )?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| crate::Error::image(path, format!("cannot decode EXR: {e}")))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    HeightMap::check_size(w, h).map_err(|e| crate::Error::image(path, e))?;
    // The channels as decoded (no `f32` copy of each: a channel is read
    // where it lies, converted sample by sample as `values_as_f32` does).
    let channels: Vec<(String, &FlatSamples)> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), &c.sample_data))
        .collect();
    // Channel names may carry a layer prefix (`height.R`).
    let find = |letter: &str| {
        channels.iter().find(|(n, _)| {
            n.rsplit('.')
                .next()
                .is_some_and(|s| s.eq_ignore_ascii_case(letter))
        })
    };
    let names = || {
        channels
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let used: Vec<(&(String, &FlatSamples), f32)> = match opts.channel {
        Some(c) => {
            let ch = find(c.letter()).ok_or_else(|| {
                crate::Error::image(
                    path,
                    format!("has no {} channel (channels: {})", c.letter(), names()),
                )
            })?;
            vec![(ch, 1.0)]
        }
        None => match (find("R"), find("G"), find("B"), find("Y")) {
            (Some(r), Some(g), Some(b), _) => vec![(r, LUMA[0]), (g, LUMA[1]), (b, LUMA[2])],
            (_, _, _, Some(y)) => vec![(y, 1.0)],
            _ => vec![(
                channels
                    .first()
                    .ok_or_else(|| crate::Error::image(path, "EXR layer has no channels"))?,
                1.0,
            )],
        },
    };
    use rayon::prelude::*;
    let at = |values: &FlatSamples, k: usize| values.value_by_flat_index(k).to_f32();
    for ((name, values), _) in &used {
        if values.len() != w * h {
            return Err(crate::Error::image(
                path,
                format!("channel {name} is subsampled, which is not supported"),
            ));
        }
        if let Some(k) = (0..w * h)
            .into_par_iter()
            .position_first(|k| !at(values, k).is_finite())
        {
            return Err(crate::Error::image(
                path,
                format!(
                    "texel ({}, {}) of channel {name} is {}: heights must be finite",
                    k % w,
                    k / w,
                    at(values, k)
                ),
            ));
        }
    }
    let mut data = crate::memory::zeroed::<f32>("the decoded heights", w * h)?;
    data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for ((_, values), weight) in &used {
            for (i, d) in row.iter_mut().enumerate() {
                *d += weight * at(values, j * w + i);
            }
        }
    });
    apply_range(path, &mut data, w, opts.range)?;
    finish(path, w, h, data, opts.address)
}

/// The values of a TIFF data raster ([`super::data_tiff`]) as heights.
fn load_data_tiff(
    path: &Path,
    probe: super::data_tiff::Probe,
    opts: &HeightOptions,
) -> Result<HeightMap> {
    if opts.channel.is_some() {
        return Err(Error::image(
            path,
            "holds one band of values: --channel applies to colour images",
        ));
    }
    let layout = probe.layout;
    let mut data = super::data_tiff::read(path, probe, |[w, h]| {
        HeightMap::check_size(w, h).map_err(|e| Error::image(path, e))
    })?;
    let [w, h] = layout.shown();
    // Unsigned 8- and 16-bit codes as stored are normalised as an image's
    // are (`code / full`); a range maps the codes themselves.
    if let (HeightRange::AsStored, Some(full)) = (opts.range, layout.full_scale()) {
        data.iter_mut().for_each(|v| *v /= full);
    }
    apply_range(path, &mut data, w, opts.range)?;
    finish(path, w, h, data, opts.address)
}

/// Heights from samples already in memory (an array a binding hands over,
/// rows of `width`, row 0 at `v = 0` as a file's first row is), mapped as
/// `range` says and checked as a loaded file's are, so that an array and
/// the file it came from give the same map; `name` names them in messages.
///
/// # Errors
///
/// As [`load`]: a sample outside the range (or, as stored, outside `[0,
/// 1]`), NaN or infinite, or a map smaller than 2x2.
pub fn from_samples(
    name: &str,
    [width, height]: [usize; 2],
    mut data: Vec<f32>,
    range: HeightRange,
    address: Address,
) -> Result<HeightMap> {
    let path = Path::new(name);
    HeightMap::check_size(width, height).map_err(|e| Error::image(path, e))?;
    apply_range(path, &mut data, width, range)?;
    finish(path, width, height, data, address)
}

/// Maps `data` (rows of `w`) to heights as `range` says; as stored, the
/// values must already lie in `[0, 1]` (an integer image's normalised codes
/// always do), and a value outside is refused, named.
fn apply_range(path: &Path, data: &mut [f32], w: usize, range: HeightRange) -> Result<()> {
    use rayon::prelude::*;
    let span = || {
        data.par_iter()
            .fold(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), &v| (a.min(v), b.max(v)),
            )
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            )
    };
    let (lo, hi) = match range {
        HeightRange::AsStored => (0.0, 1.0),
        HeightRange::Auto => span(),
        HeightRange::Span(lo, hi) => (lo, hi),
    };
    if let Some(k) = data.par_iter().position_first(|v| !(lo..=hi).contains(v)) {
        let (a, b) = span();
        let texel = format!("texel ({}, {}) is {}", k % w.max(1), k / w.max(1), data[k]);
        return Err(Error::image(
            path,
            match range {
                HeightRange::Span(..) => format!(
                    "{texel}, outside the height range {lo},{hi} (this map spans {a} to {b})"
                ),
                _ => format!(
                    "{texel}: heights must lie in [0, 1] (this map spans {a} to {b}); map them \
                     with a height range (--height-range auto, or {a},{b}) or normalise the file \
                     first, and set the depth with --extent"
                ),
            },
        ));
    }
    if range == HeightRange::AsStored {
        return Ok(());
    }
    // In f64, so that a DEM's large offset (metres above the sea) costs no
    // precision of its relief; v <= hi gives at most 1.
    let (lo, d) = (f64::from(lo), f64::from(hi) - f64::from(lo));
    data.par_iter_mut().for_each(|v| {
        *v = if d > 0.0 {
            ((f64::from(*v) - lo) / d) as f32
        } else {
            0.0
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::png::{write_height_png16, write_normal_map_png};
    use crate::NormalMap;
    use image::{ImageBuffer, Luma, LumaA, Rgb, Rgba};

    fn opts() -> HeightOptions {
        HeightOptions::default()
    }

    /// The default options reading channel `c`.
    fn channel(c: Channel) -> HeightOptions {
        HeightOptions {
            channel: Some(c),
            ..opts()
        }
    }

    fn load_path(p: &Path, o: &HeightOptions) -> Result<HeightMap> {
        load(p.to_str().unwrap(), o)
    }

    #[test]
    fn png16_keeps_full_precision() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.png");
        let img: ImageBuffer<Luma<u16>, Vec<u16>> =
            ImageBuffer::from_fn(5, 3, |x, y| Luma([(x * 13_107 + y * 3 + 1) as u16]));
        img.save(&p).unwrap();
        let m = load_path(&p, &opts()).unwrap();
        assert_eq!((m.width(), m.height()), (5, 3));
        for y in 0..3 {
            for x in 0..5 {
                let expect = (x * 13_107 + y * 3 + 1) as f32 / 65535.0;
                assert_eq!(m.texel(x as i64, y as i64), expect);
            }
        }
        // Neighbouring 16-bit codes stay distinct (no 8-bit truncation).
        assert_ne!(m.texel(0, 0), m.texel(0, 1));
    }

    /// A TIFF directory holding one orientation tag (EXIF's layout, as a
    /// camera writes it into a JPEG's APP1 segment).
    fn exif_orientation(value: u16) -> Vec<u8> {
        let mut e = b"II*\0\x08\0\0\0\x01\0".to_vec();
        e.extend_from_slice(&0x0112u16.to_le_bytes()); // Orientation
        e.extend_from_slice(&3u16.to_le_bytes()); // SHORT
        e.extend_from_slice(&1u32.to_le_bytes()); // one value
        e.extend_from_slice(&value.to_le_bytes());
        e.extend_from_slice(&[0, 0, 0, 0, 0, 0]); // padding, no next IFD
        e
    }

    #[test]
    fn photographs_load_as_shown_and_tiffs_keep_16_bits() {
        use image::ImageEncoder;
        let dir = tempfile::tempdir().unwrap();
        // A 16x8 grey ramp along x, smooth enough for JPEG to keep within a
        // few codes.
        let ramp = |x: u32, _y: u32| Luma([(x * 16) as u8]);
        let stored = ImageBuffer::<Luma<u8>, _>::from_fn(16, 8, ramp);
        let jpeg = |name: &str, orientation: Option<u16>| {
            let p = dir.path().join(name);
            let mut bytes = Vec::new();
            let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95);
            if let Some(o) = orientation {
                enc.set_exif_metadata(exif_orientation(o)).unwrap();
            }
            enc.write_image(stored.as_raw(), 16, 8, image::ExtendedColorType::L8)
                .unwrap();
            std::fs::write(&p, bytes).unwrap();
            p
        };
        let near = |a: f32, b: f32| (a - b).abs() < 6.0 / 255.0;
        let plain = load_path(&jpeg("h.jpg", None), &opts()).unwrap();
        assert_eq!((plain.width(), plain.height()), (16, 8));
        assert!(
            near(plain.texel(12, 3), 192.0 / 255.0),
            "{}",
            plain.texel(12, 3)
        );
        // Orientation 6: shown rotated 90 degrees clockwise, so the stored
        // rows become columns: the ramp runs down the shown image.
        let p = jpeg("turned.JPEG", Some(6));
        let dims = dimensions(p.to_str().unwrap(), &opts()).unwrap();
        let turned = load_path(&p, &opts()).unwrap();
        assert_eq!(dims, [8, 16]);
        assert_eq!((turned.width(), turned.height()), (8, 16));
        for x in 0..8 {
            assert!(
                near(turned.texel(x, 12), 192.0 / 255.0),
                "{}",
                turned.texel(x, 12)
            );
            assert!(
                near(turned.texel(x, 2), 32.0 / 255.0),
                "{}",
                turned.texel(x, 2)
            );
        }

        // 16-bit TIFF: every code kept, as for PNG.
        let p = dir.path().join("h.tif");
        let img: ImageBuffer<Luma<u16>, Vec<u16>> =
            ImageBuffer::from_fn(5, 3, |x, y| Luma([(x * 13_107 + y * 3 + 1) as u16]));
        img.save(&p).unwrap();
        let m = load_path(&p, &opts()).unwrap();
        for (x, y) in [(0, 0), (4, 2), (2, 1)] {
            assert_eq!(
                m.texel(x as i64, y as i64),
                (x * 13_107 + y * 3 + 1) as f32 / 65535.0
            );
        }
        // Float TIFFs of several bands are refused: heights are one band.
        let p = dir.path().join("f.tiff");
        image::Rgb32FImage::from_fn(2, 2, |_, _| Rgb([0.5, 0.5, 0.5]))
            .save(&p)
            .unwrap();
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("f.tiff") && e.contains("one band"), "{e}");
        // Formats without a reader are refused by name.
        let e = load("h.webp", &opts()).unwrap_err().to_string();
        assert!(e.contains("h.webp") && e.contains(".jpg"), "{e}");
    }

    /// Writes a one-band TIFF of `C` samples with extra `tags`.
    fn write_tiff<C: tiff::encoder::colortype::ColorType>(
        p: &Path,
        [w, h]: [u32; 2],
        data: &[C::Inner],
        tags: &[(tiff::tags::Tag, &str)],
        orientation: Option<u16>,
    ) where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let file = std::fs::File::create(p).unwrap();
        let mut enc = tiff::encoder::TiffEncoder::new(file).unwrap();
        let mut img = enc.new_image::<C>(w, h).unwrap();
        for &(tag, value) in tags {
            img.encoder().write_tag(tag, value).unwrap();
        }
        if let Some(o) = orientation {
            img.encoder()
                .write_tag(tiff::tags::Tag::Orientation, o)
                .unwrap();
        }
        img.write_data(data).unwrap();
    }

    fn range(r: &str) -> HeightOptions {
        HeightOptions {
            range: r.parse().unwrap(),
            ..opts()
        }
    }

    /// Elevation rasters (float metres, signed 16-bit) load as measured and
    /// become heights only through a range: as stored they must lie in
    /// `[0, 1]`; `auto` maps the map's extremes to 0 and 1, `LO,HI` those
    /// values, each texel `(v - lo) / (hi - lo)` (checked against the
    /// formula in `f64` on random maps); out-of-range, non-finite and
    /// no-data texels are refused, named.
    #[test]
    fn elevation_tiffs_load_as_measured_and_map_by_their_range() {
        use crate::random::SplitMix64;
        use tiff::encoder::colortype::{Gray32Float, Gray64Float, GrayI16};
        use tiff::tags::Tag;
        let dir = tempfile::tempdir().unwrap();
        let mut rng = SplitMix64::new(7);
        for case in 0..20 {
            let w = 2 + (rng.next_u64() % 40) as usize;
            let h = 2 + (rng.next_u64() % 30) as usize;
            let base = rng.next_f32() * 5000.0 - 500.0;
            let relief = rng.next_f32() * 3000.0;
            let dem: Vec<f32> = (0..w * h).map(|_| base + relief * rng.next_f32()).collect();
            let p = dir.path().join(format!("dem{case}.tif"));
            write_tiff::<Gray32Float>(&p, [w as u32, h as u32], &dem, &[], None);
            assert_eq!(dimensions(p.to_str().unwrap(), &opts()).unwrap(), [w, h]);
            let (lo, hi) = dem
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            let m = load_path(&p, &range("auto")).unwrap();
            assert_eq!((m.width(), m.height()), (w, h));
            let want = |v: f32, lo: f32, hi: f32| {
                if hi > lo {
                    ((f64::from(v) - f64::from(lo)) / (f64::from(hi) - f64::from(lo))) as f32
                } else {
                    0.0
                }
            };
            for (k, &v) in dem.iter().enumerate() {
                let got = m.texel((k % w) as i64, (k / w) as i64);
                assert_eq!(got, want(v, lo, hi), "case {case} texel {k}");
                assert!((0.0..=1.0).contains(&got));
            }
            // A wider span maps the same way; one that misses a texel is
            // refused with that texel and the map's extent.
            let (a, b) = (lo - 10.0, hi + 10.0);
            let m = load_path(&p, &range(&format!("{a},{b}"))).unwrap();
            assert_eq!(m.texel(0, 0), want(dem[0], a, b));
            if hi > lo {
                let e = load_path(&p, &range(&format!("{a},{}", (lo + hi) / 2.0)))
                    .unwrap_err()
                    .to_string();
                assert!(e.contains("outside the height range"), "{e}");
                // As stored, metres are refused with the way to map them.
                if !(0.0..=1.0).contains(&lo) || !(0.0..=1.0).contains(&hi) {
                    let e = load_path(&p, &opts()).unwrap_err().to_string();
                    assert!(
                        e.contains("[0, 1]") && e.contains("--height-range auto"),
                        "{e}"
                    );
                }
            }
        }
        // Floats already in [0, 1] load as stored, bit for bit.
        let p = dir.path().join("unit.tif");
        let unit: Vec<f32> = (0..12).map(|k| k as f32 / 11.0).collect();
        write_tiff::<Gray32Float>(&p, [4, 3], &unit, &[], None);
        assert_eq!(load_path(&p, &opts()).unwrap().data(), &unit[..]);
        // Signed 16-bit (an SRTM tile), below sea level too.
        let p = dir.path().join("srtm.tif");
        let srtm: Vec<i16> = vec![-20, 0, 100, 8848, -20, 5];
        write_tiff::<GrayI16>(&p, [3, 2], &srtm, &[], None);
        let m = load_path(&p, &range("auto")).unwrap();
        assert_eq!(m.texel(0, 0), 0.0);
        assert_eq!(m.texel(0, 1), 1.0);
        assert_eq!(m.texel(1, 0), want_i16(0, -20, 8848));
        // The no-data value is refused where it is, with what to do.
        let p = dir.path().join("holes.tif");
        let holes: Vec<i16> = vec![3, 4, -32768, 6];
        write_tiff::<GrayI16>(&p, [2, 2], &holes, &[(Tag::GdalNodata, "-32768")], None);
        let e = load_path(&p, &range("auto")).unwrap_err().to_string();
        assert!(
            e.contains("(0, 1)") && e.contains("no-data") && e.contains("holes.tif"),
            "{e}"
        );
        // Non-finite floats are refused, named.
        let p = dir.path().join("nan.tif");
        write_tiff::<Gray32Float>(&p, [2, 2], &[0.5, f32::NAN, 0.5, 0.5], &[], None);
        let e = load_path(&p, &range("auto")).unwrap_err().to_string();
        assert!(e.contains("(1, 0)") && e.contains("finite"), "{e}");
        // An unsigned 16-bit model that names its no-data value is read
        // here, its codes normalised as an image's are (the same bits as
        // without the tag), and its holes found; so are the no-data values
        // an f32 does not hold exactly (UInt32's largest, a float -9999.99).
        let codes: Vec<u16> = vec![0, 1000, 65535, 30000];
        let u16_model = |name: &str, tags: &[(Tag, &str)]| {
            let p = dir.path().join(name);
            write_tiff::<tiff::encoder::colortype::Gray16>(&p, [2, 2], &codes, tags, None);
            load_path(&p, &opts())
        };
        let plain = u16_model("u16.tif", &[]).unwrap();
        let tagged = u16_model("u16nd.tif", &[(Tag::GdalNodata, "7")]).unwrap();
        assert_eq!(tagged.data(), plain.data());
        let e = u16_model("u16hole.tif", &[(Tag::GdalNodata, "65535")])
            .unwrap_err()
            .to_string();
        assert!(e.contains("(0, 1)") && e.contains("no-data"), "{e}");
        let p = dir.path().join("u32hole.tif");
        write_tiff::<tiff::encoder::colortype::Gray32>(
            &p,
            [2, 2],
            &[5, 6, 7, u32::MAX],
            &[(Tag::GdalNodata, "4294967295")],
            None,
        );
        let e = load_path(&p, &range("auto")).unwrap_err().to_string();
        assert!(e.contains("(1, 1)") && e.contains("no-data"), "{e}");
        let p = dir.path().join("f32hole.tif");
        write_tiff::<Gray32Float>(
            &p,
            [2, 2],
            &[5.0, -9999.99, 7.0, 8.0],
            &[(Tag::GdalNodata, "-9999.99")],
            None,
        );
        let e = load_path(&p, &range("auto")).unwrap_err().to_string();
        assert!(e.contains("(1, 0)") && e.contains("no-data"), "{e}");
        // 64-bit samples: refused with the conversion to make.
        let p = dir.path().join("f64.tif");
        write_tiff::<Gray64Float>(&p, [2, 2], &[0.25, 0.5, 0.5, 0.5], &[], None);
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("64-bit") && e.contains("Float32"), "{e}");
        // A colour channel of one band is a mistake, said so.
        let e = load_path(&dir.path().join("unit.tif"), &channel(Channel::G))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--channel"), "{e}");
        // The orientation tag turns the raster as it is shown: rotated a
        // quarter turn clockwise (6), the stored first row is the right
        // column, and the size swaps.
        let p = dir.path().join("turned.tif");
        write_tiff::<Gray32Float>(&p, [3, 2], &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5], &[], Some(6));
        assert_eq!(dimensions(p.to_str().unwrap(), &opts()).unwrap(), [2, 3]);
        let m = load_path(&p, &opts()).unwrap();
        assert_eq!(m.data(), &[0.3, 0.0, 0.4, 0.1, 0.5, 0.2]);
        // An 8-bit image's range is in its codes.
        let p = dir.path().join("codes.png");
        ImageBuffer::<Luma<u8>, _>::from_fn(3, 2, |x, _| Luma([(50 + 50 * x) as u8]))
            .save(&p)
            .unwrap();
        let row = [0.0, 0.5, 1.0, 0.0, 0.5, 1.0];
        assert_eq!(load_path(&p, &range("50,150")).unwrap().data(), &row);
        assert_eq!(load_path(&p, &range("auto")).unwrap().data(), &row);
        // Ranges that are not ranges are refused when parsed.
        for bad in ["", "1", "2,1", "0,nan", "a,b", "0,inf"] {
            assert!(bad.parse::<HeightRange>().is_err(), "{bad}");
        }
    }

    fn want_i16(v: i16, lo: i16, hi: i16) -> f32 {
        ((f64::from(v) - f64::from(lo)) / (f64::from(hi) - f64::from(lo))) as f32
    }

    #[test]
    fn png8_grey_alpha_and_colour_channels() {
        let dir = tempfile::tempdir().unwrap();
        let grey = dir.path().join("g.png");
        ImageBuffer::<Luma<u8>, _>::from_fn(2, 2, |x, y| Luma([(x * 100 + y * 50) as u8]))
            .save(&grey)
            .unwrap();
        let m = load_path(&grey, &opts()).unwrap();
        assert_eq!(m.texel(1, 1), 150.0 / 255.0);
        let e = load_path(&grey, &channel(Channel::A)).unwrap_err();
        assert!(
            e.to_string().contains("no alpha") && e.to_string().contains("g.png"),
            "{e}"
        );

        let la = dir.path().join("la.png");
        ImageBuffer::<LumaA<u8>, _>::from_fn(2, 2, |_, _| LumaA([10, 200]))
            .save(&la)
            .unwrap();
        let m = load_path(&la, &channel(Channel::A)).unwrap();
        assert_eq!(m.texel(0, 0), 200.0 / 255.0);
        assert_eq!(load_path(&la, &opts()).unwrap().texel(0, 0), 10.0 / 255.0);

        let rgb = dir.path().join("c.png");
        ImageBuffer::<Rgb<u8>, _>::from_fn(2, 2, |_, _| Rgb([255, 0, 51]))
            .save(&rgb)
            .unwrap();
        let m = load_path(&rgb, &opts()).unwrap();
        assert!((m.texel(0, 0) - (0.2126 + 0.0722 * 0.2)).abs() < 1e-6);
        let m = load_path(&rgb, &channel(Channel::B)).unwrap();
        assert_eq!(m.texel(0, 0), 0.2);
        assert!(load_path(&rgb, &channel(Channel::A)).is_err());

        let rgba16 = dir.path().join("c16.png");
        ImageBuffer::<Rgba<u16>, _>::from_fn(2, 2, |_, _| Rgba([65535, 65535, 65535, 1]))
            .save(&rgba16)
            .unwrap();
        assert_eq!(load_path(&rgba16, &opts()).unwrap().texel(1, 0), 1.0);
        let m = load_path(&rgba16, &channel(Channel::A)).unwrap();
        assert_eq!(m.texel(1, 0), 1.0 / 65535.0);
    }

    #[test]
    fn bad_pngs_give_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.png");
        std::fs::write(&p, b"").unwrap();
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("bad.png") && e.contains("empty"), "{e}");

        std::fs::write(&p, b"this is not a png at all").unwrap();
        assert!(load_path(&p, &opts())
            .unwrap_err()
            .to_string()
            .contains("bad.png"));

        ImageBuffer::<Luma<u8>, _>::from_fn(1, 1, |_, _| Luma([3]))
            .save(&p)
            .unwrap();
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("1x1") && e.contains("bad.png"), "{e}");

        ImageBuffer::<Luma<u16>, _>::from_fn(64, 64, |x, y| Luma([(x * y) as u16]))
            .save(&p)
            .unwrap();
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("bad.png"), "{e}");

        let e = load("missing.png", &opts()).unwrap_err().to_string();
        assert!(e.contains("missing.png"), "{e}");
        let e = load("height.bmp", &opts()).unwrap_err().to_string();
        assert!(e.contains("height.bmp") && e.contains("gen:NAME"), "{e}");
    }

    fn write_exr(p: &Path, w: usize, h: usize, channels: Vec<(&str, Vec<f32>)>) {
        use exr::prelude::*;
        let list: Vec<AnyChannel<FlatSamples>> = channels
            .into_iter()
            .map(|(n, v)| AnyChannel::new(n, FlatSamples::F32(v)))
            .collect();
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(list.into()),
        );
        Image::from_layer(layer).write().to_file(p).unwrap();
    }

    #[test]
    fn exr_channels_and_refusals() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.exr");
        let vals: Vec<f32> = (0..12).map(|i| i as f32 / 11.0).collect();
        write_exr(&p, 4, 3, vec![("Y", vals.clone())]);
        let m = load_path(&p, &opts()).unwrap();
        assert_eq!(m.data(), &vals[..]);

        write_exr(
            &p,
            4,
            3,
            vec![
                ("R", vals.clone()),
                ("G", vec![0.5; 12]),
                ("B", vec![0.0; 12]),
            ],
        );
        let m = load_path(&p, &opts()).unwrap();
        assert!((m.texel(3, 2) - (0.2126 + 0.7152 * 0.5)).abs() < 1e-6);
        let m = load_path(&p, &channel(Channel::G)).unwrap();
        assert_eq!(m.texel(0, 0), 0.5);
        let e = load_path(&p, &channel(Channel::A)).unwrap_err().to_string();
        assert!(e.contains("no A channel"), "{e}");

        let mut nan = vals.clone();
        nan[6] = f32::NAN;
        write_exr(&p, 4, 3, vec![("Y", nan)]);
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(
            e.contains("(2, 1)") && e.contains("NaN") && e.contains("h.exr"),
            "{e}"
        );
        let mut inf = vals.clone();
        inf[0] = f32::INFINITY;
        write_exr(&p, 4, 3, vec![("Y", inf)]);
        assert!(load_path(&p, &opts())
            .unwrap_err()
            .to_string()
            .contains("inf"));

        let big: Vec<f32> = vals.iter().map(|v| v * 10.0).collect();
        write_exr(&p, 4, 3, vec![("Y", big)]);
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("normalise") && e.contains("[0, 1]"), "{e}");

        write_exr(&p, 1, 1, vec![("Y", vec![0.5])]);
        assert!(load_path(&p, &opts())
            .unwrap_err()
            .to_string()
            .contains("1x1"));

        std::fs::write(&p, b"v/1\x01garbage").unwrap();
        let e = load_path(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("h.exr") && e.contains("EXR"), "{e}");
    }

    #[test]
    fn png_writers_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let m = HeightMap::new(
            3,
            2,
            vec![0.0, 0.25, 1.0, 0.5, 0.123_456, 0.999],
            Address::Clamp,
        )
        .unwrap();
        let p = dir.path().join("h16.png");
        write_height_png16(&p, &m).unwrap();
        let back = load_path(&p, &opts()).unwrap();
        for (a, b) in back.data().iter().zip(m.data()) {
            assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-7);
        }

        let extent = crate::Extent::new(1.0, 1.0, 0.2).unwrap();
        let normals = NormalMap::from_height(&m, extent).unwrap();
        let p = dir.path().join("n.png");
        write_normal_map_png(&p, &normals).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (3, 2));
        for (px, n) in img.pixels().zip(&normals.data) {
            // +Y up: green is up the image, which is -v.
            for (c, expect) in [n.x, -n.y, n.z].into_iter().enumerate() {
                let decoded = px[c] as f32 / 255.0 * 2.0 - 1.0;
                assert!((decoded - expect).abs() <= 1.0 / 255.0 + 1e-6);
            }
        }
    }
}
