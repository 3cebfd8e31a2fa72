//! Tangent-space normal maps of the continuous surface, for one face's
//! physical proportions.
//!
//! The ray-tracer paper (section 2.2) found that normals cannot be stored with the height
//! map once and for all: "differing depths and geometry of a face can change
//! the normals". In map space ([`crate::convention`]) the surface is
//! `z = h(x / ax, y / ay)` with `(ax, ay) = extent.aspect()`, so its normal is
//! proportional to `(-dh/du / ax, -dh/dv / ay, 1)`: a deeper shell (smaller
//! `ax`, `ay`) tilts the normals more, a wider face less.
//!
//! The slope at a texel centre is the symmetric derivative of the bilinear
//! surface there: the central difference of the two neighbouring texels,
//! i.e. the mean of the slopes of the two bilinear cells that meet at the
//! centre. That paper crossed the vectors to two neighbours, a one-sided
//! difference that shifts every normal by half a texel.

use crate::convention::texel_lerp;
use crate::{Address, Extent, HeightMap};
use glam::Vec3;
use rayon::prelude::*;

/// Shading normals of a height map's surface for one face's proportions
/// (Donnelly, GPU Gems 2 ch. 8, section 8.4 reads them in tangent space).
#[derive(Clone, Debug)]
pub struct NormalMap {
    /// Normals per row: the height map's width.
    pub width: usize,
    /// Rows: the height map's height.
    pub height: usize,
    /// Unit normals in map space (x along u, y along v, z up), row-major,
    /// `data[j * width + i]` at texel centre `(i, j)` as in the height map.
    pub data: Vec<Vec3>,
    /// The height map's addressing, used again when sampling.
    pub address: Address,
}

