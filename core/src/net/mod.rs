//! Small int8 convolutional networks evaluated in fixed memory: the face finder and the
//! initializer of a landmark-free fit (`docs/init-format.md`).
//!
//! A [`Network`] is a validated view of one network's bytes inside an init file (read in place,
//! nothing copied). Activations are `i8` with one scale per tensor (zero point 0); weights are `i8`
//! with one scale per output channel, folded with the input's scale into one `f32` multiplier per
//! output channel. A layer computes, per output value, an `i32` sum of `i8 × i8` products, then
//! `y = sum × multiplier + bias`, optionally `max(y, 0)`, and stores `round(y / out_scale)` clamped
//! to `-128..=127`, or, in the last layer, `y` itself as `f32`. Every operation is integer or IEEE
//! single precision without fused multiply-add, so the host and a Cortex-M4F compute the same bits.
//!
//! Two layer kinds: a 2-D convolution over an `H×W×C` (channel-last) tensor with a square kernel
//! (1, 3 or 5), stride 1 or 2 and zero padding `kernel / 2` (output side `(in + 2·pad − k) / s + 1`),
//! and a dense layer over the whole flattened tensor (`(y·W + x)·C + c` order).

pub mod agreement;
pub mod crop;
pub mod face;
pub mod face_box;
pub mod resample;
pub mod scan;

use crate::format::bytes::Reader;
use crate::format::FormatError;
use core::fmt;

/// Largest number of layers of one network.
pub const MAX_LAYERS: usize = 32;

/// Why a network or an init file was refused, or a run could not be done. Small and `Copy`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NetError {
    /// The bytes are not a well-formed network or init file.
    Format(FormatError),
    /// A layer's description is inconsistent (the text says what).
    Layer(&'static str),
    /// A multiplier, bias or scale is NaN, infinite or (for a scale) not positive.
    NonFinite,
    /// The scratch buffers are smaller than the network's largest activation.
    ScratchTooSmall {
        /// Bytes each of the two buffers needs.
        needed: usize,
    },
    /// The caller's input or output slice does not have the network's size.
    LengthMismatch,
    /// The input image is empty or its pixel slice does not match its size.
    BadImage,
    /// The landmarks a crop is cut around span no area or are not finite.
    DegenerateLandmarks,
}

impl From<FormatError> for NetError {
    fn from(e: FormatError) -> Self {
        NetError::Format(e)
    }
}

impl fmt::Display for NetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            NetError::Format(e) => write!(f, "{e}"),
            NetError::Layer(what) => write!(f, "a network layer is inconsistent: {what}"),
            NetError::NonFinite => write!(f, "a network multiplier, bias or scale is not a finite (positive) number"),
            NetError::ScratchTooSmall { needed } => write!(f, "the network scratch is too small ({needed} bytes per buffer needed)"),
            NetError::LengthMismatch => write!(f, "the network's input or output slice has the wrong length"),
            NetError::BadImage => write!(f, "the image is empty or its pixels do not match its size"),
            NetError::DegenerateLandmarks => write!(f, "the landmarks span no area or are not finite: no crop can be cut around them"),
        }
    }
}

impl core::error::Error for NetError {}

/// What a layer computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LayerKind {
    /// 2-D convolution, channel-last, zero padding `kernel / 2`.
    Conv,
    /// Dense layer over the flattened input.
    Dense,
}

impl LayerKind {
    /// The kind's code in the file.
    pub fn code(self) -> u8 {
        match self {
            LayerKind::Conv => 1,
            LayerKind::Dense => 2,
        }
    }

    /// The kind of a code, if any.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(LayerKind::Conv),
            2 => Some(LayerKind::Dense),
            _ => None,
        }
    }
}

/// A tensor's shape: height, width, channels (channel-last).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Shape {
    /// Rows.
    pub h: usize,
    /// Columns.
    pub w: usize,
    /// Channels.
    pub c: usize,
}

impl Shape {
    /// Number of values.
    pub fn len(&self) -> usize {
        self.h.saturating_mul(self.w).saturating_mul(self.c)
    }

    /// Whether it holds no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a layer computes, over how many channels: the six fields of a layer's header that the
/// trainer writes and this reader reads (with the output scale, `docs/init-format.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LayerShape {
    /// Convolution or dense.
    pub kind: LayerKind,
    /// Kernel side (1 for dense).
    pub kernel: usize,
    /// Stride (1 for dense).
    pub stride: usize,
    /// Whether `max(y, 0)` is applied.
    pub relu: bool,
    /// Input channels (dense: the flattened input length, in `(y·W + x)·C + c` order).
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
}

