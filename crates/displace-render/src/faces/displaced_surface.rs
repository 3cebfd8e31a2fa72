//! The displaced surface of a mesh, tessellated: `S = P + depth h(uv) N`,
//! with the position `P`, the normal `N` (normalised after interpolation)
//! and the texture coordinate `uv` interpolated barycentrically over each
//! triangle, and `h` the bilinear height surface. It is the surface a
//! renderer draws when it subdivides a mesh finely and moves every vertex
//! along its interpolated normal (pbrt-v4's and Cycles' displacement), and
//! the one curved shells must reproduce: the distance-map ray tracer's
//! paper names "displacement maps on spheres, and even on arbitrary
//! objects" as its future work, and Donnelly (GPU Gems 2, 8.7) notes that
//! a locally flat mapping "results in distortion in regions of high
//! curvature".
//!
//! Each triangle is cut into `n x n` sub-triangles on the lattice of
//! barycentric points `(i, j) / n`, with one `n` for the whole mesh (so
//! neighbouring triangles cut their shared edge at the same points and the
//! result has no T-junctions), chosen so that no sub-edge spans more than
//! `edge_texels` height texels. A point on an edge is computed from the
//! edge's two corners in an order fixed by their values, not by the
//! triangle, so two triangles that share the edge's corners put their
//! points there bit for bit at the same place: the tessellation is
//! watertight wherever the mesh shares positions, normals and texture
//! coordinates (it opens, as the surface `S` does, at creases and texture
//! seams). The lattice is generated point by point, so a writer streams it
//! ([`DisplacedSurface::each_vertex`], [`DisplacedSurface::each_triangle`]).

use crate::error::{Error, Result};
use crate::mesh::MeshTriangle;
use displace_core::HeightMap;
use glam::{Vec2, Vec3};

/// Most sub-triangles a tessellation may have (an OBJ of that many is tens
/// of gigabytes already).
pub const MAX_TRIANGLES: u64 = 1 << 28;

/// Longest sub-edge the ground truth of the curved-surface tests uses, in
/// height texels: a quarter texel samples the bilinear surface finely
/// enough that the tessellation's own error is far under the tests'.
pub const REFERENCE_EDGE_TEXELS: f32 = 0.25;

/// One point of the tessellation: on the displaced surface, with the
/// texture coordinate it was lifted at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// `P + depth h(uv) N`, world space.
    pub position: Vec3,
    /// The interpolated texture coordinate.
    pub uv: Vec2,
}

/// A mesh's displaced surface, tessellated on demand: `triangles` (world
/// space, texture coordinates as the height map reads them) lifted by
/// `depth` times the heights of `height`.
pub struct DisplacedSurface<'a> {
    triangles: &'a [MeshTriangle],
    height: &'a HeightMap,
    depth: f32,
    n: u32,
}

