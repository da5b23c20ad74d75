//! Convolution as patches and one matrix product, with candle's autograd: `Patches` gathers the
//! k×k neighbourhoods of a channel-last batch (zero padding `k / 2`, the core's convention) into
//! rows, and its backward pass scatters the rows' gradients back (`ScatterPatches`). The
//! product, the bias and their gradients are candle's own (matrix products through `gemm`).
//!
//! Why not candle's `conv2d`: on the CPU its backward pass computes the input's gradient with a
//! direct transposed convolution, and the forward pass needs NCHW copies of channel-last
//! activations; at batch 64 forward + backward took 12.2 ms a sample for the finder and 7.4 for
//! the initializer (`cargo run --release -p gpmm-train --example step_time`), four fifths of it
//! backward. Here every multiply-add is in a matrix product.

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// The geometry of one convolution over a `[b, h, w, c]` batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Patches {
    /// Batch size.
    pub b: usize,
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Input channels.
    pub c: usize,
    /// Kernel side (odd).
    pub k: usize,
    /// Stride.
    pub stride: usize,
}

impl Patches {
    /// The output's height and width (zero padding `k / 2` on every side).
    pub fn out_hw(&self) -> (usize, usize) {
        let p = self.k / 2;
        ((self.h + 2 * p - self.k) / self.stride + 1, (self.w + 2 * p - self.k) / self.stride + 1)
    }

    /// Length of one row: `k · k · c`, in `[ky][kx][c]` order.
    pub fn row(&self) -> usize {
        self.k * self.k * self.c
    }

    /// Rows: one per output pixel, `b · ho · wo`.
    pub fn rows(&self) -> usize {
        let (ho, wo) = self.out_hw();
        self.b * ho * wo
    }

    /// For every output pixel of one image and every kernel tap inside the image: the row's
    /// offset, the input pixel's offset, both in values.
    fn for_each_tap(&self, mut f: impl FnMut(usize, usize)) {
        let (ho, wo) = self.out_hw();
        let p = self.k / 2;
        for oy in 0..ho {
            for ox in 0..wo {
                let row = (oy * wo + ox) * self.row();
                for ky in 0..self.k {
                    let iy = (oy * self.stride + ky) as isize - p as isize;
                    if iy < 0 || iy >= self.h as isize {
                        continue;
                    }
                    for kx in 0..self.k {
                        let ix = (ox * self.stride + kx) as isize - p as isize;
                        if ix < 0 || ix >= self.w as isize {
                            continue;
                        }
                        f(row + (ky * self.k + kx) * self.c, (iy as usize * self.w + ix as usize) * self.c);
                    }
                }
            }
        }
    }

    /// The rows of `x` (`[b, h, w, c]`) as a `[rows, row]` tensor, with autograd.
    pub fn gather(self, x: &Tensor) -> Result<Tensor> {
        x.contiguous()?.apply_op1(self)
    }
}

fn contiguous_f32<'a>(storage: &'a CpuStorage, layout: &Layout, len: usize) -> Result<&'a [f32]> {
    let values = storage.as_slice::<f32>()?;
    match layout.contiguous_offsets() {
        Some((a, b)) if b - a == len => Ok(&values[a..b]),
        _ => Err(candle_core::Error::Msg(format!("patches: expected {len} contiguous values, layout {layout:?}"))),
    }
}

impl CustomOp1 for Patches {
    fn name(&self) -> &'static str {
        "patches"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let image = self.h * self.w * self.c;
        let x = contiguous_f32(storage, layout, self.b * image)?;
        let per_image = self.rows() / self.b.max(1) * self.row();
        let mut out = vec![0f32; self.rows() * self.row()];
        out.par_chunks_mut(per_image.max(1)).zip(x.par_chunks(image.max(1))).for_each(|(rows, img)| {
            self.for_each_tap(|r, i| rows[r..r + self.c].copy_from_slice(&img[i..i + self.c]));
        });
        Ok((CpuStorage::F32(out), Shape::from((self.rows(), self.row()))))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad_res.contiguous()?.apply_op1_no_bwd(&ScatterPatches(*self))?))
    }
}

/// The adjoint of [`Patches`]: rows' gradients summed back into the `[b, h, w, c]` input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScatterPatches(pub Patches);

