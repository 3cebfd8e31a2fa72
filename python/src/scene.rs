//! A whole scene (the TOML the CLI renders): ray queries as `displace
//! trace --scene` answers them (the same function, so the same bits), and
//! renders to numpy arrays.

use crate::arrays::RayRows;
use crate::errors;
use crate::hits::{Hits, Target};
use crate::queries::Queries;
use crate::work::{self, Job};
use displace_render::scene::queries::{blocked_many, first_hits, Scratch, BATCH};
use displace_render::{Aov, Integrator, RenderOptions, SamplerKind, SceneOptions};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where a scene came from, so that a render with other settings can build
/// it again.
#[derive(Clone)]
enum Source {
    /// The built-in default scene.
    Default,
    /// A scene file.
    File(PathBuf),
    /// TOML text; relative file names resolve against `base`.
    Text { text: String, base: PathBuf },
}

/// A scene built from its TOML, with the options it was built with.
#[pyclass(module = "displace", extends = Queries, frozen)]
pub struct Scene {
    source: Source,
    cache: bool,
    scene: Arc<displace_render::Scene>,
}

/// Builds `source` with `opts`.
fn build(source: &Source, opts: &SceneOptions) -> displace_render::Result<displace_render::Scene> {
    match source {
        Source::Default => displace_render::Scene::default_scene(opts),
        Source::File(path) => displace_render::Scene::load(path, opts),
        Source::Text { text, base } => {
            displace_render::Scene::from_toml(text, Path::new("<toml>"), base, opts)
        }
    }
}

/// A built scene, as the queries of [`Scene`]'s base class hold it.
struct Built(Arc<displace_render::Scene>);

impl Built {
    /// Runs `query` over the rays in batches of [`BATCH`] (in order, as
    /// `displace trace --scene` runs them), `width` values a ray into a new
    /// buffer.
    fn batched(
        &self,
        rays: RayRows<'_>,
        job: &Job,
        width: usize,
        query: impl Fn(&displace_render::Scene, &[[f32; 7]], &mut Scratch, &mut [f32]) + Sync,
    ) -> Vec<f32> {
        let n = rays.len;
        let mut flat = vec![f32::NAN; width * n];
        flat.par_chunks_mut(width * BATCH)
            .enumerate()
            .for_each_init(
                || (Scratch::default(), Vec::with_capacity(BATCH)),
                |(sc, batch), (k, out)| {
                    if job.cancelled() {
                        return;
                    }
                    batch.clear();
                    for i in k * BATCH..n.min((k + 1) * BATCH) {
                        // A bad ray fails the whole query: its batch is
                        // left as it is.
                        let Some(r) = rays.get(i) else { return };
                        batch.push(r);
                    }
                    query(&self.0, batch, sc, out);
                },
            );
        flat
    }
}

impl Target for Built {
    fn new_hits(&self, n: usize) -> Hits {
        Hits::misses(n, false, false)
    }

    fn first_hits(&self, rays: RayRows<'_>, job: &Arc<Job>, h: &mut Hits) {
        let flat = self.batched(rays, job, 8, first_hits);
        for (i, row) in flat.chunks_exact(8).enumerate() {
            if row[0].is_finite() {
                h.t[i] = row[0];
                h.position[3 * i..3 * i + 3].copy_from_slice(&row[1..4]);
                h.normal[3 * i..3 * i + 3].copy_from_slice(&row[4..7]);
                h.id[i] = row[7] as i64;
            }
        }
    }

    fn occluded(&self, rays: RayRows<'_>, job: &Arc<Job>) -> Vec<bool> {
        let flat = self.batched(rays, job, 1, blocked_many);
        flat.iter().map(|&b| b > 0.0).collect()
    }

    fn id_key(&self) -> &'static str {
        "shape"
    }
}

/// How a scene is built: with the on-disk bake cache or without.
fn options(cache: bool) -> SceneOptions {
    SceneOptions {
        cache_dir: if cache {
            displace_render::default_cache_dir()
        } else {
            None
        },
        ..SceneOptions::default()
    }
}

impl Scene {
    /// The scene to render with these overrides: this one when there are
    /// none, else built again (bakes come from the cache).
    fn with(
        &self,
        py: Python<'_>,
        spp: Option<u32>,
        size: Option<(u32, u32)>,
        integrator: Option<&str>,
        sampler: Option<&str>,
    ) -> PyResult<Arc<displace_render::Scene>> {
        if spp.is_none() && size.is_none() && integrator.is_none() && sampler.is_none() {
            return Ok(self.scene.clone());
        }
        let parse_err = |e: displace_render::Error| errors::value(e.to_string());
        let opts = SceneOptions {
            spp,
            size: size.map(|(w, h)| [w, h]),
            integrator: integrator
                .map(str::parse::<Integrator>)
                .transpose()
                .map_err(parse_err)?,
            sampler: sampler
                .map(str::parse::<SamplerKind>)
                .transpose()
                .map_err(parse_err)?,
            ..options(self.cache)
        };
        if let Some((w, h)) = size {
            if w == 0 || h == 0 {
                return Err(errors::value(format!(
                    "size ({w}, {h}): both must be positive"
                )));
            }
        }
        if spp == Some(0) {
            return Err(errors::value("spp 0: at least one sample a pixel"));
        }
        let source = self.source.clone();
        py.detach(|| build(&source, &opts))
            .map(Arc::new)
            .map_err(errors::render)
    }

