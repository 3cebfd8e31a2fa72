//! Elevation models (heights in metres, as GDAL writes a DEM) for the tests
//! of `height_range`: the renderer's and the CLI's bake, so both build and
//! normalise them the same way.

use std::path::Path;

/// `f(x, y)` at every texel `(x, y)` of a `w x h` grid, row-major.
pub fn sampled([w, h]: [u32; 2], f: impl Fn(f32, f32) -> f32) -> Vec<f32> {
    (0..w * h)
        .map(|k| f((k % w) as f32, (k / w) as f32))
        .collect()
}

/// The lowest and the highest of `values`.
pub fn extremes(values: &[f32]) -> (f32, f32) {
    values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        })
}

/// `dem` mapped linearly onto `[0, 1]`, its lowest value to 0 and its
/// highest to 1 (in `f64`): the heights normalised beforehand.
pub fn normalised(dem: &[f32]) -> Vec<f32> {
    let (lo, hi) = extremes(dem);
    dem.iter()
        .map(|&v| ((f64::from(v) - f64::from(lo)) / (f64::from(hi) - f64::from(lo))) as f32)
        .collect()
}

/// Writes a one-band 32-bit float TIFF, as GDAL writes a DEM.
pub fn write_float_tiff(path: &Path, [w, h]: [u32; 2], values: &[f32]) {
    let file = std::fs::File::create(path).unwrap();
    tiff::encoder::TiffEncoder::new(file)
        .unwrap()
        .write_image::<tiff::encoder::colortype::Gray32Float>(w, h, values)
        .unwrap();
}
