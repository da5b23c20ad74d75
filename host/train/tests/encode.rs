//! The int8 networks and the init file: the core's quantized run against a float reference,
//! corrupted and truncated files refused, and the detector's outputs on any image.

use gpmm_core::format::init_file::{FINDER_CHANNELS, INIT_MAGIC};
use gpmm_core::format::FormatError;
use gpmm_core::model::ibug::ibug68_partner;
use gpmm_core::net::face::{read_landmarks, Reading};
use gpmm_core::net::face_box::FaceBox;
use gpmm_core::net::{LayerKind, LayerShape, NetError, NetScratch, Network, Shape};
use gpmm_host::detect::Detector;
use gpmm_train::encode::init_file_bytes;
use gpmm_train::encode::{encode_network, FloatLayer, FloatNet};
use image::RgbImage;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

fn layer(rng: &mut Xoshiro256PlusPlus, kind: LayerKind, kernel: usize, stride: usize, relu: bool, cin: usize, cout: usize) -> FloatLayer {
    let n = cout * kernel * kernel * cin;
    let scale = (2.0 / (kernel * kernel * cin) as f32).sqrt();
    FloatLayer {
        shape: LayerShape { kind, kernel, stride, relu, cin, cout },
        weights: (0..n).map(|_| rng.random_range(-1.0f32..1.0) * scale).collect(),
        bias: (0..cout).map(|_| rng.random_range(-0.1f32..0.1)).collect(),
        out_max: 0.0,
    }
}

/// Float forward pass, channel-last, zero padding `k / 2` (the reference the core approximates).
fn reference(net: &FloatNet, input: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let mut x = input.to_vec();
    let mut shape = net.input;
    let mut maxima = Vec::new();
    for l in &net.layers {
        let y = match l.shape.kind {
            LayerKind::Dense => {
                shape = Shape { h: 1, w: 1, c: l.shape.cout };
                l.weights
                    .chunks(l.shape.cin)
                    .zip(&l.bias)
                    .map(|(w, b)| w.iter().zip(&x).map(|(a, b)| a * b).sum::<f32>() + b)
                    .collect::<Vec<f32>>()
            }
            LayerKind::Conv => {
                let (k, s, p) = (l.shape.kernel, l.shape.stride, l.shape.kernel / 2);
                let (oh, ow) = ((shape.h + 2 * p - k) / s + 1, (shape.w + 2 * p - k) / s + 1);
                let mut y = vec![0.0; oh * ow * l.shape.cout];
                for oy in 0..oh {
                    for ox in 0..ow {
                        for o in 0..l.shape.cout {
                            let mut acc = l.bias[o];
                            for ky in 0..k {
                                for kx in 0..k {
                                    let (iy, ix) = ((oy * s + ky) as isize - p as isize, (ox * s + kx) as isize - p as isize);
                                    if iy < 0 || ix < 0 || iy >= shape.h as isize || ix >= shape.w as isize {
                                        continue;
                                    }
                                    for c in 0..l.shape.cin {
                                        acc += l.weights[((o * k + ky) * k + kx) * l.shape.cin + c]
                                            * x[(iy as usize * shape.w + ix as usize) * l.shape.cin + c];
                                    }
                                }
                            }
                            y[(oy * ow + ox) * l.shape.cout + o] = acc;
                        }
                    }
                }
                shape = Shape { h: oh, w: ow, c: l.shape.cout };
                y
            }
        };
        x = if l.shape.relu { y.into_iter().map(|v| v.max(0.0)).collect() } else { y };
        maxima.push(x.iter().fold(0.0f32, |m, v| m.max(v.abs())));
    }
    (x, maxima)
}

fn small_net(rng: &mut Xoshiro256PlusPlus) -> FloatNet {
    FloatNet {
        input: Shape { h: 9, w: 7, c: 3 },
        layers: vec![
            layer(rng, LayerKind::Conv, 3, 2, true, 3, 6),
            layer(rng, LayerKind::Conv, 3, 1, true, 6, 8),
            layer(rng, LayerKind::Conv, 1, 1, true, 8, 4),
            layer(rng, LayerKind::Dense, 1, 1, false, 5 * 4 * 4, 5),
        ],
    }
}

