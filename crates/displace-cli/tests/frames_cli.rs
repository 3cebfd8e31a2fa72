//! Animations: frame F of `--frames` equals `--frame F` alone, byte for
//! byte; a frame at a key equals the still scene with the camera and the
//! light where that key puts them (the paths hit their keys exactly); the
//! frames differ; `--frame auto` takes the scheduler's index; bad
//! `[animation]` keys and frames out of range are refused by name.

mod cli_common;

use cli_common::{displace_env as run, files, ok, replaced, stderr, SPHERE_SCENE};
use std::path::Path;

/// A lit sphere (16 x 16 at 2 spp) with a camera path and a moving point
/// light.
fn still() -> String {
    replaced(
        SPHERE_SCENE,
        "width = 8\nheight = 8\nspp = 1",
        "width = 16\nheight = 16\nspp = 2",
    )
}

const ANIMATION: &str = r#"
[animation]
frames = 6
fps = 12
interpolation = "catmull-rom"
camera = [
  { frame = 0, position = [0, 1, -3], look_at = [0, 0, 0] },
  { frame = 2, position = [1.3, 0.7, -2.6], look_at = [0.1, 0.2, 0] },
  { frame = 5, position = [2.5, 1.5, -1.0], look_at = [0, 0.3, 0.1] },
]
light_path = [
  { frame = 0, position = [0, 3, -1] },
  { frame = 2, position = [1.5, 2.5, -1.5] },
  { frame = 5, position = [-2, 2, -2] },
]
"#;

fn read(d: &Path, f: &str) -> Vec<u8> {
    std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"))
}

#[test]
fn frames_equal_single_frames_and_keys_are_hit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("a.toml"), format!("{}{ANIMATION}", still())).unwrap();
    ok(run(
        &[
            "render", "-q", "a.toml", "--frames", "0..6", "-o", "out.png",
        ],
        d,
        &[],
    ));
    for f in 0..6 {
        let name = format!("out_{f:04}.png");
        ok(run(
            &[
                "render",
                "-q",
                "a.toml",
                "--frame",
                &f.to_string(),
                "-o",
                "one.png",
            ],
            d,
            &[],
        ));
        assert!(read(d, &name) == read(d, "one.png"), "frame {f}");
    }
    assert!(
        read(d, "out_0000.png") != read(d, "out_0001.png"),
        "nothing moved"
    );
    // Frame 2 is the still scene with key 2's camera and light.
    let key2 = [
        ("position = [0, 1, -3]", "position = [1.3, 0.7, -2.6]"),
        ("look_at = [0, 0, 0]", "look_at = [0.1, 0.2, 0]"),
        ("position = [0, 3, -1]", "position = [1.5, 2.5, -1.5]"),
    ]
    .iter()
    .fold(still(), |text, (from, to)| replaced(&text, from, to));
    std::fs::write(d.join("key2.toml"), key2).unwrap();
    ok(run(
        &["render", "-q", "key2.toml", "-o", "key2.png"],
        d,
        &[],
    ));
    assert!(
        read(d, "out_0002.png") == read(d, "key2.png"),
        "key 2 not hit exactly"
    );
    // One frame per task, and a name pattern.
    ok(run(
        &[
            "render",
            "-q",
            "a.toml",
            "--frame",
            "auto",
            "-o",
            "task_%04d.png",
        ],
        d,
        &[("JOB_COMPLETION_INDEX", "3")],
    ));
    assert!(read(d, "task_0003.png") == read(d, "out_0003.png"));
}

