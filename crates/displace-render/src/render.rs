//! The render loop: tiles in parallel (rayon), each pixel's samples seeded
//! from `(seed, x, y, sample)` alone so the image does not depend on thread
//! count or tiling and crops stitch bit-exactly; a progress callback and a
//! cancellation flag for the CLI.

use crate::error::{Error, Result};
use crate::integrators::{tile, Scratch};
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// A rectangle of the full image, in pixels.
///
/// A crop renders exactly the pixels the full render would have there
/// (samples are seeded per pixel), which is what lets a render farm split
/// an image into crops ([`crate::film::tiling`]) and merge them ([`crate::film::merge`])
/// seamlessly. Parsed from `x,y,w,h` (`--crop`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// Left column of the crop in the full image (0 is the left edge).
    pub x: u32,
    /// Top row of the crop in the full image (0 is the top).
    pub y: u32,
    /// Columns in the crop; at least 1, and `x + width` within the image.
    pub width: u32,
    /// Rows in the crop; at least 1, and `y + height` within the image.
    pub height: u32,
}

impl std::str::FromStr for Crop {
    type Err = Error;
    /// `x,y,w,h`.
    fn from_str(s: &str) -> Result<Self> {
        let v: Vec<&str> = s.split(',').map(str::trim).collect();
        let bad = || {
            Error::Option(format!(
                "crop `{s}`: expected x,y,width,height (whole numbers)"
            ))
        };
        if v.len() != 4 {
            return Err(bad());
        }
        let n: Vec<u32> = v
            .iter()
            .map(|p| p.parse().map_err(|_| bad()))
            .collect::<Result<_>>()?;
        Ok(Crop {
            x: n[0],
            y: n[1],
            width: n[2],
            height: n[3],
        })
    }
}

/// Arbitrary output variables, one primary ray through each pixel centre.
///
/// Images besides the colour for checking and comparing renders: where the
/// displaced surface is (depth, position), how it is oriented (normal),
/// its texture coordinates, and what the sphere tracer paid for it
/// (iterations, Donnelly's cost measure in section 8.6).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Aov {
    /// World distance along the camera ray; +inf where nothing is hit.
    Depth,
    /// World shading normal (0 on misses).
    Normal,
    /// Texture coordinate (tiles).
    Uv,
    /// World position (0 on misses).
    Position,
    /// Map-space steps of a displaced hit (0 elsewhere).
    Iterations,
}

impl Aov {
    /// Every AOV (what [`str::parse`] searches), in the order `--aov`'s
    /// help lists them.
    pub const ALL: [Aov; 5] = [
        Aov::Depth,
        Aov::Normal,
        Aov::Uv,
        Aov::Position,
        Aov::Iterations,
    ];

    /// Floats a pixel of this AOV holds: 1 for depth and iterations, 2 for
    /// the texture coordinate, 3 for normal and position (the last axis of
    /// its [`AovImage`]).
    pub fn channels(self) -> usize {
        match self {
            Aov::Depth | Aov::Iterations => 1,
            Aov::Uv => 2,
            Aov::Normal | Aov::Position => 3,
        }
    }

    /// The name `--aov` takes, [`str::parse`] accepts and the AOV's files
    /// carry (`OUT.depth.npy`).
    pub fn name(self) -> &'static str {
        match self {
            Aov::Depth => "depth",
            Aov::Normal => "normal",
            Aov::Uv => "uv",
            Aov::Position => "position",
            Aov::Iterations => "iterations",
        }
    }
}

impl std::str::FromStr for Aov {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let choices = Aov::ALL.map(|a| (a.name(), a));
        displace_core::names::parse_known("AOV", s, &choices).map_err(Error::Option)
    }
}

/// How to run one render of a scene, apart from the scene itself (which
/// holds the image size, samples and integrator): which part, which extra
/// images, and the hooks the CLI needs. The default renders the whole image,
/// colour only.
#[derive(Default)]
pub struct RenderOptions<'a> {
    /// The part of the image to render; `None` for all of it.
    pub crop: Option<Crop>,
    /// Extra images to render alongside the colour, in this order in
    /// [`Rendered::aovs`]; empty for none.
    pub aovs: Vec<Aov>,
    /// `(tiles done, tiles in all)`.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Set to stop; the render then returns [`Error::Cancelled`].
    pub cancel: Option<&'a AtomicBool>,
}

/// Linear RGB pixels, row-major, row 0 at the top.
///
/// Kept linear and unclamped so that farm tiles (EXR) merge back into the
/// same image and EXR output keeps the radiance; [`crate::film::output`] encodes
/// sRGB only when writing a PNG.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Pixels a row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` radiance values, `pixels[y * width + x]`.
    pub pixels: Vec<Vec3>,
}

/// An AOV as an `(height, width, channels)` float array.
///
/// That is the layout [`crate::film::output`] writes as is, as `OUT.NAME.npy`
/// (with a false-colour PNG beside it).
#[derive(Clone, Debug, PartialEq)]
pub struct AovImage {
    /// Which variable this is (and so its channel count).
    pub aov: Aov,
    /// Pixels a row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `height * width * aov.channels()` floats, row-major, channels
    /// innermost.
    pub data: Vec<f32>,
}

/// What [`render`] returns: the colour image of the crop (or whole image)
/// and the AOVs asked for.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// The colour image, the crop's size.
    pub image: Image,
    /// One image per [`RenderOptions::aovs`] entry, in that order.
    pub aovs: Vec<AovImage>,
}

