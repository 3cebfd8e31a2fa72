//! Tangent-space normal maps generated from the continuous surface for a
//! face's physical proportions. OWNED BY HELPER: to be implemented.

use crate::{Extent, HeightMap};
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct NormalMap {
    pub width: usize,
    pub height: usize,
    /// Unit normals in map space (x along u, y along v, z up), row-major.
    pub data: Vec<Vec3>,
}

impl NormalMap {
    pub fn from_height(height: &HeightMap, extent: Extent) -> Self {
        let [ax, ay] = extent.aspect();
        let (w, h) = (height.width(), height.height());
        let mut data = Vec::with_capacity(w * h);
        for j in 0..h {
            for i in 0..w {
                let u = crate::convention::texel_centre(i, w);
                let v = crate::convention::texel_centre(j, h);
                let g = height.gradient(u, v);
                data.push(Vec3::new(-g[0] / ax, -g[1] / ay, 1.0).normalize());
            }
        }
        Self { width: w, height: h, data }
    }

    /// Bilinear, renormalised, with the height map's addressing.
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        let (i, fx) = crate::convention::texel_lerp(u, self.width);
        let (j, fy) = crate::convention::texel_lerp(v, self.height);
        let a = crate::Address::Clamp;
        let at = |ii: i64, jj: i64| self.data[a.texel_index(jj, self.height) * self.width + a.texel_index(ii, self.width)];
        let top = at(i, j).lerp(at(i + 1, j), fx);
        let bot = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
        top.lerp(bot, fy).normalize()
    }
}
