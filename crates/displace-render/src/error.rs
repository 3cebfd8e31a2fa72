//! Typed errors of the renderer. Every variant names the file or the scene
//! key at fault, so the binary can print it as is.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Malformed TOML or a value of the wrong type: where it is.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// A well-formed scene that makes no sense (camera looking nowhere, zero
    /// image size, ...).
    #[error("{path}: {message}")]
    Scene { path: PathBuf, message: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Image { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Mesh { path: PathBuf, message: String },
    #[error(transparent)]
    Core(#[from] displace_core::Error),
    #[error("invalid render option: {0}")]
    Option(String),
    #[error("render cancelled")]
    Cancelled,
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
