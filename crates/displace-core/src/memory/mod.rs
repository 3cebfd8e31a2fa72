//! Whole-command memory estimates, checked before anything large is
//! allocated. [`crate::convention::check_allocation`] bounds one buffer;
//! a bake holds several at once (the height map and its copy, the normal
//! map, the distance volume and its codes, the column ranges, the outputs),
//! so a size every buffer of which passes can still need several times the
//! machine's memory and end in the kernel's OOM killer. The estimate of the
//! whole peak is compared with the least limit in force ([`limit`]): the
//! memory the machine has available (`MemAvailable` of `/proc/meminfo`) or
//! [`LIMIT_ENV`] when set, and under either the hard limits of a cgroup or
//! of `ulimit -v` and `-d` ([`hard_limits`]).

mod alloc;
mod huge_pages;
mod limits;

pub use alloc::{filled, zeroed, Zeroable};
pub use huge_pages::{HugePages, LARGE};
pub use limits::{available, check, hard_limits, human, limit, parse_bytes, Limit};

/// Environment variable that sets the memory limit of a command, in bytes
/// with an optional `K`, `M`, `G` or `T` suffix (powers of 1024): set it
/// higher than the available memory to allow a larger job (swap, memory
/// about to be freed), or lower to keep a job small. It cannot raise a
/// hard limit ([`hard_limits`]): those are kept below it.
pub const LIMIT_ENV: &str = "DISPLACE_MEMORY_LIMIT";

/// Bytes a bake holds per height-map texel at its peak: the map (4) and
/// the copy the baked map keeps (4), the normal map (12), and the decoded
/// image or the 8-bit normal PNG on the way in or out (4).
pub const BAKE_BYTES_PER_TEXEL: u128 = 2 * HEIGHT_BYTES_PER_TEXEL + NORMAL_BYTES_PER_TEXEL;

/// Bytes a distance-only bake ([`crate::bake_distance`]) holds per
/// height-map texel: the map it reads (4), nothing more.
pub const DISTANCE_BAKE_BYTES_PER_TEXEL: u128 = HEIGHT_BYTES_PER_TEXEL;

/// Bytes per cone-map texel: the cones (4) and their working rows (4).
pub const CONE_BYTES_PER_TEXEL: u128 = 8;

/// Bytes per distance-map voxel: the float volume (4), its 8-bit codes
/// (1) and an encoded output buffer (4).
pub const BAKE_BYTES_PER_VOXEL: u128 = 9;

/// Bytes per distance-map column (`W x H`): the exact height range of its
/// footprint, low, high and centre (12).
pub const BAKE_BYTES_PER_COLUMN: u128 = RANGE_BYTES_PER_COLUMN + CENTRE_BYTES_PER_COLUMN;

/// Estimated peak bytes of baking a `height` texel map into a `map`
/// voxel distance map, with a cone map at the height map's resolution when
/// `cones`.
pub fn bake_peak_bytes(height: [usize; 2], map: [usize; 3], cones: bool) -> u128 {
    let texels = height[0] as u128 * height[1] as u128;
    distance_bake_peak_bytes(height, map)
        + texels * (BAKE_BYTES_PER_TEXEL - DISTANCE_BAKE_BYTES_PER_TEXEL)
        + if cones {
            texels * CONE_BYTES_PER_TEXEL
        } else {
            0
        }
}

/// Estimated peak bytes of [`crate::bake_distance`]: [`bake_peak_bytes`]
/// without the normal map and the copy of the heights.
pub fn distance_bake_peak_bytes(height: [usize; 2], map: [usize; 3]) -> u128 {
    let texels = height[0] as u128 * height[1] as u128;
    let columns = map[0] as u128 * map[1] as u128;
    texels * DISTANCE_BAKE_BYTES_PER_TEXEL
        + columns * map[2] as u128 * BAKE_BYTES_PER_VOXEL
        + columns * BAKE_BYTES_PER_COLUMN
}

/// Bytes per voxel of a slab in flight in a streamed bake
/// ([`crate::bake_streamed`] into [`crate::io::stream::MapStream`]): its
/// values (4).
pub const STREAM_BYTES_PER_SLAB_VOXEL: u128 = 4;

