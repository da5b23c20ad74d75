//! The landmark-free start on the device against the host.
//!
//! An init file with the default training's architecture (`host/train/src/nets.rs`: a 96 × 96
//! finder with a 6 × 6 grid, a 64 × 64 initializer reading 68 landmarks, the pose and 12 light
//! values) and seeded random weights (the instructions depend on the shapes, not the values; no
//! training needed), and a 160 × 120 camera frame, flashed into the Cortex-M4F firmware's data
//! partition under QEMU:
//! 1. the firmware's detection (box, score, pose, landmarks, light) is bit-identical to the core's
//!    `detect` on the host, the finder's and the initializer's instructions are reported apart and
//!    within the issue's budget (100 M together), and statics + stack fit the m4f RAM;
//! 2. a finder score below the frame's minimum gives a record without a face, on both sides alike;
//! 3. a corrupted init file or frame is refused by the firmware: a clear log line, a non-zero exit,
//!    never a panic or a fault.
//!
//! Needs QEMU and the thumbv7em toolchain (`tests/run.sh` installs them); missing tools fail,
//! never skip.

use gpmm_core::net::{LayerKind, LayerShape, Shape};
use gpmm_core::profile::M4F;
use gpmm_host::detect::Detector;
use gpmm_host::device::detect::{compare, frame_bytes, host_detect, partition_bytes, run_detection, DeviceDetectReport};
use gpmm_host::device::fit::run_firmware;
use gpmm_train::encode::init_file_bytes;
use gpmm_train::encode::{FloatLayer, FloatNet};
use image::RgbImage;
use std::path::PathBuf;

/// The issue's budget for the finder and the initializer together (instructions).
const NETWORK_BUDGET: u64 = 100_000_000;

/// A small deterministic generator (xorshift64*), uniform in -1..1.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
        v as f32 / (1u64 << 23) as f32 - 1.0
    }
}

/// A layer with He-scaled uniform weights and small biases.
fn layer(noise: &mut Noise, kind: LayerKind, kernel: usize, stride: usize, relu: bool, cin: usize, cout: usize) -> FloatLayer {
    let fan_in = kernel * kernel * cin;
    let scale = (6.0 / fan_in as f32).sqrt();
    FloatLayer {
        shape: LayerShape { kind, kernel, stride, relu, cin, cout },
        weights: (0..cout * fan_in).map(|_| noise.next() * scale).collect(),
        bias: (0..cout).map(|_| noise.next() * 0.1).collect(),
        out_max: if relu { 3.0 } else { 0.0 },
    }
}

fn conv(noise: &mut Noise, cin: usize, cout: usize, stride: usize) -> FloatLayer {
    layer(noise, LayerKind::Conv, 3, stride, true, cin, cout)
}

/// An init file with the default architecture and random weights.
fn init_file(seed: u64) -> Vec<u8> {
    let n = &mut Noise(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let finder = FloatNet {
        input: Shape { h: 96, w: 96, c: 3 },
        layers: vec![
            conv(n, 3, 8, 2),
            conv(n, 8, 16, 2),
            conv(n, 16, 32, 2),
            conv(n, 32, 32, 1),
            conv(n, 32, 64, 2),
            conv(n, 64, 64, 1),
            layer(n, LayerKind::Conv, 1, 1, false, 64, 4),
        ],
    };
    let outputs = 2 * 68 + 3 + 12;
    let initializer = FloatNet {
        input: Shape { h: 64, w: 64, c: 3 },
        layers: vec![
            conv(n, 3, 16, 2),
            conv(n, 16, 32, 2),
            conv(n, 32, 32, 1),
            conv(n, 32, 64, 2),
            conv(n, 64, 64, 2),
            layer(n, LayerKind::Dense, 1, 1, true, 4 * 4 * 64, 128),
            layer(n, LayerKind::Dense, 1, 1, false, 128, outputs),
        ],
    };
    init_file_bytes(&finder, &initializer, 1.4, 68, 12, r#"{"test":"random weights"}"#).expect("init file")
}

/// A 160 × 120 frame: a shaded background and a bright oval with dark eyes and mouth.
fn frame() -> RgbImage {
    RgbImage::from_fn(160, 120, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let (dx, dy) = ((fx - 98.0) / 22.0, (fy - 58.0) / 30.0);
        let eye = |ex: f32| ((fx - ex).powi(2) + (fy - 50.0).powi(2)) < 9.0;
        if dx * dx + dy * dy <= 1.0 {
            if eye(90.0) || eye(106.0) || ((fy - 72.0).abs() < 2.0 && (fx - 98.0).abs() < 8.0) {
                image::Rgb([40, 25, 20])
            } else {
                image::Rgb([220, 170, 140])
            }
        } else {
            image::Rgb([(30 + x / 2) as u8, (60 + y / 3) as u8, (90 + (x + y) % 40) as u8])
        }
    })
}

fn partition_file(name: &str, bytes: &[u8]) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::write(&path, bytes).expect("write partition");
    path
}

