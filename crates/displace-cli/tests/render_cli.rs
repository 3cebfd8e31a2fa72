//! `displace render` end to end: a tiny default render, AOVs, and bad input
//! giving a clear message, a non-zero exit and no output file.

mod cli_common;

use cli_common::{ok, stderr, words, SPHERE_SCENE};
use std::path::Path;
use std::process::{Command, Output};

fn displace(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_displace"))
        .args(args)
        .current_dir(dir)
        .env("DISPLACE_CACHE", dir.join("cache"))
        .output()
        .expect("run displace")
}

#[test]
fn default_scene_renders_with_aovs() {
    let dir = tempfile::tempdir().unwrap();
    let o = displace(
        &[
            "render",
            "-q",
            "--size",
            "24x16",
            "--spp",
            "1",
            "--aov",
            "depth,normal",
            "-o",
            "a.png",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(dir.path().join("a.png")).unwrap();
    assert_eq!((img.width(), img.height()), (24, 16));
    for f in ["a.depth.npy", "a.depth.png", "a.normal.npy", "a.normal.png"] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    // (H, W, C) float32.
    let npy = std::fs::read(dir.path().join("a.normal.npy")).unwrap();
    let header = String::from_utf8_lossy(&npy[..128]);
    assert!(
        header.contains("'<f4'") && header.contains("(16, 24, 3)"),
        "{header}"
    );
    // The second run reads the bake from the cache.
    let o = displace(
        &["render", "-q", "--size", "8x8", "--spp", "1", "-o", "b.exr"],
        dir.path(),
    );
    assert!(
        o.status.success() && stderr(&o).contains("1 from cache"),
        "{}",
        stderr(&o)
    );
    assert!(dir.path().join("b.exr").exists());
}

fn refuses(scene: &str, args: &[&str], expect: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), scene).unwrap();
    let mut all = vec!["render", "-q", "s.toml", "-o", "out.png"];
    all.extend_from_slice(args);
    let o = displace(&all, dir.path());
    let err = stderr(&o);
    assert!(!o.status.success(), "accepted: {err}");
    for e in expect {
        assert!(err.contains(e), "`{e}` not in: {err}");
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "s.toml" && n != "cache")
        .collect();
    assert!(left.is_empty(), "files left behind: {left:?}");
}

const GOOD: &str = SPHERE_SCENE;

#[test]
fn bad_input_is_refused_with_nothing_written() {
    // An edit of the scene (what, by what), the arguments, and what the
    // refusal must say.
    let grey = "color = [0.5, 0.5, 0.5]";
    let with = |key: &str| format!("{grey}\n{key}");
    let image = |key: &str| format!("spp = 1\n{key}");
    #[rustfmt::skip]
    let cases: &[(&str, &str, &[&str], &[&str])] = &[
        ("spp = 1", "spp = 1 2", &[], &["s.toml:5:"]),
        ("radius = 1", "radius = 1\nradius2 = 1", &[], &["s.toml:", "radius2"]),
        ("look_at = [0, 0, 0]", "look_at = [0, 1, -3]", &[], &["looks nowhere"]),
        ("width = 8", "width = 0", &[], &["image.width"]),
        ("spp = 1", "spp = -3", &[], &["image.spp", "-3"]),
        ("center = [0, 0, 0]", "center = [0, nan, 0]", &[], &["center", "finite"]),
        (grey, &with("texture = \"missing/wood.png\""), &[], &["missing/wood.png"]),
        ("", "", &["--size", "0x4"], &["--size"]),
        ("", "", &["--crop", "4,4,10,10"], &["crop"]),
        ("", "", &["--aov", "depth,colour"], &["colour"]),
        ("", "", &["--integrator", "bogus"],
            &["--integrator", "unknown integrator `bogus` (known: whitted, path)"]),
        ("spp = 1", &image("integrator = \"bogus\""), &[], &["s.toml", "image.integrator", "bogus"]),
        ("", "", &["--sampler", "halton"],
            &["--sampler", "unknown sampler `halton` (known: independent, sobol)"]),
        ("spp = 1", &image("sampler = \"halton\""), &[], &["s.toml", "image.sampler", "halton"]),
        ("spp = 1", &image("environment = \"sky.exr\""), &[],
            &["s.toml", "image.environment", "sky.exr"]),
        (grey, &with("emission = [1, nan, 1]"), &[], &["materials.m.emission", "finite"]),
    ];
    for &(from, to, args, expect) in cases {
        let scene = GOOD.replace(from, to);
        assert!(
            from.is_empty() || scene != GOOD,
            "{expect:?}: the edit changes nothing"
        );
        refuses(&scene, args, expect);
    }
    let dir = tempfile::tempdir().unwrap();
    let o = displace(&["render", "-q", "-o", "out.jpg"], dir.path());
    assert!(
        !o.status.success() && stderr(&o).contains("out.jpg"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("out.jpg").exists());
    let dir = tempfile::tempdir().unwrap();
    let o = displace(&["render", "-q", "nope.toml"], dir.path());
    assert!(!o.status.success() && stderr(&o).contains("nope.toml"));
}

/// `--integrator path` renders the scene with the path tracer (and says
/// so), `--integrator whitted` as before.
#[test]
fn integrator_flag_chooses_the_path_tracer() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), GOOD).unwrap();
    for name in ["path", "whitted"] {
        let out = format!("{name}.png");
        let render = format!("render -q s.toml --integrator {name} --spp 2 -o {out}");
        let o = ok(displace(&words(&render), dir.path()));
        assert!(
            stderr(&o).contains(&format!("at 2 spp ({name})")),
            "{}",
            stderr(&o)
        );
        assert!(dir.path().join(&out).exists());
    }
}

/// Ctrl-C stops the render cleanly: non-zero exit, nothing written.
#[cfg(unix)]
#[test]
fn interrupt_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_displace"))
        .args([
            "render",
            "-q",
            "--size",
            "1500x1500",
            "--spp",
            "64",
            "-o",
            "big.png",
        ])
        .current_dir(dir.path())
        .env("DISPLACE_CACHE", dir.path().join("cache"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("interrupted"), "{}", stderr(&o));
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "cache")
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
