//! Parallax mapping with offset limiting (Kaneko et al. 2001; Welsh 2004).
//!
//! Texture space: one height fetch `h0` at the entry point, then the texture
//! coordinate moves by `(1 - h0) * V.xy`, with `V` the unit view vector,
//! instead of Kaneko's `(1 - h0) * V.xy / V.z`, which runs off to infinity at
//! grazing angles. In map space (`z` up, [`super`]) a unit-length ray moved
//! by the depth `z_in - h0` has exactly that horizontal offset, so the
//! technique is "step along the ray by the height difference under the
//! entry point".

use super::{Segment, Traced};

pub(crate) fn trace(seg: &Segment) -> Traced {
    let h0 = seg.height_at(seg.at(seg.t_in));
    seg.hit_at(seg.t_in + (seg.z_in - h0).max(0.0), 1)
}
