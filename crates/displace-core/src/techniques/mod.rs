//! The per-pixel displacement techniques that engines ship today, beside
//! distance mapping, behind one interface so that `displace compare` can
//! measure them against the exact reference on the same rays (BENCHMARKS.md).
//!
//! Everything is in map space ([`crate::convention`]): `z` up, lengths in
//! shell depths, one tile `[0, ax] x [0, ay] x [0, 1]`, surface
//! `z = h(x / ax, y / ay)` with bilinear heights ([`HeightMap::sample`]).
//! The papers work in texture space with *depth* going down from the
//! polygon (`depth = 1 - z`, surface depth `1 - h`); each technique maps its
//! loop onto `z = 1 - depth` and says where.
//!
//! A ray enters the shell from above (clipped by [`sphere_trace::clip`],
//! the same slabs the sphere tracer uses) and each technique spends a
//! `budget` (layers, steps or node visits). It returns the hit it believes
//! in and the texture fetches it made, counted the same way for all: one
//! bilinear height sample = 1, one trilinear distance sample = 1, one cone
//! or pyramid texel = 1, one bilinear patch solved exactly = 1 (its four
//! texels are one gather). Each technique is a small pure function, easy to
//! port to WGSL.

mod cone;
mod distance;
mod linear;
mod max_mip;
mod parallax;

pub use cone::{ConeKind, ConeMap};
pub(crate) use max_mip::max_levels;
pub use max_mip::MaxPyramid;

use crate::sphere_trace::{self, MapRay};
use crate::{DisplacementMap, Error, HeightMap, Result};
use glam::{Vec2, Vec3};

/// A technique's answer for one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (depth units from the ray's origin).
    pub t: f32,
    /// Map space, depth units.
    pub position: Vec3,
    /// Texture coordinate the technique shades with.
    pub uv: Vec2,
}

/// Hit (or miss) plus what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Traced {
    /// The hit the technique believes in; `None` when it says the ray misses.
    pub hit: Option<Hit>,
    /// Texture fetches spent, counted alike for every technique (module docs).
    pub fetches: u32,
}

/// Every technique `displace compare` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Technique {
    /// Parallax mapping with offset limiting (Welsh 2004): one fetch.
    Parallax,
    /// Steep parallax (McGuire and McGuire 2005): `budget` layers, the first
    /// layer under the surface is the hit.
    Steep,
    /// Parallax occlusion mapping (Tatarchuk 2006): between `budget / 4`
    /// and `budget` layers by view angle, then the two last samples
    /// interpolated.
    Pom,
    /// Bevy's `ParallaxMappingMethod::Occlusion` with
    /// `max_parallax_layer_count = budget` (Bevy's default is 16).
    BevyOcclusion,
    /// Bevy's `ParallaxMappingMethod::Relief { max_steps: 5 }` with
    /// `max_parallax_layer_count = budget`.
    BevyRelief,
    /// Relief mapping (Policarpo et al. 2005): `budget` linear steps, then
    /// a binary search.
    Relief,
    /// Cone step mapping (Dummer 2006), conservative cones.
    Cone,
    /// Relaxed cone stepping (Policarpo and Oliveira, GPU Gems 3 ch. 18),
    /// then a binary search.
    RelaxedCone,
    /// Maximum mipmaps (Tevs, Ihrke and Seidel 2008): a max pyramid walked
    /// to the exact hit.
    MaxMip,
    /// Distance mapping as Donnelly has it (listing 8-2): `budget` sphere-tracing steps
    /// ([`crate::Method::SphereFixed`]).
    DistanceFixed,
    /// Ours: sphere tracing with early out and exact refinement
    /// ([`crate::Method::Sphere`]).
    Distance,
}

impl Technique {
    /// Every technique; the WGSL technique codes follow this order.
    pub const ALL: [Technique; 11] = [
        Technique::Parallax,
        Technique::Steep,
        Technique::Pom,
        Technique::BevyOcclusion,
        Technique::BevyRelief,
        Technique::Relief,
        Technique::Cone,
        Technique::RelaxedCone,
        Technique::MaxMip,
        Technique::DistanceFixed,
        Technique::Distance,
    ];

    /// The name [`str::parse`] accepts and reports print.
    pub fn name(self) -> &'static str {
        match self {
            Technique::Parallax => "parallax",
            Technique::Steep => "steep",
            Technique::Pom => "pom",
            Technique::BevyOcclusion => "bevy-occlusion",
            Technique::BevyRelief => "bevy-relief",
            Technique::Relief => "relief",
            Technique::Cone => "cone",
            Technique::RelaxedCone => "relaxed-cone",
            Technique::MaxMip => "max-mip",
            Technique::DistanceFixed => "distance-fixed",
            Technique::Distance => "distance",
        }
    }

    /// False for parallax, whose one step ignores the budget.
    pub fn uses_budget(self) -> bool {
        self != Technique::Parallax
    }

    /// What precomputation it reads besides the height map.
    pub fn needs(self) -> Needs {
        match self {
            Technique::Cone => Needs::ConservativeCones,
            Technique::RelaxedCone => Needs::RelaxedCones,
            Technique::MaxMip => Needs::Pyramid,
            Technique::DistanceFixed | Technique::Distance => Needs::DistanceMap,
            _ => Needs::Nothing,
        }
    }

    /// Traces `ray` with `budget` on `maps`. Fails only when `maps` lacks the
    /// precomputation this technique needs.
    pub fn trace(self, maps: &Maps, ray: &MapRay, budget: u32) -> Result<Traced> {
        let missing = || Error::InvalidTrace(format!("{} needs {:?}", self.name(), self.needs()));
        let budget = budget.max(1);
        if self.needs() == Needs::DistanceMap {
            let map = maps.displacement.as_ref().ok_or_else(missing)?;
            return Ok(distance::trace(
                map,
                ray,
                budget,
                self == Technique::Distance,
            ));
        }
        let Some(seg) = Segment::new(&maps.height, maps.aspect, ray) else {
            return Ok(Traced {
                hit: None,
                fetches: 0,
            });
        };
        Ok(match self {
            Technique::Parallax => parallax::trace(&seg),
            Technique::Steep => linear::steep(&seg, budget),
            Technique::Pom => linear::pom(&seg, budget),
            Technique::BevyOcclusion => linear::bevy(&seg, budget, None),
            Technique::BevyRelief => linear::bevy(&seg, budget, Some(linear::BEVY_RELIEF_STEPS)),
            Technique::Relief => linear::relief(&seg, budget),
            Technique::Cone => cone::trace(&seg, maps.cones.as_ref().ok_or_else(missing)?, budget),
            Technique::RelaxedCone => {
                cone::trace(&seg, maps.relaxed.as_ref().ok_or_else(missing)?, budget)
            }
            Technique::MaxMip => {
                max_mip::trace(&seg, maps.pyramid.as_ref().ok_or_else(missing)?, budget)
            }
            Technique::DistanceFixed | Technique::Distance => unreachable!("handled above"),
        })
    }
}

