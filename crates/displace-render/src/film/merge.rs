//! Putting farm tiles back together: the tiles must all belong to one
//! render (same content hash, image size and tile count), cover the image
//! exactly once on the grid of [`crate::film::tiling`], and be complete files.
//! Every problem found is reported, each naming the file or the tile at
//! fault, and no image is returned unless there are none; the merged image
//! is then the one a single machine renders, pixel for pixel.
//!
//! [`merge_files`] reads every tile's header first and checks the set
//! before it decodes a pixel, so a set that cannot be merged (a hundred
//! copies of one tile, a tile of another render) costs its headers only;
//! the tiles are then decoded one at a time, each checked against its
//! pixels' checksum, into the image.

use crate::film::tile_file::{read_tile, read_tile_header, TileImage, TileMeta};
use crate::film::tiling::{tile_rects, TileIndex};
use crate::render::{Crop, Image};
use glam::Vec3;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

/// One reason a set of tiles cannot be merged.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum Problem {
    /// The file could not be read as a complete tile (cut short, damaged,
    /// not a tile at all).
    #[error("{0}")]
    Unreadable(String),
    /// A tile of another render: other scene, seed, files, overrides, size
    /// or tile count than the others.
    #[error("{path}: a tile of another render: {why}")]
    Foreign {
        /// The tile file.
        path: PathBuf,
        /// What differs.
        why: String,
    },
    /// The same tile in two files.
    #[error("tile {tile} is given twice: {first} and {second}")]
    Duplicate {
        /// The tile.
        tile: TileIndex,
        /// The first file holding it.
        first: PathBuf,
        /// The second.
        second: PathBuf,
    },
    /// A tile whose rectangle is not the grid's rectangle for its index.
    #[error("{path}: tile {tile} covers {got}, but tile {tile} of this image is {want}")]
    WrongRect {
        /// The tile file.
        path: PathBuf,
        /// The tile it claims to be.
        tile: TileIndex,
        /// The rectangle it covers.
        got: String,
        /// The rectangle that tile has.
        want: String,
    },
    /// A tile of the grid that no file holds.
    #[error("tile {tile} (rows {first_row}..{end_row}) is missing")]
    Missing {
        /// The tile.
        tile: TileIndex,
        /// Its first row.
        first_row: u32,
        /// The row after its last.
        end_row: u32,
    },
    /// Tiles that claim a grid no image has (more tiles than its rows of
    /// render tiles).
    #[error("the tiles claim a grid that does not exist: {0}")]
    Grid(String),
    /// Nothing to merge.
    #[error("no tiles were given")]
    NoTiles,
    /// The merged image would not fit in the memory available.
    #[error("{0}")]
    Memory(String),
}

/// Why a merge was refused: every problem found.
#[derive(Debug, thiserror::Error)]
#[error("{}", summary(.problems))]
pub struct MergeError {
    /// Every problem found, so a farm run can fix them all at once.
    pub problems: Vec<Problem>,
}

fn summary(problems: &[Problem]) -> String {
    let mut s = format!(
        "refusing to merge ({} problem{}), nothing written:",
        problems.len(),
        if problems.len() == 1 { "" } else { "s" }
    );
    for p in problems {
        let _ = write!(s, "\n  {p}");
    }
    s
}

fn rect_text(r: &Crop) -> String {
    format!("{},{},{}x{}", r.x, r.y, r.width, r.height)
}

/// What tiles of one render share: content hash, image size, tile count.
type RenderKey = (u64, [u32; 2], u32);

/// The render most tiles agree on (ties go to the first file given): the
/// others are foreign to it.
fn reference(metas: &[(PathBuf, TileMeta)]) -> RenderKey {
    let key = |m: &TileMeta| (m.content_hash, m.full_size, m.tile.count);
    let mut votes: Vec<(RenderKey, usize)> = Vec::new();
    for (_, m) in metas {
        let k = key(m);
        match votes.iter_mut().find(|(v, _)| *v == k) {
            Some((_, n)) => *n += 1,
            None => votes.push((k, 1)),
        }
    }
    let best = votes.iter().map(|(_, n)| *n).max().unwrap_or(0);
    votes
        .into_iter()
        .find(|(_, n)| *n == best)
        .map(|(k, _)| k)
        .expect("at least one tile")
}

