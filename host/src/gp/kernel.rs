//! The paper's Gaussian-process kernels, kept in factored form.
//!
//! Every kernel of Sutherland et al. (IJCV 2023) is a sum of terms
//! `A_t · k_t(x, y)` where `k_t` is a scalar squared-exponential kernel
//! (`w · exp(-d²/s²)`, with `d` a distance in position, mirrored position or
//! template colour) and the 3x3 matrices `A_t` all commute. In a suitable
//! orthonormal basis every `A_t` is diagonal, so the matrix kernel splits into
//! independent scalar kernels, one per basis direction; directions with the
//! same coefficients form a [`DirectionClass`] and share one scalar
//! eigenproblem. See docs/design.md, "Low rank".
//!
//! Nothing here is face-specific: the kernels see only vertex positions (mm)
//! and template colours (linear RGB in \[0, 1\]).

use crate::mesh::geometry::dist2;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A vertex as a kernel sees it: position in mm and template colour in \[0, 1\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KernelPoint {
    /// Position (mm).
    pub position: [f64; 3],
    /// Template colour (linear RGB in \[0, 1\]).
    pub color: [f64; 3],
}

/// Which distance a scalar term measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Space {
    /// `|x - y|` between positions.
    Position,
    /// `|x - Φy|` with `Φ = diag(-1, 1, 1)` (mirror about the plane x = 0).
    MirroredPosition,
    /// `|c(x) - c(y)|` between template colours.
    Color,
}

/// One squared-exponential term `weight · exp(-d² / scale²)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SeTerm {
    /// Variance weight.
    pub weight: f64,
    /// Length scale (mm for positions, RGB units for colours).
    pub scale: f64,
}

/// A scalar kernel: a weighted sum of squared-exponential terms over several distances.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarKernel {
    terms: Vec<(Space, f64, f64)>, // (space, weight, 1/scale²)
}

/// The distances between one pair of points, each computed at most once.
struct PairDistances<'a> {
    a: &'a KernelPoint,
    b: &'a KernelPoint,
    cache: [Option<f64>; 3],
}

impl<'a> PairDistances<'a> {
    fn new(a: &'a KernelPoint, b: &'a KernelPoint) -> Self {
        Self { a, b, cache: [None; 3] }
    }

    /// The squared distance in `space`.
    #[inline]
    fn get(&mut self, space: Space) -> f64 {
        let (a, b) = (self.a, self.b);
        match space {
            Space::Position => *self.cache[0].get_or_insert_with(|| dist2(a.position, b.position)),
            Space::MirroredPosition => {
                *self.cache[1].get_or_insert_with(|| dist2(a.position, [-b.position[0], b.position[1], b.position[2]]))
            }
            Space::Color => *self.cache[2].get_or_insert_with(|| dist2(a.color, b.color)),
        }
    }
}

/// `exp(-d² / s²)` given `d²` and `1/s²`. Below e^-40 (4e-18 of the term's weight) a term is
/// zero in f64 sums; skipping the call avoids libm's slow underflow path. (`libm::exp`, not
/// glibc's: glibc's exp right after faer's AVX code stalled on SSE/AVX transitions and took
/// 80% of a model build.)
#[inline]
fn se_value(d2: f64, inv_s2: f64) -> f64 {
    let arg = d2 * inv_s2;
    if arg < 40.0 {
        libm::exp(-arg)
    } else {
        0.0
    }
}

impl ScalarKernel {
    /// An empty kernel (zero everywhere).
    pub fn zero() -> Self {
        Self { terms: Vec::new() }
    }

    /// Adds `factor · Σ terms` measured in `space`, dropping zero-weight terms.
    pub fn add(&mut self, space: Space, factor: f64, terms: &[SeTerm]) {
        for t in terms {
            let w = factor * t.weight;
            if w != 0.0 {
                self.terms.push((space, w, 1.0 / (t.scale * t.scale)));
            }
        }
    }

