//! The landmark-free fit on the device (`gpmm device-fit --init`) against the same core path on
//! the host.
//!
//! A symmetric-full model from the template (1,000 vertices, 50 + 50 components), quantized for
//! the `m4f` profile with 8-bit bases (the default 16-bit blob, 233 KB, and the default init file,
//! 297 KB, do not fit the 512 KiB partition together with the frame), an init file from the quick
//! training (`gpmm train-init --quick`: `gpmm_train::TrainOptions::quick`) on that model, and a
//! synthetic ICT face as the 160 × 120 camera frame. The partition holds blob + fit job + init
//! file + frame; the Cortex-M4F firmware under QEMU finds the face, crops it and fits it:
//! 1. its detection and fit records are byte-identical to the host's run of the same core path
//!    (finder, initializer, `net::crop::crop_for_fit`, standard fit); the stages' instructions and
//!    the RAM (statics + the larger stage peak) are within the bounds asserted here;
//! 2. a frame where the finder's score stays below the minimum gives a "no face found" result
//!    (status ok, no fit), on both sides alike;
//! 3. a corrupted init file, a corrupted job and a working side beyond the profile's are refused
//!    by the firmware with a line that names the problem (never a panic or a fault).
//!
//! Needs QEMU and the thumbv7em toolchain (`tests/run.sh` installs them); missing tools fail,
//! never skip. Data from `$GPMM_DATA` (default `../shared/data`).

use gpmm_core::fit::{FitSettings as CoreSettings, INIT_LANDMARK_SIGMA};
use gpmm_core::profile::M4F;
use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::detect::Detector;
use gpmm_host::device::detect::camera_frame;
use gpmm_host::device::fit::{frame_fit_settings, run_firmware};
use gpmm_host::device::frame_fit::{
    compare, frame_section, host_frame_fit, job_bytes, parse_report, partition_bytes, DeviceFrameFitReport, FrameFitParity,
};
use gpmm_host::device::quantize::{quantize, Bits, BlobBuf, Profile, QuantizeOptions};
use gpmm_host::fit::FitOptions;
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::synth::{synthesize, SynthOptions};
use gpmm_train::scene::head::HeadContext;
use image::RgbImage;
use std::path::PathBuf;
use std::sync::OnceLock;

/// Finder + initializer on the 160 × 120 frame (the detection test's budget).
const DETECTION_BUDGET: u64 = 100_000_000;
/// The crop of a 72 × 72 working image (at most 4 × 4 bilinear samples a pixel).
const CROP_BUDGET: u64 = 20_000_000;
/// Steps of the test's fit (a short one: the stages' costs per step are the default fit's).
const STEPS: (u32, u32) = (1000, 60);

struct Fixture {
    blob: BlobBuf,
    init: Vec<u8>,
    frame: RgbImage,
    settings: CoreSettings,
}

/// The 8-bit m4f blob, the quick init file trained on its model, a synthetic face's frame.
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let data = data_dir_for_tests().expect("data directory (GPMM_DATA)");
        let dir = template_dir(&data);
        let (ply, lm) = (dir.join("lee-perry-smith.ply"), dir.join("landmarks_ibug68.json"));
        let template = load_template(&ply, &lm, &TemplateOptions { vertices: Some(1000), ..Default::default() }).expect("template");
        let build = BuildOptions {
            kernel: ModelKernel::SymmetricFull,
            hyperparameters: Default::default(),
            rank_shape: RankSpec::Count(50),
            rank_color: RankSpec::Count(50),
            nystrom: NystromOptions { points: 600, ..Default::default() },
        };
        let gp = build_model(&template, &build, |_, _, _| {});
        let q = quantize(&gp, &QuantizeOptions { bits: Bits::Eight, ..QuantizeOptions::for_profile(Profile::M4f) }).expect("quantize");
        let blob = q.to_blob().expect("blob");
        let head = HeadContext::load(&gp, &ply, &lm).expect("head");
        let (init, _) = gpmm_train::train(&gp, Some(&head), &gpmm_train::TrainOptions::quick(7), |_| {}).expect("quick training");
        let opts = SynthOptions { count: 1, seed: 3, yaws_deg: vec![0.0], size: 128, ..SynthOptions::with_data_dir(&data) };
        let face = synthesize(&opts, |_, _| {}).expect("synthetic face").remove(0);
        let (frame, _) = camera_frame(&face.image, 160, 120);
        let view = blob.view().expect("blob view");
        let mut fit = CoreSettings::DEFAULT.with_steps(STEPS.0, STEPS.1).with_ranks(view.rank_shape(), view.rank_color());
        fit.landmarks = fit.landmarks.for_initializer(INIT_LANDMARK_SIGMA);
        let options = FitOptions { size: M4F.frame_fit_side, seed: 5, fit };
        let settings = frame_fit_settings(&options.core(), &M4F);
        Fixture { blob, init, frame, settings }
    })
}

fn partition(f: &Fixture, side: u32, min_score: f32) -> Vec<u8> {
    let job = job_bytes(side, 5, &f.settings).expect("job");
    let frame = frame_section(&f.frame, min_score, 1).expect("frame");
    partition_bytes(f.blob.bytes(), &job, &f.init, &frame, &M4F).expect("partition")
}

fn file(name: &str, bytes: &[u8]) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::write(&path, bytes).expect("write partition");
    path
}