#[test]
fn quantized_run_follows_the_float_network() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let mut net = small_net(&mut rng);
    let input_q: Vec<i8> = (0..9 * 7 * 3).map(|_| rng.random_range(-128i32..128) as i8).collect();
    let input: Vec<f32> = input_q.iter().map(|&q| f32::from(q) / 128.0).collect();
    let (want, maxima) = reference(&net, &input);
    for (l, m) in net.layers.iter_mut().zip(&maxima) {
        l.out_max = *m;
    }
    let bytes = encode_network(&net).unwrap();
    let (parsed, len) = Network::parse(&bytes).unwrap();
    assert_eq!(len, bytes.len());
    assert_eq!(parsed.output(), Shape { h: 1, w: 1, c: 5 });
    assert_eq!(parsed.macs(), 5 * 4 * 6 * 27 + 5 * 4 * 8 * 54 + 5 * 4 * 4 * 8 + 5 * 80);
    let mut scratch = NetScratch::<512>::new();
    scratch.input_mut(input_q.len()).unwrap().copy_from_slice(&input_q);
    let mut got = [0.0f32; 5];
    parsed.run(&mut scratch, &mut got).unwrap();
    let range = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 0.08 * range + 0.02, "quantized {g} vs float {w} (range {range})");
    }
    // A scratch smaller than the largest activation is refused, not overrun.
    let mut tiny = NetScratch::<64>::new();
    assert!(matches!(parsed.run(&mut tiny, &mut got), Err(NetError::ScratchTooSmall { .. })));
    // So is an output slice of the wrong length.
    assert_eq!(parsed.run(&mut scratch, &mut [0.0; 4]), Err(NetError::LengthMismatch));
}

/// Receptive fields larger than the core's 1 KiB patch (5 × 5 × 48 = 1,200 values) are summed
/// row by row instead: both ways follow the float network.
#[test]
fn large_receptive_fields_follow_the_float_network() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
    let mut net = FloatNet {
        input: Shape { h: 7, w: 6, c: 48 },
        layers: vec![
            layer(&mut rng, LayerKind::Conv, 5, 1, true, 48, 6),
            layer(&mut rng, LayerKind::Conv, 3, 2, true, 6, 5),
            layer(&mut rng, LayerKind::Dense, 1, 1, false, 4 * 3 * 5, 3),
        ],
    };
    let input_q: Vec<i8> = (0..7 * 6 * 48).map(|_| rng.random_range(-128i32..128) as i8).collect();
    let input: Vec<f32> = input_q.iter().map(|&q| f32::from(q) / 128.0).collect();
    let (want, maxima) = reference(&net, &input);
    for (l, m) in net.layers.iter_mut().zip(&maxima) {
        l.out_max = *m;
    }
    let bytes = encode_network(&net).unwrap();
    let (parsed, _) = Network::parse(&bytes).unwrap();
    let mut scratch = NetScratch::<4096>::new();
    scratch.input_mut(input_q.len()).unwrap().copy_from_slice(&input_q);
    let mut got = [0.0f32; 3];
    parsed.run(&mut scratch, &mut got).unwrap();
    let range = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(range > 0.0);
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 0.08 * range + 0.02, "quantized {g} vs float {w} (range {range})");
    }
}

fn init_bytes(seed: u64) -> Vec<u8> {
    init_bytes_with(seed, 68)
}

fn init_bytes_with(seed: u64, landmarks: u16) -> Vec<u8> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let finder = FloatNet {
        input: Shape { h: 32, w: 32, c: 3 },
        layers: vec![
            {
                let mut l = layer(&mut rng, LayerKind::Conv, 3, 2, true, 3, 4);
                l.out_max = 2.0;
                l
            },
            {
                let mut l = layer(&mut rng, LayerKind::Conv, 3, 2, true, 4, 4);
                l.out_max = 2.0;
                l
            },
            layer(&mut rng, LayerKind::Conv, 1, 1, false, 4, FINDER_CHANNELS),
        ],
    };
    let outputs = 2 * usize::from(landmarks) + 3 + 12;
    let initializer = FloatNet {
        input: Shape { h: 16, w: 16, c: 3 },
        layers: vec![
            {
                let mut l = layer(&mut rng, LayerKind::Conv, 3, 2, true, 3, 4);
                l.out_max = 2.0;
                l
            },
            layer(&mut rng, LayerKind::Dense, 1, 1, false, 8 * 8 * 4, outputs),
        ],
    };
    init_file_bytes(&finder, &initializer, 1.4, landmarks, 12, "{\"format\":\"gpmm-init\"}").unwrap()
}