impl<'a> DisplacedSurface<'a> {
    /// The tessellation whose sub-edges span at most `edge_texels` texels
    /// of `height` (measured in texture space: `|du| * width`,
    /// `|dv| * height`), refusing empty meshes, non-finite input and more
    /// than [`MAX_TRIANGLES`] sub-triangles before anything is generated.
    pub fn new(
        triangles: &'a [MeshTriangle],
        height: &'a HeightMap,
        depth: f32,
        edge_texels: f32,
    ) -> Result<Self> {
        if !(edge_texels.is_finite() && edge_texels > 0.0) {
            return Err(Error::Option(format!(
                "the longest sub-edge must be a positive number of texels, got {edge_texels}"
            )));
        }
        if !depth.is_finite() {
            return Err(Error::Option(format!("displacement depth {depth}")));
        }
        if triangles.is_empty() {
            return Err(Error::Option("the mesh has no triangles".into()));
        }
        let texels = Vec2::new(height.width() as f32, height.height() as f32);
        let mut longest = 0.0f32;
        for t in triangles {
            let finite = t.positions.iter().all(|p| p.is_finite())
                && t.uvs.iter().all(|uv| uv.is_finite())
                && t.normals.is_none_or(|ns| ns.iter().all(|n| n.is_finite()));
            if !finite {
                return Err(Error::Option(
                    "a mesh triangle has a non-finite position, normal or texture coordinate"
                        .into(),
                ));
            }
            for (a, b) in [(0, 1), (1, 2), (2, 0)] {
                longest = longest.max(((t.uvs[b] - t.uvs[a]) * texels).length());
            }
        }
        let cuts = (longest / edge_texels).ceil().max(1.0);
        let total = cuts as f64 * cuts as f64 * triangles.len() as f64;
        if total > MAX_TRIANGLES as f64 {
            return Err(Error::Option(format!(
                "{} triangles cut {cuts} times along each edge (sub-edges of at most \
                 {edge_texels} texels) make {total:.3e} triangles; at most {MAX_TRIANGLES} \
                 are made: allow longer sub-edges",
                triangles.len()
            )));
        }
        Ok(Self {
            triangles,
            height,
            depth,
            n: cuts as u32,
        })
    }

    /// Cuts along each edge of every triangle.
    pub fn subdivisions(&self) -> u32 {
        self.n
    }

    /// Lattice points per mesh triangle, `(n + 1)(n + 2) / 2`.
    pub fn vertices_per_triangle(&self) -> u64 {
        let n = self.n as u64;
        (n + 1) * (n + 2) / 2
    }

    /// Points written: every triangle's lattice, shared points repeated
    /// (bit for bit equal where the mesh shares its corners).
    pub fn vertex_count(&self) -> u64 {
        self.vertices_per_triangle() * self.triangles.len() as u64
    }

    /// Sub-triangles, `n^2` per mesh triangle.
    pub fn triangle_count(&self) -> u64 {
        self.n as u64 * self.n as u64 * self.triangles.len() as u64
    }

    /// Every point, triangle by triangle, each triangle's lattice row by
    /// row (`j` from corner 0 towards corner 2, `i` towards corner 1).
    pub fn each_vertex(&self) -> impl Iterator<Item = SurfacePoint> + '_ {
        let n = self.n;
        self.triangles.iter().flat_map(move |t| {
            let corners = Corners::of(t);
            (0..=n).flat_map(move |j| (0..=n - j).map(move |i| self.point(&corners, i, j)))
        })
    }

    /// Every sub-triangle as indices into [`Self::each_vertex`]'s points
    /// (0-based), wound as its mesh triangle is.
    pub fn each_triangle(&self) -> impl Iterator<Item = [u64; 3]> + '_ {
        let per = self.vertices_per_triangle();
        let n = self.n;
        (0..self.triangles.len() as u64)
            .flat_map(move |k| lattice_triangles(n).map(move |t| t.map(|i| i + k * per)))
    }

    /// Lattice point `(i, j)` of a triangle: barycentric weights `i / n`
    /// on corner 1 and `j / n` on corner 2.
    fn point(&self, t: &Corners, i: u32, j: u32) -> SurfacePoint {
        let n = self.n;
        let [c0, c1, c2] = t.corners;
        let base = if i + j == 0 {
            c0
        } else if j == 0 {
            along_edge(c0, c1, i, n)
        } else if i == 0 {
            along_edge(c0, c2, j, n)
        } else if i + j == n {
            along_edge(c1, c2, j, n)
        } else {
            let (w1, w2) = (i as f32 / n as f32, j as f32 / n as f32);
            let w0 = 1.0 - w1 - w2;
            Corner {
                p: c0.p * w0 + c1.p * w1 + c2.p * w2,
                n: c0.n * w0 + c1.n * w1 + c2.n * w2,
                uv: c0.uv * w0 + c1.uv * w1 + c2.uv * w2,
            }
        };
        let normal = base.n.try_normalize().unwrap_or(t.flat);
        let h = self.height.sample(base.uv.x, base.uv.y);
        SurfacePoint {
            position: base.p + normal * (self.depth * h),
            uv: base.uv,
        }
    }
}

