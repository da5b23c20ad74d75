//! Spherical-harmonics illumination (bands 0-2, 9 coefficients per RGB channel), Lambertian.
//!
//! Follows scalismo-faces (`SphericalHarmonicsLight`, `SphericalHarmonics`,
//! `SphericalHarmonicsLambertShader`): real SH basis `Y_i` with linear index `i = l² + l + m`,
//! i.e. the order `Y00, Y1-1 (y), Y10 (z), Y11 (x), Y2-2 (xy), Y2-1 (yz), Y20 (3z²-1), Y21 (zx),
//! Y22 (x²-y²)`, orthonormal on the sphere; the irradiance for a unit normal `n` is
//! `E_c(n) = Σ_i K_i · Y_i(n) · L_i,c` with the Lambert kernel `K = (π, 2π/3 ×3, π/4 ×5)`.
//! The light lives in camera space (x right, y up, z toward the camera): normals are rotated by
//! the pose before shading.

use crate::geometry::Vec3;

/// Number of SH coefficients per channel (bands 0, 1, 2).
pub const SH_COEFFS: usize = 9;

/// `Y00` normalization: `sqrt(1/π) / 2`.
pub const N0: f32 = 0.282_094_8;
/// Band-1 normalization: `sqrt(3/π) / 2`.
pub const N1: f32 = 0.488_602_5;
/// `Y2±1`, `Y2-2` normalization: `sqrt(15/π) / 2`.
pub const N2_1: f32 = 1.092_548_4;
/// `Y20` normalization: `sqrt(5/π) / 4`.
pub const N2_0: f32 = 0.315_391_57;
/// `Y22` normalization: `sqrt(15/π) / 4`.
pub const N2_2: f32 = 0.546_274_2;

/// Lambert kernel factors per coefficient: `π` (band 0), `2π/3` (band 1), `π/4` (band 2).
pub const LAMBERT_KERNEL: [f32; SH_COEFFS] = [
    core::f32::consts::PI,
    2.094_395_1,
    2.094_395_1,
    2.094_395_1,
    core::f32::consts::FRAC_PI_4,
    core::f32::consts::FRAC_PI_4,
    core::f32::consts::FRAC_PI_4,
    core::f32::consts::FRAC_PI_4,
    core::f32::consts::FRAC_PI_4,
];

/// The 9 real SH basis functions at direction `n` (normalized here; a zero or non-finite `n` gives band 0 only).
pub fn sh_basis(n: Vec3) -> [f32; SH_COEFFS] {
    let len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    let [x, y, z] = if len2 > 0.0 && len2.is_finite() {
        let inv = 1.0 / libm::sqrtf(len2);
        [n[0] * inv, n[1] * inv, n[2] * inv]
    } else {
        [0.0; 3]
    };
    [N0, N1 * y, N1 * z, N1 * x, N2_1 * x * y, N2_1 * y * z, N2_0 * (2.0 * z * z - x * x - y * y), N2_1 * z * x, N2_2 * (x * x - y * y)]
}

/// `K_i · Y_i(n)`: the Lambert-convolved basis, so that irradiance = `Σ_i basis_i · L_i` (linear in the light).
pub fn lambert_basis(n: Vec3) -> [f32; SH_COEFFS] {
    let mut b = sh_basis(n);
    for (v, k) in b.iter_mut().zip(LAMBERT_KERNEL) {
        *v *= k;
    }
    b
}

/// Spherical-harmonics light: `coeffs[i]` is the RGB coefficient of basis function `i`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShLight {
    /// Coefficients, `[coefficient][channel]`, in the scalismo-faces order (see the module docs).
    pub coeffs: [Vec3; SH_COEFFS],
}

impl ShLight {
    /// No light at all (everything renders black).
    pub const fn zero() -> Self {
        Self { coeffs: [[0.0; 3]; SH_COEFFS] }
    }

    /// Constant white irradiance 1 from every direction: renders the pure albedo.
    pub fn ambient_white() -> Self {
        Self::ambient([1.0; 3])
    }

    /// Constant irradiance `rgb` from every direction.
    pub fn ambient(rgb: Vec3) -> Self {
        let mut l = Self::zero();
        let s = 1.0 / (N0 * LAMBERT_KERNEL[0]);
        l.coeffs[0] = [rgb[0] * s, rgb[1] * s, rgb[2] * s];
        l
    }

    /// scalismo-faces' default frontal light: ambient 0.8 plus diffuse 0.2 from +z (toward the camera).
    pub fn frontal() -> Self {
        Self::from_ambient_diffuse([0.8; 3], [0.2; 3], [0.0, 0.0, 1.0])
    }

    /// Ambient plus a band-1 directional term: irradiance `ambient + diffuse · (n · d)` for the unit direction `d`
    /// toward the light (a zero or non-finite direction gives the ambient part only).
    pub fn from_ambient_diffuse(ambient: Vec3, diffuse: Vec3, direction: Vec3) -> Self {
        let mut l = Self::ambient(ambient);
        let b = sh_basis(direction);
        // b[1..4] = N1 · (y, z, x); the coefficient for Y1m is d_m / (N1 · K1).
        let s = 1.0 / (N1 * N1 * LAMBERT_KERNEL[1]);
        for (c, bv) in l.coeffs.iter_mut().zip(b).skip(1).take(3) {
            *c = [diffuse[0] * bv * s, diffuse[1] * bv * s, diffuse[2] * bv * s];
        }
        l
    }

    /// RGB irradiance for the (camera-space) normal `n`; `n` need not be unit length.
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        self.irradiance_of(&lambert_basis(n))
    }

    /// RGB irradiance for the Lambert basis `b` of a normal ([`lambert_basis`]).
    #[inline(always)]
    pub fn irradiance_of(&self, b: &[f32; SH_COEFFS]) -> Vec3 {
        let mut e = [0.0f32; 3];
        for (bv, c) in b.iter().zip(&self.coeffs) {
            e[0] += bv * c[0];
            e[1] += bv * c[1];
            e[2] += bv * c[2];
        }
        e
    }
}
