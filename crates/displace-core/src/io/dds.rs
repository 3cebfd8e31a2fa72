//! DDS volume textures, the container KlayGE's distance-mapping tool writes
//! its 256x256x16 8-bit maps in (Donnelly's sample shipped the same shape).
//! `ddsfile` writes and parses the container; this module maps voxels in and
//! out.
//!
//! **What DDS cannot carry.** A DDS header has no place for key/value data,
//! so a `.dds` map holds the voxels only: the extent (hence the aspect the
//! distances are valid for), the addressing and the underestimate bound must
//! come from the user when reading it back ([`read`]); the bound is assumed
//! to be the bake's ([`super::bake_underestimate`]). Values are signed
//! distances in shell depths, `[k][j][i]` with texel centres, as everywhere.
//!
//! * `R32_FLOAT`, `R16_FLOAT`: the values themselves (half floats rounded
//!   down, so still conservative).
//! * `R8_UNORM`: a **fixed** range, [`DDS_R8_RANGE`], `value = -1.5 + 4
//!   code / 255`, because DDS cannot record the per-map range KTX2 stores.
//!   Values are rounded down to a code; a map with values below `-1.5` (only
//!   absurdly coarse bakes, whose voxel diagonal exceeds a shell depth) is
//!   refused rather than clamped up, which would break conservativeness.
//!   Values above `2.5` clamp down to it, which stays safe.

use super::FormatError;
use crate::distance_map::{f16_round_down, Format, R8Range, R8_SPAN};
use crate::{Address, DistanceMap, Extent, Result};
use ddsfile::{
    AlphaMode, Caps2, D3D10ResourceDimension, D3DFormat, Dds, DxgiFormat, NewDxgiParams,
};
use std::path::Path;

/// The one range every R8 DDS map is encoded with (see the module docs).
pub const DDS_R8_RANGE: R8Range = R8Range {
    min: -1.5,
    max: -1.5 + R8_SPAN,
};

fn dxgi(format: Format) -> DxgiFormat {
    match format {
        Format::R8 => DxgiFormat::R8_UNorm,
        Format::R16F => DxgiFormat::R16_Float,
        Format::R32F => DxgiFormat::R32_Float,
    }
}

/// Refuses a volume a DDS header cannot describe.
pub(crate) fn check_size(size: [usize; 3], format: Format) -> std::result::Result<(), FormatError> {
    let [w, h, d] = size;
    let bytes = (w * h * d) as u128 * format.bytes_per_voxel() as u128;
    if bytes > u32::MAX as u128 || [w, h, d].iter().any(|&n| n > u32::MAX as usize) {
        return Err(FormatError::Unsupported(format!(
            "a {w}x{h}x{d} {} volume needs {bytes} bytes, more than a DDS file can describe (4 GiB)",
            format.name()
        )));
    }
    Ok(())
}

/// Refuses an R8 map whose lowest value `lo` is below [`DDS_R8_RANGE`]:
/// clamping it up would break conservativeness.
pub(crate) fn check_r8_min(lo: f32) -> std::result::Result<(), FormatError> {
    if lo < DDS_R8_RANGE.min {
        return Err(FormatError::Unsupported(format!(
            "the map holds {lo} shell depths, below the fixed R8 range of DDS ({}..{}); \
             write r16f/r32f or a .ktx2 file (which records its own range)",
            DDS_R8_RANGE.min, DDS_R8_RANGE.max
        )));
    }
    Ok(())
}

/// The container for a `size` volume in `format` (its data zeroed, which
/// costs no memory until written).
fn new_dds(size: [usize; 3], format: Format) -> std::result::Result<Dds, FormatError> {
    let [w, h, d] = size;
    Dds::new_dxgi(NewDxgiParams {
        height: h as u32,
        width: w as u32,
        depth: Some(d as u32),
        format: dxgi(format),
        mipmap_levels: Some(1),
        array_layers: None,
        caps2: Some(Caps2::VOLUME),
        is_cubemap: false,
        resource_dimension: D3D10ResourceDimension::Texture3D,
        alpha_mode: AlphaMode::Unknown,
    })
    .map_err(|e| FormatError::Unsupported(format!("DDS: {e}")))
}

/// The bytes of a DDS file before its voxels (magic, header, DX10 header),
/// exactly as [`to_bytes`] writes them: for the streamed writer.
pub(crate) fn header(
    size: [usize; 3],
    format: Format,
) -> std::result::Result<Vec<u8>, FormatError> {
    check_size(size, format)?;
    let mut dds = new_dds(size, format)?;
    dds.data = Vec::new();
    let mut bytes = Vec::with_capacity(148);
    dds.write(&mut bytes)
        .map_err(|e| FormatError::Invalid(format!("DDS: {e}")))?;
    Ok(bytes)
}

