//! The `gpmm` program: command-line arguments, progress display and the demo, over the
//! gpmm-host library.

mod build;
mod calibrate;
mod check_init;
mod demo;
mod detect;
mod device;
mod device_frame;
mod eval;
mod eval_reconstruction;
mod eval_setup;
mod fit;
mod fit_faces;
mod h5;
mod learn;
mod progress;
mod register;
mod render;
mod synth;
mod train_init;
mod training_photos;

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// gpmm: Gaussian-process morphable models from one scan, fitted on microcontrollers.
#[derive(Debug, Parser)]
#[command(name = "gpmm", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Build a Gaussian-process morphable model (shape + albedo) from one coloured scan.
    ///
    /// The scan is normalized to millimetres (outer eye corners 90 mm apart unless --scale
    /// is given), centred on the landmarks' mirror plane, oriented (x right, y up, z toward
    /// the camera), cropped to the face and optionally simplified. The kernel is approximated
    /// by the Nyström method and kept as a low-rank model.
    Build(Box<build::BuildArgs>),
    /// Print a model file's key figures as JSON.
    Info(build::InfoArgs),
    /// Draw random instances (all coefficients ~ N(0,1)): coloured PLY meshes and/or a rendered grid.
    Sample(render::SampleArgs),
    /// Render the mean (or given coefficients) through the core's tile rasterizer into a PNG.
    ///
    /// Colours are linear RGB written as-is (no gamma). The camera's field of view spans the
    /// shorter image side; the model is placed so that its mean shape fits with a margin.
    Render(render::RenderArgs),
    /// Render a figure (see `gpmm figure --help`).
    Figure(render::FigureArgs),
    /// Render synthetic faces with known truth: ICT identities, transferred albedo, random light and pose.
    Synth(synth::SynthArgs),
    /// The main job end to end: build a model from the template scan, render, sample, draw figures, fit a photo.
    Demo(demo::DemoArgs),
    /// Fit a model to a photo: pose, shape, colour and light by MCMC, from 68 landmarks (a .pts
    /// file, or read by the start gpmm ships: no file needed; --faces all fits every face).
    ///
    /// The photo is cropped to a square around the landmarks (side 1.8x the landmarks' larger
    /// extent, lifted by 0.1x so the forehead fits; pixels past the image's edge left out of the likelihood) and
    /// resampled to --size. Then a landmark-only chain on the pose (--landmark-steps, the jaw
    /// contour down-weighted; no rendering), a closed-form SH light, a Gauss-Newton solve of the
    /// leading shape components against the landmarks and the image, and an image chain on pose,
    /// colour and light (--image-steps, each renders the model).
    /// Writes OUTDIR/fit.json (every field: docs/fit-json.md; the chain's best sample, and the mean
    /// and spread of its second half; 90 % intervals of the angles and each vertex's spread along
    /// its normal, calibrated: docs/intervals.md), overlay.png (input | fit | blend; green dots:
    /// target landmarks, red crosses: fitted), spread.png (the face coloured by that spread) and
    /// fit.ply (the fitted shape and albedo, model space, mm; the spread as the vertices' quality).
    /// The same inputs and seed give the same fit.json except `seconds` and `timing`.
    Fit(fit::FitArgs),
    /// Fit every image of a `gpmm synth` directory (in parallel) and print error statistics as JSON.
    BenchFit(fit::BenchFitArgs),
    /// Learn a landmark detector's systematic offsets from images whose true landmarks are known.
    ///
    /// A detector's points are not the model's landmark vertices: its definition of each point
    /// differs, and its errors change with the view (they pull a turned face toward frontal).
    /// Given the detector's .pts and the true .pts of the same images (renders: `gpmm synth`, or
    /// the independent test sets of docs/realistic-testset.md), this fits per point an offset in
    /// the detected face's frame (eye line, inter-ocular distance) as a polynomial in how far the
    /// nose tip sits off the eyes' midpoint, and writes it as JSON. `gpmm fit`, `bench-fit` and
    /// `eval recognition` take it with --landmark-calibration and correct the points before the fit.
    CalibrateLandmarks(calibrate::CalibrateArgs),
    /// Learn an init file's face check from photos with known faces.
    ///
    /// The finder scores some hands, textures and parts of faces as high as faces; their readings
    /// mostly do not look like a face's: the initializer reads them differently in the mirror
    /// image, and their landmarks do not fill the finder's box. This scans every photo of the sets
    /// (down to --smallest-face, boxes scoring 0.5 or more), reads each box, and fits a logistic
    /// regression of "one of the photo's known faces" on the finder's score and those measures. The
    /// threshold keeps --kept-share of the known faces. The check is written into the init file's
    /// metadata; `gpmm detect`, `fit --init` and `eval detect` then leave out photos' faces that
    /// fail it (--no-face-check: keep them). docs/real-photos.md, "The reading's check".
    CheckInit(check_init::CheckInitArgs),
    /// Evaluate models like the paper: recognition across yaw, specificity / generalization / compactness.
    Eval(eval::EvalArgs),
    /// Learn a model from unlabelled images: no landmark files, labels or poses.
    ///
    /// Each iteration starts every image (and its mirror image with --mirror) with the init file's
    /// finder and initializer, fits the current model like `gpmm fit --init`, keeps the fits whose
    /// silhouette overlaps their start's by at least --min-iou (the rest ran off the face), and
    /// makes the next model from the kept fits' shapes and albedos by PCA: DIR/model_N.gpmm, usable
    /// by every command, with the iteration's inputs and counts in its metadata, and
    /// DIR/iteration_N/ with every image's record and pictures of the model and the fits. Images that
    /// cannot be read or show no face are recorded and skipped. Deterministic for a --seed.
    Learn(Box<learn::LearnArgs>),
    /// Register a model to a mesh (3D-to-3D fit): landmark alignment, then closest points with the model's prior.
    ///
    /// Writes OUTDIR/registered.ply (the fitted instance on the model's topology, in the mesh's frame) and
    /// OUTDIR/register.json (coefficients, rigid transform, residual: mean / median / p90 distance from the
    /// model's vertices to the mesh surface, vertices reaching past the mesh's border excluded; colour residual).
    Register(register::RegisterArgs),
    /// Quantize a model for a device profile and write its flash image (a model blob).
    ///
    /// Simplifies the model to the vertex budget (meshoptimizer; the landmark vertices are kept,
    /// in the same order), keeps the leading shape and colour components, and stores each
    /// component as 8- or 16-bit integers with its own scale (symmetric: scale = max|value| /
    /// 127 or / 32767). Means stay f32, triangle indices become u16. Refuses a blob over the
    /// profile's budget (m4f: 400 KiB of its 512 KiB data partition; m7: 800 KiB of 1 MiB),
    /// which leaves room for the test image and landmarks. Prints a summary on stderr and, on
    /// stdout, JSON with the blob size and the quantization error (float model of the kept
    /// vertices and ranks against the blob, over --draws random N(0,1) coefficient vectors)
    /// and the simplification error (source mean surface against the simplified one).
    /// Format: docs/blob-format.md.
    Quantize(device::QuantizeArgs),
    /// Validate a model blob with the device's parser and print its header and metadata as JSON.
    ///
    /// Exits with status 1 and the parser's message if the blob is invalid; the JSON is still
    /// printed when the header is readable (with "crc_ok": false for a corrupted blob).
    Inspect(device::InspectArgs),
    /// Fit a model blob to a photo on the simulated device: Cortex-M firmware under QEMU.
    ///
    /// Crops the photo around its landmarks to the profile's image size (m4f: 128x128, m7:
    /// 256x256), writes the data partition (the blob, then the image, landmarks, seed and step
    /// counts), builds the firmware for the profile, runs the core's standard fit under QEMU
    /// (instructions counted with -icount) and prints JSON: flash and RAM use against the
    /// profile's budget, instructions per stage and per image step, the fitted pose,
    /// log-likelihood and 68 landmarks. --compare-host runs the same fit on the host core too.
    ///
    /// With --init INIT instead of --landmarks, everything happens on the device: the partition
    /// holds the blob, the fit job (working side, seed, settings), the init file and the whole
    /// camera frame (the photo scaled to cover --width x --height, default 160x120); the firmware
    /// finds the face, reads its landmarks, cuts the working image around them (72x72 on m4f,
    /// whose RAM holds no larger one next to the fit; 128x128 on m7) and fits it with those
    /// landmarks as the landmark term (σ --init-landmark-sigma). The JSON reports instructions per
    /// stage (detection, crop, fit) and RAM; --compare-host checks detection and fit bit for bit
    /// against the same core path on the host. A frame without a face reports "no face found".
    /// On m4f the blob, init file and frame share a 512 KiB partition: use an 8-bit blob
    /// (`gpmm quantize --bits 8`) with the default init file.
    /// Needs a gpmm source checkout (firmware-sim/) and installs QEMU and the toolchain if missing.
    DeviceFit(device::DeviceFitArgs),
    /// Find the face and read its landmarks on the simulated device: Cortex-M firmware under QEMU.
    ///
    /// Scales the photo to cover the device camera's frame (default 160x120) and cuts it to it,
    /// writes the data partition (the init file, then the frame), builds the firmware for the
    /// profile, runs the core's finder and initializer under QEMU and prints JSON: the box,
    /// score, pose, 68 landmarks (frame and photo px) and light, the instructions of the finder
    /// and of the initializer, the stack peak and static RAM. --compare-host runs the same core
    /// code on the host on the same frame and reports whether the outputs are bit-identical.
    DeviceDetect(device::DeviceDetectArgs),
    /// Import a statismo / scalismo-faces .h5 model (e.g. the Basel Face Model) as a gpmm model (dense layout).
    ///
    /// Reads /shape and /color (model/mean, pcaBasis, pcaVariance, version, representer/cells;
    /// version 0.8 bases are read as scaled). Units: millimetres, detected from the mean shape's
    /// width (BFM 2017/2019: mm; BFM 2009: um) unless --scale is given; colours in 0..255 are
    /// divided by 255. Landmarks: --landmarks, else the file's when they are numbered vertex
    /// landmarks (`ibug68.0` ...); otherwise the model has none and cannot be fitted to photos
    /// (it says so). Prints a JSON report.
    ImportH5(h5::ImportArgs),
    /// Export a gpmm model as a statismo .h5 file (version 0.9: dense, unscaled orthonormal bases).
    ExportH5(h5::ExportArgs),
    /// Train the face finder and initializer of a landmark-free fit on renders of a model.
    ///
    /// Renders random faces of the model (shape, colour, yaw ±70°, pitch and roll ±30°, SH light,
    /// cameras of 20-70° field of view, partial framing) on the template's head dressed in hair and clothes, most with open
    /// eyes painted over the scan's shut ones, over procedural backgrounds with camera effects
    /// (blur, noise, gamma, white balance, JPEG); the labels are the model's own landmark vertices
    /// (the lid points on the painted lids), pose and light. Trains two small networks with candle
    /// on the CPU (the initializer also sees every crop once in a mirror), quantizes them to int8
    /// (per-channel weight scales) and writes an init file (docs/init-format.md). Prints
    /// the quantized networks' accuracy on held-out renders as JSON. Deterministic for a seed.
    TrainInit(train_init::TrainInitArgs),
    /// Find every face in an image and read its 68 landmarks, pose and light (with the start gpmm ships, or --init).
    ///
    /// The finder sees the whole image letterboxed to 96x96 (and, if the face is small in it, a
    /// second time a square three face sizes wide around it); the initializer a 64x64 crop around
    /// the found face, then again around its own landmarks (--refine), and that last crop once
    /// more flipped left-right, the two readings averaged (--single-read skips it). Prints JSON
    /// (box, score, angles, landmarks); -o writes a .pts that `gpmm fit --landmarks` reads.
    Detect(detect::DetectArgs),
}

