//! The synthetic world of `gpmm synth` as meshes ("scans") and as models on its own topology.
//!
//! - **Scans**: identity `id` of the world (ICT shape in its face frame, mm, hole fans included,
//!   transferred and varied albedo) as a coloured mesh with its 68 landmark vertex ids, either
//!   whole ([`EvalWorld::full_scan`], what the images show) or cut to the face region
//!   ([`EvalWorld::cropped_scan`]) with the template's face crop
//!   ([`crate::mesh::template::face_crop_indices`], computed once on the ICT neutral), so that models
//!   learned from scans cover the same part of the face as the models built from the template.
//! - **Training identities** are the world's identities [`TRAIN_ID_BASE`]`+j` of the same seed:
//!   they never coincide with the test identities `0..count` of a `gpmm synth` directory.
//! - **Upper bound** ([`EvalWorld::upper_bound_model`]): the generating world itself as a model on the
//!   cropped ICT topology. Shape: the ICT identity modes (scaled by the world's identity scale) in the
//!   neutral's face frame, the hole fans' centres moving with their rings, orthogonalized (exact:
//!   the covariance `Σ_k m_k m_kᵀ` of the world). Colour: the world's albedo variation is not
//!   linear (brightness × tint × exp(bumps)), so its model is the PCA of many sampled albedos.
//! - **PCA baseline** ([`EvalWorld::pca_model`]): PCA of a few cropped training scans.

use crate::gp::model::GpModel;
use crate::mesh::geometry::{centroid, dot, sub};
use crate::mesh::template::{face_crop_indices, ibug_frame};
use crate::mesh::Mesh;
use crate::synth::{SynthOptions, SynthWorld};

use crate::eval::models::pca::{covariance_basis, dense_part, learned_metadata, pca_model};
use crate::eval::EvalError;

/// First identity number of the training identities (scans for PCA and KDE, colour samples of the upper bound).
pub const TRAIN_ID_BASE: usize = 1 << 20;

/// Attribution of everything derived from the ICT-FaceKit identity model.
pub const ICT_ATTRIBUTION: &str = "ICT-FaceKit Light (c) 2020 USC Institute for Creative Technologies, MIT licence; \
albedo from \"Infinite, 3D Head Scan\" by Lee Perry-Smith, CC BY 3.0";

/// A coloured mesh of one identity with its iBUG-68 landmark vertex ids.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Identity number in the world.
    pub id: usize,
    /// Positions (mm, the identity's face frame), colours, triangles.
    pub mesh: Mesh,
    /// The 68 landmark vertex ids.
    pub landmarks: Vec<u32>,
}

/// The world with its face-cropped topology.
#[derive(Debug, Clone)]
pub struct EvalWorld {
    world: SynthWorld,
    options: SynthOptions,
    /// The neutral in its face frame (mm), fan centres included.
    neutral: Vec<[f64; 3]>,
    /// Each fan centre vertex with its ring.
    fans: Vec<(usize, Vec<usize>)>,
    /// Rotation rows of the neutral's face frame.
    axes: [[f64; 3]; 3],
    /// World vertices kept by the face crop (ascending).
    keep: Vec<u32>,
    /// Cropped triangles and landmarks (indices into `keep`).
    triangles: Vec<[u32; 3]>,
    landmarks: Vec<u32>,
}