/// Bytes of a layer's header: kind, kernel, stride, flags (one byte each), input and output
/// channels (`u16` each) and the output scale (`f32`).
pub const LAYER_HEADER_BYTES: usize = 12;

impl LayerShape {
    /// Weights per output channel (`kernel × kernel × cin`).
    pub fn weights_per_output(&self) -> usize {
        self.kernel.saturating_mul(self.kernel).saturating_mul(self.cin)
    }

    /// Whether the format can hold it: a convolution's kernel 1, 3 or 5 and stride 1 or 2, a dense
    /// layer's both 1, and at least one channel in and out (at most `u16::MAX`).
    pub fn is_valid(&self) -> bool {
        let sides = match self.kind {
            LayerKind::Conv => matches!(self.kernel, 1 | 3 | 5) && matches!(self.stride, 1 | 2),
            LayerKind::Dense => self.kernel == 1 && self.stride == 1,
        };
        let channels = |n: usize| (1..=usize::from(u16::MAX)).contains(&n);
        sides && channels(self.cin) && channels(self.cout)
    }

    /// The header of a layer of this shape whose output is stored at `out_scale` (`0` for the last
    /// layer's `f32` output).
    pub fn header(&self, out_scale: f32) -> Result<[u8; LAYER_HEADER_BYTES], NetError> {
        if !self.is_valid() {
            return Err(NetError::Layer("kernel, stride, channels or flags out of range"));
        }
        let byte = |n: usize| u8::try_from(n).map_err(|_| NetError::Layer("kernel or stride out of range"));
        let wide = |n: usize| u16::try_from(n).map_err(|_| NetError::Layer("channels out of range"));
        let mut h = [0u8; LAYER_HEADER_BYTES];
        let mut w = crate::format::bytes::Writer::new(&mut h);
        w.bytes(&[self.kind.code(), byte(self.kernel)?, byte(self.stride)?, u8::from(self.relu)])?;
        w.u16(wide(self.cin)?)?;
        w.u16(wide(self.cout)?)?;
        w.f32(out_scale)?;
        Ok(h)
    }

    /// Reads a layer's header: its shape and output scale, checked.
    fn read_header(r: &mut Reader<'_>) -> Result<(Self, f32), NetError> {
        let kind = LayerKind::from_code(r.array::<1>()?[0]).ok_or(NetError::Layer("unknown layer kind"))?;
        let [kernel, stride, flags] = r.array::<3>()?;
        let cin = usize::from(r.u16()?);
        let cout = usize::from(r.u16()?);
        let out_scale = r.f32()?;
        let shape = LayerShape { kind, kernel: usize::from(kernel), stride: usize::from(stride), relu: flags == 1, cin, cout };
        if !shape.is_valid() || flags > 1 {
            return Err(NetError::Layer("kernel, stride, channels or flags out of range"));
        }
        if !(out_scale.is_finite() && out_scale >= 0.0) {
            return Err(NetError::NonFinite);
        }
        Ok((shape, out_scale))
    }

    /// The shape of this layer's output for an `input` tensor.
    pub fn output_shape(&self, input: Shape) -> Result<Shape, NetError> {
        match self.kind {
            LayerKind::Dense => {
                if input.len() != self.cin {
                    return Err(NetError::Layer("a dense layer's input length differs from the tensor before it"));
                }
                Ok(Shape { h: 1, w: 1, c: self.cout })
            }
            LayerKind::Conv => {
                if input.c != self.cin {
                    return Err(NetError::Layer("a convolution's input channels differ from the tensor before it"));
                }
                let pad = self.kernel / 2;
                let side = |n: usize| (n + 2 * pad).checked_sub(self.kernel).map(|m| m / self.stride + 1);
                match (side(input.h), side(input.w)) {
                    (Some(h), Some(w)) => Ok(Shape { h, w, c: self.cout }),
                    _ => Err(NetError::Layer("a convolution's input is smaller than its kernel")),
                }
            }
        }
    }
}

impl fmt::Display for LayerShape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self.kind {
            LayerKind::Conv => "convolution",
            LayerKind::Dense => "dense",
        };
        let relu = if self.relu { " + ReLU" } else { "" };
        write!(f, "{kind} {}x{} stride {}, {} -> {} channels{relu}", self.kernel, self.kernel, self.stride, self.cin, self.cout)
    }
}

