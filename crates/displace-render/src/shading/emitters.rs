//! The lights of the path integrator, gathered in one list so that
//! next-event estimation picks one per vertex in proportion to its power
//! (pbrt-v4 section 12.6.3, `PowerLightSampler`) and multiple importance
//! sampling can ask, for a direction found by BSDF sampling, how likely
//! light sampling was to choose it (Veach 1997, section 9.2):
//!
//! - the scene's `[[lights]]` but its `fill` lights (point lights are delta
//!   lights; area lights emit from their front and are sampled uniformly by
//!   area, pbrt-v4 section 12.2),
//! - every plain quad, triangle and sphere whose material has `emission`
//!   (two-sided; sampled uniformly by area),
//! - the environment (the constant `background` or the map), when it sends
//!   any light.
//!
//! An emitting *displaced* face is not in the list (its displaced area has
//! no cheap uniform sampler): paths find it by BSDF sampling alone, with
//! MIS weight 1, which keeps the estimate unbiased.

use crate::distribution::Distribution1D;
use crate::environment::Environment;
use crate::light::Light;
use crate::material::Material;
use crate::scene::world::{Primitive, Shape};
use crate::shapes::{Quad, Sphere, Triangle};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// No emitter.
const NONE: u32 = u32::MAX;

/// One light of the path integrator.
#[derive(Clone, Debug)]
pub enum Emitter {
    /// Radiant intensity from a point (a delta light).
    Point {
        /// Where the light is.
        position: Vec3,
        /// Radiant intensity (W/sr per channel).
        intensity: Vec3,
    },
    /// A parallelogram emitting `radiance` from its front (`[[lights]]`
    /// area light) or from both sides (an emitting quad); `visible`: rays
    /// can hit it (else BSDF sampling never finds it and light sampling
    /// takes its whole weight).
    Quad {
        /// The emitting parallelogram.
        quad: Quad,
        /// Emitted radiance.
        radiance: Vec3,
        /// Emits from both sides (an emitting shape) or from the front only
        /// (an area light).
        two_sided: bool,
        /// Rays can hit it.
        visible: bool,
    },
    /// An emitting triangle, both sides.
    Triangle {
        /// The emitting triangle.
        tri: Triangle,
        /// Emitted radiance.
        radiance: Vec3,
    },
    /// An emitting sphere, sampled uniformly over its area.
    Sphere {
        /// The emitting sphere.
        sphere: Sphere,
        /// Emitted radiance.
        radiance: Vec3,
    },
    /// The light of escaping rays.
    Environment,
}

/// A point (or direction) on a light chosen by next-event estimation.
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample {
    /// The point on the light, `None` for the environment (then `wi` alone
    /// says where the light comes from).
    pub point: Option<Vec3>,
    /// Unit direction from the receiver towards the light.
    pub wi: Vec3,
    /// Radiance arriving along `wi` (for a point light, the intensity over
    /// the squared distance, its irradiance at normal incidence).
    pub radiance: Vec3,
    /// Solid-angle density of `wi`, times the probability of choosing the
    /// light; 1 for a delta light.
    pub pdf: f32,
    /// Whether BSDF sampling can find this light too (false for point
    /// lights and invisible area lights: no MIS, weight 1).
    pub hittable: bool,
}

/// A quad light as [`Emitters::pick_quad`] hands it out: the fields of
/// [`Emitter::Quad`].
#[derive(Clone, Copy, Debug)]
pub struct QuadLight<'a> {
    /// The emitting parallelogram.
    pub quad: &'a Quad,
    /// Emitted radiance.
    pub radiance: Vec3,
    /// Emits from both sides.
    pub two_sided: bool,
    /// Rays can hit it (BSDF sampling finds it too: multiple importance
    /// sampling applies).
    pub visible: bool,
}

/// The lights of a scene, their selection distribution, and which light
/// each primitive is.
#[derive(Clone, Debug)]
pub struct Emitters {
    list: Vec<Emitter>,
    select: Distribution1D,
    /// Emitter of each primitive (`NONE` if it is none or not sampled).
    of_prim: Vec<u32>,
    /// The environment's index, when it is a light.
    environment: Option<u32>,
    /// Every light is a quad (and there is one to sample): the case the
    /// path integrator's diffuse vertices sample in vector lanes.
    quads_only: bool,
    /// Every emitting surface is in `list`: none is left to BSDF sampling
    /// alone (an emitting displaced or curved face is).
    complete: bool,
}

/// Mean of the three channels: the power light selection weighs by.
fn power_weight(c: Vec3) -> f32 {
    c.element_sum() / 3.0
}

