//! `--set PATH=VALUE`: any field of the one [`FitSettings`] by its path in fit.json's settings.

use super::error::FitRunError;
use gpmm_core::fit::FitSettings;
use serde_json::Value;

/// `settings` with each `PATH=VALUE` applied in order: `PATH` is a dot-separated field path of
/// [`FitSettings`] as fit.json writes it (e.g. `landmarks.student_t`, `proposals.image.shape`,
/// `proposals.drift.shape.sigmas`), `VALUE` is JSON (a number, `true`, `[0.1, 0.02, 0.005]`).
/// Unknown paths and values of the wrong type are errors that name the path.
pub fn override_settings(settings: &FitSettings, overrides: &[String]) -> Result<FitSettings, FitRunError> {
    if overrides.is_empty() {
        return Ok(*settings);
    }
    let bad = |msg: String| FitRunError::Settings(msg);
    let mut tree = serde_json::to_value(settings).map_err(|e| bad(format!("cannot serialize the settings: {e}")))?;
    for item in overrides {
        let (path, value) = item.split_once('=').ok_or_else(|| bad(format!("--set {item}: expected PATH=VALUE")))?;
        let value: Value = serde_json::from_str(value.trim())
            .map_err(|e| bad(format!("--set {item}: the value is not JSON (a number, true/false, [..]): {e}")))?;
        let mut node = &mut tree;
        for key in path.trim().split('.') {
            node = node
                .get_mut(key)
                .ok_or_else(|| bad(format!("--set {item}: no setting `{path}` (unknown field `{key}`; see `settings` in fit.json)")))?;
        }
        if node.is_object() {
            return Err(bad(format!("--set {item}: `{path}` is a group; name one of its fields")));
        }
        *node = value;
    }
    serde_json::from_value(tree).map_err(|e| bad(format!("--set: the settings do not fit their types: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_fields_by_path_and_names_bad_ones() {
        let d = FitSettings::DEFAULT;
        let s = override_settings(&d, &["landmarks.student_t=4".into(), "image.steps=1000".into()]).unwrap();
        assert_eq!(s.landmarks.student_t, 4.0);
        assert_eq!(s.image.steps, 1000);
        assert_eq!(s.ranks, d.ranks);
        let e = override_settings(&d, &["landmarks.nope=1".into()]).unwrap_err().to_string();
        assert!(e.contains("landmarks.nope") && e.contains("nope"), "{e}");
        assert!(override_settings(&d, &["image.steps=-3".into()]).is_err());
        assert!(override_settings(&d, &["image=3".into()]).unwrap_err().to_string().contains("group"));
        assert!(override_settings(&d, &["image.steps".into()]).unwrap_err().to_string().contains("PATH=VALUE"));
    }
}
