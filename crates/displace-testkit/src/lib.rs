//! # displace-testkit
//!
//! What the tests of several crates share, so each is defined once and
//! every crate's tests judge alike: golden images judged by FLIP with a
//! mean and a percentile threshold ([`golden`]: the CPU renderer's and the
//! GPU raster path's goldens), and elevation models as GDAL writes them
//! ([`elevation`]: the renderer's and the CLI's tests of `height_range`).
//! A dev-dependency only; no library links it.

#![warn(missing_docs)]

pub mod elevation;
pub mod golden;
