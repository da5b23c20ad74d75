//! The recognition report: its content (`OUT/recognition.json`) and how it is written as
//! Markdown, CSV and a chart of the accuracy per probe yaw with its Wilson 95 % intervals.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::eval::plot::{line_chart, Chart, PlotError, Series};
use crate::eval::{create_dir, save_png, write_text, EvalError};
use crate::fit::FitOptions;

use super::fits::Coefficients;
use super::RowResult;

/// The whole report (`OUT/recognition.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecognitionReport {
    /// The synth directory.
    pub synth_dir: String,
    /// Its seed.
    pub synth_seed: u64,
    /// Identities evaluated.
    pub identities: usize,
    /// Gallery size (identities with a yaw-0 image).
    pub gallery: usize,
    /// Chance rate of rank-1 identification.
    pub chance: f64,
    /// Fit settings.
    pub settings: FitOptions,
    /// Settings of the KDE components' fits, if different.
    pub kde_settings: Option<FitOptions>,
    /// The coefficients compared (absent in older reports: the best sample).
    #[serde(default = "best_sample")]
    pub coefficients: Coefficients,
    /// Threads.
    pub jobs: usize,
    /// The command line that produced the report.
    pub command: String,
    /// Rows.
    pub rows: Vec<RowResult>,
    /// Wall-clock seconds of the whole run (model building included).
    pub total_seconds: f64,
}

/// What reports written before the choice compared.
fn best_sample() -> Coefficients {
    Coefficients::Best
}

fn pct(x: f64) -> String {
    format!("{:.1}", 100.0 * x)
}

/// The table as Markdown.
pub fn markdown(report: &RecognitionReport) -> String {
    let yaws: Vec<f32> = report.rows.first().map(|r| r.yaws.iter().map(|y| y.yaw_deg).collect()).unwrap_or_default();
    let mut s = String::new();
    s.push_str(&format!(
        "Rank-1 recognition (%), gallery yaw 0 ({} identities, chance {} %), `gpmm synth` seed {}; [Wilson 95 % interval]; \
fit: {} landmark + {} image steps at {}x{} px, {} shape + {} colour components; compared: {}",
        report.gallery,
        pct(report.chance),
        report.synth_seed,
        report.settings.fit.landmarks.steps,
        report.settings.fit.image.steps,
        report.settings.size,
        report.settings.size,
        report.settings.fit.ranks.shape,
        report.settings.fit.ranks.color,
        report.coefficients.describe()
    ));
    if let Some(k) = &report.kde_settings {
        s.push_str(&format!(" (KDE components: {} image steps)", k.fit.image.steps));
    }
    s.push_str(".\n\n| model |");
    for y in &yaws {
        s.push_str(&format!(" {y}° |"));
    }
    s.push_str(" all probes | fits | fit wall time |\n|---|");
    for _ in &yaws {
        s.push_str("---|");
    }
    s.push_str("---|---|---|\n");
    for r in &report.rows {
        s.push_str(&format!("| {} |", r.label));
        for y in r.yaws.iter().chain([&r.pooled]) {
            s.push_str(&format!(" {} [{}, {}] |", pct(y.accuracy), pct(y.wilson95[0]), pct(y.wilson95[1])));
        }
        let failed = if r.failures > 0 { format!(" ({} failed)", r.failures) } else { String::new() };
        s.push_str(&format!(
            " {}{failed} | {:.0} s ({:.2} s/fit, {} threads){} |\n",
            r.fits,
            r.fit_wall_seconds,
            r.seconds_per_fit,
            report.jobs,
            if r.cached { ", cached" } else { "" }
        ));
    }
    s.push_str("| chance |");
    for _ in 0..=yaws.len() {
        s.push_str(&format!(" {} |", pct(report.chance)));
    }
    s.push_str(" | |\n\n");
    s.push_str("Diagnostic, from the same fits: rank-1 accuracy (%) from the shape coefficients alone | from the colour coefficients alone; median pixel RMSE of the fits.\n\n| model |");
    for y in &yaws {
        s.push_str(&format!(" {y}° shape \\| colour |"));
    }
    s.push_str(" pixel RMSE |\n|---|");
    for _ in &yaws {
        s.push_str("---|");
    }
    s.push_str("---|\n");
    for r in &report.rows {
        s.push_str(&format!("| {} |", r.label));
        for (a, b) in r.shape_only.iter().zip(&r.color_only) {
            s.push_str(&format!(" {} \\| {} |", pct(a.accuracy), pct(b.accuracy)));
        }
        s.push_str(&format!(" {:.4} |\n", r.median_pixel_rmse));
    }
    s.push('\n');
    for r in &report.rows {
        s.push_str(&format!("- `{}`: {}\n", r.label, r.description));
    }
    let reused = if report.rows.iter().any(|r| r.cached) {
        "; rows marked cached reused the fits of an earlier run and show its fit times"
    } else {
        ""
    };
    s.push_str(&format!("\nCommand: `{}` (this run: {:.0} s{reused}).\n", report.command, report.total_seconds));
    s
}

