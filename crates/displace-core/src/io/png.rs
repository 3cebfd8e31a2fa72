//! The PNG writers: a normal map (the bake's `--normals`), 8-bit RGB
//! images (the comparison's plots and grids) and 16-bit heights (round trips
//! of the height loader, [`super::height::load`]), each written atomically.
//! Loading is [`super::height`]'s.

use crate::{HeightMap, NormalMap, Result};
use std::path::Path;

fn encode_png(
    w: &mut dyn std::io::Write,
    width: usize,
    height: usize,
    bytes: &[u8],
    ty: image::ExtendedColorType,
) -> std::io::Result<()> {
    use image::ImageEncoder;
    image::codecs::png::PngEncoder::new(w)
        .write_image(bytes, width as u32, height as u32, ty)
        .map_err(std::io::Error::other)
}

/// Writes a tangent-space normal map as an 8-bit RGB PNG, `rgb = n * 0.5 +
/// 0.5` in the +Y-up (OpenGL) convention of [`NormalMap::to_rgb8`] (the one
/// place that encoding is defined). Row `j` of the image is texel row `j`, as
/// the height map was read, so the two line up pixel for pixel.
pub fn write_normal_map_png(path: &Path, normals: &NormalMap) -> Result<()> {
    write_rgb8_png(path, normals.width, normals.height, &normals.to_rgb8())
}

/// Writes `width x height` 8-bit RGB pixels (row-major, top row first) as a
/// PNG, atomically.
pub fn write_rgb8_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<()> {
    super::atomic::write_atomic(path, |out| {
        encode_png(out, width, height, rgb, image::ExtendedColorType::Rgb8)
    })
}

/// Writes a height map as a 16-bit greyscale PNG (`round(h * 65535)`),
/// which [`super::height::load`] reads back to within `0.5 / 65535`.
pub fn write_height_png16(path: &Path, height: &HeightMap) -> Result<()> {
    let (w, h) = (height.width(), height.height());
    let bytes: Vec<u8> = height
        .data()
        .iter()
        .flat_map(|&v| (((v * 65535.0).round()) as u16).to_ne_bytes())
        .collect();
    super::atomic::write_atomic(path, |out| {
        encode_png(out, w, h, &bytes, image::ExtendedColorType::L16)
    })
}
