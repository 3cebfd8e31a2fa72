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
use crate::faces::displaced::DisplacedFace;
use crate::geometry::{Ray, Rays8, PACKET};
use displace_core::{MapHit, MapRay, TraceOptions};
use glam::{Vec2, Vec3};

/// A first hit as a geometric query reports it (what Embree's
/// `rtcIntersect` answers): where it is and the surface's normal there,
/// without what shading needs ([`Interaction`]'s shading normal, texture
/// coordinate and material), so that a displaced hit costs no normal-map
/// sample and each answer is a few words instead of an interaction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeometryHit {
    /// The primitive hit ([`Scene::shape_of`] names its shape).
    pub prim: u32,
    /// Distance along the (unit) ray.
    pub t: f32,
    /// World position of the hit.
    pub position: Vec3,
    /// Unit geometric normal as the shape defines it (not turned towards
    /// the ray): the [`Interaction::geometric_normal`] of the same hit.
    pub normal: Vec3,
}

/// Reusable buffers of the batch queries (one per thread: a render keeps
/// one per tile so that its batches allocate nothing after the first).
///
/// The displaced faces' queries are kept as columns (rays, options,
/// scales, entry normals, owners), which the core's tracer reads as they
/// are, so that a query is written once and nothing is copied between
/// buffers on its way to the packets.
#[derive(Default)]
pub struct Batch {
    /// `(primitive, ray)` for every displaced face a ray's BVH walk met.
    pending: Vec<(u32, u32)>,
    /// The map-space rays of one face's queries.
    rays: Vec<MapRay>,
    /// Their trace options, clipped to each ray's range.
    opts: Vec<TraceOptions>,
    /// `t_map = scale t_world` for each.
    scales: Vec<f32>,
    /// The outward normal of the prism side each enters through.
    entries: Vec<Option<Vec3>>,
    /// The pending entry each answers.
    owners: Vec<u32>,
    blocked: Vec<bool>,
    answers: Vec<bool>,
    /// Ray indices grouped by octant, for the packet walks.
    order: Vec<u32>,
    /// `(primitive, ray)` of the displaced hits being resolved, by face.
    resolving: Vec<(u32, u32)>,
    best: Vec<Option<(u32, f32, Local)>>,
}

/// Eight hits on one displaced face: each one's distance and map hit.
type FaceHits8<'a> = [(f32, &'a MapHit); 8];

impl Scene {
    /// The nearest hit of each of `rays` with `t` in `[t_min, t_max[i]]`
    /// and the primitive it lies on: `out[i]` is what
    /// `intersect_primitive(&rays[i], t_min, t_max[i])` finds.
    pub fn intersect_many(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        batch: &mut Batch,
        out: &mut Vec<Option<(u32, Interaction)>>,
    ) {
        self.nearest_many(rays, t_min, t_max, batch);
        out.clear();
        out.resize(rays.len(), None);
        let Batch {
            best, resolving, ..
        } = batch;
        // The displaced faces' hits gathered per face (in ray order within
        // each) and resolved eight at a time: a path tracer's bounce rays
        // end on the room's shapes and its displaced faces in turn, so runs
        // of eight in ray order are rare where runs of eight per face are
        // not (a wavefront's sort by what a hit must do next).
        resolving.clear();
        for (r, (b, ray)) in best.iter().zip(rays).enumerate() {
            let Some((i, t, local)) = *b else {
                continue;
            };
            match (&self.prims[i as usize].shape, local) {
                (Shape::Displaced(_), Local::Map(_)) => resolving.push((i, r as u32)),
                _ => out[r] = Some((i, self.resolve_with(i, ray, t, local, true))),
            }
        }
        if !resolving.is_sorted_by_key(|&(i, _)| i) {
            resolving.sort_by_key(|&(i, _)| i);
        }
        for run in resolving.chunk_by(|a, b| a.0 == b.0) {
            let prim = run[0].0;
            let Shape::Displaced(face) = &self.prims[prim as usize].shape else {
                unreachable!("only displaced faces' hits are gathered")
            };
            let hit = |r: u32| match &best[r as usize] {
                Some((_, t, Local::Map(m))) => (*t, m),
                _ => unreachable!("a gathered hit is a map hit"),
            };
            let color = face.color.as_deref();
            let mut eights = run.chunks_exact(8);
            for group in &mut eights {
                let hits: FaceHits8 = std::array::from_fn(|l| hit(group[l].1));
                let resolved = face.resolve8(&hits.map(|(_, m)| m));
                for ((&(_, r), &(t, _)), h) in group.iter().zip(&hits).zip(&resolved) {
                    let it = self.displaced_interaction(prim, t, h, color, true);
                    out[r as usize] = Some((prim, it));
                }
            }
            for &(_, r) in eights.remainder() {
                let (t, m) = hit(r);
                let it = self.resolve_with(prim, &rays[r as usize], t, Local::Map(*m), true);
                out[r as usize] = Some((prim, it));
            }
        }
    }