/// Runs the firmware on `init` + `frame` and checks it against the host; returns the report.
fn detect_on_both(name: &str, init: &[u8], frame: &RgbImage, min_score: f32) -> (DeviceDetectReport, bool) {
    let section = frame_bytes(frame, min_score, 1).expect("frame");
    let part = partition_bytes(init, &section, &M4F).expect("partition");
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let dev = run_detection("m4f", &part, &path, 300).unwrap_or_else(|e| panic!("firmware run: {e}"));
    let mut model = Detector::from_bytes(init).expect("init model");
    let (face, det) = host_detect(&mut model, frame, min_score, 1).expect("host detect");
    let parity = compare(&dev, &face, det.as_ref()).expect("compare");
    println!("{name}: {}", serde_json::to_string(&parity).expect("json"));
    (dev, parity.bit_identical)
}

#[test]
fn firmware_detection_is_bit_identical_to_the_host_within_budget() {
    let init = init_file(7);
    let (dev, identical) = detect_on_both("detect-m4f.partition", &init, &frame(), 0.0);
    let c = dev.counts;
    println!("{}", serde_json::to_string_pretty(&dev).expect("json"));
    println!(
        "m4f detection: finder {} + initializer {} ({} runs) = {} instructions (total with parsing {}); RAM {} static + {} stack = {} of {} B",
        c.instructions_finder,
        c.instructions_initializer,
        c.initializer_runs,
        dev.instructions_networks,
        c.instructions_total,
        dev.ram_static_bytes,
        c.stack_peak_bytes,
        dev.ram_total_bytes,
        dev.ram_budget_bytes
    );
    assert!(identical, "the firmware's detection differs from the host's");
    assert!(dev.detection.found, "a minimum score of 0 always reads the face");
    assert_eq!((dev.landmarks_px.len(), dev.light.len()), (68, 12));
    // A real run, not a constant: the landmarks are spread and finite.
    let xs: Vec<f32> = dev.landmarks_px.iter().map(|p| p[0]).collect();
    let spread = xs.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v)) - xs.iter().fold(f32::INFINITY, |m, &v| m.min(v));
    assert!(xs.iter().all(|v| v.is_finite()) && spread > 0.0, "degenerate landmarks {xs:?}");
    // The counts: both networks measured, apart, within the budget.
    assert_eq!((c.frame_width, c.frame_height, c.initializer_runs), (160, 120, 2));
    assert!(c.instructions_finder > u64::from(c.finder_macs), "finder: {} instructions for {} MACs", c.instructions_finder, c.finder_macs);
    assert!(c.instructions_initializer > 2 * u64::from(c.initializer_macs), "initializer: {}", c.instructions_initializer);
    assert!(c.instructions_finder + c.instructions_initializer < c.instructions_total);
    assert!(dev.instructions_networks <= NETWORK_BUDGET, "finder + initializer take {} instructions", dev.instructions_networks);
    // RAM: the scratch the networks need, and statics + stack within the m4f's 192 KiB.
    assert_eq!((c.scratch_bytes, c.scratch_needed_bytes), (96 * 96 * 3, 96 * 96 * 3));
    assert_eq!(dev.ram_budget_bytes, 192 * 1024);
    assert!(dev.ram_total_bytes <= dev.ram_budget_bytes, "RAM {} > {}", dev.ram_total_bytes, dev.ram_budget_bytes);
}

#[test]
fn a_low_score_gives_no_face_on_both_sides() {
    let init = init_file(7);
    let (dev, identical) = detect_on_both("detect-m4f-none.partition", &init, &frame(), 1.0);
    assert!(identical, "host and firmware disagree on the finder's box");
    // sigmoid(logit) reaches 1.0 in f32 only for a logit above ~17; then the face is read.
    assert_eq!(dev.detection.found, dev.detection.score >= 1.0);
    if !dev.detection.found {
        assert!(dev.landmarks_px.is_empty() && dev.counts.instructions_initializer == 0 && dev.counts.initializer_runs == 0);
    }
    assert!(dev.counts.instructions_finder > 0);
}

#[test]
fn firmware_refuses_a_corrupted_init_file_or_frame() {
    let init = init_file(7);
    let section = frame_bytes(&frame(), 0.0, 1).expect("frame");
    let part = partition_bytes(&init, &section, &M4F).expect("partition");
    // One flipped bit in the initializer's weights.
    let mut bad = part.clone();
    bad[init.len() - 3000] ^= 0x04;
    let err = run_firmware("m4f", &partition_file("detect-corrupt-init.partition", &bad), 300)
        .expect_err("a corrupted init file must fail")
        .to_string();
    assert!(err.contains("not a valid init file") && err.contains("CRC"), "{err}");
    assert!(err.contains("status=failed") && !err.contains("panic") && !err.contains("hard fault"), "{err}");
    // A flipped pixel in the frame.
    let mut bad = part.clone();
    let at = part.len() - 100;
    bad[at] ^= 0x80;
    let err = run_firmware("m4f", &partition_file("detect-corrupt-frame.partition", &bad), 300)
        .expect_err("a corrupted frame must fail")
        .to_string();
    assert!(err.contains("no valid detection frame") && err.contains("CRC"), "{err}");
    // The init file alone: no frame after it.
    let mut bad = init.clone();
    bad.extend_from_slice(&[0x55; 64]);
    let err =
        run_firmware("m4f", &partition_file("detect-no-frame.partition", &bad), 300).expect_err("a missing frame must fail").to_string();
    assert!(err.contains("no valid detection frame") && err.contains("GPDF"), "{err}");
}