impl NormalMap {
    /// Normals of `height`'s continuous surface at its texel centres, for a
    /// face of `extent`. Repeat addressing takes the neighbours across the
    /// opposite edge; clamp addressing uses the one-sided difference at the
    /// border texels (the clamped half-texel beyond them is flat and says
    /// nothing about the slope at the centre).
    ///
    /// # Errors
    /// [`crate::Error::OutOfMemory`] where the allocator refuses the map.
    pub fn from_height(height: &HeightMap, extent: Extent) -> crate::Result<Self> {
        let [ax, ay] = extent.aspect();
        let (w, h) = (height.width(), height.height());
        let address = height.address();
        let mut data = crate::memory::filled("the normal map", w * h, Vec3::Z)?;
        data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            let (j0, j1, dv) = neighbours(j, h, address);
            for (i, n) in row.iter_mut().enumerate() {
                let (i0, i1, du) = neighbours(i, w, address);
                let dh_du = (height.texel(i1, j as i64) - height.texel(i0, j as i64)) / du;
                let dh_dv = (height.texel(i as i64, j1) - height.texel(i as i64, j0)) / dv;
                *n = Vec3::new(-dh_du / ax, -dh_dv / ay, 1.0).normalize();
            }
        });
        Ok(Self {
            width: w,
            height: h,
            data,
            address,
        })
    }

    /// Normal at texel `(i, j)`, addressing applied.
    #[inline]
    pub fn texel(&self, i: i64, j: i64) -> Vec3 {
        let i = self.address.texel_index(i, self.width);
        let j = self.address.texel_index(j, self.height);
        self.data[j * self.width + i]
    }

    /// Bilinear between texel centres with the height map's addressing,
    /// renormalised. Every stored normal has `z > 0`, so the blend never
    /// vanishes.
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        self.blend(u, v).normalize()
    }

    /// [`Self::sample`] before its renormalisation: for a caller that
    /// transforms the normal and normalises the result anyway (a linear map
    /// commutes with the scale), one square root and division fewer.
    #[inline]
    pub fn blend(&self, u: f32, v: f32) -> Vec3 {
        let (i, fx) = texel_lerp(u, self.width);
        let (j, fy) = texel_lerp(v, self.height);
        let [n00, n10, n01, n11] = self.cell(i, j);
        n00.lerp(n10, fx).lerp(n01.lerp(n11, fx), fy)
    }

    /// [`Self::blend`] at eight points at once, as columns (`[x, y, z]`,
    /// one lane a point): the texels are read lane by lane, the blends run
    /// over the lanes in [`Self::blend`]'s order of operations (glam's
    /// `lerp`, `a (1 - s) + b s`), so lane `l` is `blend(u[l], v[l])` bit
    /// for bit while the eight blends share vector registers (pbrt-v4's
    /// wavefront path tracer, chapter 15, evaluates its materials the same
    /// way: one kernel over many hits).
    #[inline]
    pub fn blend8(&self, u: &[f32; 8], v: &[f32; 8]) -> [[f32; 8]; 3] {
        let mut n = [[[0.0f32; 8]; 3]; 4];
        let (mut fx, mut fy) = ([0.0f32; 8], [0.0f32; 8]);
        for l in 0..8 {
            let (i, x) = texel_lerp(u[l], self.width);
            let (j, y) = texel_lerp(v[l], self.height);
            (fx[l], fy[l]) = (x, y);
            for (c, t) in self.cell(i, j).iter().enumerate() {
                (n[c][0][l], n[c][1][l], n[c][2][l]) = (t.x, t.y, t.z);
            }
        }
        let lerp = |a: f32, b: f32, s: f32| a * (1.0 - s) + b * s;
        let mut out = [[0.0f32; 8]; 3];
        for (a, o) in out.iter_mut().enumerate() {
            for l in 0..8 {
                let top = lerp(n[0][a][l], n[1][a][l], fx[l]);
                let bottom = lerp(n[2][a][l], n[3][a][l], fx[l]);
                o[l] = lerp(top, bottom, fy[l]);
            }
        }
        out
    }

    /// The four normals around cell `(ci, cj)` (`n00, n10, n01, n11`, as
    /// [`crate::HeightMap::cell`] orders heights): interior cells read two
    /// rows directly, the border ring goes through the addressing. Every
    /// shaded hit samples the map once.
    #[inline]
    fn cell(&self, ci: i64, cj: i64) -> [Vec3; 4] {
        let (i, j) = (ci as u64, cj as u64);
        if i < self.width as u64 - 1 && j < self.height as u64 - 1 {
            let k = j as usize * self.width + i as usize;
            let (r0, r1) = (
                &self.data[k..k + 2],
                &self.data[k + self.width..k + self.width + 2],
            );
            [r0[0], r0[1], r1[0], r1[1]]
        } else {
            [
                self.texel(ci, cj),
                self.texel(ci + 1, cj),
                self.texel(ci, cj + 1),
                self.texel(ci + 1, cj + 1),
            ]
        }
    }

    /// The map as 8-bit RGB, rows in the height map's order (row 0 = `v = 0`
    /// = the first row of an image file), each channel `c * 0.5 + 0.5` of the
    /// normal in the image's own frame: x right, y up the image, z out of it.
    /// That is the +Y-up (OpenGL, glTF, Bevy, Blender) convention: since `v`
    /// grows down the image, green encodes `-n.y` of the map-space normal.
    pub fn to_rgb8(&self) -> Vec<u8> {
        let encode = |c: f32| ((c * 0.5 + 0.5) * 255.0).round().clamp(0.0, 255.0) as u8;
        self.data
            .iter()
            .flat_map(|n| [encode(n.x), encode(-n.y), encode(n.z)])
            .collect()
    }
}

