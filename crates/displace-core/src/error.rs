//! Typed errors of the core library. The binary adds context (file names)
//! with `anyhow`; every message here names the offending value.

use std::path::{Path, PathBuf};

/// Every failure of the core library. Variants carry the offending value
/// in their message, so callers can show it unchanged.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A height map smaller than 2x2, a size that does not match its data,
    /// a height that is not finite or lies outside `[0, 1]`, or an unknown
    /// image channel.
    #[error("invalid height map: {0}")]
    InvalidHeightMap(String),
    /// A tile extent or map aspect that is zero, negative or not finite.
    #[error("invalid extent: {0}")]
    InvalidExtent(String),
    /// A size that is too small, unparsable or not positive, values that do
    /// not match their size (or a distance map holding NaN), a streamed map
    /// fed out of order, or an unparsable memory limit.
    #[error("invalid size: {0}")]
    InvalidSize(String),
    /// A name that is none of the known choices (an addressing mode, a
    /// storage format): the message says which names are known.
    #[error("{0}")]
    UnknownName(String),
    /// A size whose allocation would exceed
    /// [`crate::convention::MAX_ALLOCATION_BYTES`]; refused before allocating.
    #[error(
        "size {what} = {size} is too large: it would need {bytes} bytes (limit {limit} bytes)"
    )]
    TooLarge {
        /// What was being allocated ("distance map", "height map", ...).
        what: String,
        /// The requested size as written (`WxH` or `WxHxD`).
        size: String,
        /// Bytes the allocation would need.
        bytes: u128,
        /// The limit it exceeds, in bytes.
        limit: u128,
    },
    /// A job whose estimated peak memory exceeds the limit
    /// ([`crate::memory::check`]); the message has the estimate.
    #[error("{message}")]
    OutOfMemory {
        /// The estimate against the limit, in words.
        message: String,
    },
    /// An output larger than the free space of the file system it goes to,
    /// found before any work ([`crate::io::atomic::check_free_space`]).
    #[error("{}: the output needs {needed} bytes ({:.2} GiB) but its file system has {free} bytes ({:.2} GiB) free", .path.display(), *.needed as f64 / GIB, *.free as f64 / GIB)]
    DiskSpace {
        /// The output file.
        path: PathBuf,
        /// Bytes the output will take.
        needed: u64,
        /// Bytes free to an unprivileged writer there.
        free: u64,
    },
    /// A `gen:` height-map spec naming no known generator.
    #[error("unknown generator `{0}` (known: flat, gaussian, studded, grating, text, noise)")]
    UnknownGenerator(String),
    /// A known generator given an unknown, malformed or out-of-range parameter.
    #[error("generator `{generator}`: {message}")]
    GeneratorParameter {
        /// The generator's name (`noise`, `text`, ...).
        generator: String,
        /// What was wrong with the parameter.
        message: String,
    },
    /// Trace options that cannot be used: an unknown method name, or a
    /// technique run without the map it needs.
    #[error("invalid trace: {0}")]
    InvalidTrace(String),
    /// A ray given by a user that cannot be traced (a component not finite
    /// or too large, a direction of no length, a bad `t_max`); the message
    /// names the ray and its column.
    #[error("{0}")]
    InvalidRay(String),
    /// A map file with an unknown extension, a format it cannot hold, or
    /// contents that break its format (KTX2, DDS, NumPy `.npy`).
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What in it is wrong.
        message: String,
    },
    /// An operating-system error reading or writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A height source that is not `gen:NAME`, a PNG, JPEG, TIFF or EXR, or an image
    /// that cannot be decoded or read as heights.
    #[error("{path}: {message}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        message: String,
    },
    /// An input path that is not a regular file, or too large to read
    /// ([`crate::io::check_input`]).
    #[error("{path}: {message}")]
    Input {
        /// The path.
        path: PathBuf,
        /// Why it is refused.
        message: String,
    },
    /// A property the library's own reasoning relies on was found broken at
    /// run time, where it is checked instead of trusted (a streamed bake's
    /// promise about the slabs to come): nothing is written; please report
    /// it with the input.
    #[error("an invariant did not hold: {0}")]
    Invariant(String),
    /// A bake stopped early because its cancel flag was set.
    #[error("operation cancelled")]
    Cancelled,
}

/// Bytes in a GiB, for messages.
const GIB: f64 = (1u64 << 30) as f64;

impl Error {
    /// [`Error::Io`] for the file at `path`: one spelling of the most common
    /// error, for every crate that reads or writes files.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// [`Error::Image`] for the file at `path`: what a height map's or an
    /// image's decoder found wrong with it, whichever loader read it.
    pub fn image(path: &Path, what: impl std::fmt::Display) -> Self {
        Error::Image {
            path: path.to_path_buf(),
            message: what.to_string(),
        }
    }
}
