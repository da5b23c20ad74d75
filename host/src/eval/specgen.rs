//! Specificity, generalization and compactness (Styner et al. 2003) of shape and colour as a
//! function of the number of components k (`gpmm eval specgen`).
//!
//! The test set is `count` identities of the synthetic world (`gpmm synth`'s ICT identities with
//! their albedo, whole meshes) drawn with their own seed; none of the models is built from them.
//! Correspondence is established by [`crate::fit::register`]: a rigid alignment on the non-jaw iBUG
//! landmarks, then iterated closest points with the model's prior as regularizer.
//!
//! - **Generalization G(k)**: each test identity is registered with the first k shape and k colour
//!   components; G is the mean over the test set of the registration residual (mean distance from
//!   the model's vertices to the closest test surface point, vertices reaching past the test
//!   mesh's border excluded), in mm; for colour, the mean Euclidean RGB distance between the fitted
//!   albedo and the test albedo at those points.
//! - **Specificity S(k)**: random instances with the first k components (coefficients ~ N(0, 1));
//!   each is compared with every test identity resampled on the model's topology (the closest test
//!   surface points of its registration with all components, covered vertices only) by the mean
//!   vertex distance (mm; for colour, the mean RGB distance); S is the mean over instances of the
//!   distance to the nearest test identity.
//! - **Compactness C(k)**: the fraction of the model's total variance (the kernel's trace for a
//!   GP model, the sum of all eigenvalues for a learned one) in the first k components.

use std::path::Path;

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::fit::register::{basis_instance, basis_matrix, register, PreparedTarget, RegisterOptions, Registration};

use crate::eval::models::scans::Scan;
use crate::eval::plot::{line_chart, side_by_side, Chart, PlotError, Series};
use crate::eval::{create_dir, save_png, write_text, EvalError};

/// Settings of [`evaluate_model`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpecGenSettings {
    /// Numbers of components (0 = all of the model's).
    pub components: Vec<usize>,
    /// Random instances per k for specificity.
    pub samples: usize,
    /// Registration settings (the ranks are set per k).
    pub register: RegisterOptions,
    /// Seed of the specificity samples.
    pub seed: u64,
}

/// The three measures at one k.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpecGenPoint {
    /// Components used (shape and colour each, capped by the model's ranks).
    pub k: usize,
    /// Shape specificity (mm).
    pub specificity_mm: f64,
    /// Shape generalization (mm).
    pub generalization_mm: f64,
    /// Shape compactness (fraction of the variance).
    pub compactness_shape: f64,
    /// Colour specificity (RGB distance).
    pub specificity_rgb: f64,
    /// Colour generalization (RGB distance).
    pub generalization_rgb: f64,
    /// Colour compactness.
    pub compactness_color: f64,
}

/// The curves of one model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelCurves {
    /// Label.
    pub label: String,
    /// Model file.
    pub model: String,
    /// Vertices.
    pub vertices: usize,
    /// Shape and colour rank.
    pub ranks: [usize; 2],
    /// Points in ascending k.
    pub points: Vec<SpecGenPoint>,
    /// Mean fraction of the model's vertices covered by the test meshes (full registration).
    pub covered_fraction: f64,
    /// Seconds.
    pub seconds: f64,
}

/// Prepares the test identities for registration.
pub fn prepare_targets(scans: &[Scan]) -> Result<Vec<PreparedTarget>, EvalError> {
    scans.iter().map(|s| PreparedTarget::new(s.mesh.clone(), Some(s.landmarks.clone())).map_err(EvalError::from)).collect()
}

fn fraction(eigenvalues: &[f64], k: usize, trace: f64) -> f64 {
    let total = if trace > 0.0 { trace } else { eigenvalues.iter().sum() };
    if total > 0.0 {
        eigenvalues.iter().take(k).sum::<f64>() / total
    } else {
        0.0
    }
}

fn mean_distance(a: &[[f64; 3]], b: &[[f64; 3]], mask: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for ((p, q), &m) in a.iter().zip(b).zip(mask) {
        if m {
            s += crate::mesh::geometry::dist2(*p, *q).sqrt();
            n += 1;
        }
    }
    if n > 0 {
        s / n as f64
    } else {
        f64::INFINITY
    }
}

/// The number of components the list asks for, capped by `rank` (0 = all), ascending and unique.
pub fn component_counts(list: &[usize], rank: usize) -> Vec<usize> {
    let mut ks: Vec<usize> = list.iter().map(|&k| if k == 0 { rank } else { k.min(rank) }).filter(|&k| k > 0).collect();
    ks.sort_unstable();
    ks.dedup();
    ks
}