impl std::str::FromStr for Technique {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Technique::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Technique::ALL.iter().map(|t| t.name()).collect();
                Error::InvalidTrace(format!(
                    "unknown technique `{s}` (expected one of {})",
                    names.join(", ")
                ))
            })
    }
}

/// The precomputation a technique reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Needs {
    /// The height map alone (the parallax and relief families).
    Nothing,
    /// Conservative cone ratios (Dummer 2006 cone step mapping).
    ConservativeCones,
    /// Relaxed cone ratios (Policarpo and Oliveira, GPU Gems 3 ch. 18).
    RelaxedCones,
    /// The maximum mipmap (Tevs, Ihrke and Seidel 2008).
    Pyramid,
    /// The baked distance map (Donnelly, GPU Gems 2 ch. 8).
    DistanceMap,
}

/// One height map and whatever precomputations were built for it.
#[derive(Clone, Debug)]
pub struct Maps {
    /// The heights every technique samples.
    pub height: HeightMap,
    /// Tile size in shell depths (`Extent::aspect`).
    pub aspect: [f32; 2],
    /// Conservative cone map, for [`Technique::Cone`].
    pub cones: Option<ConeMap>,
    /// Relaxed cone map, for [`Technique::RelaxedCone`].
    pub relaxed: Option<ConeMap>,
    /// Maximum mipmap, for [`Technique::MaxMip`].
    pub pyramid: Option<MaxPyramid>,
    /// Baked distance map, for the two distance techniques.
    pub displacement: Option<DisplacementMap>,
}

impl Maps {
    /// Only the height map: enough for parallax, POM and relief.
    pub fn new(height: HeightMap, aspect: [f32; 2]) -> Self {
        Self {
            height,
            aspect,
            cones: None,
            relaxed: None,
            pyramid: None,
            displacement: None,
        }
    }
}

/// The part of a ray a technique searches: from where it enters the shell
/// to where it would reach the shell's floor `z = 0` (depth 1), which may
/// lie past the side the ray leaves through (`t_out`). Texture-space
/// techniques parametrise the ray by depth over this stretch; a hit they
/// find beyond `t_out` is off the face and counts as a miss.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Segment<'a> {
    pub height: &'a HeightMap,
    pub aspect: [f32; 2],
    pub ray: MapRay,
    pub t_in: f32,
    pub t_out: f32,
    /// `z` at `t_in` (1 for a ray from above).
    pub z_in: f32,
}

impl<'a> Segment<'a> {
    /// `None` when the ray misses the shell or does not go down.
    fn new(height: &'a HeightMap, aspect: [f32; 2], ray: &MapRay) -> Option<Self> {
        if ray.dir.z >= 0.0 {
            return None;
        }
        let hi = Vec3::new(aspect[0], aspect[1], 1.0);
        let clip = sphere_trace::clip(ray, hi, 0.0, f32::INFINITY)?;
        Some(Self {
            height,
            aspect,
            ray: *ray,
            t_in: clip.t_in,
            t_out: clip.t_out,
            z_in: ray.origin.z + ray.dir.z * clip.t_in,
        })
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.ray.origin + self.ray.dir * t
    }

    /// Ray parameter where the ray's depth below the shell top is `depth`.
    pub fn t_at_depth(&self, depth: f32) -> f32 {
        self.t_in + ((1.0 - depth) - self.z_in) / self.ray.dir.z
    }

    /// Depth at which the ray enters (0 from above).
    pub fn depth_in(&self) -> f32 {
        1.0 - self.z_in
    }

    pub fn uv(&self, p: Vec3) -> Vec2 {
        Vec2::new(p.x / self.aspect[0], p.y / self.aspect[1])
    }

    /// The surface height under map-space `p` (one bilinear fetch).
    pub fn height_at(&self, p: Vec3) -> f32 {
        self.height
            .sample(p.x / self.aspect[0], p.y / self.aspect[1])
    }

    /// The answer for the ray point at `t`, or a miss when it is off the
    /// face (past `t_out`).
    pub fn hit_at(&self, t: f32, fetches: u32) -> Traced {
        let hit = (t <= self.t_out * (1.0 + 1e-6) + 1e-6).then(|| {
            let position = self.at(t);
            Hit {
                t,
                position,
                uv: self.uv(position),
            }
        });
        Traced { hit, fetches }
    }
}
