//! KTX 2.0 3D textures (Khronos KTX 2.0 specification), the container Bevy
//! and other engines load directly. The `ktx2` crate only parses, so the
//! writer builds the container here: identifier, header, level index, a
//! Basic Data Format Descriptor (Khronos Data Format Specification 1.3,
//! section 5), key/value data, and level 0.
//!
//! The key/value data carries everything needed to use the map without this
//! program (all values NUL-terminated UTF-8):
//!
//! | key                          | value                                            |
//! |------------------------------|--------------------------------------------------|
//! | `KTXwriter`                  | `displace <version>`                             |
//! | `displace.addressing`        | `clamp` or `repeat` (sampler address mode in u, v; depth always clamps) |
//! | `displace.aspect`            | `ax,ay`: tile width and height in shell depths   |
//! | `displace.convention`        | how voxels are placed and what they hold (prose) |
//! | `displace.encoding`          | `r8`, `r16f` or `r32f`, with the decoding rule   |
//! | `displace.extent`            | `sx,sy,sz`: the tile's physical size             |
//! | `displace.max_underestimate` | bound on `true distance - trilinear(decoded values)`, shell depths |
//! | `displace.r8_range`          | `min,max` (r8 only): `value = min + code/255 (max - min)` |
//! | `displace.units`             | `shell depths`                                   |
//!
//! A caller may add keys of its own ([`to_bytes_with_keys`]; the bake cache
//! of displace-render adds a checksum of the whole file), and
//! [`Decoded::keys`] gives every key back.
//!
//! Numbers are written in Rust's shortest round-trip form, so reading them
//! back gives the very same `f32` and an r8 code decodes to exactly the value
//! the writer checked against the original (decoded <= original).

use super::FormatError;
use crate::distance_map::{Format, R8Range};
use crate::{Address, DistanceMap, Extent, Result};
use std::path::Path;

/// VkFormat values (Vulkan 1.0 `VkFormat`).
const VK_FORMAT_R8_UNORM: u32 = 9;
const VK_FORMAT_R16_SFLOAT: u32 = 76;
const VK_FORMAT_R32_SFLOAT: u32 = 100;

const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];
const HEADER_LEN: usize = 80;
const LEVEL_INDEX_LEN: usize = 24;

/// What [`Format`] voxels look like to a GPU: Vulkan format and KTX `typeSize`.
fn vk_format(format: Format) -> (u32, u32) {
    match format {
        Format::R8 => (VK_FORMAT_R8_UNORM, 1),
        Format::R16F => (VK_FORMAT_R16_SFLOAT, 2),
        Format::R32F => (VK_FORMAT_R32_SFLOAT, 4),
    }
}

