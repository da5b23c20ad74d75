//! Every wire format fuzzed in the test suite: the cargo-fuzz targets' bodies (core/fuzz/src/bodies.rs)
//! run on their seed corpora (real files written by the formats' writers, checked current here)
//! and then for a few seconds each on random mutations of them, on stable Rust. The long runs are
//! cargo-fuzz's (core/fuzz/README.md).
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

#[path = "../fuzz/src/bodies.rs"]
mod bodies;

use gpmm_core::fit::FitSettings;
use gpmm_core::format::detection::{self, DetectCounts, DetectionFigures, Frame};
use gpmm_core::format::fit_record::{self, DeviceCounts, FitFigures};
use gpmm_core::format::init_file::{write_init_file, InitFile};
use gpmm_core::format::{fit_input, frame_fit};
use gpmm_core::render::ShLight;
use rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn seed_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds").join(target)
}

/// One network layer in the init file's encoding (docs/init-format.md, "Network"), with
/// deterministic small weights.
fn layer(out: &mut Vec<u8>, kind: u8, kernel: u8, stride: u8, cin: u16, cout: u16, out_scale: f32) {
    out.extend_from_slice(&[kind, kernel, stride, u8::from(out_scale > 0.0)]);
    out.extend_from_slice(&cin.to_le_bytes());
    out.extend_from_slice(&cout.to_le_bytes());
    out.extend_from_slice(&out_scale.to_le_bytes());
    let n = usize::from(cout) * usize::from(kernel) * usize::from(kernel) * usize::from(cin);
    out.extend((0..n).map(|i| ((i * 37 % 61) as i32 - 30) as i8 as u8));
    out.resize(out.len().next_multiple_of(4), 0);
    for o in 0..cout {
        out.extend_from_slice(&(0.01 + 0.001 * f32::from(o)).to_le_bytes());
    }
    for o in 0..cout {
        out.extend_from_slice(&(0.05 * f32::from(o % 5) - 0.1).to_le_bytes());
    }
}

