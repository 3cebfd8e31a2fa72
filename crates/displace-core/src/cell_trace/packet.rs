//! Rays eight at a time: the sphere-tracing steps of a packet in AVX2
//! lanes, one gather per step for all eight, the exact walks per lane.
//!
//! A scalar sphere trace is one chain of dependent work per ray: the step
//! read at the ray's point decides the next point, so each step waits for
//! its load. Eight rays stepped together keep eight such chains in flight
//! and pay the addressing once per packet (Wald, Slusallek, Benthin and
//! Wagner 2001, "Interactive rendering with coherent ray tracing", section
//! 3, for packets of coherent rays; here the lanes need not stay coherent,
//! each has its own exit and mask). Where a lane's step falls under the
//! early-out threshold, or it leaves the shell, the packet stops and every
//! lane takes that step through the scalar [`Lane`] state machine, so each
//! ray's hit is the one the scalar tracer finds, bit for bit, whatever its
//! packet's other rays do.
//!
//! Runs where the CPU has AVX2 (detected at run time, as the bake's
//! envelope kernel does) and the map is clamped; elsewhere every ray takes
//! the scalar loop. A sixteen-lane kernel for AVX-512 (the step phase,
//! whose rounds are bound by one gather's latency, sixteen lanes a round;
//! each half of the packet through the eight-lane walk) is held to the
//! same hits and measured against the others, but not chosen by default:
//! it is slower in fixed packets ([`Kernel`] names the three;
//! [`with_kernel`] forces one for tests and measurements).

use super::{Constants, Lane, Outcome};
use crate::sphere_trace::{MapRay, Method, TraceOptions};
use crate::{Address, DistanceMap, HeightMap};

/// Rays per packet of the AVX2 kernel.
pub const LANES: usize = 8;

/// Rays per packet of the AVX-512 kernel.
pub const WIDE_LANES: usize = 16;

/// Which kernel steps the packets: chosen at run time from what the CPU
/// has (AVX2 where present, the measured choice), unless [`with_kernel`]
/// forces one. Every kernel's hits are the scalar tracer's, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// One ray at a time (the scalar loop every kernel is held to).
    Scalar,
    /// Eight lanes: AVX2 gathers and blends.
    Avx2,
    /// Sixteen lanes in the step phase (AVX-512F gathers and mask
    /// registers), the eight-lane walk on each half.
    Avx512,
}

impl Kernel {
    /// The kernels this CPU can run, narrowest first.
    pub fn available() -> Vec<Kernel> {
        let mut k = vec![Kernel::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                k.push(Kernel::Avx2);
                if std::arch::is_x86_feature_detected!("avx512f") {
                    k.push(Kernel::Avx512);
                }
            }
        }
        k
    }

    /// The kernel packets use unless one is forced: AVX2 where the CPU has
    /// it, even beside AVX-512. Measured on an AVX-512 Xeon
    /// (`examples/trace_profile`, first hits and shadow rays of two faces),
    /// sixteen-lane packets are 4-11% slower than eight: a packet steps
    /// until its last lane parks, and twice the lanes wait twice as long
    /// for their slowest; the sixteen-lane steps pay where lanes are
    /// refilled from a queue as they leave, which fixed packets do not do.
    fn best() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                return Kernel::Avx2;
            }
        }
        Kernel::Scalar
    }
}

