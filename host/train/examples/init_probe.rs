//! Trains only the initializer, in float, with one of a few architectures and a budget of fresh
//! scenes and passes, and reports its median landmark error / IOD and |yaw error| on 600 held-out
//! crops (cut around the true box with the training's jitter; no finder), in float and after the
//! training's int8 quantization run by the core: a quick way to see what limits the initializer
//! (docs/evaluation.md, stops 34 and 35).
//! `cargo run --release -p gpmm-train --example init_probe -- MODEL TEMPLATE_DIR VARIANT CHUNKS PASSES`
//! (VARIANT: base, the default initializer, or wide, 1.5× its channels).
use candle_core::Device;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use gpmm_core::net::{LayerKind, NetScratch, Network, Shape};
use gpmm_host::init::encode::encode_network;
use gpmm_host::init::eval::quantile;
use gpmm_host::init::head::HeadContext;
use gpmm_host::init::scene::{Openings, SceneRanges, SceneSource};
use gpmm_train::data::{samples, Geometry, Sample};
use gpmm_train::nets::{batch_tensor, initializer_specs, Net, Spec};
use gpmm_train::train::{cosine_lr, geometry, initializer_loss, pass_order};

const fn conv(cin: usize, cout: usize, stride: usize) -> Spec {
    Spec { kind: LayerKind::Conv, kernel: 3, stride, relu: true, cin, cout }
}
const fn dense(cin: usize, cout: usize, relu: bool) -> Spec {
    Spec { kind: LayerKind::Dense, kernel: 1, stride: 1, relu, cin, cout }
}

fn specs(variant: &str, d: usize) -> Vec<Spec> {
    match variant {
        "base" => initializer_specs(d),
        "wide" => vec![
            conv(3, 24, 2),
            conv(24, 48, 2),
            conv(48, 48, 1),
            conv(48, 96, 2),
            conv(96, 96, 2),
            dense(1536, 128, true),
            dense(128, d, false),
        ],
        _ => Vec::new(),
    }
}

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Median landmark error / IOD and |yaw error| of `outputs` (one per sample of `data`).
fn medians(data: &[Sample], outputs: &[Vec<f32>], l: usize) -> (f64, f64) {
    let (mut errs, mut yaws) = (Vec::new(), Vec::new());
    // Outer eye corners 36 and 45: their x and y at 72, 73 and 90, 91.
    for (s, o) in data.iter().zip(outputs) {
        let t = &s.target;
        let iod = ((t[72] - t[90]).powi(2) + (t[73] - t[91]).powi(2)).sqrt();
        let e: f32 = (0..l).map(|k| ((o[2 * k] - t[2 * k]).powi(2) + (o[2 * k + 1] - t[2 * k + 1]).powi(2)).sqrt()).sum::<f32>() / l as f32;
        errs.push(f64::from(e / iod));
        yaws.push(f64::from((o[2 * l] - t[2 * l]).abs().to_degrees()));
    }
    (quantile(errs, 0.5), quantile(yaws, 0.5))
}

fn heldout_error(net: &Net, data: &[Sample], geo: &Geometry, device: &Device) -> Res<(f64, f64)> {
    let mut outputs: Vec<Vec<f32>> = Vec::new();
    for chunk in data.chunks(128) {
        let x = batch_tensor(chunk.iter().map(|s| s.crop.as_slice()), geo.crop_side, device)?;
        outputs.extend(net.forward(&x)?.0.to_vec2::<f32>()?);
    }
    Ok(medians(data, &outputs, geo.landmarks))
}