impl EvalWorld {
    /// Loads the world of `options` (ICT model, template albedo) and crops its topology.
    pub fn load(options: &SynthOptions) -> Result<Self, EvalError> {
        let world = SynthWorld::load(options)?;
        let n_ict = world.summary().vertices;
        let path = options.ict_dir.join("neutral.npy");
        let (_, raw) = crate::synth::npy::read_f32(&path).map_err(crate::synth::SynthError::from)?;
        let raw: Vec<[f64; 3]> = raw.chunks_exact(3).map(|c| [0, 1, 2].map(|k| 10.0 * f64::from(c[k]))).collect();
        if raw.len() != n_ict {
            return Err(EvalError::Invalid(format!("{}: {} vertices, the world has {n_ict}", path.display(), raw.len())));
        }
        let lm: Vec<[f64; 3]> = world.landmarks().iter().map(|&i| raw[i as usize]).collect();
        let frame = ibug_frame(&lm).map_err(|m| EvalError::Invalid(format!("ICT neutral: {m}")))?;
        let mut neutral: Vec<[f64; 3]> = raw
            .iter()
            .map(|p| {
                let d = sub(*p, frame.center);
                frame.axes.map(|a| dot(a, d))
            })
            .collect();
        // Fan centres: the vertices past the ICT ones; their rings are the other corners of their triangles.
        let total = world.base_albedo().len();
        let mut rings: Vec<Vec<usize>> = vec![Vec::new(); total - n_ict];
        for t in world.triangles() {
            for &c in t.iter().filter(|&&c| c as usize >= n_ict) {
                rings[c as usize - n_ict].extend(t.iter().filter(|&&v| v != c).map(|&v| v as usize));
            }
        }
        let mut fans = Vec::new();
        for (k, mut ring) in rings.into_iter().enumerate() {
            ring.sort_unstable();
            ring.dedup();
            neutral.push(centroid(ring.iter().map(|&i| neutral[i])));
            fans.push((n_ict + k, ring));
        }
        let full = Mesh { positions: neutral.clone(), colors: vec![[0.5; 3]; neutral.len()], triangles: world.triangles().to_vec() };
        let keep = face_crop_indices(&full, world.landmarks()).map_err(|m| EvalError::Invalid(format!("ICT face crop: {m}")))?;
        let mut map = vec![u32::MAX; neutral.len()];
        for (new, &old) in keep.iter().enumerate() {
            map[old as usize] = new as u32;
        }
        let triangles: Vec<[u32; 3]> = world
            .triangles()
            .iter()
            .filter(|t| t.iter().all(|&i| map[i as usize] != u32::MAX))
            .map(|t| t.map(|i| map[i as usize]))
            .collect();
        let landmarks: Vec<u32> = world.landmarks().iter().map(|&i| map[i as usize]).collect();
        if landmarks.contains(&u32::MAX) {
            return Err(EvalError::Invalid("the ICT face crop dropped a landmark".into()));
        }
        Ok(Self { world, options: options.clone(), neutral, fans, axes: frame.axes, keep, triangles, landmarks })
    }

    /// The world's options.
    pub fn options(&self) -> &SynthOptions {
        &self.options
    }

    /// Vertices of the cropped topology.
    pub fn cropped_vertices(&self) -> usize {
        self.keep.len()
    }

    /// The neutral (no identity coefficients) on the whole world topology, face frame, mm.
    pub fn neutral(&self) -> &[[f64; 3]] {
        &self.neutral
    }

    /// Identity `id` on the whole world topology (what `gpmm synth` renders).
    pub fn full_scan(&self, id: usize) -> Result<Scan, EvalError> {
        let identity = self.world.identity(id)?;
        let mesh = Mesh {
            positions: identity.positions.iter().map(|p| p.map(f64::from)).collect(),
            colors: identity.albedo.iter().map(|c| c.map(f64::from)).collect(),
            triangles: self.world.triangles().to_vec(),
        };
        Ok(Scan { id, mesh, landmarks: self.world.landmarks().to_vec() })
    }

    /// The world's mean face (ICT neutral, transferred template albedo) on the whole topology,
    /// as a scan like [`Self::full_scan`]'s (`id` is `usize::MAX`): what the paper's models are
    /// built around (it uses the BFM mean).
    pub fn mean_scan(&self) -> Scan {
        let (positions, albedo) = self.world.mean_face();
        let mesh = Mesh {
            positions: positions.iter().map(|p| p.map(f64::from)).collect(),
            colors: albedo.iter().map(|c| c.map(f64::from)).collect(),
            triangles: self.world.triangles().to_vec(),
        };
        Scan { id: usize::MAX, mesh, landmarks: self.world.landmarks().to_vec() }
    }

    /// Identity `id` cut to the face region (the topology of the upper-bound and PCA models).
    pub fn cropped_scan(&self, id: usize) -> Result<Scan, EvalError> {
        let full = self.full_scan(id)?;
        let pick = |v: &[[f64; 3]]| self.keep.iter().map(|&i| v[i as usize]).collect::<Vec<_>>();
        let mesh = Mesh { positions: pick(&full.mesh.positions), colors: pick(&full.mesh.colors), triangles: self.triangles.clone() };
        Ok(Scan { id, mesh, landmarks: self.landmarks.clone() })
    }

