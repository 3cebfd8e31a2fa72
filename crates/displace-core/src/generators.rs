//! Built-in height-map generators (`gen:NAME?key=value&...`).
//! OWNED BY HELPER: to be implemented.

use crate::{Address, HeightMap, Result};

/// Builds the height map named by `spec` (`gen:studded?period=8`) at
/// `width x height` texels.
pub fn generate(spec: &str, width: usize, height: usize, address: Address) -> Result<HeightMap> {
    let _ = spec;
    // Temporary until the generators land: a gaussian bump, used by doc tests.
    HeightMap::check_size(width, height)?;
    let mut data = Vec::with_capacity(width * height);
    for j in 0..height {
        for i in 0..width {
            let x = crate::convention::texel_centre(i, width) * 2.0 - 1.0;
            let y = crate::convention::texel_centre(j, height) * 2.0 - 1.0;
            data.push((-std::f32::consts::PI * (x * x + y * y) * 2.0).exp());
        }
    }
    HeightMap::new(width, height, data, address)
}
