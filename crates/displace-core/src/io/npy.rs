//! NumPy `.npy` arrays (format versions 1.0 to 3.0, as `numpy.lib.format`
//! specifies them): the exchange format with Python tools. Reading accepts
//! only little-endian C-order float32, the one layout this project uses
//! for distance maps and rays; anything else is refused with its dtype named.
//! Writing emits version 1.0 with the header padded to 64 bytes, as numpy
//! itself does, for float32 and (for occupancy volumes) uint8.

use super::FormatError;
use crate::convention::check_allocation;
use crate::{Address, DistanceMap, Error, Extent, Result};
use std::io::Write;
use std::path::Path;

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// An element type this module writes (and reads).
pub trait Element: Copy + Send + Sync + 'static {
    /// The numpy `descr` string.
    const DESCR: &'static str;
    /// Bytes per element in the file.
    const SIZE: usize;
    /// Writes the element's bytes (little-endian) into `out`, `SIZE` long.
    fn put(self, out: &mut [u8]);
    /// Reads an element from the first `SIZE` bytes (little-endian).
    fn get(bytes: &[u8]) -> Self;
}

impl Element for f32 {
    const DESCR: &'static str = "<f4";
    const SIZE: usize = 4;
    fn put(self, out: &mut [u8]) {
        out.copy_from_slice(&self.to_le_bytes());
    }
    fn get(b: &[u8]) -> Self {
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
}

impl Element for u8 {
    const DESCR: &'static str = "|u1";
    const SIZE: usize = 1;
    fn put(self, out: &mut [u8]) {
        out[0] = self;
    }
    fn get(b: &[u8]) -> Self {
        b[0]
    }
}

/// A C-order array: `data[((i0 * s1) + i1) * s2 + ...]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Array<T> {
    /// Length of each axis, outermost first.
    pub shape: Vec<usize>,
    /// The elements in C order; `data.len()` is the product of `shape`.
    pub data: Vec<T>,
}

/// The version 1.0 header for `shape`, padded with spaces to a multiple of 64
/// bytes and ending in `\n`.
pub fn header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims = match shape.len() {
        1 => format!("{},", shape[0]),
        _ => shape
            .iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join(", "),
    };
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({dims}), }}");
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

/// Streams `data` with `shape` as a `.npy` file to `w`.
pub fn write<T: Element>(w: &mut dyn Write, shape: &[usize], data: &[T]) -> std::io::Result<()> {
    let n: usize = shape.iter().product();
    if n != data.len() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "shape {shape:?} holds {n} elements but {} were given",
                data.len()
            ),
        ));
    }
    w.write_all(&header(T::DESCR, shape))?;
    let mut buf = vec![0u8; 1 << 16];
    for chunk in data.chunks(buf.len() / T::SIZE) {
        let bytes = &mut buf[..chunk.len() * T::SIZE];
        for (v, out) in chunk.iter().zip(bytes.chunks_exact_mut(T::SIZE)) {
            v.put(out);
        }
        w.write_all(bytes)?;
    }
    Ok(())
}

/// The bytes of a `.npy` file holding `data` with `shape`.
pub fn to_bytes<T: Element>(shape: &[usize], data: &[T]) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    write(&mut out, shape, data)?;
    Ok(out)
}

/// Writes a `.npy` file atomically.
pub fn write_file<T: Element>(path: &Path, shape: &[usize], data: &[T]) -> Result<()> {
    super::atomic::write_atomic(path, |w| write(w, shape, data))
}

/// The parsed header: dtype, order and shape, and where the data starts.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// The NumPy dtype string, such as `<f4` or `|u1`.
    pub descr: String,
    /// True for column-major (Fortran) data, which readers here refuse.
    pub fortran_order: bool,
    /// Length of each axis, outermost first.
    pub shape: Vec<usize>,
    /// Byte offset of the first element: magic, version, length and header.
    pub data_offset: usize,
}