    /// The 10-scan (or `count`-scan) PCA baseline: PCA of the cropped training identities `TRAIN_ID_BASE + 0..count`.
    pub fn pca_model(&self, count: usize) -> Result<GpModel, EvalError> {
        let scans: Vec<Mesh> = (0..count).map(|j| self.cropped_scan(TRAIN_ID_BASE + j).map(|s| s.mesh)).collect::<Result<_, _>>()?;
        let source = format!("PCA of {count} synthetic identities (gpmm synth world, seed {})", self.options.seed);
        pca_model(&scans, &self.triangles, &self.landmarks, &format!("pca-{count}"), &source, ICT_ATTRIBUTION)
    }

    /// The generating world as a model: exact ICT shape covariance, albedo PCA of `color_samples` identities (rank ≤ `color_rank`).
    pub fn upper_bound_model(&self, color_samples: usize, color_rank: usize) -> Result<GpModel, EvalError> {
        let path = self.options.ict_dir.join("identity_modes.npy");
        let (shape, modes) = crate::synth::npy::read_f32(&path).map_err(crate::synth::SynthError::from)?;
        let n_ict = self.neutral.len() - self.fans.len();
        let used = self.world.summary().modes;
        if shape.len() != 3 || shape[1] != n_ict || shape[2] != 3 || shape[0] < used {
            return Err(EvalError::Invalid(format!("{}: shape {shape:?} does not match the world", path.display())));
        }
        let s = f64::from(self.options.identity_scale);
        let deviations: Vec<Vec<f64>> = (0..used)
            .map(|k| {
                let raw = &modes[k * n_ict * 3..(k + 1) * n_ict * 3];
                let mut m: Vec<[f64; 3]> =
                    raw.chunks_exact(3).map(|c| self.axes.map(|a| 10.0 * dot(a, [0, 1, 2].map(|j| f64::from(c[j]))))).collect();
                for (_, ring) in &self.fans {
                    m.push(centroid(ring.iter().map(|&i| m[i])));
                }
                self.keep.iter().flat_map(|&i| m[i as usize]).collect()
            })
            .collect();
        let (es, bs) = covariance_basis(&deviations, s * s, used)?;
        let samples: Vec<Mesh> =
            (0..color_samples.max(2)).map(|j| self.cropped_scan(TRAIN_ID_BASE + j).map(|s| s.mesh)).collect::<Result<_, _>>()?;
        let colors: Vec<&[[f64; 3]]> = samples.iter().map(|m| m.colors.as_slice()).collect();
        let n = self.keep.len();
        let mut mc = vec![[0.0; 3]; n];
        for c in &colors {
            for (m, v) in mc.iter_mut().zip(c.iter()) {
                for k in 0..3 {
                    m[k] += v[k] / colors.len() as f64;
                }
            }
        }
        let dc: Vec<Vec<f64>> =
            colors.iter().map(|c| c.iter().zip(&mc).flat_map(|(v, m)| [0, 1, 2].map(|k| v[k] - m[k])).collect()).collect();
        let (ec, bc) = covariance_basis(&dc, 1.0 / (colors.len() - 1) as f64, color_rank)?;
        let ms: Vec<[f64; 3]> = self.keep.iter().map(|&i| self.neutral[i as usize]).collect();
        let source = format!(
            "the gpmm synth world: ICT identity modes x {s}, albedo PCA of {} identities (seed {})",
            colors.len(),
            self.options.seed
        );
        // The colour trace is the total sample variance (all components), so compactness is relative to the whole variation.
        let color_trace: f64 = dc.iter().map(|d| d.iter().map(|v| v * v).sum::<f64>()).sum::<f64>() / (colors.len() - 1) as f64;
        Ok(GpModel {
            shape: dense_part(&ms, es.clone(), &bs),
            color: dense_part(&mc, ec, &bc),
            triangles: self.triangles.clone(),
            landmarks: self.landmarks.clone(),
            metadata: learned_metadata("upper-bound", es.iter().sum(), color_trace, &source, ICT_ATTRIBUTION),
        })
    }
}
