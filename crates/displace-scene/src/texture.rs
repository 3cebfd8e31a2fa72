//! Image textures: colour maps (sRGB decoded to linear on load: the colour
//! convention of `docs/architecture.md`) and data maps (normal maps, read
//! as stored).

use crate::error::{Error, Result};
use glam::{Vec2, Vec3};
use std::path::Path;

/// An RGB image sampled bilinearly with repeat addressing, in linear RGB.
#[derive(Clone, Debug)]
pub struct Texture {
    width: usize,
    height: usize,
    /// Row-major, row 0 at `v = 0` (the height-map convention, so a colour
    /// map made from the same image lines up with the displacement).
    data: Vec<Vec3>,
}

/// The sRGB transfer functions, whose one definition is
/// [`displace_core::convention`]'s (the GPU's colour texels use it too).
pub use displace_core::convention::{linear_to_srgb, srgb_to_linear};

/// The size of the image file `path` (a `kind` of input, as messages name
/// it), from its header alone, after the checks every image input gets: a
/// regular file within the size limit, the decoded size checked against one
/// buffer's limit (a small file can hold a huge image; `bytes_per_texel` is
/// what a texel will cost), and when `format` is given, of that format
/// (else the message it carries). A scene counts this size in its memory
/// estimate before anything is decoded. Errors name the file.
pub(crate) fn image_dimensions(
    path: &Path,
    kind: &str,
    bytes_per_texel: u128,
    format: Option<(image::ImageFormat, &str)>,
) -> Result<[usize; 2]> {
    use displace_core::io::{check_input, MAX_IMAGE_FILE_BYTES};
    check_input(path, kind, MAX_IMAGE_FILE_BYTES)?;
    let reader = open_image(path)?;
    if let Some((want, message)) = format {
        if reader.format() != Some(want) {
            return Err(image_err(path, message.into()));
        }
    }
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| image_err(path, e.to_string()))?;
    displace_core::convention::check_allocation(
        kind,
        &format!("{w}x{h}"),
        w as u128 * h as u128,
        bytes_per_texel,
    )
    .map_err(|e| image_err(path, e.to_string()))?;
    Ok([w as usize, h as usize])
}

fn image_err(path: &Path, message: String) -> Error {
    displace_core::Error::image(path, message).into()
}

fn open_image(path: &Path) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
    image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| image_err(path, e.to_string()))
}

/// Reads the image file `path` as float RGB after the checks of
/// [`image_dimensions`] (same arguments), refusing an empty image.
pub(crate) fn read_rgb32f(
    path: &Path,
    kind: &str,
    bytes_per_texel: u128,
    format: Option<(image::ImageFormat, &str)>,
) -> Result<image::Rgb32FImage> {
    use image::ImageDecoder;
    image_dimensions(path, kind, bytes_per_texel, format)?;
    let mut decoder = open_image(path)?
        .into_decoder()
        .map_err(|e| image_err(path, e.to_string()))?;
    // The decoded size within the `image` crate's default allocation limit,
    // checked before decoding as its `decode` does (a corrupt header can
    // claim any size).
    image::Limits::default()
        .reserve(decoder.total_bytes())
        .map_err(|e| image_err(path, e.to_string()))?;
    // And against the memory limit in force (machine, cgroup, ulimit): the
    // decoder's own samples on top of `bytes_per_texel` (the float copy and
    // what the caller keeps), which a scene's estimate does not count. An
    // OpenEXR header alone can claim millions of texels (a display window
    // past its data window is decoded as filled texels), so a file of a
    // kilobyte may ask for gigabytes.
    let (w, h) = decoder.dimensions();
    displace_core::memory::check(
        &format!("decoding {} ({w}x{h} texels) as a {kind}", path.display()),
        u128::from(decoder.total_bytes()) + u128::from(w) * u128::from(h) * bytes_per_texel,
    )?;
    // A photograph is shown as its orientation tag says (none: as stored).
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img =
        image::DynamicImage::from_decoder(decoder).map_err(|e| image_err(path, e.to_string()))?;
    img.apply_orientation(orientation);
    let rgb = img.to_rgb32f();
    if rgb.width() == 0 || rgb.height() == 0 {
        return Err(image_err(path, "empty image".into()));
    }
    Ok(rgb)
}

/// The texels of a decoded float image, each refused (naming the file and
/// the texel) unless every component lies in `[lo, hi]` (NaN never does):
/// a float image (EXR) can hold what no texture or radiance means. `what`
/// names the values in the message. Shared by textures and environment
/// maps.
pub(crate) fn checked_texels<'a>(
    path: &'a Path,
    rgb: &'a image::Rgb32FImage,
    [lo, hi]: [f32; 2],
    what: &'a str,
) -> impl Iterator<Item = Result<Vec3>> + 'a {
    let w = rgb.width() as usize;
    rgb.pixels().enumerate().map(move |(i, p)| {
        let c = Vec3::new(p[0], p[1], p[2]);
        if c.is_finite() && c.min_element() >= lo && c.max_element() <= hi {
            return Ok(c);
        }
        let want = format!("finite and in [{lo:e}, {hi:e}]");
        let message = format!(
            "texel ({}, {}) is {:?}: {what} must be {want}",
            i % w,
            i / w,
            c.to_array()
        );
        Err(image_err(path, message))
    })
}

