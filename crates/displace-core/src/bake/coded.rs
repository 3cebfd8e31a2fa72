//! The rest of a streamed bake once its sink encodes R8 codes with a known
//! range ([`SlabSink::encoder`]): each value encoded as its slice computes
//! it, and the slices taken one at a time by whichever thread is free rather
//! than a slab at a time.
//!
//! Why: a slab is a barrier. Its threads start a wake-up apart and end a
//! slice's imbalance apart (the slices' costs differ with the surface they
//! cross), and on two cores that idled a tenth of the bake. Here a thread
//! that finishes takes the next slice at once; the slices reach the sink in
//! order of depth all the same, parked until the ones above them are in.
//! A thread may run at most one slice ahead of the oldest unfinished one
//! (the window), so that the codes held stay a few slices.

use super::options::BakeOptions;
use super::plan::{check_promise, is_cancelled, BakePlan, SliceJob};
use super::ranges::RowSource;
use super::sink::{CodedSlab, SlabSink};
use crate::distance_map::R8Encoder;
use crate::edt::SliceScratch;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};

/// What the threads share about the slices finished: what goes to the sink
/// next, what is parked until then, and the first failure.
struct Order<'s, S> {
    sink: &'s mut S,
    /// The next slice the sink takes.
    expected: usize,
    /// Finished slices below which one is unfinished: codes and minimum.
    parked: BTreeMap<usize, (Vec<u8>, f32)>,
    /// The bound promised for the slices from `expected` on.
    promised: f32,
    failed: Option<Error>,
}

/// The slices' shared state and the rules of the hand-over.
struct Pipeline<'a, 's, S> {
    plan: &'a BakePlan<'a>,
    encoder: &'a R8Encoder,
    /// Suffix minima of the slices' static lower bounds.
    rest: &'a [f32],
    opts: &'a BakeOptions,
    done: &'a AtomicUsize,
    next: AtomicUsize,
    window: usize,
    order: Mutex<Order<'s, S>>,
    moved: Condvar,
}

/// Bakes slices `first..` of `plan` as R8 codes into `sink`, one thread
/// per whole slice of `scratch` (at most one per thread of the pool), each
/// slice pushed as its own [`CodedSlab`] in order of depth. `promised` is
/// the bound promised for slice `first` on ([`super::bake_streamed`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn bake_coded<S: SlabSink + Send>(
    plan: &BakePlan<'_>,
    first: usize,
    promised: f32,
    encoder: &R8Encoder,
    rest: &[f32],
    scratch: &mut [f32],
    sink: &mut S,
    opts: &BakeOptions,
    done: &AtomicUsize,
) -> Result<()> {
    let [w, h, _] = plan.size;
    let plane = (w * h).max(1);
    let slots: Vec<Mutex<&mut [f32]>> = scratch
        .chunks_exact_mut(plane)
        .take(rayon::current_num_threads())
        .map(Mutex::new)
        .collect();
    let pipeline = Pipeline {
        plan,
        encoder,
        rest,
        opts,
        done,
        next: AtomicUsize::new(first),
        window: window(slots.len()),
        order: Mutex::new(Order {
            sink,
            expected: first,
            parked: BTreeMap::new(),
            promised,
            failed: None,
        }),
        moved: Condvar::new(),
    };
    rayon::broadcast(|ctx| {
        if let Some(slot) = slots.get(ctx.index()) {
            let mut slice = slot.lock().unwrap_or_else(PoisonError::into_inner);
            pipeline.work(&mut slice);
        }
    });
    let order = pipeline
        .order
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner);
    match order.failed {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// How many slices past the oldest unfinished one may be started: one per
/// thread and one more, so that a thread may run a slice ahead of the
/// other. Codes held: the window, and what the writer holds
/// ([`crate::memory::stream_encoded_slices`]).
pub(crate) fn window(threads: usize) -> usize {
    threads.max(1) + 1
}

impl<'s, S: SlabSink + Send> Pipeline<'_, 's, S> {
    fn lock(&self) -> MutexGuard<'_, Order<'s, S>> {
        self.order.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn fail(&self, mut order: MutexGuard<'_, Order<'s, S>>, e: Error) {
        order.failed.get_or_insert(e);
        self.moved.notify_all();
    }

    /// One thread's part: slices taken in turn until none is left or the
    /// bake fails.
    fn work(&self, slice: &mut [f32]) {
        let plan = self.plan;
        let [w, h, d] = plan.size;
        let mut scratch = SliceScratch::default();
        let mut source = RowSource::new(&plan.ranges, &plan.grid, plan.height, w);
        // Should this thread panic, the others must not wait for its slice.
        let _guard = FailOnPanic(self);
        loop {
            let k = self.next.fetch_add(1, Ordering::Relaxed);
            if k >= d {
                return;
            }
            let mut codes = {
                let mut order = self.lock();
                while k >= order.expected + self.window && order.failed.is_none() {
                    order = self
                        .moved
                        .wait(order)
                        .unwrap_or_else(PoisonError::into_inner);
                }
                if order.failed.is_some() {
                    return;
                }
                if is_cancelled(self.opts) {
                    return self.fail(order, Error::Cancelled);
                }
                order.sink.code_buffer()
            };
            codes.resize(w * h, 0);
            let codes_out = Some((self.encoder, &mut codes[..]));
            let job = SliceJob {
                k,
                slice,
                codes: codes_out,
                scratch: &mut scratch,
                source: &mut source,
            };
            let min = plan.slice(job);
            let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(p) = &self.opts.progress {
                p(n, d);
            }
            let mut order = self.lock();
            if order.failed.is_some() {
                return;
            }
            order.parked.insert(k, (codes, min));
            if let Err(e) = self.hand_over(&mut order) {
                return self.fail(order, e);
            }
            self.moved.notify_all();
        }
    }

    /// Pushes the parked slices that are next in depth, checking each
    /// against the bound promised for it and promising the next.
    fn hand_over(&self, order: &mut Order<'s, S>) -> Result<()> {
        while let Some((codes, min)) = order.parked.remove(&order.expected) {
            let k = order.expected;
            check_promise(k..k + 1, min, order.promised)?;
            let rest_lower_bound = self.plan.promise(self.rest, k + 1, min);
            order.sink.push_codes(CodedSlab {
                first: k,
                codes,
                min,
                rest_lower_bound,
            })?;
            order.promised = rest_lower_bound;
            order.expected += 1;
        }
        Ok(())
    }
}

/// Fails the pipeline when its thread unwinds, so that no other thread
/// waits for a slice that will not come (the panic then reaches the
/// caller through [`rayon::broadcast`]).
struct FailOnPanic<'p, 'a, 's, S: SlabSink + Send>(&'p Pipeline<'a, 's, S>);

impl<S: SlabSink + Send> Drop for FailOnPanic<'_, '_, '_, S> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            let order = self.0.lock();
            self.0.fail(
                order,
                Error::Invariant("a thread of the bake panicked".into()),
            );
        }
    }
}
