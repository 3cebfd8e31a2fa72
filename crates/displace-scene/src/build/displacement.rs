//! A shape's `displacement` table: its checks, its bake (through the
//! cache, one per height source and proportions), and the prism of one
//! triangle of a displaced triangle or mesh in its texture frame, `dP/du`
//! and `dP/dv` from the corners' texture coordinates as pbrt-v4 derives a
//! triangle's partial derivatives (section 6.5).

use super::super::spec::{DisplacementSpec, HeightRangeSpec};
use super::ctx::Ctx;
use crate::curved_shell::CurvedShell;
use crate::error::{Error, Result};
use crate::mesh::MeshTriangle;
use crate::mesh_shells::MeshShells;
use crate::placed::MeshDisplacement;
use crate::placed::{CurvedDisplacement, FaceFrame, FlatDisplacement};
use crate::shapes::Triangle;
use crate::texture::Texture;
use displace_core::convention::MAX_TRACE_ITERATIONS;
use displace_core::io::height::HeightRange;
use displace_core::{Address, Extent, Method, TraceOptions};
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// The displacement of a shape, or `None` when there is none or its depth is
/// 0 (a zero-depth displacement is the plain face).
pub(super) fn displacement_of<'a>(
    cx: &Ctx,
    d: &'a Option<DisplacementSpec>,
    what: &str,
) -> Result<Option<&'a DisplacementSpec>> {
    let Some(d) = d else { return Ok(None) };
    if !(d.depth >= 0.0 && d.depth.is_finite()) {
        return Err(cx.err(format!(
            "{what}.displacement.depth must be a finite number >= 0, got {}",
            d.depth
        )));
    }
    Ok((d.depth > 0.0).then_some(d))
}

/// `(|dP/du|, |dP/dv|)` and `(dP/du, dP/dv)` of a triangle's texture
/// parameterisation, or `None` if its coordinates are degenerate.
pub(super) fn triangle_frame(tri: &Triangle, uv: &[Vec2; 3]) -> Option<(Vec2, (Vec3, Vec3))> {
    let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
    let det = d1.x * d2.y - d2.x * d1.y;
    if det.abs() < 1e-12 || !det.is_finite() {
        return None;
    }
    let dpdu = (d2.y * tri.e1 - d1.y * tri.e2) / det;
    let dpdv = (-d2.x * tri.e1 + d1.x * tri.e2) / det;
    Some((Vec2::new(dpdu.length(), dpdv.length()), (dpdu, dpdv)))
}

/// A validated displacement with its bake, ready to make faces.
pub(super) struct DispBuild {
    pub(super) map: Arc<displace_core::DisplacementMap>,
    pub(super) depth: f32,
    pub(super) trace: TraceOptions,
    pub(super) address: Address,
    pub(super) color: Option<Arc<Texture>>,
    pub(super) normal_map: Option<Arc<Texture>>,
}

