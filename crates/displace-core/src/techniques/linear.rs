//! Linear searches in depth layers: steep parallax, parallax occlusion
//! mapping, relief mapping, and Bevy's two methods.
//!
//! Texture space walks depth `d = 0, 1/n, 2/n, ...` down from the polygon and
//! stops at the first layer where the ray is at or below the surface
//! (`d >= 1 - h`). In map space ([`super`]) that is `z = 1 - d` going down
//! the ray from where it enters; a layer is at or below the surface when
//! `z <= h`. A ray from above always stops by the floor (`z = 0 <= h`).

use super::{Segment, Traced};

/// Binary-search steps of Bevy's `Relief` method as Bevy's documentation
/// suggests (`Relief { max_steps: 5 }`).
pub(crate) const BEVY_RELIEF_STEPS: u32 = 5;

/// Binary-search steps of relief mapping and relaxed cone stepping: they
/// narrow the last bracket by 2^-6, a sixty-fourth of a linear step.
pub(crate) const BINARY_STEPS: u32 = 6;

/// A point of the search: ray parameter and `z - h` there (positive above
/// the surface).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Probe {
    pub t: f32,
    pub gap: f32,
}

impl Segment<'_> {
    /// One bilinear fetch at ray parameter `t`.
    pub(crate) fn probe(&self, t: f32) -> Probe {
        let p = self.at(t);
        Probe {
            t,
            gap: p.z - self.height_at(p),
        }
    }
}

/// Outcome of a linear search: the last layer above the surface and the
/// first at or below it, and the fetches made.
pub(crate) struct Bracket {
    pub above: Probe,
    pub below: Probe,
    pub fetches: u32,
}

/// Walks `layers` equal depth layers from where the ray enters to the floor
/// (McGuire and McGuire 2005, "steep parallax"). The entry sample is layer 0.
fn layer_search(seg: &Segment, layers: u32) -> Bracket {
    layer_search_fraction(seg, (1.0 - seg.depth_in()) / layers as f32, layers)
}

/// Where the segment between the two probes crosses the surface, assuming
/// the surface is straight between them (Tatarchuk 2006's line intersection).
fn interpolate(b: &Bracket) -> f32 {
    let (a, c) = (b.above, b.below);
    let denom = a.gap - c.gap;
    if denom <= 0.0 {
        return c.t;
    }
    a.t + (c.t - a.t) * (a.gap / denom)
}

/// Halves the bracket `steps` times (Policarpo et al. 2005), one fetch each;
/// the answer is the bracket's midpoint.
pub(crate) fn bisect(seg: &Segment, mut b: Bracket, steps: u32) -> (f32, u32) {
    for _ in 0..steps {
        let mid = seg.probe(0.5 * (b.above.t + b.below.t));
        b.fetches += 1;
        if mid.gap > 0.0 {
            b.above = mid;
        } else {
            b.below = mid;
        }
    }
    (0.5 * (b.above.t + b.below.t), b.fetches)
}

/// Steep parallax: the first layer under the surface is the hit.
pub(crate) fn steep(seg: &Segment, layers: u32) -> Traced {
    let b = layer_search(seg, layers);
    seg.hit_at(b.below.t, b.fetches)
}

/// Layer count of POM: `mix(max, min, |cos|)` with `cos` the cosine between
/// the ray and the face normal (Tatarchuk 2006, who used 8 to 50; here
/// `min = max / 4`).
fn pom_layers(seg: &Segment, max: u32) -> u32 {
    let min = (max / 4).max(1) as f32;
    let c = seg.ray.dir.z.abs();
    (max as f32 + (min - max as f32) * c).round().max(1.0) as u32
}

/// Parallax occlusion mapping (Tatarchuk 2006).
pub(crate) fn pom(seg: &Segment, max_layers: u32) -> Traced {
    let b = layer_search(seg, pom_layers(seg, max_layers));
    seg.hit_at(interpolate(&b), b.fetches)
}

/// Bevy's parallax: `layer_count = mix(max_layer_count, 1, |V.z|)`, then
/// either POM's interpolation, which fetches the previous layer again (one
/// extra fetch; Bevy keeps no previous sample), or relief's binary search of
/// `relief_steps`.
pub(crate) fn bevy(seg: &Segment, max_layers: u32, relief_steps: Option<u32>) -> Traced {
    let c = seg.ray.dir.z.abs();
    let layers = (max_layers as f32 + (1.0 - max_layers as f32) * c).max(1.0);
    // Bevy steps in fractional layers of depth 1 / layers.
    let whole = layers.ceil() as u32;
    let b = layer_search_fraction(seg, 1.0 / layers, whole);
    match relief_steps {
        Some(steps) => {
            let (t, fetches) = bisect(seg, b, steps);
            seg.hit_at(t, fetches)
        }
        None => {
            let t = interpolate(&b);
            seg.hit_at(t, b.fetches + 1)
        }
    }
}

/// Layers of `layer_depth` down from the entry, at most `layers` of them
/// and none below the floor (Bevy's layer counts are fractional). Only
/// rounding can leave the floor above the surface; then it is the answer.
fn layer_search_fraction(seg: &Segment, layer_depth: f32, layers: u32) -> Bracket {
    let d0 = seg.depth_in();
    let mut above = seg.probe(seg.t_in);
    let mut fetches = 1;
    if above.gap <= 0.0 {
        return Bracket {
            above,
            below: above,
            fetches,
        };
    }
    for i in 1..=layers {
        let d = (d0 + layer_depth * i as f32).min(1.0);
        let below = seg.probe(seg.t_at_depth(d));
        fetches += 1;
        if below.gap <= 0.0 {
            return Bracket {
                above,
                below,
                fetches,
            };
        }
        above = below;
    }
    Bracket {
        above,
        below: above,
        fetches,
    }
}

/// Relief mapping (Policarpo et al. 2005): `layers` linear steps, then
/// [`BINARY_STEPS`] of binary search.
pub(crate) fn relief(seg: &Segment, layers: u32) -> Traced {
    let b = layer_search(seg, layers);
    let (t, fetches) = bisect(seg, b, BINARY_STEPS);
    seg.hit_at(t, fetches)
}
