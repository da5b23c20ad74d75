//! Test aids shared by the training tests: the template's files and small models built from it.
#![allow(dead_code)]

use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use std::path::PathBuf;

/// The template's mesh and landmark files (`None` without the data directory).
pub fn template_files() -> Option<(PathBuf, PathBuf)> {
    let dir = template_dir(&data_dir_for_tests()?);
    Some((dir.join("lee-perry-smith.ply"), dir.join("landmarks_ibug68.json")))
}

/// A symmetric-full model of the template simplified to `vertices`, `rank` shape and colour
/// components from `nystrom` points (`None` without the data directory).
pub fn template_model(vertices: usize, rank: usize, nystrom: usize) -> Option<GpModel> {
    let (mesh, landmarks) = template_files()?;
    let template = load_template(&mesh, &landmarks, &TemplateOptions { vertices: Some(vertices), ..Default::default() }).unwrap();
    let build = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(rank),
        rank_color: RankSpec::Count(rank),
        nystrom: NystromOptions { points: nystrom, ..Default::default() },
    };
    Some(build_model(&template, &build, |_, _, _| {}))
}
