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

use cli_common::stderr;
use std::path::Path;
use std::process::Command;

/// A displaced floor under an area light, 24 x 128 pixels: 8 rows of
/// render tiles, one per task.
const SCENE: &str = r#"
[image]
width = 24
height = 128
spp = 2
shadow_samples = 2
seed = 3
[camera]
position = [0, 1.6, -2.2]
look_at = [0, 0, 0]
vfov = 55
[materials.floor]
type = "lambert"
color = [0.7, 0.6, 0.5]
[[lights]]
type = "area"
origin = [-0.3, 2, -0.3]
edge_u = [0.6, 0, 0]
edge_v = [0, 0, 0.6]
radiance = [6, 6, 6]
[[shapes]]
type = "quad"
origin = [-1, 0, -1]
edge_u = [2, 0, 0]
edge_v = [0, 0, 2]
material = "floor"
displacement = { height = "gen:gaussian", height_size = [32, 32], depth = 0.1, map_size = [32, 32, 8] }
"#;

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
    std::fs::write(d.join("s.toml"), SCENE).unwrap();
    let bin = env!("CARGO_BIN_EXE_displace");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let one = Command::new(bin)
        .args(["render", "-q", "s.toml", "-o", "one.png"])
        .current_dir(d)
        .env("DISPLACE_CACHE", d.join("cache"))
        .output()
        .unwrap();
    assert!(one.status.success(), "{}", stderr(&one));
    let exr = Command::new(bin)
        .args(["render", "-q", "s.toml", "-o", "one.exr"])
        .current_dir(d)
        .env("DISPLACE_CACHE", d.join("cache"))
        .output()
        .unwrap();
    assert!(exr.status.success(), "{}", stderr(&exr));

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
