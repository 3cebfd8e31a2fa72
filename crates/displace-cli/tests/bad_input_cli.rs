//! Adversarial input end to end (docs/reliability.md): inputs that are not regular files, counts and sizes
//! that would run for ever or exhaust memory, outputs that would collide or
//! be left half done, and messages that misreport. Each case must exit
//! non-zero, name the problem, not panic and leave nothing behind.

mod cli_common;

use cli_common::{failed, files, replaced, stderr, words, SPHERE_SCENE};
use displace_testkit::elevation::{normalised, sampled, write_float_tiff};
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
        replaced(
            SCENE,
            "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
            &format!("type = \"mesh\"\npath = \"{p}\""),
        )
    };
    std::fs::write(d.join("zero_mesh.toml"), mesh("/dev/zero")).unwrap();
    std::fs::write(d.join("fifo_mesh.toml"), mesh("fifo.npy")).unwrap();
    std::fs::write(
        d.join("dir_texture.toml"),
        replaced(
            SCENE,
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
        std::fs::write(d.join("s.toml"), replaced(SCENE, from, to)).unwrap();
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
    let text = replaced(
        SCENE,
        "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
        &quad,
    );
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
    // Refused at once under a 16 GB limit, before anything is allocated or
    // generated: `command` (a command line, split at spaces) fails naming
    // `needle`.
    let refused_at_once = |command: &str, needle: &str| {
        let start = Instant::now();
        let msg = refused("16G", &words(command));
        assert!(msg.contains(needle), "{msg}");
        assert!(start.elapsed() < Duration::from_secs(10));
    };
    // Every buffer passes the 8 GiB check; the whole needs about 17 GB (the
    // heights and the image they are decoded from), refused under 12 GB.
    let start = Instant::now();
    let msg = refused(
        "12G",
        &words("bake gen:flat --height-size 46000x46000 --size 32x32x8 -o m.npy"),
    );
    assert!(msg.contains("46000x46000"), "{msg}");
    assert!(start.elapsed() < Duration::from_secs(10));
    // `export-mesh` holds the heights and their normals (16 bytes a texel,
    // 34 GB here).
    refused_at_once(
        "export-mesh gen:flat --height-size 46000x46000 --extent 1,1,0.1 -o m.ply",
        "export-mesh of a 46000x46000",
    );
    // `compare` holds every map's heights, the one in work with its
    // precomputations and bake (hundreds of GB here): refused as fast,
    // before the output directory is made.
    let compare = "compare --only-given --height gen:flat --out o";
    refused_at_once(
        &format!("{compare} --height-size 46000x46000"),
        "compare on 1 height maps (the largest 46000x46000)",
    );
    // So are rays by the billion (their hits are kept per elevation).
    let msg = refused(
        "16G",
        &words(&format!("{compare} --quick --rays 4000000000")),
    );
    assert!(msg.contains("4000000000 rays"), "{msg}");
    // A small bake under a smaller limit; then allowed.
    let small = ["bake", "gen:gaussian", "--size", "64x64x8", "-o", "m.npy"];
    refused("40K", &small);
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
    // An image too big on its own is named as the image, in a scene with
    // no bake at all as in one whose small bake comes after it.
    let big_image = |scene: &str| {
        replaced(
            scene,
            "width = 8\nheight = 8",
            "width = 16384\nheight = 16384",
        )
    };
    std::fs::write(d.join("s.toml"), big_image(SCENE)).unwrap();
    let msg = refused("1G", &["render", "-q", "s.toml"]);
    assert!(msg.contains("16384x16384 image"), "{msg}");
    write_displaced(d, "height_size = [8, 8], map_size = [8, 8, 2]");
    let small_bake = std::fs::read_to_string(d.join("s.toml")).unwrap();
    std::fs::write(d.join("s.toml"), big_image(&small_bake)).unwrap();
    let msg = refused("100M", &["render", "-q", "s.toml"]);
    assert!(
        msg.contains("16384x16384 image") && !msg.contains("shapes[0]"),
        "{msg}"
    );
    // Nonsense in the variable is named.
    let o = cmd(d)
        .args(small)
        .env("DISPLACE_MEMORY_LIMIT", "lots")
        .output()
        .unwrap();
    failed(&o, &["DISPLACE_MEMORY_LIMIT=lots"], &[]);
}

/// A small EXR whose header claims eight full-size channels of 20000x20000
/// texels (1.5 KB on disk, 14 GB decoded): refused from its header with
/// the decoder's bytes before anything is decoded, by `bake`, by
/// `gpu-render --height` (which had no estimate at all) and by a scene;
/// the same file at its real size decodes.
#[test]
fn exr_headers_claiming_huge_decodes_are_refused_before_decoding() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let channels: Vec<AnyChannel<FlatSamples>> = ["A", "B", "G", "R", "U", "V", "W", "Z"]
        .iter()
        .map(|n| AnyChannel::new(*n, FlatSamples::F32(vec![0.5; 64])))
        .collect();
    let layer = Layer::new(
        (8, 8),
        LayerAttributes::default(),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(channels.into()),
    );
    Image::from_layer(layer)
        .write()
        .to_file(d.join("small.exr"))
        .unwrap();
    let mut bytes = std::fs::read(d.join("small.exr")).unwrap();
    // dataWindow: box2i, 16 bytes: xmin ymin xmax ymax.
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    bytes[at + 8..at + 12].copy_from_slice(&19999i32.to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&19999i32.to_le_bytes());
    std::fs::write(d.join("huge.exr"), &bytes).unwrap();
    let before = files(d);
    let refused = |args: &[&str], needles: &[&str]| {
        let o = cmd(d)
            .args(args)
            .env("DISPLACE_MEMORY_LIMIT", "6G")
            .output()
            .unwrap();
        let msg = failed(&o, needles, &["memory allocation", "panicked"]);
        assert_eq!(files(d), before, "{msg}");
        msg
    };
    // `bake` streams: its estimate (3 GiB, the heights and one decoded
    // channel) passes a 6 GiB limit; the decoder's own check does not.
    let msg = refused(
        &words("bake huge.exr --size 16x16x4 -o m.npy"),
        &["needs about", "20000x20000"],
    );
    assert!(
        msg.contains("decoding") && msg.contains("8 channels"),
        "{msg}"
    );
    // The GPU's side limit (16384 on lavapipe) or the bake's estimate,
    // whichever comes first: before anything is decoded either way.
    refused(
        &words("gpu-render --height huge.exr --map-size 16x16x4 -o r.png"),
        &["20000x20000"],
    );
    let o = cmd(d)
        .args(words("bake small.exr --size 8x8x4 -o m.npy"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}

/// An 8x8 OpenEXR whose display window claims 4194312x8 texels (1.2 KB
/// on disk; the decoder fills the display window, 0.8 GB, as the seeded
/// fuzzer found): as a scene's texture or environment it is refused from
/// its header against the memory limit, before it is decoded, and no
/// output is written. At these limits the scene's estimate (the float copy
/// and the texels kept: 0.8 GB for a texture, 1.2 GB for an environment
/// map, which keeps its sampling tables too) passes; the decoder's own
/// samples on top of it do not.
#[test]
fn exr_display_windows_past_the_memory_limit_are_refused_as_textures() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pixels = SpecificChannels::rgb(|_: Vec2<usize>| (0.5f32, 0.5f32, 0.5f32));
    Image::from_channels((8, 8), pixels)
        .write()
        .to_file(d.join("wide.exr"))
        .unwrap();
    let mut bytes = std::fs::read(d.join("wide.exr")).unwrap();
    // displayWindow: box2i, 16 bytes: xmin ymin xmax ymax.
    let key = b"displayWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    bytes[at + 8..at + 12].copy_from_slice(&4_194_311i32.to_le_bytes());
    std::fs::write(d.join("wide.exr"), &bytes).unwrap();
    let scene = |key: &str| {
        format!(
            "[image]\nwidth = 4\nheight = 4\n{}[camera]\nposition = [0.5, -1, 1]\nlook_at = [0.5, 0.5, 0]\n\
             [materials.m]\ntype = \"lambert\"\ncolor = [0.5, 0.5, 0.5]\n{}\
             [[shapes]]\ntype = \"quad\"\norigin = [0, 0, 0]\nedge_u = [1, 0, 0]\nedge_v = [0, 1, 0]\nmaterial = \"m\"\n",
            if key == "environment" { "environment = \"wide.exr\"\n" } else { "" },
            if key == "texture" { "texture = \"wide.exr\"\n" } else { "" },
        )
    };
    for (key, limit) in [("texture", "1G"), ("environment", "1400M")] {
        std::fs::write(d.join("s.toml"), scene(key)).unwrap();
        let before = files(d);
        let o = cmd(d)
            .args(words("render s.toml -o r.png"))
            .env("DISPLACE_MEMORY_LIMIT", limit)
            .output()
            .unwrap();
        let msg = failed(&o, &["wide.exr", "decoding", "needs about"], &["panicked"]);
        assert!(msg.contains("4194312x8"), "{key}: {msg}");
        assert_eq!(files(d), before, "{key}: {msg}");
    }
}

/// A 16-bit RGBA PNG decodes to 8 bytes a texel, twice what `bake`'s
/// estimate counts for a decoded image: the decoder checks its own samples
/// and the heights against the limit before it allocates, naming the file,
/// its size and its sample type; under a limit that holds them it bakes.
#[test]
fn png_decodes_are_budgeted_by_their_samples() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    image::ImageBuffer::<image::Rgba<u16>, _>::from_pixel(2048, 2048, image::Rgba([9000; 4]))
        .save(d.join("h.png"))
        .unwrap();
    let bake = |limit: &str| {
        cmd(d)
            .args(words("bake h.png --size 16x16x4 -o m.npy"))
            .env("DISPLACE_MEMORY_LIMIT", limit)
            .output()
            .unwrap()
    };
    let o = bake("40M");
    let msg = failed(
        &o,
        &[
            "decoding",
            "h.png",
            "2048x2048 texels, Rgba16",
            "needs about",
        ],
        &[],
    );
    assert_eq!(files(d), ["h.png"], "{msg}");
    let o = bake("1G");
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Under an address-space limit (`ulimit -v`, as a batch system or a
/// shared machine sets), a bake the machine's memory would allow is refused
/// by that limit up front, naming it, and `DISPLACE_MEMORY_LIMIT` cannot
/// raise it: before, the bake died of `memory allocation of N bytes
/// failed` (an abort). A small bake under the same limit still runs.
#[test]
fn bakes_past_an_address_space_limit_are_refused_not_aborted() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let limited = |args: &[&str], env_limit: Option<&str>| {
        let mut c = Command::new("sh");
        c.current_dir(d)
            .env("DISPLACE_CACHE", "")
            .arg("-c")
            .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
            .arg(env!("CARGO_BIN_EXE_displace"))
            .args(args);
        if let Some(l) = env_limit {
            c.env("DISPLACE_MEMORY_LIMIT", l);
        }
        c.output().unwrap()
    };
    let big = words("bake gen:flat --height-size 20000x20000 --size 64x64x8 -o m.npy");
    for env_limit in [None, Some("64G")] {
        let o = limited(&big, env_limit);
        let msg = failed(
            &o,
            &[
                "20000x20000",
                "needs about",
                "address-space limit (ulimit -v: 1.0 GiB",
                "VmSize",
                "hard limit",
                "DISPLACE_MEMORY_LIMIT cannot raise",
            ],
            &["memory allocation of"],
        );
        assert!(
            matches!(o.status.code(), Some(1 | 2)),
            "{:?}: {msg}",
            o.status
        );
        assert!(files(d).is_empty(), "{msg}");
    }
    let o = limited(&words("bake gen:gaussian --size 64x64x8 -o m.npy"), None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files(d), ["m.npy"]);
}

/// `trace --scene` makes no image: a scene whose 16384x16384 image alone
/// passes a 1 GiB limit is traced (it used to be refused over the image it
/// never allocates), while `render` still refuses it, naming the image.
#[test]
fn a_trace_of_a_scene_does_not_count_its_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let big = replaced(
        SCENE,
        "width = 8\nheight = 8",
        "width = 16384\nheight = 16384",
    );
    std::fs::write(d.join("s.toml"), big).unwrap();
    write_rays(&d.join("rays.npy"), &[[0.0, 0.0, 5.0, 0.0, 0.0, -1.0]; 4]);
    let o = cmd(d)
        .args(words("trace --scene s.toml --rays rays.npy -o hits.npy"))
        .env("DISPLACE_MEMORY_LIMIT", "1G")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let o = cmd(d)
        .args(words("render -q s.toml -o r.png"))
        .env("DISPLACE_MEMORY_LIMIT", "1G")
        .output()
        .unwrap();
    failed(&o, &["16384x16384 image", "needs about"], &[]);
}