    /// Evaluates the kernel between two points.
    #[inline]
    pub fn eval(&self, a: &KernelPoint, b: &KernelPoint) -> f64 {
        let mut d = PairDistances::new(a, b);
        self.terms.iter().map(|&(space, w, inv_s2)| w * se_value(d.get(space), inv_s2)).sum()
    }

    /// Whether the kernel has no terms.
    pub fn is_zero(&self) -> bool {
        self.terms.is_empty()
    }
}

/// Several scalar kernels evaluated together: each distinct `(space, scale)` term's
/// exponential is computed once per pair and shared by every kernel that uses it (the
/// direction classes of one matrix kernel differ only in their weights).
#[derive(Debug, Clone, PartialEq)]
pub struct KernelBank {
    terms: Vec<(Space, f64)>, // (space, 1/scale²)
    weights: Vec<Vec<f64>>,   // per kernel, per term
}

impl KernelBank {
    /// Collects the distinct terms of `kernels`.
    pub fn new(kernels: &[ScalarKernel]) -> Self {
        let mut terms: Vec<(Space, f64)> = Vec::new();
        for k in kernels {
            for &(space, _, inv) in &k.terms {
                if !terms.iter().any(|&(s, i)| s == space && i == inv) {
                    terms.push((space, inv));
                }
            }
        }
        let weights = kernels
            .iter()
            .map(|k| {
                let mut w = vec![0.0; terms.len()];
                for &(space, weight, inv) in &k.terms {
                    if let Some(t) = terms.iter().position(|&(s, i)| s == space && i == inv) {
                        w[t] += weight;
                    }
                }
                w
            })
            .collect();
        Self { terms, weights }
    }

    /// Number of kernels.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// Whether the bank holds no kernels.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// The distinct terms: the space each measures and its `1/scale²`.
    pub(crate) fn terms(&self) -> &[(Space, f64)] {
        &self.terms
    }

    /// Per kernel, the weight of each distinct term.
    pub(crate) fn weights(&self) -> &[Vec<f64>] {
        &self.weights
    }

    /// Number of distinct terms (scratch length for [`KernelBank::eval_into`]).
    pub fn term_count(&self) -> usize {
        self.terms.len()
    }

    /// Evaluates every kernel between `a` and `b` into `out` (one value per kernel);
    /// `scratch` must hold [`KernelBank::term_count`] values.
    #[inline]
    pub fn eval_into(&self, a: &KernelPoint, b: &KernelPoint, scratch: &mut [f64], out: &mut [f64]) {
        let mut d = PairDistances::new(a, b);
        for (v, &(space, inv_s2)) in scratch.iter_mut().zip(&self.terms) {
            *v = se_value(d.get(space), inv_s2);
        }
        for (o, w) in out.iter_mut().zip(&self.weights) {
            *o = w.iter().zip(scratch.iter()).map(|(w, v)| w * v).sum();
        }
    }
}

/// Orthonormal directions that share one scalar kernel.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectionClass {
    /// Unit 3-vectors (orthonormal).
    pub directions: Vec<[f64; 3]>,
    /// The scalar kernel every direction of the class gets.
    pub kernel: ScalarKernel,
}

/// A matrix-valued kernel `Σ_t B·diag(d_t)·Bᵀ · k_t(x, y)` with a fixed orthonormal basis `B`.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagonalKernel {
    basis: [[f64; 3]; 3],
    terms: Vec<([f64; 3], Space, f64, SeTerm)>, // (diag, space, factor, term)
}

/// The standard axes, in which `I` and `Φ = diag(-1,1,1)` are diagonal.
pub const AXES: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// A basis in which every `aI + b·11ᵀ` (such as `M_x`) is diagonal: `(1,1,1)/√3` first.
pub fn luminance_basis() -> [[f64; 3]; 3] {
    let s3 = 3f64.sqrt();
    let s2 = 2f64.sqrt();
    let s6 = 6f64.sqrt();
    [[1.0 / s3, 1.0 / s3, 1.0 / s3], [1.0 / s2, -1.0 / s2, 0.0], [1.0 / s6, 1.0 / s6, -2.0 / s6]]
}

