//! `gpmm synth`: synthetic faces with known truth.

use crate::progress::counter;
use anyhow::{Context, Result};
use clap::Args;
use gpmm_host::synth::{contact_sheet, synthesize, write_synth_dir, SynthOptions};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `gpmm synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// ICT-FaceKit directory (neutral.npy, identity_modes.npy, triangles.npy, landmarks_ibug68.json).
    #[arg(long, value_name = "DIR")]
    pub ict: Option<PathBuf>,
    /// Template directory whose albedo is transferred to the ICT faces.
    #[arg(long, value_name = "DIR")]
    pub template_dir: Option<PathBuf>,
    /// Number of identities (each is rendered at every yaw).
    #[arg(long, default_value_t = 10)]
    pub count: usize,
    /// Seed of everything random.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Yaw angles in degrees (positive turns the face toward the image right).
    #[arg(long, value_delimiter = ',', default_value = "0,15,30,45", allow_hyphen_values = true)]
    pub yaws: Vec<f32>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Also write detector-like landmarks (fixed per-point offsets, per-image jitter, jaw points
    /// sliding along the contour; about 2 px RMSE at 128 px) to DIR/detector/, for
    /// `gpmm bench-fit DIR --landmarks-dir DIR/detector`.
    #[arg(long)]
    pub detector_noise: bool,
    /// Also write a contact sheet of the images to this PNG.
    #[arg(long, value_name = "PNG")]
    pub sheet: Option<PathBuf>,
    /// Output directory: NNNN_yawYY.png, NNNN_yawYY.pts, truth.json.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
}

/// Runs `gpmm synth`.
pub fn synth(a: SynthArgs) -> Result<()> {
    let mut opts = SynthOptions::default();
    if let Some(d) = a.ict {
        opts.ict_dir = d;
    }
    if let Some(d) = a.template_dir {
        opts.template_dir = d;
    }
    opts.count = a.count;
    opts.seed = a.seed;
    opts.yaws_deg = a.yaws;
    opts.size = a.size;
    if a.detector_noise {
        opts.detector_noise = Some(gpmm_host::synth::detector::DetectorNoise::DEFAULT);
    }
    opts.validate()?;
    let t0 = Instant::now();
    let pb = counter(opts.count * opts.yaws_deg.len(), "images");
    let summary = write_synth_dir(&opts, &a.output, |done, _| pb.set_position(done as u64))?;
    pb.finish_and_clear();
    eprintln!(
        "wrote {} images of {} identities and {} in {:.1} s",
        summary.images,
        summary.identities,
        summary.truth.display(),
        t0.elapsed().as_secs_f64()
    );
    if let Some(sheet) = a.sheet {
        let faces = synthesize(&SynthOptions { count: opts.count.min(8), ..opts.clone() }, |_, _| {})?;
        contact_sheet(&faces, opts.yaws_deg.len().max(1) * 2).save(&sheet).with_context(|| format!("cannot write {}", sheet.display()))?;
        eprintln!("wrote {}", sheet.display());
    }
    Ok(())
}
