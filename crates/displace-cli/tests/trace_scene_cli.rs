//! `displace trace --scene`: whole-scene batch queries end to end. Plain
//! shapes against their analytic answers, a displaced face against the
//! one-face query (`displace trace --height`, itself held to the exact
//! reference), any-hit queries against the first hits on random rays, and
//! bad rays refused with the problem named and nothing written.

mod cli_common;

use cli_common::{displace, displace_env, failed, lambert, point_light, stderr};
use displace_core::io::npy;
use std::path::Path;

fn ok(args: &[&str], dir: &Path) {
    let o = displace(args, dir);
    assert!(o.status.success(), "{args:?} failed: {}", stderr(&o));
}

fn write_rays(path: &Path, rows: &[Vec<f32>]) {
    let cols = rows[0].len();
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    npy::write_file(path, &[rows.len(), cols], &flat).unwrap();
}

fn read(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let a = npy::read_file(path).unwrap();
    (a.shape, a.data)
}

/// The camera, material `white` and light every scene here has.
fn header() -> String {
    "\n[image]\nwidth = 8\nheight = 8\n[camera]\nposition = [0.5, -2.0, 1.0]\nlook_at = [0.5, 0.5, 0.0]\n"
        .to_string()
        + &lambert("white", "[0.5, 0.5, 0.5]")
        + &point_light("[0.5, 0.5, 3.0]", "[1.0, 1.0, 1.0]")
}

/// Writes `s.toml` in `dir`: [`header`] and then `shapes`.
fn write_scene(dir: &Path, shapes: &str) {
    std::fs::write(dir.join("s.toml"), format!("{}\n{shapes}", header())).unwrap();
}

/// `displace trace --scene s.toml --rays RAYS -o OUT EXTRA...` in `dir`,
/// which must succeed.
fn trace_scene(dir: &Path, rays: &str, out: &str, extra: &[&str]) {
    let mut args = vec!["trace", "--scene", "s.toml", "--rays", rays, "-o", out];
    args.extend_from_slice(extra);
    ok(&args, dir);
}

/// A `[[shapes]]` quad `origin + a edge_u + b edge_v` of material `white`.
fn quad(origin: &str, edge_u: &str, edge_v: &str) -> String {
    cli_common::quad(origin, edge_u, edge_v, "white")
}

/// A `[[shapes]]` sphere of material `white`.
fn sphere(center: &str, radius: f32) -> String {
    cli_common::sphere(center, radius, "white")
}

/// The unit square at the origin in the xy plane (the frame of a lone face
/// in `displace trace`), displaced by `height` (32x32 texels) to `depth`.
fn displaced_unit_quad(height: &str, depth: f32, map: [u32; 3]) -> String {
    quad("[0.0, 0.0, 0.0]", "[1.0, 0.0, 0.0]", "[0.0, 1.0, 0.0]")
        + &format!(
            "[shapes.displacement]
height = \"{height}\"
height_size = [32, 32]
depth = {depth}
map_size = {map:?}
"
        )
}

/// A floor quad (shape 0) and a sphere of radius 0.5 at (3, 0, 1) (shape
/// 1): first hits, normals, shape indices, misses and `t` along the
/// direction as given (not normalised).
#[test]
fn plain_shapes_give_their_analytic_hits() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(
        d,
        &(quad("[0.0, 0.0, 0.0]", "[2.0, 0.0, 0.0]", "[0.0, 2.0, 0.0]")
            + &sphere("[3.0, 0.0, 1.0]", 0.5)),
    );
    write_rays(
        &d.join("rays.npy"),
        &[
            // Straight down onto the floor, direction of length 2.
            vec![1.0, 1.0, 3.0, 0.0, 0.0, -2.0],
            // Along +x into the sphere's side.
            vec![0.0, 0.0, 1.0, 1.0, 0.0, 0.0],
            // Up into nothing.
            vec![1.0, 1.0, 3.0, 0.0, 0.0, 1.0],
        ],
    );
    trace_scene(d, "rays.npy", "h.npy", &[]);
    let (shape, h) = read(&d.join("h.npy"));
    assert_eq!(shape, vec![3, 8]);
    let close = |a: f32, b: f32| (a - b).abs() < 1e-4;
    // Floor: t = 3 / 2 along the given direction, normal +z, shape 0.
    assert!(close(h[0], 1.5), "{:?}", &h[..8]);
    assert!(close(h[1], 1.0) && close(h[2], 1.0) && close(h[3], 0.0));
    assert!(close(h[6].abs(), 1.0) && close(h[4], 0.0) && close(h[5], 0.0));
    assert_eq!(h[7], 0.0);
    // Sphere: enters at x = 2.5, normal -x, shape 1.
    let s = &h[8..16];
    assert!(close(s[0], 2.5) && close(s[1], 2.5), "{s:?}");
    assert!(close(s[4], -1.0), "{s:?}");
    assert_eq!(s[7], 1.0);
    // Miss: inf, NaN position, shape -1.
    let m = &h[16..24];
    assert!(m[0].is_infinite() && m[1].is_nan());
    assert_eq!(m[7], -1.0);
}

