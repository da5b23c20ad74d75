//! Text forms of render inputs shared by the `gpmm` program and the Python package: light
//! presets and SH JSON, `R,G,B` colours and backgrounds (one parser, the same messages).

use super::Background;
use gpmm_core::render::ShLight;
use std::path::Path;

/// The light presets of `--light`.
pub const LIGHT_PRESETS: [&str; 5] = ["ambient", "frontal", "left", "right", "top"];

/// Why a light, a colour or a background was refused (a light file is named).
#[derive(Debug, thiserror::Error)]
pub enum LightError {
    /// The light file could not be read.
    #[error("cannot read light file {path}: {error}")]
    File {
        /// The file as given.
        path: String,
        /// The IO error.
        error: std::io::Error,
    },
    /// Neither a preset, nor JSON, nor a file.
    #[error("unknown light '{0}': expected a preset ({presets}), a 9x3 JSON array of SH coefficients, or a JSON file", presets = LIGHT_PRESETS.join(", "))]
    Unknown(String),
    /// The JSON is not a list of rows of numbers.
    #[error("malformed light JSON: expected 9 rows of [r, g, b] SH coefficients, got '{text}': {error}")]
    Json {
        /// The JSON text.
        text: String,
        /// The parser's error.
        error: serde_json::Error,
    },
    /// Not 9 rows of 3 numbers.
    #[error("light JSON must have 9 rows of 3 numbers (SH bands 0-2 x RGB), got {0} rows")]
    Rows(usize),
    /// A coefficient is infinite or NaN.
    #[error("light JSON has a non-finite coefficient")]
    NonFinite,
    /// A colour channel is not a number.
    #[error("'{text}': {error}")]
    Channel {
        /// The channel as given.
        text: String,
        /// The parser's error.
        error: std::num::ParseFloatError,
    },
    /// Not three channels in [0, 1].
    #[error("expected three numbers in [0,1], e.g. 0.8,0.6,0.5")]
    Rgb,
    /// Neither a colour nor `transparent`.
    #[error("{0}, or 'transparent'")]
    Background(Box<LightError>),
}

/// Parses a light: a preset name, an inline 9x3 JSON array of SH coefficients, or a JSON file holding one.
pub fn parse_light(s: &str) -> Result<ShLight, LightError> {
    let t = s.trim();
    let directional = |d: [f32; 3]| ShLight::from_ambient_diffuse([0.6; 3], [0.4; 3], d);
    match t.to_ascii_lowercase().as_str() {
        "ambient" => return Ok(ShLight::ambient_white()),
        "frontal" => return Ok(ShLight::frontal()),
        "left" => return Ok(directional([-0.7, 0.2, 0.7])),
        "right" => return Ok(directional([0.7, 0.2, 0.7])),
        "top" => return Ok(directional([0.0, 0.8, 0.6])),
        _ => {}
    }
    let text = if t.starts_with('[') {
        t.to_string()
    } else if Path::new(t).is_file() {
        std::fs::read_to_string(t).map_err(|error| LightError::File { path: t.to_string(), error })?
    } else {
        return Err(LightError::Unknown(t.to_string()));
    };
    let rows: Vec<Vec<f32>> = serde_json::from_str(&text).map_err(|error| LightError::Json { text: text.trim().to_string(), error })?;
    light_from_rows(&rows)
}

/// A light from 9 rows of `[r, g, b]` SH coefficients (bands 0-2), all finite.
pub fn light_from_rows(rows: &[Vec<f32>]) -> Result<ShLight, LightError> {
    if rows.len() != 9 || rows.iter().any(|r| r.len() != 3) {
        return Err(LightError::Rows(rows.len()));
    }
    let mut light = ShLight::zero();
    for (c, r) in light.coeffs.iter_mut().zip(rows) {
        *c = [r[0], r[1], r[2]];
    }
    if !light.coeffs.iter().flatten().all(|v| v.is_finite()) {
        return Err(LightError::NonFinite);
    }
    Ok(light)
}

/// Parses `R,G,B` with each channel in \[0, 1\].
pub fn parse_rgb(s: &str) -> Result<[f64; 3], LightError> {
    let channel = |p: &str| p.trim().parse::<f64>().map_err(|error| LightError::Channel { text: p.to_string(), error });
    let v: Vec<f64> = s.split(',').map(channel).collect::<Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b]),
        _ => Err(LightError::Rgb),
    }
}

/// Parses a background: `R,G,B` in \[0, 1\] or `transparent`.
pub fn parse_background(s: &str) -> Result<Background, LightError> {
    if s.trim().eq_ignore_ascii_case("transparent") {
        return Ok(Background::Transparent);
    }
    parse_rgb(s).map(|c| Background::Color(c.map(|v| v as f32))).map_err(|e| LightError::Background(Box::new(e)))
}
