//! `gpmm.Model`: a morphable model, its arrays, and what can be done with it.

use crate::args::{coefficients, fit_settings_error, opt, within_rank, FitKeywords, Int};
use crate::arrays::{
    basis_to_numpy, json_to_py, numpy_to_points, numpy_to_rgb, points_to_numpy, rgb_to_numpy, rgba_to_numpy, vec3_to_numpy, vec_to_numpy,
};
use crate::errors::{err, read_error, value_error, write_error};
use crate::from_arrays::{model_from_arrays, PartArrays};
use gpmm_host::device::quantize::{self as q, Bits, Profile, QuantizeOptions};
use gpmm_host::fit::{camera_space_mesh, fit_image, overlay, report, ReportInputs};
use gpmm_host::gp::model::{GpModel, PartBasis};
use gpmm_host::gp::{model_io, statismo};
use gpmm_host::learn::shading::ShadingBases;
use gpmm_host::photo::calibration::LandmarkCalibration;
use gpmm_host::render::light::{light_from_rows, parse_background, parse_light};
use gpmm_host::render::{render_model, RenderSettings, View};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// A morphable model of shape (mm) and albedo (linear RGB): mean, bases, eigenvalues, triangles,
/// landmarks and metadata. Immutable; pickles through its model-file bytes.
#[pyclass(module = "gpmm._gpmm", name = "Model", frozen)]
pub struct Model {
    inner: Arc<GpModel>,
    source: String,
    /// Shape from shading's bases of this model, once a learning fit on this process asked for
    /// them (with the key of the ranks and settings they were made for).
    shading: Mutex<Option<(String, Arc<ShadingBases>)>>,
}

impl Model {
    /// Wraps a host model; `source` names it in fit reports (its file, or `<bytes>`).
    pub fn new(model: GpModel, source: String) -> Self {
        Self { inner: Arc::new(model), source, shading: Mutex::new(None) }
    }

    /// The host model.
    pub(crate) fn host(&self) -> &Arc<GpModel> {
        &self.inner
    }

    /// Shape from shading's bases for `key` (the ranks and settings `make` prepares them with):
    /// the ones kept from the last call with the same key, else made now and kept.
    pub(crate) fn shading_bases<E>(
        &self,
        key: &str,
        make: impl FnOnce(&GpModel) -> Result<ShadingBases, E>,
    ) -> Result<Arc<ShadingBases>, E> {
        let mut kept = self.shading.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((k, bases)) = kept.as_ref() {
            if k == key {
                return Ok(bases.clone());
            }
        }
        let bases = Arc::new(make(&self.inner)?);
        *kept = Some((key.to_string(), bases.clone()));
        Ok(bases)
    }
}

fn layout(b: &PartBasis) -> &'static str {
    match b {
        PartBasis::Factored { .. } => "factored",
        PartBasis::Dense { .. } => "dense",
    }
}

/// A light from a preset name / JSON text / file, or from 9 rows of 3 numbers.
fn light_arg(obj: &Bound<'_, PyAny>) -> PyResult<gpmm_core::render::ShLight> {
    if let Ok(s) = obj.extract::<String>() {
        return parse_light(&s).map_err(err);
    }
    let rows: Vec<Vec<f32>> =
        obj.extract().map_err(|_| value_error("light must be a preset name, JSON text, a file or 9 rows of [r, g, b]"))?;
    light_from_rows(&rows).map_err(err)
}

