//! `displace bench bake`: throughput of the bake next to the `edt` and
//! `scipy` distance transforms on the same occupancy volume in the same run
//! (BENCHMARKS.md). A measurement, not a test.
//!
//! The ratio that matters is against `edt.sdf`: a signed distance on both
//! sides of the surface, which is what a distance map stores. `edt.edt` and
//! scipy compute one side only (distances inside the volume, zeros outside)
//! and are printed beside it for what one such pass costs.

use crate::args::parse_extent;
use crate::threads::pool;
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::texel_centre;
use displace_core::distance_map::Format;
use displace_core::io::npy;
use displace_core::io::stream::MapStream;
use displace_core::{generators, Address, BakeOptions, Extent, HeightMap};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchBakeArgs {
    /// Small sizes only (a quick check, not the published numbers)
    #[arg(long)]
    pub quick: bool,
    /// Threads for our bake [default: all cores]
    #[arg(long)]
    pub threads: Option<usize>,
    /// Threads for `edt` (its `parallel` argument)
    #[arg(long, default_value_t = 2)]
    pub peer_threads: usize,
    /// Skip the Python peers
    #[arg(long)]
    pub no_peers: bool,
    /// The peer script [default: scripts/bench_edt_peers.py of this repository]
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Python interpreter for the peer script
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Physical extent of the face
    #[arg(long, default_value = "1,1,0.1", value_parser = parse_extent)]
    pub extent: Extent,
    /// Only these sizes, WxHxD[,WxHxD...] (e.g. 4096x4096x64) [default: the
    /// published set, or --quick's]
    #[arg(long, value_delimiter = ',', value_parser = parse_bench_size)]
    pub sizes: Vec<[usize; 3]>,
    /// Only these generators [default: studded, gaussian, noise]
    #[arg(long, value_delimiter = ',', value_parser = parse_generator)]
    pub heights: Vec<String>,
}

fn parse_bench_size(s: &str) -> Result<[usize; 3], String> {
    crate::args::parse_map_size(s).map_err(|e| format!("{e:#}"))
}

fn parse_generator(s: &str) -> Result<String, String> {
    if BAKE_GENERATORS.contains(&s) {
        Ok(s.to_string())
    } else {
        Err(format!(
            "`{s}`: expected one of {}",
            BAKE_GENERATORS.join(", ")
        ))
    }
}

const BAKE_GENERATORS: [&str; 3] = ["studded", "gaussian", "noise"];

pub fn height_for(name: &str, w: usize, h: usize) -> Result<HeightMap> {
    generators::generate(&format!("gen:{name}"), w, h, Address::Clamp)
        .with_context(|| format!("generating gen:{name}"))
}

/// The binary volume the peers transform: voxel `(i, j, k)` is 1 when its
/// centre lies below the surface at its column centre, the same sign test the
/// bake uses. Layout `(D, H, W)`, as our npy maps.
fn occupancy(height: &HeightMap, size: [usize; 3]) -> Vec<u8> {
    use rayon::prelude::*;
    let [w, h, d] = size;
    let column: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|c| height.sample(texel_centre(c % w, w), texel_centre(c / w, h)))
        .collect();
    let mut out = vec![0u8; w * h * d];
    out.par_chunks_mut((w * h).max(1))
        .enumerate()
        .for_each(|(k, slice)| {
            let z = texel_centre(k, d);
            for (o, &hc) in slice.iter_mut().zip(&column) {
                *o = u8::from(z < hc);
            }
        });
    out
}

