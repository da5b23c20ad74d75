//! `gpmm eval reconstruction`'s runs and reports: every model row fitted on a set (fits cached as
//! recognition caches them), measured against the true faces, written as Markdown, CSV, JSON and a chart.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{measure_fits, pool, ImageReconstruction, PooledReconstruction};
use crate::eval::models::scans::EvalWorld;
use crate::eval::plot::{line_chart, Chart, PlotError, Series};
use crate::eval::recognition::fits::{fit_set, Coefficients};
use crate::eval::recognition::{Row, SynthSet};
use crate::eval::{create_dir, save_png, write_text, EvalError};
use crate::fit::FitOptions;

/// One model's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionRow {
    /// Row label.
    pub label: String,
    /// What the model is.
    pub description: String,
    /// The model file.
    pub model: String,
    /// Fits measured.
    pub fits: usize,
    /// Fits that failed (their messages).
    pub failures: Vec<String>,
    /// Per |yaw| (ascending), then the whole set.
    pub pooled: Vec<PooledReconstruction>,
    /// Every image.
    pub images: Vec<ImageReconstruction>,
}

impl ReconstructionRow {
    /// The whole set's pooled figures.
    pub fn overall(&self) -> Option<&PooledReconstruction> {
        self.pooled.iter().find(|p| p.abs_yaw_deg.is_none())
    }
}

/// Progress of [`evaluate`].
#[derive(Debug, Clone, Copy)]
pub enum Progress<'a> {
    /// `done` of `total` fits of the row `label`.
    Fitting(&'a str, usize, usize),
    /// `done` of `total` fits of the row `label` measured against their true faces.
    Measuring(&'a str, usize, usize),
}

/// Fits every row's model on `set` with `settings` (cached in `out/fits/LABEL.json`, shared with
/// `gpmm eval recognition` for the same model, settings and images) and measures the fits against the
/// true faces of `world` (the world that rendered the set).
pub fn evaluate(
    rows: &[Row],
    set: &SynthSet,
    world: &EvalWorld,
    settings: &FitOptions,
    jobs: usize,
    out: &Path,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<ReconstructionRow>, EvalError> {
    let jobs = jobs.max(1);
    let threads = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().map_err(|error| EvalError::Threads { jobs, error })?;
    let mut results = Vec::new();
    for row in rows {
        let [(label, path)] = row.components.as_slice() else {
            return Err(EvalError::Invalid(format!(
                "{}: a reconstruction needs one model per row, not a mixture of {}",
                row.label,
                row.components.len()
            )));
        };
        let cache = out.join("fits").join(format!("{label}.json"));
        let on_fit = |d, t| progress(Progress::Fitting(label, d, t));
        let (fits, _) = fit_set(path, set, settings, Coefficients::PosteriorMean, jobs, &cache, &on_fit)?;
        let model = crate::gp::model_io::load(path)?;
        let on_measure = |d, t| progress(Progress::Measuring(label, d, t));
        let images = threads.install(|| measure_fits(&model, world, &fits.fits, &on_measure))?;
        results.push(ReconstructionRow {
            label: row.label.clone(),
            description: row.description.clone(),
            model: path.display().to_string(),
            fits: images.len(),
            failures: fits.failures,
            pooled: pool(&images),
            images,
        });
    }
    Ok(results)
}

/// Everything `gpmm eval reconstruction` reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionReport {
    /// The set's directory.
    pub synth_dir: String,
    /// Where its landmarks came from.
    pub landmarks: String,
    /// Fit settings.
    pub settings: FitOptions,
    /// The command line that produced the report.
    pub command: String,
    /// Rows.
    pub rows: Vec<ReconstructionRow>,
    /// Wall-clock seconds of the run.
    pub total_seconds: f64,
}

/// Millimetres with two decimals, or a dash.
fn mm(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "–".into()
    }
}

