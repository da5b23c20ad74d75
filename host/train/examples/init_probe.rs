//! Trains only the initializer, in float, with one of a few architectures and a budget of fresh
//! scenes and passes, and reports its median landmark error / IOD and |yaw error| on 600 held-out
//! crops (cut around the true box with the training's jitter; no finder), in float and after the
//! training's int8 quantization run by the core: a quick way to see what limits the initializer.
//! `cargo run --release -p gpmm-train --example init_probe -- MODEL TEMPLATE_DIR VARIANT CHUNKS PASSES`
//! (VARIANT: base, the default initializer; wide, 1.5× its channels; d256, a 256-wide hidden layer;
//! r80, an 80 px crop; m12, a crop of 1.2 face sizes; wing, the wing loss on the landmarks;
//! heat or heatlite, a soft-argmax head: one heat map per landmark on the 8 × 8 map, float only).
use candle_core::Device;
use candle_core::{Tensor, Var, D};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use gpmm_core::net::{LayerKind, LayerShape, NetScratch, Network, Shape};
use gpmm_host::detect::eval::quantile;
use gpmm_train::data::{samples, Geometry, Sample};
use gpmm_train::encode::encode_network;
use gpmm_train::nets::{batch_tensor, initializer_specs, Net};
use gpmm_train::scene::head::HeadContext;
use gpmm_train::scene::{FaceModel, Openings, SceneRanges, SceneSource};
use gpmm_train::train::{cosine_lr, geometry, output_loss, pass_order};

const fn conv(cin: usize, cout: usize, stride: usize) -> LayerShape {
    LayerShape { kind: LayerKind::Conv, kernel: 3, stride, relu: true, cin, cout }
}
const fn dense(cin: usize, cout: usize, relu: bool) -> LayerShape {
    LayerShape { kind: LayerKind::Dense, kernel: 1, stride: 1, relu, cin, cout }
}

/// The default initializer's layout with first-layer channels `c` (doubled twice on the way
/// down), a last map of `side × side` cells and a hidden layer of `hidden` values.
fn stack(c: usize, side: usize, hidden: usize, d: usize) -> Vec<LayerShape> {
    vec![
        conv(3, c, 2),
        conv(c, 2 * c, 2),
        conv(2 * c, 2 * c, 1),
        conv(2 * c, 4 * c, 2),
        conv(4 * c, 4 * c, 2),
        dense(side * side * 4 * c, hidden, true),
        dense(hidden, d, false),
    ]
}

fn specs(variant: &str, d: usize) -> Vec<LayerShape> {
    match variant {
        "base" | "wing" | "m12" => initializer_specs(d),
        "r80" => stack(16, 5, 128, d),
        "wide" => stack(24, 4, 128, d),
        "d256" => stack(16, 4, 256, d),
        _ => Vec::new(),
    }
}

/// The training's loss with the landmarks' L1 replaced by the wing loss (Feng et al. 2018:
/// `w ln(1 + |x| / ε)` below `w`, `|x| − C` above; `w`, `ε` in crop units).
fn wing_loss(out: Tensor, batch: &[&Sample], geo: &Geometry, device: &Device, w: f64, eps: f64) -> candle_core::Result<Tensor> {
    let d = geo.initializer_outputs();
    let l2 = 2 * geo.landmarks;
    let target = Tensor::from_vec(batch.iter().flat_map(|s| s.target.iter().copied()).collect::<Vec<f32>>(), (batch.len(), d), device)?;
    let a = (out - target)?.abs()?;
    let lm = a.narrow(1, 0, l2)?;
    let c = w - w * (1.0 + w / eps).ln();
    let small = ((lm.clone() / eps)? + 1.0)?.log()? * w;
    let large = (lm.clone() - c)?;
    let wing = lm.lt(w)?.where_cond(&small?, &large)?;
    let rest = a.narrow(1, l2, d - l2)?;
    let rw: Vec<f32> = (l2..d).map(|i| if i < l2 + 3 { 2.0 } else { 0.3 }).collect();
    let rest = rest.broadcast_mul(&Tensor::from_vec(rw, (1, d - l2), device)?)?;
    (wing.sum_all()? + rest.sum_all()?)? / (batch.len() * l2) as f64
}

/// A soft-argmax head: a backbone to a `g × g × c` map, a 1 × 1 convolution to one heat map per
/// landmark whose softmax-weighted cell centres are the landmark, and a branch from the same map
/// to the angles and the light.
struct Heat {
    backbone: Net,
    wh: Var,
    bh: Var,
    branch: Net,
    coords: Tensor,
    l: usize,
}