/// Runs the program and maps errors to a message and exit code 1.
fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Runs one parsed command.
fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Build(a) => build::build(*a),
        Command::Info(a) => build::info(a),
        Command::Sample(a) => render::sample(a),
        Command::Synth(a) => synth::synth(a),
        Command::Demo(a) => demo::demo(a),
        Command::Fit(a) => fit::fit(a),
        Command::BenchFit(a) => fit::bench_fit(a),
        Command::CalibrateLandmarks(a) => calibrate::calibrate(a),
        Command::CheckInit(a) => check_init::check_init(a),
        Command::Eval(a) => eval::eval(a),
        Command::Learn(a) => learn::learn(*a),
        Command::Register(a) => register::register_mesh(a),
        Command::Quantize(a) => device::quantize(a),
        Command::Inspect(a) => device::inspect(a),
        Command::DeviceFit(a) if a.landmarks.is_none() => device_frame::device_fit_init(a),
        Command::DeviceFit(a) => device::device_fit(a),
        Command::DeviceDetect(a) => device::device_detect(a),
        Command::ImportH5(a) => h5::import_h5(a),
        Command::ExportH5(a) => h5::export_h5(a),
        Command::TrainInit(a) => train_init::train_init(a),
        Command::Detect(a) => detect::detect(a),
        Command::Render(a) => render::render(a),
        Command::Figure(a) => render::figure(a),
    }
}