/// The report as a Markdown table: median / mean / std (mm) per |yaw| and over the set, a row per
/// model and one for its mean shape.
pub fn markdown(report: &ReconstructionReport) -> String {
    let yaws: Vec<Option<i32>> = report.rows.first().map(|r| r.pooled.iter().map(|p| p.abs_yaw_deg).collect()).unwrap_or_default();
    let mut s = format!(
        "Reconstruction error (mm; every true vertex to the fitted surface after a similarity alignment, as NoW \
measures it): median / mean / std. Set `{}` ({}); fit: {} landmark + {} image steps, {} shape components, \
posterior mean.\n\n| model |",
        report.synth_dir,
        report.landmarks,
        report.settings.fit.landmarks.steps,
        report.settings.fit.image.steps,
        report.settings.fit.ranks.shape
    );
    for y in &yaws {
        s.push_str(&match y {
            Some(y) => format!(" \\|yaw\\| {y}° |"),
            None => " all |".into(),
        });
    }
    s.push_str(" fits |\n|---|");
    s.push_str(&"---|".repeat(yaws.len() + 1));
    s.push('\n');
    for r in &report.rows {
        for (what, fit) in [("", true), (" mean shape", false)] {
            s.push_str(&format!("| {}{what} |", r.label));
            for p in &r.pooled {
                let d = if fit { p.fit } else { p.mean_shape };
                s.push_str(&format!(" {} / {} / {} |", mm(d.median_mm), mm(d.mean_mm), mm(d.std_mm)));
            }
            let failed = if r.failures.is_empty() { String::new() } else { format!(" ({} failed)", r.failures.len()) };
            s.push_str(&format!(" {}{failed} |\n", r.fits));
        }
    }
    // How often the fits' per-vertex intervals along the normal held the true surface.
    if report.rows.iter().any(|r| r.pooled.iter().any(|p| p.coverage.is_some())) {
        s.push_str(
            "\nThe fits' vertex intervals (± 0.674 and ± 1.645 reported sd along the normal): the share of true \
vertices within them (ideal 50 % and 90 %), and the median sd (mm).\n\n| model |",
        );
        for y in &yaws {
            s.push_str(&match y {
                Some(y) => format!(" \\|yaw\\| {y}° |"),
                None => " all |".into(),
            });
        }
        s.push_str("\n|---|");
        s.push_str(&"---|".repeat(yaws.len()));
        s.push('\n');
        for r in &report.rows {
            s.push_str(&format!("| {} |", r.label));
            for p in &r.pooled {
                s.push_str(&match p.coverage {
                    Some(c) => format!(" {:.0} % / {:.0} %, {:.2} |", 100.0 * c.covered_50, 100.0 * c.covered_90, c.median_sd_mm),
                    None => " – |".into(),
                });
            }
            s.push('\n');
        }
    }
    s
}

/// One line per image and model (CSV).
pub fn csv(report: &ReconstructionReport) -> String {
    let mut s = String::from("model,image,identity,yaw_deg,median_mm,mean_mm,std_mm,mean_shape_median_mm,border_fraction,scale\n");
    for r in &report.rows {
        for i in &r.images {
            s.push_str(&format!(
                "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5}\n",
                r.label,
                i.image,
                i.identity,
                i.yaw_deg,
                i.fit.median_mm,
                i.fit.mean_mm,
                i.fit.std_mm,
                i.mean_shape.median_mm,
                i.border_fraction,
                i.scale
            ));
        }
    }
    s
}

/// Median error against |yaw|: a line per model and one per model's mean shape.
pub fn chart(report: &ReconstructionReport) -> Result<image::RgbaImage, PlotError> {
    let line = |label: String, r: &ReconstructionRow, fit: bool| Series {
        label,
        points: r
            .pooled
            .iter()
            .filter_map(|p| p.abs_yaw_deg.map(|y| (f64::from(y), if fit { p.fit.median_mm } else { p.mean_shape.median_mm })))
            .collect(),
        intervals: Vec::new(),
    };
    let series =
        report.rows.iter().flat_map(|r| [line(r.label.clone(), r, true), line(format!("{} mean shape", r.label), r, false)]).collect();
    let chart = Chart {
        title: "Reconstruction error against |yaw|".into(),
        x_label: "|yaw| (degrees)".into(),
        y_label: "median distance, true face to fit (mm)".into(),
        log_x: false,
        y_range: None,
        series,
    };
    line_chart(&chart, 760, 480)
}

/// Writes `reconstruction.{md,csv,json,png}` to `out`.
pub fn write_report(report: &ReconstructionReport, out: &Path) -> Result<(), EvalError> {
    create_dir(out)?;
    write_text(&out.join("reconstruction.md"), &markdown(report))?;
    write_text(&out.join("reconstruction.csv"), &csv(report))?;
    let json = serde_json::to_string_pretty(report).map_err(|error| EvalError::Json { what: "report", error })?;
    write_text(&out.join("reconstruction.json"), &(json + "\n"))?;
    save_png(&chart(report)?, &out.join("reconstruction.png"))
}
