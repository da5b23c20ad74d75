//! The help of the fitting commands states the defaults the code runs: every number is read from
//! `FitSettings::default()`, the host's options and the device profiles, and looked up in
//! `gpmm fit --help`, `gpmm bench-fit --help` and `gpmm device-fit --help`.

mod common;
use common::{gpmm, ok};

use gpmm_core::fit::{FitSettings, INIT_LANDMARK_SIGMA};
use gpmm_core::profile::{M4F, M7};
use gpmm_host::fit::{FitOptions, KC, KS};

/// The help text of `command`, its whitespace collapsed (wrapping may break a line anywhere).
fn help(command: &str) -> String {
    let text = ok(&gpmm(&[command, "--help"]));
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Asserts that `text` states each of `needles`.
fn states(command: &str, text: &str, needles: &[String]) {
    for n in needles {
        assert!(text.contains(n.as_str()), "`gpmm {command} --help` does not state `{n}`:\n{text}");
    }
}

/// The help's way of saying how the landmark chain splits its steps under `settings`.
fn pose_share(settings: &FitSettings) -> String {
    let share = settings.landmarks.pose_share;
    if share >= 1.0 {
        "all on the pose".into()
    } else {
        format!("{} % on the pose, then the shape", (share * 100.0).round())
    }
}

/// What the help of `gpmm fit` and `gpmm bench-fit` must state.
fn fit_defaults() -> Vec<String> {
    let (d, f) = (FitOptions::DEFAULT, FitSettings::default());
    assert_eq!(d.fit, f, "the host's default options carry the core's default settings");
    vec![
        format!("--size <SIZE> Working image side (pixels): the crop is resampled to SIZE x SIZE [default: {}]", d.size),
        format!("--landmark-steps <N> Landmark-chain steps, {}", pose_share(&f)),
        format!("[default: {}] --image-steps", f.landmarks.steps),
        format!(
            "--image-steps <N> Image-chain steps, one render each (default: {}; in `gpmm learn` {}, its chain fitting the shape as well)",
            f.image.steps,
            gpmm_host::learn::WAKE_IMAGE_STEPS
        ),
        format!("--seed <SEED> Seed of the chains [default: {}]", d.seed),
        format!("at most the model's rank and {KS}) [default: {}]", f.ranks.shape),
        format!("at most the model's rank and {KC}) [default: {}]", f.ranks.color),
        format!("Landmark standard deviation as a fraction of the working image side [default: {}]", f.landmarks.sigma),
        format!("the {} jaw-contour points", f.landmarks.contour_landmarks),
        format!("(1 treats them like the others) [default: {}]", f.landmarks.contour_sigma_factor),
    ]
}

#[test]
fn fit_help_states_the_defaults() {
    let text = help("fit");
    let mut needles = fit_defaults();
    needles.push("--init-landmark-sigma <FRACTION>".into());
    needles.push(format!("[default: {INIT_LANDMARK_SIGMA}]"));
    states("fit", &text, &needles);
    assert!(!text.contains(" % on the pose"), "the default fit spends all landmark steps on the pose:\n{text}");
}

#[test]
fn bench_fit_help_states_the_defaults() {
    states("bench-fit", &help("bench-fit"), &fit_defaults());
}

#[test]
fn learn_help_states_its_own_image_chain() {
    let image_steps: Vec<String> = fit_defaults().into_iter().filter(|n| n.starts_with("--image-steps")).collect();
    assert_eq!(image_steps.len(), 1);
    states("learn", &help("learn"), &image_steps);
}

#[test]
fn device_fit_help_states_the_defaults() {
    let text = help("device-fit");
    // A device's default fit; without landmarks its start has no shape solve, and its landmark
    // chain fits the shape too.
    let device = FitSettings::DEVICE;
    let frame = FitSettings::DEVICE_FRAME;
    assert!(frame.landmarks.pose_share < 1.0 && frame.start.shape_rounds == 0);
    let side = |n: u32| format!("{n}x{n}");
    states(
        "device-fit",
        &text,
        &[
            format!("--landmark-steps <N> Landmark-chain steps, {}", pose_share(&device)),
            format!("(default: {}). Without --landmarks (no room for the shape solve beside the crop)", device.landmarks.steps),
            format!(
                "Without --landmarks (no room for the shape solve beside the crop): {} (default: {})",
                pose_share(&frame),
                frame.landmarks.steps
            ),
            format!("--image-steps <N> Image-chain steps (default: {}; without --landmarks {})", device.image.steps, frame.image.steps),
            format!("--seed <SEED> Seed of the chains [default: {}]", FitOptions::DEFAULT.seed),
            format!("[default: {INIT_LANDMARK_SIGMA}]"),
            format!("m4f: {}, m7: {}", side(M4F.image_side), side(M7.image_side)),
            format!("({} on m4f,", side(M4F.frame_fit_side)),
            format!("{} on m7)", side(M7.frame_fit_side)),
            format!("the profile's, {} on m4f, {} on m7", M4F.frame_fit_side, M7.frame_fit_side),
            format!("default {}x{}", gpmm_host::device::detect::DEFAULT_FRAME_WIDTH, gpmm_host::device::detect::DEFAULT_FRAME_HEIGHT),
        ],
    );
}
