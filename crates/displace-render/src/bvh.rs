//! Bounding volume hierarchy over primitive boxes, built with the binned
//! surface area heuristic (Wald, "On fast Construction of SAH-based Bounding
//! Volume Hierarchies", 2007; pbrt-v4 section 7.3) and traversed front to
//! back.

use crate::geometry::{Aabb, Ray, Rays8, PACKET};
use glam::Vec3;

const BINS: usize = 16;
const MAX_LEAF: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first index into `order`. Interior: index of the second child
    /// (the first child follows its parent).
    offset: u32,
    /// Primitives in a leaf; 0 for an interior node.
    count: u16,
    axis: u8,
}

/// A flattened BVH over the primitives of a scene (pbrt-v4 section 7.3's
/// linear layout: a node's first child follows it).
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
}

struct Item {
    bounds: Aabb,
    centroid: Vec3,
    index: u32,
    /// What testing the primitive costs, in triangle tests.
    cost: f32,
}

impl Bvh {
    /// Builds the hierarchy over `bounds` (primitive `i` has box `bounds[i]`)
    /// with the binned SAH, every primitive as costly to test as another.
    pub fn build(bounds: &[Aabb]) -> Self {
        Self::build_weighted(bounds, &vec![1.0; bounds.len()])
    }

    /// [`Self::build`] where primitive `i` costs `costs[i]` triangle tests
    /// to test (the SAH's intersection cost per primitive, pbrt-v4 section
    /// 7.3.2, which takes it as one for all): a displaced face, whose test
    /// transforms the ray into its map and clips it to the shell before any
    /// tracing, is split off into its own box where a leaf of cheap quads
    /// would otherwise make every ray that enters the leaf pay for it.
    pub fn build_weighted(bounds: &[Aabb], costs: &[f32]) -> Self {
        assert_eq!(bounds.len(), costs.len(), "one cost per box");
        let mut items: Vec<Item> = bounds
            .iter()
            .zip(costs)
            .enumerate()
            .map(|(i, (b, &cost))| Item {
                bounds: *b,
                centroid: b.centroid(),
                index: i as u32,
                cost,
            })
            .collect();
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * bounds.len() / MAX_LEAF + 1),
            order: Vec::with_capacity(bounds.len()),
        };
        if !items.is_empty() {
            bvh.build_node(&mut items);
        }
        bvh
    }

    fn build_node(&mut self, items: &mut [Item]) -> usize {
        let bounds = items.iter().fold(Aabb::EMPTY, |b, it| b.union(it.bounds));
        let id = self.nodes.len();
        self.nodes.push(Node {
            bounds,
            offset: 0,
            count: 0,
            axis: 0,
        });
        let n = items.len();
        // A small leaf is kept unless it holds a primitive dearer than a
        // triangle, which the SAH may split off.
        let cheap = items.iter().all(|it| it.cost <= 1.0);
        let split = if n <= 1 || (n <= MAX_LEAF && cheap) {
            None
        } else {
            sah_split(items, &bounds)
        };
        match split {
            None if n <= u16::MAX as usize => {
                self.nodes[id].offset = self.order.len() as u32;
                self.nodes[id].count = n as u16;
                self.order.extend(items.iter().map(|it| it.index));
            }
            other => {
                let (axis, mid) = other.unwrap_or_else(|| median_split(items));
                let (left, right) = items.split_at_mut(mid);
                self.build_node(left);
                let r = self.build_node(right);
                self.nodes[id].offset = r as u32;
                self.nodes[id].axis = axis as u8;
            }
        }
        id
    }

    /// The box of everything in the hierarchy ([`Aabb::EMPTY`] when empty).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// Visits the primitives whose boxes the ray meets, nearest node first.
    /// `visit(index, t_max)` returns the new `t_max` when it found a closer
    /// hit; with `any` the walk stops at the first such hit.
    #[inline]
    pub fn traverse(
        &self,
        ray: &Ray,
        t_min: f32,
        mut t_max: f32,
        any: bool,
        mut visit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut found = false;
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut node = 0usize;
        let neg = [ray.dir.x < 0.0, ray.dir.y < 0.0, ray.dir.z < 0.0];
        loop {
            let n = &self.nodes[node];
            if n.bounds.hit(ray, t_min, t_max).is_some() {
                if n.count > 0 {
                    for k in n.offset..n.offset + n.count as u32 {
                        if let Some(t) = visit(self.order[k as usize], t_max) {
                            t_max = t;
                            found = true;
                            if any {
                                return true;
                            }
                        }
                    }
                } else {
                    let (first, second) = if neg[n.axis as usize] {
                        (n.offset as usize, node + 1)
                    } else {
                        (node + 1, n.offset as usize)
                    };
                    if sp < stack.len() {
                        stack[sp] = second as u32;
                        sp += 1;
                        node = first;
                        continue;
                    }
                    // Deeper than the stack (pathological input): fall back
                    // to visiting the subtrees without ordering.
                    found |= self.traverse_from(second, ray, t_min, &mut t_max, any, &mut visit);
                    if found && any {
                        return true;
                    }
                    node = first;
                    continue;
                }
            }
            if sp == 0 {
                return found;
            }
            sp -= 1;
            node = stack[sp] as usize;
        }
    }

    /// [`Bvh::traverse`] of up to eight rays at once, all of one octant
    /// (the signs of their directions, which order the walk, are read
    /// from lane 0): each node's box is tested against the lanes that reached
    /// it ([`Aabb::hit8`]), and `visit(index, lanes, t_max)` is called
    /// for the lanes whose boxes hold the primitive, returning those that
    /// found a closer hit (having shortened their `t_max`). With `any`, a
    /// lane that found one leaves the walk.
    ///
    /// Each lane meets the nodes and primitives its own [`Bvh::traverse`]
    /// would, in the same order and with the same `t_max`: rays of one
    /// octant visit children in the same order, so the packet's walk is
    /// every lane's walk with the lanes a node misses masked off (Wald,
    /// Slusallek, Benthin and Wagner 2001, section 3.2). Returns the lanes
    /// that found a hit, or `None` where the walk is deeper than its stack
    /// (the caller walks those rays one at a time instead, undoing what
    /// `visit` did).
    ///
    /// [`Aabb::hit8`]: crate::geometry::Aabb::hit8
    #[inline]
    pub fn traverse8(
        &self,
        rays: &Rays8,
        t_min: f32,
        t_max: &mut [f32; PACKET],
        mut live: u32,
        any: bool,
        mut visit: impl FnMut(u32, u32, &mut [f32; PACKET]) -> u32,
    ) -> Option<u32> {
        let mut found = 0;
        if self.nodes.is_empty() {
            return Some(found);
        }
        let negative = rays.dir.map(|d| d[0] < 0.0);
        let mut stack = [(0u32, 0u32); 64];
        let mut sp = 0usize;
        let (mut node, mut lanes) = (0usize, live);
        loop {
            let n = &self.nodes[node];
            let hit = n.bounds.hit8(rays, t_min, t_max) & lanes;
            if hit != 0 {
                if n.count > 0 {
                    let mut visiting = hit;
                    for k in n.offset..n.offset + n.count as u32 {
                        let f = visit(self.order[k as usize], visiting, t_max);
                        found |= f;
                        if any {
                            visiting &= !f;
                            live &= !f;
                            if visiting == 0 {
                                break;
                            }
                        }
                    }
                } else {
                    let (first, second) = if negative[n.axis as usize] {
                        (n.offset as usize, node + 1)
                    } else {
                        (node + 1, n.offset as usize)
                    };
                    if sp == stack.len() {
                        return None;
                    }
                    stack[sp] = (second as u32, hit);
                    sp += 1;
                    (node, lanes) = (first, hit);
                    continue;
                }
            }
            loop {
                if sp == 0 || live == 0 {
                    return Some(found);
                }
                sp -= 1;
                let (next, m) = stack[sp];
                (node, lanes) = (next as usize, m & live);
                if lanes != 0 {
                    break;
                }
            }
        }
    }

    fn traverse_from(
        &self,
        root: usize,
        ray: &Ray,
        t_min: f32,
        t_max: &mut f32,
        any: bool,
        visit: &mut dyn FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        let mut found = false;
        let mut stack = vec![root];
        while let Some(node) = stack.pop() {
            let n = &self.nodes[node];
            if n.bounds.hit(ray, t_min, *t_max).is_none() {
                continue;
            }
            if n.count > 0 {
                for k in n.offset..n.offset + n.count as u32 {
                    if let Some(t) = visit(self.order[k as usize], *t_max) {
                        *t_max = t;
                        found = true;
                        if any {
                            return true;
                        }
                    }
                }
            } else {
                stack.push(node + 1);
                stack.push(n.offset as usize);
            }
        }
        found
    }
}