/// The Basic Data Format Descriptor of a one-channel format, with the
/// leading `dfdTotalSize`: colour model RGBSDA, BT.709 primaries (unused by
/// data, but the spec's default), linear transfer, one sample on channel R.
/// UNORM samples span `0..=2^bits-1`; float samples carry the SIGNED|FLOAT
/// qualifiers and the `-1.0..1.0` bounds the DFD spec requires.
fn dfd(format: Format) -> Vec<u8> {
    let bits: u8 = (format.bytes_per_voxel() * 8) as u8;
    let (qualifiers, lower, upper): (u8, u32, u32) = match format {
        Format::R8 => (0, 0, 255),
        Format::R16F | Format::R32F => (0x80 | 0x40, (-1.0f32).to_bits(), 1.0f32.to_bits()),
    };
    let block_size: u16 = 24 + 16;
    let mut out = Vec::with_capacity(4 + block_size as usize);
    out.extend_from_slice(&(4 + block_size as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes()); // vendorId 0 (Khronos), descriptorType 0 (basic)
    out.extend_from_slice(&2u16.to_le_bytes()); // versionNumber (KDF 1.3)
    out.extend_from_slice(&block_size.to_le_bytes());
    out.extend_from_slice(&[1, 1, 1, 0]); // RGBSDA, BT709, LINEAR, straight alpha
    out.extend_from_slice(&[0, 0, 0, 0]); // texel block 1x1x1x1 (stored minus one)
    out.extend_from_slice(&[format.bytes_per_voxel() as u8, 0, 0, 0, 0, 0, 0, 0]);
    out.extend_from_slice(&0u16.to_le_bytes()); // bitOffset
    out.push(bits - 1); // bitLength (stored minus one)
    out.push(qualifiers); // channel 0 (R) with qualifiers in the top bits
    out.extend_from_slice(&[0, 0, 0, 0]); // sample position
    out.extend_from_slice(&lower.to_le_bytes());
    out.extend_from_slice(&upper.to_le_bytes());
    out
}

/// The writer's own key/value pairs for `map`, unsorted.
fn key_values(
    address: Address,
    underestimate: f32,
    extent: Extent,
    format: Format,
    range: Option<R8Range>,
) -> Vec<(String, String)> {
    let [ax, ay] = extent.aspect();
    let encoding = match format {
        Format::R8 => "r8: unorm code c decodes to value = min + c / 255 * (max - min), min,max from displace.r8_range",
        Format::R16F => "r16f: half float, the value itself (rounded down)",
        Format::R32F => "r32f: float, the value itself",
    };
    let mut kv = vec![
        ("KTXwriter".to_string(), format!("displace {}", env!("CARGO_PKG_VERSION"))),
        ("displace.addressing".into(), address.name().into()),
        ("displace.aspect".into(), format!("{ax},{ay}")),
        (
            "displace.convention".into(),
            "signed distance from each voxel centre to the displaced surface, negative under it; \
             voxel (i, j, k) of a W x H x D map sits at ((i + 0.5) / W, (j + 0.5) / H, (k + 0.5) / D) of the tile \
             (texel centres); level data is ordered [k][j][i] (i fastest); sample trilinearly (linear filter): \
             the interpolated value never exceeds the true distance"
                .into(),
        ),
        ("displace.encoding".into(), encoding.into()),
        ("displace.extent".into(), format!("{},{},{}", extent.sx, extent.sy, extent.sz)),
        ("displace.max_underestimate".into(), format!("{underestimate}")),
        ("displace.units".into(), "shell depths".into()),
    ];
    if let Some(r) = range {
        kv.push(("displace.r8_range".into(), format!("{},{}", r.min, r.max)));
    }
    kv
}

fn kvd_bytes(kv: &[(String, String)]) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, v) in kv {
        let len = k.len() + 1 + v.len() + 1;
        out.extend_from_slice(&(len as u32).to_le_bytes());
        out.extend_from_slice(k.as_bytes());
        out.push(0);
        out.extend_from_slice(v.as_bytes());
        out.push(0);
        out.resize(out.len().next_multiple_of(4), 0);
    }
    out
}