impl Heat {
    fn new(variant: &str, l: usize, rest: usize, device: &Device) -> Res<Option<Self>> {
        let (back, g, c) = match variant {
            "heat" => (vec![conv(3, 16, 2), conv(16, 32, 2), conv(32, 32, 1), conv(32, 64, 2), conv(64, 64, 1)], 8, 64),
            "heatlite" => (vec![conv(3, 16, 2), conv(16, 32, 2), conv(32, 32, 1), conv(32, 64, 2)], 8, 64),
            _ => return Ok(None),
        };
        let backbone = Net::new(Shape { h: 64, w: 64, c: 3 }, back, 2, device)?;
        let branch =
            Net::new(Shape { h: g, w: g, c }, vec![conv(c, 64, 2), dense(g * g * 16, 128, true), dense(128, rest, false)], 3, device)?;
        let head = Net::new(
            Shape { h: g, w: g, c },
            vec![LayerShape { kind: LayerKind::Dense, kernel: 1, stride: 1, relu: false, cin: c, cout: l }],
            4,
            device,
        )?;
        let mut cs = Vec::new();
        for y in 0..g {
            for x in 0..g {
                cs.extend([((x as f32 + 0.5) / g as f32) * 2.0 - 1.0, ((y as f32 + 0.5) / g as f32) * 2.0 - 1.0]);
            }
        }
        let coords = Tensor::from_vec(cs, (g * g, 2), device)?;
        Ok(Some(Self { backbone, wh: head.weights[0].clone(), bh: head.biases[0].clone(), branch, coords, l }))
    }

    fn macs(&self) -> usize {
        let s = self.branch.input;
        self.backbone.macs() + self.branch.macs() + s.h * s.w * s.c * self.l
    }

    fn vars(&self) -> Vec<Var> {
        let mut v = self.backbone.vars();
        v.extend(self.branch.vars());
        v.extend([self.wh.clone(), self.bh.clone()]);
        v
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let (feat, _) = self.backbone.forward(x)?;
        let (n, g, _, c) = feat.dims4()?;
        let logits = feat.reshape((n * g * g, c))?.matmul(&self.wh.as_tensor().t()?)?.broadcast_add(self.bh.as_tensor())?;
        let p = candle_nn::ops::softmax(&logits.reshape((n, g * g, self.l))?.transpose(1, 2)?.contiguous()?, D::Minus1)?;
        let pts = p.broadcast_matmul(&self.coords)?.reshape((n, 2 * self.l))?;
        let (rest, _) = self.branch.forward(&feat)?;
        Tensor::cat(&[pts, rest], 1)
    }
}

/// Either kind of network under probe.
enum Model {
    Plain(Net),
    Heat(Heat),
}

impl Model {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        match self {
            Model::Plain(n) => Ok(n.forward(x)?.0),
            Model::Heat(h) => h.forward(x),
        }
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

fn heldout_error(net: &Model, data: &[Sample], geo: &Geometry, device: &Device) -> Res<(f64, f64)> {
    let mut outputs: Vec<Vec<f32>> = Vec::new();
    for chunk in data.chunks(128) {
        let x = batch_tensor(chunk.iter().map(|s| s.crop.as_slice()), geo.crop_side, device)?;
        outputs.extend(net.forward(&x)?.to_vec2::<f32>()?);
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
    let faces = [FaceModel { model: &model, openings: &openings }];
    let source = SceneSource { faces: &faces, head: Some(&head), ranges: &ranges, backgrounds: None };
    let l = model.landmarks.len();
    let mut geo = geometry(l);
    match variant {
        "r80" => geo.crop_side = 80,
        "m12" => geo.crop_margin = 1.2,
        _ => {}
    }
    let d = geo.initializer_outputs();
    let device = Device::Cpu;
    let model = match Heat::new(variant, l, d - 2 * l, &device)? {
        Some(h) => Model::Heat(h),
        None => {
            let layers = specs(variant, d);
            if layers.is_empty() || l != 68 {
                return Err(format!("unknown variant {variant} or a model without the 68 iBUG landmarks").into());
            }
            Model::Plain(Net::new(Shape { h: geo.crop_side, w: geo.crop_side, c: 3 }, layers, 2, &device)?)
        }
    };
    let (macs, vars) = match &model {
        Model::Plain(n) => (n.macs(), n.vars()),
        Model::Heat(h) => (h.macs(), h.vars()),
    };
    let held = samples(source, &geo, 777, 0, 600);
    let mut opt = AdamW::new(vars, ParamsAdamW { lr: 2e-3, weight_decay: 1e-4, ..Default::default() })?;
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
                let x = batch_tensor(b.iter().map(|s| s.crop.as_slice()), geo.crop_side, &device)?;
                let li = if variant == "wing" {
                    wing_loss(model.forward(&x)?, &b, &geo, &device, 0.31, 0.0625)?
                } else {
                    output_loss(model.forward(&x)?, &b, &geo, &device)?
                };
                opt.backward_step(&li)?;
                sum += li.to_scalar::<f32>()?;
                n += 1;
                done += 1;
            }
            last = sum / n as f32;
        }
        if chunk % 4 == 3 || chunk + 1 == chunks {
            let (e, y) = heldout_error(&model, &held, &geo, &device)?;
            eprintln!(
                "{variant} chunk {} step {done}/{total} loss {last:.4} held-out {e:.4} yaw {y:.2} ({:.0} s)",
                chunk + 1,
                t0.elapsed().as_secs_f64()
            );
        }
    }
    let (e, y) = heldout_error(&model, &held, &geo, &device)?;
    let (qe, qy) = match &model {
        Model::Plain(net) => quantized_error(net, &samples(source, &geo, 1, 0, 256), &held, &geo, &device)?,
        Model::Heat(_) => (f64::NAN, f64::NAN),
    };
    println!(
        "{variant} chunks {chunks} passes {passes} macs {macs} steps {total} loss {last:.4} held-out IOD {e:.4} yaw {y:.2} int8 IOD {qe:.4} yaw {qy:.2} time {:.0} s",
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