/// Depth slices of at most this many voxels (2048x2048) count as small in a
/// streamed bake. Only small slices go through the coded pipeline
/// ([`crate::SlabSink::encoder`]: codes written as the values are computed,
/// threads taking slices as they are free and a slice ahead of each other,
/// the writer queueing a slice so that no thread waits for it to wake, a
/// millisecond on a virtual machine, as long as a 512x512 slice takes).
/// That is where a slab's barrier and a separate encoding pass cost most
/// (at 2048x2048x64 the whole command went from 0.80-0.93 s to 0.71-0.86
/// s, best and median of twelve). Large slices are computed a slab at a
/// time and encoded after: at 8192x8192 the finish's codes, 32 bytes a row
/// and a row 8 KB apart, leave each cache line half written until the next
/// block of columns, and that costs more than the pipeline saves (user time
/// 68.4 s against 61.8 s); and there a slice of codes is 64 MB, which the
/// 8K bake's memory cannot spare for a queue.
pub const SMALL_SLICE_VOXELS: usize = 2048 * 2048;

/// Whether `plane`-voxel slices count as small ([`SMALL_SLICE_VOXELS`]).
pub fn small_slices(plane: usize) -> bool {
    plane <= SMALL_SLICE_VOXELS
}

/// Encoded slices the writer of a streamed bake holds with `plane`-voxel
/// slices: the one being written, and one queued where slices are small
/// ([`SMALL_SLICE_VOXELS`]).
pub fn writer_slices(plane: usize) -> usize {
    1 + usize::from(small_slices(plane))
}

/// Encoded depth slices a streamed bake of a `map`-voxel distance map holds
/// at once with `slab_slices` slices computed at once: with small slices,
/// every slice its threads may have started (their window: an r8 file's
/// codes are written as the values are computed), otherwise the slice being
/// encoded; then those the writer holds ([`writer_slices`]).
pub fn stream_encoded_slices(slab_slices: usize, map: [usize; 3]) -> u128 {
    let plane = map[0] * map[1];
    let filled = if small_slices(plane) {
        crate::bake::coded::window(slab_slices)
    } else {
        1
    };
    (filled + writer_slices(plane)) as u128
}

/// Bytes per column of the stored footprint ranges alone (low and high).
pub const RANGE_BYTES_PER_COLUMN: u128 = 8;

/// Bytes per column of the column-centre heights where they are not read
/// from the height map itself: where they differ from its texels, and where
/// the column ranges are kept too (then the centres are kept in the order
/// the transform's second pass reads them, a block of columns at a time,
/// rather than a row's stride apart).
pub const CENTRE_BYTES_PER_COLUMN: u128 = 4;

/// Depth from which a streamed bake keeps every column's footprint range
/// rather than working it out again in each slice: at 64 slices the ranges'
/// 8 bytes a column are an eighth of an r8 file and less than the slices a
/// two-thread bake has in flight; shallower maps, whose files are smaller,
/// would spend more on them than on their slices, so they pay for holding
/// none in time (measured at 4096x4096 heights and map: 5-20% of the bake
/// on one thread, 25-35% on two, whose rows share L2 with the transform).
pub const STORED_RANGES_MIN_DEPTH: usize = 64;

/// Height texels per map column from which a streamed bake keeps its
/// column ranges at any depth: working out a row's ranges reads every
/// texel under it, so a map coarser than its heights (an 8K height map
/// traced with a 2K map) would read the whole height map again in every
/// slice; kept, the ranges are at most 2 bytes a height texel, half the
/// heights' own memory. From an 8192x8192 elevation model, 32 slices of
/// 1024x1024: 4.0 s to 2.3 s; of 4096x4096: 9.4 s to 4.4 s.
pub const STORED_RANGES_MIN_TEXELS_PER_COLUMN: usize = 4;

/// Whether a streamed bake of a `height`-texel map into a `map`-voxel
/// distance map keeps its column ranges ([`STORED_RANGES_MIN_DEPTH`],
/// [`STORED_RANGES_MIN_TEXELS_PER_COLUMN`]); [`crate::bake_streamed`] and
/// the estimate both ask this.
pub fn stores_column_ranges(height: [usize; 2], map: [usize; 3]) -> bool {
    let texels = height[0] as u128 * height[1] as u128;
    let columns = map[0] as u128 * map[1] as u128;
    map[2] >= STORED_RANGES_MIN_DEPTH
        || texels >= STORED_RANGES_MIN_TEXELS_PER_COLUMN as u128 * columns
}