impl DispBuild {
    /// `tile` is the world size of one tile (`|dP/du|`, `|dP/dv|`).
    pub(super) fn new(cx: &mut Ctx, d: &DisplacementSpec, tile: Vec2, what: &str) -> Result<Self> {
        let what = format!("{what}.displacement");
        let address: Address = d
            .address
            .parse()
            .map_err(|e: displace_core::Error| cx.err(format!("{what}.address: {e}")))?;
        let method: Method = d
            .method
            .parse()
            .map_err(|e: displace_core::Error| cx.err(format!("{what}.method: {e}")))?;
        let hs = d.height_size;
        if hs.iter().any(|&n| !(2..=1 << 16).contains(&n)) {
            return Err(cx.err(format!(
                "{what}.height_size must be 2..65536 texels per side, got {hs:?}"
            )));
        }
        let ms = d.map_size;
        if ms.iter().any(|&n| !(2..=1 << 14).contains(&n)) {
            return Err(cx.err(format!(
                "{what}.map_size must be 2..16384 voxels per side, got {ms:?}"
            )));
        }
        let iterations = cx.bounded(
            d.iterations,
            MAX_TRACE_ITERATIONS.into(),
            &format!("{what}.iterations"),
        )?;
        if d.tiles.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(cx.err(format!("{what}.tiles must be positive, got {:?}", d.tiles)));
        }
        if address == Address::Clamp && d.tiles != [1.0, 1.0] {
            return Err(cx.err(format!(
                "{what}.tiles: a clamped map covers one tile; use address = \"repeat\" to tile it"
            )));
        }
        let range = match &d.height_range {
            None => Ok(HeightRange::AsStored),
            Some(HeightRangeSpec::Named(s)) => s.parse(),
            Some(HeightRangeSpec::Span([lo, hi])) => HeightRange::span(*lo as f32, *hi as f32),
        }
        .map_err(|e: displace_core::Error| cx.err(format!("{what}.height_range: {e}")))?;
        let size = [hs[0] as usize, hs[1] as usize];
        let key = (d.height.clone(), size, address, format!("{range:?}"));
        let map_size = [ms[0] as usize, ms[1] as usize, ms[2] as usize];
        let core_err = |cx: &Ctx, e: Error| match e {
            Error::Core(c) => cx.err(format!("{what}.height `{}`: {c}", d.height)),
            other => other,
        };
        if cx.planned.insert((key.clone(), map_size)) {
            // A new bake: its peak on top of what the scene holds already.
            let texels = crate::heights::dimensions(&d.height, size, address, range, cx.base)
                .map_err(|e| core_err(cx, e))?;
            cx.reserve(
                &format!(
                    "{what}: baking the {}x{} height map into {}x{}x{} voxels",
                    texels[0], texels[1], map_size[0], map_size[1], map_size[2]
                ),
                displace_core::memory::bake_peak_bytes(texels, map_size, false),
            )?;
        }
        let height = match cx.heights.get(&key) {
            Some(h) => h.clone(),
            None => {
                let h = Arc::new(
                    crate::heights::load(&d.height, size, address, range, cx.base)
                        .map_err(|e| core_err(cx, e))?,
                );
                if !d.height.starts_with("gen:") {
                    let file = cx.base.join(&d.height);
                    cx.source(file);
                }
                cx.heights.insert(key, h.clone());
                h
            }
        };
        let extent =
            Extent::new(tile.x, tile.y, d.depth).map_err(|e| cx.err(format!("{what}: {e}")))?;
        let map = cx.cache.get(&height, map_size, extent)?;
        let color = d
            .color_texture
            .as_ref()
            .map(|f| cx.texture(f, true, &format!("{what}.color_texture")))
            .transpose()?;
        let normal_map = d
            .normal_map
            .as_ref()
            .map(|f| cx.texture(f, false, &format!("{what}.normal_map")))
            .transpose()?;
        Ok(Self {
            map,
            depth: d.depth,
            trace: TraceOptions {
                method: cx.method.unwrap_or(method),
                iterations,
                tiles: d.tiles,
                ..TraceOptions::default()
            },
            address,
            color,
            normal_map,
        })
    }

    /// What every face of this displacement shares, for [`SceneMesh`],
    /// with the mesh's `shells`.
    pub(super) fn shared(&self, shells: MeshShells) -> MeshDisplacement {
        MeshDisplacement {
            map: self.map.clone(),
            depth: self.depth,
            trace: self.trace,
            textured: self.color.is_some() || self.normal_map.is_some(),
            shells,
        }
    }

    pub(super) fn finish(
        &self,
        face: Option<FlatDisplacement>,
        cx: &Ctx,
        what: &str,
    ) -> Result<FlatDisplacement> {
        let mut face =
            face.ok_or_else(|| cx.err(format!("{what}: the displaced face is degenerate")))?;
        face.color = self.color.clone();
        face.normal_map = self.normal_map.clone();
        Ok(face)
    }

    pub(super) fn triangle(
        &self,
        cx: &Ctx,
        tri: &Triangle,
        uv: &[Vec2; 3],
        what: &str,
    ) -> Result<FlatDisplacement> {
        let (_, (dpdu, dpdv)) = triangle_frame(tri, uv)
            .ok_or_else(|| cx.err(format!("{what}: degenerate texture coordinates")))?;
        let (trace, shift, local) = self.window(cx, uv, what)?;
        let frame = FaceFrame {
            origin: tri.p0 - local[0].x * dpdu - local[0].y * dpdv,
            dpdu,
            dpdv,
            normal: tri.normal(),
            depth: self.depth,
        };
        let face = FlatDisplacement::new(frame, self.map.clone(), trace, Some(local), shift);
        self.finish(face, cx, what)
    }

    /// The map window of a triangle with texture coordinates `uv`: its
    /// trace options (a repeating map's `tiles` grown to the tiles the
    /// coordinates touch), the whole-tile shift that brings them into
    /// `[0, tiles]`, and the shifted coordinates.
    fn window(
        &self,
        cx: &Ctx,
        uv: &[Vec2; 3],
        what: &str,
    ) -> Result<(TraceOptions, Vec2, [Vec2; 3])> {
        let lo = uv[0].min(uv[1]).min(uv[2]);
        let hi = uv[0].max(uv[1]).max(uv[2]);
        let mut trace = self.trace;
        let shift = match self.address {
            Address::Clamp => {
                if lo.min_element() < -1e-6 || hi.max_element() > 1.0 + 1e-6 {
                    return Err(cx.err(format!(
                        "{what}: texture coordinates leave [0, 1] but the displacement clamps; use address = \"repeat\""
                    )));
                }
                Vec2::ZERO
            }
            Address::Repeat => {
                let s = lo.floor();
                let t = (hi - s).ceil().max(Vec2::ONE);
                trace.tiles = [t.x, t.y];
                s
            }
        };
        self.check_trace(cx, &trace, what)?;
        let local =
            uv.map(|c| (c - shift).clamp(Vec2::ZERO, Vec2::new(trace.tiles[0], trace.tiles[1])));
        Ok((trace, shift, local))
    }

    /// The map's own checks of `trace` (the cells its tiles span), under
    /// the scene key `what`.
    pub(super) fn check_trace(&self, cx: &Ctx, trace: &TraceOptions, what: &str) -> Result<()> {
        self.map
            .check_trace(trace)
            .map_err(|e| cx.err(format!("{what}.displacement: {e}")))
    }

    /// The curved face over mesh triangle `t`, whose unit vertex normals
    /// the shell follows, topped at `top` (one level for the whole mesh,
    /// so neighbours share their sides), `shared` saying which sides a
    /// neighbour continues; `None` when `t` has no normals.
    pub(super) fn curved_triangle(
        &self,
        cx: &Ctx,
        t: &MeshTriangle,
        top: f64,
        shared: [bool; 3],
        what: &str,
    ) -> Result<CurvedDisplacement> {
        let (corners, uv) = (t.positions, &t.uvs);
        let normals = t
            .normals
            .ok_or_else(|| cx.err(format!("{what}: a curved triangle needs vertex normals")))?;
        let (trace, shift, local) = self.window(cx, uv, what)?;
        let shell = CurvedShell::new(corners, normals, self.depth, top)
            .ok_or_else(|| cx.err(format!("{what}: the displaced triangle is degenerate")))?;
        let mut face =
            CurvedDisplacement::new(shell, self.map.clone(), trace, local, shift, shared)
                .ok_or_else(|| cx.err(format!("{what}: degenerate texture coordinates")))?;
        face.color = self.color.clone();
        face.normal_map = self.normal_map.clone();
        Ok(face)
    }
}