/// Eigenvalues of `M_x` (1 on the diagonal, x off it) in [`luminance_basis`] order.
pub fn channel_correlation_diag(x: f64) -> [f64; 3] {
    [1.0 + 2.0 * x, 1.0 - x, 1.0 - x]
}

impl DiagonalKernel {
    /// An empty kernel with the given orthonormal basis (rows are basis vectors).
    pub fn new(basis: [[f64; 3]; 3]) -> Self {
        Self { basis, terms: Vec::new() }
    }

    /// Adds `factor · B diag(d) Bᵀ · Σ terms(space)`.
    pub fn add(&mut self, diag: [f64; 3], space: Space, factor: f64, terms: &[SeTerm]) {
        for t in terms {
            self.terms.push((diag, space, factor, *t));
        }
    }

    /// Groups basis directions with identical coefficients into classes (each one scalar problem).
    pub fn classes(&self) -> Vec<DirectionClass> {
        let mut classes: Vec<(Vec<f64>, DirectionClass)> = Vec::new();
        for (j, dir) in self.basis.iter().enumerate() {
            let signature: Vec<f64> = self.terms.iter().map(|(d, _, f, _)| d[j] * f).collect();
            if signature.iter().all(|c| *c == 0.0) {
                continue;
            }
            if let Some((_, class)) = classes.iter_mut().find(|(s, _)| *s == signature) {
                class.directions.push(*dir);
                continue;
            }
            let mut kernel = ScalarKernel::zero();
            for (c, (_, space, _, term)) in signature.iter().zip(&self.terms) {
                kernel.add(*space, *c, std::slice::from_ref(term));
            }
            classes.push((signature, DirectionClass { directions: vec![*dir], kernel }));
        }
        classes.into_iter().map(|(_, c)| c).collect()
    }

    /// Evaluates the full 3x3 matrix kernel between two points.
    pub fn eval_matrix(&self, a: &KernelPoint, b: &KernelPoint) -> [[f64; 3]; 3] {
        let mut m = [[0.0; 3]; 3];
        for class in self.classes() {
            let k = class.kernel.eval(a, b);
            for e in &class.directions {
                for (r, row) in m.iter_mut().enumerate() {
                    for (c, v) in row.iter_mut().enumerate() {
                        *v += k * e[r] * e[c];
                    }
                }
            }
        }
        m
    }
}

/// The paper's hyperparameters; every field can be overridden from TOML.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Hyperparameters {
    /// Shape kernel `Σ0` terms (mm): default `7 k_100 + 5 k_50 + 3 k_10`.
    pub shape_terms: Vec<SeTerm>,
    /// Symmetry strength α of the shape kernel (0.7).
    pub shape_alpha: f64,
    /// Albedo physical-space terms `Σ_xyz` (mm): default `0.02 k_500 + 0.01 k_20 + 0.01 k_2`.
    pub albedo_xyz_terms: Vec<SeTerm>,
    /// Albedo colour-space terms `Σ_rgb`: default `0.015 k_0.15`.
    pub albedo_rgb_terms: Vec<SeTerm>,
    /// Channel correlation β of the physical-space albedo kernel (0.9375).
    pub beta: f64,
    /// Channel correlation γ of the colour-space albedo kernel (0.95).
    pub gamma: f64,
    /// Symmetry strength α of the albedo kernel (0.7).
    pub albedo_alpha: f64,
}

impl Default for Hyperparameters {
    fn default() -> Self {
        let t = |weight, scale| SeTerm { weight, scale };
        Self {
            shape_terms: vec![t(7.0, 100.0), t(5.0, 50.0), t(3.0, 10.0)],
            shape_alpha: 0.7,
            albedo_xyz_terms: vec![t(0.02, 500.0), t(0.01, 20.0), t(0.01, 2.0)],
            albedo_rgb_terms: vec![t(0.015, 0.15)],
            beta: 0.9375,
            gamma: 0.95,
            albedo_alpha: 0.7,
        }
    }
}