#[pymethods]
impl Model {
    /// Loads a model file (`.gpmm`).
    #[staticmethod]
    pub(crate) fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let name = path.display().to_string();
        let m = py.detach(|| model_io::load(&path)).map_err(|e| read_error(e, &[&path]))?;
        Ok(Self::new(m, name))
    }

    /// A model from the bytes of a model file.
    #[staticmethod]
    pub(crate) fn from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<Self> {
        let data = data.to_vec();
        let m = py.detach(move || model_io::from_bytes(&data, "<bytes>")).map_err(err)?;
        Ok(Self::new(m, "<bytes>".into()))
    }

    /// A model from numpy arrays: `shape_mean` `N x 3` (mm), `triangles` `T x 3` vertex ids, and for shape
    /// and colour (linear RGB) a `*_basis` `K x N x 3` scaled by sqrt(eigenvalue) (as `shape_basis` gives)
    /// or a factored `*_directions` `K x 3` + `*_fields` `K x N`, `*_eigenvalues` `K` (descending;
    /// default: the components' squared norms), `landmarks` vertex ids and `metadata` entries.
    #[staticmethod]
    #[pyo3(signature = (shape_mean, triangles, *, shape_basis = None, shape_eigenvalues = None, shape_directions = None,
        shape_fields = None, color_mean = None, color_basis = None, color_eigenvalues = None, color_directions = None,
        color_fields = None, landmarks = None, metadata = None))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays<'py>(
        shape_mean: Bound<'py, PyAny>,
        triangles: Bound<'py, PyAny>,
        shape_basis: Option<Bound<'py, PyAny>>,
        shape_eigenvalues: Option<Bound<'py, PyAny>>,
        shape_directions: Option<Bound<'py, PyAny>>,
        shape_fields: Option<Bound<'py, PyAny>>,
        color_mean: Option<Bound<'py, PyAny>>,
        color_basis: Option<Bound<'py, PyAny>>,
        color_eigenvalues: Option<Bound<'py, PyAny>>,
        color_directions: Option<Bound<'py, PyAny>>,
        color_fields: Option<Bound<'py, PyAny>>,
        landmarks: Option<Bound<'py, PyAny>>,
        metadata: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let shape = PartArrays {
            mean: Some(shape_mean),
            basis: shape_basis,
            eigenvalues: shape_eigenvalues,
            directions: shape_directions,
            fields: shape_fields,
        };
        let color = PartArrays {
            mean: color_mean,
            basis: color_basis,
            eigenvalues: color_eigenvalues,
            directions: color_directions,
            fields: color_fields,
        };
        let model = model_from_arrays(shape, color, &triangles, landmarks.as_ref(), metadata.as_ref())?;
        Ok(Self::new(model, "<arrays>".into()))
    }

    /// Writes the model file (safetensors, docs/model-format.md).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let m = self.inner.clone();
        py.detach(|| model_io::save(&m, &path)).map_err(|e| write_error(e, &path))
    }

    /// The model file's bytes.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let m = self.inner.clone();
        let bytes = py.detach(move || model_io::to_bytes(&m)).map_err(err)?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Pickling: the model travels as its model-file bytes.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let f = py.import("gpmm._gpmm")?.getattr("model_from_bytes")?;
        Ok((f, (self.to_bytes(py)?,)))
    }

    /// Equal arrays and metadata.
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.extract::<PyRef<'_, Model>>().is_ok_and(|o| *o.inner == *self.inner)
    }

    fn __repr__(&self) -> String {
        format!(
            "<gpmm.Model {}: {} vertices, ranks {}/{} ({}/{}), {} landmarks>",
            self.inner.metadata.kernel,
            self.inner.vertices(),
            self.inner.shape.rank(),
            self.inner.color.rank(),
            layout(&self.inner.shape.basis),
            layout(&self.inner.color.basis),
            self.inner.landmarks.len()
        )
    }

    /// Number of vertices N.
    #[getter]
    fn vertices(&self) -> usize {
        self.inner.vertices()
    }

    /// Number of shape components.
    #[getter]
    fn rank_shape(&self) -> usize {
        self.inner.shape.rank()
    }

    /// Number of colour components.
    #[getter]
    fn rank_color(&self) -> usize {
        self.inner.color.rank()
    }

    /// Basis layouts of shape and colour: `factored` or `dense`.
    #[getter]
    fn layout(&self) -> (&'static str, &'static str) {
        (layout(&self.inner.shape.basis), layout(&self.inner.color.basis))
    }

    /// Mean positions, `N x 3` float32 (mm).
    #[getter]
    fn shape_mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        vec3_to_numpy(py, &self.inner.shape.mean)
    }

    /// Mean albedo, `N x 3` float32 (linear RGB in [0, 1]).
    #[getter]
    fn color_mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        vec3_to_numpy(py, &self.inner.color.mean)
    }

    /// Shape eigenvalues (mm²), float64 `K`.
    #[getter]
    fn shape_eigenvalues<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        vec_to_numpy(py, self.inner.shape.eigenvalues.clone())
    }

    /// Colour eigenvalues, float64 `K`.
    #[getter]
    fn color_eigenvalues<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        vec_to_numpy(py, self.inner.color.eigenvalues.clone())
    }

    /// Shape basis, `K x N x 3` float32, each component scaled by sqrt(eigenvalue) (dense, whatever the stored layout).
    #[getter]
    fn shape_basis<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let p = &self.inner.shape;
        basis_to_numpy(py, statismo::dense_values(p), p.rank(), p.mean.len())
    }

    /// Colour basis, `K x N x 3` float32, scaled like `shape_basis`.
    #[getter]
    fn color_basis<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let p = &self.inner.color;
        basis_to_numpy(py, statismo::dense_values(p), p.rank(), p.mean.len())
    }

    /// Triangles, `T x 3` uint32 (counter-clockwise seen from outside).
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        vec3_to_numpy(py, &self.inner.triangles)
    }

    /// Landmark vertex ids, uint32 `L` (iBUG-68 order for `ibug68`).
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        vec_to_numpy(py, self.inner.landmarks.clone())
    }

    /// The model's metadata (docs/model-format.md) as a dict.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.inner.metadata)
    }

    /// The key figures `gpmm info` prints, as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.inner.summary(0))
    }

    /// The instance for the given coefficients (missing ones zero): positions and colours (clamped to [0, 1]), `N x 3` float32 each.
    #[pyo3(signature = (shape = None, color = None))]
    fn instance<'py>(
        &self,
        py: Python<'py>,
        shape: Option<&Bound<'py, PyAny>>,
        color: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let shape = coefficients(shape, "shape", self.inner.shape.rank())?;
        let color = coefficients(color, "color", self.inner.color.rank())?;
        let mesh = self.inner.instance(&shape, &color).map_err(err)?;
        mesh_arrays(py, &mesh)
    }

    /// `n` random instances (all coefficients ~ N(0, 1)), drawn as `gpmm sample --seed` draws them: a list of (positions, colours).
    #[pyo3(signature = (n = Int::of(1), seed = Int::of(0)), text_signature = "(self, /, n=1, seed=0)")]
    fn sample<'py>(&self, py: Python<'py>, n: Int, seed: Int) -> PyResult<Vec<(Bound<'py, PyAny>, Bound<'py, PyAny>)>> {
        let (n, seed): (usize, u64) = (n.get("n")?, seed.get("seed")?);
        let m = self.inner.clone();
        let meshes = py
            .detach(move || {
                let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
                (0..n).map(|_| m.sample(&mut rng)).collect::<Result<Vec<_>, _>>()
            })
            .map_err(err)?;
        meshes.iter().map(|mesh| mesh_arrays(py, mesh)).collect()
    }

    /// Renders the model as `gpmm render` does: an `H x W x 4` uint8 image (linear RGB as-is, alpha 0 where uncovered
    /// only with background="transparent"). `light`: a preset, JSON text/file or 9 rows of [r, g, b].
    #[pyo3(signature = (shape = None, color = None, yaw = 0.0, pitch = 0.0, roll = 0.0, light = None, width = Int::of(256), height = Int::of(256), background = "0,0,0", fov = 20.0),
        text_signature = "(self, /, shape=None, color=None, yaw=0.0, pitch=0.0, roll=0.0, light=None, width=256, height=256, background='0,0,0', fov=20.0)")]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        shape: Option<&Bound<'py, PyAny>>,
        color: Option<&Bound<'py, PyAny>>,
        yaw: f32,
        pitch: f32,
        roll: f32,
        light: Option<&Bound<'py, PyAny>>,
        width: Int,
        height: Int,
        background: &str,
        fov: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let s = coefficients(shape, "shape", self.inner.shape.rank())?;
        let c = coefficients(color, "color", self.inner.color.rank())?;
        let (width, height) = (width.get("width")?, height.get("height")?);
        let light = match light {
            Some(l) => light_arg(l)?,
            None => parse_light("frontal").map_err(err)?,
        };
        let settings = RenderSettings {
            width,
            height,
            light,
            background: parse_background(background).map_err(err)?,
            fov_deg: fov,
            ..RenderSettings::default()
        };
        settings.validate().map_err(err)?;
        let m = self.inner.clone();
        let img = py.detach(move || render_model(&m, &s, &c, View { yaw, pitch, roll }, &settings)).map_err(err)?;
        rgba_to_numpy(py, &img)
    }

    /// Fits the model to a photo as `gpmm fit` does (same settings, defaults and seed: the same numbers).
    ///
    /// `image`: `H x W x 3` uint8 RGB; `landmarks`: `L x 2` pixel coordinates (0-based, pixel centres at +0.5),
    /// or `None`: the face is found and its 68 landmarks read by `init` (an init file; default: the start gpmm
    /// ships), as `gpmm fit PHOTO` without `--landmarks` does (the largest face, or `face`: its place in
    /// `gpmm.detect`'s list); the result's `detected` holds that face (box, score, landmarks).
    /// Returns a dict with fit.json's fields (pose in degrees, `translation_mm`, `focal_px`, `light` 9 x 3,
    /// `shape` / `color` coefficients, `fitted_landmarks` in the photo, `log_likelihood`, `log_densities`,
    /// `acceptance`, RMSEs, `crop`, `posterior`: the image chain's mean and spread per coefficient;
    /// docs/fit-json.md), `mesh` (camera-space `vertices`, `triangles`, `colors` and `vertex_sd_mm`,
    /// each vertex's standard deviation along its normal) and images: `overlay` (input | fit | blend, and the occluded pixels with
    /// `set=["occlusion.rounds=3"]`), `render` (the fit, RGBA), `working_image` (the crop the chains
    /// saw) and, for an occlusion-aware fit, `occluded` (H x W booleans of the working image) and
    /// `occluded_photo` (the same labels on the photo, its H x W) beside
    /// `occluded_fraction`. `landmark_calibration`: a detector calibration file
    /// (`gpmm calibrate-landmarks`) whose offsets are removed from the landmarks first.
    /// `image` may also be `H x W x 4` (RGBA: alpha is dropped) or anything `numpy.asarray` makes such an
    /// array of (a PIL image); its values are used as they are (the model's colours are linear RGB).
    #[pyo3(signature = (image, landmarks = None, *, seed = None, size = None, landmark_steps = None, image_steps = None,
        shape_rank = None, color_rank = None, landmark_sigma = None, contour_sigma = None, set = None,
        landmark_calibration = None, init = None, face = None))]
    #[allow(clippy::too_many_arguments)]
    fn fit<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        landmarks: Option<&Bound<'py, PyAny>>,
        seed: Option<Int>,
        size: Option<Int>,
        landmark_steps: Option<Int>,
        image_steps: Option<Int>,
        shape_rank: Option<Int>,
        color_rank: Option<Int>,
        landmark_sigma: Option<f32>,
        contour_sigma: Option<f32>,
        set: Option<&Bound<'py, PyAny>>,
        landmark_calibration: Option<PathBuf>,
        init: Option<PathBuf>,
        face: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let keywords = FitKeywords { seed, size, landmark_steps, image_steps, shape_rank, color_rank, landmark_sigma, contour_sigma, set };
        let mut flags = keywords.flags(Some([self.inner.shape.rank(), self.inner.color.rank()]))?;
        let photo = numpy_to_rgb(image)?;
        let (mut points, detected) = match landmarks {
            Some(l) => (numpy_to_points(py, l)?, None),
            None => {
                if init.is_none() {
                    gpmm_host::detect::shipped::serves(self.inner.landmarks.len()).map_err(value_error)?;
                }
                // The initializer's landmarks get their own σ, as in `gpmm fit`; `set` still wins.
                flags.initializer_sigma = Some(gpmm_host::detect::INIT_LANDMARK_SIGMA);
                let det = crate::detect::face_for_fit(py, &photo, init.as_deref(), face)?;
                (det.landmarks.to_vec(), Some(det))
            }
        };
        let opts = flags.resolve().map_err(fit_settings_error)?;
        let calibration_name = landmark_calibration.as_ref().map(|p| p.display().to_string());
        if let Some(path) = &landmark_calibration {
            let cal = LandmarkCalibration::read(path).map_err(|e| read_error(e, &[path]))?;
            // Points outside stay as they were, so the fit refuses them as it would without a calibration.
            points = cal
                .correct_in_image(&points, photo.width() as f32, photo.height() as f32)
                .map_err(|e| value_error(format!("landmarks: {e}")))?;
        }
        let m = self.inner.clone();
        let source = self.source.clone();
        let (rep, prepared, outcome) = py
            .detach(move || {
                let t0 = Instant::now();
                let (prepared, outcome) = fit_image(&m, &photo, &points, "landmarks", &opts, &mut |_, _, _| {})?;
                let inputs = ReportInputs {
                    model_path: &source,
                    image_path: "<array>",
                    pts_path: "<array>",
                    pts_one_based: false,
                    landmark_calibration: calibration_name.as_deref(),
                };
                let rep = report(&m, &inputs, &prepared, &opts, &outcome, Some(t0.elapsed().as_secs_f64()));
                Ok::<_, gpmm_host::fit::FitRunError>((rep, prepared, outcome))
            })
            .map_err(err)?;
        let ov = overlay(
            &prepared.image,
            &outcome.render,
            outcome.occlusion.as_ref().map(|o| &o.0),
            &prepared.landmarks,
            &outcome.fitted_landmarks,
        );
        let out = json_to_py(py, &rep)?;
        let dict = out.cast::<PyDict>().map_err(|_| value_error("fit report is not a dict"))?;
        dict.set_item("shape", vec_to_numpy(py, rep.shape.clone()))?;
        dict.set_item("color", vec_to_numpy(py, rep.color.clone()))?;
        dict.set_item("light", vec3_to_numpy(py, &rep.light)?)?;
        dict.set_item("translation_mm", vec_to_numpy(py, rep.translation_mm.to_vec()))?;
        dict.set_item("fitted_landmarks", points_to_numpy(py, &rep.fitted_landmarks)?)?;
        let mesh = camera_space_mesh(&self.inner, &outcome.params).map_err(err)?;
        let mesh_dict = PyDict::new(py);
        let f32s = |v: &[[f64; 3]]| v.iter().map(|p| p.map(|x| x as f32)).collect::<Vec<[f32; 3]>>();
        mesh_dict.set_item("vertices", vec3_to_numpy(py, &f32s(&mesh.positions))?)?;
        mesh_dict.set_item("triangles", vec3_to_numpy(py, &mesh.triangles)?)?;
        mesh_dict.set_item("colors", vec3_to_numpy(py, &f32s(&mesh.colors))?)?;
        let vertex_sd = outcome.vertex_sd_mm(&self.inner).map_err(err)?;
        if vertex_sd.len() == mesh.positions.len() {
            mesh_dict.set_item("vertex_sd_mm", vec_to_numpy(py, vertex_sd.to_vec()))?;
        }
        dict.set_item("mesh", mesh_dict)?;
        if let (Some(post), Ok(Some(d))) = (&rep.posterior, dict.get_item("posterior")) {
            let d = d.cast::<PyDict>().map_err(|_| value_error("posterior summary is not a dict"))?;
            for (key, v) in [
                ("shape_mean", &post.shape_mean),
                ("shape_sd", &post.shape_sd),
                ("color_mean", &post.color_mean),
                ("color_sd", &post.color_sd),
            ] {
                d.set_item(key, vec_to_numpy(py, v.clone()))?;
            }
        }
        if let Some(det) = &detected {
            dict.set_item("detected", crate::detect::face_dict(py, det)?)?;
        }
        dict.set_item("overlay", rgba_to_numpy(py, &ov)?)?;
        dict.set_item("render", rgba_to_numpy(py, &outcome.render)?)?;
        dict.set_item("working_image", rgb_to_numpy(py, &prepared.image)?)?;
        if let Some((labels, _)) = &outcome.occlusion {
            dict.set_item("occluded", crate::arrays::mask_to_numpy(py, labels)?)?;
            let photo = gpmm_host::fit::labels_in_photo(labels, &prepared.crop, prepared.original_size);
            dict.set_item("occluded_photo", crate::arrays::mask_to_numpy(py, &photo)?)?;
        }
        Ok(out)
    }

    /// Quantizes the model for a device profile (`m4f` or `m7`) as `gpmm quantize` does: the model blob's bytes.
    #[pyo3(signature = (profile = "m4f", vertices = None, rank_shape = None, rank_color = None, bits = None))]
    fn quantize<'py>(
        &self,
        py: Python<'py>,
        profile: &str,
        vertices: Option<Int>,
        rank_shape: Option<Int>,
        rank_color: Option<Int>,
        bits: Option<Int>,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let profile: Profile = profile.parse().map_err(|e: String| value_error(format!("profile: {e}")))?;
        let mut opts = QuantizeOptions::for_profile(profile);
        opts.vertices = opt(&vertices, "vertices")?.unwrap_or(opts.vertices);
        opts.rank_shape = within_rank(opt(&rank_shape, "rank_shape")?, "rank_shape", self.inner.shape.rank())?
            .unwrap_or(opts.rank_shape.min(self.inner.shape.rank()));
        opts.rank_color = within_rank(opt(&rank_color, "rank_color")?, "rank_color", self.inner.color.rank())?
            .unwrap_or(opts.rank_color.min(self.inner.color.rank()));
        if let Some(b) = opt::<u8>(&bits, "bits")? {
            opts.bits = Bits::from_count(b).ok_or_else(|| value_error(format!("bits = {b}: expected 8 or 16")))?;
        }
        opts.source = PathBuf::from(&self.source).file_name().map(|f| f.to_string_lossy().into_owned());
        let m = self.inner.clone();
        let blob = py.detach(move || q::quantize(&m, &opts).and_then(|qm| qm.to_bytes())).map_err(err)?;
        Ok(PyBytes::new(py, &blob))
    }

    /// Writes the model as a statismo `.h5` file (as `gpmm export-h5`).
    fn export_h5(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let m = self.inner.clone();
        py.detach(|| statismo::export(&m, &path)).map_err(|e| write_error(e, &path))
    }
}

fn mesh_arrays<'py>(py: Python<'py>, mesh: &gpmm_host::mesh::Mesh) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let p: Vec<[f32; 3]> = mesh.positions.iter().map(|v| v.map(|x| x as f32)).collect();
    let c: Vec<[f32; 3]> = mesh.colors.iter().map(|v| v.map(|x| x as f32)).collect();
    Ok((vec3_to_numpy(py, &p)?, vec3_to_numpy(py, &c)?))
}
