//! `gpmm eval recognition`, `gpmm eval specgen` and `gpmm register` end to end on tiny models
//! (`--quick`): the tables and figures are written and consistent, cached fits are reused with the
//! same result, registration recovers a known instance, bad input gives clear errors.

mod common;
use common::{fails, gpmm, ok, read_json};

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

struct Fixture {
    dir: tempfile::TempDir,
    data: PathBuf,
    synth: PathBuf,
    model: PathBuf,
}

/// Three identities at yaw 0 and 30, and a tiny symmetric-full model (600 vertices, rank 10), made once.
fn fixture() -> Option<&'static Fixture> {
    static F: OnceLock<Option<Fixture>> = OnceLock::new();
    F.get_or_init(|| {
        let data = gpmm_host::data::data_dir_for_tests()?;
        let dir = tempfile::tempdir().unwrap();
        let t = data.join("template/lee-perry-smith");
        let synth = dir.path().join("synth");
        let ict = data.join("ict");
        ok(&gpmm(&["synth", "--ict", s(&ict), "--template-dir", s(&t), "--count", "3", "--yaws", "0,30", "--seed", "5", "-o", s(&synth)]));
        let model = dir.path().join("tiny.gpmm");
        let (ply, lm) = (t.join("lee-perry-smith.ply"), t.join("landmarks_ibug68.json"));
        ok(&gpmm(&[
            "build",
            "--template",
            s(&ply),
            "--landmarks",
            s(&lm),
            "--vertices",
            "600",
            "--rank-shape",
            "10",
            "--rank-color",
            "10",
            "--nystrom-points",
            "300",
            "-o",
            s(&model),
        ]));
        Some(Fixture { dir, data, synth, model })
    })
    .as_ref()
}

fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines().skip(1).map(|l| l.split(',').map(str::to_string).collect()).collect()
}

