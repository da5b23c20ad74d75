//! `gpmm eval reconstruction`: the 3D error of fits against a set's true faces.

use crate::eval_setup::{command_line, start_on_synth, EvalFitArgs, EvalLandmarkArgs, EvalModelArgs};
use crate::progress::{bar_style, note, spinner};
use anyhow::Result;
use clap::Args;
use gpmm_host::eval::reconstruction::report::{evaluate, markdown, write_report, Progress, ReconstructionReport};
use gpmm_host::gp::kernel::ModelKernel;
use indicatif::ProgressBar;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `gpmm eval reconstruction`.
#[derive(Debug, Args)]
pub struct ReconstructionArgs {
    /// A `gpmm synth` directory (or a set made from one, with its truth.json).
    #[arg(long, value_name = "DIR")]
    pub synth: PathBuf,
    /// Landmarks.
    #[command(flatten)]
    pub landmarks: EvalLandmarkArgs,
    /// Models (default: symmetric-full built from the template).
    #[command(flatten)]
    pub models: EvalModelArgs,
    /// Use the first N identities of the directory (default: all; 2 with --quick).
    #[arg(long, value_name = "N")]
    pub identities: Option<usize>,
    /// Fit settings.
    #[command(flatten)]
    pub fit: EvalFitArgs,
    /// Seed of the fitting chains.
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.seed, value_name = "SEED")]
    pub fit_seed: u64,
    /// Output directory.
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
}

/// Runs `gpmm eval reconstruction`.
pub fn run(a: ReconstructionArgs) -> Result<()> {
    let t0 = Instant::now();
    let q = a.models.quick;
    let start = start_on_synth(&a.synth, 20, a.identities.or(q.then_some(2)), &a.landmarks, &a.models, &a.output)?;
    let (set, mut sel, mut factory) = (start.set, start.selection, start.factory);
    let describe = set.landmarks.describe();
    if sel.is_empty() {
        sel.kernels = vec![ModelKernel::SymmetricFull];
    }
    eprintln!("{}: {} identities, {} images", a.synth.display(), set.identities.len(), set.images.len());
    let pb = spinner("preparing models and true faces");
    let rows = factory.rows(&sel, &mut |label, built| {
        note(&pb, format!("model {label}: {}", if built { "built" } else { "reused" }));
    })?;
    let world = factory.world()?.clone();
    pb.finish_and_clear();
    let settings = gpmm_host::fit::FitOptions { seed: a.fit_seed, ..a.fit.flags(q).resolve()? };
    settings.validate()?;
    let bar = ProgressBar::new(0);
    bar.set_style(bar_style("{bar:30} {pos}/{len} {msg} [{elapsed}]"));
    let progress = |p: Progress<'_>| {
        let (what, label, done, total) = match p {
            Progress::Fitting(l, d, t) => ("fits", l, d, t),
            Progress::Measuring(l, d, t) => ("measured", l, d, t),
        };
        bar.set_message(format!("{what} ({label})"));
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let rows = evaluate(&rows, &set, &world, &settings, a.fit.jobs(), &a.output, &progress)?;
    bar.finish_and_clear();
    let report = ReconstructionReport {
        synth_dir: a.synth.display().to_string(),
        landmarks: describe,
        settings,
        command: command_line(),
        rows,
        total_seconds: t0.elapsed().as_secs_f64(),
    };
    write_report(&report, &a.output)?;
    println!("{}", markdown(&report));
    eprintln!("wrote reconstruction.md, .csv, .json and .png to {}", a.output.display());
    Ok(())
}
