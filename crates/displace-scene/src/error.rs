//! Typed errors of the renderer. Every variant names the file or the scene
//! key at fault, so the binary can print it as is.

use std::path::PathBuf;

/// Everything that can stop a scene from loading or a render from finishing.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Malformed TOML or a value of the wrong type: where it is.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
        /// What the parser says.
        message: String,
    },
    /// A well-formed scene that makes no sense (camera looking nowhere, zero
    /// image size, ...).
    #[error("{}{}: {message}", .path.display(), line_column_suffix(*.at))]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// Line and column (from 1) of the key's value in the scene file,
        /// where the file has it (a default that is at fault has none).
        at: Option<(usize, usize)>,
        /// The key at fault (first, as a key path such as
        /// `shapes[2].displacement.depth`) and why.
        message: String,
    },
    /// An OBJ mesh is malformed or too large.
    #[error("{path}: {message}")]
    Mesh {
        /// The OBJ file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The height map, bake or trace refused its input, or a file could not
    /// be read, written, decoded or encoded (core's `Io` and `Image`: one
    /// spelling of those for every crate).
    #[error(transparent)]
    Core(#[from] displace_core::Error),
    /// A render option out of range (crop outside the image, zero samples).
    #[error("invalid render option: {0}")]
    Option(String),
    /// The render was interrupted (Ctrl-C); nothing was written.
    #[error("render cancelled")]
    Cancelled,
}

/// The renderer's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `:line:column` where a place is known, else nothing.
fn line_column_suffix(at: Option<(usize, usize)>) -> String {
    at.map_or(String::new(), |(line, column)| format!(":{line}:{column}"))
}

/// 1-based line and column (in characters) of byte offset `at` of a text:
/// where [`Error::Parse`] and [`Error::Scene`] point in a scene or OBJ file.
pub fn line_column(text: &str, at: usize) -> (usize, usize) {
    let at = at.min(text.len());
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_columns_are_one_based() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
    }
}
