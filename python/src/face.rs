//! One displaced face: `displace.bake` and `displace.load` make a
//! [`DistanceMap`], which saves as the CLI writes maps and answers ray
//! queries in the face's physical frame ([`displace_core::physical`]).

use crate::arrays::RayRows;
use crate::errors;
use crate::hits::{Hits, Row, Target};
use crate::queries::Queries;
use crate::streamed;
use crate::work::{self, Job};
use displace_core::cell_trace::AnyHitPyramid;
use displace_core::distance_map::Format;
use displace_core::io::height::{self, HeightOptions, HeightRange};
use displace_core::io::{self as dio, MapFile};
use displace_core::{physical, Address, BakeOptions, Extent, HeightMap, Method, TraceOptions};
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// A baked displaced face: the height map and the conservative distance
/// map (Donnelly, GPU Gems 2 ch. 8), with the options its queries trace
/// with. Not the shading normals a renderer keeps beside them: queries
/// never read them, and at an elevation model's resolution they would be
/// three times the heights' memory.
#[pyclass(module = "displace", extends = Queries, frozen)]
pub struct DistanceMap {
    face: Arc<Face>,
}

/// What a [`DistanceMap`] holds, shared with the queries of its base class.
struct Face {
    height: HeightMap,
    distance: displace_core::DistanceMap,
    /// The heights' maximum pyramid, for `occluded`: lines of sight over
    /// terrain graze it, and the distance map's steps, bounded by their
    /// clearance, stay short the whole way (Tevs, Ihrke and Seidel 2008;
    /// [`displace_core::cell_trace::occluded_over`]).
    pyramid: AnyHitPyramid,
    extent: Extent,
    opts: TraceOptions,
}

/// Rays a parallel task traces and writes out: outputs are written in
/// place, in chunks, so that nothing is gathered afterwards.
const CHUNK: usize = 512;

/// Rays traced between two writes of their outputs (see
/// [`Face::first_hits`]): 64 hits are 3 KB.
const BLOCK: usize = 64;

impl Target for Face {
    fn new_hits(&self, n: usize) -> Hits {
        Hits::unwritten(n, true, true)
    }

    fn first_hits(&self, rays: RayRows<'_>, job: &Arc<Job>, h: &mut Hits) {
        let uv = h.uv.as_mut().expect("a face has uv");
        let it = h.iterations.as_mut().expect("a face counts steps");
        h.t.par_chunks_mut(CHUNK)
            .zip(h.position.par_chunks_mut(3 * CHUNK))
            .zip(h.normal.par_chunks_mut(3 * CHUNK))
            .zip(uv.par_chunks_mut(2 * CHUNK))
            .zip(h.id.par_chunks_mut(CHUNK))
            .zip(it.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, (((((t, p), n), uv), id), it))| {
                // A block at a time: its valid rays traced in packets
                // (`physical::intersect_many`, the hits of one ray at a
                // time; a bad ray is left a miss), then each of its rows
                // written once, hit or miss (the columns start unwritten).
                let mut block = Block::default();
                let mut found = [None; BLOCK];
                let cancelled = job.cancelled();
                for (b, t) in t.chunks_mut(BLOCK).enumerate() {
                    let j0 = b * BLOCK;
                    // Read (a bad ray flags the query) even when cancelled.
                    let count = block.gather(&rays, k * CHUNK + j0, t.len(), j0);
                    let count = if cancelled { 0 } else { count };
                    let Block { valid, at } = &block;
                    physical::intersect_many(
                        self.view(),
                        &self.opts,
                        &valid[..count],
                        &mut found[..count],
                    );
                    // Every row written once: its hit where its ray was
                    // traced and hit, a miss otherwise (`at` is ascending).
                    let mut next = at[..count].iter().zip(&found[..count]).peekable();
                    for (r, t) in t.iter_mut().enumerate() {
                        let j = j0 + r;
                        let hit = match next.peek() {
                            Some(&(&a, hit)) if a == j => {
                                next.next();
                                hit.as_ref()
                            }
                            _ => None,
                        };
                        let row = match hit {
                            Some(h) => Row::hit(h),
                            None => Row::MISS,
                        };
                        // Streamed past the caches: see `streamed`.
                        streamed::f32(t, row.t);
                        streamed::f32s(&mut p[3 * j..3 * j + 3], &row.position);
                        streamed::f32s(&mut n[3 * j..3 * j + 3], &row.normal);
                        streamed::f32s(&mut uv[2 * j..2 * j + 2], &row.uv);
                        streamed::i64(&mut id[j], row.id);
                        streamed::u32(&mut it[j], row.iterations);
                    }
                }
                streamed::fence();
            });
    }

    fn occluded(&self, rays: RayRows<'_>, job: &Arc<Job>) -> Vec<bool> {
        let mut out = vec![false; rays.len];
        out.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
            if job.cancelled() {
                return;
            }
            // The block's valid rays over the pyramid; a bad ray is left
            // unblocked.
            let mut block = Block::default();
            let n = block.gather(&rays, b * BLOCK, out.len(), 0);
            let mut blocked = [false; BLOCK];
            let valid = &block.valid[..n];
            physical::occluded_many_over(
                self.view(),
                &self.pyramid,
                &self.opts,
                valid,
                &mut blocked[..n],
            );
            for (&j, &b) in block.at[..n].iter().zip(&blocked[..n]) {
                out[j] = b;
            }
        });
        out
    }

    fn id_key(&self) -> &'static str {
        "cell"
    }
}