/// Whether a bake surely reads its column-centre heights from the height
/// map: the same size, a power of two on each side, so that every centre's
/// coordinate and weights are exact and its sample is its texel. (The bake
/// compares sample by sample, and borrows wherever they match.)
pub fn centres_are_texels(height: [usize; 2], map: [usize; 3]) -> bool {
    height == [map[0], map[1]] && height.iter().all(|n| n.is_power_of_two())
}

/// Bytes per texel of the height map a bake works from (4).
pub const HEIGHT_BYTES_PER_TEXEL: u128 = 4;

/// Bytes per texel of an image being decoded into heights, beside them (4).
pub const DECODE_BYTES_PER_TEXEL: u128 = 4;

/// Bytes per texel of the normal map (12) and its 8-bit PNG on the way out
/// (4).
pub const NORMAL_BYTES_PER_TEXEL: u128 = 16;

/// What a streamed bake holds, for [`streamed_bake_peak_bytes`].
#[derive(Clone, Copy, Debug)]
pub struct StreamedBake {
    /// Height-map texels `[W, H]`.
    pub height: [usize; 2],
    /// Distance-map voxels `[W, H, D]`.
    pub map: [usize; 3],
    /// Depth slices computed at once.
    pub slab_slices: usize,
    /// Bytes per voxel of the encoded output.
    pub encoded_bytes_per_voxel: u128,
    /// Bytes per voxel the writer must hold to the end (a KTX2 r16f level:
    /// 2; otherwise 0).
    pub held_bytes_per_voxel: u128,
    /// Whether a normal map is written after the distance map.
    pub normals: bool,
    /// Whether a cone map is built after the distance map.
    pub cones: bool,
}

/// Estimated peak bytes of a streamed bake, the largest of its phases, one
/// after the other: decoding the heights; the distance map (the heights,
/// the slab's values, [`stream_encoded_slices`] encoded slices, the direct
/// writer's buffer, what the writer holds, the column ranges where they
/// are kept and the centres where they are not borrowed from the height
/// map); then the normal map and the cone map, each beside the heights.
pub fn streamed_bake_peak_bytes(b: &StreamedBake) -> u128 {
    let texels = b.height[0] as u128 * b.height[1] as u128;
    let columns = b.map[0] as u128 * b.map[1] as u128;
    let voxels = columns * b.map[2] as u128;
    let slab = columns * b.slab_slices.clamp(1, b.map[2].max(1)) as u128;
    let heights = texels * HEIGHT_BYTES_PER_TEXEL;
    let load = heights + texels * DECODE_BYTES_PER_TEXEL;
    let distance = heights
        + slab * STREAM_BYTES_PER_SLAB_VOXEL
        + columns * stream_encoded_slices(b.slab_slices, b.map) * b.encoded_bytes_per_voxel
        + crate::io::direct::DIRECT_BUFFER_BYTES as u128
        + voxels * b.held_bytes_per_voxel
        + if stores_column_ranges(b.height, b.map) {
            columns * RANGE_BYTES_PER_COLUMN
        } else {
            0
        }
        + if centres_are_texels(b.height, b.map) && !stores_column_ranges(b.height, b.map) {
            0
        } else {
            // In the transform's block order, the last block padded.
            (b.map[0].div_ceil(crate::edt::BLOCK) * crate::edt::BLOCK) as u128
                * b.map[1] as u128
                * CENTRE_BYTES_PER_COLUMN
        };
    let normals = if b.normals {
        heights + texels * NORMAL_BYTES_PER_TEXEL
    } else {
        0
    };
    let cones = if b.cones {
        heights + texels * CONE_BYTES_PER_TEXEL
    } else {
        0
    };
    load.max(distance).max(normals).max(cones)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_issue_bake_is_about_twenty_bytes_a_texel() {
        // `bake gen:flat --height-size 46000x46000 --size 32x32x8`: each
        // buffer passes the 8 GiB check, the whole needs about 50 GB.
        let b = bake_peak_bytes([46000, 46000], [32, 32, 8], false);
        assert!(b > 40_000_000_000 && b < 60_000_000_000, "{b}");
        assert_eq!(
            bake_peak_bytes([2, 2], [2, 2, 2], true),
            4 * (24 + 8) + 8 * 9 + 4 * 12
        );
    }
}
