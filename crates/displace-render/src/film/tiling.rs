//! Farm tiles: the image cut into `N` horizontal bands of whole rows of the
//! render loop's own tiles ([`TILE`] pixels high), as even as the rows
//! allow, so that each farm task renders a rectangle that starts on the
//! loop's tile grid and the bands cover the image exactly once. Pixels are
//! seeded by their position alone, so a band rendered alone is bit-identical
//! to the same pixels of a whole render, and `merge` stitches bands back
//! into the single-machine image.

use crate::error::{Error, Result};
use crate::render::{Crop, TILE};

/// Tile `index` of `count` (`--tile I/N`), zero-based as Slurm array ids
/// and Kubernetes completion indices are.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileIndex {
    /// Zero-based index of this tile.
    pub index: u32,
    /// How many tiles the image is cut into.
    pub count: u32,
}

impl std::fmt::Display for TileIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// `--tile` as given: a fixed index, or `auto` (the scheduler's task index,
/// resolved by the caller from its environment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileArg {
    /// `--tile I/N`.
    Fixed(TileIndex),
    /// `--tile auto/N`: the index comes from the scheduler.
    Auto {
        /// How many tiles the image is cut into.
        count: u32,
    },
}

impl std::str::FromStr for TileArg {
    type Err = Error;
    /// `I/N` or `auto/N`.
    fn from_str(s: &str) -> Result<Self> {
        let bad = |why: &str| Error::Option(format!("--tile `{s}`: {why}"));
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected I/N or auto/N (tile I of N, counted from 0)"))?;
        let count: u32 = n
            .trim()
            .parse()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| bad("the tile count N must be a positive whole number"))?;
        match i.trim() {
            "auto" => Ok(TileArg::Auto { count }),
            i => {
                let index: u32 = i
                    .parse()
                    .map_err(|_| bad("the index I must be a whole number or `auto`"))?;
                TileIndex::new(index, count).map(TileArg::Fixed)
            }
        }
    }
}

impl TileIndex {
    /// Refuses an index outside `0..count`.
    pub fn new(index: u32, count: u32) -> Result<Self> {
        if count == 0 || index >= count {
            return Err(Error::Option(format!(
                "tile {index}/{count}: the index must be 0..{count} (counted from 0)"
            )));
        }
        Ok(Self { index, count })
    }
}

/// The rectangles of all `count` tiles of a `width` x `height` image, in
/// index order. A count above the image's rows of render tiles is refused:
/// some tiles would be empty.
pub fn tile_rects(width: u32, height: u32, count: u32) -> Result<Vec<Crop>> {
    let rows = height.div_ceil(TILE);
    if count == 0 || count > rows {
        return Err(Error::Option(format!(
            "{count} tiles: a {width}x{height} image has {rows} rows of {TILE}-pixel render tiles, so 1 to {rows} farm tiles"
        )));
    }
    let edge = |i: u32| {
        let row = (u64::from(i) * u64::from(rows) / u64::from(count)) as u32;
        (row * TILE).min(height)
    };
    Ok((0..count)
        .map(|i| {
            let (y0, y1) = (edge(i), edge(i + 1));
            Crop {
                x: 0,
                y: y0,
                width,
                height: y1 - y0,
            }
        })
        .collect())
}

/// The rectangle of one tile.
pub fn tile_rect(width: u32, height: u32, tile: TileIndex) -> Result<Crop> {
    Ok(tile_rects(width, height, tile.count)?[tile.index as usize])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_image_once_on_the_tile_grid() {
        for (w, h) in [(64u32, 64u32), (37, 100), (5, 16), (300, 17), (8, 4096)] {
            for n in 1..=h.div_ceil(TILE) {
                let rects = tile_rects(w, h, n).unwrap();
                assert_eq!(rects.len(), n as usize);
                let mut y = 0;
                for r in &rects {
                    assert_eq!((r.x, r.width, r.y), (0, w, y));
                    assert!(r.height > 0);
                    assert_eq!(r.y % TILE, 0, "{w}x{h} in {n}: {r:?}");
                    y += r.height;
                }
                assert_eq!(y, h);
                let (lo, hi) = rects.iter().fold((u32::MAX, 0), |(a, b), r| {
                    (a.min(r.height), b.max(r.height))
                });
                // Even to within one row of render tiles (the last is short).
                assert!(hi - lo <= TILE, "{w}x{h} in {n}: {lo}..{hi}");
            }
        }
    }

    #[test]
    fn bad_counts_and_indices_are_refused() {
        let e = tile_rects(64, 64, 5).unwrap_err().to_string();
        assert!(e.contains("1 to 4"), "{e}");
        assert!(tile_rects(64, 64, 0).is_err());
        for bad in ["3", "4/4", "1/0", "x/4", "-1/4", "auto/", "auto/0"] {
            assert!(bad.parse::<TileArg>().is_err(), "{bad}");
        }
        assert_eq!(
            "2/7".parse::<TileArg>().unwrap(),
            TileArg::Fixed(TileIndex { index: 2, count: 7 })
        );
        assert_eq!(
            "auto/8".parse::<TileArg>().unwrap(),
            TileArg::Auto { count: 8 }
        );
    }
}
