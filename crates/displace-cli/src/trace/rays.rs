//! Rays as `displace trace` reads them: an `.npy` array of one ray a row,
//! in the face's (or the scene's) physical frame, checked before any is
//! traced.

use anyhow::{bail, Context, Result};
use displace_core::io::npy;
use displace_core::physical;
use std::path::Path;

/// Rays read from `path`, checked: shape `(N, 6)`, finite, non-zero
/// directions. Returned in physical units, as given.
pub fn read_rays(path: &Path) -> Result<Vec<[f32; 6]>> {
    let rays = read_ray_rows(path, false)?;
    Ok(rays
        .iter()
        .map(|r| [r[0], r[1], r[2], r[3], r[4], r[5]])
        .collect())
}

/// Rays of shape `(N, 6)` or `(N, 7)` (then `t_max`, positive or inf),
/// checked as [`read_rays`] checks them; a missing `t_max` is inf.
pub fn read_rays_with_length(path: &Path) -> Result<Vec<[f32; 7]>> {
    read_ray_rows(path, true)
}

fn read_ray_rows(path: &Path, with_length: bool) -> Result<Vec<[f32; 7]>> {
    let arr = npy::read_file(path).with_context(|| format!("reading rays {}", path.display()))?;
    let columns = arr.shape.get(1).copied().unwrap_or(0);
    if arr.shape.len() != 2 || !(columns == 6 || (with_length && columns == 7)) {
        bail!(
            "rays {}: shape {:?}, expected (N, 6): origin x, y, z then direction x, y, z per row{}",
            path.display(),
            arr.shape,
            if with_length {
                ", or (N, 7) with t_max last"
            } else {
                ""
            }
        );
    }
    let rays: Vec<[f32; 7]> = arr
        .data
        .chunks_exact(columns)
        .map(|r| {
            let t_max = if columns == 7 { r[6] } else { f32::INFINITY };
            [r[0], r[1], r[2], r[3], r[4], r[5], t_max]
        })
        .collect();
    for (n, r) in rays.iter().enumerate() {
        physical::check_ray(|| format!("rays {}: ray {n}", path.display()), r)?;
    }
    Ok(rays)
}
