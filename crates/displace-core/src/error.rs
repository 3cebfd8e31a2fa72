//! Typed errors of the core library. The binary adds context (file names)
//! with `anyhow`; every message here names the offending value.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("invalid height map: {0}")]
    InvalidHeightMap(String),
    #[error("invalid extent: {0}")]
    InvalidExtent(String),
    #[error("invalid size: {0}")]
    InvalidSize(String),
    #[error(
        "size {what} = {size} is too large: it would need {bytes} bytes (limit {limit} bytes)"
    )]
    TooLarge {
        what: String,
        size: String,
        bytes: u128,
        limit: u128,
    },
    #[error("unknown generator `{0}` (known: flat, gaussian, studded, grating, text, noise)")]
    UnknownGenerator(String),
    #[error("generator `{generator}`: {message}")]
    GeneratorParameter { generator: String, message: String },
    #[error("invalid trace: {0}")]
    InvalidTrace(String),
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Image { path: PathBuf, message: String },
    #[error("operation cancelled")]
    Cancelled,
}