/// A network: header (layer count, input shape) and its `count` layers.
fn network(count: u16, input: [u16; 3], layers: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    let mut out = Vec::new();
    for v in [count, 0, input[0], input[1], input[2], 0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    layers(&mut out);
    out
}

/// A small init file: an 8 × 8 finder (two convolutions) and a 4 × 4 dense initializer reading
/// `landmarks` points and `light` light values.
fn init_file(landmarks: u16, light: u16) -> Vec<u8> {
    let finder = network(2, [8, 8, 3], |o| {
        layer(o, 1, 3, 2, 3, 4, 0.05);
        layer(o, 1, 1, 1, 4, 4, 0.0);
    });
    let initializer = network(1, [4, 4, 3], |o| layer(o, 2, 1, 1, 48, 2 * landmarks + 3 + light, 0.0));
    let mut out = vec![0u8; 64 + finder.len() + initializer.len() + 64];
    let n = write_init_file(&mut out, &finder, &initializer, 1.5, landmarks, light, "{\"seed\":true}").unwrap();
    out.truncate(n);
    out
}

/// The seed files of every target but the blob's (core/tests/blob.rs writes those).
fn seeds() -> Vec<(&'static str, &'static str, Vec<u8>)> {
    let settings = FitSettings::DEFAULT;
    let (w, h) = (6u32, 5u32);
    let pixels: Vec<[u8; 3]> = (0..w * h).map(|i| [(i * 9) as u8, (200 - i) as u8, 77]).collect();
    let landmarks = [[1.5f32, 2.5], [3.25, 0.5], [4.0, 4.0]];
    let mut input = vec![0u8; fit_input::buffer_len(w, h, landmarks.len())];
    // The top row left out, as for a crop that leaves the photo.
    let covered = gpmm_core::geometry::CoveredPixels { x0: 0, y0: 1, x1: w, y1: h };
    let n = fit_input::write(&mut input, w, h, 42, covered, &settings, &landmarks, &pixels).unwrap();
    input.truncate(n);
    let mut job = vec![0u8; frame_fit::buffer_len()];
    let n = frame_fit::write(&mut job, 64, 7, &settings).unwrap();
    job.truncate(n);
    let rgb: Vec<u8> = (0..3 * 7 * 5).map(|i| (i * 13 % 256) as u8).collect();
    let mut frame = vec![0u8; detection::frame_len(7, 5)];
    detection::write_frame(&mut frame, &Frame { width: 7, height: 5, min_score: 0.5, refine: 1, rgb: &rgb }).unwrap();
    let figures = DetectionFigures { found: true, cx: 30.5, cy: 20.0, size: 18.0, score: 0.9, angles: [0.1, -0.05, 0.02] };
    let counts = DetectCounts { instructions_finder: 1000, frame_width: 7, frame_height: 5, ..DetectCounts::default() };
    let mut record = vec![0u8; detection::record_len(3, 2)];
    detection::write_record(&mut record, &figures, &counts, &landmarks, &[0.5, -0.25]).unwrap();
    let fit = FitFigures { yaw: 0.2, focal: 300.0, translation: [1.0, 2.0, -600.0], covered_pixels: 99, ..FitFigures::default() };
    let device = DeviceCounts { instructions_total: 123_456, image_width: w, image_height: h, ..DeviceCounts::default() };
    let mut fit_rec = vec![0u8; fit_record::encoded_len(2, 1, 3)];
    fit_record::write(&mut fit_rec, &fit, &device, &ShLight::frontal(), &[0.5, -1.0], &[0.25], &landmarks).unwrap();
    vec![
        ("init_file", "five-landmarks.init", init_file(5, 2)),
        ("init_file", "ibug68.init", init_file(68, 0)),
        ("fit_input", "6x5-3-landmarks.gpfi", input),
        ("frame_fit_job", "side64.gpff", job),
        ("detection", "7x5.gpdf", frame),
        ("detection", "found.gpdr", record),
        ("fit_record", "small.gpfr", fit_rec),
    ]
}

/// The seeds are what the writers write, and each parses (so the targets start from valid files);
/// regenerate with `GPMM_WRITE_FUZZ_SEEDS=1 cargo test -p gpmm-core --test fuzz`.
#[test]
fn fuzz_seeds_are_current() {
    for (target, name, bytes) in seeds() {
        let words: Vec<u32> = {
            let mut w = vec![0u32; bytes.len().div_ceil(4)];
            bytemuck::cast_slice_mut::<u32, u8>(&mut w)[..bytes.len()].copy_from_slice(&bytes);
            w
        };
        let b = &bytemuck::cast_slice::<u32, u8>(&words)[..bytes.len()];
        let parses = match target {
            "init_file" => InitFile::parse(b).is_ok(),
            "fit_input" => fit_input::parse::<FitSettings>(b, 128, 68).is_ok(),
            "frame_fit_job" => frame_fit::parse::<FitSettings>(b, 72).is_ok(),
            "detection" => detection::parse_frame(b).is_ok() || detection::parse_record(b).is_ok(),
            "fit_record" => fit_record::parse(b).is_ok(),
            _ => false,
        };
        assert!(parses, "seed {target}/{name} does not parse");
        assert!(bytes.len() < 10_000, "seed {target}/{name} is large ({} bytes)", bytes.len());
        let path = seed_dir(target).join(name);
        if std::env::var_os("GPMM_WRITE_FUZZ_SEEDS").is_some() {
            std::fs::create_dir_all(seed_dir(target)).unwrap();
            std::fs::write(&path, &bytes).unwrap();
        }
        let on_disk = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e} (regenerate with GPMM_WRITE_FUZZ_SEEDS=1)", path.display()));
        assert_eq!(on_disk, bytes, "{} is stale (regenerate with GPMM_WRITE_FUZZ_SEEDS=1)", path.display());
    }
}

