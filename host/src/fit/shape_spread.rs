//! How well a fit's landmarks pin its shape down: a Laplace approximation of the shape
//! coefficients' posterior, and the spread of every vertex along its normal that follows.
//!
//! The default fit's image chain does not move the shape (the start's solve fits it, led by the
//! landmarks), so the chain's own spread of the shape coefficients is zero and says nothing. Here
//! the shape's posterior is that of the coefficients' standard normal prior times the landmark
//! term linearised at the fit: precision `I + JᵀJ / s²`, `J` the projected landmarks' derivatives
//! by the fitted shape coefficients (the basis rows at the landmarks through the projection's
//! derivative) and `s` the landmarks' residual σ the
//! fit left ([`gpmm_core::fit::PoseSpread::residual_sigma_px`]) times [`SHAPE_SPREAD_FACTOR`].
//! With `A = s² I + JJᵀ = LLᵀ` (landmark coordinates by landmark coordinates, far smaller than the
//! coefficients) and `G = L⁻¹J`, the covariance is `I − GᵀG`: a coefficient's variance is
//! `1 − |G·j|²`, and a vertex's variance along its normal `n` is `|w|² − |Gw|²` with `w = Uᵀn`,
//! `U` the vertex's rows of the shape basis. The pixels' small share in the shape solve is left
//! out: the spread is the landmarks' and the prior's.

use super::error::FitRunError;
use super::params::Params;
use super::register::basis_entry;
use crate::gp::model::{GpModel, ModelPart, PartBasis};
use faer::Mat;
use gpmm_core::model::morphable::MorphableModel;

/// Factor on the landmarks' residual σ in the shape's posterior: one face's landmark residuals
/// are not independent, and the template's landmarks are not the person's, so the residual
/// alone makes the landmarks look surer of the shape than they are. Chosen on the Mitsuba
/// development set so that the vertices' 90 % intervals along the normal hold the true surface
/// about 90 % of the time (88 % there and on the test set; at 1, 74 %: docs/intervals.md).
pub const SHAPE_SPREAD_FACTOR: f32 = 6.0;

/// Central-difference step of a landmark's position in the projection's derivative (mm).
const STEP_MM: f32 = 0.5;

/// The shape coefficients' Laplace posterior from the landmarks (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeSpread {
    /// Standard deviations of the fitted shape coefficients.
    pub coeff_sd: Vec<f32>,
    /// `G = L⁻¹J` (landmark coordinates × coefficients): the covariance is `I − GᵀG`.
    reduction: Mat<f64>,
}

impl ShapeSpread {
    /// The spread of `params`' shape (coefficients of `model`, whose core view is `mm`) given the
    /// target `landmarks` (every one used) in a `width × height` image, with the landmarks' noise
    /// `residual_px` (px, before the factor). Errors when a landmark is behind the camera or the
    /// residual is not positive and finite.
    pub fn of(
        model: &GpModel,
        mm: &MorphableModel<'_>,
        params: &Params,
        landmarks: &[[f32; 2]],
        width: u32,
        height: u32,
        residual_px: f32,
    ) -> Result<Self, FitRunError> {
        let bad = |what: String| FitRunError::Settings(format!("shape spread: {what}"));
        let s = f64::from(residual_px * SHAPE_SPREAD_FACTOR);
        if !(s > 0.0 && s.is_finite()) {
            return Err(bad(format!("the landmarks' residual σ is {residual_px}")));
        }
        let k = params.shape_len().min(model.shape.rank());
        let mut points = vec![[0.0f32; 3]; mm.landmarks().len()];
        let n = mm.landmark_positions(params.shape_coeffs(), &mut points).map_err(|e| bad(format!("landmarks: {e:?}")))?;
        if n != landmarks.len() || n != model.landmarks.len() {
            return Err(bad(format!("{n} model landmarks for {} targets", landmarks.len())));
        }
        let cam = params.camera(width, height);
        let project = |p: [f32; 3]| cam.project(params.pose.transform_point(p)).map(|q| [q.x, q.y]);
        // J = (∂ projection / ∂ point) · (∂ point / ∂ coefficient): the points are linear in the
        // coefficients (the basis rows), the projection's 2 × 3 derivative by central differences.
        let mut jac = Mat::<f64>::zeros(2 * n, k);
        for (l, (p, &v)) in points.iter().zip(&model.landmarks).enumerate() {
            let mut d = [[0.0f64; 3]; 2];
            for axis in 0..3 {
                let (mut a, mut b) = (*p, *p);
                a[axis] += STEP_MM;
                b[axis] -= STEP_MM;
                let (Some(pa), Some(pb)) = (project(a), project(b)) else {
                    return Err(bad("a landmark is behind the camera".into()));
                };
                for c in 0..2 {
                    d[c][axis] = f64::from(pa[c] - pb[c]) / f64::from(2.0 * STEP_MM);
                }
            }
            let row = 3 * v as usize;
            for j in 0..k {
                let u = [0, 1, 2].map(|axis| basis_entry(&model.shape, row + axis, j));
                for c in 0..2 {
                    jac[(2 * l + c, j)] = d[c][0] * u[0] + d[c][1] * u[1] + d[c][2] * u[2];
                }
            }
        }
        if !jac.col_iter().all(|c| c.iter().all(|x| x.is_finite())) {
            return Err(bad("the landmarks' derivatives are not finite".into()));
        }
        let mut a: Mat<f64> = &jac * jac.transpose();
        for i in 0..2 * n {
            a[(i, i)] += s * s;
        }
        let llt = a.llt(faer::Side::Lower).map_err(|e| bad(format!("Cholesky: {e:?}")))?;
        let mut reduction = jac;
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(llt.L(), reduction.as_mut(), faer::Par::Seq);
        let coeff_sd = (0..k)
            .map(|j| {
                let reduced: f64 = (0..2 * n).map(|i| reduction[(i, j)].powi(2)).sum();
                (1.0 - reduced).max(0.0).sqrt() as f32
            })
            .collect();
        Ok(Self { coeff_sd, reduction })
    }

