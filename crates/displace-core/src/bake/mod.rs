//! The bake (height map -> normal map + conservative distance map): the
//! options, the whole bake ([`bake`]) and the streamed one
//! ([`bake_streamed`], a slab of slices at a time into a [`SlabSink`]),
//! planned slice by slice (`plan`) over the surface ranges of the map's
//! columns (`ranges`); r8 codes written as the slices finish (`coded`).

use crate::distance_map::DistanceMap;
use crate::{DisplacementMap, HeightMap, NormalMap, Result};
use std::sync::atomic::AtomicUsize;

pub(crate) mod coded;
mod options;
mod plan;
mod ranges;
mod sink;

pub use options::{BakeOptions, Progress};
pub use sink::{BakeLayout, CodedSlab, Slab, SlabSink};

use plan::{check_promise, BakePlan};

/// Bakes the normal map and the conservative distance map of `height` for
/// one tile of `opts.extent`.
///
/// Cost: `O(W H D)` for the distance transform (two 1D passes of the lower
/// envelope per depth slice, slices in parallel) plus the exact height range
/// of every column footprint. Memory: the output plus one 32-column block per
/// thread. [`bake_streamed`] computes the same values a slab at a time, for
/// writers that need not hold the whole volume.
pub fn bake(height: &HeightMap, opts: &BakeOptions) -> Result<DisplacementMap> {
    let distance = bake_distance(height, opts)?;
    Ok(DisplacementMap {
        normals: NormalMap::from_height(height, opts.extent)?,
        height: height.clone(),
        distance,
        extent: opts.extent,
    })
}

/// The distance map alone of [`bake`] (the same values): what ray queries
/// need, which never read the shading normals. Against [`bake`] it saves
/// the normal map and the copy of the heights (20 of the 24 bytes a texel
/// [`crate::memory::BAKE_BYTES_PER_TEXEL`] counts, most of a bake's peak
/// when the map is coarser than the heights, as Donnelly's maps are:
/// GPU Gems 2, ch. 8, sec. 8.4).
pub fn bake_distance(height: &HeightMap, opts: &BakeOptions) -> Result<DistanceMap> {
    let plan = BakePlan::new(height, opts, true)?;
    let [w, h, d] = plan.size;
    let done = AtomicUsize::new(0);
    let mut data = crate::memory::zeroed::<f32>("the distance volume", w * h * d)?;
    plan.slices(0, &mut data, &mut vec![0.0; d], opts, &done)?;
    DistanceMap::from_raw(
        plan.size,
        plan.aspect,
        plan.address,
        data,
        plan.underestimate(),
    )
}

/// Bakes the distance map of [`bake`] a slab of `slab_slices` depth slices
/// at a time (each slab's slices in parallel) and hands each slab to `sink`
/// in order, so that peak memory is the height map, its column ranges and
/// one slab rather than the whole volume. The values are bit-identical to
/// [`bake`]'s. Once the sink offers an encoder ([`SlabSink::encoder`]: an
/// r8 file whose range is known, usually after the first slab) and slices
/// are small ([`crate::memory::SMALL_SLICE_VOXELS`]) the rest is computed
/// as codes, each slice taken by whichever of up to `slab_slices`
/// threads is free and pushed in order of depth ([`SlabSink::push_codes`]),
/// with no barrier between slabs.
pub fn bake_streamed(
    height: &HeightMap,
    opts: &BakeOptions,
    slab_slices: usize,
    sink: &mut (impl SlabSink + Send),
) -> Result<()> {
    let stored = crate::memory::stores_column_ranges([height.width(), height.height()], opts.size);
    let plan = BakePlan::new(height, opts, stored)?;
    sink.begin(BakeLayout {
        size: plan.size,
        aspect: plan.aspect,
        address: plan.address,
        extent: plan.extent,
        underestimate: plan.underestimate(),
    })?;
    let [w, h, d] = plan.size;
    let slab_slices = slab_slices.clamp(1, d);
    // Suffix minima of the per-slice lower bounds.
    let mut rest = vec![f32::INFINITY; d + 1];
    for k in (0..d).rev() {
        rest[k] = rest[k + 1].min(plan.slice_lower_bound(k));
    }
    let done = AtomicUsize::new(0);
    let mut buf =
        crate::memory::zeroed::<f32>("a slab of the distance volume", w * h * slab_slices)?;
    let mut mins = vec![0.0f32; slab_slices];
    // The bound promised for the slices still to come, checked on each.
    let mut promised = f32::NEG_INFINITY;
    let small = crate::memory::small_slices(w * h);
    for first in (0..d).step_by(slab_slices) {
        let encoder = if small { sink.encoder() } else { None };
        if let Some(encoder) = encoder {
            // The sink's range is known: codes, a slice at a time.
            return coded::bake_coded(
                &plan, first, promised, &encoder, &rest, &mut buf, sink, opts, &done,
            );
        }
        let n = slab_slices.min(d - first);
        let values = &mut buf[..w * h * n];
        let mins = &mut mins[..n];
        plan.slices(first, values, mins, opts, &done)?;
        let min = mins.iter().copied().fold(f32::INFINITY, f32::min);
        check_promise(first..first + n, min, promised)?;
        let rest_lower_bound = plan.promise(&rest, first + n, mins[n - 1]);
        sink.push(Slab {
            first,
            values,
            min,
            rest_lower_bound,
        })?;
        promised = rest_lower_bound;
    }
    Ok(())
}