/// Best SAH split over `BINS` bins per axis, or `None` when a leaf is cheaper.
fn sah_split(items: &mut [Item], bounds: &Aabb) -> Option<(usize, usize)> {
    let cb = items.iter().fold(Aabb::EMPTY, |b, it| b.grow(it.centroid));
    let extent = cb.max - cb.min;
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if extent[axis].is_nan() || extent[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |c: Vec3| (((c[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
        // Per bin: box, primitive count, summed test cost.
        let mut bins = [(Aabb::EMPTY, 0usize, 0.0f32); BINS];
        for it in items.iter() {
            let b = &mut bins[bin_of(it.centroid)];
            b.0 = b.0.union(it.bounds);
            b.1 += 1;
            b.2 += it.cost;
        }
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0usize; BINS];
        let mut right_cost = [0.0f32; BINS];
        let (mut acc, mut cnt, mut sum) = (Aabb::EMPTY, 0, 0.0);
        for k in (1..BINS).rev() {
            acc = acc.union(bins[k].0);
            cnt += bins[k].1;
            sum += bins[k].2;
            right_area[k] = acc.area();
            right_count[k] = cnt;
            right_cost[k] = sum;
        }
        let (mut acc, mut cnt, mut sum) = (Aabb::EMPTY, 0, 0.0);
        for k in 1..BINS {
            acc = acc.union(bins[k - 1].0);
            cnt += bins[k - 1].1;
            sum += bins[k - 1].2;
            if cnt == 0 || right_count[k] == 0 {
                continue;
            }
            let cost = acc.area() * sum + right_area[k] * right_cost[k];
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, k));
            }
        }
    }
    let (cost, axis, k) = best?;
    // Traversal step costs about one primitive test (pbrt's 1/8 is for a
    // far cheaper intersection than a displaced face).
    let leaf_cost = items.iter().map(|it| it.cost).sum::<f32>() * bounds.area();
    if items.len() <= 16 && cost + bounds.area() >= leaf_cost {
        return None;
    }
    let scale = BINS as f32 / extent[axis];
    let mid = partition(items, |it| {
        ((((it.centroid[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1)) < k
    });
    (mid > 0 && mid < items.len()).then_some((axis, mid))
}

fn median_split(items: &mut [Item]) -> (usize, usize) {
    let cb = items.iter().fold(Aabb::EMPTY, |b, it| b.grow(it.centroid));
    let e = cb.max - cb.min;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
    (axis, mid)
}

fn partition(items: &mut [Item], pred: impl Fn(&Item) -> bool) -> usize {
    let mut i = 0;
    for j in 0..items.len() {
        if pred(&items[j]) {
            items.swap(i, j);
            i += 1;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::sampler::Rng;

    /// The leaves holding primitive `i`, and their sizes.
    fn leaf_sizes_of(bvh: &Bvh, i: u32) -> Vec<u16> {
        bvh.nodes
            .iter()
            .filter(|n| n.count > 0)
            .filter(|n| {
                let o = n.offset as usize;
                bvh.order[o..o + n.count as usize].contains(&i)
            })
            .map(|n| n.count)
            .collect()
    }

    #[test]
    fn a_costly_primitive_gets_a_box_of_its_own() {
        // A Cornell box: five flat walls whose boxes span the room, and a
        // shallow slab over the floor (a displaced face's shell).
        let wall = |axis: usize, at: f32| {
            let (mut min, mut max) = (Vec3::ZERO, Vec3::splat(555.0));
            min[axis] = at;
            max[axis] = at;
            Aabb { min, max }
        };
        let boxes = vec![
            wall(1, 555.0),
            wall(2, 555.0),
            wall(0, 555.0),
            wall(0, 0.0),
            Aabb {
                min: Vec3::ZERO,
                max: Vec3::new(555.0, 40.0, 555.0),
            },
        ];
        // Alike, the five fit one leaf, whose box is the room: every ray in
        // the room tests all of them.
        assert_eq!(leaf_sizes_of(&Bvh::build(&boxes), 4), vec![5]);
        // A face dearer than a wall is split off.
        let costly = Bvh::build_weighted(&boxes, &[1.0, 1.0, 1.0, 1.0, 2.0]);
        assert_eq!(leaf_sizes_of(&costly, 4), vec![1]);
    }

    /// `n` random boxes with centres in `[0, 100]^3` and half-sizes up to
    /// `half` on each axis.
    fn random_boxes(rng: &mut Rng, n: usize, half: f32) -> Vec<Aabb> {
        (0..n)
            .map(|_| {
                let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 100.0;
                let e = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * half;
                Aabb {
                    min: c - e,
                    max: c + e,
                }
            })
            .collect()
    }

    #[test]
    fn finds_the_same_nearest_box_as_brute_force() {
        let mut rng = Rng::new(3, 4);
        let boxes = random_boxes(&mut rng, 2000, 3.0);
        let bvh = Bvh::build(&boxes);
        for _ in 0..500 {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 120.0
                - Vec3::splat(10.0);
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let ray = Ray::new(o, d);
            let brute = boxes
                .iter()
                .filter_map(|b| b.hit(&ray, 0.0, f32::INFINITY))
                .fold(f32::INFINITY, f32::min);
            let mut best = f32::INFINITY;
            bvh.traverse(&ray, 0.0, f32::INFINITY, false, |i, t_max| {
                boxes[i as usize]
                    .hit(&ray, 0.0, t_max)
                    .filter(|&t| t < best)
                    .inspect(|&t| best = t)
            });
            assert_eq!(best, brute);
        }
    }

    /// A random ray for the lane tests: some start on a box's face and
    /// run along an axis (an infinite reciprocal, NaN slabs), where the
    /// slab test's ordering of minima and maxima decides.
    fn ray(rng: &mut Rng, on: &[Aabb]) -> Ray {
        let mut o =
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 120.0 - Vec3::splat(10.0);
        let mut d = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        );
        if rng.next_f32() < 0.3 {
            let b = on[(rng.next_f32() * on.len() as f32) as usize % on.len()];
            let axis = (rng.next_f32() * 3.0) as usize % 3;
            o[axis] = if rng.next_f32() < 0.5 {
                b.min[axis]
            } else {
                b.max[axis]
            };
            d[(axis + 1) % 3] = 0.0;
        }
        Ray::new(o, d)
    }

    /// Each lane of a packet walk meets the primitives its own walk meets,
    /// in the same order and with the same `t_max`, both for nearest hits
    /// and for any-hit walks, on random boxes and rays (a lane's packet
    /// mates are the rays of its octant drawn around it).
    #[test]
    fn packet_walks_are_each_lanes_own_walk() {
        let mut rng = Rng::new(11, 5);
        let boxes = random_boxes(&mut rng, 300, 8.0);
        let bvh = Bvh::build(&boxes);
        let octant = |r: &Ray| [r.dir.x < 0.0, r.dir.y < 0.0, r.dir.z < 0.0];
        let (mut visits, mut hits) = (0, 0);
        for round in 0..400 {
            let any = round % 2 == 1;
            let first = ray(&mut rng, &boxes);
            let mut rays = vec![first];
            while rays.len() < 1 + round % PACKET {
                let r = ray(&mut rng, &boxes);
                if octant(&r) == octant(&first) {
                    rays.push(r);
                }
            }
            // A primitive "hits" at its box's entry when that is within
            // the lane's limit: t_max shrinks along the walk.
            let hit = |i: u32, ray: &Ray, t_max: f32| boxes[i as usize].hit(ray, 0.0, t_max * 0.9);
            let own: Vec<(Vec<(u32, f32)>, bool)> = rays
                .iter()
                .map(|r| {
                    let mut seen = Vec::new();
                    let found = bvh.traverse(r, 0.0, 1e3, any, |i, t_max| {
                        seen.push((i, t_max));
                        hit(i, r, t_max)
                    });
                    (seen, found)
                })
                .collect();
            let index: Vec<u32> = (0..rays.len() as u32).collect();
            let packet = Rays8::gather(&rays, &index);
            let mut seen = vec![Vec::new(); rays.len()];
            let mut limits = [1e3; PACKET];
            let live = (1u32 << rays.len()) - 1;
            let found = bvh
                .traverse8(&packet, 0.0, &mut limits, live, any, |i, lanes, t_max| {
                    let mut f = 0;
                    for l in (0..PACKET).filter(|l| lanes & (1 << l) != 0) {
                        seen[l].push((i, t_max[l]));
                        if let Some(t) = hit(i, &rays[l], t_max[l]) {
                            t_max[l] = t;
                            f |= 1 << l;
                        }
                    }
                    f
                })
                .expect("a shallow tree");
            for (l, (own_seen, own_found)) in own.iter().enumerate() {
                assert_eq!(&seen[l], own_seen, "round {round} lane {l}");
                assert_eq!(found & (1 << l) != 0, *own_found, "round {round} lane {l}");
                visits += own_seen.len();
                hits += usize::from(*own_found);
            }
        }
        assert!(visits > 5000 && hits > 300, "{visits} visits, {hits} hits");
    }

    /// The lane box test answers as [`Aabb::hit`] does, lane by lane,
    /// rays along an axis and starting on a slab's plane included.
    #[test]
    fn box_tests_in_lanes_are_the_one_ray_tests() {
        let mut rng = Rng::new(12, 5);
        let mut met = 0;
        for _ in 0..2000 {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 100.0;
            let b = Aabb {
                min: c - Vec3::splat(20.0),
                max: c + Vec3::splat(20.0),
            };
            let rays: Vec<Ray> = (0..PACKET).map(|_| ray(&mut rng, &[b])).collect();
            let index: Vec<u32> = (0..PACKET as u32).collect();
            let limits: [f32; PACKET] = std::array::from_fn(|l| 40.0 * l as f32);
            let m = b.hit8(&Rays8::gather(&rays, &index), 0.0, &limits);
            for (l, r) in rays.iter().enumerate() {
                let one = b.hit(r, 0.0, limits[l]).is_some();
                assert_eq!(m & (1 << l) != 0, one);
                met += usize::from(one);
            }
        }
        assert!(met > 1000, "{met}");
    }
}