fn default_script() -> PathBuf {
    let local = Path::new("scripts/bench_edt_peers.py");
    if local.is_file() {
        return local.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/bench_edt_peers.py")
}

/// What the peer script reported for one volume.
#[derive(Default, Debug)]
struct PeerTimes {
    sdf: Option<f64>,
    edt: Option<f64>,
    scipy: Option<f64>,
    missing: Vec<String>,
}

/// Pulls `"key": number` out of the script's one-line JSON object.
fn json_number(line: &str, key: &str) -> Option<f64> {
    let at = line.find(&format!("\"{key}\""))? + key.len() + 2;
    let rest = line[at..].trim_start().strip_prefix(':')?.trim_start();
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    rest[..end].trim().parse().ok()
}

fn json_missing(line: &str) -> Vec<String> {
    let Some(at) = line.find("\"missing\"") else {
        return Vec::new();
    };
    let rest = &line[at..];
    let (Some(a), Some(b)) = (rest.find('['), rest.find(']')) else {
        return Vec::new();
    };
    rest[a + 1..b]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

fn run_peers(
    args: &BenchBakeArgs,
    script: &Path,
    volume: &Path,
    spacing: [f32; 3],
) -> Result<PeerTimes> {
    let out = Command::new(&args.python)
        .arg(script)
        .arg(volume)
        .arg("--spacing")
        .arg(format!("{},{},{}", spacing[0], spacing[1], spacing[2]))
        .arg("--parallel")
        .arg(args.peer_threads.to_string())
        .output()
        .with_context(|| format!("running {} {}", args.python, script.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let Some(line) = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
    else {
        bail!(
            "{} printed no result (exit {}): {}",
            script.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    };
    Ok(PeerTimes {
        sdf: json_number(line, "edt_sdf_seconds"),
        edt: json_number(line, "edt_seconds"),
        scipy: json_number(line, "scipy_seconds"),
        missing: json_missing(line),
    })
}

/// Seconds of what `displace bake gen:NAME -o m.ktx2 --format F` does:
/// generate the height map, bake it streamed, encode and write the file
/// (fsync and rename included). The best of 3 to 10 runs, more while under
/// 2 s in all: the rule of the in-memory bake and of the peers. Each run
/// writes a new file, as a first bake does: the previous run's is removed
/// before the clock starts (replacing a file would time the file system
/// freeing the old one's blocks inside the rename, 4 ms for 16 MB here).
fn whole_command(
    pool: &rayon::ThreadPool,
    name: &str,
    opts: &BakeOptions,
    dir: &Path,
    format: Format,
) -> Result<f64> {
    let path = dir.join("m.ktx2");
    let mut best = f64::INFINITY;
    let mut total = 0.0;
    for run in 0..10 {
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("removing {}", path.display()))
            }
            _ => {}
        }
        let t = Instant::now();
        pool.install(|| -> Result<()> {
            let height = height_for(name, opts.size[0], opts.size[1])?;
            let mut stream = MapStream::create(&path, format, opts.size, opts.extent)?;
            let slab = rayon::current_num_threads();
            displace_core::bake_streamed(&height, opts, slab, &mut stream)?;
            stream.finish()?;
            Ok(())
        })
        .context("baking to a file")?;
        let s = t.elapsed().as_secs_f64();
        best = best.min(s);
        total += s;
        if run >= 2 && total > 2.0 {
            break;
        }
    }
    Ok(best)
}

pub fn run(args: BenchBakeArgs) -> Result<()> {
    let pool = pool(args.threads)?;
    let sizes: &[[usize; 3]] = if !args.sizes.is_empty() {
        &args.sizes
    } else if args.quick {
        &[[128, 128, 16], [256, 256, 16]]
    } else {
        &[
            [256, 256, 16],
            [512, 512, 64],
            [1024, 1024, 64],
            [2048, 2048, 64],
        ]
    };
    let script = args.script.clone().unwrap_or_else(default_script);
    let mut peers_ok = !args.no_peers;
    if peers_ok && !script.is_file() {
        eprintln!(
            "peer script {} not found: printing our numbers only",
            script.display()
        );
        peers_ok = false;
    }
    let tmp = tempfile::tempdir().context("creating a temporary directory")?;
    let extent = args.extent;
    let [ax, ay] = extent.aspect();
    println!(
        "bake: extent {},{},{}, {} threads (ours), edt parallel={}; Mvoxels/s, best of 3-10 runs (more while under 2 s)",
        extent.sx,
        extent.sy,
        extent.sz,
        pool.current_num_threads(),
        args.peer_threads
    );
    println!(
        "envelope kernel: {}; edt.sdf: signed, both sides (as our map); edt.edt and scipy: one side only",
        if displace_core::edt::wide_kernel() {
            "AVX-512, 16 lines at a time"
        } else if displace_core::edt::vector_kernel() {
            "AVX2, 8 lines at a time"
        } else {
            "scalar (no AVX2 on this CPU)"
        }
    );
    println!(
        "ours: the bake in memory; whole: what `displace bake gen:NAME -o m.ktx2` does \
         (generate, bake streamed, encode r8, write a new file); r32f: the same with --format r32f"
    );
    println!(
        "{:<14} {:<9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>12} {:>12} {:>13} {:>12} {:>11}",
        "size",
        "height",
        "ours",
        "whole",
        "r32f",
        "edt.sdf",
        "edt.edt",
        "scipy",
        "ours/edt.sdf",
        "ours/edt.edt",
        "whole/edt.edt",
        "r32f/edt.sdf",
        "ours/scipy"
    );
    let mut warned = false;
    for &size in sizes {
        let voxels = (size[0] * size[1] * size[2]) as f64;
        let names: Vec<&str> = if args.heights.is_empty() {
            BAKE_GENERATORS.to_vec()
        } else {
            args.heights.iter().map(String::as_str).collect()
        };
        for name in names {
            let height = height_for(name, size[0], size[1])?;
            let opts = BakeOptions::new(size, extent);
            let mut best = f64::INFINITY;
            let mut total = 0.0;
            // The same rule as the peer script: the best of 3 to 10 runs,
            // no more once 2 s are spent (small volumes need several runs
            // to get past page faults and thread start-up).
            for run in 0..10 {
                let t = Instant::now();
                let map = pool
                    .install(|| displace_core::bake(&height, &opts))
                    .context("baking")?;
                let s = t.elapsed().as_secs_f64();
                drop(map);
                best = best.min(s);
                total += s;
                if run >= 2 && total > 2.0 {
                    break;
                }
            }
            let ours = voxels / best / 1e6;
            let whole_in = |f| -> Result<f64> {
                Ok(voxels / whole_command(&pool, name, &opts, tmp.path(), f)? / 1e6)
            };
            let (whole, whole32) = (whole_in(Format::R8)?, whole_in(Format::R32F)?);
            let mut peers = PeerTimes::default();
            if peers_ok {
                let vol = tmp.path().join("occupancy.npy");
                npy::write_file(
                    &vol,
                    &[size[2], size[1], size[0]],
                    &occupancy(&height, size),
                )?;
                let spacing = [
                    1.0 / size[2] as f32,
                    ay / size[1] as f32,
                    ax / size[0] as f32,
                ];
                match run_peers(&args, &script, &vol, spacing) {
                    Ok(p) => peers = p,
                    Err(e) => {
                        eprintln!("peer benchmark failed, printing our numbers only: {e:#}");
                        peers_ok = false;
                    }
                }
                if !peers.missing.is_empty() && !warned {
                    eprintln!(
                        "python packages not importable: {}. Install them with\n    \
                         {} -m pip install numpy edt scipy\n\
                         (tested versions: scripts/requirements-bench.txt)",
                        peers.missing.join(", "),
                        args.python
                    );
                    warned = true;
                }
            }
            let rate = |s: Option<f64>| s.map(|s| voxels / s / 1e6);
            let (sdf, edt, scipy) = (rate(peers.sdf), rate(peers.edt), rate(peers.scipy));
            let show =
                |v: Option<f64>, prec: usize| v.map_or("-".to_string(), |v| format!("{v:.prec$}"));
            println!(
                "{:<14} {:<9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>12} {:>12} {:>13} {:>12} {:>11}",
                format!("{}x{}x{}", size[0], size[1], size[2]),
                name,
                format!("{ours:.1}"),
                format!("{whole:.1}"),
                format!("{whole32:.1}"),
                show(sdf, 1),
                show(edt, 1),
                show(scipy, 1),
                show(sdf.map(|e| ours / e), 2),
                show(edt.map(|e| ours / e), 2),
                show(edt.map(|e| whole / e), 2),
                show(sdf.map(|e| whole32 / e), 2),
                show(scipy.map(|s| ours / s), 2),
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_peer_json() {
        let line = r#"{"voxels": 1048576, "edt_sdf_seconds": 0.13, "edt_seconds": 0.0421, "scipy_seconds": 0.25, "missing": []}"#;
        assert_eq!(json_number(line, "edt_sdf_seconds"), Some(0.13));
        assert_eq!(json_number(line, "edt_seconds"), Some(0.0421));
        assert_eq!(json_number(line, "scipy_seconds"), Some(0.25));
        assert!(json_missing(line).is_empty());
        let line = r#"{"edt_seconds": null, "scipy_seconds": 1.5, "missing": ["edt"]}"#;
        assert_eq!(json_number(line, "edt_seconds"), None);
        assert_eq!(json_missing(line), vec!["edt".to_string()]);
    }

    #[test]
    fn occupancy_marks_voxels_below_the_surface() {
        let h = HeightMap::new(2, 2, vec![0.0, 1.0, 0.5, 0.3], Address::Clamp).unwrap();
        let occ = occupancy(&h, [2, 2, 4]);
        // Column (1, 0) is at full height: every voxel below; column (0, 0) none.
        for k in 0..4 {
            assert_eq!(occ[k * 4], 0);
            assert_eq!(occ[k * 4 + 1], 1);
        }
        // Column (0, 1) at 0.5: voxel centres 0.125 and 0.375 are below.
        assert_eq!(
            (0..4).map(|k| occ[k * 4 + 2]).collect::<Vec<_>>(),
            vec![1, 1, 0, 0]
        );
    }
}
