//! The fit on the device against the fit on the host.
//!
//! A symmetric-full model is built from the template (simplified to 1,000 vertices, 50 + 50
//! components), quantized for the `m4f` profile into a blob, and fitted to synthetic ICT faces
//! (`gpmm_host::synth`, known truth):
//! 1. the same blob, image, landmarks and seed on the host core and in the Cortex-M4F firmware
//!    under QEMU (a device's default fit, `FitSettings::DEVICE`): fitted landmarks within
//!    0.5 px, best image log-likelihood within 1 %; the firmware's flash, RAM and instruction
//!    figures are printed and checked against the m4f budget; the firmware's profile by function
//!    (`firmware-sim/profile.sh`) counts its instructions;
//! 2. the float model and the quantized blob on the host, on several synthetic faces: fitted
//!    landmarks within 1 px;
//! 3. a corrupted blob makes the firmware fail with the core's error, not a fault.
//!
//! Needs QEMU and the thumbv7em toolchain (`tests/run.sh` installs them); missing tools fail,
//! never skip. Data from `$GPMM_DATA` (default `../shared/data`).

use gpmm_core::fit::FitSettings as CoreSettings;
use gpmm_core::fit::{
    Drift, DriftSettings, ImageSettings, LandmarkSettings, LightSettings, MixtureShares, OcclusionSettings, ProposalSettings, RankSettings,
    StartSettings,
};
use gpmm_core::format::fit_record;
use gpmm_core::profile::M4F;
use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::device::fit::{
    device_settings, figure, fit_input_bytes, host_fit, parse_report, partition_bytes, record_bytes, run_firmware, run_firmware_on,
};
use gpmm_host::device::quantize::{quantize, Bits, BlobBuf, Profile, QuantizeOptions, QuantizedModel};
use gpmm_host::eval::models::pca::{pca_beside, KeptCovariance};
use gpmm_host::fit::{fit_prepared, prepare, rmse, FitOptions, Prepared};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel, PartBasis};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::synth::{synthesize, SynthFace, SynthOptions};
use std::path::Path;
use std::sync::OnceLock;

/// The symmetric-full model of the template at 1,000 vertices, 50 + 50 components (built once
/// per test binary).
fn template_model() -> &'static GpModel {
    static M: OnceLock<GpModel> = OnceLock::new();
    M.get_or_init(|| {
        let data = data_dir_for_tests().expect("data directory (GPMM_DATA)");
        let dir = template_dir(&data);
        let opts = TemplateOptions { vertices: Some(1000), ..Default::default() };
        let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &opts).expect("template");
        let build = BuildOptions {
            kernel: ModelKernel::SymmetricFull,
            hyperparameters: Default::default(),
            rank_shape: RankSpec::Count(50),
            rank_color: RankSpec::Count(50),
            nystrom: NystromOptions { points: 600, ..Default::default() },
        };
        build_model(&template, &build, |_, _, _| {})
    })
}

/// The m4f blob and the float model it was quantized from (built once per test binary).
fn models() -> &'static (QuantizedModel, BlobBuf) {
    static M: OnceLock<(QuantizedModel, BlobBuf)> = OnceLock::new();
    M.get_or_init(|| {
        let q = quantize(template_model(), &QuantizeOptions::for_profile(Profile::M4f)).expect("quantize for m4f");
        let blob = q.to_blob().expect("blob");
        (q, blob)
    })
}

fn faces(count: usize, seed: u64) -> Vec<SynthFace> {
    let data = data_dir_for_tests().expect("data directory (GPMM_DATA)");
    let opts = SynthOptions { count, seed, yaws_deg: vec![0.0, 30.0], size: 128, ..SynthOptions::with_data_dir(&data) };
    synthesize(&opts, |_, _| {}).expect("synthetic faces")
}

fn prepared(face: &SynthFace) -> Prepared {
    prepare(&face.image, &face.truth.landmarks, 128).expect("prepare")
}

fn max_distance(a: &[[f32; 2]], b: &[[f32; 2]]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0, f32::max)
}

