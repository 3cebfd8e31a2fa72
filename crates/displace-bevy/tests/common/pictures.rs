//! What the picture tests share: Bevy's frame under the adapter policy,
//! binary16 pixels, displace-gpu's checkerboard as a Bevy image, and FLIP
//! over the pixels both renderers cover.

use bevy::asset::RenderAssetUsages;
use bevy::image::{ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use displace_bevy::headless::Headless;

/// Bevy's frame, or the adapter policy's verdict.
pub fn frame(app: &mut Headless) -> Option<Image> {
    match app.capture() {
        Ok(image) => Some(image),
        Err(e) => {
            if std::env::var_os("CI").is_some() {
                panic!("GPU test: no frame in CI ({e}); CI must install mesa-vulkan-drivers");
            }
            if std::env::var("DISPLACE_ALLOW_NO_GPU").is_ok_and(|v| v == "1") {
                eprintln!("!!!!!!!! DISPLACE_ALLOW_NO_GPU=1: skipping this GPU test ({e})");
                return None;
            }
            panic!("no frame ({e}); install mesa-vulkan-drivers, or set DISPLACE_ALLOW_NO_GPU=1");
        }
    }
}

/// One little-endian binary16 channel.
pub fn half(bytes: &[u8]) -> f32 {
    half::f16::from_le_bytes([bytes[0], bytes[1]]).to_f32()
}

/// displace-gpu's checkerboard (`Renderer::new`'s colour map: the same
/// texels and box-filtered mips, the first `levels` of them) as a Bevy
/// image with displace-gpu's sampler: sRGB, trilinear, addressed as the map
/// is (`address`). Its curved draws read level 0 only, so the comparison
/// with them keeps one level.
pub fn checker_image(address: ImageAddressMode, levels: usize) -> Image {
    const SIZE: u32 = 256;
    let mut mips = displace_gpu::raster::checker_mips(SIZE, 16);
    mips.truncate(levels.max(1));
    let mut image = Image::new_uninit(
        Extent3d {
            width: SIZE,
            height: SIZE,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.mip_level_count = mips.len() as u32;
    // One layer: the levels in order, as Bevy's default data order reads them.
    image.data = Some(mips.concat());
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: address,
        address_mode_v: address,
        mag_filter: ImageFilterMode::Linear,
        min_filter: ImageFilterMode::Linear,
        mipmap_filter: ImageFilterMode::Linear,
        ..default()
    });
    image
}

/// FLIP between the plugin's frame and gpu-render's image over the pixels
/// both cover.
pub struct MaskedFlip {
    pub pixels: usize,
    pub mean: f32,
    pub p99: f32,
    /// The two sRGB images FLIP compared and its error map (magma), for a
    /// failure's report.
    ours: Vec<u8>,
    theirs: Vec<u8>,
    error: Vec<u8>,
    width: u32,
    height: u32,
}

/// Pixels either side leaves empty are set to one grey in both images
/// before FLIP runs, so its spatial filters see no difference there (the
/// shell's side walls, which gpu-render draws and the plugin does not, and
/// the rasterisers' edge pixels are not the comparison's business), and
/// only the pixels both cover are pooled: their mean, and their 99th
/// percentile (nearest rank).
pub fn masked_flip(ours: &[u8], theirs: &displace_gpu::Image) -> MaskedFlip {
    let (w, h) = (theirs.width, theirs.height);
    assert_eq!(ours.len(), (w * h * 4) as usize);
    let n = (w * h) as usize;
    let both: Vec<bool> = (0..n)
        .map(|i| ours[i * 4 + 3] > 127 && theirs.uv[i][2] != 0.0)
        .collect();
    let rgb = |rgba: &[u8]| -> Vec<u8> {
        (0..n)
            .flat_map(|i| {
                if both[i] {
                    [rgba[i * 4], rgba[i * 4 + 1], rgba[i * 4 + 2]]
                } else {
                    [128; 3]
                }
            })
            .collect()
    };
    let (a, b) = (rgb(ours), rgb(&theirs.rgba8));
    let err = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &a),
        nv_flip::FlipImageRgb8::with_data(w, h, &b),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let values = err.to_vec();
    let mut pooled: Vec<f32> = (0..n).filter(|&i| both[i]).map(|i| values[i]).collect();
    pooled.sort_by(f32::total_cmp);
    let pixels = pooled.len();
    let mean = pooled.iter().sum::<f32>() / pixels.max(1) as f32;
    let rank = ((0.99 * pixels as f64).ceil() as usize).max(1);
    let p99 = pooled.get(rank - 1).copied().unwrap_or(0.0);
    MaskedFlip {
        pixels,
        mean,
        p99,
        ours: a,
        theirs: b,
        error: err.apply_color_lut(&nv_flip::magma_lut()).to_vec(),
        width: w,
        height: h,
    }
}

impl MaskedFlip {
    /// Writes `NAME.bevy.png`, `NAME.gpu.png` and `NAME.flip.png` under
    /// Cargo's temporary directory for integration tests, and returns it.
    pub fn write(&self, name: &str) -> std::path::PathBuf {
        let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
        for (what, rgb) in [
            ("bevy", &self.ours),
            ("gpu", &self.theirs),
            ("flip", &self.error),
        ] {
            image::RgbImage::from_raw(self.width, self.height, rgb.clone())
                .unwrap()
                .save(dir.join(format!("{name}.{what}.png")))
                .unwrap();
        }
        dir
    }
}