/// Specificity, generalization and compactness of `model` against `targets`; `progress(done, total)` per registration.
pub fn evaluate_model(
    label: &str,
    model_path: &Path,
    targets: &[PreparedTarget],
    settings: &SpecGenSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<ModelCurves, EvalError> {
    let t0 = std::time::Instant::now();
    let model = crate::gp::model_io::load(model_path)?;
    if targets.is_empty() {
        return Err(EvalError::Invalid("specgen needs at least one test identity".into()));
    }
    let rank = model.shape.rank().max(model.color.rank());
    let ks = component_counts(&settings.components, rank);
    if ks.is_empty() {
        return Err(EvalError::Invalid(format!("{}: the model has no components", model_path.display())));
    }
    let jobs: Vec<(usize, usize)> = ks.iter().flat_map(|&k| (0..targets.len()).map(move |t| (k, t))).collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let regs: Vec<Result<Registration, EvalError>> = jobs
        .par_iter()
        .map(|&(k, t)| {
            let opts = RegisterOptions { shape_rank: k, color_rank: k, ..settings.register };
            let r = register(&model, &targets[t], &opts).map_err(EvalError::from);
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, jobs.len());
            r
        })
        .collect();
    let regs: Vec<Registration> = regs.into_iter().collect::<Result<_, _>>()?;
    let at = |k: usize, t: usize| &regs[ks.iter().position(|&x| x == k).unwrap_or(0) * targets.len() + t];
    let kmax = *ks.last().unwrap_or(&1);
    // The test set on the model's topology: the full-rank registrations' closest points.
    let full: Vec<&Registration> = (0..targets.len()).map(|t| at(kmax, t)).collect();
    let covered_fraction = full.iter().map(|r| r.residual.covered_fraction).sum::<f64>() / full.len() as f64;

    let bs = basis_matrix(&model.shape, kmax);
    let bc = basis_matrix(&model.color, kmax);
    let mut points = Vec::new();
    for &k in &ks {
        let gen = |f: &dyn Fn(&Registration) -> f64| (0..targets.len()).map(|t| f(at(k, t))).sum::<f64>() / targets.len() as f64;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(settings.seed ^ (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let (mut spec_s, mut spec_c) = (0.0, 0.0);
        let samples = settings.samples.max(1);
        for _ in 0..samples {
            let a: Vec<f64> = (0..k.min(bs.ncols())).map(|_| StandardNormal.sample(&mut rng)).collect();
            let b: Vec<f64> = (0..k.min(bc.ncols())).map(|_| StandardNormal.sample(&mut rng)).collect();
            let shape = basis_instance(&bs, &model.shape.mean, &a);
            let color: Vec<[f64; 3]> =
                basis_instance(&bc, &model.color.mean, &b).into_iter().map(|c| c.map(|v| v.clamp(0.0, 1.0))).collect();
            spec_s += full.iter().map(|r| mean_distance(&shape, &r.closest, &r.covered)).fold(f64::INFINITY, f64::min);
            spec_c += full.iter().map(|r| mean_distance(&color, &r.closest_colors, &r.covered)).fold(f64::INFINITY, f64::min);
        }
        points.push(SpecGenPoint {
            k,
            specificity_mm: spec_s / samples as f64,
            generalization_mm: gen(&|r| r.residual.mean),
            compactness_shape: fraction(&model.shape.eigenvalues, k, model.metadata.shape_trace),
            specificity_rgb: spec_c / samples as f64,
            generalization_rgb: gen(&|r| r.color_residual.mean),
            compactness_color: fraction(&model.color.eigenvalues, k, model.metadata.color_trace),
        });
    }
    Ok(ModelCurves {
        label: label.into(),
        model: model_path.display().to_string(),
        vertices: model.vertices(),
        ranks: [model.shape.rank(), model.color.rank()],
        points,
        covered_fraction,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The report of `gpmm eval specgen` (`OUT/specgen.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpecGenReport {
    /// Test identities.
    pub test_count: usize,
    /// Their world seed.
    pub test_seed: u64,
    /// Settings.
    pub settings: SpecGenSettings,
    /// The command line.
    pub command: String,
    /// Curves per model.
    pub models: Vec<ModelCurves>,
    /// Wall-clock seconds.
    pub total_seconds: f64,
}

/// The numbers as Markdown tables (shape, then colour).
pub fn markdown(report: &SpecGenReport) -> String {
    let mut s = format!(
        "Specificity / generalization / compactness against {} test identities of the synthetic world (seed {}); \
specificity from {} random instances per k; registration: {} iterations.\n\n",
        report.test_count, report.test_seed, report.settings.samples, report.settings.register.iterations
    );
    for (title, unit) in [("Shape", "mm"), ("Colour", "RGB distance")] {
        s.push_str(&format!("**{title}** (specificity and generalization in {unit}; compactness = fraction of the variance)\n\n"));
        s.push_str("| model | k | specificity | generalization | compactness |\n|---|---|---|---|---|\n");
        for m in &report.models {
            for p in &m.points {
                let (a, b, c) = if title == "Shape" {
                    (format!("{:.2}", p.specificity_mm), format!("{:.2}", p.generalization_mm), p.compactness_shape)
                } else {
                    (format!("{:.4}", p.specificity_rgb), format!("{:.4}", p.generalization_rgb), p.compactness_color)
                };
                s.push_str(&format!("| {} | {} | {a} | {b} | {:.3} |\n", m.label, p.k, c));
            }
        }
        s.push('\n');
    }
    s.push_str(&format!("Command: `{}` ({:.0} s).\n", report.command, report.total_seconds));
    s
}

/// The numbers as CSV.
pub fn csv(report: &SpecGenReport) -> String {
    let mut s =
        String::from("model,k,specificity_mm,generalization_mm,compactness_shape,specificity_rgb,generalization_rgb,compactness_color\n");
    for m in &report.models {
        for p in &m.points {
            s.push_str(&format!(
                "{},{},{:.4},{:.4},{:.5},{:.5},{:.5},{:.5}\n",
                m.label,
                p.k,
                p.specificity_mm,
                p.generalization_mm,
                p.compactness_shape,
                p.specificity_rgb,
                p.generalization_rgb,
                p.compactness_color
            ));
        }
    }
    s
}

/// Three panels (specificity, generalization, compactness) for shape or colour.
pub fn figure(report: &SpecGenReport, shape: bool) -> Result<image::RgbaImage, PlotError> {
    type Pick = fn(&SpecGenPoint) -> f64;
    let (what, unit, picks): (&str, &str, [Pick; 3]) = if shape {
        ("shape", "mm", [|p| p.specificity_mm, |p| p.generalization_mm, |p| p.compactness_shape])
    } else {
        ("colour", "RGB distance", [|p| p.specificity_rgb, |p| p.generalization_rgb, |p| p.compactness_color])
    };
    let names = ["specificity", "generalization", "compactness"];
    let panels: Vec<image::RgbaImage> = names
        .iter()
        .zip(picks)
        .map(|(name, pick)| {
            let chart = Chart {
                title: format!("{what} {name} ({} test faces)", report.test_count),
                x_label: "components k".into(),
                y_label: if *name == "compactness" { "fraction of variance".into() } else { format!("{unit} (lower is better)") },
                log_x: true,
                y_range: if *name == "compactness" { Some((0.0, 1.0)) } else { None },
                series: report
                    .models
                    .iter()
                    .map(|m| Series {
                        label: m.label.clone(),
                        points: m.points.iter().map(|p| (p.k as f64, pick(p))).collect(),
                        intervals: Vec::new(),
                    })
                    .collect(),
            };
            line_chart(&chart, 520, 380)
        })
        .collect::<Result<_, _>>()?;
    Ok(side_by_side(&panels))
}

/// Writes `specgen.md`, `specgen.csv`, `specgen.json`, `specgen-shape.png` and `specgen-color.png` into `out`.
pub fn write_report(report: &SpecGenReport, out: &Path) -> Result<(), EvalError> {
    create_dir(out)?;
    write_text(&out.join("specgen.md"), &markdown(report))?;
    write_text(&out.join("specgen.csv"), &csv(report))?;
    let json = serde_json::to_string_pretty(report).map_err(|error| EvalError::Json { what: "report", error })?;
    write_text(&out.join("specgen.json"), &(json + "\n"))?;
    save_png(&figure(report, true)?, &out.join("specgen-shape.png"))?;
    save_png(&figure(report, false)?, &out.join("specgen-color.png"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn component_counts_cap_sort_and_expand_all() {
        assert_eq!(component_counts(&[1, 2, 5, 10, 20, 50, 100, 0], 30), vec![1, 2, 5, 10, 20, 30]);
        assert_eq!(component_counts(&[0, 5], 0), Vec::<usize>::new());
    }

    #[test]
    fn compactness_fraction_uses_the_trace() {
        assert!((fraction(&[3.0, 1.0], 1, 8.0) - 0.375).abs() < 1e-12);
        assert!((fraction(&[3.0, 1.0], 1, 0.0) - 0.75).abs() < 1e-12);
    }
}