/// A value a mutation writes into a header field: the edges of the ranges the parsers check.
fn interesting(rng: &mut Xoshiro256PlusPlus) -> u32 {
    const EDGES: [u32; 12] = [0, 1, 2, 3, 4, 15, 16, 68, 69, 0x7fff_ffff, 0xffff_ffff, 0x1_0000];
    match rng.next_u32() % 3 {
        0 => EDGES[rng.next_u32() as usize % EDGES.len()],
        1 => rng.next_u32() % 300,
        _ => rng.next_u32(),
    }
}

/// `seed` changed by one to four random edits (bit flips, bytes, 32-bit fields at 4-byte
/// offsets, truncations, insertions, a splice of another seed).
fn mutate(rng: &mut Xoshiro256PlusPlus, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.next_u32() % 4 {
        let at = if b.is_empty() { 0 } else { rng.next_u32() as usize % b.len() };
        match rng.next_u32() % 7 {
            0 if !b.is_empty() => b[at] ^= 1 << (rng.next_u32() % 8),
            1 if !b.is_empty() => b[at] = rng.next_u32() as u8,
            2 => {
                let field = (at / 4 * 4).min(b.len().saturating_sub(4));
                if b.len() >= 4 {
                    b[field..field + 4].copy_from_slice(&interesting(rng).to_le_bytes());
                }
            }
            3 => b.truncate(at),
            4 => {
                let n = 1 + rng.next_u32() as usize % 16;
                let bytes: Vec<u8> = (0..n).map(|_| rng.next_u32() as u8).collect();
                b.splice(at..at, bytes);
            }
            5 if !other.is_empty() => {
                let from = rng.next_u32() as usize % other.len();
                let n = (rng.next_u32() as usize % 64).min(other.len() - from);
                let end = (at + n).min(b.len());
                b.splice(at..end, other[from..from + n].iter().copied());
            }
            _ => b.extend((0..rng.next_u32() % 8).map(|_| rng.next_u32() as u8)),
        }
    }
    b
}

/// Seconds of mutations per target (`GPMM_FUZZ_SECONDS`, default 2).
fn seconds() -> f64 {
    std::env::var("GPMM_FUZZ_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(2.0)
}

#[test]
fn every_target_survives_its_seeds_and_a_few_seconds_of_mutations() {
    for (i, (target, body)) in bodies::TARGETS.into_iter().enumerate() {
        let mut corpus: Vec<Vec<u8>> = std::fs::read_dir(seed_dir(target))
            .unwrap_or_else(|e| panic!("{}: {e}", seed_dir(target).display()))
            .map(|e| std::fs::read(e.unwrap().path()).unwrap())
            .collect();
        corpus.sort();
        assert!(!corpus.is_empty(), "{target}: no seeds");
        for seed in &corpus {
            assert!(body(seed) > 0, "{target}: a seed does not parse");
            body(&seed[..seed.len() / 2]);
            body(&[]);
        }
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x5eed + i as u64);
        let (start, budget) = (Instant::now(), Duration::from_secs_f64(seconds()));
        let (mut runs, mut parsed) = (0u64, 0u64);
        while start.elapsed() < budget {
            let seed = &corpus[rng.next_u32() as usize % corpus.len()];
            let other = &corpus[rng.next_u32() as usize % corpus.len()];
            let input = mutate(&mut rng, seed, other);
            parsed += u64::from(body(&input) > 0);
            runs += 1;
        }
        eprintln!(
            "{target}: {} seeds, {runs} mutated inputs in {:.1} s, {parsed} of them parsed",
            corpus.len(),
            start.elapsed().as_secs_f64()
        );
        // The mutations reach past the checks (the CRC fix-up): some mutated inputs parse and are used.
        assert!(parsed > 0 && parsed < runs, "{target}: {parsed} of {runs} mutated inputs parsed");
    }
}
