//! No code: this crate's manifest asks for the dependency features that
//! the CLI and the Python extension must share, so that Cargo resolves the
//! tracer's crate identically in both and builds it once (its manifest
//! says why).
#![no_std]