#[test]
fn recognition_quick_writes_a_consistent_table_and_reuses_its_fits() {
    let Some(f) = fixture() else { return };
    let out = f.dir.path().join("rec");
    let args = [
        "eval",
        "recognition",
        "--synth",
        s(&f.synth),
        "--quick",
        "--data",
        s(&f.data),
        "--model",
        s(&f.model),
        "--mean-face-kernels",
        "symmetric-full",
        "--upper-bound",
        "--pca",
        "3",
        "--kde",
        "2",
        "--image-steps",
        "20",
        "-o",
        s(&out),
    ];
    let table = ok(&gpmm(&args));
    for name in [
        "recognition.md",
        "recognition.csv",
        "recognition.json",
        "recognition.png",
        "models/upper-bound-seed5.gpmm",
        "models/mean-face-symmetric-full-seed5.gpmm",
        "models/scans/mean-face.ply",
        "fits/tiny.json",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let rows = csv_rows(&out.join("recognition.csv"));
    // Five rows (tiny, the mean-face model, upper-bound, pca-3, kde-2), one probe yaw (30).
    let labels: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(labels, ["tiny", "mean-face-symmetric-full", "upper-bound", "pca-3", "kde-2"]);
    for r in &rows {
        assert_eq!(r[1], "30");
        let (correct, total): (usize, usize) = (r[2].parse().unwrap(), r[3].parse().unwrap());
        assert_eq!(total, 3, "one probe per identity");
        let (acc, lo, hi, chance): (f64, f64, f64, f64) =
            (r[4].parse().unwrap(), r[5].parse().unwrap(), r[6].parse().unwrap(), r[7].parse().unwrap());
        assert!((acc - correct as f64 / 3.0).abs() < 1e-3);
        assert!(lo <= acc && acc <= hi && (0.0..=1.0).contains(&lo) && hi <= 1.0, "{r:?}");
        assert!((chance - 1.0 / 3.0).abs() < 1e-3);
    }
    // The KDE row fitted every image with both components.
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("recognition.json")).unwrap()).unwrap();
    let kde = report["rows"].as_array().unwrap().iter().find(|r| r["label"] == "kde-2").unwrap();
    assert_eq!(kde["fits"], 12);
    assert!(table.contains("| chance |") && table.contains("kde-2"), "{table}");

    // Again: every fit comes from the cache and the table is the same.
    let again = ok(&gpmm(&args));
    assert_eq!(
        csv_rows(&out.join("recognition.csv")).iter().map(|r| r[..8].to_vec()).collect::<Vec<_>>(),
        rows.iter().map(|r| r[..8].to_vec()).collect::<Vec<_>>()
    );
    assert_eq!(again.matches(", cached").count(), 5, "{again}");

    // The same landmarks read from another directory: fitted anew (the cache knows where the
    // landmarks came from), and the same table.
    let lm_dir = f.dir.path().join("copied-landmarks");
    std::fs::create_dir_all(&lm_dir).unwrap();
    for e in std::fs::read_dir(&f.synth).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "pts") {
            std::fs::copy(&p, lm_dir.join(p.file_name().unwrap())).unwrap();
        }
    }
    let tiny = ["eval", "recognition", "--synth", s(&f.synth), "--quick", "--data", s(&f.data), "--model", s(&f.model)];
    let with_dir = ok(&gpmm(&[&tiny[..], &["--image-steps", "20", "--landmarks-dir", s(&lm_dir), "-o", s(&out)]].concat()));
    assert_eq!(with_dir.matches(", cached").count(), 0, "{with_dir}");
    let tiny_row = |rows: &[Vec<String>]| rows.iter().find(|r| r[0] == "tiny").map(|r| r[..8].to_vec());
    assert_eq!(tiny_row(&csv_rows(&out.join("recognition.csv"))), tiny_row(&rows));

    // The best samples instead of the posterior means: the cache knows which it kept, and the
    // reports say which were compared.
    assert_eq!(report["coefficients"], "posterior-mean");
    let best_out = f.dir.path().join("recognition-best");
    let best = ok(&gpmm(&[&tiny[..], &["--image-steps", "20", "--coefficients", "best", "-o", s(&best_out)]].concat()));
    assert!(best.contains("compared: the image chain's best sample"), "{best}");
    assert_eq!(read_json(&best_out.join("recognition.json"))["coefficients"], "best");
    let again_best = ok(&gpmm(&[&tiny[..], &["--image-steps", "20", "--coefficients", "posterior-mean", "-o", s(&best_out)]].concat()));
    assert_eq!(again_best.matches(", cached").count(), 0, "{again_best}");

    // Several fit seeds: one full report per seed, and their pooled figures side by side. The
    // first seed's report is the single-seed run's (same settings, same fits).
    let seeds_out = f.dir.path().join("recognition-seeds");
    let single = seeds_out.join("single");
    ok(&gpmm(&[&tiny[..], &["--image-steps", "20", "--fit-seed", "3", "-o", s(&single)]].concat()));
    let printed = ok(&gpmm(&[&tiny[..], &["--image-steps", "20", "--fit-seed", "3,4,3", "-o", s(&seeds_out)]].concat()));
    assert!(printed.contains("seed 3") && printed.contains("seed 4") && printed.contains("mean"), "{printed}");
    let summary = read_json(&seeds_out.join("seeds.json"));
    assert_eq!(summary["seeds"], serde_json::json!([3, 4]), "a repeated seed runs once: {summary}");
    let row = summary["rows"].as_array().unwrap().iter().find(|r| r["label"] == "tiny").expect("the model's row");
    let per: Vec<f64> = row["per_seed"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let (mean, min, max) = (row["mean"].as_f64().unwrap(), row["min"].as_f64().unwrap(), row["max"].as_f64().unwrap());
    assert!((mean - (per[0] + per[1]) / 2.0).abs() < 1e-12 && min <= mean && mean <= max, "{row}");
    assert!(seeds_out.join("seeds.md").is_file() && seeds_out.join("seed-4/recognition.md").is_file());
    assert_eq!(tiny_row(&csv_rows(&seeds_out.join("seed-3/recognition.csv"))), tiny_row(&csv_rows(&single.join("recognition.csv"))));
}

#[test]
fn specgen_quick_writes_curves_that_behave() {
    let Some(f) = fixture() else { return };
    let out = f.dir.path().join("specgen");
    ok(&gpmm(&[
        "eval",
        "specgen",
        "--quick",
        "--data",
        s(&f.data),
        "--model",
        s(&f.model),
        "--test-count",
        "2",
        "--components",
        "1,3,all",
        "-o",
        s(&out),
    ]));
    for name in ["specgen.md", "specgen.csv", "specgen.json", "specgen-shape.png", "specgen-color.png"] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let rows = csv_rows(&out.join("specgen.csv"));
    let ks: Vec<&str> = rows.iter().map(|r| r[1].as_str()).collect();
    assert_eq!(ks, ["1", "3", "10"]);
    let col = |k: usize| rows.iter().map(|r| r[k].parse::<f64>().unwrap()).collect::<Vec<f64>>();
    let (spec, gen, comp, gen_c, comp_c) = (col(2), col(3), col(4), col(6), col(7));
    // More components generalize better and explain more variance; everything is finite and positive.
    assert!(gen[2] < gen[0], "generalization {gen:?}");
    assert!(gen_c[2] < gen_c[0], "colour generalization {gen_c:?}");
    assert!(comp.windows(2).all(|w| w[0] < w[1]) && comp[2] <= 1.0, "{comp:?}");
    assert!(comp_c.windows(2).all(|w| w[0] < w[1]) && comp_c[2] <= 1.0, "{comp_c:?}");
    assert!(spec.iter().chain(&gen).all(|v| v.is_finite() && *v > 0.0 && *v < 50.0), "{spec:?} {gen:?}");
}