#[test]
fn firmware_fit_matches_the_host_within_the_m4f_budget() {
    let (q, blob) = models();
    let face = &faces(1, 11)[1];
    let prep = prepared(face);
    // The device's default fit (device_settings: the ranks capped), with the start's shape solve
    // and its image chain at half resolution.
    let fit = device_settings(&CoreSettings::DEVICE.with_ranks(q.shape.rank(), q.color.rank()), &M4F);
    assert!(fit.start.shape_rounds > 0, "the device's default fit runs the shape solve");
    assert!(fit.image.coarse_steps > 0, "the device's default fit starts its image chain at half resolution");
    let settings = FitOptions { fit, ..FitOptions::DEFAULT };

    let device = device_settings(&settings.core(), &M4F);
    let (host, host_lm) = host_fit(blob, &prep, &device, settings.seed).expect("host fit");
    let host_ll = host.image.best_image.expect("image term").log_likelihood;

    let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &device, settings.seed).expect("fit input"));
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fit-m4f.partition");
    std::fs::write(&file, &part).expect("write partition");
    let log = run_firmware("m4f", &file, 1200).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let dev = parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"));
    println!("{}", serde_json::to_string_pretty(&dev).expect("json"));

    // Parity.
    let d = max_distance(&host_lm, &dev.landmarks_px);
    let rel = ((host_ll - dev.log_likelihood) / host_ll.abs()).abs();
    println!("host vs firmware: landmarks differ by at most {d} px; log-likelihood {host_ll} vs {} ({rel:e})", dev.log_likelihood);
    assert!(d <= 0.5, "fitted landmarks differ by {d} px between host and firmware");
    assert!(rel <= 0.01, "log-likelihood differs by {rel} (host {host_ll}, firmware {})", dev.log_likelihood);
    assert!((host.params().pose.yaw.to_degrees() - dev.yaw_deg).abs() < 0.1);
    // The record's landmark acceptance is the whole landmark chain's (both phases), as fit.json's.
    let landmark_acceptance = host.landmark_acceptance();
    assert!((0.05..0.95).contains(&landmark_acceptance), "landmark chain acceptance {landmark_acceptance}");
    assert_eq!(dev.acceptance_landmark_chain, landmark_acceptance, "the device record's landmark acceptance");
    assert!(dev.acceptance_image_chain > 0.0, "the device record's image acceptance");
    // The device reports the pose's spread from the landmarks, the host's own to the bit.
    let valid = vec![true; prep.landmarks.len()];
    let target = gpmm_core::fit::LandmarkTarget::new(&prep.landmarks, &valid, 1.0).expect("landmarks");
    let view = blob.view().expect("blob");
    let spread = gpmm_core::fit::pose_spread(&view.morphable().expect("model"), host.params(), &target, 128, 128).expect("spread");
    assert_eq!(dev.angles_sd_deg, gpmm_host::fit::calibrated_angles_sd_deg(&spread), "the device's pose spread");
    assert!(dev.angles_sd_deg.iter().all(|s| *s > 0.0) && dev.landmark_residual_px == spread.residual_sigma_px);

    // Budgets (m4f: 1 MiB flash for code + blob, 192 KiB RAM for statics + stack).
    assert_eq!(dev.flash_budget_bytes, 1024 * 1024);
    assert!(dev.flash_total_bytes <= dev.flash_budget_bytes, "flash {} > {}", dev.flash_total_bytes, dev.flash_budget_bytes);
    assert_eq!(dev.ram_budget_bytes, 192 * 1024);
    assert!(dev.ram_total_bytes <= dev.ram_budget_bytes, "RAM {} > {}", dev.ram_total_bytes, dev.ram_budget_bytes);
    assert!(dev.instructions_total > 100_000_000, "implausibly few instructions: {}", dev.instructions_total);
    // A third of the host's default fit: at most 0.4 × 10⁹ instructions (2.4 s at 168 MHz).
    assert!(dev.instructions_total <= 400_000_000, "the m4f default fit took {} instructions", dev.instructions_total);
    assert!(dev.instructions_landmark_chain + dev.instructions_image_chain < dev.instructions_total, "the stages are part of the total");
    println!(
        "m4f default fit: {} instructions ({:.1} s at 168 MHz, 1 instruction per cycle); {} per image step; flash {} + blob {} B; RAM {} + stack {} B",
        dev.instructions_total,
        dev.seconds_at_168mhz,
        dev.instructions_per_image_step,
        dev.flash_bytes,
        dev.blob_bytes,
        dev.ram_static_bytes,
        dev.stack_peak_bytes
    );
}

