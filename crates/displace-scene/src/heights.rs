//! Height sources named in scenes: `gen:` generators or image files,
//! relative to the scene file, loaded by [`displace_core::io::height`].

use crate::error::Result;
use displace_core::io::height::{self, HeightOptions, HeightRange};
use displace_core::{Address, HeightMap};
use std::path::Path;

/// Loads `source` for a face: a generator spec at `size` texels, or a file
/// relative to `base` (its own size), its values mapped by `range`.
pub fn load(
    source: &str,
    size: [usize; 2],
    address: Address,
    range: HeightRange,
    base: &Path,
) -> Result<HeightMap> {
    let (source, opts) = resolve(source, size, address, range, base);
    Ok(height::load(&source, &opts)?)
}

/// The texel size [`load`] would give, from the file's header alone.
pub fn dimensions(
    source: &str,
    size: [usize; 2],
    address: Address,
    range: HeightRange,
    base: &Path,
) -> Result<[usize; 2]> {
    let (source, opts) = resolve(source, size, address, range, base);
    Ok(height::dimensions(&source, &opts)?)
}

/// The source as the core reads it (files relative to `base`) and its
/// options.
fn resolve(
    source: &str,
    size: [usize; 2],
    address: Address,
    range: HeightRange,
    base: &Path,
) -> (String, HeightOptions) {
    let opts = HeightOptions {
        size,
        address,
        range,
        ..HeightOptions::default()
    };
    if source.starts_with("gen:") {
        return (source.to_string(), opts);
    }
    (base.join(source).to_string_lossy().into_owned(), opts)
}
