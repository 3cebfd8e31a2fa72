//! Output columns that are used again: the buffers of the arrays a query
//! returned come back here when numpy frees those arrays, and the next
//! query writes into them.
//!
//! Why: a million first hits are 48 MB of new arrays. Fresh memory from the
//! allocator is fresh pages from the kernel (glibc maps buffers this large
//! on their own and unmaps them on free), and the first touch of each page
//! is a fault that zeroes it: measured, a tenth of a query on a coarse map,
//! where `displace trace` writes 20 bytes a ray. A caller that queries in a
//! loop (a lidar sweep, a viewshed, a benchmark) lets the last results go
//! before or as it asks for the next; their pages, already faulted in, are
//! what the next query writes. Only buffers that numpy has released are
//! kept, up to [`KEEP_BYTES`] per element type, so the pool never holds
//! more than what a caller has already had and let go.

use numpy::ndarray::{ArrayView, Dimension, Ix1, Ix2};
use numpy::{Element, PyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use std::sync::{Mutex, MutexGuard};

/// The most bytes of released buffers kept, per element type.
const KEEP_BYTES: usize = 256 << 20;

/// The most released buffers kept, per element type.
const KEEP_BUFFERS: usize = 8;

/// Released buffers of one element type.
pub struct Pool<T> {
    free: Mutex<Vec<Vec<T>>>,
}

impl<T> Pool<T> {
    const fn new() -> Self {
        Self {
            free: Mutex::new(Vec::new()),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Vec<Vec<T>>> {
        self.free.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// An element type of the output columns, with its pool.
pub trait Pooled: Element + Copy + Default + Send + 'static {
    /// This type's pool.
    fn pool() -> &'static Pool<Self>;
    /// `v` as the type-erased column the array's owner holds.
    fn column(v: Vec<Self>) -> Column;
}

macro_rules! pooled {
    ($t:ty, $variant:ident) => {
        impl Pooled for $t {
            fn pool() -> &'static Pool<Self> {
                static POOL: Pool<$t> = Pool::new();
                &POOL
            }
            fn column(v: Vec<Self>) -> Column {
                Column::$variant(v)
            }
        }
    };
}
pooled!(f32, F32);
pooled!(i64, I64);
pooled!(u32, U32);

/// A column of one of the [`Pooled`] types.
pub enum Column {
    /// float32 values.
    F32(Vec<f32>),
    /// int64 values.
    I64(Vec<i64>),
    /// uint32 values.
    U32(Vec<u32>),
}

/// `n` values whose contents are unspecified (left from an earlier query,
/// or zeros): for a writer that writes every one. A released buffer of at
/// least `n` and at most twice `n` values is used when there is one, so
/// that a small query does not hold a large buffer; otherwise new zeroed
/// memory (untouched pages, faulted in by the writer's threads).
pub fn take<T: Pooled>(n: usize) -> Vec<T> {
    let found = {
        let mut free = T::pool().lock();
        let best = free
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= n && v.capacity() <= 2 * n.max(1024))
            .min_by_key(|(_, v)| v.capacity())
            .map(|(k, _)| k);
        best.map(|k| free.swap_remove(k))
    };
    match found {
        Some(mut v) => {
            // Within the capacity: no new memory, no fault for the part
            // already written.
            v.resize(n, T::default());
            v
        }
        None => vec![T::default(); n],
    }
}

/// Gives `v` back for a later [`take`], unless the pool is full.
fn give_back<T: Pooled>(v: Vec<T>) {
    let bytes = |v: &Vec<T>| v.capacity() * std::mem::size_of::<T>();
    if v.capacity() == 0 || bytes(&v) > KEEP_BYTES {
        return;
    }
    let mut free = T::pool().lock();
    free.push(v);
    // Oldest first out, until both limits hold.
    while free.len() > KEEP_BUFFERS || free.iter().map(bytes).sum::<usize>() > KEEP_BYTES {
        free.remove(0);
    }
}

/// The owner of a returned array's buffer (the array's numpy `base`):
/// gives the buffer back to its pool when numpy frees the array.
#[pyclass(module = "displace", frozen)]
pub struct Buffer(Option<Column>);

impl Drop for Buffer {
    fn drop(&mut self) {
        match self.0.take() {
            Some(Column::F32(v)) => give_back(v),
            Some(Column::I64(v)) => give_back(v),
            Some(Column::U32(v)) => give_back(v),
            None => {}
        }
    }
}

/// `data` as a numpy array of shape `dim` over its own buffer (no copy),
/// the buffer given back to the pool when numpy frees the array.
fn owned<T: Pooled, D: Dimension>(
    py: Python<'_>,
    data: Vec<T>,
    dim: D,
) -> PyResult<Bound<'_, PyArray<T, D>>> {
    assert_eq!(data.len(), dim.size(), "the shape's count of values");
    let ptr = data.as_ptr();
    let owner = Bound::new(py, Buffer(Some(T::column(data))))?;
    // SAFETY: `ptr` is the buffer of `dim.size()` initialised values that
    // `owner` now holds; moving the Vec into it did not move its buffer,
    // and nothing reads or changes the Vec again until `owner` is dropped,
    // which numpy does when it frees the array (whose base `owner` is).
    let view = unsafe { ArrayView::from_shape_ptr(dim, ptr) };
    // SAFETY: as above: the view's memory lives as long as `owner`.
    Ok(unsafe { PyArray::borrow_from_array(&view, owner.into_any()) })
}

/// `data` as an `(n, k)` numpy array, as [`owned`] makes one.
pub fn rows<T: Pooled>(
    py: Python<'_>,
    data: Vec<T>,
    n: usize,
    k: usize,
) -> PyResult<Bound<'_, PyArray2<T>>> {
    owned(py, data, Ix2(n, k))
}

/// `data` as a 1-D numpy array, as [`owned`] makes one.
pub fn column<T: Pooled>(py: Python<'_>, data: Vec<T>) -> PyResult<Bound<'_, PyArray1<T>>> {
    let n = data.len();
    owned(py, data, Ix1(n))
}