/// The same measure after quantizing as the training does (activation ranges from `calib`) and
/// running the core's int8 network.
fn quantized_error(net: &Net, calib: &[Sample], data: &[Sample], geo: &Geometry, device: &Device) -> Res<(f64, f64)> {
    let x = batch_tensor(calib.iter().map(|s| s.crop.as_slice()), geo.crop_side, device)?;
    let bytes = encode_network(&net.to_float(&net.calibrate(&x)?)?)?;
    let (core, _) = Network::parse(&bytes).map_err(|e| format!("{e:?}"))?;
    let mut scratch = Box::new(NetScratch::<{ 64 * 1024 }>::new());
    let mut outputs = Vec::with_capacity(data.len());
    for s in data {
        scratch.input_mut(s.crop.len()).map_err(|e| format!("{e:?}"))?.copy_from_slice(&s.crop);
        let mut out = vec![0.0f32; core.output().len()];
        core.run(&mut scratch, &mut out).map_err(|e| format!("{e:?}"))?;
        outputs.push(out);
    }
    Ok(medians(data, &outputs, geo.landmarks))
}

fn main() -> Res<()> {
    let a: Vec<String> = std::env::args().collect();
    let [_, model_path, template, variant, chunks, passes] = a.as_slice() else {
        return Err("usage: init_probe MODEL TEMPLATE_DIR VARIANT CHUNKS PASSES".into());
    };
    let (template, variant) = (std::path::Path::new(template), variant.as_str());
    let (chunks, passes): (usize, usize) = (chunks.parse()?, passes.parse()?);
    let model = gpmm_host::gp::model_io::load(std::path::Path::new(model_path))?;
    let head = HeadContext::load(&model, &template.join("lee-perry-smith.ply"), &template.join("landmarks_ibug68.json"))?;
    let ranges = SceneRanges::default();
    let openings = Openings::of_model(&model, &ranges);
    let source = SceneSource { model: &model, head: Some(&head), ranges: &ranges, openings: &openings };
    let l = model.landmarks.len();
    let geo = geometry(l);
    let d = geo.init_outputs();
    let device = Device::Cpu;
    let layers = specs(variant, d);
    if layers.is_empty() || l != 68 {
        return Err(format!("unknown variant {variant} or a model without the 68 iBUG landmarks").into());
    }
    let net = Net::new(Shape { h: geo.crop_side, w: geo.crop_side, c: 3 }, layers, 2, &device)?;
    let macs = net.macs();
    let held = samples(source, &geo, 777, 0, 600);
    let mut opt = AdamW::new(net.vars(), ParamsAdamW { lr: 2e-3, weight_decay: 1e-4, ..Default::default() })?;
    let (chunk_scenes, batch, lr0) = (2048usize, 64usize, 2e-3f64);
    let total = chunks * passes * chunk_scenes.div_ceil(batch);
    let mut done = 0;
    let t0 = std::time::Instant::now();
    let mut last = 0.0;
    for chunk in 0..chunks {
        let data = samples(source, &geo, 1, (chunk * chunk_scenes) as u64, chunk_scenes as u64);
        for pass in 0..passes {
            let order = pass_order(1, chunk, pass, data.len());
            let mut sum = 0.0;
            let mut n = 0;
            for idx in order.chunks(batch) {
                let b: Vec<&Sample> = idx.iter().map(|&i| &data[i]).collect();
                let lr = cosine_lr(lr0, done, total);
                opt.set_learning_rate(lr);
                let li = initializer_loss(&net, &b, &geo, &device)?;
                opt.backward_step(&li)?;
                sum += li.to_scalar::<f32>()?;
                n += 1;
                done += 1;
            }
            last = sum / n as f32;
        }
        if chunk % 4 == 3 || chunk + 1 == chunks {
            let (e, y) = heldout_error(&net, &held, &geo, &device)?;
            eprintln!(
                "{variant} chunk {} step {done}/{total} loss {last:.4} held-out {e:.4} yaw {y:.2} ({:.0} s)",
                chunk + 1,
                t0.elapsed().as_secs_f64()
            );
        }
    }
    let (e, y) = heldout_error(&net, &held, &geo, &device)?;
    let calib = samples(source, &geo, 1, 0, 256);
    let (qe, qy) = quantized_error(&net, &calib, &held, &geo, &device)?;
    println!(
        "{variant} chunks {chunks} passes {passes} macs {macs} steps {total} loss {last:.4} held-out IOD {e:.4} yaw {y:.2} int8 IOD {qe:.4} yaw {qy:.2} time {:.0} s",
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
