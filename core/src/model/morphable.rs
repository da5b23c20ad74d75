//! The borrowed model view used by the fitter (its cached per-vertex instance is in [`super::instance`]).

use crate::error::FitError;
use crate::geometry::{TriIndex, Vec3};
use crate::model::basis::{Basis, FactoredBasis};
use crate::model::MAX_LANDMARKS;

/// A morphable model, borrowed: means, bases, triangles and landmark vertex ids (iBUG-68 order).
///
/// ```
/// use gpmm_core::model::{Basis, FactoredBasis, MorphableModel};
///
/// // A tetrahedron (mm) with one shape component, which lifts the apex by 10 mm per unit
/// // coefficient, and no colour component.
/// let shape_mean = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]];
/// let color_mean = [[0.5; 3]; 4];
/// let (fields, directions) = ([0.0, 0.0, 0.0, 10.0], [[0.0, 0.0, 1.0]]);
/// let shape = Basis::Factored(FactoredBasis::new(&fields, &directions, 4)?);
/// let color = Basis::Factored(FactoredBasis::new(&[], &[], 4)?);
/// let triangles: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
/// let landmarks = [3];
/// let model = MorphableModel::new(&shape_mean, &color_mean, shape, color, &triangles, &landmarks)?;
/// assert_eq!((model.vertices(), model.shape_rank(), model.color_rank()), (4, 1, 0));
///
/// // An instance: the mean plus the coefficients times the components.
/// let mut positions = [[0.0; 3]; 4];
/// model.shape_instance(&[0.5], &mut positions)?;
/// assert_eq!(positions, [shape_mean[0], shape_mean[1], shape_mean[2], [0.0, 0.0, 15.0]]);
/// let mut apex = [[0.0; 3]; 1];
/// model.landmark_positions(&[-1.0], &mut apex)?;
/// assert_eq!(apex, [[0.0, 0.0, 0.0]]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct MorphableModel<'a, I: TriIndex = u32> {
    shape_mean: &'a [Vec3],
    color_mean: &'a [Vec3],
    shape: Basis<'a>,
    color: Basis<'a>,
    triangles: &'a [[I; 3]],
    landmarks: &'a [u32],
    /// The shape basis at the landmark vertices only, contiguous (see [`MorphableModel::with_landmark_fields`]).
    landmark_basis: Option<FactoredBasis<'a>>,
}

/// `0, 1, 2, …`: the vertex ids of a basis restricted to the landmarks.
// (A compile-time loop: `i < MAX_LANDMARKS` bounds the index.)
#[allow(clippy::indexing_slicing)]
const IN_ORDER: [u32; MAX_LANDMARKS] = {
    let mut ids = [0u32; MAX_LANDMARKS];
    let mut i = 0;
    while i < MAX_LANDMARKS {
        ids[i] = i as u32;
        i += 1;
    }
    ids
};

impl<'a, I: TriIndex> MorphableModel<'a, I> {
    /// Wraps borrowed model data, checking every length and index once (O(vertices + triangles)).
    pub fn new(
        shape_mean: &'a [Vec3],
        color_mean: &'a [Vec3],
        shape: Basis<'a>,
        color: Basis<'a>,
        triangles: &'a [[I; 3]],
        landmarks: &'a [u32],
    ) -> Result<Self, FitError> {
        let n = shape_mean.len();
        if color_mean.len() != n || shape.vertices() != n || color.vertices() != n {
            return Err(FitError::LengthMismatch);
        }
        if landmarks.len() > MAX_LANDMARKS {
            return Err(FitError::TooManyLandmarks);
        }
        if landmarks.iter().any(|&l| l as usize >= n) || triangles.iter().flatten().any(|i| i.index() >= n) {
            return Err(FitError::IndexOutOfRange);
        }
        if !shape_mean.iter().chain(color_mean).flatten().all(|v| v.is_finite()) {
            return Err(FitError::NonFinite);
        }
        Ok(Self { shape_mean, color_mean, shape, color, triangles, landmarks, landmark_basis: None })
    }

    /// The shape basis's fields at the landmark vertices, `rank × landmarks` row-major, into `out`
    /// (for [`MorphableModel::with_landmark_fields`]); `None` unless the shape basis is factored
    /// and `out` has exactly that length.
    pub fn landmark_fields(&self, out: &mut [f32]) -> Option<()> {
        let Basis::Factored(shape) = self.shape else {
            return None;
        };
        let (n, l) = (shape.vertices(), self.landmarks.len());
        if out.len() != shape.rank() * l || n == 0 || l == 0 {
            return None;
        }
        for (full, part) in shape.fields().chunks_exact(n).zip(out.chunks_exact_mut(l)) {
            for (p, &v) in part.iter_mut().zip(self.landmarks) {
                *p = *full.get(v as usize)?;
            }
        }
        Some(())
    }

