//! The landmark-free start on the device: an init file (`GPMI`, `docs/init-format.md`) at the start
//! of the data partition and a camera frame after it (`gpmm_core::format::detection`, `GPDF`), the
//! core's finder and initializer on the whole frame (`find_face`, then `read_landmarks`: the two
//! halves of `face::detect`, which `gpmm detect` runs on the host), and the result as a detection
//! record (`GPDR`, logged as `GPDR <hex>` lines) plus the figures as `key=value`.
//!
//! RAM: the networks' two activation buffers (`NetScratch`, `PROFILE.net_scratch` bytes each) live
//! on this function's stack, not in the statics: a detection and a fit never run in one boot, so
//! the fit's static RAM and stack margin stay as they were.

use crate::board::{fail, PROFILE};
use crate::clock::{self, instructions_now};
use crate::{hexlog, stack};
use gpmm_core::format::detection::{self, DetectCounts, Frame, MAX_RECORD_LANDMARKS, MAX_RECORD_LIGHT};
use gpmm_core::format::init_file::InitFile;
use gpmm_core::net::face::{bounded_reading, find_face, read_landmarks, record_parts, Detection};
use gpmm_core::net::face_box::{is_face, FaceBox};
use gpmm_core::net::{NetError, NetScratch};

/// Bytes of each activation buffer.
pub(crate) const SCRATCH: usize = PROFILE.net_scratch;

/// The detection frame at byte `at` of `part` (after the init file); logs and fails if it is
/// missing or invalid.
pub(crate) fn frame_at(part: &'static [u8], at: usize) -> Frame<'static> {
    match part.get(at..).map(detection::parse_frame) {
        Some(Ok(f)) => f,
        Some(Err(e)) => {
            defmt::error!("data partition: no valid detection frame after the init file: {}", defmt::Display2Format(&e));
            fail();
        }
        None => {
            defmt::error!("data partition: the init file fills it, no room for a detection frame");
            fail();
        }
    }
}

/// The init file at the start of `bytes` and its length; logs and fails if it is not a valid one
/// (`after`: what it follows in the data partition, for the message, e.g. " after the fit job").
pub(crate) fn init_file_at(bytes: &'static [u8], after: &str) -> (InitFile<'static>, usize) {
    match InitFile::parse(bytes) {
        Ok(init) => (init, InitFile::byte_len(bytes).unwrap_or(bytes.len())),
        Err(e) => {
            defmt::error!("data partition: not a valid init file{=str}: {}", after, defmt::Display2Format(&e));
            fail();
        }
    }
}

/// Logs and fails if an init file's networks need more than [`SCRATCH`] bytes per activation
/// buffer (`needed`, `InitFile::scratch_bytes`).
pub(crate) fn check_scratch(needed: usize) {
    if needed > SCRATCH {
        defmt::error!(
            "the init file's networks need {=u32} bytes per activation buffer; this firmware has {=u32}",
            needed as u32,
            SCRATCH as u32
        );
        fail();
    }
}

/// Runs the detection on the init file and the frame in `part`; logs everything, fails on bad data.
pub fn run(part: &'static [u8]) {
    let t_start = instructions_now();
    let (init, init_len) = init_file_at(part, "");
    let frame = frame_at(part, detection::frame_offset(init_len));
    let t_parsed = instructions_now();
    let needed = init.scratch_bytes();
    defmt::info!(
        "init_bytes={=u32} frame_width={=u32} frame_height={=u32} net_scratch_bytes={=u32} net_scratch_needed_bytes={=u32} finder_macs={=u32} initializer_macs={=u32}",
        init_len as u32,
        frame.width,
        frame.height,
        SCRATCH as u32,
        needed as u32,
        init.finder.macs() as u32,
        init.initializer.macs() as u32
    );
    check_scratch(needed);
    let mut counts = DetectCounts {
        instructions_parse: t_parsed - t_start,
        scratch_bytes: SCRATCH as u32,
        scratch_needed_bytes: needed as u32,
        init_bytes: init_len as u32,
        partition_bytes: part.len() as u32,
        finder_macs: init.finder.macs() as u32,
        initializer_macs: init.initializer.macs() as u32,
        frame_width: frame.width,
        frame_height: frame.height,
        ..DetectCounts::default()
    };
    let (face, det) = networks(&init, &frame, &mut counts);
    counts.instructions_total = instructions_now() - t_start;
    log_record(&face, det.as_ref(), &mut counts);
}

/// The finder, then (if it found a face) the initializer, each timed; the scratch is this frame's.
#[inline(never)]
pub(crate) fn networks(init: &InitFile<'_>, frame: &Frame<'_>, counts: &mut DetectCounts) -> (FaceBox, Option<Detection>) {
    let mut scratch = NetScratch::<SCRATCH>::new();
    let (w, h) = (frame.width as usize, frame.height as usize);
    let (face, finder) = clock::measure(|| find_face(init, frame.rgb, w, h, &mut scratch));
    counts.instructions_finder = finder;
    let face = face.unwrap_or_else(|e| refused("finder", e));
    if !is_face(&face, frame.min_score) {
        return (face, None);
    }
    // Within the instruction bound: a second look of the finder takes a refinement pass's place.
    let reading = bounded_reading(&face, frame.refine as usize, init.landmarks);
    let (det, initializer) = clock::measure(|| read_landmarks(init, frame.rgb, w, h, face, reading, &mut scratch));
    counts.instructions_initializer = initializer;
    counts.initializer_runs = reading.runs(init.landmarks) as u32;
    (face, Some(det.unwrap_or_else(|e| refused("initializer", e))))
}

/// Encodes the record and logs it as hex lines, then the figures and a human summary.
#[inline(never)]
pub(crate) fn log_record(face: &FaceBox, det: Option<&Detection>, counts: &mut DetectCounts) {
    let (figures, landmarks, light) = record_parts(face, det);
    // Everything the detection used is behind us: the high-water mark is the detection's.
    counts.stack_peak_bytes = stack::peak_bytes();
    let mut record = [0u8; detection::record_len(MAX_RECORD_LANDMARKS, MAX_RECORD_LIGHT)];
    let len = match detection::write_record(&mut record, &figures, counts, landmarks, light) {
        Ok(len) => len,
        Err(e) => {
            defmt::error!("detection record: {}", e);
            fail();
        }
    };
    hexlog::lines("GPDR", record.get(..len).unwrap_or(&[]));
    defmt::info!(
        "finder_instructions={=u64} initializer_instructions={=u64} initializer_runs={=u32} detect_instructions={=u64}",
        counts.instructions_finder,
        counts.instructions_initializer,
        counts.initializer_runs,
        counts.instructions_total
    );
    match det {
        Some(d) => defmt::info!(
            "detect: face at ({=f32}, {=f32}) px, size {=f32} px, score {=f32}; yaw {=f32} rad; {=u32} landmarks",
            d.face.cx,
            d.face.cy,
            d.face.size,
            d.face.score,
            d.angles[0],
            d.landmarks.len() as u32
        ),
        None => defmt::info!("detect: no face (finder score {=f32} below the frame's minimum)", face.score),
    }
}

fn refused(stage: &str, e: NetError) -> ! {
    defmt::error!("{=str}: the core refused the input: {}", stage, defmt::Display2Format(&e));
    fail()
}
