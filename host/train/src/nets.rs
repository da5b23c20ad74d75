//! The two networks as candle graphs with their own seeded initialization, and their export to
//! the float description the encoder quantizes ([`crate::encode::FloatNet`]).

use crate::encode::{FloatLayer, FloatNet};
use crate::patches::Patches;
use candle_core::{DType, Device, Result, Tensor, Var, D};
use gpmm_core::net::{LayerKind, LayerShape, Shape};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

const fn conv(cin: usize, cout: usize, stride: usize) -> LayerShape {
    LayerShape { kind: LayerKind::Conv, kernel: 3, stride, relu: true, cin, cout }
}

/// The finder: a `side × side` RGB frame to a grid of `side / 16` cells × 4 values. Its last
/// cells see 79 px of the input, as large as the largest faces it is trained on.
pub fn finder_specs() -> Vec<LayerShape> {
    vec![
        conv(3, 8, 2),
        conv(8, 16, 2),
        conv(16, 32, 2),
        conv(32, 32, 1),
        conv(32, 64, 2),
        conv(64, 64, 1),
        LayerShape { kind: LayerKind::Conv, kernel: 1, stride: 1, relu: false, cin: 64, cout: 4 },
    ]
}

/// The initializer: a 64 × 64 RGB crop to `outputs` values.
pub fn initializer_specs(outputs: usize) -> Vec<LayerShape> {
    vec![
        conv(3, 16, 2),
        conv(16, 32, 2),
        conv(32, 32, 1),
        conv(32, 64, 2),
        conv(64, 64, 2),
        LayerShape { kind: LayerKind::Dense, kernel: 1, stride: 1, relu: true, cin: 4 * 4 * 64, cout: 128 },
        LayerShape { kind: LayerKind::Dense, kernel: 1, stride: 1, relu: false, cin: 128, cout: outputs },
    ]
}

/// How a trained network differs from the one a training builds.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ArchitectureMismatch {
    /// Another input shape.
    #[error("its input is {found_h}x{found_w}x{found_c}, the training's {h}x{w}x{c}", found_h = found.h, found_w = found.w, found_c = found.c, h = expected.h, w = expected.w, c = expected.c)]
    Input {
        /// The trained network's.
        found: Shape,
        /// The training's.
        expected: Shape,
    },
    /// Another number of layers.
    #[error("it has {found} layers, the training's {expected}")]
    Layers {
        /// The trained network's.
        found: usize,
        /// The training's.
        expected: usize,
    },
    /// A layer of another shape.
    #[error("its layer {layer} is a {found}, the training's a {expected}")]
    Layer {
        /// Layer index.
        layer: usize,
        /// The trained network's.
        found: LayerShape,
        /// The training's.
        expected: LayerShape,
    },
}

/// Whether `net` has the input shape and layers a training builds (`input`, `specs`).
pub fn check_architecture(net: &FloatNet, input: Shape, specs: &[LayerShape]) -> std::result::Result<(), ArchitectureMismatch> {
    if net.input != input {
        return Err(ArchitectureMismatch::Input { found: net.input, expected: input });
    }
    if net.layers.len() != specs.len() {
        return Err(ArchitectureMismatch::Layers { found: net.layers.len(), expected: specs.len() });
    }
    for (layer, (l, &expected)) in net.layers.iter().zip(specs).enumerate() {
        let found = l.shape;
        if found != expected {
            return Err(ArchitectureMismatch::Layer { layer, found, expected });
        }
    }
    Ok(())
}

/// A network under training.
#[derive(Debug)]
pub struct Net {
    /// Input shape.
    pub input: Shape,
    /// Layer shapes.
    pub specs: Vec<LayerShape>,
    /// Weights `[cout, k·k·cin]` (columns in `[ky][kx][cin]` order; dense: `k = 1`).
    pub weights: Vec<Var>,
    /// Biases `[cout]`.
    pub biases: Vec<Var>,
}