/// Why hyperparameters were refused.
#[derive(Debug, thiserror::Error)]
pub enum HyperparameterError {
    /// The TOML could not be parsed.
    #[error("{path}: {error}")]
    Toml {
        /// File name.
        path: String,
        /// Parser error.
        error: toml::de::Error,
    },
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// File name.
        path: String,
        /// IO error.
        error: std::io::Error,
    },
    /// A value is out of its valid range.
    #[error("{path}: {error}")]
    Invalid {
        /// File name.
        path: String,
        /// Which value and its range.
        error: InvalidHyperparameter,
    },
}

/// A hyperparameter outside the range where the kernels it defines are positive semi-definite.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidHyperparameter {
    /// A kernel term's weight is negative or not finite.
    #[error("kernel weight {0} must be finite and non-negative")]
    Weight(f64),
    /// A kernel term's length scale is not positive or not finite.
    #[error("kernel scale {0} must be finite and positive")]
    Scale(f64),
    /// A symmetry weight outside `[-1, 1]`.
    #[error("{name} = {value} must lie in [-1, 1] for a valid kernel")]
    Symmetry {
        /// `shape_alpha` or `albedo_alpha`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A channel correlation outside `[-0.5, 1]`.
    #[error("{name} = {value} must lie in [-0.5, 1] (M_x is positive semi-definite only there)")]
    Correlation {
        /// `beta` or `gamma`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
}

impl Hyperparameters {
    /// Reads overrides from a TOML file (missing fields keep the paper's defaults).
    pub fn from_toml_file(path: &std::path::Path) -> Result<Self, HyperparameterError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| HyperparameterError::Io { path: name.clone(), error })?;
        let hp: Self = toml::from_str(&text).map_err(|error| HyperparameterError::Toml { path: name.clone(), error })?;
        hp.validate().map_err(|error| HyperparameterError::Invalid { path: name, error })?;
        Ok(hp)
    }

    /// Checks that the kernels these values define are positive semi-definite.
    pub fn validate(&self) -> Result<(), InvalidHyperparameter> {
        let all = self.shape_terms.iter().chain(&self.albedo_xyz_terms).chain(&self.albedo_rgb_terms);
        for t in all {
            if !(t.weight.is_finite() && t.weight >= 0.0) {
                return Err(InvalidHyperparameter::Weight(t.weight));
            }
            if !(t.scale.is_finite() && t.scale > 0.0) {
                return Err(InvalidHyperparameter::Scale(t.scale));
            }
        }
        for (name, a) in [("shape_alpha", self.shape_alpha), ("albedo_alpha", self.albedo_alpha)] {
            if !(a.is_finite() && (-1.0..=1.0).contains(&a)) {
                return Err(InvalidHyperparameter::Symmetry { name, value: a });
            }
        }
        for (name, x) in [("beta", self.beta), ("gamma", self.gamma)] {
            if !(x.is_finite() && (-0.5..=1.0).contains(&x)) {
                return Err(InvalidHyperparameter::Correlation { name, value: x });
            }
        }
        Ok(())
    }
}

/// The shape kernel `K_s = I3 Σ0`.
pub fn shape_standard(hp: &Hyperparameters) -> DiagonalKernel {
    let mut k = DiagonalKernel::new(AXES);
    k.add([1.0; 3], Space::Position, 1.0, &hp.shape_terms);
    k
}

/// The symmetric shape kernel `K_s_sym(x,y) = I3 Σ0(x,y) + α Φ Σ0(x, Φy)`.
pub fn shape_symmetric(hp: &Hyperparameters) -> DiagonalKernel {
    let mut k = shape_standard(hp);
    k.add([-1.0, 1.0, 1.0], Space::MirroredPosition, hp.shape_alpha, &hp.shape_terms);
    k
}

