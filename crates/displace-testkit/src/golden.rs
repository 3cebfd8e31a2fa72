//! Golden images judged by NVIDIA's FLIP (Andersson et al. 2020, crate
//! `nv-flip`, as rend3's tests use it), with two thresholds as rend3's
//! `ThresholdSet` has them: the mean FLIP (an error spread over the image)
//! and the 99th-percentile FLIP (an error in a small region: a stud or a
//! shadow edge gone, which the mean dilutes). One definition for the CPU
//! renderer's golden test and the GPU raster path's, so both are judged,
//! stored and blessed the same way.
//!
//! A reference is `DIR/NAME.png` (sRGB); a failure writes `NAME.diff.png`
//! (the FLIP error map, magma) and `NAME.actual.png` next to it. The
//! references are regenerated only on request: with `DISPLACE_BLESS` set,
//! [`check`] writes the render as the reference instead of comparing.

use std::path::Path;

/// A PNG of 8-bit RGB pixels, as the renderers write them (the PNG encoder
/// of `image` with its defaults): references and the failure's pictures.
fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> std::io::Result<()> {
    use image::ImageEncoder;
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    image::codecs::png::PngEncoder::new(file)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(std::io::Error::other)
}

/// What a suite allows: the mean and the 99th-percentile FLIP.
#[derive(Clone, Copy, Debug)]
pub struct Thresholds {
    /// Largest mean FLIP: an error spread over the image.
    pub mean: f32,
    /// Largest 99th-percentile FLIP: an error in a small region.
    pub p99: f32,
}

/// FLIP between two sRGB images: the error map and its pooled values.
pub struct Flip {
    /// FLIP per pixel, in `[0, 1]`.
    pub error: nv_flip::FlipImageFloat,
    /// Its mean.
    pub mean: f32,
    /// Its 99th percentile.
    pub p99: f32,
}

impl Thresholds {
    /// Whether `flip` is within both thresholds.
    pub fn pass(&self, flip: &Flip) -> bool {
        flip.mean <= self.mean && flip.p99 <= self.p99
    }
}

/// FLIP between `reference` and `actual`, RGB8 sRGB images of
/// `width x height`, pooled over every pixel.
pub fn flip([width, height]: [u32; 2], reference: &[u8], actual: &[u8]) -> Flip {
    let error = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(width, height, reference),
        nv_flip::FlipImageRgb8::with_data(width, height, actual),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mut pool = nv_flip::FlipPool::from_image(&error);
    let (mean, p99) = (pool.mean(), pool.get_percentile(0.99, false));
    Flip { error, mean, p99 }
}

/// Compares `actual` (RGB8 sRGB, `size`) with `dir/NAME.png` and panics,
/// after writing the diff and the actual image, where it exceeds `limits`;
/// returns the measured FLIP. With `DISPLACE_BLESS` set, writes `actual` as
/// the reference and returns `None`.
pub fn check(
    dir: &Path,
    name: &str,
    size @ [width, height]: [u32; 2],
    actual: &[u8],
    limits: Thresholds,
) -> Option<Flip> {
    let reference = dir.join(format!("{name}.png"));
    if std::env::var_os("DISPLACE_BLESS").is_some() {
        write_png_rgb8(&reference, width, height, actual).unwrap();
        return None;
    }
    let stored = image::open(&reference)
        .unwrap_or_else(|e| panic!("{}: {e} (bless with DISPLACE_BLESS=1)", reference.display()))
        .to_rgb8();
    assert_eq!(
        (stored.width(), stored.height()),
        (width, height),
        "{}",
        reference.display()
    );
    let measured = flip(size, stored.as_raw(), actual);
    if !limits.pass(&measured) {
        let diff = measured.error.apply_color_lut(&nv_flip::magma_lut());
        let diff_path = dir.join(format!("{name}.diff.png"));
        write_png_rgb8(&diff_path, width, height, &diff.to_vec()).unwrap();
        let actual_path = dir.join(format!("{name}.actual.png"));
        write_png_rgb8(&actual_path, width, height, actual).unwrap();
        panic!(
            "{name}: mean FLIP {} (allowed {}), 99th percentile {} (allowed {}); see {}",
            measured.mean,
            limits.mean,
            measured.p99,
            limits.p99,
            diff_path.display()
        );
    }
    Some(measured)
}

/// Asserts that `limits` tell a small local error from a spread one:
/// `rgb` (`size`) with a black 5x5 patch at pixel (30, 30) (0.5% of a 72x72
/// image) passes the mean, which dilutes it, and fails the percentile.
pub fn assert_percentile_catches_a_patch(
    size @ [width, _]: [u32; 2],
    rgb: &[u8],
    limits: Thresholds,
) {
    let mut patched = rgb.to_vec();
    for row in 30..35 {
        let k = 3 * (row * width as usize + 30);
        patched[k..k + 15].fill(0);
    }
    let f = flip(size, rgb, &patched);
    assert!(
        f.mean <= limits.mean && f.p99 > limits.p99,
        "local error: mean {}, p99 {}",
        f.mean,
        f.p99
    );
}
