//! Float networks (as trained) quantized into the core's int8 network encoding
//! (`docs/init-format.md`): per-output-channel weight scales, one activation scale per tensor;
//! a finder and an initializer so encoded make an init file. And back: an encoded network
//! dequantized into floats, for training to start from ([`decode_network`]).

use gpmm_core::format::init_file::write_init_file;
use gpmm_core::format::FormatError;
use gpmm_core::net::{network_header, LayerShape, Network, Shape};
use gpmm_host::detect::Detector;

/// One trained layer in `f32`.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatLayer {
    /// What it computes, over how many channels.
    pub shape: LayerShape,
    /// Weights `[cout][kernel][kernel][cin]`.
    pub weights: Vec<f32>,
    /// Biases `[cout]`.
    pub bias: Vec<f32>,
    /// Largest |output| seen on calibration data (sets the output's scale; unused in the last layer).
    pub out_max: f32,
}

/// A trained network: its input shape and layers.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatNet {
    /// Input tensor shape (the input is `(pixel − 128) / 128`).
    pub input: Shape,
    /// Layers in order.
    pub layers: Vec<FloatLayer>,
}

/// Scale of the input tensor: `i8` value `pixel − 128` stands for `(pixel − 128) / 128`.
pub const INPUT_SCALE: f32 = 1.0 / 128.0;

/// Why a network could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// Sizes do not agree or are out of the format's range.
    #[error("network layer {layer}: {what}")]
    Layer {
        /// Layer index.
        layer: usize,
        /// What is wrong.
        what: &'static str,
    },
    /// A weight, bias or calibration maximum is NaN or infinite.
    #[error("network layer {0}: a weight, bias or calibration value is not finite")]
    NonFinite(usize),
    /// The encoder's own output did not read back (a bug).
    #[error("the encoded network does not read back: {0}")]
    Readback(gpmm_core::net::NetError),
    /// The init file around the networks could not be written.
    #[error("the init file cannot be written: {0}")]
    File(FormatError),
}

/// Quantizes and encodes `net`.
pub fn encode_network(net: &FloatNet) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::new();
    let head = network_header(net.layers.len(), net.input)
        .map_err(|_| EncodeError::Layer { layer: 0, what: "layer count or input shape out of range" })?;
    out.extend_from_slice(&head);
    let mut in_scale = INPUT_SCALE;
    let last = net.layers.len().saturating_sub(1);
    for (li, l) in net.layers.iter().enumerate() {
        let per = l.shape.weights_per_output();
        if l.weights.len() != l.shape.cout * per || l.bias.len() != l.shape.cout {
            return Err(EncodeError::Layer { layer: li, what: "weight or bias count differs from the shape" });
        }
        if !l.weights.iter().chain(&l.bias).all(|v| v.is_finite()) || !l.out_max.is_finite() {
            return Err(EncodeError::NonFinite(li));
        }
        let out_scale = if li == last { 0.0 } else { l.out_max.max(1e-6) / 127.0 };
        out.extend_from_slice(
            &l.shape
                .header(out_scale)
                .map_err(|_| EncodeError::Layer { layer: li, what: "kernel, stride or channels out of the format's range" })?,
        );
        let mut mults = Vec::with_capacity(l.shape.cout);
        for w in l.weights.chunks_exact(per.max(1)) {
            let scale = w.iter().fold(0.0f32, |m, v| m.max(v.abs())) / 127.0;
            let scale = if scale > 0.0 { scale } else { 1.0 };
            out.extend(w.iter().map(|v| (v / scale).round().clamp(-127.0, 127.0) as i8 as u8));
            mults.push(scale * in_scale);
        }
        while out.len() % 4 != 0 {
            out.push(0);
        }
        mults.iter().chain(&l.bias).for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        in_scale = out_scale;
    }
    Network::parse(&out).map_err(EncodeError::Readback)?;
    Ok(out)
}

/// Encodes a finder and an initializer into init-file bytes (read back before they are returned).
pub fn init_file_bytes(
    finder: &FloatNet,
    initializer: &FloatNet,
    crop_margin: f32,
    landmarks: u16,
    light: u16,
    metadata: &str,
) -> Result<Vec<u8>, EncodeError> {
    let f = encode_network(finder)?;
    let i = encode_network(initializer)?;
    let mut out = vec![0u8; 64 + f.len() + i.len() + metadata.len() + 16];
    let len = write_init_file(&mut out, &f, &i, crop_margin, landmarks, light, metadata).map_err(EncodeError::File)?;
    out.truncate(len);
    Detector::from_bytes(&out).map_err(EncodeError::Readback)?;
    Ok(out)
}

/// The float network an encoded one stands for: each weight its `i8` value times its output
/// channel's multiplier over the input tensor's scale, the biases as stored, each layer's
/// calibration maximum from its output scale. Encoding the result gives the same weights back.
pub fn decode_network(net: &Network<'_>) -> FloatNet {
    let mut in_scale = INPUT_SCALE;
    let mut layers = Vec::with_capacity(net.layer_count());
    for l in net.layers_iter() {
        let per = l.shape.weights_per_output();
        let weights = l
            .weights
            .chunks_exact(per.max(1))
            .enumerate()
            .flat_map(|(o, w)| {
                let scale = l.multiplier(o) / in_scale;
                w.iter().map(move |&q| f32::from(q) * scale)
            })
            .collect();
        layers.push(FloatLayer {
            shape: l.shape,
            weights,
            bias: (0..l.shape.cout).map(|o| l.bias(o)).collect(),
            out_max: l.out_scale * 127.0,
        });
        in_scale = l.out_scale;
    }
    FloatNet { input: net.input(), layers }
}