/// Parses and checks the header at the start of `bytes`.
pub fn parse_header(bytes: &[u8]) -> std::result::Result<Header, FormatError> {
    if bytes.len() < 8 || &bytes[..6] != MAGIC {
        return Err(if bytes.len() < 8 && MAGIC.starts_with(bytes) {
            FormatError::Truncated(format!(
                "{} bytes is too short for a .npy header",
                bytes.len()
            ))
        } else {
            FormatError::BadMagic("numpy .npy")
        });
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (len_bytes, utf8) = match major {
        1 => (2, false),
        2 => (4, false),
        3 => (4, true),
        _ => {
            return Err(FormatError::Unsupported(format!(
                ".npy format version {major}.{minor} (this reader knows 1.0, 2.0 and 3.0)"
            )))
        }
    };
    let start = 8 + len_bytes;
    if bytes.len() < start {
        return Err(FormatError::Truncated(
            "the header length is cut off".into(),
        ));
    }
    let header_len = if len_bytes == 2 {
        u16::from_le_bytes([bytes[8], bytes[9]]) as usize
    } else {
        u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize
    };
    let end = start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| {
            FormatError::Truncated(format!(
                "the header claims {header_len} bytes but the file ends after {}",
                bytes.len().saturating_sub(start)
            ))
        })?;
    let raw = &bytes[start..end];
    if !utf8 && !raw.is_ascii() {
        return Err(FormatError::Invalid("the header is not ASCII".into()));
    }
    let text = std::str::from_utf8(raw)
        .map_err(|_| FormatError::Invalid("the header is not UTF-8".into()))?;
    let (descr, fortran_order, shape) = parse_dict(text)?;
    Ok(Header {
        descr,
        fortran_order,
        shape,
        data_offset: end,
    })
}

/// Reads a little-endian C-order float32 array from the bytes of a `.npy`
/// file, refusing anything else before allocating for it.
pub fn from_bytes(bytes: &[u8]) -> std::result::Result<Array<f32>, FormatError> {
    from_bytes_as::<f32>(bytes)
}

/// As [`from_bytes`], for any [`Element`] type.
pub fn from_bytes_as<T: Element>(bytes: &[u8]) -> std::result::Result<Array<T>, FormatError> {
    let h = parse_header(bytes)?;
    if h.descr != T::DESCR {
        return Err(FormatError::Unsupported(format!(
            "dtype '{}' ({}): expected '{}' ({}); convert with arr.astype(np.{})",
            h.descr,
            dtype_name(&h.descr),
            T::DESCR,
            dtype_name(T::DESCR),
            numpy_name(T::DESCR),
        )));
    }
    if h.fortran_order {
        return Err(FormatError::Unsupported(
            "Fortran (column-major) order: save a C-order array (np.ascontiguousarray)".into(),
        ));
    }
    let count = h
        .shape
        .iter()
        .try_fold(1u128, |acc, &n| acc.checked_mul(n as u128))
        .ok_or_else(|| FormatError::Invalid(format!("shape {:?} overflows", h.shape)))?;
    check_allocation(
        "npy array",
        &format!("{:?}", h.shape),
        count,
        T::SIZE as u128,
    )?;
    let need = count as usize * T::SIZE;
    let have = bytes.len() - h.data_offset;
    if have < need {
        return Err(FormatError::Truncated(format!(
            "shape {:?} needs {need} bytes of data but only {have} are present",
            h.shape
        )));
    }
    if have > need {
        return Err(FormatError::Invalid(format!(
            "{} unexpected bytes after the data of shape {:?}",
            have - need,
            h.shape
        )));
    }
    let data = bytes[h.data_offset..]
        .chunks_exact(T::SIZE)
        .map(T::get)
        .collect();
    Ok(Array {
        shape: h.shape,
        data,
    })
}

/// Reads a float32 `.npy` file; errors name the file.
pub fn read_file(path: &Path) -> Result<Array<f32>> {
    read_file_as::<f32>(path)
}

/// As [`read_file`], for any [`Element`] type.
pub fn read_file_as<T: Element>(path: &Path) -> Result<Array<T>> {
    let bytes = super::read_bytes(path)?;
    from_bytes_as::<T>(&bytes).map_err(|e| e.at(path))
}

/// Writes `map` in the layout Python tools read: float32, shape `(D, H, W)`,
/// C order, element `[k][j][i]` the signed distance from voxel centre
/// `((i+0.5)/W SX, (j+0.5)/H SY, (k+0.5)/D SZ)` in the units of `extent`
/// (the map stores shell depths, so every value is scaled by `SZ`).
pub fn write_distance_map(path: &Path, map: &DistanceMap, extent: Extent) -> Result<()> {
    let [w, h, d] = map.size();
    let sz = extent.sz;
    super::atomic::write_atomic(path, |out| {
        out.write_all(&header(f32::DESCR, &[d, h, w]))?;
        let mut buf = Vec::with_capacity(w * h * 4);
        for slice in map.data().chunks(w * h) {
            buf.clear();
            for v in slice {
                buf.extend_from_slice(&(v * sz).to_le_bytes());
            }
            out.write_all(&buf)?;
        }
        Ok(())
    })
}