/// Runs the firmware and the host on the same inputs.
fn on_both(name: &str, min_score: f32) -> (DeviceFrameFitReport, FrameFitParity) {
    let f = fixture();
    let side = M4F.frame_fit_side;
    let log = run_firmware("m4f", &file(name, &partition(f, side, min_score)), 900).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let dev = parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"));
    let model = Detector::from_bytes(&f.init).expect("init model");
    let host = host_frame_fit(&f.blob, &model, &f.frame, min_score, 1, side, &f.settings, 5).expect("host run");
    let parity = compare(&dev, &host).expect("compare");
    println!("{name}: {}", serde_json::to_string(&parity).expect("json"));
    (dev, parity)
}

#[test]
fn landmark_free_device_fit_is_bit_identical_to_the_host_within_bounds() {
    let (dev, parity) = on_both("frame-fit-m4f.partition", 0.0);
    let (s, ram) = (dev.stage_instructions, dev.ram());
    println!("{}", serde_json::to_string_pretty(&dev).expect("json"));
    println!(
        "m4f landmark-free fit ({} + {} steps): detection {} + crop {} + fit {} = {} instructions with parsing; RAM {} static + max(detection {}, crop + fit {}) = {} of {} B",
        STEPS.0, STEPS.1, s.detection, s.crop, s.fit, s.total, ram.static_bytes, ram.detection_stack_bytes, ram.fit_stack_bytes, ram.total_bytes, ram.budget_bytes
    );
    assert!(parity.detection_bit_identical, "the detection records differ");
    assert!(parity.fit_bit_identical && parity.same_outcome, "the fit records differ: {parity:?}");
    let fit = dev.fit.as_ref().expect("a minimum score of 0 always fits");
    assert_eq!((fit.landmarks_px.len(), fit.shape.len(), fit.color.len()), (68, 50, 50));
    let crop = dev.crop.expect("crop");
    assert_eq!(crop.side, M4F.frame_fit_side);
    // The stages: each measured, within its bound, together the total.
    assert!(s.detection > 10_000_000 && s.detection <= DETECTION_BUDGET, "detection {}", s.detection);
    assert!(s.crop > 72 * 72 * 20 && s.crop <= CROP_BUDGET, "crop {}", s.crop);
    assert!(s.fit > 50_000_000 && s.fit < 400_000_000, "fit {}", s.fit);
    assert!(s.parse + s.detection + s.crop + s.fit <= s.total, "{s:?}");
    // RAM: statics + the larger stage's stack within the m4f's 192 KiB, each stage's peak plausible.
    assert_eq!((ram.static_bytes, ram.budget_bytes), (124_976, 192 * 1024));
    assert!(ram.total_bytes <= ram.budget_bytes, "RAM {} > {}", ram.total_bytes, ram.budget_bytes);
    assert!(ram.detection_stack_bytes > 2 * 27_648, "the detection's scratch is on its stack: {}", ram.detection_stack_bytes);
    assert!(ram.fit_stack_bytes > 72 * 72 * 3 + 40_000, "the working image is on the fit's stack: {}", ram.fit_stack_bytes);
}

#[test]
fn a_frame_without_a_face_reports_no_face_found() {
    // sigmoid(logit) reaches 1.0 in f32 only for a logit above ~17: no face at a minimum of 1.
    let (dev, parity) = on_both("frame-fit-m4f-noface.partition", 1.0);
    assert!(parity.detection_bit_identical && parity.same_outcome, "{parity:?}");
    if dev.detection.detection.found {
        eprintln!("the finder's logit exceeded 17: this frame counted as a face at a minimum score of 1");
        return;
    }
    assert!(dev.fit.is_none() && dev.crop.is_none() && dev.fit_record.is_none());
    assert_eq!(dev.detection.counts.initializer_runs, 0);
    // The firmware says so and ends with status ok.
    let f = fixture();
    let log = run_firmware("m4f", &file("frame-fit-m4f-noface2.partition", &partition(f, M4F.frame_fit_side, 1.0)), 300).expect("run");
    assert!(log.contains("no face found") && log.contains("status=ok") && !log.contains("GPFR"), "{log}");
}

#[test]
fn firmware_refuses_corrupted_or_mismatched_inputs() {
    let f = fixture();
    let part = partition(f, M4F.frame_fit_side, 0.0);
    let job_at = f.blob.bytes().len().next_multiple_of(16);
    let init_at = (job_at + job_bytes(M4F.frame_fit_side, 5, &f.settings).expect("job").len()).next_multiple_of(16);
    let refused = |name: &str, bytes: &[u8]| {
        let err = run_firmware("m4f", &file(name, bytes), 300).expect_err("must fail").to_string();
        assert!(err.contains("status=failed") && !err.contains("panic") && !err.contains("hard fault"), "{err}");
        err
    };
    // One flipped bit in the initializer's weights.
    let mut bad = part.clone();
    bad[init_at + f.init.len() - 3000] ^= 0x04;
    let err = refused("frame-fit-corrupt-init.partition", &bad);
    assert!(err.contains("not a valid init file after the fit job") && err.contains("CRC"), "{err}");
    // One flipped bit in the job's settings.
    let mut bad = part.clone();
    bad[job_at + 30] ^= 0x01;
    let err = refused("frame-fit-corrupt-job.partition", &bad);
    assert!(err.contains("no valid landmark-free fit job") && err.contains("CRC"), "{err}");
    // A working side the m4f's RAM does not hold.
    let err = refused("frame-fit-side.partition", &partition(f, M4F.frame_fit_side + 8, 0.0));
    assert!(err.contains("working side") && err.contains("16..=72"), "{err}");
    // A flipped pixel in the frame.
    let mut bad = part.clone();
    let at = part.len() - 100;
    bad[at] ^= 0x80;
    let err = refused("frame-fit-corrupt-frame.partition", &bad);
    assert!(err.contains("no valid detection frame") && err.contains("CRC"), "{err}");
}