#[test]
fn reconstruction_quick_measures_every_fit_against_its_true_face() {
    let Some(f) = fixture() else { return };
    let out = f.dir.path().join("reconstruction");
    let args = ["eval", "reconstruction", "--synth", s(&f.synth), "--quick", "--data", s(&f.data), "--model", s(&f.model), "-o", s(&out)];
    ok(&gpmm(&args));
    for name in ["reconstruction.md", "reconstruction.csv", "reconstruction.json", "reconstruction.png", "fits/tiny.json"] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let report = read_json(&out.join("reconstruction.json"));
    let row = &report["rows"][0];
    // --quick: the first two identities, each at yaw 0 and 30.
    assert_eq!(row["fits"], 4, "{row}");
    let yaws: Vec<serde_json::Value> = row["pooled"].as_array().unwrap().iter().map(|p| p["abs_yaw_deg"].clone()).collect();
    assert_eq!(yaws, [serde_json::json!(0), serde_json::json!(30), serde_json::Value::Null]);
    let all = &row["pooled"][2];
    let mm = |v: &serde_json::Value| v.as_f64().unwrap();
    // A face of another person lies millimetres away, never zero and never centimetres.
    for d in [&all["fit"], &all["mean_shape"]] {
        assert!(mm(&d["median_mm"]) > 0.3 && mm(&d["median_mm"]) < 10.0, "{d}");
        assert!(mm(&d["mean_mm"]) >= mm(&d["median_mm"]) * 0.5 && mm(&d["std_mm"]) > 0.0, "{d}");
    }
    // The CSV has a line per image; the fits are reused on a second run with the same figures.
    assert_eq!(csv_rows(&out.join("reconstruction.csv")).len(), 4);
    ok(&gpmm(&args));
    assert_eq!(read_json(&out.join("reconstruction.json"))["rows"][0]["pooled"], row["pooled"]);
}

#[test]
fn register_recovers_a_moved_instance_of_the_model() {
    let Some(f) = fixture() else { return };
    let model = gpmm_host::gp::model_io::load(&f.model).unwrap();
    // An instance with known coefficients, turned by 10 degrees and shifted: the target.
    let mut mesh = model.instance(&[1.2, -0.8, 0.5, 0.3, -1.0], &[0.7, -0.5]).unwrap();
    let (c, sn) = (10f64.to_radians().cos(), 10f64.to_radians().sin());
    for p in mesh.positions.iter_mut() {
        *p = [c * p[0] + sn * p[2] + 4.0, p[1] - 3.0, -sn * p[0] + c * p[2] + 2.0];
    }
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("target.ply");
    gpmm_host::mesh::io::write_ply(&target, &mesh).unwrap();
    let lm = dir.path().join("target.json");
    std::fs::write(&lm, serde_json::json!({ "scheme": "ibug68", "vertex_ids": model.landmarks }).to_string()).unwrap();

    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["register", s(&f.model), s(&target), "--landmarks", s(&lm), "-o", s(out)];
        args.extend(extra);
        ok(&gpmm(&args));
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(out.join("register.json")).unwrap()).unwrap()
    };
    let full = run(&dir.path().join("full"), &[]);
    let one = run(&dir.path().join("one"), &["--shape-rank", "1", "--color-rank", "1"]);
    let res = |j: &serde_json::Value| j["residual_mm"]["mean"].as_f64().unwrap();
    assert!(res(&full) < 0.5, "residual {} mm", res(&full));
    assert!(res(&one) > 2.0 * res(&full), "one component {} vs all {}", res(&one), res(&full));
    // Vertex by vertex (the same topology), the registered instance, written in the target's frame, lies on the target:
    // the correspondence is recovered, not just the surface (the coefficients themselves are only defined up to the
    // near-rigid components the pose can absorb).
    let reg = gpmm_host::mesh::io::read_mesh(&dir.path().join("full/registered.ply"), None, None).unwrap();
    assert_eq!(reg.positions.len(), mesh.positions.len());
    let d: f64 =
        reg.positions.iter().zip(&mesh.positions).map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()).sum::<f64>()
            / mesh.positions.len() as f64;
    assert!(d < 1.0, "mean vertex-to-vertex distance {d} mm");
    let moved: f64 = model
        .shape
        .mean
        .iter()
        .zip(&mesh.positions)
        .map(|(a, b)| (0..3).map(|k| (f64::from(a[k]) - b[k]).powi(2)).sum::<f64>().sqrt())
        .sum::<f64>()
        / mesh.positions.len() as f64;
    assert!(moved > 5.0 * d.max(0.1), "the target was moved by {moved} mm on average");
    // The 10-degree turn is in the pose. (Not the shift: a long-range kernel has near-translation components that
    // absorb part of it, by an amount that depends on how the subspace was found.)
    let turned = full["pose"]["rotation"][0][2].as_f64().unwrap().abs().asin().to_degrees();
    assert!((turned - 10.0).abs() < 0.5, "recovered turn {turned} degrees: {}", full["pose"]);
}

