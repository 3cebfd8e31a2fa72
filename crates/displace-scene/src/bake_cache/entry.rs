//! One bake cache entry on disk, `<key>.ktx2`: the distance map as a KTX
//! 2.0 3D texture in r32f, written by the writer `displace bake` uses and
//! read back by the same reader ([`displace_core::io::ktx2`]), so an entry
//! is also a map any KTX2 tool opens. Its key/value data carries the size,
//! the aspect (as the extent `ax,ay,1`), the addressing and the bound on the
//! values' underestimate; r32f keeps every value bit-exact, so a map read
//! back traces exactly as the one baked.
//!
//! The cache adds one key, `displace.cache_checksum`: 16 lowercase hex
//! digits of a hash of the whole file as written with those digits all
//! `0`. A flipped bit anywhere, in the header, the keys or the values, is
//! caught and the entry baked again rather than trusted, since a wrong
//! distance would make the tracer step through the surface (Donnelly, GPU
//! Gems 2 ch. 8, section 8.3: each step may advance only as far as the
//! distance says is empty). A KTX2 map without the key (one `displace
//! bake` wrote) is another tool's file, not an entry: it is baked again.

use crate::sampler::hash_iter;
use displace_core::distance_map::Format;
use displace_core::io::atomic::write_atomic;
use displace_core::io::{check_input, ktx2, MAX_ARRAY_FILE_BYTES};
use displace_core::{Address, DistanceMap, Extent};
use std::path::Path;

/// The file name extension of an entry.
pub(super) const EXTENSION: &str = "ktx2";

/// The key of the entry's checksum.
const CHECKSUM_KEY: &str = "displace.cache_checksum";

/// The checksum's digits while it is computed.
const UNSET: &[u8; 16] = b"0000000000000000";

/// Writes `map` (baked for the canonical `extent`, depth 1) to `path`,
/// atomically.
pub(super) fn write(path: &Path, map: &DistanceMap, extent: Extent) -> displace_core::Result<()> {
    let unset = std::str::from_utf8(UNSET).expect("ASCII");
    // The header alone in memory; the values are hashed and then written
    // from the map itself. Built whole, the file (and the r32f copy made on
    // the way) held twice the map's memory again while it was written.
    let mut head = ktx2::r32f_header_with_keys(map, extent, &[(CHECKSUM_KEY, unset)])
        .map_err(|e| e.at(path))?;
    let at = checksum_at(&head).expect("the checksum key was just written");
    let sum = format!("{:016x}", streamed_checksum(&head, at, map.data()));
    head[at..at + UNSET.len()].copy_from_slice(sum.as_bytes());
    write_atomic(path, |w| {
        w.write_all(&head)?;
        let mut buf = Vec::with_capacity(1 << 16);
        for chunk in map.data().chunks(1 << 14) {
            buf.clear();
            buf.extend(chunk.iter().flat_map(|v| v.to_le_bytes()));
            w.write_all(&buf)?;
        }
        Ok(())
    })
}

/// [`checksum`] of the file made of `head` and then the values `data` as
/// little-endian r32f, without that file in memory: the same words (the
/// length, then each part in words of eight from its own start, the last
/// word of a part padded with zeros).
fn streamed_checksum(head: &[u8], at: usize, data: &[f32]) -> u64 {
    let len = head.len() + 4 * data.len();
    let rest = head[at + UNSET.len()..]
        .iter()
        .copied()
        .chain(data.iter().flat_map(|v| v.to_le_bytes()));
    let words_of = |part: &[u8]| -> Vec<u64> { words(part.iter().copied()).collect() };
    hash_iter(
        std::iter::once(len as u64)
            .chain(words_of(&head[..at]))
            .chain(words_of(UNSET))
            .chain(words(rest)),
    )
}

/// `bytes` in little-endian words of eight, the last padded with zeros.
fn words(mut bytes: impl Iterator<Item = u8>) -> impl Iterator<Item = u64> {
    std::iter::from_fn(move || {
        let mut word = [0u8; 8];
        let mut n = 0;
        while n < 8 {
            let Some(b) = bytes.next() else { break };
            word[n] = b;
            n += 1;
        }
        (n > 0).then(|| u64::from_le_bytes(word))
    })
}

/// What is at an entry's path.
pub(super) enum Entry {
    /// Nothing: the map was never baked here.
    Absent,
    /// The map asked for.
    Found(DistanceMap),
    /// A file that is not the entry asked for (corrupt, truncated, another
    /// tool's or other settings'), and why.
    Unusable(String),
}