/// Area light emission for a surface point with unit normal `n` seen from
/// `from`: the point, the direction to it, and `|cos|` at the light.
fn towards(from: Vec3, point: Vec3, n: Vec3) -> Option<(Vec3, f32, f32)> {
    let d = point - from;
    let r2 = d.length_squared();
    if !(r2.is_finite() && r2 > 0.0) {
        return None;
    }
    let wi = d / r2.sqrt();
    Some((wi, r2, n.dot(wi)))
}

impl Emitters {
    /// Gathers the lights of a built scene: `fill[i]` marks `lights[i]` a
    /// fill light (left out); `radius` bounds the scene (the environment's
    /// power).
    pub fn new(
        lights: &[Light],
        fill: &[bool],
        prims: &[Primitive],
        materials: &[Material],
        environment: &Environment,
        radius: f32,
    ) -> Self {
        let mut list = Vec::new();
        let mut power = Vec::new();
        let mut of_prim = vec![NONE; prims.len()];
        let mut of_light = vec![NONE; lights.len()];
        for (i, l) in lights.iter().enumerate() {
            if fill.get(i).copied().unwrap_or(false) {
                continue;
            }
            match l {
                Light::Point {
                    position,
                    intensity,
                } => {
                    power.push(4.0 * PI * power_weight(*intensity));
                    list.push(Emitter::Point {
                        position: *position,
                        intensity: *intensity,
                    });
                }
                Light::Area { quad, radiance } => {
                    power.push(PI * quad.area() * power_weight(*radiance));
                    list.push(Emitter::Quad {
                        quad: *quad,
                        radiance: *radiance,
                        two_sided: false,
                        visible: prims.iter().any(|p| p.emitter == Some(i as u32)),
                    });
                }
            }
            of_light[i] = list.len() as u32 - 1;
        }
        for (k, p) in prims.iter().enumerate() {
            if let Some(e) = p.emitter {
                of_prim[k] = of_light[e as usize];
                continue;
            }
            let radiance = materials[p.material as usize].emission;
            if radiance == Vec3::ZERO {
                continue;
            }
            let (e, area) = match &p.shape {
                Shape::Quad(q) => (
                    Emitter::Quad {
                        quad: *q,
                        radiance,
                        two_sided: true,
                        visible: true,
                    },
                    q.area(),
                ),
                Shape::Triangle { tri, .. } => (
                    Emitter::Triangle {
                        tri: *tri,
                        radiance,
                    },
                    0.5 * tri.e1.cross(tri.e2).length(),
                ),
                Shape::Sphere(s) => (
                    Emitter::Sphere {
                        sphere: *s,
                        radiance,
                    },
                    4.0 * PI * s.radius * s.radius,
                ),
                Shape::Displaced(_) | Shape::Curved(_) => continue,
            };
            power.push(2.0 * PI * area * power_weight(radiance));
            list.push(e);
            of_prim[k] = list.len() as u32 - 1;
        }
        // An emitting face left out of the list above (no uniform sampler).
        let complete = !prims.iter().any(|p| {
            matches!(p.shape, Shape::Displaced(_) | Shape::Curved(_))
                && p.emitter.is_none()
                && materials[p.material as usize].emission != Vec3::ZERO
        });
        let mut env = None;
        if !environment.is_black() {
            power.push(power_weight(environment.power(radius)));
            list.push(Emitter::Environment);
            env = Some(list.len() as u32 - 1);
        }
        // A light of no power is never chosen (its weight is 0).
        let select = Distribution1D::new(&power);
        let quads_only = select.total() > 0.0
            && !list.is_empty()
            && list.iter().all(|e| matches!(e, Emitter::Quad { .. }));
        Self {
            select,
            list,
            of_prim,
            environment: env,
            quads_only,
            complete,
        }
    }

    /// Whether light sampling can reach every emitting surface: no
    /// emitting displaced or curved face, which only BSDF sampling finds.
    /// Then light sampling alone is an unbiased estimate of the light a
    /// vertex receives directly (Veach 1997, section 9.2: each of the
    /// combined techniques is unbiased by itself).
    pub fn complete(&self) -> bool {
        self.complete
    }

    /// Whether every light is a quad and one can be chosen: then
    /// [`Emitters::pick_quad`] answers every pick.
    pub fn quads_only(&self) -> bool {
        self.quads_only
    }