/// Which albedo kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlbedoKernel {
    /// `K_a = ½(I3 Σ_xyz + I3 Σ_rgb)`.
    Standard,
    /// `K_a,rgb = I3 Σ_rgb`.
    StandardRgb,
    /// `K_a,xyz = I3 Σ_xyz`.
    StandardXyz,
    /// `K_a_sym = ½(K_a,rgb_sym + K_a,xyz_sym)`.
    Symmetric,
    /// `K_a,rgb_sym = M_γ Σ_rgb`.
    SymmetricRgb,
    /// `K_a,xyz_sym(x,y) = M_β Σ_xyz(x,y) + α M_β Σ_xyz(x,Φy)`.
    SymmetricXyz,
    /// `K_a_cor = ½(K_a,rgb_sym + K_a,xyz_cor)`.
    Correlated,
    /// `K_a,rgb_cor = M_γ Σ_rgb`.
    CorrelatedRgb,
    /// `K_a,xyz_cor = M_β Σ_xyz`.
    CorrelatedXyz,
}

/// Builds an albedo kernel.
pub fn albedo(kind: AlbedoKernel, hp: &Hyperparameters) -> DiagonalKernel {
    use AlbedoKernel::*;
    let mut k = DiagonalKernel::new(luminance_basis());
    let ident = [1.0; 3];
    let m_beta = channel_correlation_diag(hp.beta);
    let m_gamma = channel_correlation_diag(hp.gamma);
    let (xyz, rgb) = (&hp.albedo_xyz_terms, &hp.albedo_rgb_terms);
    match kind {
        Standard => {
            k.add(ident, Space::Position, 0.5, xyz);
            k.add(ident, Space::Color, 0.5, rgb);
        }
        StandardRgb => k.add(ident, Space::Color, 1.0, rgb),
        StandardXyz => k.add(ident, Space::Position, 1.0, xyz),
        Symmetric => {
            k.add(m_gamma, Space::Color, 0.5, rgb);
            k.add(m_beta, Space::Position, 0.5, xyz);
            k.add(m_beta, Space::MirroredPosition, 0.5 * hp.albedo_alpha, xyz);
        }
        SymmetricRgb | CorrelatedRgb => k.add(m_gamma, Space::Color, 1.0, rgb),
        SymmetricXyz => {
            k.add(m_beta, Space::Position, 1.0, xyz);
            k.add(m_beta, Space::MirroredPosition, hp.albedo_alpha, xyz);
        }
        Correlated => {
            k.add(m_gamma, Space::Color, 0.5, rgb);
            k.add(m_beta, Space::Position, 0.5, xyz);
        }
        CorrelatedXyz => k.add(m_beta, Space::Position, 1.0, xyz),
    }
    k
}

/// The nine named models of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModelKernel {
    /// `K_s` with `K_a`.
    StandardFull,
    /// `K_s` with `K_a,rgb`.
    StandardRgb,
    /// `K_s` with `K_a,xyz`.
    StandardXyz,
    /// `K_s_sym` with `K_a_sym`.
    SymmetricFull,
    /// `K_s_sym` with `K_a,rgb_sym`.
    SymmetricRgb,
    /// `K_s_sym` with `K_a,xyz_sym`.
    SymmetricXyz,
    /// `K_s` with `K_a_cor`.
    CorrelatedFull,
    /// `K_s` with `K_a,rgb_cor`.
    CorrelatedRgb,
    /// `K_s` with `K_a,xyz_cor`.
    CorrelatedXyz,
}

impl ModelKernel {
    /// All nine, in the paper's order.
    pub const ALL: [ModelKernel; 9] = [
        ModelKernel::StandardFull,
        ModelKernel::StandardRgb,
        ModelKernel::StandardXyz,
        ModelKernel::SymmetricFull,
        ModelKernel::SymmetricRgb,
        ModelKernel::SymmetricXyz,
        ModelKernel::CorrelatedFull,
        ModelKernel::CorrelatedRgb,
        ModelKernel::CorrelatedXyz,
    ];

