//! The firmware smoke test: the cropped template (simplified to 1,000 vertices) rendered at 128×128 by the core on the host and by
//! the Cortex-M4F firmware under QEMU must give the same frame checksum.
//!
//! The host writes the template as a device mesh (`gpmm_host::device::mesh`: mesh + pose, camera
//! and light), renders it with gpmm-core into a `FrameChecksum`, and runs `firmware-sim/run.sh
//! --data FILE`, which flashes the file into the firmware's data partition. The firmware is
//! built once per test run (the first run builds it; the others run the built ELF).
//!
//! Needs QEMU and a thumbv7em toolchain: `firmware-sim/install-deps.sh` installs them (tests/run.sh
//! does that first). Missing tools make these tests fail, never skip. The template comes from
//! `$GPMM_DATA` (default `../shared/data` next to the workspace).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use gpmm_core::checksum::FrameChecksum;
use gpmm_host::device::mesh::{smoke_test_scene, DeviceMesh};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use serde_json::Value;

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim")
}

const INSTALL_HINT: &str = "run `sudo firmware-sim/install-deps.sh` (installs qemu-system-arm, binutils-arm-none-eabi and a \
                            thumbv7em-none-eabihf Rust toolchain; tests/run.sh does this first)";

/// Fails (never skips) when the tools the firmware needs are missing.
fn require_tools() {
    for tool in ["qemu-system-arm", "arm-none-eabi-size", "arm-none-eabi-nm"] {
        let found = Command::new(tool).arg("--version").output().map(|o| o.status.success()).unwrap_or(false);
        assert!(found, "{tool} is not installed: {INSTALL_HINT}");
    }
}

/// What one firmware run printed.
struct Run {
    ok: bool,
    stdout: String,
    stderr: String,
    figures: Option<Value>,
}

fn run_script(args: &[&str]) -> Run {
    let out = Command::new("bash")
        .arg(firmware_dir().join("run.sh"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot start firmware-sim/run.sh: {e}; {INSTALL_HINT}"));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let figures = stdout
        .lines()
        .find_map(|l| l.strip_prefix("GPMM_FIGURES "))
        .map(|j| serde_json::from_str(j).unwrap_or_else(|e| panic!("GPMM_FIGURES is not JSON ({e}): {j}")));
    Run { ok: out.status.success(), stdout, stderr, figures }
}

/// The firmware ELF, built once per test binary run (by the first run.sh call, without data).
fn firmware_elf() -> &'static Path {
    static ELF: OnceLock<PathBuf> = OnceLock::new();
    ELF.get_or_init(|| {
        require_tools();
        let run = run_script(&[]);
        assert!(
            run.ok,
            "building or running the firmware failed; if a tool is missing, {INSTALL_HINT}\n--- stdout\n{}\n--- stderr\n{}",
            run.stdout, run.stderr
        );
        assert!(run.stdout.contains("no data partition"), "without data the firmware says so:\n{}", run.stdout);
        let elf = firmware_dir().join("target/thumbv7em-none-eabihf/release/gpmm-firmware-sim");
        assert!(elf.is_file(), "no firmware ELF at {}", elf.display());
        elf
    })
}

/// Runs the built firmware with `data` in its data partition.
fn run_firmware(data: &Path) -> Run {
    let elf = firmware_elf();
    run_script(&["--elf", elf.to_str().expect("UTF-8 path"), "--data", data.to_str().expect("UTF-8 path")])
}

fn template_device_mesh(data: &Path) -> DeviceMesh {
    let dir = data.join("template/lee-perry-smith");
    // Simplified to 1,000 vertices: the m4f firmware's projected-vertex buffer holds 1,024
    // (`gpmm_core::profile::M4F.projected_pool`; its RAM is shared with the fit's buffers and stack).
    let opts = TemplateOptions { vertices: Some(1000), ..TemplateOptions::default() };
    let t = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &opts).expect("template loads");
    DeviceMesh::from_mesh(&t.mesh, smoke_test_scene(128)).expect("device mesh")
}

fn num(f: &Value, key: &str) -> u64 {
    f.get(key).and_then(Value::as_u64).unwrap_or_else(|| panic!("GPMM_FIGURES has no integer {key}: {f}"))
}