/// A scene's textures count together in its memory estimate, each before
/// it is decoded: two textures of 6 MiB each fit a 16 MiB limit (the
/// same file twice is read once, and counted once), a third tips the scene
/// over and is named, though each of them alone is far below any
/// one-buffer check.
#[test]
fn a_scenes_textures_are_counted_together() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for name in ["t1.png", "t2.png", "t3.png"] {
        image::RgbImage::from_pixel(512, 512, image::Rgb([200, 100, 50]))
            .save(d.join(name))
            .unwrap();
    }
    let scene = |textures: &[&str]| {
        let mut text = replaced(
            SCENE,
            "color = [0.5, 0.5, 0.5]",
            "color = [0.5, 0.5, 0.5]\ntexture = \"t1.png\"",
        );
        for (k, t) in textures.iter().enumerate() {
            text.push_str(&format!(
                "[materials.extra{k}]\ntype = \"lambert\"\ncolor = [1, 1, 1]\ntexture = \"{t}\"\n"
            ));
        }
        std::fs::write(d.join("s.toml"), text).unwrap();
    };
    let render = |args: &[&str]| {
        cmd(d)
            .args(args)
            .env("DISPLACE_MEMORY_LIMIT", "16M")
            .output()
            .unwrap()
    };
    scene(&["t1.png", "t2.png"]);
    let o = render(&["render", "-q", "s.toml", "-o", "r.png"]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_file(d.join("r.png")).unwrap();
    scene(&["t1.png", "t2.png", "t3.png"]);
    let before = files(d);
    let o = render(&["render", "-q", "s.toml", "-o", "r.png"]);
    failed(
        &o,
        &[
            "s.toml",
            "materials.extra2.texture = \"t3.png\": a 512x512 texture",
            "needs about 18.0 MiB",
            "DISPLACE_MEMORY_LIMIT",
        ],
        &[],
    );
    assert_eq!(files(d), before);
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
#[cfg(feature = "gpu")]
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
        replaced(
            SCENE,
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
        replaced(SCENE, "position = [0, 1, -3]", "position = [0, 0, -3e38]"),
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

/// `child` gone within `limit` of now; killed and the test failed if not.
fn exits_within(mut child: std::process::Child, limit: Duration) -> Output {
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!("still running {limit:?} after the signal: {o:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// Work and waits that used to ignore signals stop on them: a relaxed cone
/// bake (minutes at 512x512) ends within a texel's work of SIGINT, and a
/// render waiting on a bake cache lock held by a live process says what it
/// waits for and ends at SIGINT; neither leaves a file.
#[test]
fn cone_bakes_and_lock_waits_stop_on_signals() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let child = cmd(d)
        .args(words(
            "bake gen:noise --height-size 512x512 --size 16x16x4 --cone c.npy --cone-kind relaxed -o m.npy",
        ))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    send("-INT", &child);
    let o = exits_within(child, Duration::from_secs(5));
    failed(&o, &["interrupted"], &[]);
    assert!(files(d).is_empty(), "{:?}", files(d));

    // The scene's bake lands in the cache; then its entry is removed and a
    // lock planted in its place naming this host and a live process (this
    // test), which never refreshes it.
    let cache = tempfile::tempdir().unwrap();
    write_displaced(d, "height_size = [16, 16], map_size = [16, 16, 4]");
    let render = || {
        let mut c = cmd(d);
        c.env("DISPLACE_CACHE", cache.path())
            .args(["render", "-q", "s.toml", "-o", "r.png"])
            .stderr(Stdio::piped());
        c
    };
    let o = render().output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_file(d.join("r.png")).unwrap();
    let entries: Vec<_> = std::fs::read_dir(cache.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(entries.len(), 1, "{entries:?}");
    std::fs::remove_file(&entries[0]).unwrap();
    let mut lock = entries[0].clone().into_os_string();
    lock.push(".lock");
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    std::fs::write(&lock, format!("{} {}\n", host.trim(), std::process::id())).unwrap();
    let child = render().spawn().unwrap();
    std::thread::sleep(Duration::from_millis(3500));
    send("-INT", &child);
    let o = exits_within(child, Duration::from_secs(3));
    failed(
        &o,
        &[
            "waiting for another process's bake",
            ".lock is held by",
            "interrupted",
        ],
        &[],
    );
    assert!(files(d) == ["s.toml"], "{:?}", files(d));
}

/// Commands that had no handler, or installed it only after their first
/// file, stop on SIGINT and leave nothing: a mesh export streaming a large
/// grid (it used to leave its temporary file, up to a gigabyte), a
/// `compare` (it left its empty `--out` directory), and a bake interrupted
/// while its height map is still being made (it left `.m.ktx2.PID.0.tmp`).
#[test]
fn exports_compares_and_early_bakes_stop_on_signals_leaving_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&str, u64); 3] = [
        (
            "export-mesh gen:noise --height-size 1024x1024 --scale 6 --extent 1,1,0.1 -o m.obj",
            1500,
        ),
        (
            "compare --only-given --height gen:noise --height-size 512x512 --out o/deeper",
            1500,
        ),
        (
            "bake gen:noise --height-size 2048x2048 --size 64x64x8 -o m.ktx2",
            150,
        ),
    ];
    for (command, after_ms) in cases {
        let child = cmd(d)
            .args(words(command))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(after_ms));
        send("-INT", &child);
        let o = exits_within(child, Duration::from_secs(5));
        let msg = failed(&o, &["interrupted"], &[]);
        assert!(files(d).is_empty(), "{command}: {:?} {msg}", files(d));
    }
}