#[test]
fn bad_animations_and_frames_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A whole scene or an animation appended to a still, the arguments, and
    // what the refusal must say.
    let anim = |from: &str, to: &str| ANIMATION.replace(from, to);
    let key = "position = [1.3, 0.7, -2.6], look_at = [0.1, 0.2, 0]";
    let degenerate = "position = [0.1, 0.2, 0], look_at = [0.1, 0.2, 0]";
    #[rustfmt::skip]
    let cases: &[(&str, &[&str], &str)] = &[
        (&still(), &["--frame", "0"], "no [animation]"),
        (ANIMATION, &["--frame", "6"], "has 6 frames"),
        (ANIMATION, &["--frames", "4..9"], "has 6 frames"),
        (ANIMATION, &["--frame", "auto"], "neither SLURM_ARRAY_TASK_ID"),
        (&anim("catmull-rom", "cubic"), &[], "animation.interpolation = \"cubic\""),
        (&anim("{ frame = 2, position = [1.3", "{ frame = 7, position = [1.3"), &[],
            "animation.camera (position)[1].frame = 7"),
        (&anim("{ frame = 5, position = [2.5", "{ frame = 1, position = [2.5"), &[],
            "increasing frame order"),
        (&anim("frames = 6", "frames = 0"), &[], "animation.frames"),
        (&anim("fps = 12", "fps = -1"), &[], "animation.fps"),
        (&anim("light_path = [", "light = 3\nlight_path = ["), &[], "animation.light = 3"),
        // A light index past the lights is refused without a path too.
        (&format!("{}light = 5\n", &ANIMATION[..ANIMATION.find("light_path").unwrap()]), &[],
            "animation.light = 5"),
        (&anim("fps = 12", "fps = 12\nspeed = 2"), &[], "speed"),
        // A key half way that puts the camera on the point it looks at:
        // found before frame 0 is written, and named by its frame.
        (&anim(key, degenerate), &["--frames", "0..6"],
            "animation frame 2: the camera's position and look_at"),
        (&anim(key, degenerate), &["--frame", "2"], "animation frame 2"),
        (&anim(&format!("{{ frame = 2, {key} }}"), "{ frame = 2 }"), &[],
            "animation.camera[1] (frame 2) sets neither position nor look_at"),
    ];
    for (anim, args, expect) in cases {
        let text = if anim.contains("[image]") {
            anim.to_string()
        } else {
            format!("{}{anim}", still())
        };
        std::fs::write(d.join("s.toml"), text).unwrap();
        let before = files(d);
        let mut all = vec!["render", "-q", "s.toml", "-o", "x.png"];
        all.extend_from_slice(args);
        let o = run(&all, d, &[]);
        assert!(!o.status.success(), "{expect}: accepted");
        assert!(
            stderr(&o).contains(expect),
            "`{expect}` not in: {}",
            stderr(&o)
        );
        assert_eq!(files(d), before, "{expect}: files written");
    }
}

/// Every frame's outputs are checked before the first frame is rendered:
/// a later frame whose name is one of the scene's files (frame 1 of
/// `-o t.png` is `t_0001.png`, a texture here), and a name longer than a
/// file system takes, used to be found after frame 0 was written, or after
/// the whole render.
#[test]
fn every_frames_outputs_are_checked_before_the_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    image::RgbImage::from_pixel(4, 4, image::Rgb([200, 100, 50]))
        .save(d.join("t_0001.png"))
        .unwrap();
    let textured = replaced(
        &still(),
        "color = [0.5, 0.5, 0.5]",
        "color = [0.5, 0.5, 0.5]\ntexture = \"t_0001.png\"",
    );
    std::fs::write(d.join("s.toml"), format!("{textured}{ANIMATION}")).unwrap();
    let before = files(d);
    let o = run(
        &["render", "-q", "s.toml", "--frames", "0..3", "-o", "t.png"],
        d,
        &[],
    );
    let msg = stderr(&o);
    assert!(!o.status.success(), "{msg}");
    assert!(
        msg.contains("t_0001.png") && msg.contains("(frame 1)") && msg.contains("is also an input"),
        "{msg}"
    );
    assert_eq!(files(d), before);
    let long = format!("{}.png", "n".repeat(300));
    let o = run(
        &["render", "-q", "s.toml", "--frames", "0..2", "-o", &long],
        d,
        &[],
    );
    let msg = stderr(&o);
    assert!(!o.status.success(), "{msg}");
    assert!(msg.contains("more than the 255"), "{msg}");
    assert_eq!(files(d), before);
}