impl Row {
    /// The row of a face's hit.
    fn hit(h: &physical::PhysicalHit) -> Row {
        Row {
            t: h.t,
            position: h.position.to_array(),
            normal: h.normal.to_array(),
            uv: h.uv.to_array(),
            id: i64::from(h.cell),
            iterations: h.iterations,
        }
    }
}

/// The valid rays of one block of a query (those [`RayRows::get`]
/// accepts), packed for the packet tracer, each with the row it answers.
struct Block {
    valid: [[f32; 7]; BLOCK],
    at: [usize; BLOCK],
}

impl Default for Block {
    fn default() -> Self {
        Self {
            valid: [[0.0; 7]; BLOCK],
            at: [0; BLOCK],
        }
    }
}

impl Block {
    /// Packs the valid ones of rays `first..first + n` (at most [`BLOCK`]),
    /// ray `first + j` answering row `row0 + j`; returns how many.
    fn gather(&mut self, rays: &RayRows<'_>, first: usize, n: usize, row0: usize) -> usize {
        rays.prefetch(first + BLOCK, BLOCK);
        let mut count = 0;
        for j in 0..n {
            if let Some(r) = rays.get(first + j) {
                (self.valid[count], self.at[count]) = (r, row0 + j);
                count += 1;
            }
        }
        count
    }
}

impl Face {
    /// The face, with its pyramid built (on the current thread pool; call
    /// it off the GIL). Refused before anything is allocated when the
    /// pyramid does not fit in the memory left.
    fn new(
        height: HeightMap,
        distance: displace_core::DistanceMap,
        extent: Extent,
        opts: TraceOptions,
    ) -> Result<Self, displace_core::Error> {
        displace_core::memory::check(
            &format!(
                "the maximum pyramid of the {}x{} height map",
                height.width(),
                height.height()
            ),
            AnyHitPyramid::bytes_for(height.width(), height.height()),
        )?;
        let pyramid = AnyHitPyramid::build(&height);
        Ok(Self {
            height,
            distance,
            pyramid,
            extent,
            opts,
        })
    }

    /// The face as the core's queries read it.
    fn view(&self) -> physical::Face<'_> {
        physical::Face {
            height: &self.height,
            distance: &self.distance,
            extent: self.extent,
        }
    }

    /// A new Python object of this face.
    fn into_py(self, py: Python<'_>) -> PyResult<Py<DistanceMap>> {
        let face = Arc::new(self);
        let base = Queries::new(face.clone());
        Py::new(
            py,
            PyClassInitializer::from(base).add_subclass(DistanceMap { face }),
        )
    }

    /// Bytes held: heights (f32), distances (f32 values and the 8-bit
    /// codes the tracer reads), the maximum pyramid (f32).
    fn bytes(&self) -> usize {
        let voxels: usize = self.distance.size().iter().product();
        self.height.data().len() * 4 + voxels * 5 + self.pyramid.bytes()
    }
}

/// `(SX, SY, SZ)` as an [`Extent`].
fn extent_of(extent: (f32, f32, f32)) -> PyResult<Extent> {
    Extent::new(extent.0, extent.1, extent.2).map_err(errors::core)
}

/// `clamp` or `repeat`.
fn address_of(s: &str) -> PyResult<Address> {
    s.parse().map_err(errors::core)
}

/// `None` (as stored), `"auto"` or `(lo, hi)`.
fn range_of(obj: Option<&Bound<'_, PyAny>>) -> PyResult<HeightRange> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(HeightRange::AsStored);
    };
    if let Ok(s) = obj.extract::<String>() {
        return s.parse().map_err(errors::core);
    }
    let (lo, hi): (f32, f32) = obj
        .extract()
        .map_err(|_| errors::value("height_range: expected None, \"auto\" or (lo, hi)"))?;
    HeightRange::span(lo, hi).map_err(errors::core)
}

/// The trace options of `method` and `iterations`, checked.
fn trace_options(method: &str, iterations: u32) -> PyResult<TraceOptions> {
    let method: Method = method.parse().map_err(errors::core)?;
    displace_core::check_iterations(iterations).map_err(errors::core)?;
    Ok(TraceOptions {
        method,
        iterations,
        ..TraceOptions::default()
    })
}

