//! Height sources named in scenes: `gen:` generators or image files,
//! relative to the scene file, loaded by [`displace_core::io::height`].

use crate::error::Result;
use displace_core::io::height::{self, HeightOptions};
use displace_core::{Address, HeightMap};
use std::path::Path;

/// Loads `source` for a face: a generator spec at `size` texels, or a file
/// relative to `base` (its own size).
pub fn load(source: &str, size: [usize; 2], address: Address, base: &Path) -> Result<HeightMap> {
    let opts = HeightOptions {
        size,
        address,
        ..HeightOptions::default()
    };
    if source.starts_with("gen:") {
        return Ok(height::load(source, &opts)?);
    }
    let path = base.join(source);
    Ok(height::load(&path.to_string_lossy(), &opts)?)
}
