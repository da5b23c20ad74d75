//! `gpmm import-h5` and `gpmm export-h5`: statismo / scalismo-faces `.h5` models (the Basel
//! Face Model's format) to and from gpmm model files.

use anyhow::{Context, Result};
use clap::Args;
use gpmm_host::gp::model_io;
use gpmm_host::gp::statismo::{self, ImportOptions};
use gpmm_host::mesh::io::read_landmarks_json;
use std::path::PathBuf;

/// Arguments of `gpmm import-h5`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The statismo .h5 file (shape and color parts; an expression part is not imported).
    pub input: PathBuf,
    /// Millimetres per file unit (default: detected from the mean shape's width: mm, um, cm or m).
    #[arg(long, value_name = "MM_PER_UNIT")]
    pub scale: Option<f64>,
    /// Landmarks to use: {"scheme": "ibug68", "vertex_ids": [...]} (default: the file's, if they are vertex landmarks).
    #[arg(long, value_name = "JSON")]
    pub landmarks: Option<PathBuf>,
    /// Output model file.
    #[arg(short, long, value_name = "MODEL")]
    pub output: PathBuf,
}

/// Arguments of `gpmm export-h5`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Model file.
    pub model: PathBuf,
    /// Output .h5 file.
    #[arg(short, long, value_name = "H5")]
    pub output: PathBuf,
}

/// Runs `gpmm import-h5`: prints what was found as JSON on stdout.
pub fn import_h5(a: ImportArgs) -> Result<()> {
    let landmarks = a.landmarks.as_deref().map(read_landmarks_json).transpose()?;
    let (model, report) = statismo::import(&a.input, &ImportOptions { scale: a.scale, landmarks })?;
    model_io::save(&model, &a.output)?;
    for note in &report.notes {
        eprintln!("note: {note}");
    }
    eprintln!(
        "{}: {} vertices, {} triangles, ranks {}/{}, {} landmarks, {:.6} mm per unit ({})",
        a.output.display(),
        report.vertices,
        report.triangles,
        report.rank_shape,
        report.rank_color,
        report.landmarks,
        report.scale_mm_per_unit,
        report.units
    );
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// Runs `gpmm export-h5`.
pub fn export_h5(a: ExportArgs) -> Result<()> {
    let model = model_io::load(&a.model)?;
    statismo::export(&model, &a.output).with_context(|| format!("exporting {}", a.model.display()))?;
    eprintln!(
        "wrote {} (statismo 0.9: {} vertices, ranks {}/{}, {} landmarks)",
        a.output.display(),
        model.vertices(),
        model.shape.rank(),
        model.color.rank(),
        model.landmarks.len()
    );
    Ok(())
}