    /// The first half of [`Emitters::sample`] where the lights are quads:
    /// the light that `pick` chooses (by power) and the probability of
    /// choosing it, for callers that sample the quad themselves, many
    /// receivers at once (the path integrator's vertices in vector lanes).
    /// `None` where the chosen light is not a quad or has probability 0
    /// (then `sample` would give `None` too).
    pub fn pick_quad(&self, pick: f32) -> Option<(QuadLight<'_>, f32)> {
        let (k, pmf) = self.select.choose(pick);
        match &self.list[k] {
            Emitter::Quad {
                quad,
                radiance,
                two_sided,
                visible,
            } if pmf > 0.0 => Some((
                QuadLight {
                    quad,
                    radiance: *radiance,
                    two_sided: *two_sided,
                    visible: *visible,
                },
                pmf,
            )),
            _ => None,
        }
    }

    /// Whether there is no light to sample.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty() || self.select.total() <= 0.0
    }

    /// Number of lights (fill lights and displaced emitters not counted).
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// Chooses a light (by `pick`) and a point on it (by `u`) for a
    /// receiver at `from`; `None` when there are no lights or the sample
    /// carries no light.
    pub fn sample(
        &self,
        env: &Environment,
        from: Vec3,
        pick: f32,
        u: Vec2,
    ) -> Option<EmitterSample> {
        if self.is_empty() {
            return None;
        }
        let (k, pmf, _) = self.select.sample_discrete(pick);
        if pmf <= 0.0 {
            return None;
        }
        let area_sample = |point: Vec3, n: Vec3, area: f32, radiance: Vec3, two_sided: bool| {
            let (wi, r2, cos) = towards(from, point, n)?;
            // Light leaves the front when the receiver is in front: n . wi < 0.
            let cos_l = if two_sided { cos.abs() } else { -cos };
            (cos_l > 0.0).then(|| EmitterSample {
                point: Some(point),
                wi,
                radiance,
                pdf: pmf * r2 / (cos_l * area),
                hittable: true,
            })
        };
        match &self.list[k] {
            Emitter::Point {
                position,
                intensity,
            } => {
                let (wi, r2, _) = towards(from, *position, Vec3::Z)?;
                Some(EmitterSample {
                    point: Some(*position),
                    wi,
                    radiance: *intensity / r2,
                    pdf: pmf,
                    hittable: false,
                })
            }
            Emitter::Quad {
                quad,
                radiance,
                two_sided,
                visible,
            } => area_sample(
                quad.point(u),
                quad.normal,
                quad.area(),
                *radiance,
                *two_sided,
            )
            .map(|s| EmitterSample {
                hittable: *visible,
                ..s
            }),
            Emitter::Triangle { tri, radiance } => {
                // Uniform barycentrics (pbrt-v4 section 6.5.4, square-root map).
                let s = u.x.sqrt();
                let b = Vec2::new(1.0 - s, u.y * s);
                let p = tri.p0 + b.x * tri.e1 + b.y * tri.e2;
                let area = 0.5 * tri.e1.cross(tri.e2).length();
                area_sample(p, tri.normal(), area, *radiance, true)
            }
            Emitter::Sphere { sphere, radiance } => {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                let n = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                let area = 4.0 * PI * sphere.radius * sphere.radius;
                area_sample(sphere.center + sphere.radius * n, n, area, *radiance, true)
            }
            Emitter::Environment => {
                let s = env.sample(u)?;
                Some(EmitterSample {
                    point: None,
                    wi: s.wi,
                    radiance: s.radiance,
                    pdf: pmf * s.pdf,
                    hittable: true,
                })
            }
        }
    }

    /// The density with which [`Emitters::sample`] from `from` chooses the
    /// point `point` (normal `n`) of primitive `prim`: 0 when the primitive
    /// is no sampled light.
    pub fn pdf_hit(&self, prim: u32, from: Vec3, point: Vec3, n: Vec3) -> f32 {
        let k = self.of_prim.get(prim as usize).copied().unwrap_or(NONE);
        if k == NONE {
            return 0.0;
        }
        let area = match &self.list[k as usize] {
            Emitter::Quad { quad, .. } => quad.area(),
            Emitter::Triangle { tri, .. } => 0.5 * tri.e1.cross(tri.e2).length(),
            Emitter::Sphere { sphere, .. } => 4.0 * PI * sphere.radius * sphere.radius,
            Emitter::Point { .. } | Emitter::Environment => return 0.0,
        };
        let Some((_, r2, cos)) = towards(from, point, n) else {
            return 0.0;
        };
        let cos = cos.abs();
        if cos <= 0.0 {
            return 0.0;
        }
        self.select.pmf(k as usize) * r2 / (cos * area)
    }

    /// The density with which [`Emitters::sample`] chooses the environment
    /// in unit direction `d`.
    pub fn pdf_environment(&self, env: &Environment, d: Vec3) -> f32 {
        self.environment
            .map_or(0.0, |k| self.select.pmf(k as usize) * env.pdf(d))
    }
}