impl CustomOp1 for ScatterPatches {
    fn name(&self) -> &'static str {
        "scatter-patches"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let p = self.0;
        let rows = contiguous_f32(storage, layout, p.rows() * p.row())?;
        let image = p.h * p.w * p.c;
        let per_image = p.rows() / p.b.max(1) * p.row();
        let mut out = vec![0f32; p.b * image];
        out.par_chunks_mut(image.max(1)).zip(rows.par_chunks(per_image.max(1))).for_each(|(img, rows)| {
            p.for_each_tap(|r, i| {
                for (o, g) in img[i..i + p.c].iter_mut().zip(&rows[r..r + p.c]) {
                    *o += g;
                }
            });
        });
        Ok((CpuStorage::F32(out), Shape::from((p.b, p.h, p.w, p.c))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// Candle's own convolution of a channel-last batch with `[cout][ky][kx][cin]` weights.
    fn reference(x: &Tensor, w: &Tensor, cout: usize, k: usize, stride: usize) -> Result<Tensor> {
        let c = x.dim(3)?;
        let wk = w.reshape((cout, k, k, c))?.permute((0, 3, 1, 2))?.contiguous()?;
        x.permute((0, 3, 1, 2))?.contiguous()?.conv2d(&wk, k / 2, stride, 1, 1)?.permute((0, 2, 3, 1))?.contiguous()
    }

    fn max_diff(a: &Tensor, b: &Tensor) -> f32 {
        (a - b).unwrap().abs().unwrap().flatten_all().unwrap().max(0).unwrap().to_scalar::<f32>().unwrap()
    }

    #[test]
    fn patches_times_weights_is_the_convolution_forward_and_backward() -> Result<()> {
        let dev = Device::Cpu;
        // Sizes where candle's own backward pass is defined (its transposed convolution cannot give
        // back an input whose padded size minus the kernel is not a multiple of the stride).
        for &(h, w, c, cout, k, stride) in &[(9, 7, 3, 5, 3, 2), (8, 8, 4, 6, 3, 1), (9, 13, 2, 3, 5, 2), (6, 5, 3, 4, 1, 1)] {
            let x = Var::from_tensor(&Tensor::randn(0f32, 1.0, (2, h, w, c), &dev)?)?;
            let wt = Var::from_tensor(&Tensor::randn(0f32, 1.0, (cout, k * k * c), &dev)?)?;
            let p = Patches { b: 2, h, w, c, k, stride };
            let (oh, ow) = p.out_hw();
            let ours = p.gather(x.as_tensor())?.matmul(&wt.as_tensor().t()?)?.reshape((2, oh, ow, cout))?;
            let theirs = reference(x.as_tensor(), wt.as_tensor(), cout, k, stride)?;
            assert_eq!(ours.dims(), theirs.dims(), "{h}x{w} k{k} s{stride}");
            assert!(max_diff(&ours, &theirs) < 1e-4, "forward differs: {}", max_diff(&ours, &theirs));
            // The same loss through both: the gradients of the input and the weights agree.
            let g = Tensor::randn(0f32, 1.0, ours.dims(), &dev)?;
            let ga = (ours * &g)?.sum_all()?.backward()?;
            let gb = (theirs * &g)?.sum_all()?.backward()?;
            for v in [&x, &wt] {
                let (a, b) = (ga.get(v).expect("gradient"), gb.get(v).expect("gradient"));
                assert!(max_diff(a, b) < 1e-3, "gradient differs by {} ({h}x{w} k{k} s{stride})", max_diff(a, b));
            }
        }
        Ok(())
    }

    #[test]
    fn scattering_is_the_adjoint_of_gathering_at_every_size() -> Result<()> {
        // <gather(x), g> = <x, scatter(g)> for any x and g: the backward pass is exact, also where
        // the stride does not divide the padded size (the networks' 96 and 64 px inputs).
        let dev = Device::Cpu;
        for &(h, w, c, k, stride) in &[(8, 8, 3, 3, 2), (11, 6, 2, 5, 2), (7, 9, 4, 3, 1), (5, 5, 1, 1, 2)] {
            let p = Patches { b: 3, h, w, c, k, stride };
            let x = Tensor::randn(0f32, 1.0, (3, h, w, c), &dev)?;
            let g = Tensor::randn(0f32, 1.0, (p.rows(), p.row()), &dev)?;
            let lhs = (p.gather(&x)? * &g)?.sum_all()?.to_scalar::<f32>()?;
            let rhs = (x * g.apply_op1_no_bwd(&ScatterPatches(p))?)?.sum_all()?.to_scalar::<f32>()?;
            assert!((lhs - rhs).abs() < 1e-3 * (1.0 + lhs.abs()), "{lhs} vs {rhs} ({h}x{w} k{k} s{stride})");
        }
        Ok(())
    }

    #[test]
    fn a_wrongly_sized_input_is_an_error_not_a_panic() -> Result<()> {
        let x = Tensor::zeros((1, 4, 4, 2), candle_core::DType::F32, &Device::Cpu)?;
        let wrong = Patches { b: 1, h: 5, w: 4, c: 2, k: 3, stride: 1 };
        assert!(wrong.gather(&x).is_err());
        Ok(())
    }
}
