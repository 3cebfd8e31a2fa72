//! Where a streamed bake's slices go, and in what form: slabs of values
//! ([`Slab`]) or of r8 codes ([`CodedSlab`]), handed to a [`SlabSink`] in
//! order of depth.

use crate::distance_map::R8Encoder;
use crate::{Address, Error, Extent, Result};

/// One slab of consecutive depth slices of a streamed bake, handed to the
/// sink of [`bake_streamed`](crate::bake_streamed) in order of depth.
#[derive(Debug)]
pub struct Slab<'a> {
    /// Depth index of the slab's first slice.
    pub first: usize,
    /// The slices' values (`[k][j][i]`, depth units), exactly as [`bake`](fn@crate::bake)
    /// computes them.
    pub values: &'a [f32],
    /// The lowest of `values` (found as they were computed, so a sink need
    /// not pass over them again).
    pub min: f32,
    /// A lower bound on every value of the slices still to come (`+inf`
    /// after the last slab), so that a writer whose header depends on the
    /// volume's minimum (KTX2's r8 range) can settle it early instead of
    /// holding the whole volume.
    pub rest_lower_bound: f32,
}

/// What a streamed bake knows about its map before any slab is computed.
#[derive(Clone, Copy, Debug)]
pub struct BakeLayout {
    /// Distance-map voxels `[W, H, D]`.
    pub size: [usize; 3],
    /// Tile width and height in shell depths.
    pub aspect: [f32; 2],
    /// The map's addressing (the height map's).
    pub address: Address,
    /// Physical size of one tile.
    pub extent: Extent,
    /// The bound [`DistanceMap::from_raw`](crate::DistanceMap::from_raw) takes, before any rounding.
    pub underestimate: f32,
}

/// Where a streamed bake's slabs go ([`crate::io::stream::MapStream`]
/// writes them to a file).
pub trait SlabSink {
    /// Called once, before the first slab, with what a writer needs for its
    /// header.
    fn begin(&mut self, layout: BakeLayout) -> Result<()>;
    /// Called with each slab, in order of depth.
    fn push(&mut self, slab: Slab<'_>) -> Result<()>;

    /// The encoder of the sink's R8 codes, once what it writes no longer
    /// depends on the values still to come (a KTX2 r8 file's range
    /// settled, a DDS r8 file's fixed one): the bake then encodes each
    /// value as it computes it and hands the slabs' codes to
    /// [`Self::push_codes`] instead of their values to [`Self::push`], so
    /// that the values never go through memory as `f32` (their write and
    /// read back were a fifth of an r8 bake). `None`, the default: values.
    fn encoder(&self) -> Option<R8Encoder> {
        None
    }

    /// A buffer for a slab's codes: one the sink has finished with, where
    /// it keeps them, or a new one.
    fn code_buffer(&mut self) -> Vec<u8> {
        Vec::new()
    }

    /// Called with the codes of each slice, in order of depth, once
    /// [`Self::encoder`] gave an encoder (it is asked before each slab).
    fn push_codes(&mut self, slab: CodedSlab) -> Result<()> {
        Err(Error::Invariant(format!(
            "codes of depth slices from {} were pushed to a sink that offered no encoder",
            slab.first
        )))
    }
}

/// Depth slices of a streamed bake as R8 codes ([`SlabSink::push_codes`];
/// one slice each, from the bake's pipeline).
#[derive(Debug)]
pub struct CodedSlab {
    /// Depth index of the first slice.
    pub first: usize,
    /// The codes of the slices' values (`[k][j][i]`), as the sink's
    /// encoder gives them.
    pub codes: Vec<u8>,
    /// The lowest of the slices' values.
    pub min: f32,
    /// A lower bound on every value of the slices still to come (as
    /// [`Slab::rest_lower_bound`]).
    pub rest_lower_bound: f32,
}