    /// Uses `fields` (`rank × landmarks` row-major: component `k`'s field at landmark `j` is
    /// `fields[k · landmarks + j]`) for the landmark positions: the same values as the shape
    /// basis's at the landmark vertices (checked here, bit for bit), but contiguous, so the
    /// landmark sums of every shape proposal read a few kilobytes instead of gathering across the
    /// whole basis. Only for a factored shape basis.
    pub fn with_landmark_fields(mut self, fields: &'a [f32]) -> Result<Self, FitError> {
        let Basis::Factored(shape) = self.shape else {
            return Err(FitError::BadConfig);
        };
        let (n, l) = (shape.vertices(), self.landmarks.len());
        let basis = FactoredBasis::new(fields, shape.directions(), l).map_err(|_| FitError::LengthMismatch)?;
        let same = shape.fields().chunks_exact(n.max(1)).zip(fields.chunks_exact(l.max(1))).all(|(full, part)| {
            self.landmarks.iter().zip(part).all(|(&v, p)| full.get(v as usize).map(|f| f.to_bits()) == Some(p.to_bits()))
        });
        if !same {
            return Err(FitError::BadConfig);
        }
        self.landmark_basis = Some(basis);
        Ok(self)
    }

    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.shape_mean.len()
    }

    /// Shape rank (number of shape components).
    pub fn shape_rank(&self) -> usize {
        self.shape.rank()
    }

    /// Colour rank.
    pub fn color_rank(&self) -> usize {
        self.color.rank()
    }

    /// The triangle list.
    pub fn triangles(&self) -> &'a [[I; 3]] {
        self.triangles
    }

    /// Landmark vertex ids.
    pub fn landmarks(&self) -> &'a [u32] {
        self.landmarks
    }

    /// The shape mean.
    pub fn shape_mean(&self) -> &'a [Vec3] {
        self.shape_mean
    }

    /// Shape instance positions into `out` (one per vertex).
    pub fn shape_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), FitError> {
        if out.len() != self.vertices() {
            return Err(FitError::LengthMismatch);
        }
        out.copy_from_slice(self.shape_mean);
        Ok(self.shape.add_instance(coeffs, out)?)
    }

    /// Colour instance (albedo) into `out` (one per vertex).
    pub fn color_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), FitError> {
        if out.len() != self.vertices() {
            return Err(FitError::LengthMismatch);
        }
        out.copy_from_slice(self.color_mean);
        Ok(self.color.add_instance(coeffs, out)?)
    }

    /// Mean albedo, one per vertex.
    pub fn color_mean(&self) -> &'a [Vec3] {
        self.color_mean
    }

    /// Shape component `k`'s (scaled) vector at `vertex` (zero outside the basis).
    pub fn shape_component(&self, k: usize, vertex: usize) -> Vec3 {
        self.shape.component_at(k, vertex)
    }

    /// Colour component `k`'s (scaled) vector at `vertex` (zero outside the basis).
    pub fn color_component(&self, k: usize, vertex: usize) -> Vec3 {
        self.color.component_at(k, vertex)
    }

    /// The first `out.len()` colour components' (scaled) vectors at `vertex` into `out`.
    pub fn color_components_at(&self, vertex: usize, out: &mut [Vec3]) {
        self.color.components_at(vertex, out)
    }

    /// Instance position of one vertex (`rank` multiply-adds per coordinate).
    pub fn vertex_position(&self, coeffs: &[f32], vertex: u32) -> Result<Vec3, FitError> {
        let mut p = self.shape_mean.get(vertex as usize).copied().ok_or(FitError::IndexOutOfRange)?;
        self.shape.add_vertex(coeffs, vertex as usize, &mut p)?;
        Ok(p)
    }

    /// Instance positions of the landmark vertices only (`rank × landmarks` multiply-adds) into
    /// `out[..landmarks]`; returns the number written.
    pub fn landmark_positions(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<usize, FitError> {
        let n = self.landmarks.len();
        self.landmarks_into(coeffs, 0..n, out.get_mut(..n).ok_or(FitError::LengthMismatch)?)?;
        Ok(n)
    }

    /// Instance position of landmark `i` alone (`rank` multiply-adds): the same bits as
    /// [`Self::landmark_positions`] gives it.
    pub fn landmark_position(&self, coeffs: &[f32], i: usize) -> Result<Vec3, FitError> {
        let mut out = [[0.0f32; 3]];
        self.landmarks_into(coeffs, i..i + 1, &mut out)?;
        Ok(out[0])
    }

    /// The positions of landmarks `range` into `out` (one per landmark; each sum is independent
    /// of the others, so any range gives the same bits).
    fn landmarks_into(&self, coeffs: &[f32], range: core::ops::Range<usize>, out: &mut [Vec3]) -> Result<(), FitError> {
        let ids = self.landmarks.get(range.clone()).ok_or(FitError::IndexOutOfRange)?;
        if out.len() != ids.len() {
            return Err(FitError::LengthMismatch);
        }
        for (o, &l) in out.iter_mut().zip(ids) {
            *o = self.shape_mean.get(l as usize).copied().ok_or(FitError::IndexOutOfRange)?;
        }
        match (self.landmark_basis, IN_ORDER.get(range)) {
            // The same components in the same order, from contiguous fields: the same sums.
            (Some(b), Some(rows)) => Basis::Factored(b).add_vertices(coeffs, rows, out)?,
            _ => self.shape.add_vertices(coeffs, ids, out)?,
        }
        Ok(())
    }
}
