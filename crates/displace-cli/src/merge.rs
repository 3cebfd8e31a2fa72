//! `displace merge TILE... -o out.png|out.exr`: the farm's last step. The
//! tiles `render --tile` wrote are checked (one render, the image covered
//! exactly once, every file complete) and stitched into the image a single
//! machine renders, written atomically; otherwise every problem is named
//! and nothing is written.

use anyhow::{Context, Result};
use displace_render::film::merge::merge_files;
use displace_render::film::output::{write_image, ImageFile};
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Tile files written by `displace render --tile I/N` (any order).
    #[arg(required = true)]
    pub tiles: Vec<PathBuf>,
    /// The merged image: .png (sRGB) or .exr (linear), as `render` writes.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(args: MergeArgs) -> Result<()> {
    ImageFile::from_path(&args.output)?;
    crate::outputs::check_output_dir(&args.output)?;
    let tiles: Vec<(&str, &std::path::Path)> =
        args.tiles.iter().map(|t| ("tile", t.as_path())).collect();
    crate::outputs::check_not_inputs(&[("-o", &args.output)], &tiles)?;
    let start = Instant::now();
    let image = merge_files(&args.tiles)?;
    write_image(&args.output, &image)
        .with_context(|| format!("writing the merged image {}", args.output.display()))?;
    eprintln!(
        "merged {} tiles into {}x{} in {:.2} s -> {}",
        args.tiles.len(),
        image.width,
        image.height,
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    Ok(())
}