/// The int16 blob fits like the float model it was made from. Not bit for bit: the start's shape
/// solve carries a 1e-4 mm quantization difference into the coefficients, and the chains are
/// chaotic (one accept decision flipped and the two runs are two draws of the same posterior).
/// The fitted landmarks stay within a pixel of each other, and every face fits the target
/// landmarks equally well.
#[test]
fn float_model_and_blob_fit_the_same_landmarks() {
    let (q, blob) = models();
    // The device's settings: the float fit compares like with like.
    let fit = device_settings(&CoreSettings::DEFAULT.with_ranks(q.shape.rank(), q.color.rank()), &M4F);
    let settings = FitOptions { fit, ..FitOptions::DEFAULT };
    let (mut worst, mut worst_quality) = (0.0f32, 0.0f32);
    let faces = faces(3, 5);
    for face in &faces {
        let prep = prepared(face);
        let (_, blob_lm) = host_fit(blob, &prep, &device_settings(&settings.core(), &M4F), settings.seed).expect("blob fit");
        let float = fit_prepared(&q.reduced, &prep, &settings, &mut |_, _, _| {}).expect("float fit");
        let d = max_distance(&float.fitted_landmarks, &blob_lm);
        let (rf, rb) = (rmse(&float.fitted_landmarks, &prep.landmarks), rmse(&blob_lm, &prep.landmarks));
        println!("{}: float vs blob landmarks differ by at most {d:.3} px; RMSE to the target {rf:.3} vs {rb:.3} px", face.truth.image);
        worst = worst.max(d);
        worst_quality = worst_quality.max((rf - rb).abs());
    }
    assert!(worst <= 1.0, "float model and blob fits differ by {worst} px");
    assert!(worst_quality <= 0.25, "the blob fits the target landmarks worse or better by {worst_quality} px");
}

#[test]
fn firmware_rejects_a_corrupted_blob() {
    let (_, blob) = models();
    let face = &faces(1, 11)[0];
    let prep = prepared(face);
    let settings = FitOptions { fit: CoreSettings::DEFAULT.with_steps(10, 2), ..FitOptions::DEFAULT };
    let mut part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &settings.core(), settings.seed).expect("fit input"));
    part[5000] ^= 0x10;
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fit-m4f-corrupt.partition");
    std::fs::write(&file, &part).expect("write partition");
    let err = run_firmware("m4f", &file, 300).expect_err("a corrupted blob must fail").to_string();
    assert!(err.contains("not a valid model blob") && err.contains("CRC"), "{err}");
    assert!(!err.contains("panic") && !err.contains("hard fault"), "{err}");
}

/// The fit input carries every setting: with each one away from its default, host and firmware
/// still give the same fit, and that fit differs from the default-settings one.
#[test]
fn firmware_fit_uses_every_setting() {
    let (_, blob) = models();
    let face = &faces(1, 11)[1];
    let prep = prepared(face);
    let defaults = CoreSettings::DEFAULT;
    let settings = CoreSettings {
        landmarks: LandmarkSettings {
            steps: 1500,
            pose_share: 0.5,
            contour_landmarks: 12,
            contour_sigma_factor: 2.0,
            sigma: 0.008,
            student_t: 5.0,
            silhouette: true,
            hidden_contour_min_cos: -0.3,
        },
        image: ImageSettings {
            steps: 40,
            coarse_steps: 15,
            pixel_sigma: 0.05,
            background_floor: 0.02,
            color_polish_rounds: 1,
            landmark_sigma_factor: 2.0,
        },
        ranks: RankSettings { shape: 30, color: 20 },
        start: StartSettings {
            nominal_distance_mm: 600.0,
            color_rounds: 2,
            color_stride: 3,
            color_weight: 0.5,
            color_iterations: 12,
            shape_rounds: 1,
            shape_components: 12,
            shape_iterations: 2,
            shape_stride: 3,
            shape_min_cos: 0.5,
            shape_weight: 0.5,
            shape_landmarks: false,
            shape_pose: true,
        },
        proposals: ProposalSettings {
            landmark_pose: MixtureShares { pose: 0.9, ..defaults.proposals.landmark_pose },
            landmark_shape: MixtureShares { shape: 0.5, ..defaults.proposals.landmark_shape },
            image: MixtureShares { light_solve: 0.08, ..defaults.proposals.image },
            drift: DriftSettings {
                shape: Drift { sigmas: [0.25, 0.1, 0.03], ..defaults.proposals.drift.shape },
                shape_leading: [8, 30, 0],
                color_leading: [5, 20, 0],
                ..defaults.proposals.drift
            },
        },
        light: LightSettings { solve_stride: 5, ridge_ambient: [0.7; 3], ..defaults.light },
        occlusion: OcclusionSettings { rounds: 2, threshold: -6.0, smoothing: 1 },
    };
    // Every top-level field and group differs from the default. A new field must be added here;
    // 102 fields counting the groups' own.
    let fields = format!("{settings:?}");
    assert_eq!(fields.matches(": ").count(), 102, "update this test for the new settings: {fields}");
    let seed = 99;
    let (host, host_lm) = host_fit(blob, &prep, &settings, seed).expect("host fit");
    let host_ll = host.image.best_image.expect("image term").log_likelihood;
    let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &settings, seed).expect("fit input"));
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fit-m4f-settings.partition");
    std::fs::write(&file, &part).expect("write partition");
    let log = run_firmware("m4f", &file, 600).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let dev = parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"));
    let d = max_distance(&host_lm, &dev.landmarks_px);
    let rel = ((host_ll - dev.log_likelihood) / host_ll.abs()).abs();
    println!("non-default settings: host vs firmware landmarks {d} px apart, log-likelihood {host_ll} vs {}", dev.log_likelihood);
    assert!(d <= 1e-3, "fitted landmarks differ by {d} px between host and firmware");
    assert!(rel <= 1e-5, "log-likelihood differs by {rel}");
    assert_eq!((dev.shape.len(), dev.color.len()), (30, 20), "the ranks reached the device");
    let (default_fit, _) = host_fit(blob, &prep, &device_settings(&defaults.with_ranks(30, 20), &M4F), seed).expect("default fit");
    assert_ne!(default_fit.params().pose.yaw, host.params().pose.yaw, "the settings changed nothing");
}