/// Everything of a KTX2 file before its level data, with room reserved for
/// that data: identifier, header, level index, descriptor and key/value data
/// (`underestimate` and `range` as the rounded map states them), padded to
/// where level 0 starts, with the caller's `extra` keys. Shared by
/// [`to_bytes`] and the streamed writer of [`super::stream`], so both write
/// the same bytes.
pub(crate) fn header(
    size: [usize; 3],
    address: Address,
    underestimate: f32,
    extent: Extent,
    format: Format,
    range: Option<R8Range>,
    extra: &[(&str, &str)],
) -> Vec<u8> {
    let [w, h, d] = size;
    let (vk, type_size) = vk_format(format);
    let dfd = dfd(format);
    let mut kv = key_values(address, underestimate, extent, format, range);
    kv.extend(extra.iter().map(|(k, v)| (k.to_string(), v.to_string())));
    // Sorted by key, as the KTX 2.0 spec's key/value data requires.
    kv.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    let kvd = kvd_bytes(&kv);
    let dfd_offset = HEADER_LEN + LEVEL_INDEX_LEN;
    let kvd_offset = dfd_offset + dfd.len();
    // Level data aligns to lcm(texel block size, 4) = 4 for these formats.
    let level_offset = (kvd_offset + kvd.len()).next_multiple_of(4);
    let level_len = w * h * d * format.bytes_per_voxel();

    let mut out = Vec::with_capacity(level_offset);
    out.extend_from_slice(&IDENTIFIER);
    for v in [vk, type_size, w as u32, h as u32, d as u32, 0, 1, 1, 0] {
        // vkFormat, typeSize, pixelWidth/Height/Depth, layerCount 0 (not an
        // array), faceCount 1, levelCount 1, supercompressionScheme 0.
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [
        dfd_offset as u32,
        dfd.len() as u32,
        kvd_offset as u32,
        kvd.len() as u32,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteOffset
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteLength
    for v in [level_offset as u64, level_len as u64, level_len as u64] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    out.resize(level_offset, 0);
    out
}

/// Encodes `map` (one tile of `extent`) as a KTX2 3D texture in `format`,
/// rounded down with [`DistanceMap::quantized`] so it stays conservative.
pub fn to_bytes(
    map: &DistanceMap,
    extent: Extent,
    format: Format,
) -> std::result::Result<Vec<u8>, FormatError> {
    to_bytes_with_keys(map, extent, format, &[])
}

/// [`to_bytes`] with the caller's own key/value pairs beside the
/// `displace.*` ones (the spec lets a writer add any, sorted among the
/// rest); a key this writer writes itself is refused.
pub fn to_bytes_with_keys(
    map: &DistanceMap,
    extent: Extent,
    format: Format,
    extra: &[(&str, &str)],
) -> std::result::Result<Vec<u8>, FormatError> {
    check_writable(map, extent, format, extra)?;
    let [w, h, d] = map.size();
    let (q, range) = map.quantized(format);
    let mut out = header(
        [w, h, d],
        map.address(),
        q.data_underestimate(),
        extent,
        format,
        range,
        extra,
    );
    out.reserve(w * h * d * format.bytes_per_voxel());
    match (format, range) {
        // Encoded from the original values, as `quantized` does: re-encoding
        // an already decoded value could land one code lower.
        (Format::R8, Some(r)) => out.extend(map.data().iter().map(|&v| r.encode(v))),
        (Format::R16F, _) => {
            // Already representable: the conversion is exact.
            for &v in q.data() {
                out.extend_from_slice(&half::f16::from_f32(v).to_le_bytes());
            }
        }
        _ => {
            for &v in q.data() {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    Ok(out)
}

/// Refuses a map [`to_bytes_with_keys`] cannot write: a key of the
/// writer's own among `extra`, an `extent` of other proportions than the
/// map was baked for, sizes past KTX2's 32 bits.
fn check_writable(
    map: &DistanceMap,
    extent: Extent,
    format: Format,
    extra: &[(&str, &str)],
) -> std::result::Result<(), FormatError> {
    let own = key_values(map.address(), 0.0, extent, format, None);
    if let Some((k, _)) = extra
        .iter()
        .find(|(k, _)| *k == "displace.r8_range" || own.iter().any(|(o, _)| o == k))
    {
        return Err(FormatError::Invalid(format!(
            "key `{k}` is the writer's own"
        )));
    }
    let [w, h, d] = map.size();
    let (a, b) = (map.aspect(), extent.aspect());
    if (a[0] - b[0]).abs() > 1e-4 * a[0] || (a[1] - b[1]).abs() > 1e-4 * a[1] {
        return Err(FormatError::Invalid(format!(
            "the map was baked for aspect {a:?} but extent {},{},{} has aspect {b:?}",
            extent.sx, extent.sy, extent.sz
        )));
    }
    if [w, h, d].iter().any(|&n| n > u32::MAX as usize) {
        return Err(FormatError::Unsupported(format!(
            "{w}x{h}x{d} exceeds KTX2's 32-bit sizes"
        )));
    }
    Ok(())
}

/// The header (identifier, index, format descriptor, key/value data and
/// padding) of [`to_bytes_with_keys`] in [`Format::R32F`], without the
/// values: r32f stores the map's values as they are, so a writer can
/// stream them after it from the map itself rather than build the whole
/// file in memory (the bake cache's entries, as large as the map).
pub fn r32f_header_with_keys(
    map: &DistanceMap,
    extent: Extent,
    extra: &[(&str, &str)],
) -> std::result::Result<Vec<u8>, FormatError> {
    check_writable(map, extent, Format::R32F, extra)?;
    Ok(header(
        map.size(),
        map.address(),
        map.data_underestimate(),
        extent,
        Format::R32F,
        None,
        extra,
    ))
}

/// Writes `map` as a KTX2 file, atomically.
pub fn write(path: &Path, map: &DistanceMap, extent: Extent, format: Format) -> Result<()> {
    let bytes = to_bytes(map, extent, format).map_err(|e| e.at(path))?;
    super::atomic::write_atomic(path, |w| w.write_all(&bytes))
}

/// A distance map read back from KTX2, with what its key/value data says.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The distance map, values decoded to depth units.
    pub map: DistanceMap,
    /// The tile's physical size, from the `displace.extent` key.
    pub extent: Extent,
    /// The storage format of the file's voxels.
    pub format: Format,
    /// The `KTXwriter` key (the tool that wrote the file), if present.
    pub writer: Option<String>,
    /// Every key/value pair of the file, values without their NUL.
    pub keys: std::collections::BTreeMap<String, String>,
}

/// Checks what the `ktx2` crate's parser would panic on rather than
/// refuse (found by tests/fuzz.rs of displace-render): a data format
/// descriptor range past the file or shorter than its length field, and a
/// basic descriptor block whose texel block dimension byte is 255 (the
/// crate adds 1 to it in a `u8` and unwraps a `NonZeroU8`). Anything else
/// is left to that parser, which reports it.
fn check_dfd(bytes: &[u8]) -> std::result::Result<(), FormatError> {
    let u32_at = |o: usize| -> Option<u32> {
        Some(u32::from_le_bytes(bytes.get(o..o + 4)?.try_into().ok()?))
    };
    let (Some(offset), Some(length)) = (u32_at(48), u32_at(52)) else {
        return Ok(()); // A short header: the parser says it is cut off.
    };
    let (offset, length) = (offset as usize, length as usize);
    let end = offset
        .checked_add(length)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| FormatError::Truncated("the data format descriptor is cut off".into()))?;
    if length < 4 {
        return Err(FormatError::Invalid(format!(
            "the data format descriptor is {length} bytes, shorter than its length field"
        )));
    }
    let mut at = offset + 4;
    while at + 8 <= end {
        let size = u16::from_le_bytes([bytes[at + 6], bytes[at + 7]]) as usize;
        if size < 8 || at + size > end {
            return Ok(()); // The parser refuses a bad block size.
        }
        let basic = u32_at(at) == Some(0);
        if basic && size >= 16 && bytes[at + 12..at + 16].contains(&255) {
            return Err(FormatError::Invalid(
                "a texel block dimension of the data format descriptor is 256 (at most 255)".into(),
            ));
        }
        at += size;
    }
    Ok(())
}

/// Decodes a KTX2 distance map written by [`to_bytes`] (or any tool that
/// writes the same `displace.*` keys), checking the sizes in the header
/// before allocating.
pub fn from_bytes(bytes: &[u8]) -> std::result::Result<Decoded, FormatError> {
    if bytes.len() < IDENTIFIER.len() || bytes[..IDENTIFIER.len()] != IDENTIFIER {
        return Err(FormatError::BadMagic("KTX2"));
    }
    check_dfd(bytes)?;
    let reader = ::ktx2::Reader::new(bytes).map_err(|e| match e {
        ::ktx2::ParseError::UnexpectedEnd => {
            FormatError::Truncated("the KTX2 container is cut off".into())
        }
        other => FormatError::Invalid(format!("KTX2 container: {other:?}")),
    })?;
    let header = reader.header();
    let format = match header.format.map(|f| f.value()) {
        Some(VK_FORMAT_R8_UNORM) => Format::R8,
        Some(VK_FORMAT_R16_SFLOAT) => Format::R16F,
        Some(VK_FORMAT_R32_SFLOAT) => Format::R32F,
        other => {
            return Err(FormatError::Unsupported(format!(
                "VkFormat {} (expected R8_UNORM, R16_SFLOAT or R32_SFLOAT)",
                other.map_or("UNDEFINED".to_string(), |v| v.to_string())
            )))
        }
    };
    if header.supercompression_scheme.is_some() {
        return Err(FormatError::Unsupported("supercompressed KTX2 data".into()));
    }
    if header.pixel_depth < 2 || header.pixel_height == 0 {
        return Err(FormatError::Unsupported(format!(
            "a {}x{}x{} texture: a distance map is a 3D texture (depth >= 2)",
            header.pixel_width, header.pixel_height, header.pixel_depth
        )));
    }
    if header.layer_count > 1 || header.face_count != 1 {
        return Err(FormatError::Unsupported(
            "array or cube-map textures".into(),
        ));
    }
    let size = [
        header.pixel_width as usize,
        header.pixel_height as usize,
        header.pixel_depth as usize,
    ];
    DistanceMap::check_size(size)?;

    let mut kv = std::collections::BTreeMap::new();
    for (k, v) in reader.key_value_data() {
        let v = v.strip_suffix(&[0]).unwrap_or(v);
        kv.insert(k.to_string(), String::from_utf8_lossy(v).into_owned());
    }
    let writer = kv.get("KTXwriter").cloned();
    let get = |key: &str| {
        kv.get(key).ok_or_else(|| {
            FormatError::Invalid(format!(
                "no `{key}` key: not a displace distance map (written by {})",
                writer.as_deref().unwrap_or("an unknown tool")
            ))
        })
    };
    let floats = |key: &str, n: usize| -> std::result::Result<Vec<f32>, FormatError> {
        let text = get(key)?;
        let v: Vec<f32> = text
            .split(',')
            .map(|s| s.trim().parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| FormatError::Invalid(format!("`{key}` = `{text}` is not {n} numbers")))?;
        if v.len() != n || v.iter().any(|x| !x.is_finite()) {
            return Err(FormatError::Invalid(format!(
                "`{key}` = `{text}` is not {n} finite numbers"
            )));
        }
        Ok(v)
    };
    let e = floats("displace.extent", 3)?;
    let extent = Extent::new(e[0], e[1], e[2])?;
    let address: Address = get("displace.addressing")?
        .parse()
        .map_err(|err: crate::Error| FormatError::Invalid(err.to_string()))?;
    let bound = floats("displace.max_underestimate", 1)?[0];
    let units = get("displace.units")?;
    if units != "shell depths" {
        return Err(FormatError::Unsupported(format!(
            "`displace.units` = `{units}` (expected `shell depths`)"
        )));
    }
    let range = if format == Format::R8 {
        let r = floats("displace.r8_range", 2)?;
        if r[1] <= r[0] {
            return Err(FormatError::Invalid(format!(
                "`displace.r8_range` {r:?} is empty"
            )));
        }
        Some(R8Range {
            min: r[0],
            max: r[1],
        })
    } else {
        None
    };

    let level = reader
        .levels()
        .next()
        .ok_or_else(|| FormatError::Invalid("no mip level".into()))?;
    let count = size[0] * size[1] * size[2];
    let need = count * format.bytes_per_voxel();
    if level.data.len() != need {
        return Err(FormatError::Invalid(format!(
            "level 0 holds {} bytes but {}x{}x{} {} needs {need}",
            level.data.len(),
            size[0],
            size[1],
            size[2],
            format.name()
        )));
    }
    let data: Vec<f32> = match (format, range) {
        (Format::R8, Some(r)) => level.data.iter().map(|&c| r.decode(c)).collect(),
        (Format::R16F, _) => level
            .data
            .chunks_exact(2)
            .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
            .collect(),
        _ => level
            .data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
    };
    super::check_no_nan(&data, size)?;
    super::check_plausible(&data, size, extent.aspect())?;
    let map = DistanceMap::from_raw(size, extent.aspect(), address, data, bound)?;
    Ok(Decoded {
        map,
        extent,
        format,
        writer,
        keys: kv,
    })
}

/// Reads a KTX2 distance map and the extent it was baked for.
pub fn read_distance_map(path: &Path) -> Result<(DistanceMap, Extent)> {
    let bytes = super::read_bytes(path)?;
    let d = from_bytes(&bytes).map_err(|e| e.at(path))?;
    Ok((d.map, d.extent))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::assert_refused;
    use crate::{bake, generators, BakeOptions};

    fn baked(address: Address) -> (DistanceMap, Extent) {
        let extent = Extent::new(1.0, 0.5, 0.125).unwrap();
        let height = generators::generate("gen:gaussian", 20, 12, address).unwrap();
        let m = bake(&height, &BakeOptions::new([10, 6, 4], extent)).unwrap();
        (m.distance, extent)
    }

    #[test]
    fn the_ktx2_crate_reads_what_we_write() {
        let (map, extent) = baked(Address::Repeat);
        for format in [Format::R8, Format::R16F, Format::R32F] {
            let bytes = to_bytes(&map, extent, format).unwrap();
            let r = ::ktx2::Reader::new(&bytes[..]).expect("valid KTX2");
            let h = r.header();
            let (vk, ts) = vk_format(format);
            assert_eq!(h.format.map(|f| f.value()), Some(vk));
            assert_eq!(h.type_size, ts);
            assert_eq!((h.pixel_width, h.pixel_height, h.pixel_depth), (10, 6, 4));
            assert_eq!((h.layer_count, h.face_count, h.level_count), (0, 1, 1));
            assert!(h.supercompression_scheme.is_none());
            // Our descriptor is byte for byte what the crate generates for the format.
            let (basic, type_size) = ::ktx2::dfd::Basic::from_format(h.format.unwrap()).unwrap();
            assert_eq!(type_size, ts);
            let block = ::ktx2::dfd::Block::Basic(basic).to_vec();
            let start = h.index.dfd_byte_offset as usize;
            assert_eq!(h.index.dfd_byte_length as usize, 4 + block.len());
            assert_eq!(
                &bytes[start + 4..start + 4 + block.len()],
                &block[..],
                "{format:?}"
            );
            assert_eq!(
                r.transfer_function(),
                Some(::ktx2::TransferFunction::Linear)
            );
            // Key/value data: sorted, complete, parseable.
            let keys: Vec<&str> = r.key_value_data().map(|(k, _)| k).collect();
            let mut sorted = keys.clone();
            sorted.sort();
            assert_eq!(keys, sorted);
            assert!(r.writer().unwrap().starts_with("displace "));
            let kv: std::collections::HashMap<&str, &[u8]> = r.key_value_data().collect();
            assert_eq!(kv["displace.units"], b"shell depths\0");
            assert_eq!(kv["displace.addressing"], b"repeat\0");
            assert_eq!(kv["displace.extent"], b"1,0.5,0.125\0");
            assert_eq!(kv["displace.aspect"], b"8,4\0");
            assert!(
                kv.contains_key("displace.convention")
                    && kv.contains_key("displace.max_underestimate")
            );
            assert_eq!(kv.contains_key("displace.r8_range"), format == Format::R8);
            // Level data: aligned, complete.
            let level = r.levels().next().unwrap();
            assert_eq!(level.data.len(), 10 * 6 * 4 * format.bytes_per_voxel());
            assert_eq!(
                (level.data.as_ptr() as usize - bytes.as_ptr() as usize) % 4,
                0
            );
        }
    }

    #[test]
    fn round_trips_conservatively() {
        let (map, extent) = baked(Address::Clamp);
        for format in [Format::R8, Format::R16F, Format::R32F] {
            let bytes = to_bytes(&map, extent, format).unwrap();
            let d = from_bytes(&bytes).unwrap();
            assert_eq!(d.format, format);
            assert_eq!(d.extent, extent);
            assert_eq!(d.map.address(), Address::Clamp);
            assert_eq!(d.map.size(), map.size());
            let (q, _) = map.quantized(format);
            assert_eq!(
                d.map.data(),
                q.data(),
                "{format:?}: decoded differs from the quantised map"
            );
            assert!((d.map.max_underestimate() - q.max_underestimate()).abs() < 1e-6);
            for (a, b) in d.map.data().iter().zip(map.data()) {
                assert!(a <= b, "{format:?}: decoded {a} above original {b}");
            }
        }
    }

    #[test]
    fn refuses_malformed_files() {
        let (map, extent) = baked(Address::Clamp);
        let good = to_bytes(&map, extent, Format::R16F).unwrap();
        let err = |b: &[u8]| from_bytes(b).unwrap_err().to_string();
        assert_refused(&err, b"", &["bad magic"]);
        assert_refused(&err, b"DDS \x7c\0\0\0", &["bad magic"]);
        assert_refused(&err, &good[..50], &["truncated"]);
        assert_refused(&err, &good[..good.len() - 1], &["truncated"]);
        let mut huge = good.clone();
        huge[20..24].copy_from_slice(&100_000u32.to_le_bytes());
        huge[24..28].copy_from_slice(&100_000u32.to_le_bytes());
        huge[28..32].copy_from_slice(&1000u32.to_le_bytes());
        assert_refused(&err, &huge, &["too large"]);
        let mut flat = good.clone();
        flat[28..32].copy_from_slice(&0u32.to_le_bytes());
        assert_refused(&err, &flat, &["3D texture"]);
        let mut rgba = good.clone();
        rgba[12..16].copy_from_slice(&37u32.to_le_bytes());
        assert_refused(&err, &rgba, &["VkFormat 37"]);
        // A KTX2 file without our keys.
        let mut foreign = good.clone();
        let kvd = 104 + 44;
        let pos = foreign[kvd..]
            .windows(15)
            .position(|w| w == b"displace.extent")
            .unwrap();
        foreign[kvd + pos] = b'X';
        assert!(
            err(&foreign).contains("displace.extent"),
            "{}",
            err(&foreign)
        );
        // Found by fuzzing: what the ktx2 crate panics on is refused first.
        let dfd = u32::from_le_bytes(good[48..52].try_into().unwrap()) as usize;
        let mut dims = good.clone();
        dims[dfd + 4 + 12] = 255;
        assert!(
            err(&dims).contains("texel block dimension"),
            "{}",
            err(&dims)
        );
        let mut past = good.clone();
        past[52..56].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(err(&past).contains("truncated"), "{}", err(&past));
        let mut short = good.clone();
        short[52..56].copy_from_slice(&2u32.to_le_bytes());
        assert!(err(&short).contains("descriptor"), "{}", err(&short));
    }

    #[test]
    fn extra_keys_are_sorted_in_and_read_back() {
        let (map, extent) = baked(Address::Clamp);
        let bytes =
            to_bytes_with_keys(&map, extent, Format::R32F, &[("displace.cache_x", "7")]).unwrap();
        let r = ::ktx2::Reader::new(&bytes[..]).expect("valid KTX2");
        let keys: Vec<&str> = r.key_value_data().map(|(k, _)| k).collect();
        let mut sorted = keys.clone();
        sorted.sort();
        assert_eq!(keys, sorted);
        let d = from_bytes(&bytes).unwrap();
        assert_eq!(d.keys["displace.cache_x"], "7");
        assert_eq!(d.keys["displace.units"], "shell depths");
        assert_eq!(d.map.data(), map.data());
        for own in ["displace.extent", "KTXwriter", "displace.r8_range"] {
            let e = to_bytes_with_keys(&map, extent, Format::R32F, &[(own, "1")]).unwrap_err();
            assert!(e.to_string().contains(own), "{e}");
        }
    }

    #[test]
    fn path_level_round_trip() {
        let (map, extent) = baked(Address::Repeat);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ktx2");
        write(&p, &map, extent, Format::R32F).unwrap();
        let (back, e) = read_distance_map(&p).unwrap();
        assert_eq!(e, extent);
        assert_eq!(back.data(), map.data());
        assert_eq!(
            (back.size(), back.aspect(), back.address()),
            (map.size(), map.aspect(), map.address())
        );
        assert!((back.max_underestimate() - map.max_underestimate()).abs() < 1e-6);
        std::fs::write(&p, &b"\xABKTX 20\xBB\r\n\x1A\n"[..]).unwrap();
        let e = read_distance_map(&p).unwrap_err().to_string();
        assert!(e.contains("m.ktx2") && e.contains("truncated"), "{e}");
        let wrong = Extent::new(2.0, 0.5, 0.125).unwrap();
        assert!(to_bytes(&map, wrong, Format::R8)
            .unwrap_err()
            .to_string()
            .contains("aspect"));
    }
}
