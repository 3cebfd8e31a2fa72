//! The ray queries every target answers, in the three shapes Python users
//! know: ours (`intersect`, `occluded`), embreex's `run` and trimesh's
//! `intersects_*`, written once on the base class [`Queries`] that
//! `DistanceMap` and `Scene` extend.

use crate::arrays::{RayRows, Rays};
use crate::errors;
use crate::hits::{rows, Hits, Target};
use crate::work::{self, Job};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::sync::Arc;

/// Rays below this count run on the calling thread, without the helper
/// thread that makes a long query interruptible.
const QUICK: usize = 1 << 16;

/// embreex's far limit when `dists` is not given.
const EMBREEX_FAR: f32 = 1e37;

/// What a displaced face and a scene share: ray queries on numpy arrays.
#[pyclass(module = "displace", subclass, frozen)]
pub struct Queries {
    target: Arc<dyn Target + Send>,
}

impl Queries {
    /// The queries of `target`.
    pub fn new(target: Arc<dyn Target + Send>) -> Self {
        Self { target }
    }

    /// `query` of the target over `rays`, off the GIL, each ray checked
    /// as the query reads it: a bad ray raises (for the first one, by
    /// index) and the query's results are dropped.
    fn traced<T: Send>(
        &self,
        py: Python<'_>,
        rays: &Rays<'_>,
        threads: Option<usize>,
        query: impl FnOnce(&dyn Target, RayRows<'_>, &Arc<Job>) -> T + Send,
    ) -> PyResult<T> {
        let rows = rays.rows();
        let target = &*self.target;
        work::run(py, threads, None, rows.len < QUICK, |job| {
            let value = query(target, rows, job);
            rows.failure().map_or(Ok(value), Err)
        })?
        .map_err(errors::core)
    }

    /// The first hits of `rays` as [`Hits`].
    fn hits(&self, py: Python<'_>, rays: &Rays<'_>, threads: Option<usize>) -> PyResult<Hits> {
        let mut h = self.target.new_hits(rays.len());
        self.traced(py, rays, threads, |t, rows, job| {
            t.first_hits(rows, job, &mut h)
        })?;
        Ok(h)
    }

    /// Whether each of `rays` is blocked.
    fn blocked(
        &self,
        py: Python<'_>,
        rays: &Rays<'_>,
        threads: Option<usize>,
    ) -> PyResult<Vec<bool>> {
        self.traced(py, rays, threads, |t, rows, job| t.occluded(rows, job))
    }

    /// For the rays that hit: `(ids, ray indices, locations)`, locations
    /// float64 `(M, 3)` as trimesh gives them.
    ///
    /// A displaced surface is the top of a solid, met once from outside,
    /// so a ray has at most one hit here whatever `multiple_hits` says;
    /// trimesh, on an open tessellated sheet, also lists the exits.
    fn located(
        &self,
        py: Python<'_>,
        origins: &Bound<'_, PyAny>,
        directions: &Bound<'_, PyAny>,
        threads: Option<usize>,
    ) -> PyResult<(Vec<i64>, Vec<i64>, Vec<f64>)> {
        let rays = Rays::new(origins, directions, None, "t_max", f32::INFINITY)?;
        let h = self.hits(py, &rays, threads)?;
        let mut found = (Vec::new(), Vec::new(), Vec::new());
        for (i, &t) in h.t.iter().enumerate() {
            if t.is_finite() {
                found.0.push(h.id[i]);
                found.1.push(i as i64);
                found
                    .2
                    .extend(h.position[3 * i..3 * i + 3].iter().map(|&v| f64::from(v)));
            }
        }
        Ok(found)
    }
}

#[pymethods]
impl Queries {
    /// First hits: a dict of arrays `t`, `position`, `normal` (and `uv`,
    /// the id, `iterations` where the target has them).
    #[pyo3(signature = (origins, directions, t_max=None, *, threads=None))]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        t_max: Option<&Bound<'py, PyAny>>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rays = Rays::new(origins, directions, t_max, "t_max", f32::INFINITY)?;
        self.hits(py, &rays, threads)?
            .into_dict(py, self.target.id_key())
    }