    /// The command-line name, e.g. `symmetric-full`.
    pub fn name(self) -> &'static str {
        match self {
            ModelKernel::StandardFull => "standard-full",
            ModelKernel::StandardRgb => "standard-rgb",
            ModelKernel::StandardXyz => "standard-xyz",
            ModelKernel::SymmetricFull => "symmetric-full",
            ModelKernel::SymmetricRgb => "symmetric-rgb",
            ModelKernel::SymmetricXyz => "symmetric-xyz",
            ModelKernel::CorrelatedFull => "correlated-full",
            ModelKernel::CorrelatedRgb => "correlated-rgb",
            ModelKernel::CorrelatedXyz => "correlated-xyz",
        }
    }

    /// The shape kernel of this model.
    pub fn shape_kernel(self, hp: &Hyperparameters) -> DiagonalKernel {
        match self {
            ModelKernel::SymmetricFull | ModelKernel::SymmetricRgb | ModelKernel::SymmetricXyz => shape_symmetric(hp),
            _ => shape_standard(hp),
        }
    }

    /// The albedo kernel of this model.
    pub fn albedo_kernel(self, hp: &Hyperparameters) -> DiagonalKernel {
        let kind = match self {
            ModelKernel::StandardFull => AlbedoKernel::Standard,
            ModelKernel::StandardRgb => AlbedoKernel::StandardRgb,
            ModelKernel::StandardXyz => AlbedoKernel::StandardXyz,
            ModelKernel::SymmetricFull => AlbedoKernel::Symmetric,
            ModelKernel::SymmetricRgb => AlbedoKernel::SymmetricRgb,
            ModelKernel::SymmetricXyz => AlbedoKernel::SymmetricXyz,
            ModelKernel::CorrelatedFull => AlbedoKernel::Correlated,
            ModelKernel::CorrelatedRgb => AlbedoKernel::CorrelatedRgb,
            ModelKernel::CorrelatedXyz => AlbedoKernel::CorrelatedXyz,
        };
        albedo(kind, hp)
    }
}

impl fmt::Display for ModelKernel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown kernel name.
#[derive(Debug, thiserror::Error)]
#[error("unknown kernel '{0}'; expected one of: standard-full, standard-rgb, standard-xyz, symmetric-full, symmetric-rgb, symmetric-xyz, correlated-full, correlated-rgb, correlated-xyz")]
pub struct UnknownKernel(pub String);

impl FromStr for ModelKernel {
    type Err = UnknownKernel;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        ModelKernel::ALL.into_iter().find(|k| k.name() == lower).ok_or_else(|| UnknownKernel(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64, z: f64, c: [f64; 3]) -> KernelPoint {
        KernelPoint { position: [x, y, z], color: c }
    }

    #[test]
    fn names_round_trip() {
        for k in ModelKernel::ALL {
            assert_eq!(k.name().parse::<ModelKernel>().unwrap(), k);
        }
        assert!("symmetric".parse::<ModelKernel>().is_err());
    }

    #[test]
    fn symmetric_shape_splits_into_two_classes() {
        let hp = Hyperparameters::default();
        let classes = shape_symmetric(&hp).classes();
        assert_eq!(classes.len(), 2);
        assert_eq!(classes[0].directions, vec![[1.0, 0.0, 0.0]]);
        assert_eq!(classes[1].directions.len(), 2);
        assert_eq!(shape_standard(&hp).classes().len(), 1);
    }

    #[test]
    fn correlated_albedo_channel_correlation_is_gamma_in_colour_space() {
        let hp = Hyperparameters::default();
        let k = albedo(AlbedoKernel::CorrelatedRgb, &hp);
        let a = p(0.0, 0.0, 0.0, [0.5, 0.4, 0.3]);
        let m = k.eval_matrix(&a, &a);
        assert!((m[0][1] / m[0][0] - hp.gamma).abs() < 1e-12);
        assert!((m[1][2] / m[2][2] - hp.gamma).abs() < 1e-12);
    }

    #[test]
    fn hyperparameters_reject_invalid_values() {
        let hp = Hyperparameters { shape_alpha: 1.5, ..Default::default() };
        assert!(hp.validate().is_err());
        let hp = Hyperparameters { beta: f64::NAN, ..Default::default() };
        assert!(hp.validate().is_err());
        assert!(Hyperparameters::default().validate().is_ok());
    }
}