/// How this machine mounts a small tmpfs for one command without touching
/// any other process: in a private mount namespace as root (`unshare -m`),
/// else in a user namespace (`unshare -r -m`, where unprivileged user
/// namespaces are allowed). Probed once by mounting a 4 KiB tmpfs. The
/// full-disk test needs one of them and fails (never skips) naming both
/// errors when neither works: a test that silently did nothing would
/// prove nothing.
fn namespace_prefix() -> &'static [&'static str] {
    static PREFIX: std::sync::OnceLock<Result<&'static [&'static str], String>> =
        std::sync::OnceLock::new();
    let probe = || {
        let dir = tempfile::tempdir().unwrap();
        let mut errors = Vec::new();
        let ways: [&'static [&'static str]; 2] = [&["unshare", "-m"], &["unshare", "-r", "-m"]];
        for prefix in ways {
            let o = Command::new(prefix[0])
                .args(&prefix[1..])
                .args([
                    "sh",
                    "-c",
                    r#"mount -t tmpfs -o size=4096 tmpfs "$1""#,
                    "sh",
                ])
                .arg(dir.path())
                .output();
            match o {
                Ok(o) if o.status.success() => return Ok(prefix),
                Ok(o) => errors.push(format!("`{}`: {}", prefix.join(" "), stderr(&o).trim())),
                Err(e) => errors.push(format!("`{}`: {e}", prefix.join(" "))),
            }
        }
        Err(errors.join("; "))
    };
    match PREFIX.get_or_init(probe) {
        Ok(prefix) => prefix,
        Err(why) => panic!(
            "the full-disk test mounts a small tmpfs in its own mount namespace: run it as \
             root (`unshare -m`) or where user namespaces are allowed (`unshare -r -m`); \
             both failed: {why}"
        ),
    }
}