#[test]
fn firmware_renders_the_template_with_the_host_checksum() {
    let Some(data) = data_dir() else { return };
    let mesh = template_device_mesh(&data);
    // Kept after the test (target/tmp/template-128.gpdm), so `firmware-sim/run.sh --data FILE` can rerun it.
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join("template-128.gpdm");
    mesh.write(&file).expect("write device mesh");
    let bytes = std::fs::metadata(&file).expect("file").len();
    println!("device mesh {}: {} vertices, {} triangles, {bytes} bytes", file.display(), mesh.positions.len(), mesh.triangles.len());
    assert!(bytes <= 512 * 1024, "the device mesh must fit the m4f data partition");
    // The host renders what the firmware will read: the file's content, parsed back.
    let read_back = DeviceMesh::read(&file).expect("read back");
    assert_eq!(read_back, mesh);
    let (host, stats): (FrameChecksum, _) = read_back.render_checksum().expect("host render");
    println!("host: checksum {} covered {} colour sums {:?} ({stats:?})", host.value(), host.covered, host.color_sum);
    assert!(host.covered > 2000, "the face covers a good part of the 128x128 frame: {host:?}");

    let run = run_firmware(&file);
    assert!(run.ok, "the firmware failed on the template\n--- stdout\n{}\n--- stderr\n{}", run.stdout, run.stderr);
    let f = run.figures.expect("GPMM_FIGURES line");
    println!("{}", run.stdout);

    // Same frame, same checksum. (Colours are quantized to u8 before hashing; host and firmware
    // evaluate the same IEEE f32 operations without FMA contraction, so no tolerance is needed.
    // If this ever fails, compare covered_pixels and the colour sums first.)
    assert_eq!(num(&f, "mesh_vertices"), mesh.positions.len() as u64);
    assert_eq!(num(&f, "mesh_triangles"), mesh.triangles.len() as u64);
    assert_eq!(num(&f, "drawn_triangles"), u64::from(stats.drawn));
    assert_eq!(num(&f, "covered_pixels"), u64::from(host.covered), "covered pixels differ");
    let fw_sums = [num(&f, "color_sum_r"), num(&f, "color_sum_g"), num(&f, "color_sum_b")];
    assert_eq!(fw_sums, host.color_sum, "quantized colour sums differ");
    assert_eq!(num(&f, "frame_checksum"), u64::from(host.value()), "frame checksum differs");

    // Figures present and sane.
    let (vs, rs, total) = (num(&f, "vertex_instructions"), num(&f, "raster_instructions"), num(&f, "frame_instructions"));
    assert_eq!(vs + rs, total);
    assert!(vs > 10_000 && rs > 10_000, "implausibly few instructions: vertex {vs}, raster {rs}");
    assert!(total < 200_000_000, "a 128x128 frame should take far fewer than 200 M instructions: {total}");
    let stack = num(&f, "stack_peak_bytes");
    let ram_static = num(&f, "ram_static_bytes");
    let ram_budget = num(&f, "ram_budget_bytes");
    assert!(stack > 0 && stack <= 64 * 1024, "stack peak {stack} bytes");
    assert_eq!(ram_budget, 192 * 1024, "the m4f profile");
    assert!(ram_static + stack <= ram_budget, "RAM: static {ram_static} + stack {stack} > {ram_budget}");
    let flash = num(&f, "flash_bytes");
    assert!(flash <= num(&f, "flash_code_budget_bytes"));
    println!(
        "firmware 128x128 frame: vertex stage {vs} + raster {rs} = {total} instructions; stack peak {stack} B; static RAM {ram_static} B; \
         renderer RAM {} B; flash {flash} B",
        num(&f, "renderer_ram_bytes")
    );
}

#[test]
fn firmware_rejects_a_corrupt_device_mesh() {
    let Some(data) = data_dir() else { return };
    let bytes = template_device_mesh(&data).to_bytes().expect("bytes");
    let dir = tempfile::tempdir().expect("temp dir");
    type Corrupt = fn(&mut Vec<u8>);
    let cases: [(&str, Corrupt, &str); 3] = [
        ("flipped byte", |b| b[1000] ^= 0x40, "CRC-32 mismatch"),
        ("truncated", |b| b.truncate(b.len() / 2), "CRC-32 mismatch"),
        ("huge vertex count", |b| b[8..12].copy_from_slice(&u32::MAX.to_le_bytes()), "vertex count is out of range"),
    ];
    for (name, corrupt, error) in cases {
        let mut b = bytes.clone();
        corrupt(&mut b);
        let file = dir.path().join("bad.gpdm");
        std::fs::write(&file, &b).expect("write");
        let run = run_firmware(&file);
        assert!(!run.ok, "{name}: the firmware accepted a corrupt mesh:\n{}", run.stdout);
        assert!(run.stdout.contains("not a valid device mesh"), "{name}: no error logged:\n{}\n{}", run.stdout, run.stderr);
        assert!(run.stdout.contains(error), "{name}: expected {error}:\n{}", run.stdout);
        assert!(!run.stdout.contains("panic") && !run.stdout.contains("hard fault"), "{name}:\n{}", run.stdout);
    }
}
