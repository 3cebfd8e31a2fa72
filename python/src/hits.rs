//! What a first-hit query returns to Python, and the two kinds of thing
//! queries run against (one face, a whole scene) behind one trait, so that
//! every query shape (ours, embreex's, trimesh's) is written once.

use crate::arrays::RayRows;
use crate::work::Job;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1};
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

impl Hits {
    /// `n` misses, to be filled.
    pub fn misses(n: usize, uv: bool, iterations: bool) -> Self {
        Self {
            t: vec![f32::INFINITY; n],
            position: vec![f32::NAN; 3 * n],
            normal: vec![f32::NAN; 3 * n],
            uv: uv.then(|| vec![f32::NAN; 2 * n]),
            id: vec![-1; n],
            iterations: iterations.then(|| vec![0; n]),
        }
    }

    /// The hits as a dict of new numpy arrays: `t` (N,), `position` and
    /// `normal` (N, 3), `uv` (N, 2) where known, and the id under `id_key`
    /// (`cell` or `shape`).
    pub fn into_dict<'py>(self, py: Python<'py>, id_key: &str) -> PyResult<Bound<'py, PyDict>> {
        let n = self.t.len();
        let d = PyDict::new(py);
        d.set_item("t", PyArray1::from_vec(py, self.t))?;
        d.set_item("position", rows(py, self.position, n, 3))?;
        d.set_item("normal", rows(py, self.normal, n, 3))?;
        if let Some(uv) = self.uv {
            d.set_item("uv", rows(py, uv, n, 2))?;
        }
        d.set_item(id_key, PyArray1::from_vec(py, self.id))?;
        if let Some(it) = self.iterations {
            d.set_item("iterations", PyArray1::from_vec(py, it))?;
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
    /// First hits of every ray (checked), on the current pool; rays after
    /// `job` is cancelled are left as misses.
    fn first_hits(&self, rays: RayRows<'_>, job: &Arc<Job>) -> Hits;
    /// Whether each ray (checked) is blocked within its `t_max`.
    fn occluded(&self, rays: RayRows<'_>, job: &Arc<Job>) -> Vec<bool>;
    /// The key under which [`Hits::id`] is returned.
    fn id_key(&self) -> &'static str;
}
