//! Least-squares alignment of point sets: the similarity transform (rotation, translation, scale).

use crate::mesh::geometry::{add, centroid, dot, mul, sub};

/// `p ↦ s R p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    /// Scale `s`.
    pub scale: f64,
    /// Rotation `R` (rows).
    pub rot: [[f64; 3]; 3],
    /// Translation `t`.
    pub trans: [f64; 3],
}

impl Similarity {
    /// Least-squares similarity from `src` to `dst` (Horn's quaternion method; scale as Umeyama).
    pub fn fit(src: &[[f64; 3]], dst: &[[f64; 3]]) -> Option<Self> {
        if src.len() != dst.len() || src.len() < 3 {
            return None;
        }
        let cs = centroid(src.iter().copied());
        let cd = centroid(dst.iter().copied());
        let mut s = [[0.0f64; 3]; 3];
        let mut var = 0.0;
        for (a, b) in src.iter().zip(dst) {
            let (a, b) = (sub(*a, cs), sub(*b, cd));
            var += dot(a, a);
            for i in 0..3 {
                for j in 0..3 {
                    s[i][j] += a[i] * b[j];
                }
            }
        }
        if !(var > 0.0 && var.is_finite()) {
            return None;
        }
        let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
        let nmat = [
            [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
            [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
            [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
            [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
        ];
        let m = faer::Mat::from_fn(4, 4, |i, j| nmat[i][j]);
        let eig = m.self_adjoint_eigen(faer::Side::Lower).ok()?;
        let lambda = eig.S().column_vector();
        let top = (0..4).max_by(|&a, &b| lambda[a].total_cmp(&lambda[b]))?;
        let u = eig.U();
        let (w, x, y, z) = (u[(0, top)], u[(1, top)], u[(2, top)], u[(3, top)]);
        let rot = [
            [w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ];
        let mut num = 0.0;
        for (a, b) in src.iter().zip(dst) {
            let (a, b) = (sub(*a, cs), sub(*b, cd));
            num += dot(b, [dot(rot[0], a), dot(rot[1], a), dot(rot[2], a)]);
        }
        let scale = num / var;
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let rc = [dot(rot[0], cs), dot(rot[1], cs), dot(rot[2], cs)];
        Some(Self { scale, rot, trans: sub(cd, mul(rc, scale)) })
    }

    /// `s R p + t`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = [dot(self.rot[0], p), dot(self.rot[1], p), dot(self.rot[2], p)];
        add(mul(r, self.scale), self.trans)
    }
}