/// A face at the photo's edge: the synthetic face cut a pixel above its chin point, so the chin
/// lies outside the photo and the fit's crop leaves it; the host and the firmware leave the same
/// pixels out (the fit input carries them) and give the same fit bit for bit.
#[test]
fn firmware_fit_of_a_face_cut_by_the_frame_matches_the_host_bit_for_bit() {
    let (_, blob) = models();
    let face = &faces(1, 11)[0];
    let chin = face.truth.landmarks[8][1];
    let rows = chin.floor() as u32 - 1;
    let photo = image::imageops::crop_imm(&face.image, 0, 0, face.image.width(), rows).to_image();
    let prep = prepare(&photo, &face.truth.landmarks, 128).expect("prepare");
    assert!(prep.covered.y1 < 128, "the crop leaves the photo at the bottom: {:?}", prep.covered);
    let settings = device_settings(&CoreSettings::DEFAULT.with_ranks(30, 20).with_steps(600, 30), &M4F);
    let (host, host_lm) = host_fit(blob, &prep, &settings, 7).expect("host fit");
    let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &settings, 7).expect("fit input"));
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fit-m4f-edge.partition");
    std::fs::write(&file, &part).expect("write partition");
    let log = run_firmware("m4f", &file, 600).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let dev = parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"));
    let host_ll = host.image.best_image.expect("image term").log_likelihood;
    assert_eq!(host_lm, dev.landmarks_px, "fitted landmarks differ between host and firmware");
    assert_eq!(host_ll.to_bits(), dev.log_likelihood.to_bits(), "log-likelihood {host_ll} vs {}", dev.log_likelihood);
    // Leaving the pixels out changed the fit: the same input with every pixel counted differs.
    let mut whole = prep.clone();
    whole.covered = gpmm_core::fit::CoveredPixels::whole(128, 128);
    let (counted, _) = host_fit(blob, &whole, &settings, 7).expect("host fit, all pixels counted");
    assert_ne!(counted.image.best_image.expect("image term").log_likelihood.to_bits(), host_ll.to_bits());
}