/// Encodes `map` as the bytes of a DDS volume texture (DX10 header, one mip
/// level), rounding values down to `format`.
pub fn to_bytes(map: &DistanceMap, format: Format) -> std::result::Result<Vec<u8>, FormatError> {
    let [w, h, d] = map.size();
    check_size([w, h, d], format)?;
    if format == Format::R8 {
        let lo = map.data().iter().copied().fold(f32::INFINITY, f32::min);
        check_r8_min(lo)?;
    }
    let mut dds = new_dds([w, h, d], format)?;
    let out = dds
        .get_mut_data(0)
        .map_err(|e| FormatError::Invalid(format!("DDS layout: {e}")))?;
    let values = map.data();
    match format {
        Format::R8 => {
            for (o, &v) in out.iter_mut().zip(values) {
                *o = DDS_R8_RANGE.encode(v);
            }
        }
        Format::R16F => {
            for (o, &v) in out.chunks_exact_mut(2).zip(values) {
                o.copy_from_slice(&f16_round_down(v).to_le_bytes());
            }
        }
        Format::R32F => {
            for (o, &v) in out.chunks_exact_mut(4).zip(values) {
                o.copy_from_slice(&v.to_le_bytes());
            }
        }
    }
    let mut bytes = Vec::with_capacity(out.len() + 148);
    dds.write(&mut bytes)
        .map_err(|e| FormatError::Invalid(format!("DDS: {e}")))?;
    Ok(bytes)
}

/// Writes `map` as a DDS volume texture, atomically.
pub fn write(path: &Path, map: &DistanceMap, format: Format) -> Result<()> {
    let bytes = to_bytes(map, format).map_err(|e| e.at(path))?;
    super::atomic::write_atomic(path, |w| w.write_all(&bytes))
}

/// Decodes a DDS volume texture (DX10 `R8_UNORM`, `R16_FLOAT`, `R32_FLOAT`,
/// or the legacy `L8`, `R16F`, `R32F`) into a distance map for one tile of
/// `extent` with `address`ing. Returns the storage format found too.
pub fn from_bytes(
    bytes: &[u8],
    extent: Extent,
    address: Address,
) -> std::result::Result<(DistanceMap, Format), FormatError> {
    if bytes.len() < 4 || &bytes[..4] != b"DDS " {
        return Err(FormatError::BadMagic("DDS"));
    }
    let dds = Dds::read(bytes).map_err(|e| match e {
        ddsfile::Error::Io(_) => FormatError::Truncated("the DDS header is cut off".into()),
        other => FormatError::Invalid(format!("DDS header: {other}")),
    })?;
    let format = if let Some(f) = dds.get_dxgi_format() {
        match f {
            DxgiFormat::R8_UNorm => Format::R8,
            DxgiFormat::R16_Float => Format::R16F,
            DxgiFormat::R32_Float => Format::R32F,
            other => {
                return Err(FormatError::Unsupported(format!(
                    "DXGI format {other:?} (expected R8_UNORM, R16_FLOAT or R32_FLOAT)"
                )))
            }
        }
    } else {
        match dds.get_d3d_format() {
            Some(D3DFormat::L8) => Format::R8,
            Some(D3DFormat::R16F) => Format::R16F,
            Some(D3DFormat::R32F) => Format::R32F,
            Some(other) => {
                return Err(FormatError::Unsupported(format!(
                    "D3D format {other:?} (expected L8, R16F or R32F)"
                )))
            }
            None => {
                return Err(FormatError::Unsupported(
                    "DDS pixel format not recognised".into(),
                ))
            }
        }
    };
    let size = [
        dds.get_width() as usize,
        dds.get_height() as usize,
        dds.get_depth() as usize,
    ];
    if size[2] < 2 {
        return Err(FormatError::Unsupported(format!(
            "a {}x{} 2D texture: a distance map is a volume texture (depth >= 2)",
            size[0], size[1]
        )));
    }
    check_layout(&dds, size)?;
    DistanceMap::check_size(size)?;
    let count = size[0] * size[1] * size[2];
    let need = count * format.bytes_per_voxel();
    if dds.data.len() < need {
        return Err(FormatError::Truncated(format!(
            "{}x{}x{} {} needs {need} bytes of voxels but {} are present",
            size[0],
            size[1],
            size[2],
            format.name(),
            dds.data.len()
        )));
    }
    let raw = &dds.data[..need];
    let (data, quantum): (Vec<f32>, f32) = match format {
        Format::R8 => (
            raw.iter().map(|&c| DDS_R8_RANGE.decode(c)).collect(),
            DDS_R8_RANGE.quantum(),
        ),
        Format::R16F => {
            let data: Vec<f32> = raw
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect();
            // Rounding down to a half float lost at most one unit in the last
            // place: 2^-10 of the magnitude, or the smallest subnormal.
            let big = data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            (data, big * (1.0 / 1024.0) + 6.0e-8)
        }
        Format::R32F => (
            raw.chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            0.0,
        ),
    };
    super::check_no_nan(&data, size)?;
    super::check_plausible(&data, size, extent.aspect())?;
    let bound = super::bake_underestimate(size, extent.aspect(), quantum);
    let map = DistanceMap::from_raw(size, extent.aspect(), address, data, bound)?;
    Ok((map, format))
}

