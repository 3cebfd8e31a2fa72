//! What a bake is asked for: the distance map's resolution, the tile's
//! proportions, and the caller's hooks for progress and cancellation.

use crate::convention::Extent;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Called with `(slices done, slices in all)` as the bake progresses.
pub type Progress = Arc<dyn Fn(usize, usize) + Send + Sync>;

/// What [`bake`](fn@crate::bake) builds: the distance map's resolution, the tile's
/// proportions, and the caller's hooks for progress and cancellation.
#[derive(Clone)]
pub struct BakeOptions {
    /// Distance-map voxels `[W, H, D]`. Donnelly used 256x256x16.
    pub size: [usize; 3],
    /// Physical size of one tile of the face.
    pub extent: Extent,
    /// Told after each depth slice; `None` for silence.
    pub progress: Option<Progress>,
    /// Set to stop a bake early; [`bake`](fn@crate::bake) then returns [`Error::Cancelled`](crate::Error::Cancelled).
    pub cancel: Option<Arc<AtomicBool>>,
}

impl Default for BakeOptions {
    fn default() -> Self {
        Self {
            size: [256, 256, 16],
            extent: Extent {
                sx: 1.0,
                sy: 1.0,
                sz: 0.1,
            },
            progress: None,
            cancel: None,
        }
    }
}

impl BakeOptions {
    /// A bake of `size` voxels over tiles of `extent`, silent and not
    /// cancellable: what a caller without a progress bar or a Ctrl-C
    /// handler (a test, a benchmark, a one-off tool) asks for.
    pub fn new(size: [usize; 3], extent: Extent) -> Self {
        Self {
            size,
            extent,
            ..Self::default()
        }
    }
}

impl std::fmt::Debug for BakeOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BakeOptions")
            .field("size", &self.size)
            .field("extent", &self.extent)
            .finish_non_exhaustive()
    }
}