/// The STM32F405's memory map (`gpmm_core::profile::NETDUINOPLUS2`, QEMU's F405 machine: statics
/// in the 128 KiB SRAM, the stack in its own 64 KiB block, flash and the data partition at
/// `0x0800_0000`) gives the same fit record as the mps2 board, and the fit stays in both blocks.
#[test]
fn the_stm32f405_memory_map_gives_the_same_fit_record_within_its_ram_blocks() {
    let (q, blob) = models();
    let prep = prepared(&faces(1, 11)[1]);
    // The device's default fit, shortened (stack depth and statics do not depend on the steps).
    let fit = device_settings(&CoreSettings::DEFAULT.with_ranks(q.shape.rank(), q.color.rank()), &M4F).with_steps(400, 40);
    let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &fit, 5).expect("fit input"));
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fit-m4f-maps.partition");
    std::fs::write(&file, &part).expect("write partition");
    let run = |map: &str| {
        let log = run_firmware_on("m4f", map, &file, 900).unwrap_or_else(|e| panic!("firmware run on {map}: {e}"));
        (record_bytes(&log).unwrap_or_else(|e| panic!("{e}\n{log}")), log)
    };
    let ((mps2, _), (f405, f405_log)) = std::thread::scope(|s| {
        let a = s.spawn(|| run("mps2"));
        let b = s.spawn(|| run("netduinoplus2"));
        (a.join().expect("mps2 run"), b.join().expect("netduinoplus2 run"))
    });
    let (a, b) = (fit_record::parse(&mps2).expect("mps2 record"), fit_record::parse(&f405).expect("f405 record"));
    // The fit itself, bit for bit.
    assert_eq!(format!("{:?}", a.figures), format!("{:?}", b.figures));
    assert_eq!(a.light, b.light);
    let bits = |v: fit_record::F32s<'_>| v.iter().map(f32::to_bits).collect::<Vec<_>>();
    assert_eq!(bits(a.shape), bits(b.shape));
    assert_eq!(bits(a.color), bits(b.color));
    assert_eq!(bits(a.landmarks), bits(b.landmarks));
    let (ca, cb) = (a.counts, b.counts);
    assert_eq!(
        (ca.shape_updates, ca.color_updates, ca.blob_bytes, ca.partition_bytes),
        (cb.shape_updates, cb.color_updates, cb.blob_bytes, cb.partition_bytes)
    );
    // The instructions: the same code, counted from a 25 MHz or a 168 MHz SysTick.
    let rel = (ca.instructions_total as f64 - cb.instructions_total as f64).abs() / ca.instructions_total as f64;
    println!(
        "instructions: mps2 {} vs netduinoplus2 {} ({rel:e}); stack peak {} vs {} B",
        ca.instructions_total, cb.instructions_total, ca.stack_peak_bytes, cb.stack_peak_bytes
    );
    assert!(rel < 1e-3, "instruction counts differ by {rel}");
    // The F405's blocks: statics in 128 KiB, the stack's peak in 64 KiB (the whole run's).
    let statics: u64 = figure(&f405_log, "ram_static_bytes").expect("statics");
    let peak: u64 = figure(&f405_log, "stack_peak_bytes").expect("stack peak");
    let (statics_budget, stack_budget): (u64, u64) = (
        figure(&f405_log, "statics_budget_bytes").expect("statics budget"),
        figure(&f405_log, "stack_budget_bytes").expect("stack budget"),
    );
    let f405 = gpmm_core::profile::STM32F405;
    assert_eq!((statics_budget, stack_budget), (f405.statics_bytes.unwrap_or(0) as u64, f405.stack.map_or(0, |s| s.bytes) as u64));
    assert_eq!((statics_budget, stack_budget), (128 * 1024, 64 * 1024));
    println!("STM32F405 map: statics {statics} of {statics_budget} B, stack peak {peak} of {stack_budget} B");
    assert!(statics <= statics_budget, "statics {statics} B > {statics_budget} B");
    assert!(peak < stack_budget, "stack peak {peak} B reaches the {stack_budget} B block");
    assert!(peak >= u64::from(cb.stack_peak_bytes) && peak > 10_000, "implausible stack peak {peak}");
}