/// Refuses a header whose layout is not one volume texture, though its
/// depth says so: a DX10 resource that is not `Texture3D` (a 2D texture
/// with a depth field), a legacy header without the volume flag, more
/// than one array layer (as the KTX2 reader refuses arrays: which layer
/// would be the map?), or more mip levels than a texture of `size` has.
/// Only the first level is read, but a header that miscounts its levels
/// is not the file its writer meant.
fn check_layout(dds: &Dds, size: [usize; 3]) -> std::result::Result<(), FormatError> {
    let [w, h, d] = size;
    match &dds.header10 {
        Some(h10) if h10.resource_dimension != D3D10ResourceDimension::Texture3D => {
            return Err(FormatError::Unsupported(format!(
                "a {:?} resource {w}x{h} of depth {d}: a distance map is a volume texture \
                 (Texture3D)",
                h10.resource_dimension
            )));
        }
        None if !dds.header.caps2.contains(Caps2::VOLUME) => {
            return Err(FormatError::Unsupported(format!(
                "a {w}x{h} texture of depth {d} without the volume flag (DDSCAPS2_VOLUME): a \
                 distance map is a volume texture"
            )));
        }
        _ => {}
    }
    let layers = dds.get_num_array_layers();
    if layers > 1 {
        return Err(FormatError::Unsupported(format!(
            "{layers} array layers: a distance map is one volume texture"
        )));
    }
    let most = usize::BITS - w.max(h).max(d).leading_zeros();
    let levels = dds.get_num_mipmap_levels();
    if levels > most {
        return Err(FormatError::Invalid(format!(
            "{levels} mip levels for a {w}x{h}x{d} texture, which has at most {most}"
        )));
    }
    Ok(())
}

