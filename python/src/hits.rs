//! What a first-hit query returns to Python, and the two kinds of thing
//! queries run against (one face, a whole scene) behind one trait, so that
//! every query shape (ours, embreex's, trimesh's) is written once.

use crate::arrays::RayRows;
use crate::pool;
use crate::work::Job;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// First hits of a batch of rays, as columns: what [`Target::first_hits`]
/// fills and `intersect` hands to Python as arrays.
pub struct Hits {
    /// Ray parameter in units of the direction as given; inf on a miss.
    pub t: Vec<f32>,
    /// Hit points, 3 a ray; NaN on a miss.
    pub position: Vec<f32>,
    /// Unit geometric normals, 3 a ray; NaN on a miss.
    pub normal: Vec<f32>,
    /// Texture coordinates, 2 a ray (NaN on a miss), where the target has
    /// them.
    pub uv: Option<Vec<f32>>,
    /// What was hit: a face's height-map cell, a scene's shape; -1 on a
    /// miss (-2 on a scene's visible area light).
    pub id: Vec<i64>,
    /// Tracing cost per ray, where the target counts it.
    pub iterations: Option<Vec<u32>>,
}

/// One row of the first-hit columns, as a target that writes every row
/// writes it.
pub struct Row {
    /// [`Hits::t`]'s value.
    pub t: f32,
    /// [`Hits::position`]'s three.
    pub position: [f32; 3],
    /// [`Hits::normal`]'s three.
    pub normal: [f32; 3],
    /// [`Hits::uv`]'s two.
    pub uv: [f32; 2],
    /// [`Hits::id`]'s value.
    pub id: i64,
    /// [`Hits::iterations`]' value.
    pub iterations: u32,
}

impl Row {
    /// What a miss (or a ray left untraced) reads as, in every column.
    pub const MISS: Row = Row {
        t: f32::INFINITY,
        position: [f32::NAN; 3],
        normal: [f32::NAN; 3],
        uv: [f32::NAN; 2],
        id: -1,
        iterations: 0,
    };
}

impl Hits {
    /// `n` misses ([`Row::MISS`]), to be filled.
    pub fn misses(n: usize, uv: bool, iterations: bool) -> Self {
        let miss = Row::MISS;
        let mut h = Self::unwritten(n, uv, iterations);
        h.t.fill(miss.t);
        h.position.fill(miss.position[0]);
        h.normal.fill(miss.normal[0]);
        if let Some(uv) = &mut h.uv {
            uv.fill(miss.uv[0]);
        }
        h.id.fill(miss.id);
        if let Some(it) = &mut h.iterations {
            it.fill(miss.iterations);
        }
        h
    }

    /// `n` rows of unspecified values, for a target that writes every
    /// row (hit or miss): buffers of earlier results from the [`pool`],
    /// or new zeroed memory, untouched pages, so that the first touch of
    /// the outputs happens in the parallel loop that writes them and not
    /// in a fill on one thread before it (that fill, and the page faults,
    /// were a tenth of a query on a coarse map).
    pub fn unwritten(n: usize, uv: bool, iterations: bool) -> Self {
        Self {
            t: pool::take(n),
            position: pool::take(3 * n),
            normal: pool::take(3 * n),
            uv: uv.then(|| pool::take(2 * n)),
            id: pool::take(n),
            iterations: iterations.then(|| pool::take(n)),
        }
    }

    /// The hits as a dict of new numpy arrays: `t` (N,), `position` and
    /// `normal` (N, 3), `uv` (N, 2) where known, and the id under `id_key`
    /// (`cell` or `shape`).
    pub fn into_dict<'py>(self, py: Python<'py>, id_key: &str) -> PyResult<Bound<'py, PyDict>> {
        let n = self.t.len();
        let d = PyDict::new(py);
        d.set_item("t", pool::column(py, self.t)?)?;
        d.set_item("position", pool::rows(py, self.position, n, 3)?)?;
        d.set_item("normal", pool::rows(py, self.normal, n, 3)?)?;
        if let Some(uv) = self.uv {
            d.set_item("uv", pool::rows(py, uv, n, 2)?)?;
        }
        d.set_item(id_key, pool::column(py, self.id)?)?;
        if let Some(it) = self.iterations {
            d.set_item("iterations", pool::column(py, it)?)?;
        }
        Ok(d)
    }
}

/// `data` as an `(n, k)` numpy array, without a copy.
pub fn rows<T: numpy::Element>(
    py: Python<'_>,
    data: Vec<T>,
    n: usize,
    k: usize,
) -> Bound<'_, numpy::PyArray2<T>> {
    Array2::from_shape_vec((n, k), data)
        .expect("k values a row")
        .into_pyarray(py)
}

/// What rays are traced against: one displaced face, or a scene.
pub trait Target: Sync {
    /// Writes the first hits of every ray into `hits` (made by
    /// [`Target::new_hits`]), on the current pool, each read through
    /// [`RayRows::get`] (a bad ray is left a miss and fails the query);
    /// rays after `job` is cancelled are left as misses.
    fn first_hits(&self, rays: RayRows<'_>, job: &Arc<Job>, hits: &mut Hits);
    /// The columns [`Target::first_hits`] writes `n` rays' hits into,
    /// with the optional ones it fills: [`Hits::misses`], or
    /// [`Hits::unwritten`] for a target that writes every row.
    fn new_hits(&self, n: usize) -> Hits;
    /// Whether each ray (read through [`RayRows::get`]) is blocked within
    /// its `t_max`.
    fn occluded(&self, rays: RayRows<'_>, job: &Arc<Job>) -> Vec<bool>;
    /// The key under which [`Hits::id`] is returned.
    fn id_key(&self) -> &'static str;
}