/// Reads a `(D, H, W)` float32 distance volume in physical units (as
/// [`write_distance_map`] writes it) back into a map for `extent`.
///
/// npy carries no bound on how far the values underestimate the distance, so
/// the bake's own bound for a map of this size is assumed
/// ([`super::bake_underestimate`]); values are used as they are.
pub fn read_distance_map(path: &Path, extent: Extent, address: Address) -> Result<DistanceMap> {
    let arr = read_file(path)?;
    let [d, h, w] = <[usize; 3]>::try_from(arr.shape.as_slice()).map_err(|_| Error::Format {
        path: path.to_path_buf(),
        message: format!("a distance map has shape (D, H, W), got {:?}", arr.shape),
    })?;
    if let Some(i) = arr.data.iter().position(|v| v.is_nan()) {
        return Err(Error::Format {
            path: path.to_path_buf(),
            message: format!(
                "element [{}][{}][{}] is NaN",
                i / (w * h),
                (i / w) % h,
                i % w
            ),
        });
    }
    let inv = 1.0 / extent.sz;
    let data: Vec<f32> = arr.data.into_iter().map(|v| v * inv).collect();
    let size = [w, h, d];
    super::check_plausible(&data, size, extent.aspect()).map_err(|e| Error::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    DistanceMap::from_raw(
        size,
        extent.aspect(),
        address,
        data,
        super::bake_underestimate(size, extent.aspect(), 0.0),
    )
    .map_err(|e| Error::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn dtype_name(descr: &str) -> String {
    let kind = descr.trim_start_matches(['<', '>', '|', '=']);
    let endian = match descr.chars().next() {
        Some('>') => ", big-endian",
        Some('<') if !kind.ends_with('1') => ", little-endian",
        _ => "",
    };
    let base = match kind {
        "f2" => "float16",
        "f4" => "float32",
        "f8" => "float64",
        "f16" => "float128",
        "i1" => "int8",
        "i2" => "int16",
        "i4" => "int32",
        "i8" => "int64",
        "u1" => "uint8",
        "u2" => "uint16",
        "u4" => "uint32",
        "u8" => "uint64",
        "b1" => "bool",
        "c8" => "complex64",
        "c16" => "complex128",
        _ => return format!("unsupported dtype{endian}"),
    };
    format!("{base}{endian}")
}

fn numpy_name(descr: &str) -> &'static str {
    match descr {
        "|u1" => "uint8",
        _ => "float32",
    }
}

/// The header dict: `{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }`,
/// a Python literal parsed just far enough for these three keys.
fn parse_dict(text: &str) -> std::result::Result<(String, bool, Vec<usize>), FormatError> {
    let bad =
        |what: &str| FormatError::Invalid(format!("bad header ({what}): {}", text.trim_end()));
    let mut p = Parser {
        s: text.as_bytes(),
        i: 0,
    };
    p.ws();
    if !p.eat(b'{') {
        return Err(bad("expected a dict"));
    }
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    loop {
        p.ws();
        if p.eat(b'}') {
            break;
        }
        let key = p.string().ok_or_else(|| bad("expected a key"))?;
        p.ws();
        if !p.eat(b':') {
            return Err(bad("expected `:`"));
        }
        p.ws();
        match key.as_str() {
            "descr" => {
                if p.peek() == Some(b'[') {
                    return Err(FormatError::Unsupported(
                        "structured dtypes: expected a plain float32 array".into(),
                    ));
                }
                descr = Some(p.string().ok_or_else(|| bad("descr is not a string"))?);
            }
            "fortran_order" => {
                fortran = Some(if p.word("True") {
                    true
                } else if p.word("False") {
                    false
                } else {
                    return Err(bad("fortran_order is not True or False"));
                })
            }
            "shape" => {
                shape = Some(
                    p.tuple()
                        .ok_or_else(|| bad("shape is not a tuple of whole numbers"))?,
                )
            }
            _ => return Err(bad(&format!("unexpected key `{key}`"))),
        }
        p.ws();
        if !p.eat(b',') {
            p.ws();
            if p.eat(b'}') {
                break;
            }
            return Err(bad("expected `,` or `}`"));
        }
    }
    p.ws();
    if p.i != p.s.len() {
        return Err(bad("text after the dict"));
    }
    match (descr, fortran, shape) {
        (Some(d), Some(f), Some(s)) => Ok((d, f, s)),
        _ => Err(bad("descr, fortran_order and shape are all required")),
    }
}

struct Parser<'a> {
    s: &'a [u8],
    i: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<u8> {
        self.s.get(self.i).copied()
    }
    fn ws(&mut self) {
        while matches!(self.peek(), Some(b' ' | b'\t' | b'\n' | b'\r')) {
            self.i += 1;
        }
    }
    fn eat(&mut self, c: u8) -> bool {
        if self.peek() == Some(c) {
            self.i += 1;
            true
        } else {
            false
        }
    }
    fn word(&mut self, w: &str) -> bool {
        if self.s[self.i..].starts_with(w.as_bytes()) {
            self.i += w.len();
            true
        } else {
            false
        }
    }
    fn string(&mut self) -> Option<String> {
        let q = self.peek().filter(|&c| c == b'\'' || c == b'"')?;
        self.i += 1;
        let start = self.i;
        while self.peek()? != q {
            self.i += 1;
        }
        let out = std::str::from_utf8(&self.s[start..self.i])
            .ok()?
            .to_string();
        self.i += 1;
        Some(out)
    }
    fn tuple(&mut self) -> Option<Vec<usize>> {
        if !self.eat(b'(') {
            return None;
        }
        let mut out = Vec::new();
        loop {
            self.ws();
            if self.eat(b')') {
                return Some(out);
            }
            let start = self.i;
            while matches!(self.peek(), Some(b'0'..=b'9')) {
                self.i += 1;
            }
            let digits = std::str::from_utf8(&self.s[start..self.i]).ok()?;
            // Python 2 era files may write `3L`.
            self.eat(b'L');
            out.push(digits.parse().ok()?);
            self.ws();
            if !self.eat(b',') {
                self.ws();
                return self.eat(b')').then_some(out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::assert_refused;
    use proptest::prelude::*;

    fn raw(version: u8, dict: &str, payload: &[u8]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&[version, 0]);
        if version == 1 {
            out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        } else {
            out.extend_from_slice(&(dict.len() as u32).to_le_bytes());
        }
        out.extend_from_slice(dict.as_bytes());
        out.extend_from_slice(payload);
        out
    }

    #[test]
    fn header_matches_numpy_byte_for_byte() {
        // np.save of np.zeros((2, 3), np.float32), header part.
        let h = header("<f4", &[2, 3]);
        let expect =
            b"\x93NUMPY\x01\x00v\x00{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }";
        assert_eq!(&h[..expect.len()], expect);
        assert_eq!(h.len(), 128);
        assert_eq!(*h.last().unwrap(), b'\n');
        assert!(h[expect.len()..h.len() - 1].iter().all(|&c| c == b' '));
        // One-element tuples keep their comma, as Python writes them.
        let h1 = String::from_utf8_lossy(&header("<f4", &[5])).into_owned();
        assert!(h1.contains("'shape': (5,)"), "{h1}");
        let h0 = String::from_utf8_lossy(&header("<f4", &[])).into_owned();
        assert!(h0.contains("'shape': ()"), "{h0}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(crate::random::property_cases(256)))]
        #[test]
        fn round_trips_any_shape(shape in prop::collection::vec(0usize..5, 0..5), seed in any::<u32>()) {
            let n: usize = shape.iter().product();
            let data: Vec<f32> = (0..n).map(|i| (i as f32 + seed as f32) * 0.37 - 3.0).collect();
            let bytes = to_bytes(&shape, &data).unwrap();
            prop_assert_eq!(bytes.len() % 64, (n * 4) % 64);
            let back = from_bytes(&bytes).unwrap();
            prop_assert_eq!(back.shape, shape);
            prop_assert_eq!(back.data, data);
        }
    }

    #[test]
    fn reads_versions_2_and_3_and_odd_spacing() {
        let payload: Vec<u8> = [1.5f32, -2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        for v in [1u8, 2, 3] {
            let b = raw(
                v,
                "{\"shape\":(2,),\"fortran_order\":False,\"descr\":\"<f4\"}\n",
                &payload,
            );
            let a = from_bytes(&b).unwrap();
            assert_eq!(a.shape, vec![2]);
            assert_eq!(a.data, vec![1.5, -2.0]);
        }
        let b = raw(
            1,
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1L, 2L)}",
            &payload,
        );
        assert_eq!(from_bytes(&b).unwrap().shape, vec![1, 2]);
    }

    #[test]
    fn u8_round_trip() {
        let data = vec![0u8, 1, 1, 0, 1, 0];
        let bytes = to_bytes(&[2, 3], &data).unwrap();
        assert!(String::from_utf8_lossy(&bytes).contains("'|u1'"));
        assert_eq!(from_bytes_as::<u8>(&bytes).unwrap().data, data);
    }

    fn err(bytes: &[u8]) -> String {
        from_bytes(bytes).unwrap_err().to_string()
    }

    #[test]
    fn refuses_malformed_input() {
        let good = to_bytes(&[2, 2], &[1.0f32, 2.0, 3.0, 4.0]).unwrap();
        // Bad magic, empty, truncated header, truncated data, extra data.
        assert_refused(&err, b"PK\x03\x04not numpy at all", &["bad magic"]);
        assert_refused(&err, b"", &["too short"]);
        assert_refused(&err, &good[..20], &["truncated"]);
        assert_refused(&err, &good[..good.len() - 3], &["truncated", "[2, 2]"]);
        let mut extra = good.clone();
        extra.push(0);
        assert_refused(&err, &extra, &["unexpected bytes"]);
        // Wrong dtypes are named.
        let e = err(&raw(
            1,
            "{'descr': '<f8', 'fortran_order': False, 'shape': (1,), }",
            &[0; 8],
        ));
        assert!(
            e.contains("'<f8'") && e.contains("float64") && e.contains("float32"),
            "{e}"
        );
        let e = err(&raw(
            1,
            "{'descr': '>f4', 'fortran_order': False, 'shape': (1,), }",
            &[0; 4],
        ));
        assert!(e.contains("big-endian"), "{e}");
        let e = err(&raw(
            1,
            "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (1,), }",
            &[0; 4],
        ));
        assert!(e.contains("structured"), "{e}");
        // Fortran order.
        let e = err(&raw(
            1,
            "{'descr': '<f4', 'fortran_order': True, 'shape': (1,), }",
            &[0; 4],
        ));
        assert!(e.contains("Fortran"), "{e}");
        // Garbled headers and unknown versions.
        assert!(err(&raw(1, "{'descr': '<f4', 'shape': (1,), }", &[0; 4])).contains("required"));
        assert!(err(&raw(1, "['descr']", &[])).contains("bad header"));
        assert!(err(&raw(
            1,
            "{'descr': '<f4', 'fortran_order': Maybe, 'shape': (1,)}",
            &[]
        ))
        .contains("fortran_order"));
        assert!(err(&raw(
            1,
            "{'descr': '<f4', 'fortran_order': False, 'shape': (-1,)}",
            &[]
        ))
        .contains("shape"));
        let mut v9 = good.clone();
        v9[6] = 9;
        assert!(err(&v9).contains("version 9.0"));
    }

    #[test]
    fn refuses_absurd_shapes_before_allocating() {
        let e = err(&raw(
            1,
            "{'descr': '<f4', 'fortran_order': False, 'shape': (100000, 100000, 1000), }",
            &[],
        ));
        assert!(e.contains("too large"), "{e}");
        let e = err(&raw(
            1,
            "{'descr': '<f4', 'fortran_order': False, 'shape': (18446744073709551615, 18446744073709551615, 4), }",
            &[],
        ));
        assert!(e.contains("overflows") || e.contains("too large"), "{e}");
    }

    #[test]
    fn path_level_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rays.npy");
        std::fs::write(&p, b"garbage").unwrap();
        let e = read_file(&p).unwrap_err().to_string();
        assert!(e.contains("rays.npy") && e.contains("bad magic"), "{e}");
        let e = read_file(&dir.path().join("missing.npy"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.npy"), "{e}");
    }

    #[test]
    fn distance_map_round_trips_in_physical_units() {
        let size = [3, 2, 2];
        let data: Vec<f32> = (0..12).map(|i| i as f32 * 0.1 - 0.5).collect();
        let extent = Extent::new(1.2, 0.8, 0.2).unwrap();
        let map = DistanceMap::from_raw(size, extent.aspect(), Address::Repeat, data.clone(), 0.3)
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.npy");
        write_distance_map(&p, &map, extent).unwrap();
        let arr = read_file(&p).unwrap();
        assert_eq!(arr.shape, vec![2, 2, 3]);
        for (a, b) in arr.data.iter().zip(&data) {
            assert!((a - b * 0.2).abs() < 1e-6);
        }
        let back = read_distance_map(&p, extent, Address::Repeat).unwrap();
        assert_eq!(back.size(), size);
        for (a, b) in back.data().iter().zip(&data) {
            assert!((a - b).abs() < 1e-5);
        }
        let e = read_distance_map(&dir.path().join("x.npy"), extent, Address::Clamp).unwrap_err();
        assert!(e.to_string().contains("x.npy"));
        write_file(&p, &[12], &data).unwrap();
        let e = read_distance_map(&p, extent, Address::Clamp)
            .unwrap_err()
            .to_string();
        assert!(e.contains("(D, H, W)") && e.contains("d.npy"), "{e}");
    }
}