/// The side of the square tiles the render loop hands to its threads; farm
/// tiles ([`crate::film::tiling`]) are whole rows of them.
pub const TILE: u32 = 16;

/// Renders `scene` in the current rayon pool.
///
/// Tiles of [`TILE`] pixels are shaded in parallel; each pixel's samples
/// are seeded from the scene's seed and the pixel alone, so the result is
/// the same for any thread count and a crop's pixels are the full image's.
/// The integrator is the scene's ([`crate::integrators`]: Whitted or path
/// tracing).
///
/// # Errors
///
/// [`Error::Option`] when the crop is empty or leaves the image;
/// [`Error::Cancelled`] when [`RenderOptions::cancel`] is set before the
/// last tile starts.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<Rendered> {
    let (fw, fh) = (scene.width, scene.height);
    let crop = opts.crop.unwrap_or(Crop {
        x: 0,
        y: 0,
        width: fw,
        height: fh,
    });
    if crop.width == 0
        || crop.height == 0
        || crop.x as u64 + crop.width as u64 > fw as u64
        || crop.y as u64 + crop.height as u64 > fh as u64
    {
        return Err(Error::Option(format!(
            "crop {},{},{},{} does not fit in the {fw}x{fh} image (or is empty)",
            crop.x, crop.y, crop.width, crop.height
        )));
    }
    let tiles: Vec<(u32, u32)> = (0..crop.height.div_ceil(TILE))
        .flat_map(|ty| (0..crop.width.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE)))
        .collect();
    let done = AtomicUsize::new(0);
    let total = tiles.len();
    let results: Vec<(Vec<Vec3>, Vec<Vec<f32>>)> = tiles
        .par_iter()
        // One scratch per rayon job, not per tile: a tile's wave buffers
        // are megabytes, and grown afresh they cost more in page faults and
        // copies than the tile's shading.
        .map_init(Scratch::default, |scratch, &(tx, ty)| {
            if opts.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                return Err(Error::Cancelled);
            }
            let w = TILE.min(crop.width - tx);
            let h = TILE.min(crop.height - ty);
            let mut px = Vec::with_capacity((w * h) as usize);
            let mut aov: Vec<Vec<f32>> = opts
                .aovs
                .iter()
                .map(|a| Vec::with_capacity((w * h) as usize * a.channels()))
                .collect();
            let coords: Vec<(u32, u32)> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (crop.x + tx + x, crop.y + ty + y)))
                .collect();
            tile(scene, &coords, scratch, &mut px);
            if !opts.aovs.is_empty() {
                for &(gx, gy) in &coords {
                    aov_pixel(scene, gx, gy, &opts.aovs, &mut aov);
                }
            }
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(p) = opts.progress {
                p(n, total);
            }
            Ok((px, aov))
        })
        .collect::<Result<_>>()?;

    let (cw, ch) = (crop.width as usize, crop.height as usize);
    let mut pixels = displace_core::memory::filled("the image", cw * ch, Vec3::ZERO)?;
    let mut aovs: Vec<AovImage> = opts
        .aovs
        .iter()
        .map(|&a| {
            Ok(AovImage {
                aov: a,
                width: crop.width,
                height: crop.height,
                data: displace_core::memory::zeroed(
                    &format!("the {} image", a.name()),
                    cw * ch * a.channels(),
                )?,
            })
        })
        .collect::<Result<_>>()?;
    for (&(tx, ty), (px, aov)) in tiles.iter().zip(&results) {
        let w = TILE.min(crop.width - tx) as usize;
        for (k, p) in px.iter().enumerate() {
            let (x, y) = (tx as usize + k % w, ty as usize + k / w);
            pixels[y * cw + x] = *p;
            for (img, src) in aovs.iter_mut().zip(aov) {
                let c = img.aov.channels();
                img.data[(y * cw + x) * c..(y * cw + x + 1) * c]
                    .copy_from_slice(&src[k * c..(k + 1) * c]);
            }
        }
    }
    Ok(Rendered {
        image: Image {
            width: crop.width,
            height: crop.height,
            pixels,
        },
        aovs,
    })
}

fn aov_pixel(scene: &Scene, x: u32, y: u32, aovs: &[Aov], out: &mut [Vec<f32>]) {
    let film = Vec2::new(
        (x as f32 + 0.5) / scene.width as f32,
        (y as f32 + 0.5) / scene.height as f32,
    );
    let ray = scene.camera.ray(film, Vec2::splat(0.5));
    let hit = scene.intersect(&ray, 0.0, f32::INFINITY);
    for (a, o) in aovs.iter().zip(out.iter_mut()) {
        match (a, &hit) {
            (Aov::Depth, Some(h)) => o.push(h.t),
            (Aov::Depth, None) => o.push(f32::INFINITY),
            (Aov::Normal, Some(h)) => o.extend(h.shading_normal.to_array()),
            (Aov::Position, Some(h)) => o.extend(h.position.to_array()),
            (Aov::Normal | Aov::Position, None) => o.extend([0.0; 3]),
            (Aov::Uv, Some(h)) => o.extend(h.uv.to_array()),
            (Aov::Uv, None) => o.extend([0.0; 2]),
            (Aov::Iterations, Some(h)) => o.push(h.iterations as f32),
            (Aov::Iterations, None) => o.push(0.0),
        }
    }
}
