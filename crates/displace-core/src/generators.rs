//! Built-in height maps, named `gen:NAME` with optional parameters
//! `gen:NAME?key=value&key=value` (values URL-decoded, so `%20` is a space).
//!
//! | name | what | parameters (defaults) |
//! |------|------|------------------------|
//! | `flat` | every texel at one height: the ray-tracer paper's debugging map | `level` (1) |
//! | `gaussian` | `h = exp(-pi (x^2 + y^2))`, the ray-tracer paper | `scale` (2: `x, y` in `[-2, 2]`) |
//! | `studded` | alternating squares of two heights, sharp edges: the ray-tracer paper | `period` (W/8 texels), `low` (0), `high` (1) |
//! | `grating` | parallel raised bars, optionally crossed: Donnelly fig. 8-6 | `period` (W/8 texels), `duty` (0.5), `crossed` (false) |
//! | `text` | a string as raised letters: Donnelly fig. 8-3 | `text` (`displace`), `size` (fits the map) |
//! | `noise` | fractal Perlin noise, tiling under repeat addressing | `seed` (0), `octaves` (5), `frequency` (4), `gain` (0.5) |
//!
//! Every generator is deterministic, evaluates the texel centres of
//! [`crate::convention`] and returns heights in `[0, 1]`. Row `j = 0` is
//! `v = 0`, the first row of an image file, so `text` reads correctly when
//! the map is saved as a PNG.

mod noise;
mod params;
mod shapes;
mod text;

pub use text::FONT;

use crate::convention::texel_centre;
use crate::{Address, Error, HeightMap, Result};
use rayon::prelude::*;

/// Spec prefix that marks a generator rather than a file.
pub const PREFIX: &str = "gen:";

/// The generators, as `gen:NAME` names them.
pub const NAMES: [&str; 6] = ["flat", "gaussian", "studded", "grating", "text", "noise"];

/// Builds the height map named by `spec` (`gen:studded?period=8`) at
/// `width x height` texels with `address` addressing.
///
/// Unknown names give [`Error::UnknownGenerator`]; unknown parameters and
/// bad values give [`Error::GeneratorParameter`] naming the parameter and
/// the accepted ones; sizes are checked before anything is allocated.
///
/// ```
/// use displace_core::{generators::generate, Address};
/// let m = generate("gen:studded?period=4&low=0.25", 16, 16, Address::Repeat).unwrap();
/// assert_eq!((m.texel(0, 0), m.texel(4, 0)), (1.0, 0.25));
/// ```
pub fn generate(spec: &str, width: usize, height: usize, address: Address) -> Result<HeightMap> {
    let rest = spec
        .strip_prefix(PREFIX)
        .ok_or_else(|| Error::UnknownGenerator(spec.to_string()))?;
    let (name, query) = match rest.split_once('?') {
        Some((name, query)) => (name, Some(query)),
        None => (rest, None),
    };
    let grid = Grid::new(width, height, address)?;
    match name {
        "flat" => shapes::flat(query, grid),
        "gaussian" => shapes::gaussian(query, grid),
        "studded" => shapes::studded(query, grid),
        "grating" => shapes::grating(query, grid),
        "text" => text::text(query, grid),
        "noise" => noise::noise(query, grid),
        _ => Err(Error::UnknownGenerator(name.to_string())),
    }
}

/// The size and addressing of the map being generated; its size has passed
/// [`HeightMap::check_size`].
#[derive(Clone, Copy, Debug)]
struct Grid {
    width: usize,
    height: usize,
    address: Address,
}

impl Grid {
    fn new(width: usize, height: usize, address: Address) -> Result<Self> {
        HeightMap::check_size(width, height)?;
        Ok(Self {
            width,
            height,
            address,
        })
    }

    /// Texture coordinates of texel `(i, j)`'s centre.
    fn uv(&self, i: usize, j: usize) -> (f64, f64) {
        (
            texel_centre(i, self.width) as f64,
            texel_centre(j, self.height) as f64,
        )
    }