    /// The nearest hit of each of `rays` as a geometric query reports it:
    /// `out[i]` is where [`Self::intersect_many`]'s `out[i]` lies and its
    /// geometric normal, worked out without the shading.
    pub fn intersect_geometry_many(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        batch: &mut Batch,
        out: &mut Vec<Option<GeometryHit>>,
    ) {
        self.nearest_many(rays, t_min, t_max, batch);
        out.clear();
        for (best, rays) in batch.best.chunks(8).zip(rays.chunks(8)) {
            if let Some(hits) = self.displaced_geometry8(best) {
                out.extend(hits.into_iter().map(Some));
                continue;
            }
            out.extend(
                best.iter()
                    .zip(rays)
                    .map(|(b, ray)| self.geometry_of(b, ray)),
            );
        }
    }

    /// Eight nearest hits on one displaced face, carried to the world
    /// together ([`crate::faces::displaced::DisplacedFace::world_geometry8`]);
    /// `None` unless `best` is eight such hits.
    fn displaced_geometry8(&self, best: &[Option<(u32, f32, Local)>]) -> Option<[GeometryHit; 8]> {
        let (prim, face, hits) = self.one_displaced_face8(best)?;
        let column = |f: fn(&MapHit) -> Vec3| -> [[f32; 8]; 3] {
            let v = hits.map(|(_, m)| f(m));
            [v.map(|p| p.x), v.map(|p| p.y), v.map(|p| p.z)]
        };
        let [p, n] = face.world_geometry8(&column(|m| m.position), &column(|m| m.normal));
        Some(std::array::from_fn(|l| GeometryHit {
            prim,
            t: hits[l].0,
            position: Vec3::new(p[0][l], p[1][l], p[2][l]),
            normal: Vec3::new(n[0][l], n[1][l], n[2][l]),
        }))
    }

