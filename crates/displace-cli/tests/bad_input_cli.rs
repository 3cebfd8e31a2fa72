//! Adversarial input end to end (docs/reliability.md): inputs that are not regular files, counts and sizes
//! that would run for ever or exhaust memory, outputs that would collide or
//! be left half done, and messages that misreport. Each case must exit
//! non-zero, name the problem, not panic and leave nothing behind.

mod cli_common;

use cli_common::{files, stderr, SPHERE_SCENE};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn cmd(dir: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_displace"));
    c.current_dir(dir).env("DISPLACE_CACHE", "");
    c
}

fn run(args: &[&str], dir: &Path) -> Output {
    cmd(dir).args(args).output().expect("run displace")
}

/// `o` failed without a panic, its message holding every needle and none
/// of the `absent` ones.
fn failed(o: &Output, needles: &[&str], absent: &[&str]) -> String {
    let msg = stderr(o);
    assert!(!o.status.success(), "succeeded: {msg}");
    assert!(!msg.contains("panicked"), "{msg}");
    for n in needles {
        assert!(msg.contains(n), "`{n}` not in: {msg}");
    }
    for a in absent {
        assert!(!msg.contains(a), "`{a}` in: {msg}");
    }
    msg
}

/// Runs `args` in `dir`, which must fail as [`failed`] says and leave the
/// directory as it was.
fn refuses(dir: &Path, args: &[&str], needles: &[&str], absent: &[&str]) -> String {
    let before = files(dir);
    let msg = failed(&run(args, dir), needles, absent);
    assert_eq!(files(dir), before, "{args:?} left files: {msg}");
    msg
}

const SCENE: &str = SPHERE_SCENE;

fn mkfifo(path: &Path) {
    let ok = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(ok.success());
}

/// A directory, a FIFO and `/dev/zero` as every kind of input: refused at
/// once (a read would block or never end), naming the path and the kind.
#[test]
fn inputs_that_are_not_regular_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("adir.toml")).unwrap();
    mkfifo(&d.join("fifo.toml"));
    std::fs::create_dir(d.join("adir.png")).unwrap();
    mkfifo(&d.join("fifo.npy"));
    let mesh = |p: &str| {
        SCENE.replace(
            "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
            &format!("type = \"mesh\"\npath = \"{p}\""),
        )
    };
    std::fs::write(d.join("zero_mesh.toml"), mesh("/dev/zero")).unwrap();
    std::fs::write(d.join("fifo_mesh.toml"), mesh("fifo.npy")).unwrap();
    std::fs::write(
        d.join("dir_texture.toml"),
        SCENE.replace(
            "color = [0.5, 0.5, 0.5]",
            "color = [0.5, 0.5, 0.5]\ntexture = \"adir.png\"",
        ),
    )
    .unwrap();
    let start = Instant::now();
    let trace = |rays: &'static str| {
        vec![
            "trace", "--height", "gen:flat", "--extent", "1,1,0.1", "--rays", rays, "-o", "h.npy",
        ]
    };
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["render", "-q", "adir.toml"],
            vec!["adir.toml", "directory"],
        ),
        (vec!["render", "-q", "fifo.toml"], vec!["fifo.toml", "FIFO"]),
        (
            vec!["render", "-q", "/dev/zero"],
            vec!["/dev/zero", "device"],
        ),
        (
            vec!["render", "-q", "zero_mesh.toml"],
            vec!["/dev/zero", "mesh"],
        ),
        (
            vec!["render", "-q", "fifo_mesh.toml"],
            vec!["fifo.npy", "FIFO"],
        ),
        (
            vec!["render", "-q", "dir_texture.toml"],
            vec!["materials.m.texture", "adir.png", "directory"],
        ),
        (
            vec!["bake", "adir.png", "-o", "m.npy"],
            vec!["adir.png", "directory"],
        ),
        (trace("fifo.npy"), vec!["fifo.npy", "FIFO"]),
        (trace("/dev/zero"), vec!["/dev/zero", "device"]),
    ];
    for (args, needles) in cases {
        refuses(d, &args, &needles, &[]);
    }
    assert!(start.elapsed() < Duration::from_secs(60));
}