/// A mesh triangle's corners as they are interpolated, and its face
/// normal (the corners' normal where the mesh gives none, and the fallback
/// where interpolated normals cancel), worked out once per triangle.
#[derive(Clone, Copy)]
struct Corners {
    corners: [Corner; 3],
    flat: Vec3,
}

impl Corners {
    fn of(t: &MeshTriangle) -> Self {
        let flat = (t.positions[1] - t.positions[0])
            .cross(t.positions[2] - t.positions[0])
            .normalize_or_zero();
        let corners = std::array::from_fn(|c| Corner {
            p: t.positions[c],
            n: t.normals.map_or(flat, |ns| ns[c]),
            uv: t.uvs[c],
        });
        Self { corners, flat }
    }
}

/// What is interpolated over a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Corner {
    p: Vec3,
    n: Vec3,
    uv: Vec2,
}

impl Corner {
    /// A total order on corners by their bits, so an edge is walked from
    /// the same end whichever triangle walks it.
    fn key(&self) -> [u32; 8] {
        let [px, py, pz] = self.p.to_array().map(f32::to_bits);
        let [nx, ny, nz] = self.n.to_array().map(f32::to_bits);
        let [u, v] = self.uv.to_array().map(f32::to_bits);
        [px, py, pz, u, v, nx, ny, nz]
    }
}

/// The point `s / n` of the way from `a` to `b`, computed from whichever
/// of the two orders first by [`Corner::key`], so both triangles sharing
/// the edge compute it alike.
fn along_edge(a: Corner, b: Corner, s: u32, n: u32) -> Corner {
    let (a, b, s) = if a.key() <= b.key() {
        (a, b, s)
    } else {
        (b, a, n - s)
    };
    if s == 0 {
        return a;
    }
    if s == n {
        return b;
    }
    let f = s as f32 / n as f32;
    Corner {
        p: a.p + (b.p - a.p) * f,
        n: a.n + (b.n - a.n) * f,
        uv: a.uv + (b.uv - a.uv) * f,
    }
}

/// Index of lattice point `(i, j)` in row-by-row order.
fn lattice_index(i: u32, j: u32, n: u32) -> u64 {
    let (i, j, n) = (i as u64, j as u64, n as u64);
    j * (n + 1) - j * (j.saturating_sub(1)) / 2 + i
}

