//! The wire formats of `gpmm_core::format`: what is written is read back exactly, and every
//! corruption (any single flipped bit, any truncation) is refused with an error, never a panic.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

use gpmm_core::fit::{CoveredPixels, FitSettings, ImageSettings, LandmarkSettings, StartSettings};
use gpmm_core::format::detection::{self, DetectCounts, DetectionFigures, Frame};
use gpmm_core::format::device_mesh::{self, DeviceMeshView, DeviceScene};
use gpmm_core::format::fit_record::{self, DeviceCounts, FitFigures};
use gpmm_core::format::{fit_input, FormatError};
use gpmm_core::render::{Camera, Pose, ShLight};

/// Bytes copied into a 4-byte aligned buffer (formats are read in place).
fn aligned(bytes: &[u8]) -> Vec<u32> {
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
    words
}

fn as_bytes(words: &[u32], len: usize) -> &[u8] {
    &bytemuck::cast_slice::<u32, u8>(words)[..len]
}

/// Every single-bit flip and every truncation of `bytes` is refused by `parse`.
fn refuses_corruption(bytes: &[u8], parse: impl Fn(&[u8]) -> bool) {
    for i in 0..bytes.len() {
        for bit in 0..8 {
            let mut c = bytes.to_vec();
            c[i] ^= 1 << bit;
            let w = aligned(&c);
            assert!(!parse(as_bytes(&w, c.len())), "flip of bit {bit} of byte {i} was accepted");
        }
    }
    for cut in 0..bytes.len() {
        let w = aligned(&bytes[..cut]);
        assert!(!parse(as_bytes(&w, cut)), "truncation to {cut} bytes was accepted");
    }
}

fn scene() -> DeviceScene {
    DeviceScene {
        width: 64,
        height: 48,
        pose: Pose { yaw: 0.3, pitch: -0.1, roll: 0.05, translation: [1.0, -2.0, -600.0] },
        camera: Camera::centered(64, 48, 120.0),
        light: ShLight::from_ambient_diffuse([0.6; 3], [0.5, 0.45, 0.4], [-0.4, 0.5, 0.77]),
    }
}

