//! The real scheduler: `scripts/slurm-local.sh` starts a throwaway one-node
//! Slurm (slurmctld, slurmd, munged in a temporary directory), renders a
//! scene as an 8-task array job of `deploy/slurm/render.sbatch` plus its
//! dependent merge job, and stops every daemon; the merged PNG and EXR
//! equal the single render byte for byte.
//!
//! Slurm and munge come from `scripts/install-deps.sh`. Without them (or
//! without root) the test fails, in CI always; elsewhere
//! `DISPLACE_ALLOW_NO_SLURM=1` lets it pass without running, knowingly.

mod cli_common;

use cli_common::{floor_scene, ok, small_bake, stderr};
use std::path::Path;
use std::process::Command;

/// Why Slurm cannot run here, if it cannot.
fn missing() -> Option<String> {
    for tool in ["munged", "slurmctld", "slurmd", "sbatch"] {
        let found = std::env::var_os("PATH")
            .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
            || Path::new("/usr/sbin").join(tool).is_file();
        if !found {
            return Some(format!("{tool} is not installed"));
        }
    }
    let uid = Command::new("id").arg("-u").output().ok()?;
    (String::from_utf8_lossy(&uid.stdout).trim() != "0")
        .then(|| "slurm-local.sh runs the daemons as root".to_string())
}

#[test]
fn an_eight_task_slurm_array_merges_to_the_single_render() {
    if let Some(why) = missing() {
        let allowed = std::env::var("DISPLACE_ALLOW_NO_SLURM").is_ok_and(|v| v == "1");
        if std::env::var_os("CI").is_some() || !allowed {
            panic!("Slurm test: {why}; run scripts/install-deps.sh as root, or set DISPLACE_ALLOW_NO_SLURM=1 outside CI to skip knowingly");
        }
        eprintln!("!!!!!!!! SLURM TEST NOT RUN: {why}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 8 rows of render tiles, one per task.
    std::fs::write(
        d.join("s.toml"),
        floor_scene(24, 128, 3, &small_bake("gen:gaussian")),
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_displace");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    for single in ["one.png", "one.exr"] {
        ok(Command::new(bin)
            .args(["render", "-q", "s.toml", "-o", single])
            .current_dir(d)
            .env("DISPLACE_CACHE", d.join("cache"))
            .output()
            .unwrap());
    }

    let o = Command::new("bash")
        .arg(root.join("scripts/slurm-local.sh"))
        .args(["s.toml", "8", "farm"])
        .current_dir(d)
        .env("DISPLACE", bin)
        .env("DISPLACE_CACHE", d.join("farm-cache"))
        .env("SLURM_LOCAL_TIMEOUT", "600")
        .output()
        .unwrap();
    let log = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    assert!(o.status.success(), "slurm-local.sh failed:\n{log}");
    assert!(log.contains("8 tasks"), "{log}");
    for (merged, single) in [("farm/image.png", "one.png"), ("farm/image.exr", "one.exr")] {
        assert!(
            std::fs::read(d.join(merged)).unwrap() == std::fs::read(d.join(single)).unwrap(),
            "{merged} differs from {single}"
        );
    }
    for i in 0..8 {
        assert!(d.join(format!("farm/tile_{i}.exr")).is_file(), "tile {i}");
    }
}