#[test]
fn register_landmark_weight_zero_lets_the_surface_decide() {
    let Some(f) = fixture() else { return };
    let model = gpmm_host::gp::model_io::load(&f.model).unwrap();
    let mesh = model.instance(&[0.8, -0.5, 0.4], &[]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("target.ply");
    gpmm_host::mesh::io::write_ply(&target, &mesh).unwrap();
    // The target's brow points (17-26) are defined 10 mm higher than the model's: another landmark convention.
    let d2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
    let mut ids = model.landmarks.clone();
    for id in ids.iter_mut().take(27).skip(17) {
        let p = mesh.positions[*id as usize];
        let up = [p[0], p[1] + 10.0, p[2]];
        *id = (0..mesh.positions.len()).min_by(|&a, &b| d2(mesh.positions[a], up).total_cmp(&d2(mesh.positions[b], up))).unwrap() as u32;
    }
    let lm = dir.path().join("target.json");
    std::fs::write(&lm, serde_json::json!({ "scheme": "ibug68", "vertex_ids": ids }).to_string()).unwrap();
    // Mean distance of the registered brow vertices from where the model's brow vertices truly are on the target.
    let brow_shift = |extra: &[&str]| {
        let out = dir.path().join(format!("w{}", extra.len()));
        let mut args = vec!["register", s(&f.model), s(&target), "--landmarks", s(&lm), "-o", s(&out)];
        args.extend(extra);
        ok(&gpmm(&args));
        let reg = gpmm_host::mesh::io::read_mesh(&out.join("registered.ply"), None, None).unwrap();
        (17..27).map(|k| d2(reg.positions[model.landmarks[k] as usize], mesh.positions[model.landmarks[k] as usize]).sqrt()).sum::<f64>()
            / 10.0
    };
    let pulled = brow_shift(&[]);
    let free = brow_shift(&["--landmark-weight", "0"]);
    eprintln!("brow vertices off by {pulled:.2} mm with the default weight, {free:.2} mm with 0");
    assert!(free < 1.0, "with weight 0 the brow vertices are {free} mm off");
    assert!(pulled > 2.0 * free.max(0.2), "the default weight pulls them {pulled} mm (weight 0: {free} mm)");
    let e = fails(&gpmm(&["register", s(&f.model), s(&target), "--landmark-weight=-1", "-o", s(&dir.path().join("bad"))]));
    assert!(e.contains("landmark weight"), "{e}");
}

#[test]
fn bad_input_gives_clear_errors() {
    let Some(f) = fixture() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (d, o) = (s(&f.data), s(&out));

    let e =
        fails(&gpmm(&["eval", "recognition", "--synth", s(&dir.path().join("nope")), "--data", d, "--kernels", "symmetric-full", "-o", o]));
    assert!(e.contains("nope") && e.contains("not found"), "{e}");
    let e = fails(&gpmm(&["eval", "recognition", "--synth", s(&f.synth), "--data", d, "--kernels", "fancy-full", "-o", o]));
    assert!(e.contains("unknown kernel 'fancy-full'"), "{e}");
    let e = fails(&gpmm(&["eval", "recognition", "--synth", s(&f.synth), "--data", d, "-o", o]));
    assert!(e.contains("no models selected"), "{e}");
    let junk = dir.path().join("junk.gpmm");
    std::fs::write(&junk, b"not a model").unwrap();
    let e = fails(&gpmm(&["eval", "recognition", "--synth", s(&f.synth), "--data", d, "--model", s(&junk), "-o", o]));
    assert!(e.contains("junk.gpmm") && e.contains("not a gpmm model"), "{e}");

    // A synth directory without yaw-0 images has no gallery.
    let no_gallery = dir.path().join("side");
    let t = f.data.join("template/lee-perry-smith");
    ok(&gpmm(&[
        "synth",
        "--ict",
        s(&f.data.join("ict")),
        "--template-dir",
        s(&t),
        "--count",
        "1",
        "--yaws",
        "30",
        "--size",
        "32",
        "-o",
        s(&no_gallery),
    ]));
    let e = fails(&gpmm(&["eval", "recognition", "--synth", s(&no_gallery), "--data", d, "--model", s(&f.model), "-o", o]));
    assert!(e.contains("no yaw-0 images"), "{e}");

    let e = fails(&gpmm(&["eval", "specgen", "--data", d, "--model", s(&f.model), "--components", "1,zero", "-o", o]));
    assert!(e.contains("'zero'"), "{e}");

    // register: a missing mesh, landmarks that do not fit.
    let e = fails(&gpmm(&["register", s(&f.model), s(&dir.path().join("missing.ply")), "-o", o]));
    assert!(e.contains("missing.ply"), "{e}");
    let mesh = gpmm_host::gp::model_io::load(&f.model).unwrap().instance(&[], &[]).unwrap();
    let target = dir.path().join("t.ply");
    gpmm_host::mesh::io::write_ply(&target, &mesh).unwrap();
    let lm = dir.path().join("few.json");
    std::fs::write(&lm, r#"{"scheme": "ibug68", "vertex_ids": [1, 2, 3]}"#).unwrap();
    let e = fails(&gpmm(&["register", s(&f.model), s(&target), "--landmarks", s(&lm), "-o", o]));
    assert!(e.contains("few.json") && e.contains("3 ids"), "{e}");
}

#[test]
fn eval_and_register_have_help() {
    for cmd in [&["eval", "recognition", "--help"][..], &["eval", "specgen", "--help"], &["register", "--help"]] {
        let text = ok(&gpmm(cmd));
        assert!(text.contains("Usage") && text.len() > 500, "{cmd:?}: {text}");
    }
}

/// The world models: the neutral matches `gpmm synth`'s frame, the crop keeps the landmarks, and a world
/// identity's shape lies (up to its own rigid frame) in the span of the upper bound's shape basis.
#[test]
fn world_models_match_the_world() {
    use gpmm_host::eval::models::scans::EvalWorld;
    use gpmm_host::synth::{SynthOptions, SynthWorld};
    let Some(f) = fixture() else { return };
    let opts = SynthOptions { seed: 5, ..SynthOptions::with_data_dir(&f.data) };
    let world = EvalWorld::load(&opts).unwrap();
    let flat = SynthWorld::load(&SynthOptions { identity_scale: 0.0, ..opts.clone() }).unwrap().identity(0).unwrap();
    assert_eq!(flat.positions.len(), world.neutral().len());
    let worst = flat
        .positions
        .iter()
        .zip(world.neutral())
        .map(|(a, b)| (0..3).map(|k| (f64::from(a[k]) - b[k]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    assert!(worst < 1e-3, "neutral differs from the synth world's by {worst} mm");

    let (full, cropped) = (world.full_scan(3).unwrap(), world.cropped_scan(3).unwrap());
    assert_eq!(cropped.mesh.positions.len(), world.cropped_vertices());
    assert!(world.cropped_vertices() < full.mesh.positions.len() * 9 / 10, "the crop removes the back of the head");
    for (a, b) in full.landmarks.iter().zip(&cropped.landmarks) {
        assert_eq!(full.mesh.positions[*a as usize], cropped.mesh.positions[*b as usize]);
    }

    let ub = world.upper_bound_model(5, 4).unwrap();
    assert_eq!(ub.vertices(), world.cropped_vertices());
    assert_eq!((ub.shape.rank(), ub.color.rank()), (100, 4));
    let basis = gpmm_host::fit::register::basis_matrix(&ub.shape, 100);
    let d: Vec<f64> =
        cropped.mesh.positions.iter().zip(&ub.shape.mean).flat_map(|(p, m)| (0..3).map(move |k| p[k] - f64::from(m[k]))).collect();
    let norm2: f64 = d.iter().map(|v| v * v).sum();
    // Least-squares projection onto the (orthogonal) columns.
    let mut explained = 0.0;
    for j in 0..basis.ncols() {
        let (mut dot, mut nn) = (0.0, 0.0);
        for (r, v) in d.iter().enumerate() {
            dot += basis[(r, j)] * v;
            nn += basis[(r, j)] * basis[(r, j)];
        }
        explained += dot * dot / nn;
    }
    assert!(explained / norm2 > 0.95, "the upper bound's basis explains {:.3} of an identity's deviation", explained / norm2);
}
