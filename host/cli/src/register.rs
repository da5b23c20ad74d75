//! `gpmm register`: a model fitted to a mesh in 3D.

use crate::progress::spinner;
use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_host::gp::model_io;
use gpmm_host::mesh::io as mesh_io;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `gpmm register`.
#[derive(Debug, Args)]
pub struct RegisterArgs {
    /// Model file.
    pub model: PathBuf,
    /// Target mesh (PLY or glTF, millimetres; without per-vertex colours the colour fit is against grey).
    pub mesh: PathBuf,
    /// The target's landmarks {"scheme": "ibug68", "vertex_ids": [...]}: rigid alignment on them first
    /// (otherwise the target must already be roughly in the model's frame: centroids are aligned).
    #[arg(long, value_name = "JSON")]
    pub landmarks: Option<PathBuf>,
    /// Shape components used (default: all).
    #[arg(long, value_name = "K")]
    pub shape_rank: Option<usize>,
    /// Colour components used (default: all).
    #[arg(long, value_name = "K")]
    pub color_rank: Option<usize>,
    /// Closest-point iterations.
    #[arg(long, default_value_t = gpmm_host::fit::register::RegisterOptions::default().iterations, value_name = "N")]
    pub iterations: usize,
    /// Weight of each landmark pair in the first iteration, falling to min(W, 1) in the last; 0 uses
    /// the landmarks for the rigid alignment only, so the surface alone decides where each model
    /// vertex lands (e.g. to see where the model's landmark vertices fall on another face).
    #[arg(long, default_value_t = gpmm_host::fit::register::RegisterOptions::default().landmark_weight, value_name = "W")]
    pub landmark_weight: f64,
    /// Output directory: registered.ply (model topology, in the target's frame) and register.json.
    #[arg(short, long, value_name = "OUTDIR")]
    pub output: PathBuf,
}

/// Runs `gpmm register`.
pub fn register_mesh(a: RegisterArgs) -> Result<()> {
    use gpmm_host::fit::register::{register, PreparedTarget, RegisterOptions, RegisterReport};
    let t0 = Instant::now();
    let model = model_io::load(&a.model)?;
    let mesh = mesh_io::read_mesh(&a.mesh, None, Some([0.5; 3]))?;
    let landmarks = match &a.landmarks {
        Some(p) => {
            let (scheme, ids) = mesh_io::read_landmarks_json(p)?;
            if scheme != model.metadata.landmark_scheme || ids.len() != model.landmarks.len() {
                bail!(
                    "{}: scheme {scheme} with {} ids does not match the model's {} with {}",
                    p.display(),
                    ids.len(),
                    model.metadata.landmark_scheme,
                    model.landmarks.len()
                );
            }
            Some(ids)
        }
        None => None,
    };
    let opts = RegisterOptions {
        shape_rank: a.shape_rank.unwrap_or(usize::MAX),
        color_rank: a.color_rank.unwrap_or(usize::MAX),
        iterations: a.iterations,
        landmark_weight: a.landmark_weight,
        ..Default::default()
    };
    let landmarks_used = landmarks.is_some();
    let target = PreparedTarget::new(mesh, landmarks).with_context(|| format!("target {}", a.mesh.display()))?;
    let pb = spinner("registering");
    let reg = register(&model, &target, &opts)?;
    pb.finish_and_clear();
    std::fs::create_dir_all(&a.output).with_context(|| format!("cannot create {}", a.output.display()))?;
    let out_mesh = gpmm_host::mesh::template::Mesh {
        positions: reg.positions.iter().map(|p| reg.pose.apply_inverse(*p)).collect(),
        colors: reg.colors.clone(),
        triangles: model.triangles.clone(),
    };
    let attribution = model.metadata.template.attribution.clone().unwrap_or_default();
    let comments: Vec<&str> = if attribution.is_empty() { vec![] } else { vec![attribution.as_str()] };
    mesh_io::write_ply_with(&a.output.join("registered.ply"), &out_mesh, mesh_io::PlyEncoding::BinaryLittleEndian, &comments)?;
    let report = RegisterReport {
        format: "gpmm-register".into(),
        model: a.model.display().to_string(),
        model_kernel: model.metadata.kernel.clone(),
        target: a.mesh.display().to_string(),
        landmarks_used,
        options: opts,
        ranks: [reg.shape.len(), reg.color.len()],
        residual_mm: reg.residual,
        color_residual: reg.color_residual,
        pose: reg.pose,
        shape: reg.shape.clone(),
        color: reg.color.clone(),
        history_mm: reg.history.clone(),
        seconds: t0.elapsed().as_secs_f64(),
    };
    let path = a.output.join("register.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!(
        "residual {:.2} mm mean, {:.2} mm median, {:.2} mm p90 over {:.0} % of the model's vertices; colour {:.4}; {} + {} components; {:.1} s",
        reg.residual.mean,
        reg.residual.median,
        reg.residual.p90,
        100.0 * reg.residual.covered_fraction,
        reg.color_residual.mean,
        reg.shape.len(),
        reg.color.len(),
        t0.elapsed().as_secs_f64()
    );
    eprintln!("wrote registered.ply and register.json to {}", a.output.display());
    Ok(())
}