/// Counts that would run for years or exhaust the machine are refused
/// before any work, each naming its key and bound.
#[test]
fn runaway_counts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = |from: &str, to: &str| {
        assert!(SCENE.contains(from), "{from}");
        std::fs::write(d.join("s.toml"), SCENE.replace(from, to)).unwrap();
    };
    scene("spp = 1", "spp = 4000000000");
    refuses(d, &["render", "-q", "s.toml"], &["image.spp", "65536"], &[]);
    scene("spp = 1", "spp = 1\nshadow_samples = 4000000000");
    refuses(
        d,
        &["render", "-q", "s.toml"],
        &["image.shadow_samples"],
        &[],
    );
    scene("spp = 1", "spp = 1\nmax_depth = 5000");
    refuses(
        d,
        &["render", "-q", "s.toml"],
        &["image.max_depth", "64"],
        &[],
    );
    scene("width = 8\nheight = 8", "width = 16384\nheight = 16384");
    refuses(
        d,
        &["render", "-q", "s.toml", "--spp", "65536"],
        &["camera samples"],
        &[],
    );
    scene("spp = 1", "spp = 1");
    refuses(
        d,
        &["render", "-q", "s.toml", "--threads", "100000"],
        &["--threads", "1024"],
        &[],
    );
    // Refused before the rays are read (there are none here) or a map baked
    // (at 4096^2 x 64 voxels a bake would take minutes).
    let start = Instant::now();
    let trace = [
        "trace",
        "--height",
        "gen:flat",
        "--extent",
        "1,1,0.1",
        "--size",
        "4096x4096x64",
        "--rays",
        "missing.npy",
        "--method",
        "sphere-fixed",
        "-o",
        "h.npy",
        "--iterations",
    ];
    for (n, extra, bound) in [
        ("0", None, "65536"),
        ("4000000000", None, "65536"),
        ("17000", Some("--backend=gpu"), "4096"),
    ] {
        let mut args = trace.to_vec();
        args.push(n);
        args.extend(extra);
        refuses(d, &args, &["--iterations", bound], &["missing.npy"]);
    }
    assert!(start.elapsed() < Duration::from_secs(20));
}

/// `s.toml` in `dir`: the scene with its sphere replaced by a displaced
/// quad, `keys` added to the displacement.
fn write_displaced(dir: &Path, keys: &str) {
    let quad = format!(
        "type = \"quad\"\norigin = [-1, -1, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 2, 0]\n\
         displacement = {{ height = \"gen:gaussian\", depth = 0.1, {keys} }}"
    );
    let text = SCENE.replace("type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1", &quad);
    std::fs::write(dir.join("s.toml"), text).unwrap();
}

fn write_rays(path: &Path, rays: &[[f32; 6]]) {
    let flat: Vec<f32> = rays.iter().flatten().copied().collect();
    displace_core::io::npy::write_file(path, &[rays.len(), 6], &flat).unwrap();
}