#[test]
fn init_file_reads_back_and_detects_on_any_image() {
    let bytes = init_bytes(5);
    assert_eq!(&bytes[..4], &INIT_MAGIC);
    let mut detector = Detector::from_bytes(&bytes).unwrap();
    let file = detector.file().unwrap();
    assert_eq!((file.landmarks, file.light), (68, 12));
    assert_eq!(file.metadata, "{\"format\":\"gpmm-init\"}");
    // Any image, any aspect: a detection with finite landmarks (random weights: no meaning).
    for (w, h) in [(40u32, 30u32), (17, 50), (1, 1)] {
        let img = RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7) as u8, (y * 5) as u8, 100]));
        let det = detector.detect(&img, 0.0, Reading { refine: 2, mirror: true }).unwrap().expect("min score 0 always finds");
        assert_eq!(det.landmarks.len(), 68);
        assert!(det.landmarks.iter().flatten().chain(&det.angles).all(|v| v.is_finite()));
        assert!((0.0..=1.0).contains(&det.face.score));
    }
    // A finder score threshold above 1 finds nothing.
    let img = RgbImage::new(20, 20);
    assert!(detector.detect(&img, 1.5, Reading::passes(0)).unwrap().is_none());
    // The same bytes always give the same detection.
    let a = Detector::from_bytes(&bytes).unwrap().detect(&img, 0.0, Reading::DEFAULT).unwrap();
    let b = Detector::from_bytes(&bytes).unwrap().detect(&img, 0.0, Reading::DEFAULT).unwrap();
    assert_eq!(a, b);
}

#[test]
fn the_mirrored_reading_reads_a_mirror_image_as_the_mirror_of_the_face() {
    let bytes = init_bytes(7);
    let detector = Detector::from_bytes(&bytes).unwrap();
    let file = detector.file().unwrap();
    let (w, h) = (48u32, 40u32);
    // A smooth, asymmetric image and its mirror image.
    let img = RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 5) as u8, (y * 6 + x) as u8, (200 - 3 * x) as u8]));
    let flipped = image::imageops::flip_horizontal(&img);
    let face = FaceBox { cx: 20.0, cy: 21.0, size: 18.0, score: 1.0, looks: 1 };
    let mirror_box = FaceBox { cx: w as f32 - face.cx, ..face };
    let mut scratch = Box::new(NetScratch::<{ 64 * 1024 }>::new());
    let mut read = |rgb: &RgbImage, face: FaceBox, reading: Reading| {
        read_landmarks(&file, rgb.as_raw(), w as usize, h as usize, face, reading, &mut scratch).unwrap()
    };
    let both = Reading::passes(0);
    let (single, single_flipped) = (read(&img, face, both), read(&flipped, mirror_box, both));
    let mirror = Reading { refine: 0, mirror: true };
    let (a, b) = (read(&img, face, mirror), read(&flipped, mirror_box, mirror));
    // Averaged with its mirrored reading, a face reads as exactly the mirror of its mirror image.
    let worst = (0..68)
        .map(|k| {
            let (p, q) = (a.landmarks[k], b.landmarks[ibug68_partner(k)]);
            (p[0] - (w as f32 - q[0])).abs().max((p[1] - q[1]).abs())
        })
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "mirror readings differ by {worst} px");
    assert!((a.angles[0] + b.angles[0]).abs() < 1e-4 && (a.angles[1] - b.angles[1]).abs() < 1e-4);
    // A single reading (random weights) has no such symmetry, so the test would see a missing flip.
    let single_worst = (0..68)
        .map(|k| (single.landmarks[k][0] - (w as f32 - single_flipped.landmarks[ibug68_partner(k)][0])).abs())
        .fold(0.0f32, f32::max);
    assert!(single_worst > 0.05, "single readings already symmetric ({single_worst} px)");
}