/// The table as CSV (one line per row and probe yaw).
pub fn csv(report: &RecognitionReport) -> String {
    let mut s = String::from("model,yaw_deg,correct,total,accuracy,wilson95_low,wilson95_high,chance,fit_wall_seconds,seconds_per_fit\n");
    for r in &report.rows {
        for y in &r.yaws {
            s.push_str(&format!(
                "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.1},{:.3}\n",
                r.label,
                y.yaw_deg,
                y.correct,
                y.total,
                y.accuracy,
                y.wilson95[0],
                y.wilson95[1],
                report.chance,
                r.fit_wall_seconds,
                r.seconds_per_fit
            ));
        }
    }
    s
}

/// Writes `recognition.md`, `recognition.csv`, `recognition.json` and `recognition.png` into `out`.
pub fn write_report(report: &RecognitionReport, out: &Path) -> Result<(), EvalError> {
    create_dir(out)?;
    write_text(&out.join("recognition.md"), &markdown(report))?;
    write_text(&out.join("recognition.csv"), &csv(report))?;
    let json = serde_json::to_string_pretty(report).map_err(|error| EvalError::Json { what: "report", error })?;
    write_text(&out.join("recognition.json"), &(json + "\n"))?;
    save_png(&chart(report)?, &out.join("recognition.png"))
}

/// Rank-1 accuracy (%) against probe yaw, a line per model with its Wilson 95 % intervals as error bars.
pub fn chart(report: &RecognitionReport) -> Result<image::RgbaImage, PlotError> {
    let series: Vec<Series> = report
        .rows
        .iter()
        .map(|r| Series {
            label: r.label.clone(),
            points: r.yaws.iter().map(|y| (f64::from(y.yaw_deg), 100.0 * y.accuracy)).collect(),
            intervals: r.yaws.iter().map(|y| (100.0 * y.wilson95[0], 100.0 * y.wilson95[1])).collect(),
        })
        .collect();
    let chart = Chart {
        title: format!("Rank-1 recognition, gallery yaw 0, {} identities (chance {} %)", report.gallery, pct(report.chance)),
        x_label: "probe yaw (degrees)".into(),
        y_label: "rank-1 accuracy (%), Wilson 95 % interval".into(),
        log_x: false,
        y_range: Some((0.0, 100.0)),
        series,
    };
    line_chart(&chart, 760, 480)
}

#[cfg(test)]
mod tests {
    use super::super::identify::{ProbeOutcome, YawAccuracy};
    use super::*;
    use crate::eval::wilson_interval;

    fn accuracy(yaw_deg: f32, correct: usize, total: usize) -> YawAccuracy {
        let (lo, hi) = wilson_interval(correct, total, 1.96);
        YawAccuracy { yaw_deg, correct, total, accuracy: correct as f64 / total as f64, wilson95: [lo, hi] }
    }

    fn report() -> RecognitionReport {
        let row = RowResult {
            label: "tiny".into(),
            description: "a hand-made row".into(),
            models: vec!["tiny.gpmm".into()],
            vertices: 10,
            yaws: vec![accuracy(15.0, 3, 3), accuracy(30.0, 2, 3)],
            pooled: accuracy(f32::NAN, 5, 6),
            shape_only: vec![accuracy(15.0, 1, 3), accuracy(30.0, 0, 3)],
            color_only: vec![accuracy(15.0, 2, 3), accuracy(30.0, 1, 3)],
            median_pixel_rmse: 0.05,
            fits: 9,
            failures: 0,
            fit_wall_seconds: 12.0,
            seconds_per_fit: 1.5,
            cached: false,
            probes: vec![ProbeOutcome { image: "0002_yaw30.png".into(), identity: 2, predicted: Some(0) }],
        };
        RecognitionReport {
            synth_dir: "set".into(),
            synth_seed: 1,
            identities: 3,
            gallery: 3,
            chance: 1.0 / 3.0,
            settings: FitOptions::DEFAULT,
            kde_settings: None,
            coefficients: Coefficients::PosteriorMean,
            jobs: 2,
            command: "gpmm eval recognition".into(),
            rows: vec![row],
            total_seconds: 20.0,
        }
    }

    #[test]
    fn the_tables_give_each_accuracy_with_its_wilson_interval() {
        let r = report();
        let md = markdown(&r);
        assert!(md.contains("| tiny | 100.0 [43.8, 100.0] | 66.7 [20.8, 93.9] | 83.3 [43.6, 97.0] | 9 |"), "{md}");
        assert!(md.contains("| chance | 33.3 | 33.3 | 33.3 |"), "{md}");
        assert!(md.contains("| tiny | 33.3 \\| 66.7 | 0.0 \\| 33.3 | 0.0500 |"), "{md}");
        let csv = csv(&r);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[2], "tiny,30,2,3,0.6667,0.2077,0.9385,0.3333,12.0,1.500");
        // The probes are written as [image, identity, predicted].
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["rows"][0]["probes"][0], serde_json::json!(["0002_yaw30.png", 2, 0]));
    }

    #[test]
    fn the_chart_has_a_line_per_model() {
        let img = chart(&report()).unwrap();
        assert_eq!(img.dimensions(), (760, 480));
        assert!(img.pixels().filter(|p| **p == crate::eval::plot::series_color(0)).count() > 100);
    }
}