impl Texture {
    /// Bytes a texture holds per texel while it loads: the decoded float
    /// image and the texels kept (a `Vec3` each).
    pub const BYTES_PER_TEXEL: u128 = std::mem::size_of::<Vec3>() as u128 * 2;

    /// The texel size [`Texture::load`] would give, from the file's header
    /// alone (with the same checks), for memory estimates.
    pub fn dimensions(path: &Path) -> Result<[usize; 2]> {
        image_dimensions(path, "texture", Self::BYTES_PER_TEXEL, None)
    }

    /// Loads `path`; `srgb` decodes the sRGB transfer function (colour maps),
    /// otherwise values are kept as stored (normal maps).
    ///
    /// A float image (EXR, HDR) can hold what no texture means: a texel
    /// that is not finite is refused, and so is one outside `[0, 1]` in a
    /// colour map (a reflectance) or past `MAX_COORDINATE` in a normal map
    /// (its squared length must fit in single precision), naming the file
    /// and the texel, rather than rendered into NaN, negative or infinite
    /// pixels.
    pub fn load(path: &Path, srgb: bool) -> Result<Self> {
        let rgb = read_rgb32f(path, "texture", Self::BYTES_PER_TEXEL, None)?;
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let decode = |c: f32| if srgb { srgb_to_linear(c) } else { c };
        let range = if srgb {
            [0.0, 1.0]
        } else {
            let m = crate::build::MAX_COORDINATE;
            [-m, m]
        };
        let data = checked_texels(path, &rgb, range, "a texture's values")
            .map(|c| c.map(|c| c.map(decode)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            width: w,
            height: h,
            data,
        })
    }

    /// A texture of `width x height` linear pixels, row 0 at `v = 0`.
    pub fn from_pixels(width: usize, height: usize, data: Vec<Vec3>) -> Self {
        assert_eq!(data.len(), width * height);
        Self {
            width,
            height,
            data,
        }
    }

    /// Bilinear between texel centres, repeating.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let (i, fx) = displace_core::convention::texel_lerp(uv.x.rem_euclid(1.0), self.width);
        let (j, fy) = displace_core::convention::texel_lerp(uv.y.rem_euclid(1.0), self.height);
        let at = |ii: i64, jj: i64| {
            let x = ii.rem_euclid(self.width as i64) as usize;
            let y = jj.rem_euclid(self.height as i64) as usize;
            self.data[y * self.width + x]
        };
        let top = at(i, j).lerp(at(i + 1, j), fx);
        let bottom = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
        top.lerp(bottom, fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for k in 0..=20 {
            let c = k as f32 / 20.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
        assert!((srgb_to_linear(0.5) - 0.214).abs() < 1e-3);
    }

    #[test]
    fn samples_texel_centres() {
        let t = Texture::from_pixels(2, 1, vec![Vec3::ZERO, Vec3::ONE]);
        assert!((t.sample(Vec2::new(0.25, 0.5)) - Vec3::ZERO).length() < 1e-6);
        assert!((t.sample(Vec2::new(0.5, 0.5)) - Vec3::splat(0.5)).length() < 1e-6);
    }

    #[test]
    fn photographs_load_as_their_orientation_shows_them() {
        use image::ImageEncoder;
        let dir = tempfile::tempdir().unwrap();
        // Left half black, right half white, 16x8 as stored.
        let stored = image::RgbImage::from_fn(16, 8, |x, _| {
            image::Rgb(if x < 8 { [0, 0, 0] } else { [255, 255, 255] })
        });
        // EXIF orientation 6 (shown turned 90 degrees clockwise): a TIFF
        // directory of one SHORT tag 0x0112.
        let mut exif = b"II*\0\x08\0\0\0\x01\0\x12\x01\x03\0\x01\0\0\0\x06\0".to_vec();
        exif.extend_from_slice(&[0; 6]);
        let p = dir.path().join("photo.jpg");
        let mut bytes = Vec::new();
        let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95);
        enc.set_exif_metadata(exif).unwrap();
        enc.write_image(stored.as_raw(), 16, 8, image::ExtendedColorType::Rgb8)
            .unwrap();
        std::fs::write(&p, bytes).unwrap();
        let t = Texture::load(&p, false).unwrap();
        assert_eq!((t.width, t.height), (8, 16));
        // Shown turned: the stored left half (black) is now the top.
        assert!(
            t.data[2 * 8 + 4].max_element() < 0.05,
            "{:?}",
            t.data[2 * 8 + 4]
        );
        assert!(
            t.data[13 * 8 + 4].min_element() > 0.95,
            "{:?}",
            t.data[13 * 8 + 4]
        );
    }

    #[test]
    fn missing_file_names_its_path() {
        let e = Texture::load(Path::new("/no/such/brick.png"), true).unwrap_err();
        assert!(e.to_string().contains("/no/such/brick.png"), "{e}");
    }
}
