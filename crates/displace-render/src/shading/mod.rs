//! What shading a hit needs beside the scene: the BSDF of a material at a
//! hit ([`bsdf`]), the emitters the path tracer samples ([`emitters`]), and
//! the numbers both integrators draw ([`sampler`]: independent or
//! Owen-scrambled [`sobol`] points).

pub mod bsdf;
pub mod emitters;
pub mod sampler;
pub mod sobol;