/// A displaced face at the origin of the world, in the frame `displace
/// trace` uses for a lone face: the scene query finds the same hits.
#[test]
fn displaced_faces_agree_with_the_face_query() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(
        d,
        &displaced_unit_quad("gen:studded?period=8", 0.1, [32, 32, 8]),
    );
    let mut rng = displace_core::random::SplitMix64::new(7);
    let rays: Vec<Vec<f32>> = (0..2000)
        .map(|_| {
            // From above the face towards a point inside it.
            let (tx, ty) = (0.1 + 0.8 * rng.next_f32(), 0.1 + 0.8 * rng.next_f32());
            let (ox, oy) = (rng.next_f32() - 0.5, rng.next_f32() - 0.5);
            let o = [tx + ox * 0.3, ty + oy * 0.3, 0.3];
            vec![o[0], o[1], o[2], tx - o[0], ty - o[1], -o[2]]
        })
        .collect();
    write_rays(&d.join("rays.npy"), &rays);
    trace_scene(d, "rays.npy", "scene.npy", &[]);
    ok(
        &[
            "trace",
            "--height",
            "gen:studded?period=8",
            "--height-size",
            "32x32",
            "--extent",
            "1,1,0.1",
            "--size",
            "32x32x8",
            "--rays",
            "rays.npy",
            "-o",
            "face.npy",
        ],
        d,
    );
    let (_, s) = read(&d.join("scene.npy"));
    let (_, f) = read(&d.join("face.npy"));
    let mut hits = 0;
    for (k, (s, f)) in s.chunks(8).zip(f.chunks(5)).enumerate() {
        assert_eq!(
            s[0].is_finite(),
            f[0].is_finite(),
            "ray {k}: {s:?} vs {f:?}"
        );
        if s[0].is_finite() {
            hits += 1;
            assert!(
                (s[0] - f[0]).abs() < 1e-4,
                "ray {k}: t {} vs {}",
                s[0],
                f[0]
            );
            for c in 0..3 {
                assert!(
                    (s[1 + c] - f[1 + c]).abs() < 1e-4,
                    "ray {k}: {s:?} vs {f:?}"
                );
            }
            assert_eq!(s[7], 0.0);
            let n = (s[4] * s[4] + s[5] * s[5] + s[6] * s[6]).sqrt();
            assert!((n - 1.0).abs() < 1e-4, "ray {k}: normal {s:?}");
        }
    }
    assert!(hits > 1900, "only {hits} hits");
}

/// Writes `s.toml` in `dir`: a displaced gaussian face with a sphere over
/// it, the scene of the any-hit and repeated-pass tests.
fn write_bumps_under_a_ball(dir: &Path) {
    write_scene(
        dir,
        &(displaced_unit_quad("gen:gaussian", 0.3, [16, 16, 8]) + &sphere("[0.5, 0.5, 0.6]", 0.1)),
    );
}

/// Any-hit queries over random segments agree with the first hits: blocked
/// exactly when the first hit lies before `t_max` (away from the ends).
#[test]
fn any_hit_agrees_with_the_first_hit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_bumps_under_a_ball(d);
    let mut rng = displace_core::random::SplitMix64::new(11);
    let rays: Vec<Vec<f32>> = (0..3000)
        .map(|_| {
            let o = [rng.next_f32(), rng.next_f32(), 0.2 + rng.next_f32()];
            let t = [rng.next_f32(), rng.next_f32(), rng.next_f32() * 0.5];
            let t_max = 2.0 * rng.next_f32() + 0.01;
            vec![
                o[0],
                o[1],
                o[2],
                t[0] - o[0],
                t[1] - o[1],
                t[2] - o[2],
                t_max,
            ]
        })
        .collect();
    write_rays(&d.join("rays.npy"), &rays);
    let unbounded: Vec<Vec<f32>> = rays.iter().map(|r| r[..6].to_vec()).collect();
    write_rays(&d.join("first.npy"), &unbounded);
    trace_scene(d, "first.npy", "h.npy", &[]);
    trace_scene(d, "rays.npy", "b.npy", &["--any-hit"]);
    let (_, h) = read(&d.join("h.npy"));
    let (shape, b) = read(&d.join("b.npy"));
    assert_eq!(shape, vec![rays.len(), 1]);
    let (mut blocked, mut free, mut checked) = (0, 0, 0);
    for (k, (r, (h, b))) in rays.iter().zip(h.chunks(8).zip(&b)).enumerate() {
        let t_max = r[6];
        if (h[0] - t_max).abs() < 1e-3 {
            continue;
        }
        checked += 1;
        let want = h[0] < t_max;
        assert_eq!(
            *b == 1.0,
            want,
            "ray {k}: first hit t {} t_max {t_max}",
            h[0]
        );
        if want {
            blocked += 1;
        } else {
            free += 1;
        }
    }
    assert!(
        checked > 2900 && blocked > 300 && free > 300,
        "{blocked} {free}"
    );
}

