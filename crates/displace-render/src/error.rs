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
    #[error("{path}: {message}")]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// The key at fault and why.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// An image (texture, environment map, output) could not be decoded or
    /// encoded.
    #[error("{path}: {message}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// What the codec says.
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
    /// The height map, bake or trace refused its input.
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