/// The names under `dir`, as paths relative to it, sorted.
fn tree(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            out.push(p.strip_prefix(dir).unwrap().to_string_lossy().into_owned());
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    out.sort();
    out
}

/// Bytes `dir`'s files take on a tmpfs: each file's size in whole pages.
fn pages_under(dir: &Path, page: u64) -> u64 {
    tree(dir)
        .iter()
        .map(|p| dir.join(p))
        .filter(|p| p.is_file())
        .map(|p| std::fs::metadata(p).unwrap().len().div_ceil(page) * page)
        .sum()
}

/// Runs `displace ARGS` in `dir` with a tmpfs of `bytes` mounted on
/// `dir/disk` for that run only (its own mount namespace: the disk goes
/// when the run ends), and returns what it did and what it left on the
/// disk (paths under `disk`, from `find`, sorted).
fn on_small_disk(dir: &Path, bytes: u64, args: &[&str]) -> (Output, Vec<String>) {
    const SCRIPT: &str = r#"size=$1; shift
mount -t tmpfs -o "size=$size" tmpfs disk || { echo "mounting the small disk failed" >&2; exit 97; }
"$@"; rc=$?
(cd disk && find . -mindepth 1) > left || exit 98
exit $rc"#;
    std::fs::create_dir_all(dir.join("disk")).unwrap();
    let prefix = namespace_prefix();
    let o = Command::new(prefix[0])
        .args(&prefix[1..])
        .args(["sh", "-c", SCRIPT, "sh", &bytes.to_string()])
        .arg(env!("CARGO_BIN_EXE_displace"))
        .args(args)
        .current_dir(dir)
        .env("DISPLACE_CACHE", "")
        .output()
        .unwrap();
    assert!(
        !matches!(o.status.code(), Some(97 | 98)),
        "set-up: {}",
        stderr(&o)
    );
    let left = std::fs::read_to_string(dir.join("left")).unwrap();
    std::fs::remove_file(dir.join("left")).unwrap();
    let mut left: Vec<String> = left
        .lines()
        .map(|l| l.trim_start_matches("./").to_string())
        .collect();
    left.sort();
    (o, left)
}