/// A model `gpmm learn` makes (a PCA of reconstructions beside its predecessor's covariance: dense
/// components) goes on the m4f as docs/learning.md says (8-bit values, 40 + 40 components) and
/// fits there as on the host, bit for bit, at most a tenth dearer than the template model's
/// factored blob with the same settings.
#[test]
fn a_learned_dense_model_fits_on_the_firmware_bit_for_bit() {
    let gp = template_model();
    let examples: Vec<_> = (0..12)
        .map(|j| {
            let c = |k: usize, f: f64| (((j * 31 + k * 17) as f64 * f).sin() * 1.5) as f32;
            gp.instance(&(0..20).map(|k| c(k, 0.37)).collect::<Vec<_>>(), &(0..20).map(|k| c(k, 0.53)).collect::<Vec<_>>())
                .expect("instance")
        })
        .collect();
    let kept = KeptCovariance { model: gp, share: 1.0, max_rank: 50 };
    let learned = pca_beside(&examples, Some(kept), &gp.triangles, &gp.landmarks, "learned", "test", "test").expect("learned model");
    assert!(matches!(learned.shape.basis, PartBasis::Dense { .. }), "a learned model is dense");
    let options = QuantizeOptions { bits: Bits::Eight, rank_shape: 40, rank_color: 40, ..QuantizeOptions::for_profile(Profile::M4f) };
    let blob = quantize(&learned, &options).expect("quantize for m4f").to_blob().expect("blob");
    let prep = prepared(&faces(1, 11)[1]);
    let fit = device_settings(&CoreSettings::DEFAULT.with_ranks(40, 40), &M4F);
    let (host, host_lm) = host_fit(&blob, &prep, &fit, 3).expect("host fit");
    let run = |blob: &BlobBuf, name: &str| {
        let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &fit, 3).expect("fit input"));
        let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        std::fs::write(&file, &part).expect("write partition");
        let log = run_firmware("m4f", &file, 1200).unwrap_or_else(|e| panic!("firmware run: {e}"));
        parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"))
    };
    let (dev, template) = std::thread::scope(|s| {
        let a = s.spawn(|| run(&blob, "fit-m4f-learned.partition"));
        let b = s.spawn(|| run(&models().1, "fit-m4f-template.partition"));
        (a.join().expect("learned model run"), b.join().expect("template model run"))
    });
    let host_ll = host.image.best_image.expect("image term").log_likelihood;
    assert_eq!(host_lm, dev.landmarks_px, "fitted landmarks differ between host and firmware");
    assert_eq!(host_ll.to_bits(), dev.log_likelihood.to_bits(), "log-likelihood {host_ll} vs {}", dev.log_likelihood);
    println!(
        "learned dense model, 8-bit 40 + 40: {} instructions (template model, 16-bit factored: {}), blob {} B, RAM {} + stack {} B",
        dev.instructions_total, template.instructions_total, dev.blob_bytes, dev.ram_static_bytes, dev.stack_peak_bytes
    );
    let ratio = dev.instructions_total as f64 / template.instructions_total as f64;
    assert!(ratio <= 1.1, "the learned model's fit costs {ratio:.3} times the template model's");
    assert!(dev.ram_total_bytes <= dev.ram_budget_bytes && dev.flash_total_bytes <= dev.flash_budget_bytes, "{dev:?}");
}

/// The profile of a short fit by function (`firmware-sim/profile.sh`, how docs/evaluation.md
/// breaks a step down) counts at least the instructions the firmware counts itself, and names
/// the image chain's and the shape solve's functions.
#[test]
fn the_firmware_profile_counts_its_instructions_by_function() {
    let (q, blob) = models();
    let face = &faces(1, 11)[1];
    let prep = prepared(face);
    let fit = device_settings(&CoreSettings::DEVICE.with_ranks(q.shape.rank(), q.color.rank()).with_steps(200, 20), &M4F);
    let part = partition_bytes(blob.bytes(), &fit_input_bytes(&prep, &fit, 0).expect("fit input"));
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("profile-m4f.partition");
    std::fs::write(&file, &part).expect("write partition");
    let log = run_firmware("m4f", &file, 600).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let dev = parse_report("m4f", &log).unwrap_or_else(|e| panic!("{e}\n{log}"));

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim/profile.sh");
    let out = std::process::Command::new("bash")
        .arg(&script)
        .arg("--data")
        .arg(&file)
        .args(["--json", "--top", "40"])
        .output()
        .expect("run profile.sh");
    assert!(out.status.success(), "profile.sh failed: {}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("profile JSON");
    assert_eq!((j["format"].as_str(), j["version"].as_u64()), (Some("gpmm-qemu-profile"), Some(1)));
    let total = j["instructions"].as_u64().expect("total");
    // The whole run: the firmware's counted stages, its start-up and its exit.
    assert!(
        total >= dev.instructions_total && total <= dev.instructions_total + dev.instructions_total / 10 + 10_000_000,
        "profile {total} against the firmware's {}",
        dev.instructions_total
    );
    let rows = j["functions"].as_array().expect("functions");
    let names: Vec<&str> = rows.iter().filter_map(|r| r["function"].as_str()).collect();
    for f in ["fit::chain::render_eval", "fit::solve::shape::iterate", "basis::blocks::in_blocks_of_four"] {
        assert!(names.iter().any(|n| n.contains(f)), "{f} not among {names:?}");
    }
    let counts: Vec<u64> = rows.iter().filter_map(|r| r["instructions"].as_u64()).collect();
    assert!(counts.windows(2).all(|w| w[0] >= w[1]), "not sorted: {counts:?}");
    assert!(counts.iter().sum::<u64>() <= total);
    println!("profile of a short fit: {total} instructions (firmware {}); top: {:?}", dev.instructions_total, &names[..5.min(names.len())]);
}
