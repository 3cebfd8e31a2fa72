//! Writing renders: PNG (sRGB encoded, 8 bit), EXR (linear float), AOVs as
//! `.npy` float32 `(H, W, C)` plus a false-colour PNG each. Every file is
//! written to a temporary file and renamed, so an error or an interrupt
//! leaves nothing half-written.

use crate::error::{Error, Result};
use crate::render::{Aov, AovImage, Image};
use crate::texture::linear_to_srgb;
use displace_core::io::atomic::write_atomic;
use image::ImageEncoder;
use std::path::{Path, PathBuf};

/// The image file types, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFile {
    /// `.png`: 8-bit sRGB.
    Png,
    /// `.exr`: linear half floats.
    Exr,
}

impl ImageFile {
    /// The type `path`'s extension names; other extensions are refused.
    pub fn from_path(path: &Path) -> Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("png") => Ok(ImageFile::Png),
            Some("exr") => Ok(ImageFile::Exr),
            _ => Err(image_err(
                path,
                "unknown image type (expected .png or .exr)",
            )),
        }
    }
}

fn image_err(path: &Path, e: impl std::fmt::Display) -> Error {
    displace_core::Error::image(path, e).into()
}

/// 8-bit sRGB bytes of a linear image (clamped to `[0, 1]`).
pub fn srgb8(img: &Image) -> Vec<u8> {
    img.pixels
        .iter()
        .flat_map(|p| {
            p.to_array()
                .map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)
        })
        .collect()
}

/// Writes 8-bit RGB rows (already sRGB-encoded) as a PNG, atomically.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// Writes `img` as PNG (sRGB) or EXR (linear), by extension.
pub fn write_image(path: &Path, img: &Image) -> Result<()> {
    match ImageFile::from_path(path)? {
        ImageFile::Png => write_png_rgb8(path, img.width, img.height, &srgb8(img)),
        ImageFile::Exr => {
            let data: Vec<f32> = img.pixels.iter().flat_map(|p| p.to_array()).collect();
            let buf = image::Rgb32FImage::from_raw(img.width, img.height, data)
                .ok_or_else(|| image_err(path, "image size mismatch"))?;
            let mut bytes = std::io::Cursor::new(Vec::new());
            image::DynamicImage::ImageRgb32F(buf)
                .write_to(&mut bytes, image::ImageFormat::OpenExr)
                .map_err(|e| image_err(path, e))?;
            write_atomic(path, |w| w.write_all(bytes.get_ref()))?;
            Ok(())
        }
    }
}

/// The `.npy` and false-colour `.png` paths of an AOV next to `output`:
/// `out.png` -> `out.depth.npy`, `out.depth.png`.
pub fn aov_paths(output: &Path, aov: Aov) -> (PathBuf, PathBuf) {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let dir = output.parent().unwrap_or(Path::new(""));
    (
        dir.join(format!("{stem}.{}.npy", aov.name())),
        dir.join(format!("{stem}.{}.png", aov.name())),
    )
}

/// Writes `aov` beside `output` as `STEM.NAME.npy` (float32, `(H, W, C)`)
/// and a false-colour `STEM.NAME.png`.
pub fn write_aov(output: &Path, aov: &AovImage) -> Result<()> {
    let (npy, png) = aov_paths(output, aov.aov);
    let shape = [aov.height as usize, aov.width as usize, aov.aov.channels()];
    displace_core::io::npy::write_file(&npy, &shape, &aov.data)?;
    write_png_rgb8(&png, aov.width, aov.height, &false_colour(aov))
}

/// A viewable picture of an AOV: normals as `0.5 n + 0.5`, texture
/// coordinates as red/green of their fractional parts, positions per axis
/// over their range, depth and iterations through a blue-to-yellow ramp
/// (misses black).
pub fn false_colour(aov: &AovImage) -> Vec<u8> {
    let c = aov.aov.channels();
    let px = aov.data.chunks_exact(c);
    let to8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    match aov.aov {
        Aov::Normal => px
            .flat_map(|p| {
                [
                    to8(0.5 * p[0] + 0.5),
                    to8(0.5 * p[1] + 0.5),
                    to8(0.5 * p[2] + 0.5),
                ]
            })
            .collect(),
        Aov::Uv => px
            .flat_map(|p| [to8(p[0].rem_euclid(1.0)), to8(p[1].rem_euclid(1.0)), 0])
            .collect(),
        Aov::Position => {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for p in aov.data.chunks_exact(3) {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            px.flat_map(|p| {
                std::array::from_fn::<u8, 3, _>(
                    |k| to8((p[k] - lo[k]) / (hi[k] - lo[k]).max(1e-30)),
                )
            })
            .collect()
        }
        Aov::Depth | Aov::Iterations => {
            let finite = aov.data.iter().copied().filter(|v| v.is_finite());
            let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            px.flat_map(|p| {
                let v = p[0];
                if !v.is_finite() || (aov.aov == Aov::Iterations && v == 0.0) {
                    return [0, 0, 0];
                }
                let x = (v - lo) / (hi - lo).max(1e-30);
                // Near is bright for depth; many steps bright for iterations.
                let x = if aov.aov == Aov::Depth { 1.0 - x } else { x };
                [to8(x * x.sqrt()), to8(x), to8(1.0 - x * 0.8)]
            })
            .collect()
        }
    }
}
