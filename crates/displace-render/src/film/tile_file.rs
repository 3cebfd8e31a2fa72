//! Farm tile files: one tile of a render as an OpenEXR image (linear RGB,
//! 32-bit float, so a merge loses nothing), written with the OpenEXR
//! windows for what they are meant for: the display window is the full
//! image, the data window the tile's own rectangle. Two attributes say
//! which render it belongs to: `displace.content_hash` (the scene's
//! [`content hash`](crate::Scene::content_hash), 16 hex digits) and
//! `displace.tile` (`I/N CHECKSUM`: the tile's index, the tile count and a
//! checksum of its pixels, 16 hex digits, so that a tile damaged on its way
//! through a farm's file system is refused at merge instead of stitched
//! into a different image).
//!
//! Reading checks the header before any pixel is decoded (a small file
//! that claims a huge tile is refused before it is allocated), then the
//! pixels: finite, not negative (radiance never is), and matching their
//! checksum.

use crate::error::{Error, Result};
use crate::film::tiling::TileIndex;
use crate::render::{Crop, Image};
use displace_core::io::atomic::write_atomic;
use exr::meta::attribute::{AttributeValue, IntegerBounds, SampleType, Text};
use exr::prelude::{
    Encoding, Image as ExrImage, LayerAttributes, ReadChannels, ReadLayers, SpecificChannels, Vec2,
    WritableImage,
};
use glam::Vec3;
use std::path::Path;

/// Attribute naming the render a tile belongs to.
pub const HASH_ATTRIBUTE: &str = "displace.content_hash";
/// Attribute giving a tile's `I/N`.
pub const TILE_ATTRIBUTE: &str = "displace.tile";

/// Largest tile file read: the largest image a scene allows (2^28 pixels)
/// at 12 bytes a pixel, with room for the header.
const MAX_TILE_FILE_BYTES: u64 = (12 << 28) + (1 << 20);

/// Most pixels of a tile and of the image it belongs to: the largest image
/// a scene allows.
pub const MAX_TILE_PIXELS: u64 = 1 << 28;

/// A checksum of `pixels` (their bits in order, through SplitMix64's
/// finaliser): what a tile records of its pixels and a merge verifies.
pub fn pixel_checksum(pixels: &[Vec3]) -> u64 {
    pixels
        .iter()
        .flat_map(|p| p.to_array())
        .fold(0x9e37_79b9_7f4a_7c15, |h, v| {
            displace_core::random::mix64(h ^ u64::from(v.to_bits()))
        })
}

/// What a tile file says about itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileMeta {
    /// The render's [`content hash`](crate::Scene::content_hash).
    pub content_hash: u64,
    /// The whole image, `[width, height]`.
    pub full_size: [u32; 2],
    /// This tile's pixels within it.
    pub rect: Crop,
    /// Which tile of how many.
    pub tile: TileIndex,
}

/// A tile as read back: what it says and its pixels (row-major over
/// `meta.rect`).
#[derive(Clone, Debug)]
pub struct TileImage {
    /// The tile's header.
    pub meta: TileMeta,
    /// Linear RGB, row-major over `meta.rect`.
    pub pixels: Vec<Vec3>,
}

fn bad(path: &Path, message: impl Into<String>) -> Error {
    displace_core::Error::image(path, message.into()).into()
}

/// Writes `image` (the pixels of `meta.rect`) to `path` atomically.
pub fn write_tile(path: &Path, meta: &TileMeta, image: &Image) -> Result<()> {
    let r = meta.rect;
    if (image.width, image.height) != (r.width, r.height) {
        return Err(bad(
            path,
            format!(
                "a {}x{} image is not the {}x{} tile it is written as",
                image.width, image.height, r.width, r.height
            ),
        ));
    }
    let width = r.width as usize;
    let pixels = &image.pixels;
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let v = pixels[p.y() * width + p.x()];
        (v.x, v.y, v.z)
    });
    let mut attributes = LayerAttributes::named("rgb");
    attributes.layer_position = Vec2(r.x as i32, r.y as i32);
    let layer = exr::prelude::Layer::new(
        (r.width as usize, r.height as usize),
        attributes,
        // Blocks in order, not as the threads finish them: the same tile
        // is the same bytes on every run.
        Encoding {
            line_order: exr::meta::attribute::LineOrder::Increasing,
            ..Encoding::FAST_LOSSLESS
        },
        channels,
    );
    let mut exr = ExrImage::from_layer(layer);
    exr.attributes.display_window = IntegerBounds::new(
        (0, 0),
        (meta.full_size[0] as usize, meta.full_size[1] as usize),
    );
    // One custom attribute per map: the writer walks each map in hash
    // order, which changes from process to process, and a tile must be
    // the same bytes on every run. The hash is the whole render's, the
    // index this layer's.
    exr.attributes.other.insert(
        Text::from(HASH_ATTRIBUTE),
        AttributeValue::Text(Text::from(format!("{:016x}", meta.content_hash).as_str())),
    );
    let tile = format!("{} {:016x}", meta.tile, pixel_checksum(pixels));
    exr.layer_data.attributes.other.insert(
        Text::from(TILE_ATTRIBUTE),
        AttributeValue::Text(Text::from(tile.as_str())),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr.write()
        .to_buffered(&mut bytes)
        .map_err(|e| bad(path, e.to_string()))?;
    write_atomic(path, |w| w.write_all(bytes.get_ref()))?;
    Ok(())
}

