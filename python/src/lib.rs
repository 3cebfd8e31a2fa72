//! `displace` for Python: bake distance maps from numpy height fields,
//! answer ray queries (first hit, occlusion) on displaced faces and whole
//! scenes from numpy arrays, and render scenes to numpy images, without
//! tessellating the surfaces (Donnelly, GPU Gems 2 ch. 8: a conservative
//! distance map, sphere traced, refined exactly on the bilinear surface).
//!
//! The Python package `displace` re-exports this module (`displace._native`)
//! and ships its type stubs.

#![warn(missing_docs)]

mod arrays;
mod errors;
mod face;
mod hits;
mod pool;
mod queries;
mod scene;
mod streamed;
mod work;

/// The extension's own buffers (the maps it bakes or loads, its output
/// columns) in transparent huge pages, as the CLI's: a trace through a
/// large map reads it at scattered places, and in 4 KiB pages most of
/// those reads also miss the TLB ([`displace_core::memory::HugePages`]).
/// numpy's and Python's memory is not the extension's and keeps theirs.
#[global_allocator]
static ALLOC: displace_core::memory::HugePages = displace_core::memory::HugePages;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(face::bake, m)?)?;
    m.add_function(wrap_pyfunction!(face::load, m)?)?;
    m.add_class::<queries::Queries>()?;
    m.add_class::<face::DistanceMap>()?;
    m.add_class::<scene::Scene>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