    /// A bool array: something lies on the ray within `t_max`.
    #[pyo3(signature = (origins, directions, t_max=None, *, threads=None))]
    fn occluded<'py>(
        &self,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        t_max: Option<&Bound<'py, PyAny>>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (py, rays) = (
            origins.py(),
            Rays::new(origins, directions, t_max, "t_max", f32::INFINITY)?,
        );
        Ok(PyArray1::from_vec(py, self.blocked(py, &rays, threads)?))
    }

    /// embreex's `EmbreeScene.run`: `query` INTERSECT gives the hit's id
    /// (int32, -1 on a miss) or, with `output`, a dict `u, v, Ng, tfar,
    /// primID, geomID`; OCCLUDED gives int32 0 where blocked and -1 where
    /// not (embreex 4's convention); DISTANCE gives `tfar` (the limit on a
    /// miss).
    #[pyo3(signature = (vec_origins, vec_directions, dists=None, query="INTERSECT", output=None, *, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn run<'py>(
        &self,
        py: Python<'py>,
        vec_origins: &Bound<'py, PyAny>,
        vec_directions: &Bound<'py, PyAny>,
        dists: Option<&Bound<'py, PyAny>>,
        query: &str,
        output: Option<bool>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let rays = Rays::new(vec_origins, vec_directions, dists, "dists", EMBREEX_FAR)?;
        let output = output.unwrap_or(false);
        if query == "OCCLUDED" {
            let b = self.blocked(py, &rays, threads)?;
            let ids: Vec<i32> = b.iter().map(|&b| if b { 0 } else { -1 }).collect();
            return Ok(PyArray1::from_vec(py, ids).into_any());
        }
        if query != "INTERSECT" && query != "DISTANCE" {
            return Err(errors::value(format!(
                "query `{query}`: expected INTERSECT, OCCLUDED or DISTANCE"
            )));
        }
        let h = self.hits(py, &rays, threads)?;
        let n = h.t.len();
        let far = rays.rows();
        let tfar: Vec<f32> = (0..n)
            .map(|i| {
                if h.t[i].is_finite() {
                    h.t[i]
                } else {
                    far.raw(i)[6]
                }
            })
            .collect();
        if query == "DISTANCE" && !output {
            return Ok(PyArray1::from_vec(py, tfar).into_any());
        }
        let ids: Vec<i32> =
            h.id.iter()
                .map(|&k| k.clamp(-1, i64::from(i32::MAX)) as i32)
                .collect();
        if !output {
            return Ok(PyArray1::from_vec(py, ids).into_any());
        }
        let (u, v): (Vec<f32>, Vec<f32>) = match &h.uv {
            Some(uv) => uv.chunks_exact(2).map(|c| (c[0], c[1])).unzip(),
            None => (vec![f32::NAN; n], vec![f32::NAN; n]),
        };
        let geom: Vec<i32> = ids.iter().map(|&k| if k >= 0 { 0 } else { -1 }).collect();
        let d = PyDict::new(py);
        d.set_item("u", PyArray1::from_vec(py, u))?;
        d.set_item("v", PyArray1::from_vec(py, v))?;
        d.set_item("Ng", rows(py, h.normal, n, 3))?;
        d.set_item("tfar", PyArray1::from_vec(py, tfar))?;
        d.set_item("primID", PyArray1::from_vec(py, ids))?;
        d.set_item("geomID", PyArray1::from_vec(py, geom))?;
        Ok(d.into_any())
    }

    /// trimesh's `intersects_first`: the id of the first thing each ray
    /// hits, -1 on a miss (int64).
    #[pyo3(signature = (ray_origins, ray_directions, *, threads=None))]
    fn intersects_first<'py>(
        &self,
        py: Python<'py>,
        ray_origins: &Bound<'py, PyAny>,
        ray_directions: &Bound<'py, PyAny>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let rays = Rays::new(ray_origins, ray_directions, None, "t_max", f32::INFINITY)?;
        Ok(PyArray1::from_vec(py, self.hits(py, &rays, threads)?.id))
    }

    /// trimesh's `intersects_any`: whether each ray hits anything.
    #[pyo3(signature = (ray_origins, ray_directions, *, threads=None))]
    fn intersects_any<'py>(
        &self,
        ray_origins: &Bound<'py, PyAny>,
        ray_directions: &Bound<'py, PyAny>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        self.occluded(ray_origins, ray_directions, None, threads)
    }

    /// trimesh's `intersects_location`: `(locations, index_ray,
    /// index_tri)`, at most one hit a ray (see [`Queries::located`]).
    #[pyo3(signature = (ray_origins, ray_directions, multiple_hits=true, *, threads=None))]
    fn intersects_location<'py>(
        &self,
        py: Python<'py>,
        ray_origins: &Bound<'py, PyAny>,
        ray_directions: &Bound<'py, PyAny>,
        multiple_hits: bool,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let _ = multiple_hits;
        let (ids, index_ray, locations) = self.located(py, ray_origins, ray_directions, threads)?;
        let m = ids.len();
        PyTuple::new(
            py,
            [
                rows(py, locations, m, 3).into_any(),
                PyArray1::from_vec(py, index_ray).into_any(),
                PyArray1::from_vec(py, ids).into_any(),
            ],
        )
    }

    /// trimesh's `intersects_id`: `(index_tri, index_ray)`, and the
    /// locations third when `return_locations`.
    #[pyo3(signature = (ray_origins, ray_directions, multiple_hits=true, max_hits=20, return_locations=false, *, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn intersects_id<'py>(
        &self,
        py: Python<'py>,
        ray_origins: &Bound<'py, PyAny>,
        ray_directions: &Bound<'py, PyAny>,
        multiple_hits: bool,
        max_hits: usize,
        return_locations: bool,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let _ = (multiple_hits, max_hits);
        let (ids, index_ray, locations) = self.located(py, ray_origins, ray_directions, threads)?;
        let m = ids.len();
        let mut items = vec![
            PyArray1::from_vec(py, ids).into_any(),
            PyArray1::from_vec(py, index_ray).into_any(),
        ];
        if return_locations {
            items.push(rows(py, locations, m, 3).into_any());
        }
        PyTuple::new(py, items)
    }
}
