//! numpy arrays in: rays as `(N, 3)` origins and directions of float32 or
//! float64, in any memory order and any stride, read where they lie (no
//! copy of the inputs), each checked as it is read with the CLI's checks
//! ([`displace_core::physical::check_ray`]): a bad ray fails the query
//! with the CLI's message for the first one.

use crate::errors;
use displace_core::physical;
use numpy::ndarray::{ArrayView1, ArrayView2};
use numpy::ndarray::{Dimension, Ix1, Ix2};
use numpy::PyReadonlyArray;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A borrowed float array of dimension `D`, of either float type.
pub enum Floats<'py, D: Dimension> {
    /// float32, as numpy holds it.
    F32(PyReadonlyArray<'py, f32, D>),
    /// float64, read as float32 (the tracer's precision).
    F64(PyReadonlyArray<'py, f64, D>),
}

/// A borrowed `(N, 3)` array.
pub type Held<'py> = Floats<'py, Ix2>;

/// `arr` borrowed as float32 or float64, or a `ValueError` naming `name`
/// and the dtype found.
fn floats<'py, D: Dimension>(name: &str, arr: &Bound<'py, PyAny>) -> PyResult<Floats<'py, D>> {
    if let Ok(a) = arr.extract::<PyReadonlyArray<f32, D>>() {
        return Ok(Floats::F32(a));
    }
    if let Ok(a) = arr.extract::<PyReadonlyArray<f64, D>>() {
        return Ok(Floats::F64(a));
    }
    Err(errors::value(format!(
        "{name}: dtype {}, expected float32 or float64",
        dtype_name(arr)
    )))
}

/// A view of the rows of a [`Held`] array, `Send` so that the GIL can be
/// released while the tracer reads it.
#[derive(Clone, Copy)]
pub enum Rows<'a> {
    /// One row, broadcast to every ray (as embreex broadcasts one
    /// direction).
    One([f32; 3]),
    /// float32 rows packed 3 a row (C order, unit stride: what numpy makes
    /// by default), read as a slice. This is the common case, and the one
    /// that must cost nothing beside the trace: indexing a strided view
    /// per ray cost a tenth of the trace of a ray through a coarse map.
    Packed(&'a [[f32; 3]]),
    /// float32 rows in any other layout.
    F32(ArrayView2<'a, f32>),
    /// float64 rows.
    F64(ArrayView2<'a, f64>),
}

impl Rows<'_> {
    /// Rows in the array (1 is broadcast to every ray).
    pub fn len(&self) -> usize {
        match self {
            Rows::One(_) => 1,
            Rows::Packed(a) => a.len(),
            Rows::F32(a) => a.nrows(),
            Rows::F64(a) => a.nrows(),
        }
    }

    /// Asks the caches for rows `i..i + n` of a packed array ahead of
    /// their reads (nothing for other layouts).
    #[inline(always)]
    pub fn prefetch(&self, i: usize, n: usize) {
        #[cfg(target_arch = "x86_64")]
        if let Rows::Packed(a) = self {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let rows = &a[i.min(a.len())..(i + n).min(a.len())];
            let bytes = std::mem::size_of_val(rows);
            let base = rows.as_ptr().cast::<i8>();
            for off in (0..bytes).step_by(64) {
                // SAFETY: a prefetch reads nothing; the address is inside
                // the rows.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(off)) };
            }
        }
    }

    /// Row `i` (the one row when there is one: broadcast).
    #[inline(always)]
    pub fn row(&self, i: usize) -> [f32; 3] {
        match self {
            Rows::One(r) => *r,
            Rows::Packed(a) => a[i],
            Rows::F32(a) => [a[[i, 0]], a[[i, 1]], a[[i, 2]]],
            Rows::F64(a) => [a[[i, 0]] as f32, a[[i, 1]] as f32, a[[i, 2]] as f32],
        }
    }
}

impl Held<'_> {
    /// The rows of the held array, packed where its layout allows.
    pub fn rows(&self) -> Rows<'_> {
        let rows = match self {
            Floats::F32(a) => {
                let view = a.as_array();
                match view.to_slice() {
                    Some(flat) => Rows::Packed(flat.as_chunks::<3>().0),
                    None => Rows::F32(view),
                }
            }
            Floats::F64(a) => Rows::F64(a.as_array()),
        };
        if rows.len() == 1 {
            Rows::One(rows.row(0))
        } else {
            rows
        }
    }
}

/// The dtype of `obj` as numpy names it, for messages.
fn dtype_name(obj: &Bound<'_, PyAny>) -> String {
    obj.getattr("dtype")
        .and_then(|d| d.str().map(|s| s.to_string()))
        .unwrap_or_else(|_| obj.get_type().name().map_or("?".into(), |n| n.to_string()))
}

/// `obj` as a numpy array: itself, or `numpy.asarray(obj)` for lists and
/// other sequences.
fn as_array<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    if obj.is_instance(&np.getattr("ndarray")?)? {
        return Ok(obj.clone());
    }
    np.call_method1("asarray", (obj,))
        .map_err(|e| errors::value(format!("not an array: {e}")))
}

/// An `(N, 3)` float array named `name` in messages.
pub fn points<'py>(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Held<'py>> {
    let arr = as_array(obj)?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(errors::value(format!(
            "{name}: shape {shape:?}, expected (N, 3): x, y, z per row"
        )));
    }
    floats(name, &arr)
}