std::thread_local! {
    static FORCED: std::cell::Cell<Option<Kernel>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with the packets of this thread stepped by `kernel` instead of
/// the widest the CPU has: for the tests that hold each kernel to the
/// scalar tracer, and for measuring one against another.
///
/// # Panics
/// If this CPU cannot run `kernel` ([`Kernel::available`]).
pub fn with_kernel<R>(kernel: Kernel, f: impl FnOnce() -> R) -> R {
    assert!(
        Kernel::available().contains(&kernel),
        "this CPU cannot run the {kernel:?} kernel"
    );
    let before = FORCED.with(|c| c.replace(Some(kernel)));
    struct Restore(Option<Kernel>);
    impl Drop for Restore {
        fn drop(&mut self) {
            FORCED.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(before);
    f()
}

/// The kernel this thread's packets use now.
fn kernel() -> Kernel {
    FORCED.with(|c| c.get()).unwrap_or_else(Kernel::best)
}

/// Traces every ray of `rays` with its own options, handing each outcome to
/// `emit` with the ray's index. The outcomes are those of the scalar
/// [`super::run`].
pub(super) fn run_all<const ANY: bool>(
    height: &HeightMap,
    distance: &DistanceMap,
    rays: &[MapRay],
    opts: &[TraceOptions],
    mut emit: impl FnMut(usize, Outcome),
) {
    debug_assert_eq!(rays.len(), opts.len());
    let c = Constants::new(height, distance);
    let kernel = if eligible(height, distance) {
        kernel()
    } else {
        Kernel::Scalar
    };
    let width = if kernel == Kernel::Avx512 {
        WIDE_LANES
    } else {
        LANES
    };
    let mut k = 0;
    while k < rays.len() {
        let n = width.min(rays.len() - k);
        let mut lanes: [Option<Lane>; WIDE_LANES] = Default::default();
        for l in 0..n {
            let (ray, o) = (&rays[k + l], &opts[k + l]);
            if o.method != Method::Sphere {
                emit(k + l, super::run_other(height, distance, ray, o, ANY));
                continue;
            }
            match Lane::begin(height, &c, ray, o, ANY) {
                Ok(lane) => lanes[l] = Some(lane),
                Err(out) => emit(k + l, out),
            }
        }
        match kernel {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX2 and AVX-512F are present (`Kernel::available`,
            // `Kernel::best`), and the map's voxel indices fit the kernel's
            // 32-bit gathers (`eligible`).
            Kernel::Avx512 => unsafe {
                avx512::steps::<ANY>(height, distance, &c, &mut lanes, &mut |l, out| {
                    emit(k + l, out)
                });
            },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX2 is present, and the indices fit, as above.
            Kernel::Avx2 => unsafe {
                let eight: &mut [Option<Lane>; LANES] = (&mut lanes[..LANES])
                    .try_into()
                    .expect("a packet's first eight lanes");
                avx2::steps::<ANY>(height, distance, &c, eight, &mut |l, out| emit(k + l, out));
            },
            _ => {
                for (l, lane) in lanes.iter_mut().enumerate() {
                    if let Some(lane) = lane {
                        emit(k + l, lane.finish::<ANY>(height, distance, &c));
                    }
                }
            }
        }
        k += n;
    }
}

/// Whether the kernel's assumptions hold for `distance`: a clamped map
/// (the kernel clamps; a repeating map's wrap stays scalar) whose voxel
/// indices fit in 32 bits.
fn eligible(height: &HeightMap, distance: &DistanceMap) -> bool {
    let [w, h, d] = distance.size();
    distance.address() == Address::Clamp
        && height.address() == Address::Clamp
        && (w as u64) * (h as u64) * (d as u64) <= i32::MAX as u64
        && (height.width() as u64) * (height.height() as u64) <= i32::MAX as u64
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::super::{walk_after, Cursor, Next, SurfaceHit, Walk};
    use super::{Constants, Lane, Outcome, LANES};
    use crate::exact::patch_hit;
    use crate::{DistanceMap, HeightMap};
    use std::arch::x86_64::*;

    /// A lane's walk in progress, in the vector kernel's arrays.
    #[derive(Clone, Copy, Default)]
    pub(super) struct WalkState {
        pub(super) t1: f32,
        pub(super) last: bool,
    }

    /// The lanes of bit set `m`, lowest first: one iteration a set bit
    /// (a loop over all eight with a test each mispredicts on every lane
    /// that changes).
    #[inline(always)]
    pub(super) fn lanes_of(mut m: u32) -> impl Iterator<Item = usize> {
        std::iter::from_fn(move || {
            (m != 0).then(|| {
                let l = m.trailing_zeros() as usize;
                m &= m - 1;
                l
            })
        })
    }

    /// Bit `l` set for each lane `l` of `mask`.
    #[inline(always)]
    unsafe fn bits(mask: __m256) -> u32 {
        _mm256_movemask_ps(mask) as u32
    }

    /// The lanes of `live` as an all-ones / all-zeros vector mask.
    #[inline(always)]
    unsafe fn lane_mask(live: u32) -> __m256 {
        _mm256_castsi256_ps(_mm256_cmpgt_epi32(
            _mm256_and_si256(
                _mm256_set1_epi32(live as i32),
                _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128),
            ),
            _mm256_setzero_si256(),
        ))
    }

    /// Traces the packet's lanes to their ends, handing each outcome to
    /// `emit` with its lane.
    ///
    /// Two phases alternate. **Steps**: every stepping lane reads its
    /// voxel (one gather for all), and the packet goes on while each of
    /// them takes a plain sphere step; a lane whose step falls under the
    /// early-out threshold, runs out of budget or leaves the shell is
    /// handed to [`Lane::take_step`] / [`Lane::check`] and parks until the
    /// others have parked too. **Walks**: the parked lanes walk their bands
    /// cell by cell together (four gathers of the height map per cell, the
    /// cell steps as blends, no branch per lane), each candidate patch
    /// solved by the scalar solver, the ends handed to [`Lane::walked`].
    ///
    /// Every operation on a lane's values is the scalar tracer's, in the
    /// same order ([`DistanceMap::cell_bound`]'s multiply, clamp, truncation
    /// and index for a step; [`super::super::walk`]'s minima, maxima and
    /// margins for a cell), so the hits are the scalar tracer's bit for
    /// bit. Parking a lane changes when its work is done, not what it is.
    ///
    /// # Safety
    /// AVX2 must be present, the distance map's voxel count must fit in an
    /// `i32`, and the map must be clamped.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn steps<const ANY: bool>(
        height: &HeightMap,
        distance: &DistanceMap,
        c: &Constants,
        lanes: &mut [Option<Lane>; LANES],
        emit: &mut impl FnMut(usize, Outcome),
    ) {
        drive(
            lanes,
            emit,
            // SAFETY: the caller's guarantees, which both phases share.
            |lanes, live, emit| unsafe { step_phase(distance, c, lanes, live, emit) },
            |lanes, live, walks, emit| unsafe {
                walk_phase::<ANY>(height, c, lanes, live, walks, emit)
            },
        );
    }

    /// The alternation of phases of a packet of `N` lanes, whichever
    /// kernel runs them: the lanes at the top of the scalar loop (every
    /// lane at first, then those a walk hands back) are checked, the
    /// stepping ones stepped together by `step` until each parks or ends,
    /// and the parked ones walked together by `walk`, which returns the
    /// lanes that step on. Inlined into each kernel, so the phases inline
    /// with their target features.
    #[inline(always)]
    pub(super) fn drive<const N: usize, E: FnMut(usize, Outcome)>(
        lanes: &mut [Option<Lane>; N],
        emit: &mut E,
        mut step: impl FnMut(&mut [Option<Lane>; N], u32, &mut E) -> (u32, [WalkState; N]),
        mut walk: impl FnMut(&mut [Option<Lane>; N], u32, &[WalkState; N], &mut E) -> u32,
    ) {
        let mut walks = [WalkState::default(); N];
        let mut pending = lanes
            .iter()
            .enumerate()
            .fold(0u32, |m, (l, s)| m | (u32::from(s.is_some()) << l));
        while pending != 0 {
            let mut stepping = 0u32;
            let mut walking = 0u32;
            for l in lanes_of(pending) {
                let lane = lanes[l].as_mut().expect("a pending lane");
                match lane.check() {
                    Next::Step => stepping |= 1 << l,
                    Next::Done(out) => emit(l, out),
                    Next::Walk { t1, last } => {
                        walks[l] = WalkState { t1, last };
                        walking |= 1 << l;
                    }
                }
            }
            if stepping != 0 {
                let (parked, parked_walks) = step(lanes, stepping, emit);
                walking |= parked;
                for l in lanes_of(parked) {
                    walks[l] = parked_walks[l];
                }
            }
            pending = if walking != 0 {
                walk(lanes, walking, &walks, emit)
            } else {
                0
            };
        }
    }

    /// Steps the lanes of `live` until each has parked for a walk or
    /// ended; returns the parked lanes and their walks.
    // Always inlined into the kernel (whose `target_feature` its AVX2
    // intrinsics then inline under): left to the inliner, whether the
    // phases were inlined followed unrelated changes to the crate, and the
    // CLI and the Python extension ran the same trace 10-20% apart.
    // (`inline(always)` is not allowed with `target_feature`, so the phases
    // take none of their own and are only called from `steps`.)
    #[inline(always)]
    unsafe fn step_phase(
        distance: &DistanceMap,
        c: &Constants,
        lanes: &mut [Option<Lane>; LANES],
        mut live: u32,
        emit: &mut impl FnMut(usize, Outcome),
    ) -> (u32, [WalkState; LANES]) {
        let [w, h, d] = distance.size();
        let [sx, sy, sz] = distance.cell_scale();
        let data = distance.data();
        let mut o = [[0.0f32; LANES]; 3];
        let mut dir = [[0.0f32; LANES]; 3];
        let mut t_out = [0.0f32; LANES];
        let mut max_steps = [0i32; LANES];
        let mut t = [0.0f32; LANES];
        let mut steps = [0i32; LANES];
        for (l, slot) in lanes.iter().enumerate() {
            if let Some(lane) = slot {
                // Component by component: a `Vec3` indexed by a loop
                // variable is a branch per access.
                let (ro, rd) = (lane.ray.origin, lane.ray.dir);
                (o[0][l], o[1][l], o[2][l]) = (ro.x, ro.y, ro.z);
                (dir[0][l], dir[1][l], dir[2][l]) = (rd.x, rd.y, rd.z);
                t_out[l] = lane.t_out;
                max_steps[l] = lane.max_steps.min(i32::MAX as u32) as i32;
                t[l] = lane.t;
                steps[l] = lane.steps.min(i32::MAX as u32) as i32;
            }
        }
        let load = |v: &[f32; LANES]| _mm256_loadu_ps(v.as_ptr());
        let (ox, oy, oz) = (load(&o[0]), load(&o[1]), load(&o[2]));
        let (dx, dy, dz) = (load(&dir[0]), load(&dir[1]), load(&dir[2]));
        let t_out_v = load(&t_out);
        let max_steps_v = _mm256_loadu_si256(max_steps.as_ptr().cast());
        let scale = [_mm256_set1_ps(sx), _mm256_set1_ps(sy), _mm256_set1_ps(sz)];
        let top = [w, h, d].map(|n| _mm256_set1_ps((n - 1) as f32));
        let (wv, hv) = (_mm256_set1_epi32(w as i32), _mm256_set1_epi32(h as i32));
        let zero = _mm256_setzero_ps();
        let tau = _mm256_set1_ps(c.tau);
        let one = _mm256_set1_epi32(1);
        let mut tv = load(&t);
        let mut sv = _mm256_loadu_si256(steps.as_ptr().cast());
        let mut parked = 0u32;
        let mut walks = [WalkState::default(); LANES];
        let mut s = [0.0f32; LANES];
        while live != 0 {
            let live_v = lane_mask(live);
            let clamped = |p: __m256, a: usize| {
                let x = _mm256_mul_ps(p, scale[a]);
                _mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(x, zero), top[a]))
            };
            let i = clamped(_mm256_add_ps(ox, _mm256_mul_ps(dx, tv)), 0);
            let j = clamped(_mm256_add_ps(oy, _mm256_mul_ps(dy, tv)), 1);
            let k = clamped(_mm256_add_ps(oz, _mm256_mul_ps(dz, tv)), 2);
            let idx = _mm256_add_epi32(
                _mm256_mullo_epi32(_mm256_add_epi32(_mm256_mullo_epi32(k, hv), j), wv),
                i,
            );
            let value = _mm256_i32gather_ps::<4>(data.as_ptr(), idx);
            let next_t = _mm256_add_ps(tv, value);
            let next_steps = _mm256_add_epi32(sv, one);
            // A lane stays in the vector loop while its step is a sphere
            // step that keeps it in the shell and in budget: exactly when
            // the scalar loop would take the step and find nothing to do
            // before the next.
            let fast = _mm256_and_ps(
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(value, tau),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(next_t, t_out_v),
                ),
                _mm256_castsi256_ps(_mm256_cmpgt_epi32(max_steps_v, next_steps)),
            );
            let fast_live = _mm256_and_ps(fast, live_v);
            tv = _mm256_blendv_ps(tv, next_t, fast_live);
            sv = _mm256_blendv_epi8(sv, next_steps, _mm256_castps_si256(fast_live));
            let slow = live & !bits(fast_live);
            if slow == 0 {
                continue;
            }
            // The lanes that did not take a plain step take this one
            // through the scalar transitions.
            _mm256_storeu_ps(t.as_mut_ptr(), tv);
            _mm256_storeu_si256(steps.as_mut_ptr().cast(), sv);
            _mm256_storeu_ps(s.as_mut_ptr(), value);
            for l in lanes_of(slow) {
                let lane = lanes[l].as_mut().expect("a live lane");
                lane.t = t[l];
                lane.steps = steps[l] as u32;
                let mut next = lane.take_step(c, s[l]);
                if matches!(next, Next::Step) {
                    next = lane.check();
                }
                live &= !(1 << l);
                match next {
                    // A sphere step that left the shell or the budget was
                    // checked above; one that did neither stays.
                    Next::Step => {
                        live |= 1 << l;
                        t[l] = lane.t;
                        steps[l] = lane.steps as i32;
                    }
                    Next::Done(out) => emit(l, out),
                    Next::Walk { t1, last } => {
                        walks[l] = WalkState { t1, last };
                        parked |= 1 << l;
                    }
                }
            }
            tv = load(&t);
            sv = _mm256_loadu_si256(steps.as_ptr().cast());
        }
        // Every lane has parked or ended, its point and budget written back
        // on the way out of the loop.
        (parked, walks)
    }

    /// Walks the lanes of `live` over their bands together; returns the
    /// lanes that step on.
    #[inline(always)]
    pub(super) unsafe fn walk_phase<const ANY: bool>(
        height: &HeightMap,
        c: &Constants,
        lanes: &mut [Option<Lane>; LANES],
        mut live: u32,
        walks: &[WalkState; LANES],
        emit: &mut impl FnMut(usize, Outcome),
    ) -> u32 {
        let mut resume = 0u32;
        let mut ci = [0i32; LANES];
        let mut cj = [0i32; LANES];
        let mut tx = [0.0f32; LANES];
        let mut ty = [0.0f32; LANES];
        let mut dtx = [0.0f32; LANES];
        let mut dty = [0.0f32; LANES];
        let mut sti = [0i32; LANES];
        let mut stj = [0i32; LANES];
        let mut ta = [0.0f32; LANES];
        let mut t1 = [0.0f32; LANES];
        let mut margin = [0.0f32; LANES];
        let mut oz = [0.0f32; LANES];
        let mut axes = [[0.0f32; LANES]; 4];
        let mut dz = [0.0f32; LANES];
        for l in lanes_of(live) {
            let lane = lanes[l].as_ref().expect("a live lane");
            let (t0, end) = (lane.t, walks[l].t1);
            if end < t0 {
                // The walk of an empty band: its miss, at once.
                live &= !(1 << l);
                let lane = lanes[l].as_mut().expect("a live lane");
                match lane.walked::<ANY>(c, Walk::Miss { cells: 0 }, end, walks[l].last) {
                    Some(out) => emit(l, out),
                    None => resume |= 1 << l,
                }
                continue;
            }
            let g = &lane.grid;
            let (i, x) = g.x.start(t0);
            let (j, y) = g.y.start(t0);
            // Cells lie within a cell or two of the map (the band is
            // inside the shell box): far inside `i32`.
            ci[l] = i.clamp(i32::MIN as i64 / 2, i32::MAX as i64 / 2) as i32;
            cj[l] = j.clamp(i32::MIN as i64 / 2, i32::MAX as i64 / 2) as i32;
            tx[l] = x;
            ty[l] = y;
            dtx[l] = g.x.dt;
            dty[l] = g.y.dt;
            sti[l] = g.x.step as i32;
            stj[l] = g.y.step as i32;
            ta[l] = t0;
            t1[l] = end;
            margin[l] = 1e-4 * (1.0 + end.abs());
            oz[l] = g.o.z;
            axes[0][l] = g.x.o;
            axes[1][l] = g.x.d;
            axes[2][l] = g.y.o;
            axes[3][l] = g.y.d;
            dz[l] = g.d.z;
        }
        let load = |v: &[f32; LANES]| _mm256_loadu_ps(v.as_ptr());
        let loadi = |v: &[i32; LANES]| _mm256_loadu_si256(v.as_ptr().cast());
        let (mut ci_v, mut cj_v) = (loadi(&ci), loadi(&cj));
        let (mut tx_v, mut ty_v) = (load(&tx), load(&ty));
        let (dtx_v, dty_v) = (load(&dtx), load(&dty));
        let (sti_v, stj_v) = (loadi(&sti), loadi(&stj));
        let mut ta_v = load(&ta);
        let t1_v = load(&t1);
        let margin_v = load(&margin);
        let (oz_v, dz_v) = (load(&oz), load(&dz));
        let descending = _mm256_cmp_ps::<_CMP_LT_OQ>(dz_v, _mm256_setzero_ps());
        let (w, h) = (height.width() as i32, height.height() as i32);
        let (wmax, hmax) = (_mm256_set1_epi32(w - 1), _mm256_set1_epi32(h - 1));
        let zero_i = _mm256_setzero_si256();
        let one_i = _mm256_set1_epi32(1);
        let wv = _mm256_set1_epi32(w);
        let data = height.data();
        let (xo_v, xd_v, yo_v, yd_v) = (
            load(&axes[0]),
            load(&axes[1]),
            load(&axes[2]),
            load(&axes[3]),
        );
        // What single precision may miss of the ray's height over a patch:
        // its cell coordinates are rounded at the scale of the map's width
        // and height (a few ulps each), and each corner difference carries
        // that error into the height.
        let slack = _mm256_set1_ps(8.0 * f32::EPSILON * (w + h + 2) as f32);
        let abs = |v: __m256| _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        let mut cells = [0u32; LANES];
        // Cells walked per lane: each live lane's all-ones mask (-1)
        // subtracted once a cell.
        let mut cells_v = _mm256_setzero_si256();
        let mut corners = [[0.0f32; LANES]; 4];
        let mut tb = [0.0f32; LANES];
        // Lanes whose walk ended on a crossing, their solves still to do.
        let mut waiting = 0u32;
        let mut deferred = [Deferred::default(); LANES];
        while live != 0 {
            let live_v = lane_mask(live);
            let tb_v = _mm256_min_ps(_mm256_min_ps(tx_v, ty_v), t1_v);
            cells_v = _mm256_sub_epi32(cells_v, _mm256_castps_si256(live_v));
            // The cell's corners, clamped to the map as `HeightMap::cell`
            // addresses a clamped map.
            let clamp = |v: __m256i, hi: __m256i| _mm256_min_epi32(_mm256_max_epi32(v, zero_i), hi);
            let i0 = clamp(ci_v, wmax);
            let i1 = clamp(_mm256_add_epi32(ci_v, one_i), wmax);
            let r0 = _mm256_mullo_epi32(clamp(cj_v, hmax), wv);
            let r1 = _mm256_mullo_epi32(clamp(_mm256_add_epi32(cj_v, one_i), hmax), wv);
            let ptr = data.as_ptr();
            let h00 = _mm256_i32gather_ps::<4>(ptr, _mm256_add_epi32(r0, i0));
            let h10 = _mm256_i32gather_ps::<4>(ptr, _mm256_add_epi32(r0, i1));
            let h01 = _mm256_i32gather_ps::<4>(ptr, _mm256_add_epi32(r1, i0));
            let h11 = _mm256_i32gather_ps::<4>(ptr, _mm256_add_epi32(r1, i1));
            let z_low = _mm256_add_ps(
                oz_v,
                _mm256_mul_ps(dz_v, _mm256_blendv_ps(ta_v, tb_v, descending)),
            );
            let highest = _mm256_max_ps(_mm256_max_ps(h00, h10), _mm256_max_ps(h01, h11));
            let mut ended = 0u32;
            let mut defer_now = 0u32;
            if ANY {
                let lowest = _mm256_min_ps(_mm256_min_ps(h00, h10), _mm256_min_ps(h01, h11));
                let below = _mm256_cmp_ps::<_CMP_LT_OQ>(z_low, _mm256_sub_ps(lowest, margin_v));
                let blocked = live & bits(below);
                for l in lanes_of(blocked) {
                    emit(l, Outcome::Blocked);
                }
                ended |= blocked;
            }
            let near = _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_sub_ps(z_low, margin_v), highest);
            let mut solve = live & !ended & bits(near);
            if solve != 0 {
                // The patch's quadratic along the stretch, in single
                // precision (`exact::patch_hit`'s in double): a cell where
                // the ray stays above the patch by more than the rounding
                // of either is not solved. The solve would find no root
                // there, so the hits are unchanged; most cells the ray
                // comes down to but passes over end here, without the
                // double-precision solve.
                let mul = _mm256_mul_ps;
                let (add, sub) = (_mm256_add_ps, _mm256_sub_ps);
                let px = sub(add(xo_v, mul(xd_v, ta_v)), _mm256_cvtepi32_ps(ci_v));
                let py = sub(add(yo_v, mul(yd_v, ta_v)), _mm256_cvtepi32_ps(cj_v));
                let a = sub(h10, h00);
                let b = sub(h01, h00);
                let c = add(sub(sub(h00, h10), h01), h11);
                let z0 = add(oz_v, mul(dz_v, ta_v));
                let k0 = sub(
                    sub(sub(sub(z0, h00), mul(a, px)), mul(b, py)),
                    mul(c, mul(px, py)),
                );
                let k1 = sub(
                    sub(sub(dz_v, mul(a, xd_v)), mul(b, yd_v)),
                    mul(c, add(mul(px, yd_v), mul(xd_v, py))),
                );
                let k2 = sub(zero, mul(c, mul(xd_v, yd_v)));
                let len = sub(tb_v, ta_v);
                let k_end = add(k0, mul(len, add(k1, mul(len, k2))));
                let m = add(
                    margin_v,
                    mul(slack, add(add(abs(a), abs(b)), add(abs(c), one))),
                );
                let gt = |x: __m256, y: __m256| _mm256_cmp_ps::<_CMP_GT_OQ>(x, y);
                let ends_clear = _mm256_and_ps(gt(k0, m), gt(k_end, m));
                // Convex with its vertex inside the stretch: clear only if
                // the vertex too stays above the margin.
                let neg_k1 = sub(zero, k1);
                let two_k2 = add(k2, k2);
                let vertex_inside = _mm256_and_ps(
                    _mm256_and_ps(gt(k2, zero), gt(neg_k1, zero)),
                    gt(mul(two_k2, len), neg_k1),
                );
                let vertex_clear = gt(mul(add(two_k2, two_k2), sub(k0, m)), mul(k1, k1));
                let clear = _mm256_and_ps(
                    ends_clear,
                    _mm256_or_ps(
                        _mm256_andnot_ps(vertex_inside, _mm256_castsi256_ps(_mm256_set1_epi32(-1))),
                        vertex_clear,
                    ),
                );
                solve &= !bits(clear);
                // Above the patch at the stretch's start and below it at
                // its end by more than the rounding: the ray crosses it
                // here, so this lane's walk ends at this cell (its solve
                // finds the root). The solve waits until the packet's walks
                // are done, so the others do not wait for its square root
                // and divisions, and the deferred solves overlap.
                let lt = |x: __m256, y: __m256| _mm256_cmp_ps::<_CMP_LT_OQ>(x, y);
                let crossing = _mm256_and_ps(gt(k0, m), lt(k_end, sub(zero, m)));
                defer_now = solve & bits(crossing);
                solve &= !defer_now;
            }
            let last_cell = _mm256_cmp_ps::<_CMP_GE_OQ>(tb_v, t1_v);
            let at_end = live & !ended & !defer_now & bits(last_cell);
            if solve | at_end | defer_now != 0 {
                _mm256_storeu_ps(tb.as_mut_ptr(), tb_v);
                _mm256_storeu_ps(ta.as_mut_ptr(), ta_v);
                _mm256_storeu_si256(ci.as_mut_ptr().cast(), ci_v);
                _mm256_storeu_si256(cj.as_mut_ptr().cast(), cj_v);
                if solve | defer_now != 0 {
                    _mm256_storeu_ps(corners[0].as_mut_ptr(), h00);
                    _mm256_storeu_ps(corners[1].as_mut_ptr(), h10);
                    _mm256_storeu_ps(corners[2].as_mut_ptr(), h01);
                    _mm256_storeu_ps(corners[3].as_mut_ptr(), h11);
                }
                _mm256_storeu_si256(cells.as_mut_ptr().cast(), cells_v);
                if defer_now != 0 {
                    let (mut txs, mut tys) = ([0.0f32; LANES], [0.0f32; LANES]);
                    _mm256_storeu_ps(txs.as_mut_ptr(), tx_v);
                    _mm256_storeu_ps(tys.as_mut_ptr(), ty_v);
                    for l in lanes_of(defer_now) {
                        deferred[l] = Deferred {
                            corners: [corners[0][l], corners[1][l], corners[2][l], corners[3][l]],
                            at: Cursor {
                                ci: ci[l] as i64,
                                cj: cj[l] as i64,
                                tx: txs[l],
                                ty: tys[l],
                                ta: ta[l],
                                cells: cells[l],
                            },
                            tb: tb[l],
                        };
                    }
                    ended |= defer_now;
                    waiting |= defer_now;
                }
                for l in lanes_of(solve | at_end) {
                    let bit = 1 << l;
                    let lane = lanes[l].as_mut().expect("a live lane");
                    let mut w = None;
                    if solve & bit != 0 {
                        let g = &lane.grid;
                        let cell = [corners[0][l], corners[1][l], corners[2][l], corners[3][l]];
                        if let Some((t, normal)) = patch_hit(
                            cell,
                            ci[l] as i64,
                            cj[l] as i64,
                            g.o.as_dvec3(),
                            g.d.as_dvec3(),
                            c.cells[0],
                            c.cells[1],
                            ta[l] as f64,
                            tb[l] as f64,
                        ) {
                            w = Some(Walk::Hit(SurfaceHit {
                                t,
                                normal,
                                cells: cells[l],
                            }));
                        }
                    }
                    if w.is_none() && at_end & bit != 0 {
                        w = Some(Walk::Miss { cells: cells[l] });
                    }
                    let Some(w) = w else { continue };
                    ended |= bit;
                    match lane.walked::<ANY>(c, w, walks[l].t1, walks[l].last) {
                        Some(out) => emit(l, out),
                        None => resume |= bit,
                    }
                }
            }
            live &= !ended;
            // The next cell: across where the ray leaves through an x side
            // first, down otherwise (the scalar walk's `tx < ty`). Every
            // lane steps, ended or not (an ended lane's cells are clamped
            // into the map and never read back): masking the step by the
            // live lanes would make each cell's address wait for the last
            // cell's gathers, where now the gathers of successive cells
            // overlap.
            ta_v = tb_v;
            let across = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(tx_v, ty_v));
            let along = _mm256_xor_si256(across, _mm256_set1_epi32(-1));
            ci_v = _mm256_add_epi32(ci_v, _mm256_and_si256(sti_v, across));
            cj_v = _mm256_add_epi32(cj_v, _mm256_and_si256(stj_v, along));
            tx_v = _mm256_blendv_ps(
                tx_v,
                _mm256_add_ps(tx_v, dtx_v),
                _mm256_castsi256_ps(across),
            );
            ty_v = _mm256_blendv_ps(ty_v, _mm256_add_ps(ty_v, dty_v), _mm256_castsi256_ps(along));
        }
        // The deferred solves, each as the scalar walk solves that cell; in
        // the (numerically degenerate) case that it finds no root after
        // all, the walk goes on from the next cell as the scalar walk would.
        for l in lanes_of(waiting) {
            let lane = lanes[l].as_mut().expect("a deferred lane");
            let d = &deferred[l];
            let g = &lane.grid;
            let (t1, last) = (walks[l].t1, walks[l].last);
            let w = match patch_hit(
                d.corners,
                d.at.ci,
                d.at.cj,
                g.o.as_dvec3(),
                g.d.as_dvec3(),
                c.cells[0],
                c.cells[1],
                d.at.ta as f64,
                d.tb as f64,
            ) {
                Some((t, normal)) => Walk::Hit(SurfaceHit {
                    t,
                    normal,
                    cells: d.at.cells,
                }),
                None => walk_after::<ANY>(height, g, c.cells, d.at, t1),
            };
            match lane.walked::<ANY>(c, w, t1, last) {
                Some(out) => emit(l, out),
                None => resume |= 1 << l,
            }
        }
        resume
    }

    /// A lane's walk stopped at a crossing cell, its solve deferred: the
    /// cell and where the walk stood in it.
    #[derive(Clone, Copy, Default)]
    struct Deferred {
        corners: [f32; 4],
        at: Cursor,
        tb: f32,
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::super::Next;
    use super::avx2::{drive, lanes_of, walk_phase, WalkState};
    use super::{Constants, Lane, Outcome, LANES, WIDE_LANES};
    use crate::{DistanceMap, HeightMap};
    use std::arch::x86_64::*;

    /// [`super::avx2::steps`] for a packet of sixteen lanes: the same
    /// alternation of phases, the steps sixteen lanes a round in AVX-512
    /// registers (one gather of sixteen voxels, the lane masks in mask
    /// registers), the walks of each half of the packet through the
    /// eight-lane walk. Every operation on a lane's values is the scalar
    /// tracer's, in its order, so the hits are its hits bit for bit.
    ///
    /// # Safety
    /// AVX2 and AVX-512F must be present, the distance map's voxel count
    /// must fit in an `i32`, and the map must be clamped.
    #[target_feature(enable = "avx2,avx512f")]
    pub(super) unsafe fn steps<const ANY: bool>(
        height: &HeightMap,
        distance: &DistanceMap,
        c: &Constants,
        lanes: &mut [Option<Lane>; WIDE_LANES],
        emit: &mut impl FnMut(usize, Outcome),
    ) {
        drive(
            lanes,
            emit,
            // SAFETY: the caller's guarantees, which both phases share.
            |lanes, live, emit| unsafe { step_phase(distance, c, lanes, live, emit) },
            |lanes, walking, walks, emit| {
                let mut resume = 0u32;
                let (low, high) = lanes.split_at_mut(LANES);
                for (half, base) in [(low, 0), (high, LANES)] {
                    let live = (walking >> base) & 0xff;
                    if live == 0 {
                        continue;
                    }
                    let half: &mut [Option<Lane>; LANES] =
                        half.try_into().expect("half a packet: eight lanes");
                    let half_walks: [WalkState; LANES] = std::array::from_fn(|l| walks[base + l]);
                    // SAFETY: as above (AVX2 is present beside AVX-512F).
                    let walked = unsafe {
                        walk_phase::<ANY>(height, c, half, live, &half_walks, &mut |l, out| {
                            emit(base + l, out)
                        })
                    };
                    resume |= walked << base;
                }
                resume
            },
        );
    }

    /// Steps the lanes of `live` until each has parked for a walk or
    /// ended; returns the parked lanes and their walks
    /// ([`super::avx2`]'s step phase, sixteen lanes a round).
    #[target_feature(enable = "avx2,avx512f")]
    unsafe fn step_phase(
        distance: &DistanceMap,
        c: &Constants,
        lanes: &mut [Option<Lane>; WIDE_LANES],
        mut live: u32,
        emit: &mut impl FnMut(usize, Outcome),
    ) -> (u32, [WalkState; WIDE_LANES]) {
        let [w, h, d] = distance.size();
        let [sx, sy, sz] = distance.cell_scale();
        let data = distance.data();
        let mut o = [[0.0f32; WIDE_LANES]; 3];
        let mut dir = [[0.0f32; WIDE_LANES]; 3];
        let mut t_out = [0.0f32; WIDE_LANES];
        let mut max_steps = [0i32; WIDE_LANES];
        let mut t = [0.0f32; WIDE_LANES];
        let mut steps = [0i32; WIDE_LANES];
        for (l, slot) in lanes.iter().enumerate() {
            if let Some(lane) = slot {
                let (ro, rd) = (lane.ray.origin, lane.ray.dir);
                (o[0][l], o[1][l], o[2][l]) = (ro.x, ro.y, ro.z);
                (dir[0][l], dir[1][l], dir[2][l]) = (rd.x, rd.y, rd.z);
                t_out[l] = lane.t_out;
                max_steps[l] = lane.max_steps.min(i32::MAX as u32) as i32;
                t[l] = lane.t;
                steps[l] = lane.steps.min(i32::MAX as u32) as i32;
            }
        }
        let load = |v: &[f32; WIDE_LANES]| _mm512_loadu_ps(v.as_ptr());
        let loadi = |v: &[i32; WIDE_LANES]| _mm512_loadu_si512(v.as_ptr().cast());
        let (ox, oy, oz) = (load(&o[0]), load(&o[1]), load(&o[2]));
        let (dx, dy, dz) = (load(&dir[0]), load(&dir[1]), load(&dir[2]));
        let t_out_v = load(&t_out);
        let max_steps_v = loadi(&max_steps);
        let scale = [_mm512_set1_ps(sx), _mm512_set1_ps(sy), _mm512_set1_ps(sz)];
        let top = [w, h, d].map(|n| _mm512_set1_ps((n - 1) as f32));
        let (wv, hv) = (_mm512_set1_epi32(w as i32), _mm512_set1_epi32(h as i32));
        let zero = _mm512_setzero_ps();
        let tau = _mm512_set1_ps(c.tau);
        let one = _mm512_set1_epi32(1);
        let mut tv = load(&t);
        let mut sv = loadi(&steps);
        let mut parked = 0u32;
        let mut walks = [WalkState::default(); WIDE_LANES];
        let mut s = [0.0f32; WIDE_LANES];
        while live != 0 {
            let live_k = live as __mmask16;
            let clamped = |p: __m512, a: usize| {
                let x = _mm512_mul_ps(p, scale[a]);
                _mm512_cvttps_epi32(_mm512_min_ps(_mm512_max_ps(x, zero), top[a]))
            };
            let i = clamped(_mm512_add_ps(ox, _mm512_mul_ps(dx, tv)), 0);
            let j = clamped(_mm512_add_ps(oy, _mm512_mul_ps(dy, tv)), 1);
            let k = clamped(_mm512_add_ps(oz, _mm512_mul_ps(dz, tv)), 2);
            let idx = _mm512_add_epi32(
                _mm512_mullo_epi32(_mm512_add_epi32(_mm512_mullo_epi32(k, hv), j), wv),
                i,
            );
            // Only the live lanes load (the others keep zero).
            let value = _mm512_mask_i32gather_ps::<4>(zero, live_k, idx, data.as_ptr());
            let next_t = _mm512_add_ps(tv, value);
            let next_steps = _mm512_add_epi32(sv, one);
            // A lane stays in the vector loop while its step is a sphere
            // step that keeps it in the shell and in budget, exactly as in
            // the eight-lane kernel.
            let fast = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(value, tau)
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(next_t, t_out_v)
                & _mm512_cmpgt_epi32_mask(max_steps_v, next_steps);
            let fast_live = fast & live_k;
            tv = _mm512_mask_blend_ps(fast_live, tv, next_t);
            sv = _mm512_mask_blend_epi32(fast_live, sv, next_steps);
            let slow = live & !u32::from(fast_live);
            if slow == 0 {
                continue;
            }
            _mm512_storeu_ps(t.as_mut_ptr(), tv);
            _mm512_storeu_si512(steps.as_mut_ptr().cast(), sv);
            _mm512_storeu_ps(s.as_mut_ptr(), value);
            for l in lanes_of(slow) {
                let lane = lanes[l].as_mut().expect("a live lane");
                lane.t = t[l];
                lane.steps = steps[l] as u32;
                let mut next = lane.take_step(c, s[l]);
                if matches!(next, Next::Step) {
                    next = lane.check();
                }
                live &= !(1 << l);
                match next {
                    Next::Step => {
                        live |= 1 << l;
                        t[l] = lane.t;
                        steps[l] = lane.steps as i32;
                    }
                    Next::Done(out) => emit(l, out),
                    Next::Walk { t1, last } => {
                        walks[l] = WalkState { t1, last };
                        parked |= 1 << l;
                    }
                }
            }
            tv = load(&t);
            sv = loadi(&steps);
        }
        (parked, walks)
    }
}
