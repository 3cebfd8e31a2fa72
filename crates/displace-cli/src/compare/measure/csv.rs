//! The comparison's tables as CSV, written to any [`Write`] so the caller
//! decides where they land (atomically, beside the plots): `compare.csv`
//! (one row per map, elevation, technique and budget), `precompute.csv` and
//! `equal_error.csv`. Fixed decimals, so two runs on the same seed differ
//! only in the timing columns.

use super::{equal_error, Precompute, Row};
use std::io::{Result, Write};

/// The header line of `compare.csv`.
pub const CSV_HEADER: &str = "map,elevation_deg,technique,budget,rays,wrong_fraction,mean_error_texels,p99_error_texels,fetches_per_ray,ns_per_ray,gpu_ns_per_ray";

/// Writes `compare.csv`: [`CSV_HEADER`], then `rows`.
pub fn write_rows(w: &mut dyn Write, rows: &[Row]) -> Result<()> {
    writeln!(w, "{CSV_HEADER}")?;
    for r in rows {
        writeln!(
            w,
            "{},{},{},{},{},{:.6},{:.6},{:.6},{:.3},{:.1},{}",
            r.map,
            r.elevation,
            r.technique.name(),
            r.budget,
            r.rays,
            r.wrong,
            r.mean_error,
            r.p99_error,
            r.fetches,
            r.ns_per_ray,
            r.gpu_ns_per_ray
                .map(|g| format!("{g:.3}"))
                .unwrap_or_default()
        )?;
    }
    Ok(())
}

/// Writes `precompute.csv`: each map's precomputations.
pub fn write_precompute(w: &mut dyn Write, precompute: &[(String, Precompute)]) -> Result<()> {
    writeln!(w, "map,precomputation,seconds,bytes")?;
    for (map, p) in precompute {
        writeln!(w, "{map},{},{:.4},{}", p.name, p.seconds, p.bytes)?;
    }
    Ok(())
}

/// Writes `equal_error.csv`: per map, elevation and technique the cheapest
/// budget within the error bound ([`equal_error`]), empty where none is.
pub fn write_equal_error(w: &mut dyn Write, rows: &[Row]) -> Result<()> {
    writeln!(
        w,
        "map,elevation_deg,technique,budget,fetches_per_ray,ns_per_ray"
    )?;
    for (r, cheapest) in equal_error(rows) {
        match cheapest {
            Some(c) => writeln!(
                w,
                "{},{},{},{},{:.3},{:.1}",
                r.map,
                r.elevation,
                r.technique.name(),
                c.budget,
                c.fetches,
                c.ns_per_ray
            )?,
            None => writeln!(w, "{},{},{},,,", r.map, r.elevation, r.technique.name())?,
        }
    }
    Ok(())
}