    /// Evaluates `f(i, j)` at every texel, rows in parallel.
    fn fill(&self, f: impl Fn(usize, usize) -> f32 + Sync) -> Vec<f32> {
        let mut data = vec![0.0f32; self.width * self.height];
        data.par_chunks_mut(self.width)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, h) in row.iter_mut().enumerate() {
                    *h = f(i, j);
                }
            });
        data
    }

    fn map(&self, data: Vec<f32>) -> Result<HeightMap> {
        HeightMap::new(self.width, self.height, data, self.address)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPECS: [&str; 7] = [
        "gen:flat",
        "gen:gaussian",
        "gen:studded",
        "gen:grating",
        "gen:grating?crossed=true&duty=0.3&period=5.5",
        "gen:text?text=Hi%20there",
        "gen:noise",
    ];

    #[test]
    fn every_generator_has_the_size_range_and_determinism_asked_for() {
        for spec in SPECS {
            for (w, h) in [(2, 2), (37, 23), (64, 64)] {
                for address in [Address::Clamp, Address::Repeat] {
                    let a = generate(spec, w, h, address).unwrap();
                    assert_eq!(
                        (a.width(), a.height(), a.address()),
                        (w, h, address),
                        "{spec}"
                    );
                    assert!(a.data().iter().all(|v| (0.0..=1.0).contains(v)), "{spec}");
                    let b = generate(spec, w, h, address).unwrap();
                    assert_eq!(a, b, "{spec} is not deterministic");
                }
            }
        }
    }

    #[test]
    fn names_match_the_dispatch() {
        for name in NAMES {
            assert!(
                generate(&format!("gen:{name}"), 8, 8, Address::Clamp).is_ok(),
                "{name}"
            );
        }
    }

    #[test]
    fn unknown_names_and_bad_sizes_are_refused() {
        for spec in ["gen:bumpy", "gen:", "studded", "gen:Flat?level=1"] {
            assert!(
                matches!(
                    generate(spec, 8, 8, Address::Clamp),
                    Err(Error::UnknownGenerator(_))
                ),
                "{spec}"
            );
        }
        assert!(matches!(
            generate("gen:flat", 1, 8, Address::Clamp),
            Err(Error::InvalidHeightMap(_))
        ));
        // Refused before allocating: this would be 4 EiB.
        assert!(matches!(
            generate("gen:noise", 1 << 31, 1 << 31, Address::Clamp),
            Err(Error::TooLarge { .. })
        ));
    }

    #[test]
    fn parameter_errors_name_the_generator_and_key() {
        let cases = [
            ("gen:flat?level=2", "flat", "level"),
            ("gen:flat?height=1", "flat", "height"),
            ("gen:gaussian?scale=0", "gaussian", "scale"),
            ("gen:studded?period=0", "studded", "period"),
            ("gen:studded?period=2.5", "studded", "period"),
            ("gen:grating?duty=1.5", "grating", "duty"),
            ("gen:grating?crossed=maybe", "grating", "crossed"),
            ("gen:text?size=-3", "text", "size"),
            ("gen:noise?octaves=0", "noise", "octaves"),
            ("gen:noise?seed=-1", "noise", "seed"),
            ("gen:noise?gain=x", "noise", "gain"),
        ];
        for (spec, generator, key) in cases {
            match generate(spec, 16, 16, Address::Clamp) {
                Err(Error::GeneratorParameter {
                    generator: g,
                    message,
                }) => {
                    assert_eq!(g, generator, "{spec}");
                    assert!(message.contains(&format!("`{key}`")), "{spec}: {message}");
                    assert!(message.contains("accepted parameters"), "{spec}: {message}");
                }
                other => panic!("{spec}: expected a parameter error, got {other:?}"),
            }
        }
    }
}
