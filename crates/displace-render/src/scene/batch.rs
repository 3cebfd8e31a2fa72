//! Many rays against the scene at once: the BVH is walked ray by ray, the
//! plain shapes met on the way are intersected there, and the displaced
//! faces' traces are gathered per face and run through the core's packet
//! tracer ([`DisplacementMap::trace_many`], eight rays at a time), the way a
//! wavefront renderer sorts its rays by what they must do next (Laine,
//! Karras and Aila 2013, "Megakernels considered harmful", section 4).
//!
//! The answers are those of [`Scene::intersect_primitive`] and
//! [`Scene::occluded`] ray by ray: the nearest hit over every primitive the
//! ray meets (a displaced face is traced up to the nearest plain hit, not
//! up to an earlier displaced hit as the one-ray walk may; the nearest is
//! the same), and any blocker at all.
//!
//! [`DisplacementMap::trace_many`]: displace_core::DisplacementMap::trace_many

use super::world::{Local, Shape};
use super::{Interaction, Scene};
use crate::displaced::MapQuery;
use crate::geometry::Ray;
use displace_core::{MapHit, MapRay, TraceOptions};

/// How much of a hit a batch query works out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detail {
    /// Everything shading needs ([`Scene::intersect_primitive`]'s answer).
    Shading,
    /// Where the hit is: a displaced hit's shading normal is its geometric
    /// one and its texture is not sampled (what Embree's `rtcIntersect`
    /// answers; the normal map's sample is a fifth of a hit's cost).
    Geometry,
}

/// Reusable buffers of the batch queries (one per thread: a render keeps
/// one per tile so that its batches allocate nothing after the first).
#[derive(Default)]
pub struct Batch {
    /// `(primitive, ray)` for every displaced face a ray's BVH walk met.
    pending: Vec<(u32, u32)>,
    queries: Vec<MapQuery>,
    owners: Vec<u32>,
    rays: Vec<MapRay>,
    opts: Vec<TraceOptions>,
    hits: Vec<Option<MapHit>>,
    blocked: Vec<bool>,
    answers: Vec<bool>,
    best: Vec<Option<(u32, f32, Local)>>,
}

impl Scene {
    /// The nearest hit of each of `rays` with `t` in `[t_min, t_max[i]]`
    /// and the primitive it lies on: `out[i]` is what
    /// `intersect_primitive(&rays[i], t_min, t_max[i])` finds, described as
    /// far as `detail` asks.
    pub fn intersect_many(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        detail: Detail,
        batch: &mut Batch,
        out: &mut Vec<Option<(u32, Interaction)>>,
    ) {
        assert_eq!(rays.len(), t_max.len());
        batch.pending.clear();
        batch.best.clear();
        for (r, ray) in rays.iter().enumerate() {
            let mut best: Option<(u32, f32, Local)> = None;
            let pending = &mut batch.pending;
            self.bvh.traverse(ray, t_min, t_max[r], false, |i, t_max| {
                if let Shape::Displaced(_) = &self.prims[i as usize].shape {
                    pending.push((i, r as u32));
                    return None;
                }
                let (t, local) = self.hit_prim(i, ray, t_min, t_max)?;
                best = Some((i, t, local));
                Some(t)
            });
            batch.best.push(best);
        }
        self.trace_pending(rays, t_min, t_max, batch, false);
        out.clear();
        out.extend(batch.best.iter().zip(rays).map(|(b, ray)| {
            b.map(|(i, t, local)| {
                (
                    i,
                    self.resolve_with(i, ray, t, local, detail == Detail::Shading),
                )
            })
        }));
    }

    /// Whether anything lies on each of `rays` within `[t_min, t_max[i]]`:
    /// `out[i]` is `occluded(&rays[i], t_min, t_max[i])`.
    pub fn occluded_many(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        batch: &mut Batch,
        out: &mut Vec<bool>,
    ) {
        assert_eq!(rays.len(), t_max.len());
        batch.pending.clear();
        out.clear();
        for (r, ray) in rays.iter().enumerate() {
            let pending = &mut batch.pending;
            let mut deferred = 0;
            let blocked = self.bvh.traverse(ray, t_min, t_max[r], true, |i, t_max| {
                if let Shape::Displaced(_) = &self.prims[i as usize].shape {
                    pending.push((i, r as u32));
                    deferred += 1;
                    return None;
                }
                self.hit_prim(i, ray, t_min, t_max).map(|(t, _)| t)
            });
            if blocked {
                // A plain shape blocks it: its displaced faces need no trace.
                pending.truncate(pending.len() - deferred);
            }
            out.push(blocked);
        }
        self.trace_pending(rays, t_min, t_max, batch, true);
        for (&(_, r), &b) in batch.pending.iter().zip(&batch.blocked) {
            out[r as usize] |= b;
        }
    }

    /// Traces the gathered displaced faces, face by face: first hits into
    /// `batch.best` (keeping the nearer), or any-hit answers into
    /// `batch.blocked` (one per pending entry, in its order).
    fn trace_pending(&self, rays: &[Ray], t_min: f32, t_max: &[f32], batch: &mut Batch, any: bool) {
        // Grouped by face (stable: within a face, in ray order), so each
        // face's rays go through its map together.
        batch.pending.sort_by_key(|&(i, _)| i);
        batch.blocked.clear();
        batch.blocked.resize(batch.pending.len(), false);
        let mut start = 0;
        while start < batch.pending.len() {
            let prim = batch.pending[start].0;
            let end = start
                + batch.pending[start..]
                    .iter()
                    .take_while(|&&(i, _)| i == prim)
                    .count();
            let Shape::Displaced(face) = &self.prims[prim as usize].shape else {
                unreachable!("only displaced faces are pending")
            };
            batch.queries.clear();
            batch.owners.clear();
            for (k, &(_, r)) in batch.pending[start..end].iter().enumerate() {
                let r = r as usize;
                // A first hit only matters before the nearest plain hit.
                let limit = match (any, &batch.best.get(r)) {
                    (false, Some(Some((_, t, _)))) => *t,
                    _ => t_max[r],
                };
                if let Some(q) = face.map_query(&rays[r], t_min, limit) {
                    batch.queries.push(q);
                    batch.owners.push((start + k) as u32);
                }
            }
            batch.rays.clear();
            batch.rays.extend(batch.queries.iter().map(|q| q.ray));
            batch.opts.clear();
            batch.opts.extend(batch.queries.iter().map(|q| q.opts));
            let n = batch.queries.len();
            let map = face.map();
            if any {
                batch.answers.clear();
                batch.answers.resize(n, false);
                map.occluded_many(&batch.rays, &batch.opts, &mut batch.answers);
                for (&k, &b) in batch.owners.iter().zip(&batch.answers) {
                    batch.blocked[k as usize] = b;
                }
            } else {
                batch.hits.clear();
                batch.hits.resize(n, None);
                map.trace_many(&batch.rays, &batch.opts, &mut batch.hits);
                for ((q, &k), hit) in batch.queries.iter().zip(&batch.owners).zip(&batch.hits) {
                    let Some(hit) = hit else { continue };
                    let (t, hit) = q.finish(*hit);
                    let r = batch.pending[k as usize].1 as usize;
                    if batch.best[r].is_none_or(|(_, best, _)| t < best) {
                        batch.best[r] = Some((prim, t, Local::Map(hit)));
                    }
                }
            }
            start = end;
        }
    }
}
