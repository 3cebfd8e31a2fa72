//! Random scenes at the edges of what a scene file may say: sizes from a
//! thousandth to a hundred thousand units, lights and emission up to the
//! radiance bound, shininess up to a million, displacement depths from
//! nothing to taller than the face, cameras at any angle and field of view,
//! both integrators. A scene is either refused with an error or rendered,
//! and a rendered image and its AOVs hold no NaN and no infinity (depth is
//! `+inf` exactly where nothing is hit, as documented), and no negative
//! radiance. Cases come from proptest's seeded generator (fixed in CI,
//! fresh under `scripts/explore.sh`).

mod common;

use common::opts;
use displace_core::random::SplitMix64;
use displace_render::{render, Aov, RenderOptions, Scene};
use proptest::prelude::*;
use std::fmt::Write;
use std::path::Path;

/// Draws from one case's generator.
struct Draw(SplitMix64);

impl Draw {
    fn unit(&mut self) -> f32 {
        self.0.next_f32()
    }
    fn below(&mut self, n: u32) -> u32 {
        (self.0.next_u64() % u64::from(n)) as u32
    }
    /// `10^e`, `e` uniform in `[lo, hi]`.
    fn magnitude(&mut self, lo: f32, hi: f32) -> f32 {
        10f32.powf(lo + (hi - lo) * self.unit())
    }
    /// A signed value of magnitude `10^[lo, hi]`.
    fn signed(&mut self, lo: f32, hi: f32) -> f32 {
        let m = self.magnitude(lo, hi);
        if self.unit() < 0.5 {
            -m
        } else {
            m
        }
    }
    fn point(&mut self, scale: f32) -> String {
        let p: Vec<f32> = (0..3).map(|_| self.signed(-3.0, 0.0) * scale).collect();
        format!("[{:e}, {:e}, {:e}]", p[0], p[1], p[2])
    }
    /// A reflectance in `[0, 1]`, often at its ends.
    fn reflectance(&mut self) -> String {
        let c: Vec<f32> = (0..3)
            .map(|_| match self.below(4) {
                0 => 0.0,
                1 => 1.0,
                _ => self.unit(),
            })
            .collect();
        format!("[{}, {}, {}]", c[0], c[1], c[2])
    }
    /// A radiance up to the bound of 1e15.
    fn radiance(&mut self) -> String {
        let c: Vec<f32> = (0..3)
            .map(|_| {
                if self.below(4) == 0 {
                    0.0
                } else {
                    self.magnitude(-6.0, 15.0)
                }
            })
            .collect();
        format!("[{:e}, {:e}, {:e}]", c[0], c[1], c[2])
    }
}