/// A height map from what `bake` and `load` take: a 2-D numpy array
/// (float32/float64 heights, uint8/uint16 codes over their full scale,
/// row `j` at `v = (j + 0.5) / H` as an image's rows are), or a path or
/// `gen:` source as the CLI reads it (`gen:` at `size`).
fn height_of(
    py: Python<'_>,
    height: &Bound<'_, PyAny>,
    size: [usize; 2],
    range: HeightRange,
    address: Address,
) -> PyResult<HeightMap> {
    if let Ok(source) = height.extract::<PathBuf>() {
        let source = source.to_string_lossy().into_owned();
        let opts = HeightOptions {
            size,
            address,
            range,
            ..HeightOptions::default()
        };
        return py
            .detach(|| height::load(&source, &opts))
            .map_err(errors::core);
    }
    let np = py.import("numpy")?;
    let arr = if height.is_instance(&np.getattr("ndarray")?)? {
        height.clone()
    } else {
        np.call_method1("asarray", (height,))?
    };
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    let [h, w] = shape[..] else {
        return Err(errors::value(format!(
            "height: shape {shape:?}, expected a 2-D array (rows, columns)"
        )));
    };
    // Integer images are codes over their full scale unless a range maps
    // them, as the CLI reads PNGs; floats are heights as they are.
    let (data, full): (Vec<f32>, f32) = if let Ok(a) = arr.extract::<PyReadonlyArray2<f32>>() {
        (a.as_array().iter().copied().collect(), 1.0)
    } else if let Ok(a) = arr.extract::<PyReadonlyArray2<f64>>() {
        (a.as_array().iter().map(|&v| v as f32).collect(), 1.0)
    } else if let Ok(a) = arr.extract::<PyReadonlyArray2<u8>>() {
        (a.as_array().iter().map(|&v| f32::from(v)).collect(), 255.0)
    } else if let Ok(a) = arr.extract::<PyReadonlyArray2<u16>>() {
        (
            a.as_array().iter().map(|&v| f32::from(v)).collect(),
            65535.0,
        )
    } else {
        let dtype = arr.getattr("dtype")?.str()?.to_string();
        return Err(errors::value(format!(
            "height: dtype {dtype}, expected float32, float64, uint8 or uint16"
        )));
    };
    let data = if range == HeightRange::AsStored && full != 1.0 {
        data.into_iter().map(|v| v / full).collect()
    } else {
        data
    };
    height::from_samples("height array", [w, h], data, range, address).map_err(errors::core)
}

/// Refuses a bake whose estimated peak memory exceeds what the machine
/// allows ([`displace_core::memory`]), before anything is allocated.
fn check_memory(height: [usize; 2], size: [usize; 3]) -> PyResult<()> {
    displace_core::memory::check(
        &format!(
            "baking the {}x{} height map into {}x{}x{} voxels",
            height[0], height[1], size[0], size[1], size[2]
        ),
        displace_core::memory::distance_bake_peak_bytes(height, size),
    )
    .map_err(errors::core)
}

/// The size of what `height` names, before it is loaded.
fn height_dimensions(
    height: &Bound<'_, PyAny>,
    size: [usize; 2],
    address: Address,
) -> PyResult<Option<[usize; 2]>> {
    let Ok(source) = height.extract::<PathBuf>() else {
        return Ok(None);
    };
    let opts = HeightOptions {
        size,
        address,
        ..HeightOptions::default()
    };
    height::dimensions(&source.to_string_lossy(), &opts)
        .map(Some)
        .map_err(errors::core)
}

/// Bakes a height map into a [`DistanceMap`]; see the package's stubs.
#[pyfunction]
#[pyo3(signature = (height, size=(256, 256, 16), extent=(1.0, 1.0, 0.1), *, height_range=None, address="clamp", method="sphere", iterations=64, threads=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn bake(
    py: Python<'_>,
    height: &Bound<'_, PyAny>,
    size: (usize, usize, usize),
    extent: (f32, f32, f32),
    height_range: Option<&Bound<'_, PyAny>>,
    address: &str,
    method: &str,
    iterations: u32,
    threads: Option<usize>,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<Py<DistanceMap>> {
    let size = [size.0, size.1, size.2];
    displace_core::DistanceMap::check_size(size).map_err(errors::core)?;
    let extent = extent_of(extent)?;
    let address = address_of(address)?;
    let range = range_of(height_range)?;
    let opts = trace_options(method, iterations)?;
    // A file's size is checked from its header, before it is read; an
    // array's once it is converted.
    let dims = height_dimensions(height, [size[0], size[1]], address)?;
    if let Some(dims) = dims {
        check_memory(dims, size)?;
    }
    let heights = height_of(py, height, [size[0], size[1]], range, address)?;
    if dims.is_none() {
        check_memory([heights.width(), heights.height()], size)?;
    }
    let map = work::run(py, threads, progress, false, |job| {
        let job2 = job.clone();
        let bake = BakeOptions {
            progress: Some(Arc::new(move |done, total| job2.progress(done, total))),
            cancel: Some(job.cancel.clone()),
            ..BakeOptions::new(size, extent)
        };
        let map = displace_core::bake_distance(&heights, &bake)?;
        Face::new(heights, map, extent, opts)
    })?
    .map_err(errors::core)?;
    // Queries need no shading normals (see `Face`): none are made.
    map.into_py(py)
}