/// The texels on either side of texel `k` of `n` (before addressing) and
/// their distance in texture units: two texels, or one at a clamped border.
fn neighbours(k: usize, n: usize, address: Address) -> (i64, i64, f32) {
    let k = k as i64;
    let (a, b) = match address {
        Address::Repeat => (k - 1, k + 1),
        Address::Clamp => ((k - 1).max(0), (k + 1).min(n as i64 - 1)),
    };
    (a, b, (b - a) as f32 / n as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convention::texel_centre;
    use proptest::prelude::*;

    fn plane(w: usize, h: usize, a: f32, b: f32, c: f32, address: Address) -> HeightMap {
        let data = (0..h)
            .flat_map(|j| (0..w).map(move |i| a + b * texel_centre(i, w) + c * texel_centre(j, h)))
            .collect();
        HeightMap::new(w, h, data, address).unwrap()
    }

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).length() < tol
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(crate::random::property_cases(256)))]
        /// Eight blends in lanes are the eight blends one at a time, bit
        /// for bit, inside the map, on its border ring and past it, on
        /// either addressing.
        #[test]
        fn eight_blends_in_lanes_are_the_blends_one_by_one(
            heights in proptest::collection::vec(0.0f32..1.0, 4 * 7),
            uv in proptest::array::uniform8((-0.5f32..1.5, -0.5f32..1.5)),
            repeat in any::<bool>(),
        ) {
            let address = if repeat { Address::Repeat } else { Address::Clamp };
            let m = HeightMap::new(7, 4, heights, address).unwrap();
            let n = NormalMap::from_height(&m, Extent::new(1.0, 2.0, 0.3).unwrap()).unwrap();
            let lanes = n.blend8(&uv.map(|p| p.0), &uv.map(|p| p.1));
            for (l, &(u, v)) in uv.iter().enumerate() {
                let one = n.blend(u, v);
                prop_assert_eq!(
                    [lanes[0][l], lanes[1][l], lanes[2][l]].map(f32::to_bits),
                    one.to_array().map(f32::to_bits)
                );
            }
        }

        /// A tilted plane has the analytic normal at every texel, border
        /// texels included, for any proportions of the face.
        #[test]
        fn tilted_plane_has_the_analytic_normal(
            b in -0.2f32..0.2, c in -0.2f32..0.2,
            sx in 0.1f32..10.0, sy in 0.1f32..10.0, sz in 0.01f32..2.0,
            w in 2usize..20, h in 2usize..20,
        ) {
            let m = plane(w, h, 0.5, b, c, Address::Clamp);
            let extent = Extent::new(sx, sy, sz).unwrap();
            let [ax, ay] = extent.aspect();
            let expected = Vec3::new(-b / ax, -c / ay, 1.0).normalize();
            let n = NormalMap::from_height(&m, extent).unwrap();
            for (k, got) in n.data.iter().enumerate() {
                prop_assert!(close(*got, expected, 1e-4), "texel {k}: {got} vs {expected}");
            }
            prop_assert!(close(n.sample(0.3, 0.7), expected, 1e-4));
        }
    }

    #[test]
    fn depth_and_aspect_change_the_normals_as_the_ray_tracer_paper_says() {
        let m = plane(16, 16, 0.2, 0.5, 0.25, Address::Clamp);
        let slopes = |e: Extent| {
            let n = NormalMap::from_height(&m, e).unwrap().data[5 * 16 + 7];
            (-n.x / n.z, -n.y / n.z)
        };
        let base = slopes(Extent::new(1.0, 1.0, 0.1).unwrap());
        assert!(
            (base.0 - 0.05).abs() < 1e-5 && (base.1 - 0.025).abs() < 1e-5,
            "{base:?}"
        );
        // Twice the depth: twice the slope, both ways.
        let deep = slopes(Extent::new(1.0, 1.0, 0.2).unwrap());
        assert!((deep.0 - 2.0 * base.0).abs() < 1e-5 && (deep.1 - 2.0 * base.1).abs() < 1e-5);
        // Twice as wide: half the slope along u only.
        let wide = slopes(Extent::new(2.0, 1.0, 0.1).unwrap());
        assert!((wide.0 - 0.5 * base.0).abs() < 1e-5 && (wide.1 - base.1).abs() < 1e-5);
    }

    #[test]
    fn central_differences_of_the_continuous_surface() {
        // A ridge along u: texel 2 of [0, 0.2, 1, 0.6, 0]. At its peak the two
        // cells' slopes are +0.8 and -0.4 texel heights per texel: the
        // symmetric derivative is their mean, 0.2 per texel = 1.0 per unit u.
        let row = [0.0, 0.2, 1.0, 0.6, 0.0];
        let m = HeightMap::new(5, 2, [row, row].concat(), Address::Clamp).unwrap();
        let n = NormalMap::from_height(&m, Extent::new(1.0, 1.0, 1.0).unwrap()).unwrap();
        assert!(close(
            n.texel(2, 0),
            Vec3::new(-1.0, 0.0, 1.0).normalize(),
            1e-6
        ));
        // Border texels: one-sided under clamp (slope 0.2 per texel = 1.0).
        assert!(close(
            n.texel(0, 0),
            Vec3::new(-1.0, 0.0, 1.0).normalize(),
            1e-6
        ));
        // ... and across the wrap under repeat ((0.2 - 0) / 2 texels = 0.5).
        let r = NormalMap::from_height(
            &m.clone().with_address(Address::Repeat),
            Extent::new(1.0, 1.0, 1.0).unwrap(),
        )
        .unwrap();
        assert!(close(
            r.texel(0, 0),
            Vec3::new(-0.5, 0.0, 1.0).normalize(),
            1e-6
        ));
    }

    #[test]
    fn repeat_addressing_wraps() {
        let w = 32;
        let data: Vec<f32> = (0..w * 8)
            .map(|k| 0.5 + 0.4 * (std::f32::consts::TAU * texel_centre(k % w, w)).sin())
            .collect();
        let m = HeightMap::new(w, 8, data, Address::Repeat).unwrap();
        let extent = Extent::new(1.0, 1.0, 0.5).unwrap();
        let n = NormalMap::from_height(&m, extent).unwrap();
        assert_eq!(n.address, Address::Repeat);
        // A periodic surface: the edge texels get the same treatment as the
        // interior, so the map is symmetric about the peak at u = 1/4.
        let ax = extent.aspect()[0];
        for i in 0..w {
            let u = texel_centre(i, w);
            let spacing = 1.0 / w as f32;
            let slope = 0.4
                * ((std::f32::consts::TAU * (u + spacing)).sin()
                    - (std::f32::consts::TAU * (u - spacing)).sin())
                / (2.0 * spacing);
            let expected = Vec3::new(-slope / ax, 0.0, 1.0).normalize();
            assert!(close(n.texel(i as i64, 3), expected, 1e-4), "texel {i}");
        }
        // Sampling wraps: one tile over is the same normal, and the border
        // blends the last and the first column.
        for (u, v) in [(0.13, 0.4), (0.77, 0.9), (0.999, 0.1)] {
            assert!(close(n.sample(u, v), n.sample(u + 1.0, v - 1.0), 1e-5));
        }
        let edge = n.sample(0.0, 0.5);
        let mean = (n.texel(-1, 3) + n.texel(0, 3)).normalize();
        assert!(close(edge, mean, 1e-5), "{edge} vs {mean}");
        // Clamp holds the edge texel instead.
        let c = NormalMap::from_height(&m.clone().with_address(Address::Clamp), extent).unwrap();
        assert!(close(c.sample(0.0, 0.5), c.texel(0, 3), 1e-6));
    }

    #[test]
    fn rgb_is_opengl_convention_in_image_rows() {
        let flat = plane(4, 4, 0.5, 0.0, 0.0, Address::Clamp);
        let rgb = NormalMap::from_height(&flat, Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap()
            .to_rgb8();
        assert_eq!(rgb.len(), 48);
        assert!(rgb.chunks(3).all(|p| p == [128, 128, 255]));
        // Height rising with u (to the right) and with v (down the image):
        // the surface faces left and up the image, so red < 128, green > 128.
        let ramp = plane(4, 4, 0.1, 0.4, 0.4, Address::Clamp);
        let rgb = NormalMap::from_height(&ramp, Extent::new(1.0, 1.0, 1.0).unwrap())
            .unwrap()
            .to_rgb8();
        let n = Vec3::new(-0.4, -0.4, 1.0).normalize();
        let expected = [n.x, -n.y, n.z].map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8);
        assert!(
            rgb.chunks(3).all(|p| p == expected),
            "{:?} vs {expected:?}",
            &rgb[..3]
        );
        assert!(expected[0] < 128 && expected[1] > 128);
    }
}