    /// Per vertex of `params`' shape, the standard deviation of its position along its normal (mm):
    /// how far the true surface may lie from the fitted one there.
    pub fn vertex_sd_mm(&self, model: &GpModel, params: &Params) -> Result<Vec<f32>, FitRunError> {
        let k = self.reduction.ncols();
        if model.shape.rank() < k {
            return Err(FitRunError::Model(format!("its shape has {} components, the spread {k}", model.shape.rank())));
        }
        let positions =
            model.shape.instance(&params.shape_coeffs()[..k]).map_err(|e| FitRunError::Model(format!("shape instance: {e}")))?;
        let mut normals = vec![[0.0f32; 3]; positions.len()];
        gpmm_core::render::vertex_normals(&positions, &model.triangles, &mut normals)
            .map_err(|e| FitRunError::Model(format!("normals of the fitted shape: {e:?}")))?;
        let n = positions.len();
        // W: row v is Uᵀn of vertex v.
        let w = normal_components(&model.shape, &normals, k);
        let gw: Mat<f64> = &self.reduction * w.transpose();
        Ok((0..n)
            .map(|v| {
                let prior: f64 = (0..k).map(|j| w[(v, j)].powi(2)).sum();
                let reduced: f64 = (0..gw.nrows()).map(|i| gw[(i, v)].powi(2)).sum();
                (prior - reduced).max(0.0).sqrt() as f32
            })
            .collect())
    }
}

/// `W`, row `v` holding `Uᵀn` of vertex `v`: each of the first `k` components' displacement of
/// the vertex along its normal `normals[v]`.
fn normal_components(part: &ModelPart, normals: &[[f32; 3]], k: usize) -> Mat<f64> {
    let n = normals.len();
    let mut w = Mat::<f64>::zeros(n, k);
    for j in 0..k {
        let mut col = w.col_mut(j);
        match &part.basis {
            // A factored component moves every vertex along one direction: its normal share.
            PartBasis::Factored { directions, fields } => {
                let d = directions[j];
                for (v, (f, nv)) in fields[j * n..(j + 1) * n].iter().zip(normals).enumerate() {
                    col[v] = f64::from(*f) * f64::from(d[0] * nv[0] + d[1] * nv[1] + d[2] * nv[2]);
                }
            }
            PartBasis::Dense { .. } => {
                for (v, nv) in normals.iter().enumerate() {
                    col[v] = (0..3).map(|c| basis_entry(part, 3 * v + c, j) * f64::from(nv[c])).sum();
                }
            }
        }
    }
    w
}
