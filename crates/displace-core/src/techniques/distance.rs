//! Distance mapping, through [`DisplacementMap::trace_counted`] (the
//! project's tracer, not a copy): Donnelly's fixed loop
//! ([`Method::SphereFixed`], Donnelly's listing 8-2) or ours
//! ([`Method::Sphere`]: early out, then the exact walk).

use super::{Hit, Traced};
use crate::sphere_trace::{MapRay, Method, TraceOptions};
use crate::DisplacementMap;

pub(crate) fn trace(map: &DisplacementMap, ray: &MapRay, budget: u32, early_out: bool) -> Traced {
    let opts = TraceOptions {
        method: if early_out {
            Method::Sphere
        } else {
            Method::SphereFixed
        },
        iterations: budget,
        ..TraceOptions::default()
    };
    let (hit, fetches) = map.trace_counted(ray, &opts);
    Traced {
        hit: hit.map(|h| Hit {
            t: h.t,
            position: h.position,
            uv: h.uv,
        }),
        fetches,
    }
}
