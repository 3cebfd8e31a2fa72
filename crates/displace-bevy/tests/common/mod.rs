//! Set-up shared by the plugin's tests.

use displace_core::io::height::{load, HeightOptions};
use displace_core::{bake, Address, BakeOptions, DisplacementMap, Extent};

/// `source` (a generator) at `size` texels, baked to `map_size` voxels on
/// a unit face `depth` deep.
pub fn baked(
    source: &str,
    size: [usize; 2],
    address: Address,
    map_size: [usize; 3],
    depth: f32,
) -> DisplacementMap {
    let opts = HeightOptions {
        size,
        address,
        ..Default::default()
    };
    let height = load(source, &opts).unwrap();
    bake(
        &height,
        &BakeOptions {
            size: map_size,
            extent: Extent {
                sx: 1.0,
                sy: 1.0,
                sz: depth,
            },
            ..Default::default()
        },
    )
    .unwrap()
}