/// Reads a DDS distance map; `extent` and `address` must be the ones it was
/// baked for, since the file cannot say.
pub fn read(path: &Path, extent: Extent, address: Address) -> Result<DistanceMap> {
    let bytes = super::read_bytes(path)?;
    from_bytes(&bytes, extent, address)
        .map(|(m, _)| m)
        .map_err(|e| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::assert_refused;
    use crate::{bake, generators, BakeOptions};

    fn baked() -> (DistanceMap, Extent) {
        let extent = Extent::new(1.0, 1.0, 0.2).unwrap();
        let height = generators::generate("gen:gaussian", 16, 16, Address::Clamp).unwrap();
        let map = bake(&height, &BakeOptions::new([12, 10, 6], extent)).unwrap();
        (map.distance, extent)
    }

    #[test]
    fn round_trips_every_format_conservatively() {
        let (map, extent) = baked();
        for format in [Format::R8, Format::R16F, Format::R32F] {
            let bytes = to_bytes(&map, format).unwrap();
            let dds = Dds::read(&bytes[..]).unwrap();
            assert_eq!(dds.get_dxgi_format(), Some(dxgi(format)));
            assert_eq!(
                (dds.get_width(), dds.get_height(), dds.get_depth()),
                (12, 10, 6)
            );
            assert!(dds.header.caps2.contains(Caps2::VOLUME));
            let (back, f) = from_bytes(&bytes, extent, Address::Clamp).unwrap();
            assert_eq!(f, format);
            assert_eq!(back.size(), map.size());
            let step = match format {
                Format::R8 => DDS_R8_RANGE.quantum(),
                Format::R16F => 2e-3,
                Format::R32F => 0.0,
            };
            for (a, b) in back.data().iter().zip(map.data()) {
                assert!(a <= b, "{format:?}: decoded {a} above original {b}");
                assert!(b - a <= step + 1e-6 || (format == Format::R8 && *b > DDS_R8_RANGE.max));
            }
            assert!(back.max_underestimate() >= map.max_underestimate() - 1e-6);
        }
    }

    /// A 4x4 DXGI file (`depth` deep) of one mip level, as another writer
    /// would make it.
    fn dxgi_file(
        depth: Option<u32>,
        format: DxgiFormat,
        caps2: Option<Caps2>,
        resource_dimension: D3D10ResourceDimension,
    ) -> Vec<u8> {
        let dds = Dds::new_dxgi(NewDxgiParams {
            height: 4,
            width: 4,
            depth,
            format,
            mipmap_levels: Some(1),
            array_layers: None,
            caps2,
            is_cubemap: false,
            resource_dimension,
            alpha_mode: AlphaMode::Unknown,
        })
        .unwrap();
        let mut b = Vec::new();
        dds.write(&mut b).unwrap();
        b
    }

    #[test]
    fn refuses_what_r8_cannot_hold_and_malformed_files() {
        let (map, extent) = baked();
        let mut low = map.data().to_vec();
        low[0] = -2.0;
        let low =
            DistanceMap::from_raw(map.size(), map.aspect(), Address::Clamp, low, 0.1).unwrap();
        let e = to_bytes(&low, Format::R8).unwrap_err().to_string();
        assert!(e.contains("fixed R8 range"), "{e}");
        assert!(to_bytes(&low, Format::R16F).is_ok());

        let good = to_bytes(&map, Format::R16F).unwrap();
        let err = |b: &[u8]| {
            from_bytes(b, extent, Address::Clamp)
                .unwrap_err()
                .to_string()
        };
        assert_refused(&err, b"", &["bad magic"]);
        assert_refused(&err, b"\x89PNG\r\n\x1a\n", &["bad magic"]);
        assert_refused(&err, &good[..60], &["truncated"]);
        assert_refused(&err, &good[..good.len() - 10], &["truncated", "12x10x6"]);
        // A 2D texture is not a distance map.
        let flat = dxgi_file(
            None,
            DxgiFormat::R32_Float,
            None,
            D3D10ResourceDimension::Texture2D,
        );
        assert_refused(&err, &flat, &["volume texture"]);
        // Wrong pixel format.
        let rgba = dxgi_file(
            Some(4),
            DxgiFormat::R8G8B8A8_UNorm,
            Some(Caps2::VOLUME),
            D3D10ResourceDimension::Texture3D,
        );
        assert_refused(&err, &rgba, &["R8G8B8A8"]);
        // Headers that are not one volume texture: six array layers, a
        // 2D resource that claims a depth, a legacy header without the
        // volume flag, and a mip count no 12x10x6 texture has.
        let mut layered = Dds::read(&good[..]).unwrap();
        layered.header10.as_mut().unwrap().array_size = 6;
        let mut b = Vec::new();
        layered.write(&mut b).unwrap();
        assert_refused(&err, &b, &["6 array layers"]);
        let flat_deep = dxgi_file(
            Some(4),
            DxgiFormat::R32_Float,
            None,
            D3D10ResourceDimension::Texture2D,
        );
        assert_refused(&err, &flat_deep, &["Texture2D", "volume texture"]);
        // A legacy header (no DX10 extension) of `R32F`, its FourCC set by
        // hand: `ddsfile` writes that format's legacy pixel format as a
        // bit count that no reader takes for a float.
        let legacy = |caps2| {
            let mut dds = Dds::new_d3d(ddsfile::NewD3dParams {
                height: 4,
                width: 4,
                depth: Some(4),
                format: D3DFormat::R32F,
                mipmap_levels: Some(1),
                caps2,
            })
            .unwrap();
            dds.header.spf = ddsfile::PixelFormat {
                flags: ddsfile::PixelFormatFlags::FOURCC,
                fourcc: Some(ddsfile::FourCC(ddsfile::FourCC::R32F)),
                rgb_bit_count: None,
                r_bit_mask: None,
                g_bit_mask: None,
                b_bit_mask: None,
                a_bit_mask: None,
                ..dds.header.spf
            };
            let mut b = Vec::new();
            dds.write(&mut b).unwrap();
            b
        };
        assert_refused(&err, &legacy(None), &["volume flag"]);
        from_bytes(&legacy(Some(Caps2::VOLUME)), extent, Address::Clamp).unwrap();
        // The mip count, with its header flag (DDSD_MIPMAPCOUNT), patched
        // into the header's bytes as another writer would set them.
        let mut mips = good.clone();
        let flags = u32::from_le_bytes(mips[8..12].try_into().unwrap()) | 0x2_0000;
        mips[8..12].copy_from_slice(&flags.to_le_bytes());
        mips[28..32].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_refused(&err, &mips, &["4294967295 mip levels", "at most 4"]);
        // An absurd size in the header is refused before allocating.
        let mut huge = good.clone();
        for (off, v) in [(12usize, 100_000u32), (16, 100_000), (24, 1000)] {
            huge[off..off + 4].copy_from_slice(&v.to_le_bytes());
        }
        assert_refused(&err, &huge, &["too large"]);
    }

    #[test]
    fn path_level_round_trip_names_files() {
        let (map, extent) = baked();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.dds");
        write(&p, &map, Format::R32F).unwrap();
        let back = read(&p, extent, Address::Clamp).unwrap();
        assert_eq!(back.data(), map.data());
        std::fs::write(&p, b"DDS garbage").unwrap();
        let e = read(&p, extent, Address::Clamp).unwrap_err().to_string();
        assert!(e.contains("m.dds"), "{e}");
    }
}