/// One layer read from the file: its description and its parameters in place.
#[derive(Debug, Clone, Copy)]
pub struct Layer<'a> {
    /// What it computes, over how many channels.
    pub shape: LayerShape,
    /// Scale of the stored output (`0` in the last layer: `f32` output).
    pub out_scale: f32,
    /// Weights `[cout][kernel][kernel][cin]`.
    pub weights: &'a [i8],
    /// Per output channel multipliers, little-endian `f32`.
    multipliers: &'a [u8],
    /// Per output channel biases, little-endian `f32`.
    biases: &'a [u8],
}

fn f32_at(bytes: &[u8], i: usize) -> f32 {
    let mut b = [0u8; 4];
    if let Some(s) = bytes.get(i * 4..i * 4 + 4) {
        b.copy_from_slice(s);
    }
    f32::from_le_bytes(b)
}

impl Layer<'_> {
    /// Multiplier of output channel `o`.
    pub fn multiplier(&self, o: usize) -> f32 {
        f32_at(self.multipliers, o)
    }

    /// Bias of output channel `o`.
    pub fn bias(&self, o: usize) -> f32 {
        f32_at(self.biases, o)
    }

    fn read<'a>(r: &mut Reader<'a>) -> Result<Layer<'a>, NetError> {
        let (shape, out_scale) = LayerShape::read_header(r)?;
        let weights: &[i8] = bytemuck::cast_slice(r.take(shape.cout * shape.weights_per_output())?);
        r.align4()?;
        let multipliers = r.take(shape.cout * 4)?;
        let biases = r.take(shape.cout * 4)?;
        let layer = Layer { shape, out_scale, weights, multipliers, biases };
        if (0..shape.cout).any(|o| !layer.multiplier(o).is_finite() || !layer.bias(o).is_finite()) {
            return Err(NetError::NonFinite);
        }
        Ok(layer)
    }
}

/// Bytes of a network's header: layer count, a reserved `u16`, input height, width and channels,
/// a reserved `u16`.
pub const NETWORK_HEADER_BYTES: usize = 12;

/// The header of a network of `layers` layers over an `input` tensor (what [`Network::parse`]
/// reads first).
pub fn network_header(layers: usize, input: Shape) -> Result<[u8; NETWORK_HEADER_BYTES], NetError> {
    if layers == 0 || layers > MAX_LAYERS || input.is_empty() {
        return Err(NetError::Layer("layer count or input shape out of range"));
    }
    let wide = |n: usize| u16::try_from(n).map_err(|_| NetError::Layer("input shape out of range"));
    let mut h = [0u8; NETWORK_HEADER_BYTES];
    let mut w = crate::format::bytes::Writer::new(&mut h);
    for v in [wide(layers)?, 0, wide(input.h)?, wide(input.w)?, wide(input.c)?, 0] {
        w.u16(v)?;
    }
    Ok(h)
}

/// A validated network inside a byte slice (`docs/init-format.md`, "Network").
#[derive(Debug, Clone, Copy)]
pub struct Network<'a> {
    bytes: &'a [u8],
    layers: usize,
    input: Shape,
    output: Shape,
    largest: usize,
}

impl<'a> Network<'a> {
    /// Reads and checks the network at the start of `bytes`; returns it and its length in bytes.
    pub fn parse(bytes: &'a [u8]) -> Result<(Self, usize), NetError> {
        let mut r = Reader::new(bytes);
        let layers = usize::from(r.u16()?);
        let _reserved = r.u16()?;
        let input = Shape { h: usize::from(r.u16()?), w: usize::from(r.u16()?), c: usize::from(r.u16()?) };
        let _reserved = r.u16()?;
        if layers == 0 || layers > MAX_LAYERS || input.is_empty() {
            return Err(NetError::Layer("layer count or input shape out of range"));
        }
        let mut shape = input;
        let mut largest = input.len();
        for i in 0..layers {
            let layer = Layer::read(&mut r)?;
            let last = i + 1 == layers;
            if last != (layer.out_scale == 0.0) {
                return Err(NetError::Layer("only the last layer has an f32 output (out_scale 0)"));
            }
            shape = layer.shape.output_shape(shape)?;
            largest = largest.max(shape.len());
        }
        let len = r.position();
        let body = bytes.get(..len).ok_or(FormatError::Truncated { needed: len, available: bytes.len() })?;
        Ok((Self { bytes: body, layers, input, output: shape, largest }, len))
    }