#[test]
fn corrupted_or_truncated_init_files_are_refused() {
    let bytes = init_bytes(6);
    for at in [20, 40, bytes.len() / 2, bytes.len() - 8] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        assert!(matches!(Detector::from_bytes(&bad), Err(NetError::Format(FormatError::Crc { .. }))), "flip at {at}");
    }
    for len in [0, 3, 12, 31, bytes.len() - 1] {
        assert!(Detector::from_bytes(&bytes[..len]).is_err(), "truncated to {len}");
    }
    let mut other = bytes.clone();
    other[0] = b'X';
    assert!(matches!(Detector::from_bytes(&other), Err(NetError::Format(FormatError::BadMagic { .. }))));
    let mut version = bytes.clone();
    version[4] = 2;
    assert!(matches!(Detector::from_bytes(&version), Err(NetError::Format(FormatError::BadVersion { .. }))));
    // A missing file names the path.
    let err = Detector::load(std::path::Path::new("/nonexistent/x.init")).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/x.init"), "{err}");
}

#[test]
fn a_face_check_written_into_an_init_file_is_read_back_and_filters_a_scan() {
    use gpmm_host::detect::check::FaceCheck;
    use gpmm_host::detect::check_fit::with_metadata;
    let bytes = init_bytes(5);
    let mut plain = Detector::from_bytes(&bytes).unwrap();
    assert!(plain.check().is_none());
    let img = RgbImage::from_fn(48, 40, |x, y| image::Rgb([(x * 5) as u8, (y * 6) as u8, 90]));
    let measured = plain.scan_measured(&img, 0.0, f32::INFINITY, Reading::DEFAULT).unwrap();
    assert!(!measured.is_empty() && measured.iter().all(|(_, a)| a.is_some_and(|a| a.is_finite())));
    // A check no box passes, written into the metadata beside what was there.
    let none = FaceCheck { weights: [0.0; 4], bias: -10.0, threshold: 0.5, faces: 10, others: 10 };
    let metadata = none.into_metadata(plain.file().unwrap().metadata).unwrap();
    let checked = with_metadata(&bytes, &metadata).unwrap();
    let mut detector = Detector::from_bytes(&checked).unwrap();
    assert_eq!(detector.check(), Some(&none));
    let file = detector.file().unwrap();
    assert!(file.metadata.contains("\"format\":\"gpmm-init\""));
    let was = plain.file().unwrap();
    assert_eq!((file.finder.bytes(), file.initializer.bytes()), (was.finder.bytes(), was.initializer.bytes()));
    assert!(detector.scan_all(&img, 0.0, f32::INFINITY, Reading::DEFAULT).unwrap().is_empty());
    // A command that fits one face still gets every face when the check leaves none.
    assert_eq!(detector.scan_for_fit(&img, 0.0, f32::INFINITY, Reading::DEFAULT).unwrap().len(), measured.len());
    // The same boxes as before without it, and with a check every box passes.
    detector.set_check(None);
    assert_eq!(detector.scan_all(&img, 0.0, f32::INFINITY, Reading::DEFAULT).unwrap().len(), measured.len());
    detector.set_check(Some(FaceCheck { bias: 10.0, ..none }));
    assert_eq!(detector.scan_all(&img, 0.0, f32::INFINITY, Reading::DEFAULT).unwrap().len(), measured.len());
    // A check the metadata cannot hold as one is refused by name when the file is loaded.
    let broken = with_metadata(&bytes, r#"{"face_check": {"weights": [1, 2]}}"#).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.init");
    std::fs::write(&path, broken).unwrap();
    let err = Detector::load(&path).unwrap_err().to_string();
    assert!(err.contains("broken.init") && err.contains("face_check"), "{err}");
    // An initializer without the 68 points has no mirrored reading to check: said before any scan.
    let five = Detector::from_bytes(&init_bytes_with(5, 5)).unwrap();
    let fitted = gpmm_host::detect::check_fit::fit_check(&five, &[dir.path()], 32.0, Reading::DEFAULT, 0.98, &|_, _| {});
    let err = fitted.unwrap_err().to_string();
    assert!(err.contains("68 iBUG points") && err.contains("reads 5"), "{err}");
}
