//! Fitting a model to a photo (`gpmm fit`): crop around the landmarks, the core's landmark chain,
//! a least-squares light, the core's image chain; `fit.json`, `overlay.png` and `fit.ply`.
//!
//! Steps ([`fit_prepared`]; 2 to 5 are the core's [`gpmm_core::fit::standard_fit`], which the firmware runs too,
//! described step by step in `gpmm_core::fit::recipe`):
//! 1. The photo is cropped and resampled to `size × size` ([`crate::photo`]); the landmarks follow.
//! 2. Start ([`gpmm_core::fit::initial_guess`]): the scaled-orthographic pose of the mean face's
//!    landmarks, at [`gpmm_core::fit::StartSettings::nominal_distance_mm`] (the focal length
//!    follows from that distance).
//! 3. Landmark chain (`prior × landmarks`, no rendering), [`gpmm_core::fit::LandmarkSettings::steps`]
//!    steps on the pose (jaw contour σ × 3).
//! 4. The SH light of its best sample, solved in closed form (the "landmark-only result", the
//!    baseline of the pixel RMSE), then the start's shape solve (Gauss–Newton on the landmarks
//!    and the image).
//! 5. Image chain (`prior × landmarks × image`, delayed acceptance),
//!    [`gpmm_core::fit::ImageSettings::steps`] steps on pose, colour and light; its second half is
//!    summarized as the posterior ([`PosteriorSummary`]).
//!
//! Both chains run once each, reporting progress through the core's step callback. The
//! result is a deterministic function of the inputs, the settings and the seed: `fit.json` is
//! bit-identical across runs except for `seconds` and `timing` (omitted with `--no-timing`).
//!
//! One file per job: the error (`error.rs`), the photo read, checked and cropped (`input.rs`), the
//! fit (`pipeline.rs`: [`fit_prepared`], [`fit_image`]), `fit.json`'s schema (`report.rs`), the
//! overlay's drawing (`overlay.rs`), `gpmm fit`'s file job (`job.rs`: [`fit_files`]) and every face
//! of a photo fitted and drawn into it (`faces.rs`: [`fit_faces`]); beside
//! them the coefficient capacity (`params.rs`), the options and `--set` overrides, the chains'
//! observer and the posterior summary. This file only re-exports them; they import each other one
//! way and never this file.

mod buffers;
mod error;
mod faces;
mod input;
mod job;
mod observe;
mod options;
mod overlay;
mod overrides;
mod params;
mod pipeline;
mod posterior;
pub mod register;
mod report;
mod shape_spread;
mod spread_picture;

pub use buffers::FitBuffers;
pub use error::FitRunError;
pub use faces::{draw_fit, fit_faces, FaceFitted, FaceToFit, DRAWN_FIT_SHARE};
pub use gpmm_core::fit::FitSettings;
pub use input::{check_landmarks, load_photo, prepare, Prepared};
pub use job::{fit_files, write_fit_files, FitFilesError, FitJob};
pub use observe::{AcceptanceReport, KindCounts};
pub use options::{FitFlags, FitOptions};
pub use overlay::{labels_in_photo, overlay, FITTED_COLOR, OVERLAY_SCALE, TARGET_COLOR};
pub use overrides::override_settings;
pub use params::{Params, KC, KS};
pub use pipeline::{camera_space_mesh, fit_image, fit_prepared, morphable, project_landmarks, project_landmarks_of, rmse, Outcome};
pub use posterior::{
    calibrated_angles_sd_deg, calibrated_translation_sd_mm, central_intervals, PosteriorSummary, VertexSpread, TRANSLATION_SPREAD_FACTOR,
    Z50, Z90,
};
pub use report::{report, AcceptanceBoth, FitReport, LogDensities, ReportInputs, Timing};
pub use shape_spread::{ShapeSpread, SHAPE_SPREAD_FACTOR};
pub use spread_picture::{spread_color, spread_picture};