/// Loads a distance map the CLI (or [`DistanceMap::save`]) wrote, with the
/// height map it was baked from; see the package's stubs.
#[pyfunction]
#[pyo3(signature = (path, height, extent=None, *, height_range=None, address="clamp", method="sphere", iterations=64))]
#[allow(clippy::too_many_arguments)]
pub fn load(
    py: Python<'_>,
    path: PathBuf,
    height: &Bound<'_, PyAny>,
    extent: Option<(f32, f32, f32)>,
    height_range: Option<&Bound<'_, PyAny>>,
    address: &str,
    method: &str,
    iterations: u32,
) -> PyResult<Py<DistanceMap>> {
    let address = address_of(address)?;
    let range = range_of(height_range)?;
    let opts = trace_options(method, iterations)?;
    let (distance, extent) = match (MapFile::from_path(&path).map_err(errors::core)?, extent) {
        (MapFile::Ktx2, None) => py
            .detach(|| dio::ktx2::read_distance_map(&path))
            .map_err(errors::core)?,
        (_, Some(e)) => {
            let e = extent_of(e)?;
            let map = py
                .detach(|| dio::read_distance_map(&path, e, address))
                .map_err(errors::core)?;
            (map, e)
        }
        (_, None) => {
            return Err(errors::value(format!(
                "{}: a .dds or .npy map does not record its extent: pass extent=(SX, SY, SZ) as it was baked",
                path.display()
            )))
        }
    };
    let [w, h, _] = distance.size();
    let height = height_of(py, height, [w, h], range, distance.address())?;
    py.detach(|| Face::new(height, distance, extent, opts))
        .map_err(errors::core)?
        .into_py(py)
}

#[pymethods]
impl DistanceMap {
    /// Distance-map voxels `(W, H, D)`.
    #[getter]
    fn size(&self) -> (usize, usize, usize) {
        let [w, h, d] = self.face.distance.size();
        (w, h, d)
    }

    /// Physical size of one tile `(SX, SY, SZ)`.
    #[getter]
    fn extent(&self) -> (f32, f32, f32) {
        let e = self.face.extent;
        (e.sx, e.sy, e.sz)
    }

    /// `clamp` (one tile) or `repeat`.
    #[getter]
    fn address(&self) -> &'static str {
        match self.face.height.address() {
            Address::Clamp => "clamp",
            Address::Repeat => "repeat",
        }
    }

    /// Bytes the map holds in memory (heights, distances, the maximum
    /// pyramid `occluded` walks).
    #[getter]
    fn nbytes(&self) -> usize {
        self.face.bytes()
    }

    /// The heights, `(H, W)` float32 in `[0, 1]` (a copy).
    #[getter]
    fn heights<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let h = &self.face.height;
        crate::hits::rows(py, h.data().to_vec(), h.height(), h.width())
    }

    /// Writes the map as the CLI's `bake` does: `.ktx2`, `.dds` (`format`
    /// r8, r16f or r32f; r8 by default) or `.npy` (float32), under a
    /// temporary name renamed last.
    #[pyo3(signature = (path, format=None))]
    fn save(&self, py: Python<'_>, path: PathBuf, format: Option<&str>) -> PyResult<()> {
        let kind = MapFile::from_path(&path).map_err(errors::core)?;
        let format = match (kind, format) {
            (MapFile::Npy, None) => Format::R32F,
            (_, None) => Format::R8,
            (_, Some(f)) => f.parse().map_err(errors::core)?,
        };
        py.detach(|| dio::write_distance_map(&path, &self.face.distance, self.face.extent, format))
            .map_err(errors::core)
    }

    fn __repr__(&self) -> String {
        let [w, h, d] = self.face.distance.size();
        let e = self.face.extent;
        format!(
            "DistanceMap(size=({w}, {h}, {d}), extent=({}, {}, {}), address='{}', {:.1} MB)",
            e.sx,
            e.sy,
            e.sz,
            self.address(),
            self.face.bytes() as f64 / 1e6
        )
    }
}