/// The whole peak of a bake is estimated and refused past the memory
/// limit, with the estimate in the message, before anything is loaded;
/// `DISPLACE_MEMORY_LIMIT` allows more.
#[test]
fn bakes_past_the_memory_limit_are_refused_with_their_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let refused = |limit: &str, args: &[&str]| {
        let before = files(d);
        let o = cmd(d)
            .args(args)
            .env("DISPLACE_MEMORY_LIMIT", limit)
            .output()
            .unwrap();
        let msg = failed(&o, &["needs about", "DISPLACE_MEMORY_LIMIT"], &[]);
        assert_eq!(files(d), before, "{msg}");
        msg
    };
    // The case: every buffer passes the 8 GiB check; the whole
    // needs about 50 GB. Refused at once, nothing allocated.
    let start = Instant::now();
    let msg = refused(
        "16G",
        &[
            "bake",
            "gen:flat",
            "--height-size",
            "46000x46000",
            "--size",
            "32x32x8",
            "-o",
            "m.npy",
        ],
    );
    assert!(msg.contains("46000x46000"), "{msg}");
    assert!(start.elapsed() < Duration::from_secs(10));
    // `export-mesh` holds the heights and their normals (16 bytes a texel,
    // 34 GB here): refused as fast, before the generator runs.
    let start = Instant::now();
    let msg = refused(
        "16G",
        &[
            "export-mesh",
            "gen:flat",
            "--height-size",
            "46000x46000",
            "--extent",
            "1,1,0.1",
            "-o",
            "m.ply",
        ],
    );
    assert!(msg.contains("export-mesh of a 46000x46000"), "{msg}");
    assert!(start.elapsed() < Duration::from_secs(10));
    // A small bake under a smaller limit; then allowed.
    let small = ["bake", "gen:gaussian", "--size", "64x64x8", "-o", "m.npy"];
    refused("100K", &small);
    let o = cmd(d)
        .args(small)
        .env("DISPLACE_MEMORY_LIMIT", "1G")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files(d), ["m.npy"]);
    // A scene's bake counts too, and names the displacement.
    write_displaced(d, "height_size = [40000, 40000]");
    let msg = refused("8G", &["render", "-q", "s.toml"]);
    assert!(msg.contains("shapes[0].displacement"), "{msg}");
    // Nonsense in the variable is named.
    let o = cmd(d)
        .args(small)
        .env("DISPLACE_MEMORY_LIMIT", "lots")
        .output()
        .unwrap();
    failed(&o, &["DISPLACE_MEMORY_LIMIT=lots"], &[]);
}

/// Outputs of one command are checked before the work and land together:
/// no output replaces another, and a failing one leaves none behind.
#[test]
fn outputs_are_checked_first_and_committed_together() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("d")).unwrap();
    refuses(
        d,
        &[
            "bake", "--size", "16x16x4", "-o", "m.npy", "--cone", "m.npy",
        ],
        &["same file", "m.npy"],
        &[],
    );
    refuses(
        d,
        &[
            "bake",
            "--size",
            "16x16x4",
            "-o",
            "d/m.ktx2",
            "--normals",
            "d/missing/n.png",
        ],
        &["d/missing"],
        &[],
    );
    // A render into a missing directory fails before rendering: at 65536
    // spp the render itself would take minutes.
    std::fs::write(d.join("s.toml"), SCENE).unwrap();
    let start = Instant::now();
    refuses(
        d,
        &["render", "-q", "s.toml", "--spp", "65536", "-o", "no/r.png"],
        &["no/r.png", "does not exist"],
        &[],
    );
    assert!(start.elapsed() < Duration::from_secs(20));
    // A valid 250-byte name: its temporary must not be too long.
    let long = format!("{}.npy", "m".repeat(246));
    let o = run(&["bake", "--size", "16x16x4", "-o", &long], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(files(d).contains(&long));
}

/// `gpu-render` refuses what it cannot write or trace before touching the
/// GPU, so these run on machines without one.
#[test]
fn gpu_render_refuses_before_any_gpu_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    refuses(d, &["gpu-render", "-o", "out.jpg"], &["out.jpg"], &[]);
    refuses(
        d,
        &["gpu-render", "-o", "no/out.png"],
        &["does not exist"],
        &[],
    );
    for n in ["0", "17000"] {
        refuses(
            d,
            &["gpu-render", "--iterations", n, "-o", "out.png"],
            &["--iterations", "4096"],
            &[],
        );
    }
}