impl Net {
    /// He-initialized weights from `seed`, zero biases.
    pub fn new(input: Shape, specs: Vec<LayerShape>, seed: u64, device: &Device) -> Result<Self> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let (mut weights, mut biases) = (Vec::new(), Vec::new());
        for s in &specs {
            let fan_in = s.kernel * s.kernel * s.cin;
            let std = (2.0 / fan_in as f32).sqrt() * if s.relu { 1.0 } else { 0.5 };
            let normal = Normal::new(0.0f32, std).map_err(|e| candle_core::Error::Msg(e.to_string()))?;
            let values: Vec<f32> = (0..s.cout * fan_in).map(|_| normal.sample(&mut rng)).collect();
            // Conv weights as a `[cout, k·k·cin]` matrix in the core's `[ky][kx][cin]` order.
            let w = Tensor::from_vec(values, (s.cout, fan_in), device)?;
            weights.push(Var::from_tensor(&w)?);
            biases.push(Var::from_tensor(&Tensor::zeros(s.cout, DType::F32, device)?)?);
        }
        Ok(Self { input, specs, weights, biases })
    }

    /// A network starting from trained weights (`net`'s; its calibration maxima are not kept).
    pub fn from_float(net: &FloatNet, device: &Device) -> Result<Self> {
        let (mut weights, mut biases) = (Vec::new(), Vec::new());
        for l in &net.layers {
            let w = Tensor::from_vec(l.weights.clone(), (l.shape.cout, l.shape.weights_per_output()), device)?;
            weights.push(Var::from_tensor(&w)?);
            biases.push(Var::from_tensor(&Tensor::from_vec(l.bias.clone(), l.shape.cout, device)?)?);
        }
        Ok(Self { input: net.input, specs: net.layers.iter().map(|l| l.shape).collect(), weights, biases })
    }

    /// Multiply-accumulates of one forward pass of one sample.
    pub fn macs(&self) -> usize {
        let (mut h, mut w) = (self.input.h, self.input.w);
        self.specs
            .iter()
            .map(|s| match s.kind {
                LayerKind::Conv => {
                    (h, w) = Patches { b: 1, h, w, c: s.cin, k: s.kernel, stride: s.stride }.out_hw();
                    h * w * s.cout * s.kernel * s.kernel * s.cin
                }
                LayerKind::Dense => s.cin * s.cout,
            })
            .sum()
    }

    /// Every trainable variable.
    pub fn vars(&self) -> Vec<Var> {
        self.weights.iter().chain(&self.biases).cloned().collect()
    }

    /// The output for an NHWC batch, and every layer's output (for calibration).
    pub fn forward(&self, x: &Tensor) -> Result<(Tensor, Vec<Tensor>)> {
        let mut h = x.clone();
        let mut acts = Vec::with_capacity(self.specs.len());
        for ((s, w), b) in self.specs.iter().zip(&self.weights).zip(&self.biases) {
            h = match s.kind {
                LayerKind::Conv => {
                    // Channel-last patches times the `[cout, k·k·cin]` weights: the output is
                    // channel-last already (crate::patches says why not candle's conv2d).
                    let (n, ih, iw, c) = h.dims4()?;
                    let p = Patches { b: n, h: ih, w: iw, c, k: s.kernel, stride: s.stride };
                    let (oh, ow) = p.out_hw();
                    let y = p.gather(&h)?.matmul(&w.as_tensor().t()?)?.broadcast_add(b.as_tensor())?;
                    y.reshape((n, oh, ow, s.cout))?
                }
                LayerKind::Dense => {
                    // Channel-last activations flatten in the core's (y·W + x)·C + c order.
                    let flat = if h.rank() == 4 { h.flatten_from(1)? } else { h };
                    flat.matmul(&w.as_tensor().t()?)?.broadcast_add(b.as_tensor())?
                }
            };
            if s.relu {
                h = h.relu()?;
            }
            acts.push(h.clone());
        }
        Ok((h, acts))
    }

    /// The largest |value| of every layer's output on a calibration batch.
    pub fn calibrate(&self, x: &Tensor) -> Result<Vec<f32>> {
        let (_, acts) = self.forward(x)?;
        acts.iter().map(|a| a.abs()?.flatten_all()?.max(D::Minus1)?.to_scalar::<f32>()).collect()
    }

    /// The trained network in the host's float description (channel-last weights).
    pub fn to_float(&self, out_max: &[f32]) -> Result<FloatNet> {
        let mut layers = Vec::new();
        for (i, ((s, w), b)) in self.specs.iter().zip(&self.weights).zip(&self.biases).enumerate() {
            let w = w.as_tensor();
            layers.push(FloatLayer {
                shape: *s,
                weights: w.flatten_all()?.to_vec1()?,
                bias: b.as_tensor().to_vec1()?,
                out_max: out_max.get(i).copied().unwrap_or(1.0),
            });
        }
        Ok(FloatNet { input: self.input, layers })
    }
}

/// An NHWC `f32` batch (`value / 128`) from channel-last `i8` inputs of side `side`.
pub fn batch_tensor<'a>(inputs: impl Iterator<Item = &'a [i8]>, side: usize, device: &Device) -> Result<Tensor> {
    let mut data = Vec::new();
    let mut n = 0;
    for x in inputs {
        data.extend(x.iter().map(|&v| f32::from(v) / 128.0));
        n += 1;
    }
    Tensor::from_vec(data, (n, side, side, 3), device)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_multiply_accumulates_are_those_the_core_counts() {
        // The core's count of the default networks (`Network::macs`, as the training report gives it).
        let device = Device::Cpu;
        let finder = Net::new(Shape { h: 96, w: 96, c: 3 }, finder_specs(), 1, &device).unwrap();
        let init = Net::new(Shape { h: 64, w: 64, c: 3 }, initializer_specs(151), 2, &device).unwrap();
        assert_eq!(finder.macs(), 5_151_744);
        assert_eq!(init.macs(), 5_901_184);
    }
}