/// `--repeat N` times N passes after the first and reports the best, with
/// the answers the one pass writes (the tool itself fails a pass that
/// answers otherwise); without `--scene` it is refused by name.
#[test]
fn repeated_passes_report_the_best_and_answer_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_bumps_under_a_ball(d);
    let mut rng = displace_core::random::SplitMix64::new(12);
    let rays: Vec<Vec<f32>> = (0..2000)
        .map(|_| {
            let o = [rng.next_f32(), rng.next_f32(), 1.0 + rng.next_f32()];
            let t = [rng.next_f32(), rng.next_f32(), 0.0];
            vec![o[0], o[1], o[2], t[0] - o[0], t[1] - o[1], t[2] - o[2]]
        })
        .collect();
    write_rays(&d.join("rays.npy"), &rays);
    for any in [false, true] {
        let flag: &[&str] = if any { &["--any-hit"] } else { &[] };
        trace_scene(d, "rays.npy", "one.npy", flag);
        let mut args = vec![
            "trace", "--scene", "s.toml", "--rays", "rays.npy", "-o", "rep.npy",
        ];
        args.extend_from_slice(flag);
        args.extend_from_slice(&["--repeat", "3"]);
        let o = displace(&args, d);
        assert!(o.status.success(), "{args:?} failed: {}", stderr(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            out.contains("the best of 3 passes after the first"),
            "{out}"
        );
        assert_eq!(
            std::fs::read(d.join("one.npy")).unwrap(),
            std::fs::read(d.join("rep.npy")).unwrap(),
            "any-hit {any}"
        );
    }
    let o = displace(
        &[
            "trace",
            "--height",
            "gen:gaussian",
            "--extent",
            "1,1,0.1",
            "--rays",
            "rays.npy",
            "-o",
            "x.npy",
            "--repeat",
            "2",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--repeat applies to whole-scene queries"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("x.npy").exists());
    // The queries' memory (2000 rays of 24 bytes: the file, its floats,
    // the rays and two passes' answers, about 0.3 MB) is estimated from the
    // file's size and refused past the limit before anything is read.
    for (limit, ok) in [("200K", false), ("2M", true)] {
        let o = displace_env(
            &[
                "trace", "--scene", "s.toml", "--rays", "rays.npy", "-o", "lim.npy", "--repeat",
                "1",
            ],
            d,
            &[("DISPLACE_MEMORY_LIMIT", limit)],
        );
        if ok {
            assert!(o.status.success(), "{limit}: {}", stderr(&o));
        } else {
            failed(&o, &["needs about", "rays.npy"], &[]);
        }
        assert_eq!(d.join("lim.npy").exists(), ok);
    }
}

#[test]
fn bad_rays_are_refused_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(d, &sphere("[0.0, 0.0, 0.0]", 1.0));
    let cases: [(&str, Vec<Vec<f32>>, &str); 3] = [
        ("five.npy", vec![vec![0.0; 5]], "expected (n, 6)"),
        (
            "neg.npy",
            vec![vec![0.0, 0.0, 5.0, 0.0, 0.0, -1.0, -1.0]],
            "t_max",
        ),
        (
            "zero.npy",
            vec![vec![0.0, 0.0, 5.0, 0.0, 0.0, 0.0]],
            "no length",
        ),
    ];
    for (name, rows, needle) in cases {
        write_rays(&d.join(name), &rows);
        let o = displace(
            &[
                "trace", "--scene", "s.toml", "--rays", name, "-o", "out.npy",
            ],
            d,
        );
        let msg = stderr(&o).to_lowercase();
        assert!(!o.status.success(), "{name} accepted");
        assert!(msg.contains(needle) && msg.contains(name), "{name}: {msg}");
        assert!(!msg.contains("panicked"), "{msg}");
        assert!(!d.join("out.npy").exists(), "{name}: output written");
    }
    // --any-hit belongs to scene queries.
    let o = displace(
        &[
            "trace",
            "--height",
            "gen:flat",
            "--extent",
            "1,1,0.1",
            "--rays",
            "five.npy",
            "-o",
            "o.npy",
            "--any-hit",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--scene"));
}