    /// `best` as eight map-space hits on one displaced face (its index, the
    /// face and each hit's distance and map hit), the case the eight-lane
    /// resolutions take; `None` for fewer than eight, a miss, another
    /// shape or a second face among them.
    fn one_displaced_face8<'a>(
        &'a self,
        best: &'a [Option<(u32, f32, Local)>],
    ) -> Option<(u32, &'a DisplacedFace, FaceHits8<'a>)> {
        let &Some((prim, _, _)) = best.first()? else {
            return None;
        };
        let Shape::Displaced(face) = &self.prims[prim as usize].shape else {
            return None;
        };
        if best.len() != 8 {
            return None;
        }
        let mut hits = [None; 8];
        for (h, b) in hits.iter_mut().zip(best) {
            match b {
                Some((p, t, Local::Map(m))) if *p == prim => *h = Some((*t, m)),
                _ => return None,
            }
        }
        Some((prim, face, hits.map(|h| h.expect("every lane checked"))))
    }

    /// One nearest hit as a geometric query reports it.
    fn geometry_of(&self, best: &Option<(u32, f32, Local)>, ray: &Ray) -> Option<GeometryHit> {
        best.map(|(prim, t, local)| {
            let (position, normal) = match (&self.prims[prim as usize].shape, local) {
                (Shape::Displaced(d), Local::Map(h)) => d.world_geometry(&h),
                _ => {
                    let hit = self.resolve_with(prim, ray, t, local, false);
                    (hit.position, hit.geometric_normal)
                }
            };
            GeometryHit {
                prim,
                t,
                position,
                normal,
            }
        })
    }

    /// The nearest primitive, distance and local hit of each ray into
    /// `batch.best`: the BVH walked by packets of eight rays of one octant
    /// ([`Bvh::traverse8`], quads tested in lanes), the other plain shapes
    /// met on the way intersected lane by lane, the displaced faces
    /// gathered and traced together.
    ///
    /// [`Bvh::traverse8`]: crate::bvh::Bvh::traverse8
    fn nearest_many(&self, rays: &[Ray], t_min: f32, t_max: &[f32], batch: &mut Batch) {
        assert_eq!(rays.len(), t_max.len());
        batch.pending.clear();
        batch.best.clear();
        batch.best.resize(rays.len(), None);
        let starts = by_octant(rays, &mut batch.order);
        for o in 0..8 {
            for k in (starts[o]..starts[o + 1]).step_by(PACKET) {
                let end = (k + PACKET).min(starts[o + 1]);
                self.nearest8(rays, k..end, t_min, t_max, batch);
            }
        }
        self.trace_pending(rays, t_min, t_max, batch, false);
    }

    /// The rays `batch.order[range]` (at most eight, of one octant) walked
    /// together: what each one's own walk ([`Self::nearest_one`]) leaves
    /// in `batch.best` and `batch.pending`.
    fn nearest8(
        &self,
        rays: &[Ray],
        range: std::ops::Range<usize>,
        t_min: f32,
        t_max: &[f32],
        batch: &mut Batch,
    ) {
        let Batch {
            order,
            pending,
            best,
            ..
        } = batch;
        let group = &order[range];
        let before = pending.len();
        let walked = self.walk8(
            rays,
            group,
            t_min,
            t_max,
            false,
            |i, lanes, packet, limits| {
                let mut hits = 0;
                match &self.prims[i as usize].shape {
                    Shape::Displaced(_) => {
                        pending.extend(lanes_of(lanes).map(|l| (i, group[l])));
                    }
                    Shape::Quad(q) => {
                        let (mut t, mut ab) = ([0.0; PACKET], [Vec2::ZERO; PACKET]);
                        hits = q.intersect8(packet, lanes, t_min, limits, &mut t, &mut ab);
                        for l in lanes_of(hits) {
                            limits[l] = t[l];
                            best[group[l] as usize] = Some((i, t[l], Local::Param(ab[l])));
                        }
                    }
                    _ => {
                        for l in lanes_of(lanes) {
                            let r = group[l] as usize;
                            if let Some((t, local)) = self.hit_prim(i, &rays[r], t_min, limits[l]) {
                                limits[l] = t;
                                best[r] = Some((i, t, local));
                                hits |= 1 << l;
                            }
                        }
                    }
                }
                hits
            },
        );
        if walked.is_none() {
            pending.truncate(before);
            for &r in group {
                let r = r as usize;
                best[r] = self.nearest_one(&rays[r], r, t_min, t_max[r], pending);
            }
        }
    }

    /// The BVH walk of the rays `group` (at most eight, of one octant) as
    /// one packet ([`crate::bvh::Bvh::traverse8`]), `visit` also handed the
    /// packet's columns.
    fn walk8(
        &self,
        rays: &[Ray],
        group: &[u32],
        t_min: f32,
        t_max: &[f32],
        any: bool,
        mut visit: impl FnMut(u32, u32, &Rays8, &mut [f32; PACKET]) -> u32,
    ) -> Option<u32> {
        let packet = Rays8::gather(rays, group);
        let mut limits =
            std::array::from_fn(|l| t_max[group[if l < group.len() { l } else { 0 }] as usize]);
        let live = (1u32 << group.len()) - 1;
        self.bvh.traverse8(
            &packet,
            t_min,
            &mut limits,
            live,
            any,
            |i, lanes, limits| visit(i, lanes, &packet, limits),
        )
    }

    /// One ray's walk: its nearest plain hit, its displaced faces pending.
    fn nearest_one(
        &self,
        ray: &Ray,
        r: usize,
        t_min: f32,
        t_max: f32,
        pending: &mut Vec<(u32, u32)>,
    ) -> Option<(u32, f32, Local)> {
        let mut best: Option<(u32, f32, Local)> = None;
        self.bvh.traverse(ray, t_min, t_max, false, |i, t_max| {
            if let Shape::Displaced(_) = &self.prims[i as usize].shape {
                pending.push((i, r as u32));
                return None;
            }
            let (t, local) = self.hit_prim(i, ray, t_min, t_max)?;
            best = Some((i, t, local));
            Some(t)
        });
        best
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
        out.resize(rays.len(), false);
        let starts = by_octant(rays, &mut batch.order);
        for o in 0..8 {
            for k in (starts[o]..starts[o + 1]).step_by(PACKET) {
                let end = (k + PACKET).min(starts[o + 1]);
                self.occluded8(rays, k..end, t_min, t_max, batch, out);
            }
        }
        self.trace_pending(rays, t_min, t_max, batch, true);
        for (&(_, r), &b) in batch.pending.iter().zip(&batch.blocked) {
            out[r as usize] |= b;
        }
    }

    /// The any-hit walks of the rays `batch.order[range]` (at most eight,
    /// of one octant) together: a ray a plain shape blocks is answered
    /// (and its displaced faces need no trace), the others' displaced
    /// faces are left pending, as each ray's own walk leaves them.
    fn occluded8(
        &self,
        rays: &[Ray],
        range: std::ops::Range<usize>,
        t_min: f32,
        t_max: &[f32],
        batch: &mut Batch,
        out: &mut [bool],
    ) {
        let Batch { order, pending, .. } = batch;
        let group = &order[range];
        let before = pending.len();
        let blocked = self.walk8(
            rays,
            group,
            t_min,
            t_max,
            true,
            |i, lanes, packet, limits| match &self.prims[i as usize].shape {
                Shape::Displaced(_) => {
                    pending.extend(lanes_of(lanes).map(|l| (i, group[l])));
                    0
                }
                Shape::Quad(q) => {
                    let (mut t, mut ab) = ([0.0; PACKET], [Vec2::ZERO; PACKET]);
                    q.intersect8(packet, lanes, t_min, limits, &mut t, &mut ab)
                }
                _ => lanes_of(lanes)
                    .filter(|&l| {
                        let r = group[l] as usize;
                        self.hit_prim(i, &rays[r], t_min, limits[l]).is_some()
                    })
                    .fold(0, |m, l| m | (1 << l)),
            },
        );
        match blocked {
            Some(b) => {
                for (l, &r) in group.iter().enumerate() {
                    out[r as usize] = b & (1 << l) != 0;
                }
            }
            None => {
                pending.truncate(before);
                for &r in group {
                    out[r as usize] = self.occluded_one(rays, r as usize, t_min, t_max, pending);
                }
            }
        }
        // A plain shape blocks them: their displaced faces need no trace.
        let mut kept = before;
        for k in before..pending.len() {
            if !out[pending[k].1 as usize] {
                pending[kept] = pending[k];
                kept += 1;
            }
        }
        pending.truncate(kept);
    }

    /// One ray's any-hit walk: whether a plain shape blocks it, its
    /// displaced faces pending otherwise.
    fn occluded_one(
        &self,
        rays: &[Ray],
        r: usize,
        t_min: f32,
        t_max: &[f32],
        pending: &mut Vec<(u32, u32)>,
    ) -> bool {
        let ray = &rays[r];
        self.bvh.traverse(ray, t_min, t_max[r], true, |i, t_max| {
            if let Shape::Displaced(_) = &self.prims[i as usize].shape {
                pending.push((i, r as u32));
                return None;
            }
            self.hit_prim(i, ray, t_min, t_max).map(|(t, _)| t)
        })
    }

    /// Traces the gathered displaced faces, face by face: first hits into
    /// `batch.best` (keeping the nearer), or any-hit answers into
    /// `batch.blocked` (one per pending entry, in its order).
    fn trace_pending(&self, rays: &[Ray], t_min: f32, t_max: &[f32], batch: &mut Batch, any: bool) {
        // Grouped by face (stable: within a face, in ray order), so each
        // face's rays go through its map together. A BVH walk meets the
        // faces of one ray in its own order, so the entries of a batch
        // over one face are sorted already.
        if !batch.pending.is_sorted_by_key(|&(i, _)| i) {
            batch.pending.sort_by_key(|&(i, _)| i);
        }
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
            batch.rays.clear();
            batch.opts.clear();
            batch.scales.clear();
            batch.entries.clear();
            batch.owners.clear();
            // A first hit only matters before the nearest plain hit.
            let best = &batch.best;
            let limit = |r: usize| match (any, best.get(r)) {
                (false, Some(Some((_, t, _)))) => *t,
                _ => t_max[r],
            };
            let mut k = start;
            while k < end {
                let group = &batch.pending[k..end.min(k + 8)];
                let rs: [&Ray; 8] =
                    std::array::from_fn(|l| &rays[group[l.min(group.len() - 1)].1 as usize]);
                let lanes = if group.len() == 8 {
                    let limits = std::array::from_fn(|l| limit(group[l].1 as usize));
                    face.map_queries8(&rs, &[t_min; 8], &limits)
                } else {
                    None
                };
                match lanes {
                    Some(q) => {
                        for l in (0..8).filter(|&l| q.valid[l]) {
                            let at = |v: &[[f32; 8]; 3]| Vec3::new(v[0][l], v[1][l], v[2][l]);
                            batch.rays.push(MapRay {
                                origin: at(&q.origin),
                                dir: at(&q.dir),
                            });
                            batch.opts.push(face.lane_options(&q, l));
                            batch.scales.push(q.scale[l]);
                            batch.entries.push(None);
                            batch.owners.push((k + l) as u32);
                        }
                    }
                    None => {
                        for (l, &(_, r)) in group.iter().enumerate() {
                            let r = r as usize;
                            if let Some(q) = face.map_query(&rays[r], t_min, limit(r)) {
                                batch.rays.push(q.ray);
                                batch.opts.push(q.opts);
                                batch.scales.push(q.scale);
                                batch.entries.push(q.entry);
                                batch.owners.push((k + l) as u32);
                            }
                        }
                    }
                }
                k += group.len();
            }
            let map = face.map();
            if any {
                batch.answers.clear();
                batch.answers.resize(batch.rays.len(), false);
                map.occluded_many(&batch.rays, &batch.opts, &mut batch.answers);
                for (&k, &b) in batch.owners.iter().zip(&batch.answers) {
                    batch.blocked[k as usize] = b;
                }
            } else {
                let Batch {
                    pending,
                    scales,
                    entries,
                    owners,
                    best,
                    ..
                } = batch;
                map.trace_each(&batch.rays, &batch.opts, |q, hit| {
                    let (t, hit) = crate::faces::displaced::finish(entries[q], scales[q], hit);
                    let r = pending[owners[q] as usize].1 as usize;
                    if best[r].is_none_or(|(_, best, _)| t < best) {
                        best[r] = Some((prim, t, Local::Map(hit)));
                    }
                });
            }
            start = end;
        }
    }
}

/// Ray indices grouped by the octant of their directions into `order`
/// (in ray order within each), and where each octant's run starts:
/// octant `o` is `order[starts[o]..starts[o + 1]]`. Rays of one octant
/// walk a BVH in one order ([`crate::bvh::Bvh::traverse8`]).
fn by_octant(rays: &[Ray], order: &mut Vec<u32>) -> [usize; 9] {
    let octant = |r: &Ray| {
        usize::from(r.dir.x < 0.0)
            | usize::from(r.dir.y < 0.0) << 1
            | usize::from(r.dir.z < 0.0) << 2
    };
    let mut starts = [0usize; 9];
    for r in rays {
        starts[octant(r) + 1] += 1;
    }
    for o in 0..8 {
        starts[o + 1] += starts[o];
    }
    let mut next = starts;
    order.clear();
    order.resize(rays.len(), 0);
    for (i, r) in rays.iter().enumerate() {
        let o = octant(r);
        order[next[o]] = i as u32;
        next[o] += 1;
    }
    starts
}

/// The lanes of bit set `m`, lowest first.
fn lanes_of(mut m: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            l
        })
    })
}
