//! A detected face as `gpmm detect` lists it and the Python package returns it: the finder's box
//! and score, the pose and the landmarks the initializer read.

use gpmm_core::net::face::Detection;
use serde::Serialize;

/// The finder's square box in the image (px) and its score (0..1).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxRecord {
    /// Centre, x.
    pub cx: f64,
    /// Centre, y.
    pub cy: f64,
    /// The finder's score.
    pub score: f64,
    /// Side.
    pub size: f64,
}

/// One detected face.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaceRecord {
    /// The finder's box.
    #[serde(rename = "box")]
    pub face_box: BoxRecord,
    /// The landmarks read (image px, 0-based, pixel centres at +0.5).
    pub landmarks: Vec<[f64; 2]>,
    /// Pitch read (degrees).
    pub pitch_deg: f64,
    /// Roll read (degrees).
    pub roll_deg: f64,
    /// Yaw read (degrees).
    pub yaw_deg: f64,
}

impl From<&Detection> for FaceRecord {
    fn from(det: &Detection) -> Self {
        let f = &det.face;
        Self {
            face_box: BoxRecord { cx: f.cx.into(), cy: f.cy.into(), score: f.score.into(), size: f.size.into() },
            landmarks: det.landmarks.iter().map(|p| [p[0].into(), p[1].into()]).collect(),
            pitch_deg: det.angles[1].to_degrees().into(),
            roll_deg: det.angles[2].to_degrees().into(),
            yaw_deg: det.angles[0].to_degrees().into(),
        }
    }
}
