//! How a scene asks to be rendered, apart from what it holds: the light
//! transport algorithm ([`Integrator`]) and the path tracer's estimators of
//! direct light ([`Sampling`]), read from `image.integrator` and
//! `image.sampling` (or the command line) and handed to the integrators.

use crate::error::Error;
use displace_core::names::parse_known;

/// The light transport algorithm of a render (`image.integrator`,
/// `--integrator`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// The seed's Whitted ray tracer with distributed effects
    /// (displace-render's `integrators::whitted`).
    #[default]
    Whitted,
    /// Path tracing with next-event estimation and MIS (displace-render's `integrators::path`).
    Path,
}

impl Integrator {
    /// The name a scene file and the command line use.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Whitted => "whitted",
            Integrator::Path => "path",
        }
    }
}

impl std::str::FromStr for Integrator {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self, Error> {
        let choices = [Self::Whitted, Self::Path].map(|i| (i.name(), i));
        parse_known("integrator", s, &choices).map_err(Error::Option)
    }
}

/// Which estimators of direct light the path integrator combines
/// (`image.sampling`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Sampling {
    /// Light sampling and BSDF sampling, power heuristic (the default).
    #[default]
    Mis,
    /// Light sampling alone: emitters that paths hit count only where light
    /// sampling cannot reach them (after a mirror, the camera's own view,
    /// lights no sampler knows).
    Light,
    /// BSDF sampling alone: lights are sampled only where BSDF sampling
    /// cannot find them (point lights, invisible area lights).
    Bsdf,
}

impl std::str::FromStr for Sampling {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self, Error> {
        let choices = [
            ("mis", Self::Mis),
            ("light", Self::Light),
            ("bsdf", Self::Bsdf),
        ];
        parse_known("sampling", s, &choices).map_err(Error::Option)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_bad_ones_are_listed() {
        assert_eq!("path".parse::<Integrator>().unwrap(), Integrator::Path);
        assert_eq!(
            "whitted".parse::<Integrator>().unwrap(),
            Integrator::Whitted
        );
        let e = "bogus".parse::<Integrator>().unwrap_err().to_string();
        assert!(e.contains("bogus") && e.contains("whitted, path"), "{e}");
        assert_eq!("bsdf".parse::<Sampling>().unwrap(), Sampling::Bsdf);
        assert!("both".parse::<Sampling>().is_err());
    }
}