/// One random scene (TOML) drawn from `seed`, its lengths around `scale`.
fn scene_text(seed: u64) -> String {
    let mut d = Draw(SplitMix64::new(seed));
    let scale = d.magnitude(-3.0, 5.0);
    let mut t = String::new();
    let integrator = if d.below(2) == 0 { "whitted" } else { "path" };
    let background = if d.below(2) == 0 {
        "[0, 0, 0]".to_string()
    } else {
        d.radiance()
    };
    writeln!(
        t,
        "[image]\nwidth = 16\nheight = 12\nspp = {}\nshadow_samples = {}\nmax_depth = {}\n\
         integrator = \"{integrator}\"\nbackground = {background}\nseed = {}\n",
        1 + d.below(4),
        1 + d.below(3),
        d.below(7),
        d.below(1000)
    )
    .unwrap();
    let aperture = if d.below(3) == 0 {
        d.magnitude(-4.0, 1.0) * scale
    } else {
        0.0
    };
    writeln!(
        t,
        "[camera]\nposition = {}\nlook_at = {}\nvfov = {}\naperture = {aperture:e}\n",
        d.point(scale * 4.0),
        d.point(scale * 0.1),
        0.01 + 179.9 * d.unit(),
    )
    .unwrap();
    let materials = 1 + d.below(3);
    for m in 0..materials {
        let emission = if d.below(4) == 0 {
            d.radiance()
        } else {
            "[0, 0, 0]".into()
        };
        let body = match d.below(4) {
            0 => format!("type = \"lambert\"\ncolor = {}", d.reflectance()),
            1 => format!(
                "type = \"phong\"\ncolor = {}\nspecular = {}\nshininess = {:e}",
                d.reflectance(),
                d.reflectance(),
                d.magnitude(-2.0, 6.0)
            ),
            2 => format!(
                "type = \"mirror\"\ncolor = {}\ndiffuse = {}",
                d.reflectance(),
                d.reflectance()
            ),
            _ => format!(
                "type = \"glossy\"\nroughness = {:e}\ncolor = {}",
                d.magnitude(-6.0, 0.0),
                d.reflectance()
            ),
        };
        writeln!(t, "[materials.m{m}]\n{body}\nemission = {emission}\n").unwrap();
    }
    for _ in 0..d.below(4) {
        if d.below(2) == 0 {
            writeln!(
                t,
                "[[lights]]\ntype = \"point\"\nposition = {}\nintensity = {}\n",
                d.point(scale * 2.0),
                d.radiance()
            )
            .unwrap();
        } else {
            writeln!(
                t,
                "[[lights]]\ntype = \"area\"\norigin = {}\nedge_u = {}\nedge_v = {}\nradiance = {}\nvisible = {}\n",
                d.point(scale * 2.0),
                d.point(scale),
                d.point(scale),
                d.radiance(),
                d.below(2) == 0
            )
            .unwrap();
        }
    }
    for _ in 0..1 + d.below(4) {
        let material = d.below(materials);
        match d.below(4) {
            0 => writeln!(
                t,
                "[[shapes]]\ntype = \"sphere\"\ncenter = {}\nradius = {:e}\nmaterial = \"m{material}\"\n",
                d.point(scale),
                d.magnitude(-3.0, 0.5) * scale
            )
            .unwrap(),
            1 => writeln!(
                t,
                "[[shapes]]\ntype = \"triangle\"\nvertices = [{}, {}, {}]\nmaterial = \"m{material}\"\n",
                d.point(scale),
                d.point(scale),
                d.point(scale)
            )
            .unwrap(),
            _ => {
                writeln!(
                    t,
                    "[[shapes]]\ntype = \"quad\"\norigin = {}\nedge_u = {}\nedge_v = {}\nmaterial = \"m{material}\"\n",
                    d.point(scale),
                    d.point(scale),
                    d.point(scale)
                )
                .unwrap();
                if d.below(3) != 0 {
                    let height = ["gen:gaussian", "gen:studded", "gen:noise", "gen:flat"]
                        [d.below(4) as usize];
                    let repeat = d.below(2) == 0;
                    let tiles = if repeat { 1 + d.below(5) } else { 1 };
                    writeln!(
                        t,
                        "[shapes.displacement]\nheight = \"{height}\"\nheight_size = [{}, {}]\n\
                         depth = {:e}\nmap_size = [{}, {}, {}]\naddress = \"{}\"\ntiles = [{tiles}, {tiles}]\n",
                        2 + d.below(40),
                        2 + d.below(40),
                        if d.below(5) == 0 { 0.0 } else { d.magnitude(-5.0, 0.5) * scale },
                        1 + d.below(24),
                        1 + d.below(24),
                        1 + d.below(8),
                        if repeat { "repeat" } else { "clamp" },
                    )
                    .unwrap();
                }
            }
        }
    }
    t
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(96)))]
    /// Every scene that loads renders to finite, non-negative pixels and
    /// finite AOVs (depth `+inf` exactly on misses).
    #[test]
    fn extreme_scenes_render_finite_or_are_refused(seed in any::<u64>()) {
        let text = scene_text(seed);
        let Ok(scene) = Scene::from_toml(&text, Path::new("extreme.toml"), Path::new("."), &opts())
        else {
            return Ok(());
        };
        let out = render(&scene, &RenderOptions { aovs: Aov::ALL.to_vec(), ..Default::default() })
            .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        for (k, p) in out.image.pixels.iter().enumerate() {
            prop_assert!(p.is_finite() && p.min_element() >= 0.0, "pixel {k} = {p}\n{text}");
        }
        for img in &out.aovs {
            let c = img.aov.channels();
            for (k, v) in img.data.iter().enumerate() {
                let ok = match img.aov {
                    Aov::Depth => v.is_finite() || *v == f32::INFINITY,
                    _ => v.is_finite(),
                };
                prop_assert!(ok, "{} pixel {} = {v}\n{text}", img.aov.name(), k / c);
            }
            if img.aov == Aov::Depth {
                let normal = &out.aovs.iter().find(|a| a.aov == Aov::Normal).unwrap().data;
                for (k, v) in img.data.iter().enumerate() {
                    let n = &normal[3 * k..3 * k + 3];
                    prop_assert_eq!(
                        v.is_infinite(),
                        n == [0.0; 3],
                        "pixel {}: depth {} normal {:?}\n{}", k, v, n, text
                    );
                }
            }
        }
    }
}

/// The generator reaches what the property is about: most scenes load, and
/// the ones that do cover both integrators and displaced faces.
#[test]
fn the_generator_makes_loadable_scenes() {
    let (mut loaded, mut displaced, mut path) = (0, 0, 0);
    for seed in 0..64 {
        let text = scene_text(seed);
        if Scene::from_toml(&text, Path::new("extreme.toml"), Path::new("."), &opts()).is_ok() {
            loaded += 1;
            displaced += usize::from(text.contains("[shapes.displacement]"));
            path += usize::from(text.contains("\"path\""));
        }
    }
    assert!(loaded >= 32, "only {loaded} of 64 scenes load");
    assert!(
        displaced >= 10 && path >= 10,
        "{displaced} displaced, {path} path-traced"
    );
}
