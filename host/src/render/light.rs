//! Text forms of render inputs shared by the `gpmm` program and the Python package: light
//! presets and SH JSON, `R,G,B` colours and backgrounds (one parser, the same messages).

use super::Background;
use gpmm_core::render::ShLight;
use std::path::Path;

/// The light presets of `--light`.
pub const LIGHT_PRESETS: [&str; 5] = ["ambient", "frontal", "left", "right", "top"];

/// Parses a light: a preset name, an inline 9x3 JSON array of SH coefficients, or a JSON file holding one.
pub fn parse_light(s: &str) -> Result<ShLight, String> {
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
        std::fs::read_to_string(t).map_err(|e| format!("cannot read light file {t}: {e}"))?
    } else {
        return Err(format!(
            "unknown light '{t}': expected a preset ({}), a 9x3 JSON array of SH coefficients, or a JSON file",
            LIGHT_PRESETS.join(", ")
        ));
    };
    let rows: Vec<Vec<f32>> = serde_json::from_str(&text)
        .map_err(|e| format!("malformed light JSON: expected 9 rows of [r, g, b] SH coefficients, got '{}': {e}", text.trim()))?;
    light_from_rows(&rows)
}

/// A light from 9 rows of `[r, g, b]` SH coefficients (bands 0-2), all finite.
pub fn light_from_rows(rows: &[Vec<f32>]) -> Result<ShLight, String> {
    if rows.len() != 9 || rows.iter().any(|r| r.len() != 3) {
        return Err(format!("light JSON must have 9 rows of 3 numbers (SH bands 0-2 x RGB), got {} rows", rows.len()));
    }
    let mut light = ShLight::zero();
    for (c, r) in light.coeffs.iter_mut().zip(rows) {
        *c = [r[0], r[1], r[2]];
    }
    if !light.coeffs.iter().flatten().all(|v| v.is_finite()) {
        return Err("light JSON has a non-finite coefficient".into());
    }
    Ok(light)
}

/// Parses `R,G,B` with each channel in \[0, 1\].
pub fn parse_rgb(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s.split(',').map(|p| p.trim().parse::<f64>().map_err(|e| format!("'{p}': {e}"))).collect::<Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b]),
        _ => Err("expected three numbers in [0,1], e.g. 0.8,0.6,0.5".into()),
    }
}

/// Parses a background: `R,G,B` in \[0, 1\] or `transparent`.
pub fn parse_background(s: &str) -> Result<Background, String> {
    if s.trim().eq_ignore_ascii_case("transparent") {
        return Ok(Background::Transparent);
    }
    parse_rgb(s).map(|c| Background::Color(c.map(|v| v as f32))).map_err(|e| format!("{e}, or 'transparent'"))
}