    /// Renders `scene` with `aovs`, interruptibly.
    fn render_with(
        py: Python<'_>,
        scene: &displace_render::Scene,
        aovs: Vec<Aov>,
        threads: Option<usize>,
        progress: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<displace_render::Rendered> {
        let (w, h) = (u64::from(scene.width()), u64::from(scene.height()));
        let floats = 3 + aovs.iter().map(|a| a.channels() as u64).sum::<u64>();
        // The image, its AOVs and the array handed back: twice the floats.
        displace_core::memory::check(
            &format!("rendering {w}x{h} pixels"),
            u128::from(w * h * floats * 4 * 2),
        )
        .map_err(errors::core)?;
        work::run(py, threads, progress, false, |job| {
            let report = |done: usize, total: usize| job.progress(done, total);
            let opts = RenderOptions {
                aovs,
                progress: Some(&report),
                cancel: Some(&job.cancel),
                ..RenderOptions::default()
            };
            displace_render::render(scene, &opts)
        })?
        .map_err(errors::render)
    }
}

/// The colour image as `(H, W, 3)` float32.
fn image_array<'py>(
    py: Python<'py>,
    image: &displace_render::Image,
) -> Bound<'py, numpy::PyArray3<f32>> {
    let flat: Vec<f32> = image.pixels.iter().flat_map(|p| p.to_array()).collect();
    numpy::ndarray::Array3::from_shape_vec((image.height as usize, image.width as usize, 3), flat)
        .expect("three channels a pixel")
        .into_pyarray(py)
}

use numpy::IntoPyArray;

#[pymethods]
impl Scene {
    /// Builds a scene; see the package's stubs.
    #[new]
    #[pyo3(signature = (source=None, *, cache=true))]
    fn new(
        py: Python<'_>,
        source: Option<&Bound<'_, PyAny>>,
        cache: bool,
    ) -> PyResult<PyClassInitializer<Self>> {
        let source = match source {
            None => Source::Default,
            Some(s) => match s.extract::<String>().ok() {
                // TOML text has a `[table]` or a `key = value`; a path has
                // neither a newline nor an equals sign.
                Some(t) if t.contains('\n') || t.contains('=') => Source::Text {
                    text: t,
                    base: std::env::current_dir().unwrap_or_default(),
                },
                _ => Source::File(
                    s.extract::<PathBuf>()
                        .map_err(|_| errors::value("source: expected a path, TOML text or None"))?,
                ),
            },
        };
        let opts = options(cache);
        let src = source.clone();
        let scene = Arc::new(py.detach(|| build(&src, &opts)).map_err(errors::render)?);
        let base = Queries::new(Arc::new(Built(scene.clone())));
        Ok(PyClassInitializer::from(base).add_subclass(Self {
            source,
            cache,
            scene,
        }))
    }

    /// Image `(width, height)` as the scene asks.
    #[getter]
    fn size(&self) -> (u32, u32) {
        (self.scene.width(), self.scene.height())
    }

    /// Samples per pixel as the scene asks.
    #[getter]
    fn spp(&self) -> u32 {
        self.scene.spp()
    }

    /// `whitted` or `path`.
    #[getter]
    fn integrator(&self) -> &'static str {
        self.scene.integrator().name()
    }

    /// Bytes of the displacement maps the scene holds.
    #[getter]
    fn nbytes(&self) -> usize {
        self.scene.map_bytes()
    }

    /// What went wrong without stopping the build (warnings the CLI
    /// prints).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.scene.warnings().to_vec()
    }

    /// Renders the colour image, or with `aovs` a dict of it and the
    /// AOVs; see the package's stubs.
    #[pyo3(signature = (spp=None, size=None, integrator=None, *, aovs=None, sampler=None, threads=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        spp: Option<u32>,
        size: Option<(u32, u32)>,
        integrator: Option<&str>,
        aovs: Option<Vec<String>>,
        sampler: Option<&str>,
        threads: Option<usize>,
        progress: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let wanted: Vec<Aov> = aovs
            .iter()
            .flatten()
            .map(|a| a.parse::<Aov>().map_err(|e| errors::value(e.to_string())))
            .collect::<PyResult<_>>()?;
        let scene = self.with(py, spp, size, integrator, sampler)?;
        let r = Self::render_with(py, &scene, wanted, threads, progress)?;
        let color = image_array(py, &r.image);
        if aovs.is_none() {
            return Ok(color.into_any());
        }
        let d = PyDict::new(py);
        d.set_item("color", color)?;
        for a in r.aovs {
            let (h, w, c) = (a.height as usize, a.width as usize, a.aov.channels());
            let arr = numpy::ndarray::Array3::from_shape_vec((h, w, c), a.data)
                .expect("channels a pixel")
                .into_pyarray(py);
            d.set_item(a.aov.name(), arr)?;
        }
        Ok(d.into_any())
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({}x{}, {} spp, {}, {} primitives)",
            self.scene.width(),
            self.scene.height(),
            self.scene.spp(),
            self.scene.integrator().name(),
            self.scene.primitive_count()
        )
    }
}
