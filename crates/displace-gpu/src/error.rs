//! Typed errors of the GPU crate. The binary adds context (file names) with
//! `anyhow`; each message names what failed and why.

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("no GPU adapter found ({0}); on a machine without a GPU install Mesa's software Vulkan (`apt-get install mesa-vulkan-drivers`)")]
    NoAdapter(String),
    #[error("could not open the GPU device on {adapter}: {message}")]
    Device { adapter: String, message: String },
    #[error("the GPU reported an error while {during}: {message}")]
    Gpu { during: String, message: String },
    #[error("ray {index}: {reason}")]
    InvalidRay { index: usize, reason: String },
    #[error("{what} {size} exceeds this GPU's limit of {limit}")]
    Limit {
        what: String,
        size: String,
        limit: String,
    },
    #[error(
        "could not open a window: {0} (the viewer needs a display: DISPLAY set, or Xvfb running)"
    )]
    Window(String),
    #[error("invalid option: {0}")]
    InvalidOption(String),
    #[error(transparent)]
    Core(#[from] displace_core::Error),
}