/// The memory page, which tmpfs sizes and files are counted in.
fn page_size() -> u64 {
    let o = Command::new("getconf").arg("PAGESIZE").output().unwrap();
    String::from_utf8_lossy(&o.stdout).trim().parse().unwrap()
}

/// `render -o r.exr --aov ...` and `compare --out` on a real full disk (a
/// small tmpfs): whether the disk fills in the first output, in the middle
/// or in the last, the command fails naming the disk's error and leaves
/// nothing (the outputs are written under temporary names and renamed
/// only when all are written); with room for all, all land.
#[test]
fn a_full_disk_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("s.toml"),
        replaced(SCENE, "width = 8\nheight = 8", "width = 48\nheight = 48"),
    )
    .unwrap();
    let page = page_size();
    // Each command with the output it writes last: a disk that fills half
    // way through that one has every other output written (under its
    // temporary name) when the write fails.
    let render = [
        "render",
        "-q",
        "s.toml",
        "-o",
        "OUT/r.exr",
        "--aov",
        "depth,normal,position",
    ];
    let compare = [
        "compare",
        "--quick",
        "--only-given",
        "--height",
        "gen:studded",
        "--techniques",
        "distance,pom",
        "--out",
        "OUT/o",
    ];
    for (command, last) in [
        (&render[..], "r.position.png"),
        (&compare[..], "o/grid.png"),
    ] {
        let on = |root: &str| -> Vec<String> {
            command.iter().map(|a| a.replace("OUT", root)).collect()
        };
        // The outputs and the room they take, from a run on the real disk.
        std::fs::create_dir_all(d.join("ref")).unwrap();
        let args = on("ref");
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&args, d);
        assert!(o.status.success(), "{}", stderr(&o));
        let outputs = tree(&d.join("ref"));
        assert!(outputs.len() >= 5, "{outputs:?}");
        let need = pages_under(&d.join("ref"), page);
        let last_pages = std::fs::metadata(d.join("ref").join(last))
            .unwrap()
            .len()
            .div_ceil(page);
        std::fs::remove_dir_all(d.join("ref")).unwrap();
        let args = on("disk");
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        // Full at the first write, half way, and half way through the last
        // output (compare's CSVs and plots hold timings, so their sizes
        // vary by a few bytes between runs; its last output, the grid, does
        // not).
        let mut sizes = vec![
            page,
            (need / 2).div_ceil(page) * page,
            need - last_pages.div_ceil(2) * page,
        ];
        sizes.dedup();
        for bytes in sizes {
            let (o, left) = on_small_disk(d, bytes, &args);
            failed(&o, &["No space left on device"], &[]);
            assert!(left.is_empty(), "{args:?} on {bytes} bytes left {left:?}");
        }
        // With room, every output lands: the disk itself is not the fault.
        let (o, left) = on_small_disk(d, need + need / 4 + 16 * page, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(left, outputs);
    }
}

