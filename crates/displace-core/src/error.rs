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
    /// A name that is none of the known choices (an addressing mode, a
    /// storage format): the message says which names are known.
    #[error("{0}")]
    UnknownName(String),
    #[error(
        "size {what} = {size} is too large: it would need {bytes} bytes (limit {limit} bytes)"
    )]
    TooLarge {
        what: String,
        size: String,
        bytes: u128,
        limit: u128,
    },
    /// A job whose estimated peak memory exceeds the limit
    /// ([`crate::memory::check`]); the message has the estimate.
    #[error("{message}")]
    OutOfMemory { message: String },
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
    /// An input path that is not a regular file, or too large to read
    /// ([`crate::io::check_input`]).
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    #[error("operation cancelled")]
    Cancelled,
}