/// A ray length limit: none (unbounded), one number for every ray, or one
/// per ray.
pub enum Limits<'py> {
    /// Every ray unbounded, or bounded alike.
    All(f32),
    /// One per ray.
    PerRay(Floats<'py, Ix1>),
}

/// A view of [`Limits`], `Send`.
#[derive(Clone, Copy)]
pub enum LimitRows<'a> {
    /// Every ray alike.
    All(f32),
    /// float32 per ray.
    F32(ArrayView1<'a, f32>),
    /// float64 per ray.
    F64(ArrayView1<'a, f64>),
}

impl LimitRows<'_> {
    /// The limit of ray `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            LimitRows::All(t) => *t,
            LimitRows::F32(a) => a[i],
            LimitRows::F64(a) => a[i] as f32,
        }
    }
}

impl<'py> Limits<'py> {
    /// The view of these limits.
    pub fn rows(&self) -> LimitRows<'_> {
        match self {
            Limits::All(t) => LimitRows::All(*t),
            Limits::PerRay(Floats::F32(a)) => LimitRows::F32(a.as_array()),
            Limits::PerRay(Floats::F64(a)) => LimitRows::F64(a.as_array()),
        }
    }
}

/// `t_max` (or embreex's `dists`) as given: `None`, a number or an `(N,)`
/// array of float32 or float64; `default` for `None`.
pub fn limits<'py>(
    name: &str,
    obj: Option<&Bound<'py, PyAny>>,
    n: usize,
    default: f32,
) -> PyResult<Limits<'py>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(Limits::All(default));
    };
    if let Ok(t) = obj.extract::<f64>() {
        return Ok(Limits::All(t as f32));
    }
    let arr = as_array(obj)?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape != [n] {
        return Err(errors::value(format!(
            "{name}: shape {shape:?}, expected a number or ({n},): one per ray"
        )));
    }
    floats(name, &arr).map(Limits::PerRay)
}

/// The rays of a query: origins, directions (one row broadcast to all)
/// and their limits, borrowed from the caller's arrays.
pub struct Rays<'py> {
    origins: Held<'py>,
    directions: Held<'py>,
    limits: Limits<'py>,
    /// Set when a traced loop met a ray that fails its check
    /// ([`RayRows::get`]): the query then raises for the first such ray.
    bad: AtomicBool,
}

/// A `Send` view of [`Rays`], what the traced closure reads.
#[derive(Clone, Copy)]
pub struct RayRows<'a> {
    origins: Rows<'a>,
    directions: Rows<'a>,
    limits: LimitRows<'a>,
    bad: &'a AtomicBool,
    /// How many rays.
    pub len: usize,
}

impl RayRows<'_> {
    /// Ray `i` as the tracer takes it (origin, direction, `t_max`),
    /// unchecked.
    #[inline(always)]
    pub fn raw(&self, i: usize) -> [f32; 7] {
        let o = self.origins.row(i);
        let d = self.directions.row(i);
        [o[0], o[1], o[2], d[0], d[1], d[2], self.limits.get(i)]
    }

    /// Asks the caches for rays `i..i + n` ahead of their reads.
    #[inline(always)]
    pub fn prefetch(&self, i: usize, n: usize) {
        self.origins.prefetch(i, n);
        self.directions.prefetch(i, n);
    }

    /// Ray `i`, checked as it is read: `None` (and the query marked as
    /// failed) for a ray that `displace trace` would refuse. Checking
    /// each ray in the loop that traces it reads the rays once, where a
    /// pass of its own before the trace read them twice (a tenth of a
    /// query on a coarse map).
    #[inline(always)]
    pub fn get(&self, i: usize) -> Option<[f32; 7]> {
        let r = self.raw(i);
        if physical::ray_is_valid(&r) {
            Some(r)
        } else {
            self.bad.store(true, Ordering::Relaxed);
            None
        }
    }

    /// The error for the first bad ray, with its index, where a traced
    /// loop met one.
    pub fn failure(&self) -> Option<displace_core::Error> {
        if !self.bad.load(Ordering::Relaxed) {
            return None;
        }
        (0..self.len).find_map(|i| physical::check_ray(|| format!("ray {i}"), &self.raw(i)).err())
    }
}

impl<'py> Rays<'py> {
    /// Reads the arguments of a query: `(N, 3)` origins, `(N, 3)` or `(1,
    /// 3)` directions, and `t_max` (see [`limits`]).
    pub fn new(
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        t_max: Option<&Bound<'py, PyAny>>,
        t_max_name: &str,
        default: f32,
    ) -> PyResult<Self> {
        let origins = points("origins", origins)?;
        let directions = points("directions", directions)?;
        let n = origins.rows().len();
        let nd = directions.rows().len();
        if nd != n && nd != 1 {
            return Err(errors::value(format!(
                "directions: {nd} rows for {n} origins: give one direction per origin, or one for all"
            )));
        }
        let limits = limits(t_max_name, t_max, n, default)?;
        Ok(Self {
            origins,
            directions,
            limits,
            bad: AtomicBool::new(false),
        })
    }

    /// How many rays.
    pub fn len(&self) -> usize {
        self.origins.rows().len()
    }

    /// The `Send` view the tracer reads.
    pub fn rows(&self) -> RayRows<'_> {
        RayRows {
            origins: self.origins.rows(),
            directions: self.directions.rows(),
            limits: self.limits.rows(),
            bad: &self.bad,
            len: self.len(),
        }
    }
}