/// An output that names one of the command's inputs is refused before any
/// work, and the input is left byte for byte as it was: the height map of
/// `bake` (as `-o`'s normal map), the rays of `trace` (one face or a
/// scene), a texture of a rendered scene (also through another spelling of
/// its path), the tiles of `merge`, the mesh a scene exported by
/// `export-mesh --scene` reads, an AOV written beside the image over a
/// texture the scene reads, `gpu-render`'s height map and scene texture.
/// Each was replaced by what was made from it.
#[test]
fn outputs_that_are_inputs_are_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    image::GrayImage::from_fn(16, 16, |x, y| image::Luma([(x * 16 + y) as u8]))
        .save(d.join("h.png"))
        .unwrap();
    image::RgbImage::from_pixel(4, 4, image::Rgb([200, 100, 50]))
        .save(d.join("wood.png"))
        .unwrap();
    write_rays(&d.join("rays.npy"), &[[0.5, 0.5, 1.0, 0.0, 0.0, -1.0]]);
    let scene = replaced(
        SCENE,
        "color = [0.5, 0.5, 0.5]",
        "color = [0.5, 0.5, 0.5]\ntexture = \"wood.png\"",
    );
    std::fs::write(d.join("s.toml"), scene).unwrap();
    std::fs::write(
        d.join("q.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n",
    )
    .unwrap();
    let meshed = replaced(
        SCENE,
        "type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1",
        "type = \"mesh\"\npath = \"q.obj\"",
    );
    std::fs::write(d.join("m.toml"), meshed).unwrap();
    // A scene textured by the file `render -o o.png --aov depth` would
    // write beside its image.
    std::fs::copy(d.join("wood.png"), d.join("o.depth.png")).unwrap();
    let aov_named = replaced(
        SCENE,
        "color = [0.5, 0.5, 0.5]",
        "color = [0.5, 0.5, 0.5]\ntexture = \"o.depth.png\"",
    );
    std::fs::write(d.join("d.toml"), aov_named).unwrap();
    let tile = run(
        &["render", "-q", "s.toml", "--tile", "0/1", "-o", "t0.exr"],
        d,
    );
    assert!(tile.status.success(), "{}", stderr(&tile));
    let bytes = |name: &str| std::fs::read(d.join(name)).unwrap();
    let bake = "bake h.png --size 16x16x4 -o m.npy --normals";
    let trace = "trace --height gen:studded --size 16x16x4 --extent 1,1,0.1 --rays rays.npy";
    for (command, input) in [
        (format!("{bake} h.png"), "h.png"),
        (format!("{bake} ./h.png"), "h.png"),
        (format!("{trace} -o rays.npy"), "rays.npy"),
        ("render -q s.toml -o wood.png".into(), "wood.png"),
        ("render -q s.toml -o ./wood.png".into(), "wood.png"),
        ("merge t0.exr -o t0.exr".into(), "t0.exr"),
        ("export-mesh --scene m.toml -o q.obj".into(), "q.obj"),
        (
            "trace --scene m.toml --rays rays.npy -o rays.npy".into(),
            "rays.npy",
        ),
        // Outputs named after -o (AOVs), and gpu-render's.
        (
            "render -q d.toml -o o.png --aov depth".into(),
            "o.depth.png",
        ),
        ("gpu-render --height h.png -o h.png".into(), "h.png"),
        ("gpu-render s.toml -o wood.png".into(), "wood.png"),
    ] {
        let before = bytes(input);
        refuses(d, &words(&command), &["is also an input"], &[]);
        assert_eq!(bytes(input), before, "{command}");
    }
}