/// The text attribute `name` of a tile, wherever the reader filed it (a
/// one-layer file has one header: custom attributes come back as the
/// layer's or the image's).
fn text_attribute(
    attrs: [&std::collections::HashMap<Text, AttributeValue>; 2],
    name: &str,
    path: &Path,
) -> Result<String> {
    let key = Text::from(name);
    match attrs.iter().find_map(|a| a.get(&key)) {
        Some(AttributeValue::Text(t)) => Ok(t.to_string()),
        Some(_) => Err(bad(path, format!("attribute {name} is not text"))),
        None => Err(bad(
            path,
            format!("not a displace tile: it has no {name} attribute (write tiles with `displace render --tile I/N`)"),
        )),
    }
}

/// A tile's header as read before its pixels: what it says of itself and
/// the checksum its pixels must match.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileHeader {
    /// What the tile says about itself.
    pub meta: TileMeta,
    /// [`pixel_checksum`] of its pixels as written.
    pub checksum: u64,
}

/// Reads a tile file's header alone: its attributes and windows, checked
/// (one layer of 32-bit float R, G, B; a rectangle inside an image of at
/// most [`MAX_TILE_PIXELS`]), without decoding a pixel. A merge reads every
/// tile's header first, so a set of tiles that cannot be merged is refused
/// before any is decoded.
pub fn read_tile_header(path: &Path) -> Result<TileHeader> {
    displace_core::io::check_input(path, "tile file", MAX_TILE_FILE_BYTES)?;
    let file = std::fs::File::open(path).map_err(|e| displace_core::Error::io(path, e))?;
    let meta = exr::meta::MetaData::read_from_buffered(std::io::BufReader::new(file), true)
        .map_err(|e| unreadable(path, e))?;
    let [header] = meta.headers.as_slice() else {
        return Err(bad(path, "a tile has exactly one layer"));
    };
    let names: Vec<String> = header
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    if names != ["B", "G", "R"]
        || header
            .channels
            .list
            .iter()
            .any(|c| c.sample_type != SampleType::F32)
    {
        // Named with their sample types: a half-float tile has the right
        // names, and only its types are wrong.
        let held: Vec<String> = header
            .channels
            .list
            .iter()
            .map(|c| {
                let kind = match c.sample_type {
                    SampleType::F16 => "16-bit float",
                    SampleType::F32 => "32-bit float",
                    SampleType::U32 => "32-bit unsigned integer",
                };
                format!("{} ({kind})", c.name)
            })
            .collect();
        return Err(bad(
            path,
            format!(
                "a tile holds 32-bit float R, G, B channels, this one {}",
                held.join(", ")
            ),
        ));
    }
    let attrs = [
        &header.shared_attributes.other,
        &header.own_attributes.other,
    ];
    let hash_text = text_attribute(attrs, HASH_ATTRIBUTE, path)?;
    let content_hash = u64::from_str_radix(&hash_text, 16)
        .ok()
        .filter(|_| hash_text.len() == 16)
        .ok_or_else(|| {
            bad(
                path,
                format!("{HASH_ATTRIBUTE} = `{hash_text}` is not 16 hex digits"),
            )
        })?;
    let tile_text = text_attribute(attrs, TILE_ATTRIBUTE, path)?;
    let (index_text, checksum_text) = tile_text.split_once(' ').unwrap_or((&tile_text, ""));
    let tile = match index_text.parse() {
        Ok(crate::film::tiling::TileArg::Fixed(t)) => t,
        _ => {
            return Err(bad(
                path,
                format!("{TILE_ATTRIBUTE} = `{tile_text}` is not `I/N CHECKSUM`"),
            ))
        }
    };
    let checksum = u64::from_str_radix(checksum_text, 16)
        .ok()
        .filter(|_| checksum_text.len() == 16)
        .ok_or_else(|| {
            bad(
                path,
                format!(
                    "{TILE_ATTRIBUTE} = `{tile_text}` carries no checksum of its pixels (16 hex \
                     digits after `I/N`): a tile of an older displace? render it again"
                ),
            )
        })?;
    let display = header.shared_attributes.display_window;
    let (pos, size) = (header.own_attributes.layer_position, header.layer_size);
    let fits = |v: i64| u32::try_from(v).ok();
    let (Some(fw), Some(fh), Some(x), Some(y)) = (
        fits(display.size.width() as i64).filter(|_| display.position == Vec2(0, 0)),
        fits(display.size.height() as i64),
        fits(pos.x() as i64),
        fits(pos.y() as i64),
    ) else {
        return Err(bad(
            path,
            format!("the display window (full image) must start at 0,0 and the data window (tile) inside it; they are {display:?} and {pos:?}+{size:?}"),
        ));
    };
    let rect = Crop {
        x,
        y,
        width: size.width() as u32,
        height: size.height() as u32,
    };
    if u64::from(fw) * u64::from(fh) > MAX_TILE_PIXELS {
        return Err(bad(
            path,
            format!(
                "a tile of a {fw}x{fh} image: more than the {MAX_TILE_PIXELS} pixels an image may have"
            ),
        ));
    }
    if u64::from(x) + u64::from(rect.width) > u64::from(fw)
        || u64::from(y) + u64::from(rect.height) > u64::from(fh)
    {
        return Err(bad(
            path,
            format!(
                "the tile's rectangle {x},{y},{},{} lies outside its {fw}x{fh} image",
                rect.width, rect.height
            ),
        ));
    }
    Ok(TileHeader {
        meta: TileMeta {
            content_hash,
            full_size: [fw, fh],
            rect,
            tile,
        },
        checksum,
    })
}