    /// The network's bytes (its section of the init file, without padding).
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Shape of the input tensor.
    pub fn input(&self) -> Shape {
        self.input
    }

    /// Shape of the output tensor (`f32`).
    pub fn output(&self) -> Shape {
        self.output
    }

    /// Bytes each of the two scratch buffers needs (the largest `i8` activation).
    pub fn scratch_bytes(&self) -> usize {
        self.largest
    }

    /// Number of layers.
    pub fn layer_count(&self) -> usize {
        self.layers
    }

    /// Multiply-accumulates of one run (for budgets and reports).
    pub fn macs(&self) -> usize {
        let mut shape = self.input;
        let mut total = 0usize;
        for layer in self.layers_iter() {
            let Ok(next) = layer.shape.output_shape(shape) else { break };
            total = total.saturating_add(next.len().saturating_mul(layer.shape.weights_per_output()));
            shape = next;
        }
        total
    }

    /// The layers in order.
    pub fn layers_iter(&self) -> impl Iterator<Item = Layer<'a>> + 'a {
        let mut r = Reader::new(self.bytes);
        let skip = r.take(NETWORK_HEADER_BYTES).is_ok();
        let mut left = if skip { self.layers } else { 0 };
        core::iter::from_fn(move || {
            if left == 0 {
                return None;
            }
            left -= 1;
            Layer::read(&mut r).ok()
        })
    }

    /// Runs the network on the `i8` input held in `scratch.input_mut(..)`; writes the `f32` output.
    pub fn run<const A: usize>(&self, scratch: &mut NetScratch<A>, out: &mut [f32]) -> Result<(), NetError> {
        if self.largest > A {
            return Err(NetError::ScratchTooSmall { needed: self.largest });
        }
        if out.len() != self.output.len() {
            return Err(NetError::LengthMismatch);
        }
        let mut shape = self.input;
        let mut in_a = true;
        for layer in self.layers_iter() {
            let next = layer.shape.output_shape(shape)?;
            let (src, dst) = if in_a { (&scratch.a, &mut scratch.b) } else { (&scratch.b, &mut scratch.a) };
            let src = src.get(..shape.len()).ok_or(NetError::LengthMismatch)?;
            if layer.out_scale == 0.0 {
                layer_forward(&layer, src, shape, next, |i, y| {
                    if let Some(o) = out.get_mut(i) {
                        *o = y;
                    }
                });
            } else {
                let dst = dst.get_mut(..next.len()).ok_or(NetError::LengthMismatch)?;
                let s = layer.out_scale;
                layer_forward(&layer, src, shape, next, |i, y| {
                    if let Some(o) = dst.get_mut(i) {
                        *o = quantize(y, s);
                    }
                });
            }
            in_a = !in_a;
            shape = next;
        }
        Ok(())
    }
}

/// `round(y / scale)` clamped to `i8` (NaN gives 0).
pub fn quantize(y: f32, scale: f32) -> i8 {
    let q = libm::roundf(y / scale);
    // `as` saturates and maps NaN to 0.
    q.clamp(-128.0, 127.0) as i8
}

/// The value of one layer output before quantization, for every output index in order.
fn layer_forward(layer: &Layer<'_>, src: &[i8], input: Shape, output: Shape, mut emit: impl FnMut(usize, f32)) {
    let k = layer.shape.kernel;
    let finish = |acc: i32, o: usize| {
        let y = acc as f32 * layer.multiplier(o) + layer.bias(o);
        if layer.shape.relu {
            y.max(0.0)
        } else {
            y
        }
    };
    match layer.shape.kind {
        LayerKind::Dense => dot_channels(src, layer.weights, layer.shape.cout, |o, acc| emit(o, finish(acc, o))),
        LayerKind::Conv => {
            let pad = k / 2;
            let taps = k * k * layer.shape.cin;
            let mut patch = [0i8; MAX_PATCH];
            let mut i = 0;
            for oy in 0..output.h {
                for ox in 0..output.w {
                    if let Some(patch) = patch.get_mut(..taps) {
                        // The receptive field as one contiguous `[ky][kx][cin]` run, zeros outside
                        // the image: one dot product per output channel, in the weights' order.
                        gather(src, input, layer, (oy, ox), patch);
                        dot_channels(patch, layer.weights, layer.shape.cout, |o, acc| emit(i + o, finish(acc, o)));
                        i += layer.shape.cout;
                        continue;
                    }
                    // The kernel window clipped to the image (zero padding contributes nothing).
                    let y0 = (oy * layer.shape.stride).saturating_sub(pad);
                    let y1 = (oy * layer.shape.stride + k - pad).min(input.h);
                    let x0 = (ox * layer.shape.stride).saturating_sub(pad);
                    let x1 = (ox * layer.shape.stride + k - pad).min(input.w);
                    let ky0 = y0 + pad - oy * layer.shape.stride;
                    let kx0 = x0 + pad - ox * layer.shape.stride;
                    let run = (x1.saturating_sub(x0)) * layer.shape.cin;
                    let row = k * layer.shape.cin;
                    for (o, w) in layer.weights.chunks_exact(taps).enumerate() {
                        let mut acc = 0i32;
                        for (dy, iy) in (y0..y1).enumerate() {
                            let a = src.get((iy * input.w + x0) * layer.shape.cin..).unwrap_or(&[]);
                            let wr = w.get((ky0 + dy) * row + kx0 * layer.shape.cin..).unwrap_or(&[]);
                            acc += dot(a.get(..run).unwrap_or(&[]), wr);
                        }
                        emit(i, finish(acc, o));
                        i += 1;
                    }
                }
            }
        }
    }
}