/// The `n^2` sub-triangles of one lattice, counter-clockwise in `(i, j)`
/// as the mesh triangle is in its corners 0, 1, 2: made as they are
/// written, since a fine lattice (a few thousand cuts along an edge) holds
/// more triangles than memory would.
fn lattice_triangles(n: u32) -> impl Iterator<Item = [u64; 3]> + Clone {
    (0..n).flat_map(move |j| {
        (0..n - j).flat_map(move |i| {
            let at = |i, j| lattice_index(i, j, n);
            let up = [at(i, j), at(i + 1, j), at(i, j + 1)];
            let down = (i + j + 1 < n).then(|| [at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            std::iter::once(up).chain(down)
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin_mesh;
    use displace_core::Address;

    fn heights(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> HeightMap {
        let data = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| f(i, j));
        HeightMap::new(w, h, data.collect(), Address::Repeat).unwrap()
    }

    fn sphere() -> Vec<MeshTriangle> {
        builtin_mesh::generate("sphere").unwrap().triangles
    }

    #[test]
    fn the_lattice_has_n_squared_triangles_over_its_points() {
        for n in 1..7 {
            let tris: Vec<[u64; 3]> = lattice_triangles(n).collect();
            assert_eq!(tris.len() as u32, n * n);
            let points = ((n + 1) * (n + 2) / 2) as u64;
            assert_eq!(lattice_index(0, n, n), points - 1);
            assert!(tris.iter().flatten().all(|&i| i < points));
            // Each interior edge is shared by exactly two sub-triangles,
            // each boundary edge (3n of them) by one.
            let mut edges = std::collections::HashMap::new();
            for t in &tris {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
            let boundary = edges.values().filter(|&&c| c == 1).count() as u32;
            assert_eq!(boundary, 3 * n);
            assert!(edges.values().all(|&c| c == 1 || c == 2));
        }
    }

    /// A flat square of two triangles at z = 0, normals +z, texture
    /// coordinates its xy: its tessellation is the height field itself.
    #[test]
    fn a_flat_mesh_is_lifted_to_the_height_field() {
        let h = heights(8, 8, |i, j| ((i * 3 + j * 5) % 7) as f32 / 7.0);
        let corner = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let tris: Vec<MeshTriangle> = [[0, 1, 2], [0, 2, 3]]
            .iter()
            .map(|c| MeshTriangle {
                positions: c.map(|k| corner[k].extend(0.0)),
                normals: Some([Vec3::Z; 3]),
                uvs: c.map(|k| corner[k]),
            })
            .collect();
        let s = DisplacedSurface::new(&tris, &h, 0.3, 0.5).unwrap();
        // The diagonal spans 8 sqrt 2 texels: 23 cuts of at most half a texel.
        assert_eq!(s.subdivisions(), 23);
        for p in s.each_vertex() {
            assert_eq!(p.position.truncate(), p.uv);
            let want = 0.3 * h.sample(p.uv.x, p.uv.y);
            assert!((p.position.z - want).abs() < 1e-6, "{p:?}");
        }
        assert_eq!(s.each_vertex().count() as u64, s.vertex_count());
        assert_eq!(s.each_triangle().count() as u64, s.triangle_count());
    }

    /// Heights that are the same everywhere lift the unit sphere to a
    /// sphere of radius `1 + depth h` at every point (the normals
    /// interpolate and are normalised, not the flat face normals).
    #[test]
    fn a_constant_height_lifts_the_sphere_to_a_sphere() {
        let tris = sphere();
        let h = heights(96, 48, |_, _| 0.75);
        let s = DisplacedSurface::new(&tris, &h, 0.2, 1.0).unwrap();
        assert!(s.subdivisions() >= 2);
        let mut worst = 0.0f32;
        let mut count = 0u64;
        for p in s.each_vertex() {
            let n = p.position.normalize();
            // On a vertex the base point lies on the unit sphere; between
            // them it is a chord's point, inside it, pushed out along the
            // interpolated normal, which for the sphere is radial up to the
            // chord's error.
            let lifted = p.position - n * (0.2 * 0.75);
            worst = worst.max((lifted.length() - 1.0).abs());
            count += 1;
        }
        assert_eq!(count, s.vertex_count());
        // The chords of a 48 x 24 sphere sag by under 1 - cos(pi / 24).
        assert!(
            worst < 1.0 - (std::f32::consts::PI / 24.0).cos() + 1e-5,
            "{worst}"
        );
    }

    /// The boundary points of every triangle's lattice that no other
    /// triangle's lattice has, bit for bit.
    fn unshared(s: &DisplacedSurface) -> (Vec<SurfacePoint>, usize) {
        let n = s.subdivisions();
        let key = |p: Vec3| p.to_array().map(f32::to_bits);
        let mut seen = std::collections::HashMap::<[u32; 3], (u32, SurfacePoint)>::new();
        for (k, p) in s.each_vertex().enumerate() {
            let local = k as u64 % s.vertices_per_triangle();
            let j = (0..=n)
                .find(|&j| lattice_index(0, j + 1, n) > local)
                .unwrap();
            let i = (local - lattice_index(0, j, n)) as u32;
            if i == 0 || j == 0 || i + j == n {
                seen.entry(key(p.position)).or_insert((0, p)).0 += 1;
            }
        }
        let single = seen.values().filter(|(c, _)| *c == 1).map(|(_, p)| *p);
        (single.collect(), seen.len())
    }

    /// On a texture seam: where the built-ins' generators give the two
    /// sides' corners positions a few ulps apart (`sin(2 pi)` is not 0).
    fn on_seam(p: &SurfacePoint) -> bool {
        [p.uv.x, p.uv.y].iter().any(|&c| c == 0.0 || c == 1.0)
    }

    /// Where two triangles share an edge's corners, their points along it
    /// are bit for bit the same, whichever way each walks it: the closed
    /// torus opens nowhere but on its texture seams, where its own corners
    /// already differ in their last bits.
    #[test]
    fn shared_edges_meet_bit_for_bit() {
        let torus = builtin_mesh::generate("torus").unwrap().triangles;
        let h = heights(64, 24, |i, j| ((i * 7 + j * 3) % 5) as f32 / 5.0);
        let s = DisplacedSurface::new(&torus, &h, 0.1, 0.4).unwrap();
        assert!(s.subdivisions() >= 3);
        let (single, total) = unshared(&s);
        assert!(total > 10_000, "{total}");
        let inner: Vec<_> = single.iter().filter(|p| !on_seam(p)).collect();
        assert!(
            inner.is_empty(),
            "{} of {total}: {:?}",
            inner.len(),
            &inner[..inner.len().min(4)]
        );
    }

    /// The sphere opens only where its texture coordinates part at shared
    /// corners, along the edges that meet at its poles (each triangle gives
    /// the pole its own `u`), and on its seam.
    #[test]
    fn the_sphere_opens_at_its_poles_only() {
        let h = heights(32, 16, |i, j| ((i * 7 + j * 3) % 5) as f32 / 5.0);
        let tris = sphere();
        let s = DisplacedSurface::new(&tris, &h, 0.1, 0.5).unwrap();
        let (single, total) = unshared(&s);
        // The first and last ring of quads span colatitudes under pi / 24.
        let cap = (std::f32::consts::PI / 24.0).cos() * 0.99;
        let poles = single
            .iter()
            .filter(|p| p.position.normalize().y.abs() > cap);
        assert!(poles.count() > 0);
        for p in single.iter().filter(|p| !on_seam(p)) {
            assert!(p.position.normalize().y.abs() > cap, "{p:?} of {total}");
        }
    }

    #[test]
    fn sub_edges_stay_under_the_limit() {
        let tris = sphere();
        let h = heights(64, 32, |_, _| 0.0);
        for limit in [0.25, 1.0, 3.0] {
            let s = DisplacedSurface::new(&tris, &h, 0.1, limit).unwrap();
            let points: Vec<_> = s.each_vertex().collect();
            let texels = Vec2::new(64.0, 32.0);
            for t in s.each_triangle() {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    let d = (points[b as usize].uv - points[a as usize].uv) * texels;
                    assert!(d.length() <= limit * 1.0001, "{limit}: {}", d.length());
                }
            }
        }
    }

    #[test]
    fn bad_requests_are_refused_before_any_work() {
        let tris = sphere();
        let h = heights(64, 32, |_, _| 0.0);
        for edge in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(
                DisplacedSurface::new(&tris, &h, 0.1, edge).is_err(),
                "{edge}"
            );
        }
        assert!(DisplacedSurface::new(&tris, &h, f32::NAN, 1.0).is_err());
        assert!(DisplacedSurface::new(&[], &h, 0.1, 1.0).is_err());
        let err = DisplacedSurface::new(&tris, &h, 0.1, 1e-6).err().unwrap();
        assert!(err.to_string().contains("at most"), "{err}");
        let mut bad = tris.clone();
        bad[3].uvs[1] = Vec2::NAN;
        assert!(DisplacedSurface::new(&bad, &h, 0.1, 1.0).is_err());
    }
}
