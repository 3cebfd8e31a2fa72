//! `--frame F|auto` and `--frames A..B`: which frames of an animated scene
//! one `render` command draws, and the file each goes to (`%04d` in the
//! output name replaced by the frame number, else `_NNNN` appended to its
//! stem for `--frames`).

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// The `(frame, output)` pairs to render: one `(None, output)` for a still.
pub fn jobs(
    frame: Option<&str>,
    frames: Option<&str>,
    output: &Path,
) -> Result<Vec<(Option<u32>, PathBuf)>> {
    if let Some(f) = frame {
        let f = match f.trim() {
            "auto" => crate::farm_env::task_index("--frame auto")?,
            n => n.parse().with_context(|| {
                format!("--frame `{f}`: expected a frame number (from 0) or `auto`")
            })?,
        };
        return Ok(vec![(Some(f), frame_path(output, f, false))]);
    }
    let Some(range) = frames else {
        return Ok(vec![(None, output.to_path_buf())]);
    };
    let bad = || format!("--frames `{range}`: expected A..B, frames A to B-1 (e.g. 0..48)");
    let (a, b) = range.split_once("..").with_context(bad)?;
    let a: u32 = a.trim().parse().with_context(bad)?;
    let b: u32 = b.trim().parse().with_context(bad)?;
    if a >= b {
        bail!("--frames {range}: the range is empty (the end is not included)");
    }
    Ok((a..b)
        .map(|f| (Some(f), frame_path(output, f, true)))
        .collect())
}

/// `output` for frame `f`: its `%04d` replaced, or (with `append`) the
/// number appended to the stem, `out.png` -> `out_0007.png`.
pub fn frame_path(output: &Path, f: u32, append: bool) -> PathBuf {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let named = if name.contains("%04d") {
        name.replace("%04d", &format!("{f:04}"))
    } else if append {
        let stem = output.file_stem().unwrap_or_default().to_string_lossy();
        match output.extension() {
            Some(e) => format!("{stem}_{f:04}.{}", e.to_string_lossy()),
            None => format!("{stem}_{f:04}"),
        }
    } else {
        return output.to_path_buf();
    };
    output.with_file_name(named)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_names() {
        assert_eq!(
            frame_path(Path::new("d/out.png"), 7, true),
            Path::new("d/out_0007.png")
        );
        assert_eq!(
            frame_path(Path::new("f_%04d.exr"), 12, false),
            Path::new("f_0012.exr")
        );
        assert_eq!(
            frame_path(Path::new("still.png"), 3, false),
            Path::new("still.png")
        );
        let j = jobs(None, Some("2..4"), Path::new("o.png")).unwrap();
        assert_eq!(
            j,
            vec![
                (Some(2), PathBuf::from("o_0002.png")),
                (Some(3), PathBuf::from("o_0003.png"))
            ]
        );
        for bad in ["3", "4..4", "5..2", "a..3", "1..x"] {
            assert!(jobs(None, Some(bad), Path::new("o.png")).is_err(), "{bad}");
        }
        assert!(jobs(Some("x"), None, Path::new("o.png")).is_err());
    }
}