/// Options that would be silently ignored or repeated are refused, naming
/// the option: `--height-size` with a height-map file (it sizes generated
/// maps only; the file kept its own size), an AOV asked for twice (listed
/// and written twice over one file).
#[test]
fn ignored_or_repeated_options_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    image::GrayImage::from_pixel(16, 16, image::Luma([128]))
        .save(d.join("h.png"))
        .unwrap();
    refuses(
        d,
        &words("bake h.png --height-size 64x64 --size 16x16x4 -o m.npy"),
        &["--height-size 64x64", "h.png", "has its own size"],
        &[],
    );
    let o = run(
        &words("bake gen:noise --height-size 64x64 --size 16x16x4 -o m.npy"),
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_file(d.join("m.npy")).unwrap();
    for aovs in ["--aov depth,normal,depth", "--aov depth --aov depth"] {
        refuses(
            d,
            &words(&format!("render --size 8x8 --spp 1 -q -o r.exr {aovs}")),
            &["--aov depth is asked for twice"],
            &[],
        );
    }
}

/// An elevation model in metres is refused as heights (they must lie in
/// [0, 1]) with the option that maps it, and nothing is written; with
/// `--height-range auto` it bakes, byte for byte, the map of the same
/// heights normalised beforehand.
#[test]
fn an_elevation_model_bakes_through_its_height_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let size = [24u32, 20u32];
    let dem = sampled(size, |x, y| {
        1200.0 + 300.0 * (x * 0.4).sin() * (y * 0.3).cos() + 7.0 * y
    });
    write_float_tiff(&d.join("dem.tif"), size, &dem);
    refuses(
        d,
        &words("bake dem.tif --size 24x20x8 -o m.npy"),
        &["dem.tif", "[0, 1]", "--height-range auto"],
        &[],
    );
    write_float_tiff(&d.join("unit.tif"), size, &normalised(&dem));
    for (args, out) in [
        (
            "bake dem.tif --height-range auto --size 24x20x8 -o a.npy",
            "a.npy",
        ),
        ("bake unit.tif --size 24x20x8 -o b.npy", "b.npy"),
    ] {
        let o = run(&words(args), d);
        assert!(o.status.success(), "{args}: {}", stderr(&o));
        assert!(d.join(out).is_file());
    }
    assert_eq!(
        std::fs::read(d.join("a.npy")).unwrap(),
        std::fs::read(d.join("b.npy")).unwrap()
    );
    refuses(
        d,
        &words("bake dem.tif --height-range 1300,2000 --size 24x20x8 -o c.npy"),
        &["dem.tif", "outside the height range 1300,2000"],
        &[],
    );
}

/// `export-mesh` of a map whose mesh cannot fit on the output's disk (a
/// small tmpfs) is refused before the map is loaded, saying what it needs
/// and what is free, and leaves nothing; the same mesh fits a disk with
/// room.
#[test]
fn a_mesh_larger_than_the_free_disk_is_refused_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 258 x 258 vertices and 2 x 257 x 257 triangles: a 3.8 MB PLY body.
    let args = words("export-mesh gen:noise --height-size 256x256 --extent 1,1,0.1 -o disk/m.ply");
    let (o, left) = on_small_disk(d, 1 << 20, &args);
    failed(
        &o,
        &["disk/m.ply", "the output needs", "free"],
        &["No space left"],
    );
    assert!(left.is_empty(), "{left:?}");
    let (o, left) = on_small_disk(d, 8 << 20, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(left, ["m.ply"]);
}