/// Largest receptive field (`k·k·cin` bytes) gathered into a contiguous patch on the stack
/// (3 × 3 × 64 = 576 in the default networks); larger layers sum row by row from the tensor.
const MAX_PATCH: usize = 1024;

/// Copies the `k × k × cin` receptive field of output `(oy, ox)` into `patch`, zeros outside the image.
fn gather(src: &[i8], input: Shape, layer: &Layer<'_>, (oy, ox): (usize, usize), patch: &mut [i8]) {
    let (k, cin) = (layer.shape.kernel, layer.shape.cin);
    let pad = k / 2;
    for (ky, row) in patch.chunks_exact_mut(k * cin).enumerate() {
        let iy = (oy * layer.shape.stride + ky).checked_sub(pad).filter(|&y| y < input.h);
        for (kx, px) in row.chunks_exact_mut(cin).enumerate() {
            let ix = (ox * layer.shape.stride + kx).checked_sub(pad).filter(|&x| x < input.w);
            let from = iy.zip(ix).and_then(|(y, x)| src.get((y * input.w + x) * cin..(y * input.w + x + 1) * cin));
            match from {
                Some(v) => px.copy_from_slice(v),
                None => px.fill(0),
            }
        }
    }
}

/// `emit(o, Σ a·w_o)` for every output channel `o` of `weights` (`cout` rows of `a.len()`), in
/// order; two channels share each load of `a`. Integer sums: the order does not change them.
fn dot_channels(a: &[i8], weights: &[i8], cout: usize, mut emit: impl FnMut(usize, i32)) {
    let n = a.len();
    if n == 0 {
        (0..cout).for_each(|o| emit(o, 0));
        return;
    }
    let mut rows = weights.chunks_exact(n).take(cout);
    let mut o = 0;
    while o + 2 <= cout {
        let (Some(w0), Some(w1)) = (rows.next(), rows.next()) else { break };
        let (mut s0, mut s1) = (0i32, 0i32);
        for ((&x, &p), &q) in a.iter().zip(w0).zip(w1) {
            let x = i32::from(x);
            s0 += x * i32::from(p);
            s1 += x * i32::from(q);
        }
        emit(o, s0);
        emit(o + 1, s1);
        o += 2;
    }
    for w in rows {
        emit(o, dot(a, w));
        o += 1;
    }
}

/// `Σ a_i·b_i` in `i32` over the shorter of the two.
fn dot(a: &[i8], b: &[i8]) -> i32 {
    a.iter().zip(b).map(|(&x, &y)| i32::from(x) * i32::from(y)).sum()
}

/// The two ping-pong activation buffers of a run, `A` bytes each (size them with
/// [`Network::scratch_bytes`]).
#[derive(Debug, Clone)]
pub struct NetScratch<const A: usize> {
    a: [i8; A],
    b: [i8; A],
}

impl<const A: usize> Default for NetScratch<A> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const A: usize> NetScratch<A> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self { a: [0; A], b: [0; A] }
    }

    /// The first `len` bytes of the input buffer, to fill before [`Network::run`].
    pub fn input_mut(&mut self, len: usize) -> Result<&mut [i8], NetError> {
        self.a.get_mut(..len).ok_or(NetError::ScratchTooSmall { needed: len })
    }
}