/// Why `meta` is not of the render `want`, if it is not.
fn foreign(meta: &TileMeta, want: RenderKey) -> Option<String> {
    let (hash, [w, h], count) = want;
    let mut why = Vec::new();
    if meta.content_hash != hash {
        why.push(format!(
            "content hash {:016x}, the others {hash:016x} (another scene, seed, referenced file or override)",
            meta.content_hash
        ));
    }
    if meta.full_size != [w, h] {
        why.push(format!(
            "a {}x{} image, the others {w}x{h}",
            meta.full_size[0], meta.full_size[1]
        ));
    }
    if meta.tile.count != count {
        why.push(format!(
            "one of {} tiles, the others of {count}",
            meta.tile.count
        ));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

/// The whole image's size and which of `metas` is each band, in band
/// order, if the tiles make one image; else every problem.
fn plan(metas: &[(PathBuf, TileMeta)]) -> Result<([u32; 2], Vec<usize>), Vec<Problem>> {
    if metas.is_empty() {
        return Err(vec![Problem::NoTiles]);
    }
    let want = reference(metas);
    let (_, [width, height], count) = want;
    let grid = tile_rects(width, height, count).map_err(|e| vec![Problem::Grid(e.to_string())])?;
    let mut problems = Vec::new();
    let mut placed: BTreeMap<u32, usize> = BTreeMap::new();
    for (k, (path, m)) in metas.iter().enumerate() {
        let path = path.clone();
        if let Some(why) = foreign(m, want) {
            problems.push(Problem::Foreign { path, why });
            continue;
        }
        let tile = m.tile;
        let expected = grid[tile.index as usize];
        if m.rect != expected {
            problems.push(Problem::WrongRect {
                path,
                tile,
                got: rect_text(&m.rect),
                want: rect_text(&expected),
            });
            continue;
        }
        if let Some(&first) = placed.get(&tile.index) {
            problems.push(Problem::Duplicate {
                tile,
                first: metas[first].0.clone(),
                second: path,
            });
            continue;
        }
        placed.insert(tile.index, k);
    }
    for (i, r) in grid.iter().enumerate() {
        if !placed.contains_key(&(i as u32)) {
            problems.push(Problem::Missing {
                tile: TileIndex {
                    index: i as u32,
                    count,
                },
                first_row: r.y,
                end_row: r.y + r.height,
            });
        }
    }
    if !problems.is_empty() {
        return Err(problems);
    }
    Ok(([width, height], placed.into_values().collect()))
}

/// Checks `tiles` (each with the file it came from) and stitches them.
pub fn merge(tiles: Vec<(PathBuf, TileImage)>) -> Result<Image, MergeError> {
    let metas: Vec<(PathBuf, TileMeta)> = tiles.iter().map(|(p, t)| (p.clone(), t.meta)).collect();
    let ([width, height], order) = plan(&metas).map_err(|problems| MergeError { problems })?;
    // Bands are whole rows in index order: the image is their pixels in turn.
    let mut pixels: Vec<Vec3> = Vec::with_capacity(width as usize * height as usize);
    for k in order {
        pixels.extend_from_slice(&tiles[k].1.pixels);
    }
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Reads the tile files at `paths` and merges them: every header first
/// (a file that cannot be read is one of the problems reported, beside any
/// among the others), the set checked, the image's memory checked against
/// the limits in force, then each tile decoded and verified in turn.
pub fn merge_files(paths: &[PathBuf]) -> Result<Image, MergeError> {
    if paths.is_empty() {
        return Err(MergeError {
            problems: vec![Problem::NoTiles],
        });
    }
    let mut metas = Vec::with_capacity(paths.len());
    let mut problems = Vec::new();
    for p in paths {
        match read_tile_header(p) {
            Ok(h) => metas.push((p.clone(), h.meta)),
            Err(e) => problems.push(Problem::Unreadable(e.to_string())),
        }
    }
    let planned = if metas.is_empty() {
        None
    } else {
        match plan(&metas) {
            Ok(p) => Some(p),
            // An unreadable file is likely the tile reported missing: both
            // are said.
            Err(mut more) => {
                problems.append(&mut more);
                None
            }
        }
    };
    let (Some(([width, height], order)), true) = (planned, problems.is_empty()) else {
        return Err(MergeError { problems });
    };
    let count = width as usize * height as usize;
    displace_core::memory::check("the merged image", count as u128 * 12).map_err(|e| {
        MergeError {
            problems: vec![Problem::Memory(e.to_string())],
        }
    })?;
    let mut pixels: Vec<Vec3> = Vec::with_capacity(count);
    for k in order {
        match read_tile(&metas[k].0) {
            Ok(t) if t.meta == metas[k].1 => pixels.extend_from_slice(&t.pixels),
            Ok(_) => problems.push(Problem::Unreadable(format!(
                "{}: the tile changed while it was merged",
                metas[k].0.display()
            ))),
            Err(e) => problems.push(Problem::Unreadable(e.to_string())),
        }
    }
    if !problems.is_empty() {
        return Err(MergeError { problems });
    }
    Ok(Image {
        width,
        height,
        pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(hash: u64, index: u32, count: u32) -> (PathBuf, TileImage) {
        let rect = tile_rects(4, 64, count).unwrap()[index as usize];
        let pixels = (0..rect.width * rect.height)
            .map(|k| Vec3::splat((rect.y * rect.width + k) as f32))
            .collect();
        (
            PathBuf::from(format!("t{index}of{count}.exr")),
            TileImage {
                meta: TileMeta {
                    content_hash: hash,
                    full_size: [4, 64],
                    rect,
                    tile: TileIndex { index, count },
                },
                pixels,
            },
        )
    }

    #[test]
    fn bands_in_any_order_stitch_to_the_whole() {
        let tiles = vec![tile(7, 2, 3), tile(7, 0, 3), tile(7, 1, 3)];
        let img = merge(tiles).unwrap();
        assert_eq!((img.width, img.height), (4, 64));
        for (k, p) in img.pixels.iter().enumerate() {
            assert_eq!(*p, Vec3::splat(k as f32));
        }
    }

    #[test]
    fn every_problem_is_named() {
        let mut shifted = tile(7, 1, 3);
        shifted.1.meta.rect.y += 16;
        let e = merge(vec![
            tile(7, 0, 3),
            tile(7, 0, 3),
            tile(9, 1, 3),
            shifted,
            tile(7, 0, 4),
        ])
        .unwrap_err();
        let text = e.to_string();
        assert_eq!(e.problems.len(), 6, "{text}");
        assert!(text.contains("tile 0/3 is given twice"), "{text}");
        assert!(
            text.contains("t1of3.exr: a tile of another render: content hash 0000000000000009"),
            "{text}"
        );
        assert!(
            text.contains("t1of3.exr: tile 1/3 covers 0,32,4x16"),
            "{text}"
        );
        assert!(
            text.contains("t0of4.exr: a tile of another render: one of 4 tiles"),
            "{text}"
        );
        assert!(text.contains("tile 1/3 (rows 16..32) is missing"), "{text}");
        assert!(text.contains("tile 2/3 (rows 32..64) is missing"), "{text}");
        assert_eq!(merge(vec![]).unwrap_err().problems, vec![Problem::NoTiles]);
    }

    /// Files: a set that cannot be merged is refused from the headers
    /// alone (a damaged tile among them is never decoded, so only the
    /// set's problems are said); once the set is whole, the damaged tile
    /// is decoded and refused by its checksum; the undamaged set merges.
    #[test]
    fn files_are_checked_as_a_set_before_any_is_decoded() {
        use crate::film::tile_file::{pixel_checksum, write_tile};
        let dir = tempfile::tempdir().unwrap();
        let mut paths = Vec::new();
        for index in 0..3 {
            let (_, t) = tile(7, index, 3);
            let p = dir.path().join(format!("t{index}.exr"));
            let r = t.meta.rect;
            let img = Image {
                width: r.width,
                height: r.height,
                pixels: t.pixels,
            };
            write_tile(&p, &t.meta, &img).unwrap();
            paths.push(p);
        }
        let whole = merge_files(&paths).unwrap();
        // Tile 1's checksum swapped for another's: its pixels no longer
        // match it.
        let bytes = std::fs::read(&paths[1]).unwrap();
        let (_, t1) = tile(7, 1, 3);
        let mine = format!("{:016x}", pixel_checksum(&t1.pixels));
        let at = bytes
            .windows(16)
            .position(|w| w == mine.as_bytes())
            .unwrap();
        let mut damaged = bytes.clone();
        damaged[at..at + 16].copy_from_slice(b"0123456789abcdef");
        std::fs::write(&paths[1], &damaged).unwrap();
        let twice = [paths.clone(), vec![paths[0].clone()]].concat();
        let e = merge_files(&twice).unwrap_err().to_string();
        assert!(
            e.contains("tile 0/3 is given twice") && !e.contains("checksum"),
            "{e}"
        );
        let e = merge_files(&paths).unwrap_err().to_string();
        assert!(
            e.contains("t1.exr") && e.contains("do not match the checksum"),
            "{e}"
        );
        std::fs::write(&paths[1], &bytes).unwrap();
        assert_eq!(merge_files(&paths).unwrap(), whole);
    }
}