/// The entry at `path` for a `size` map of `aspect` and `address`.
pub(super) fn read(path: &Path, size: [usize; 3], aspect: [f32; 2], address: Address) -> Entry {
    if std::fs::symlink_metadata(path).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound) {
        return Entry::Absent;
    }
    // An entry replaced by a FIFO or a device must not hang the run.
    let found = check_input(path, "cache entry", MAX_ARRAY_FILE_BYTES)
        .map_err(|e| e.to_string())
        .and_then(|_| std::fs::read(path).map_err(|e| e.to_string()))
        .and_then(|b| decode(&b, size, aspect, address));
    match found {
        Ok(map) => Entry::Found(map),
        Err(why) => Entry::Unusable(why),
    }
}

/// The map in `bytes` if they are an intact entry for these settings.
fn decode(
    bytes: &[u8],
    size: [usize; 3],
    aspect: [f32; 2],
    address: Address,
) -> Result<DistanceMap, String> {
    let at = checksum_at(bytes)
        .ok_or_else(|| format!("no `{CHECKSUM_KEY}` key: not a bake cache entry"))?;
    let sum = format!("{:016x}", checksum(bytes, at));
    if bytes[at..at + UNSET.len()] != *sum.as_bytes() {
        return Err("the checksum does not match: the file is corrupt".into());
    }
    let d = ktx2::from_bytes(bytes).map_err(|e| e.to_string())?;
    let m = d.map;
    if d.format != Format::R32F
        || m.size() != size
        || m.aspect() != aspect
        || m.address() != address
    {
        return Err(format!(
            "an {} {:?} map of aspect {:?}, {} addressing, not the r32f {size:?} map of aspect \
             {aspect:?}, {} addressing asked for",
            d.format.name(),
            m.size(),
            m.aspect(),
            m.address().name(),
            address.name()
        ));
    }
    Ok(m)
}

/// Where the checksum's digits start: after the first `key NUL` of the
/// checksum key (the key/value data precedes the level data), with room
/// for the digits.
fn checksum_at(bytes: &[u8]) -> Option<usize> {
    let key = [CHECKSUM_KEY.as_bytes(), b"\0"].concat();
    let at = bytes.windows(key.len()).position(|w| w == key)? + key.len();
    (at + UNSET.len() <= bytes.len()).then_some(at)
}

/// The hash of `bytes` (their length first) with the checksum's digits at
/// `at` read as [`UNSET`], eight bytes a word.
fn checksum(bytes: &[u8], at: usize) -> u64 {
    let parts = [&bytes[..at], &UNSET[..], &bytes[at + UNSET.len()..]];
    let words = parts.into_iter().flat_map(|p| p.chunks(8)).map(|c| {
        let mut word = [0u8; 8];
        word[..c.len()].copy_from_slice(c);
        u64::from_le_bytes(word)
    });
    hash_iter(std::iter::once(bytes.len() as u64).chain(words))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streamed entry is the file the whole-file writer makes, byte for
    /// byte, and its streamed checksum is the checksum of those bytes: on
    /// maps whose headers put the digits at different word offsets.
    #[test]
    fn streamed_entries_equal_whole_ones() {
        for (n, depth) in [(8, 4), (13, 3), (16, 8)] {
            let h =
                displace_core::generators::generate("gen:gaussian", n, n, Address::Clamp).unwrap();
            let extent = Extent::new(1.0, 1.0, 1.0).unwrap();
            let map =
                displace_core::bake(&h, &displace_core::BakeOptions::new([n, n, depth], extent))
                    .unwrap()
                    .distance;
            let unset = std::str::from_utf8(UNSET).unwrap();
            let keys = [(CHECKSUM_KEY, unset)];
            let whole = ktx2::to_bytes_with_keys(&map, extent, Format::R32F, &keys).unwrap();
            let head = ktx2::r32f_header_with_keys(&map, extent, &keys).unwrap();
            let streamed: Vec<u8> = head
                .iter()
                .copied()
                .chain(map.data().iter().flat_map(|v| v.to_le_bytes()))
                .collect();
            assert_eq!(whole, streamed, "{n}x{n}x{depth}");
            let at = checksum_at(&whole).unwrap();
            assert_eq!(
                streamed_checksum(&head, at, map.data()),
                checksum(&whole, at)
            );
        }
    }
}