#[test]
fn device_mesh_round_trip_and_corruption() {
    let positions = [[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [0.0, 0.0, 30.0]];
    let albedo = [[0.9, 0.2, 0.1], [0.1, 0.8, 0.2], [0.2, 0.3, 0.9], [1.0, 1.0, 1.0]];
    let triangles = [[0u16, 1, 3], [1, 2, 3], [2, 0, 3]];
    let view = DeviceMeshView { positions: &positions, albedo: &albedo, triangles: &triangles, scene: scene() };
    let mut out = vec![0u8; device_mesh::encoded_len(4, 3)];
    assert_eq!(device_mesh::write(&view, &mut out).unwrap(), out.len());
    assert_eq!(out.len(), 168 + 24 * 4 + 18 + 2 + 4);
    assert_eq!(device_mesh::encoded_len(4249, 8352), 152_260);
    let w = aligned(&out);
    let back = device_mesh::parse(as_bytes(&w, out.len()), 100).unwrap();
    assert_eq!(back.positions, &positions);
    assert_eq!(back.albedo, &albedo);
    assert_eq!(back.triangles, &triangles);
    assert_eq!(back.scene, scene());
    assert_eq!(device_mesh::parse(as_bytes(&w, out.len()), 3).unwrap_err(), FormatError::TooMany("vertices"));
    refuses_corruption(&out, |b| device_mesh::parse(b, 100).is_ok());
    // An index out of range is refused by the writer, and by the reader even with a valid CRC.
    let bad = [[0u16, 1, 4]];
    let v = DeviceMeshView { triangles: &bad, ..view };
    assert_eq!(device_mesh::write(&v, &mut out).unwrap_err(), FormatError::BadField("triangle index"));
}

#[test]
fn fit_input_carries_every_setting() {
    let d = FitSettings::DEFAULT;
    let settings = FitSettings {
        landmarks: LandmarkSettings { steps: 123, ..d.landmarks },
        image: ImageSettings { steps: 45, pixel_sigma: 0.07, ..d.image },
        start: StartSettings { nominal_distance_mm: 800.0, ..StartSettings::DEFAULT },
        ..d
    };
    let (w, h) = (5u32, 3u32);
    let pixels: Vec<[u8; 3]> = (0..w * h).map(|i| [i as u8, 2 * i as u8, 255 - i as u8]).collect();
    let landmarks = [[1.5f32, 2.5], [3.25, 0.5]];
    let mut out = vec![0u8; fit_input::buffer_len(w, h, 2)];
    let covered = CoveredPixels { x0: 1, y0: 0, x1: 5, y1: 2 };
    let n = fit_input::write(&mut out, w, h, 0xdead_beef_1234, covered, &settings, &landmarks, &pixels).unwrap();
    out.truncate(n);
    let words = aligned(&out);
    let back: fit_input::FitInput<'_, FitSettings> = fit_input::parse(as_bytes(&words, n), 128, 68).unwrap();
    assert_eq!((back.width, back.height, back.seed, back.covered), (w, h, 0xdead_beef_1234, covered));
    assert_eq!(back.settings, settings);
    assert_eq!(back.landmarks, &landmarks);
    assert_eq!(back.pixels, &pixels[..]);
    assert_eq!(fit_input::parse::<FitSettings>(as_bytes(&words, n), 4, 68).unwrap_err(), FormatError::BadField("image width"));
    assert_eq!(fit_input::parse::<FitSettings>(as_bytes(&words, n), 128, 1).unwrap_err(), FormatError::BadField("landmark count"));
    refuses_corruption(&out, |b| fit_input::parse::<FitSettings>(b, 128, 68).is_ok());
    // A buffer too small for the image is an error, not a panic.
    let mut small = vec![0u8; 40];
    assert!(fit_input::write(&mut small, w, h, 1, covered, &settings, &landmarks, &pixels).is_err());
    // Covered pixels past the image are refused.
    let past = CoveredPixels { x1: 6, ..covered };
    assert_eq!(
        fit_input::write(&mut out, w, h, 1, past, &settings, &landmarks, &pixels).unwrap_err(),
        FormatError::BadField("covered pixels")
    );
}

#[test]
fn fit_record_round_trip_and_corruption() {
    let figures = FitFigures {
        yaw: 0.1,
        pitch: -0.2,
        focal: 333.0,
        translation: [1.0, 2.0, -500.0],
        covered_pixels: 4321,
        log_likelihood: 45.5,
        angles_sd: [0.01, 0.02, 0.005],
        translation_sd: [0.3, 0.4, 2.5],
        landmark_residual_px: 0.9,
        ..FitFigures::default()
    };
    let counts =
        DeviceCounts { instructions_total: 1_711_172_480, stack_peak_bytes: 37_264, blob_bytes: 300_000, ..DeviceCounts::default() };
    let light = ShLight::frontal();
    let (shape, color, lm) = ([0.5f32, -1.0, 2.0], [0.25f32], [[10.0f32, 20.0], [30.5, 40.5]]);
    let mut out = vec![0u8; fit_record::encoded_len(3, 1, 2)];
    assert_eq!(fit_record::write(&mut out, &figures, &counts, &light, &shape, &color, &lm).unwrap(), out.len());
    let r = fit_record::parse(&out).unwrap();
    assert_eq!(r.figures, figures);
    assert_eq!(r.counts, counts);
    assert_eq!(r.light, light);
    assert_eq!(r.shape.iter().collect::<Vec<_>>(), shape);
    assert_eq!(r.color.iter().collect::<Vec<_>>(), color);
    assert_eq!(r.landmarks.iter().collect::<Vec<_>>(), [10.0, 20.0, 30.5, 40.5]);
    refuses_corruption(&out, |b| fit_record::parse(b).is_ok());
}

#[test]
fn detection_frame_round_trip_and_corruption() {
    let rgb: Vec<u8> = (0..5 * 3 * 3).map(|i| (i * 7 % 256) as u8).collect();
    let frame = Frame { width: 5, height: 3, min_score: 0.25, refine: 2, rgb: &rgb };
    let mut out = vec![0u8; detection::frame_len(5, 3)];
    assert_eq!(detection::write_frame(&mut out, &frame).unwrap(), out.len());
    assert_eq!(out.len(), 24 + 48 + 4, "45 pixel bytes padded to 48");
    let back = detection::parse_frame(&out).unwrap();
    assert_eq!((back.width, back.height, back.min_score, back.refine, back.rgb), (5, 3, 0.25, 2, &rgb[..]));
    // More bytes after the frame (the rest of the partition) are ignored.
    let mut longer = out.clone();
    longer.extend_from_slice(&[0xff; 9]);
    assert!(detection::parse_frame(&longer).is_ok());
    refuses_corruption(&out, |b| detection::parse_frame(b).is_ok());
    // The writer refuses what the reader would.
    let bad = |f: Frame<'_>| detection::write_frame(&mut vec![0u8; 4096], &f).unwrap_err();
    assert_eq!(bad(Frame { min_score: f32::NAN, ..frame }), FormatError::BadField("minimum score"));
    assert_eq!(bad(Frame { refine: 9, ..frame }), FormatError::BadField("refinement passes"));
    assert_eq!(bad(Frame { width: 4, ..frame }), FormatError::BadField("pixel count"));
    assert_eq!(bad(Frame { width: 0, rgb: &[], ..frame }), FormatError::BadField("frame width"));
    assert!(matches!(detection::write_frame(&mut [0u8; 40], &frame), Err(FormatError::BufferTooSmall { .. })));
    assert_eq!(detection::frame_offset(230_768), 230_768);
    assert_eq!(detection::frame_offset(230_770), 230_784);
}

#[test]
fn detection_record_round_trip_and_corruption() {
    let figures = DetectionFigures { found: true, cx: 80.5, cy: 61.25, size: 40.0, score: 0.875, angles: [0.1, -0.2, 0.03] };
    let counts = DetectCounts {
        instructions_finder: 21_000_000,
        instructions_initializer: 43_000_000,
        stack_peak_bytes: 62_000,
        scratch_bytes: 27_648,
        frame_width: 160,
        frame_height: 120,
        ..DetectCounts::default()
    };
    let lm = [[10.0f32, 20.0], [30.5, 40.5], [-1.0, 1e6]];
    let light = [0.5f32, 0.25, -0.125, 1.0];
    let mut out = vec![0u8; detection::record_len(3, 4)];
    assert_eq!(detection::write_record(&mut out, &figures, &counts, &lm, &light).unwrap(), out.len());
    let r = detection::parse_record(&out).unwrap();
    assert_eq!(r.figures, figures);
    assert_eq!(r.counts, counts);
    assert_eq!(r.landmarks.iter().collect::<Vec<_>>(), [10.0, 20.0, 30.5, 40.5, -1.0, 1e6]);
    assert_eq!(r.light.iter().collect::<Vec<_>>(), light);
    refuses_corruption(&out, |b| detection::parse_record(b).is_ok());
    // Nothing found: an empty record.
    let none = DetectionFigures { found: false, ..figures };
    let mut out = vec![0u8; detection::record_len(0, 0)];
    detection::write_record(&mut out, &none, &counts, &[], &[]).unwrap();
    let r = detection::parse_record(&out).unwrap();
    assert!(!r.figures.found && r.landmarks.is_empty() && r.light.is_empty());
    // More than a record holds.
    let many = [[0.0f32; 2]; 69];
    let err = detection::write_record(&mut vec![0u8; 2048], &figures, &counts, &many, &[]).unwrap_err();
    assert_eq!(err, FormatError::TooMany("landmarks"));
}

#[test]
fn frame_fit_job_round_trip_and_corruption() {
    use gpmm_core::format::frame_fit;
    let settings = FitSettings { landmarks: LandmarkSettings { sigma: 0.015, ..FitSettings::DEFAULT.landmarks }, ..FitSettings::DEFAULT };
    let mut out = vec![0u8; frame_fit::buffer_len()];
    let n = frame_fit::write(&mut out, 72, 99, &settings).unwrap();
    out.truncate(n);
    assert_eq!(&out[..4], b"GPFF");
    let job = frame_fit::parse::<FitSettings>(&out, 72).unwrap();
    assert_eq!((job.side, job.seed, job.len), (72, 99, n));
    assert_eq!(job.settings, settings);
    // A side beyond the reader's, a side below 16, a foreign section.
    assert_eq!(frame_fit::parse::<FitSettings>(&out, 64).unwrap_err(), FormatError::BadField("working side"));
    assert!(frame_fit::write(&mut vec![0u8; frame_fit::buffer_len()], 8, 0, &settings).is_err());
    assert!(matches!(frame_fit::parse::<FitSettings>(b"GPFI\x04\0\0\0", 72), Err(FormatError::BadMagic { .. })));
    refuses_corruption(&out, |b| frame_fit::parse::<FitSettings>(b, 72).is_ok());
    assert_eq!(frame_fit::next_section(17), 32);
}

#[test]
fn the_fit_crop_copies_pixels_at_one_to_one_and_maps_the_landmarks() {
    use gpmm_core::net::crop::{crop_for_fit, fit_window, CROP_FACTOR};
    let (w, h) = (160usize, 120usize);
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
    // A 20 px landmark box: the crop is 36 px; sampled into 36 px it is a copy of the frame.
    let lm = [[50.0f32, 40.0], [70.0, 40.0], [60.0, 60.0]];
    let side = (CROP_FACTOR * 20.0) as usize;
    let win = fit_window(&lm, w, h, side).unwrap();
    assert_eq!(win.step, 1.0);
    let (mut px, mut work) = (vec![[0u8; 3]; side * side], vec![[0.0f32; 2]; 3]);
    let got = crop_for_fit(&rgb, w, h, &lm, side, &mut px, &mut work).unwrap();
    assert_eq!(got, win);
    let (x0, y0) = (win.x0 as usize, win.y0 as usize);
    assert_eq!((win.x0.fract(), win.y0.fract()), (0.0, 0.0), "{win:?}");
    for (k, p) in px.iter().enumerate() {
        let i = ((y0 + k / side) * w + x0 + k % side) * 3;
        assert_eq!(p, &[rgb[i], rgb[i + 1], rgb[i + 2]], "pixel {k}");
    }
    assert_eq!(work[0], [50.0 - win.x0, 40.0 - win.y0]);
    // A crop near the border is moved inside the frame; degenerate landmarks give no crop.
    let edge = fit_window(&[[2.0, 2.0], [22.0, 22.0]], w, h, 36).unwrap();
    assert_eq!((edge.x0, edge.y0), (0.0, 0.0));
    assert!(crop_for_fit(&rgb, w, h, &[[5.0, 5.0]; 3], side, &mut px, &mut work).is_err());
}