/// Messages say each thing once and name the right problem.
#[test]
fn messages_name_the_problem_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let msg = refuses(
        d,
        &["bake", "missing.png", "-o", "m.npy"],
        &["missing.png"],
        &[],
    );
    assert_eq!(msg.matches("No such file").count(), 1, "{msg}");
    std::fs::write(
        d.join("s.toml"),
        SCENE.replace(
            "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
            "type = \"mesh\"\npath = \"gone.obj\"",
        ),
    )
    .unwrap();
    let msg = refuses(d, &["render", "-q", "s.toml"], &["gone.obj"], &[]);
    assert_eq!(msg.matches("No such file").count(), 1, "{msg}");
    refuses(
        d,
        &["bake", "--format", "bogus", "-o", "m.ktx2"],
        &["bogus"],
        &["invalid size"],
    );
    write_displaced(d, "address = \"mirror\"");
    refuses(
        d,
        &["render", "-q", "s.toml"],
        &["address", "mirror"],
        &["invalid size"],
    );
    // Invalid UTF-8 on line 3: the line and column.
    let mut bytes = b"[image]\nwidth = 8\nheight = \xff8\n".to_vec();
    bytes.extend_from_slice(&SCENE.as_bytes()[SCENE.find("spp").unwrap()..]);
    std::fs::write(d.join("s.toml"), bytes).unwrap();
    refuses(
        d,
        &["render", "-q", "s.toml"],
        &["s.toml:3:10:", "UTF-8"],
        &[],
    );
    // A camera too far out is out of range, not "looking nowhere".
    std::fs::write(
        d.join("s.toml"),
        SCENE.replace("position = [0, 1, -3]", "position = [0, 0, -3e38]"),
    )
    .unwrap();
    refuses(
        d,
        &["render", "-q", "s.toml"],
        &["camera.position", "1e18"],
        &["looks nowhere"],
    );
    // A direction too long to measure is out of range, not "no length".
    write_rays(&d.join("rays.npy"), &[[0.5, 0.5, 0.2, 1e30, 0.0, -1.0]]);
    let trace = |out: &str| {
        [
            "trace", "--height", "gen:flat", "--extent", "1,1,0.1", "--size", "8x8x4", "--rays",
            "rays.npy", "-o",
        ]
        .into_iter()
        .chain([out])
        .map(str::to_string)
        .collect::<Vec<_>>()
    };
    let args = trace("h.npy");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    refuses(d, &args, &["ray 0", "1e18"], &["no length"]);
    // trace writes .npy only, and says only that.
    let args = trace("h.txt");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    refuses(d, &args, &["h.txt", ".npy"], &[".ktx2", ".dds"]);
}

/// Sends `signal` (`-TERM`, `-HUP`) to `child`.
fn send(signal: &str, child: &std::process::Child) {
    let kill = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
}

/// SIGTERM and SIGHUP stop a render as Ctrl-C does: a message, a non-zero
/// exit, nothing written.
#[test]
fn termination_signals_stop_cleanly() {
    for signal in ["-TERM", "-HUP"] {
        let dir = tempfile::tempdir().unwrap();
        let child = cmd(dir.path())
            .args(["render", "-q", "--size", "1500x1500", "--spp", "64"])
            .args(["-o", "big.png"])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(1500));
        send(signal, &child);
        let o = child.wait_with_output().unwrap();
        failed(&o, &["interrupted"], &[]);
        assert!(files(dir.path()).is_empty(), "{signal}");
    }
}

/// A bake interrupted while it streams its map leaves neither the map nor
/// its temporary file, and a bake whose directory does not exist fails
/// before any work.
#[test]
fn an_interrupted_bake_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let child = cmd(dir.path())
        .args(["bake", "gen:noise", "--height-size", "1024x1024"])
        .args([
            "--size",
            "2048x2048x128",
            "--extent",
            "1,1,0.03",
            "-o",
            "big.ktx2",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    send("-TERM", &child);
    let o = child.wait_with_output().unwrap();
    failed(&o, &["interrupted"], &[]);
    assert!(files(dir.path()).is_empty(), "{:?}", files(dir.path()));
    let start = Instant::now();
    let o = run(
        &["bake", "--size", "2048x2048x128", "-o", "no/such/m.ktx2"],
        dir.path(),
    );
    failed(&o, &["no/such", "does not exist"], &[]);
    assert!(start.elapsed() < Duration::from_secs(2));
}