fn unreadable(path: &Path, e: exr::error::Error) -> Error {
    bad(
        path,
        format!("not a complete OpenEXR tile (cut short or damaged?): {e}"),
    )
}

/// Reads a tile file: its header ([`read_tile_header`]), then every pixel,
/// each finite and not negative, and all of them matching the header's
/// checksum. A file cut short, damaged or not a tile is an error naming
/// the file.
pub fn read_tile(path: &Path) -> Result<TileImage> {
    let header = read_tile_header(path)?;
    let bytes = std::fs::read(path).map_err(|e| displace_core::Error::io(path, e))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |size, _| (size.width(), vec![Vec3::ZERO; size.width() * size.height()]),
            |(w, px): &mut (usize, Vec<Vec3>), p, (r, g, b): (f32, f32, f32)| {
                px[p.y() * *w + p.x()] = Vec3::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .pedantic()
        .from_buffered(std::io::Cursor::new(&bytes))
        .map_err(|e| unreadable(path, e))?;
    let layer = image.layer_data;
    let rect = header.meta.rect;
    if (layer.size.width() as u32, layer.size.height() as u32) != (rect.width, rect.height) {
        return Err(bad(
            path,
            "the tile's pixels are not the size its header says",
        ));
    }
    let pixels = layer.channel_data.pixels.1;
    if let Some(k) = pixels
        .iter()
        .position(|p| !p.is_finite() || p.min_element() < 0.0)
    {
        let (x, y) = (
            rect.x + k as u32 % rect.width,
            rect.y + k as u32 / rect.width,
        );
        return Err(bad(
            path,
            format!(
                "pixel ({x}, {y}) is {:?}: a render's pixels are finite and not negative",
                pixels[k].to_array()
            ),
        ));
    }
    let found = pixel_checksum(&pixels);
    if found != header.checksum {
        return Err(bad(
            path,
            format!(
                "its pixels do not match the checksum written with them ({found:016x}, written \
                 {:016x}): the file was damaged after it was written",
                header.checksum
            ),
        ));
    }
    Ok(TileImage {
        meta: header.meta,
        pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn sample() -> (TileMeta, Image) {
        let rect = Crop {
            x: 0,
            y: 16,
            width: 5,
            height: 3,
        };
        let pixels = (0..15)
            .map(|i| Vec3::new(i as f32 * 0.1, 1.5e-39, f32::MAX / (i + 1) as f32))
            .collect();
        (
            TileMeta {
                content_hash: 0x0123_4567_89ab_cdef,
                full_size: [5, 40],
                rect,
                tile: TileIndex { index: 1, count: 3 },
            },
            Image {
                width: 5,
                height: 3,
                pixels,
            },
        )
    }

    /// [`sample`] written as `t.exr` in `dir`: its path, metadata and pixels.
    fn written_sample(dir: &Path) -> (PathBuf, TileMeta, Image) {
        let p = dir.join("t.exr");
        let (meta, img) = sample();
        write_tile(&p, &meta, &img).unwrap();
        (p, meta, img)
    }

    #[test]
    fn tiles_round_trip_bit_exactly_with_their_metadata() {
        let dir = tempfile::tempdir().unwrap();
        let (p, meta, img) = written_sample(dir.path());
        let back = read_tile(&p).unwrap();
        assert_eq!(back.meta, meta);
        let bits = |v: &[Vec3]| -> Vec<u32> {
            v.iter()
                .flat_map(|p| p.to_array())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(bits(&back.pixels), bits(&img.pixels));
    }

    #[test]
    fn cut_short_and_foreign_files_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let (p, _, img) = written_sample(dir.path());
        let good = std::fs::read(&p).unwrap();
        for keep in [good.len() - 1, good.len() / 2, 10, 0] {
            std::fs::write(&p, &good[..keep]).unwrap();
            let e = read_tile(&p).unwrap_err().to_string();
            assert!(e.contains("t.exr"), "{keep}: {e}");
        }
        // An EXR without the attributes: not a tile.
        let plain = dir.path().join("plain.exr");
        crate::film::output::write_image(&plain, &img).unwrap();
        let e = read_tile(&plain).unwrap_err().to_string();
        assert!(e.contains("plain.exr") && e.contains(HASH_ATTRIBUTE), "{e}");
    }

    /// A tile whose channels are half floats (the right names, the wrong
    /// type) is refused saying so, not only by the channels' names.
    #[test]
    fn a_half_float_tile_is_named_as_one() {
        let dir = tempfile::tempdir().unwrap();
        let (p, _, _) = written_sample(dir.path());
        let mut bytes = std::fs::read(&p).unwrap();
        let key = b"channels\0chlist\0";
        let mut i = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        // Each channel: its name, then its pixel type (1: half), pLinear
        // and three reserved bytes, and two samplings.
        for _ in 0..3 {
            i += bytes[i..].iter().position(|&b| b == 0).unwrap() + 1;
            bytes[i..i + 4].copy_from_slice(&1i32.to_le_bytes());
            i += 16;
        }
        std::fs::write(&p, &bytes).unwrap();
        let e = read_tile_header(&p).err().unwrap().to_string();
        assert!(e.contains("t.exr") && e.contains("R (16-bit float)"), "{e}");
    }

    /// A tile whose pixels no longer match their checksum (bits flipped
    /// after writing), one holding NaN or a negative pixel, and one whose
    /// header claims an image past the pixel limit are refused by name;
    /// the last before any pixel is decoded.
    #[test]
    fn damaged_non_finite_and_oversized_tiles_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let (p, meta, img) = written_sample(dir.path());
        let good = std::fs::read(&p).unwrap();
        // The same tile with one pixel changed, carrying the first one's
        // checksum: what a flipped bit on the way does.
        let mut other = img.clone();
        other.pixels[7].x += 0.25;
        write_tile(&p, &meta, &other).unwrap();
        let hex = |px: &[Vec3]| format!("{:016x}", pixel_checksum(px));
        let (want, got) = (hex(&img.pixels), hex(&other.pixels));
        let mut bytes = std::fs::read(&p).unwrap();
        let at = bytes.windows(16).position(|w| w == got.as_bytes()).unwrap();
        bytes[at..at + 16].copy_from_slice(want.as_bytes());
        std::fs::write(&p, &bytes).unwrap();
        let e = read_tile(&p).unwrap_err().to_string();
        assert!(
            e.contains("t.exr") && e.contains("do not match the checksum"),
            "{e}"
        );
        // NaN and a negative pixel, named where they are in the image.
        for (k, v) in [(3, f32::NAN), (11, -0.5)] {
            let mut bad = img.clone();
            bad.pixels[k].y = v;
            write_tile(&p, &meta, &bad).unwrap();
            let e = read_tile(&p).unwrap_err().to_string();
            let (x, y) = (k % 5, 16 + k / 5);
            assert!(
                e.contains(&format!("pixel ({x}, {y})")) && e.contains("finite and not negative"),
                "{e}"
            );
        }
        // A tile of a 65536x65536 image: 2^32 pixels claimed.
        let huge = TileMeta {
            full_size: [1 << 16, 1 << 16],
            ..meta
        };
        write_tile(&p, &huge, &img).unwrap();
        let e = read_tile_header(&p).unwrap_err().to_string();
        assert!(
            e.contains("65536x65536") && e.contains("pixels an image may have"),
            "{e}"
        );
        // The good file still reads.
        std::fs::write(&p, &good).unwrap();
        assert_eq!(read_tile(&p).unwrap().meta, meta);
    }
}
