//! The estimated peak memory of a whole comparison, so that one too large
//! for the machine is refused from the height maps' headers alone
//! ([`displace_core::memory::check`]) rather than failing an allocation minutes in.

use displace_core::techniques::{Needs, Technique};
use displace_core::MapRay;
use glam::Vec2;

/// Bytes per height texel every map holds from the start (the maps are
/// all read before any work, so a bad file fails first): its heights.
const LOADED_BYTES_PER_TEXEL: u128 = 4;

/// Bytes per height texel of the map being compared, beyond its bake
/// ([`displace_core::memory::bake_peak_bytes`] counts that): the heights the
/// techniques sample (4) and, when the techniques need them, each cone map
/// (4), the max pyramid of Tevs et al. 2008 (about 4/3 of 4, counted 6) and
/// the scratch of a cone build (the footprints' height ranges and slopes,
/// or the relaxed build's block maxima: 12).
fn prepare_bytes_per_texel(techniques: &[Technique]) -> u128 {
    let needs = |n: Needs| techniques.iter().any(|t| t.needs() == n);
    let cones = needs(Needs::ConservativeCones) as u128 + needs(Needs::RelaxedCones) as u128;
    4 + 4 * cones + if needs(Needs::Pyramid) { 6 } else { 0 } + if cones > 0 { 12 } else { 0 }
}

/// Estimated peak bytes of comparing `techniques` on height maps of
/// `sizes` with `depth` distance-map slices and `rays` rays per elevation:
/// every map's heights, read first; the map being compared with its
/// precomputations and bake; the grid's map, kept from an earlier one when
/// there are several; the rays of one elevation with their exact and
/// measured hits; and with `gpu_rays` the repeated rays of a GPU dispatch
/// (the batch and its upload).
pub fn peak_bytes(
    sizes: &[[usize; 2]],
    depth: usize,
    techniques: &[Technique],
    rays: usize,
    gpu_rays: Option<usize>,
) -> u128 {
    let texels = |s: &[usize; 2]| s[0] as u128 * s[1] as u128;
    let loaded: u128 = sizes
        .iter()
        .map(|s| texels(s) * LOADED_BYTES_PER_TEXEL)
        .sum();
    let per_texel = prepare_bytes_per_texel(techniques);
    let working = sizes
        .iter()
        .map(|s| {
            texels(s) * per_texel
                + displace_core::memory::bake_peak_bytes(*s, [s[0], s[1], depth], false)
        })
        .max()
        .unwrap_or(0);
    let grid = if sizes.len() > 1 { working } else { 0 };
    let ray = std::mem::size_of::<MapRay>() as u128;
    let hit = std::mem::size_of::<Option<Vec2>>() as u128;
    let rays = rays as u128 * (ray + 2 * hit) + gpu_rays.map_or(0, |n| 2 * n as u128 * ray);
    loaded + working + grid + rays
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One map, a height-only technique: the heights read first, their
    /// copy beside the bake's peak, and the rays with their two hit lists.
    #[test]
    fn the_peak_counts_heights_bake_and_rays() {
        let ray = std::mem::size_of::<MapRay>() as u128;
        let hit = std::mem::size_of::<Option<Vec2>>() as u128;
        let bake = displace_core::memory::bake_peak_bytes([10, 10], [10, 10, 4], false);
        assert_eq!(
            peak_bytes(&[[10, 10]], 4, &[Technique::Pom], 3, None),
            100 * 4 + 100 * 4 + bake + 3 * (ray + 2 * hit)
        );
        // Cones, pyramid and a second map (the grid's, kept) add to it.
        let one = peak_bytes(&[[10, 10]], 4, &Technique::ALL, 3, None);
        assert_eq!(
            one,
            100 * 4 + 100 * (4 + 8 + 6 + 12) + bake + 3 * (ray + 2 * hit)
        );
        let two = peak_bytes(&[[10, 10], [10, 10]], 4, &Technique::ALL, 3, None);
        assert_eq!(two - one, 100 * 4 + 100 * (4 + 8 + 6 + 12) + bake);
        // The GPU's repeated rays: the batch and its upload.
        let gpu = peak_bytes(&[[10, 10]], 4, &Technique::ALL, 3, Some(1000));
        assert_eq!(gpu - one, 2 * 1000 * ray);
    }

    /// A 46000x46000 map needs tens of gigabytes (every buffer of which
    /// passes the one-buffer check).
    #[test]
    fn a_46000_texel_map_needs_tens_of_gigabytes() {
        let b = peak_bytes(&[[46000, 46000]], 16, &Technique::ALL, 2000, None);
        assert!(b > 300_000_000_000 && b < 500_000_000_000, "{b}");
    }
}
