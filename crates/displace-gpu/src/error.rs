//! Typed errors of the GPU crate. The binary adds context (file names) with
//! `anyhow`; each message names what failed and why.

/// Everything that can go wrong on the GPU path, each variant naming the step
/// that failed so the CLI's message says what to do.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// No adapter answered the request; the text is what was asked for.
    #[error("no GPU adapter found ({0}); on a machine without a GPU install Mesa's software Vulkan (`apt-get install mesa-vulkan-drivers`)")]
    NoAdapter(String),
    /// The adapter was found but refused to open a device (limits, features).
    #[error("could not open the GPU device on {adapter}: {message}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// What the driver said.
        message: String,
    },
    /// A validation or out-of-memory error the device reported during a step.
    #[error("the GPU reported an error while {during}: {message}")]
    Gpu {
        /// The step, as "while ..." reads it.
        during: String,
        /// What the device said.
        message: String,
    },
    /// A ray of a batch query is unusable (non-finite, zero direction).
    #[error("ray {index}: {reason}")]
    InvalidRay {
        /// The ray's index in the batch.
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A map or image is larger than this device accepts.
    #[error("{what} {size} exceeds this GPU's limit of {limit}")]
    Limit {
        /// What was too large ("distance map", "image").
        what: String,
        /// Its size as asked for.
        size: String,
        /// The device's limit.
        limit: String,
    },
    /// The viewer could not open its window.
    #[error(
        "could not open a window: {0} (the viewer needs a display: DISPLAY set, or Xvfb running)"
    )]
    Window(String),
    /// An option the GPU path cannot honour (tiles on a clamped map, NaN bounds).
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// A step count the GPU cannot trace
    /// ([`crate::convention::MAX_GPU_ITERATIONS`] says why).
    #[error("{0} steps: the GPU traces 1..={max} steps per ray (drivers cut longer loops short: lavapipe ends a shader's loops after 65535 iterations in all)", max = crate::convention::MAX_GPU_ITERATIONS)]
    Iterations(u32),
    /// A scene the GPU raster path cannot draw as it stands (no light, a
    /// face traced with the CPU's exact reference, nothing it draws).
    #[error("{0}")]
    Scene(String),
    /// A step of turning a scene into draws failed; `during` names the
    /// shape and step, and the cause follows as the error's source (the
    /// CLI joins the two with `: `).
    #[error("{during}")]
    SceneStep {
        /// The shape and step ("uploading displaced face 3").
        during: String,
        /// What failed.
        #[source]
        source: Box<Error>,
    },
    /// An error of the map itself (loading, baking, checking).
    #[error(transparent)]
    Core(#[from] displace_core::Error),
}
