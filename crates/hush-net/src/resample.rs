//! The U-Net's 2×2 max pooling and its decoder input (nearest ×2 upsampling concatenated with the skip
//! tensor), as single CPU passes that run over image planes in parallel, with their gradients.
//!
//! Candle's `max_pool2d`, a broadcast upsampling and `Tensor::cat` walk strided indices on one thread, while
//! the convolutions run on every core (512² `unet` inference, `hush bench inference`, 2 threads, idle:
//! 0.67–0.69 s with them, 0.53–0.56 s with these). Elsewhere (CUDA, other dtypes) the functions below are
//! built from candle ops with the same values and gradients.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, DType, Layout, Result, Shape, Tensor, bail};
use rayon::prelude::*;

use crate::conv::{f32_data, output_buffer};

/// 2×2 max pooling with stride 2 of an NCHW tensor (odd trailing rows and columns are dropped, as in
/// candle's `max_pool2d`). The gradient goes to the maximum of each window: on the CPU to the first of tied
/// maxima in row-major order (PyTorch's choice), elsewhere to each of them. (Candle 0.11's own
/// `max_pool2d` backward multiplies by the share of maxima in the window, 1/4 without ties, where it
/// should divide by their count; neither path uses it.)
pub fn max_pool2(x: &Tensor) -> Result<Tensor> {
    if x.device().is_cpu() && x.dtype() == DType::F32 {
        x.contiguous()?.apply_op1(MaxPool2)
    } else {
        max_pool2_reduce(x)
    }
}

/// [`max_pool2`] from candle's max reductions over the window axes, whose backward passes the gradient
/// to the elements equal to the maximum.
fn max_pool2_reduce(x: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    let (oh, ow) = (h / 2, w / 2);
    let x = x.narrow(2, 0, 2 * oh)?.narrow(3, 0, 2 * ow)?.contiguous()?;
    x.reshape((n, c, oh, 2, ow, 2))?.max_keepdim(5)?.max_keepdim(3)?.reshape((n, c, oh, ow))
}

/// Nearest-neighbour ×2 upsampling from reshape + broadcast, whose gradients are plain sums.
/// (`Tensor::upsample_nearest2d`'s backward is a grouped convolution with one group per channel,
/// slow on the CPU, and it overwrites rather than accumulates its input's gradient.)
pub fn upsample2(x: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    x.reshape((n, c, h, 1, w, 1))?.broadcast_as((n, c, h, 2, w, 2))?.reshape((n, c, 2 * h, 2 * w))
}

/// `[upsample2(low), skip]` along the channels: nearest-neighbour ×2 upsampling of `low` (`N × C1 × H × W`)
/// concatenated with `skip` (`N × C2 × 2H × 2W`).
pub fn upsample2_cat(low: &Tensor, skip: &Tensor) -> Result<Tensor> {
    check_upsample2_cat(low.shape(), skip.shape())?;
    let cpu_f32 = low.device().is_cpu() && low.dtype() == DType::F32 && skip.dtype() == DType::F32;
    if cpu_f32 {
        low.contiguous()?.apply_op2(&skip.contiguous()?, Upsample2Cat)
    } else {
        Tensor::cat(&[&upsample2(low)?, skip], 1)
    }
}

/// `skip` must be as many images of twice the height and width of `low`.
fn check_upsample2_cat(low: &Shape, skip: &Shape) -> Result<()> {
    let (n, _, h, w) = low.dims4()?;
    let (sn, _, sh, sw) = skip.dims4()?;
    if (sn, sh, sw) != (n, 2 * h, 2 * w) {
        bail!("upsample2_cat: skip {:?} does not fit twice the size of {:?}", skip.dims(), low.dims())
    }
    Ok(())
}

struct MaxPool2;

impl CustomOp1 for MaxPool2 {
    fn name(&self) -> &'static str {
        "hush-max-pool2"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (n, c, h, w) = l.shape().dims4()?;
        let x = f32_data(s, l, "max_pool2 input")?;
        let (oh, ow) = (h / 2, w / 2);
        let mut y = output_buffer(n * c * oh * ow);
        if oh * ow > 0 {
            y.par_chunks_mut(oh * ow).zip(x.par_chunks(h * w)).for_each(|(out, plane)| {
                for (oy, row) in out.chunks_mut(ow).enumerate() {
                    let (r0, r1) = (&plane[2 * oy * w..][..w], &plane[(2 * oy + 1) * w..][..w]);
                    for (ox, o) in row.iter_mut().enumerate() {
                        *o = r0[2 * ox].max(r0[2 * ox + 1]).max(r1[2 * ox]).max(r1[2 * ox + 1]);
                    }
                }
            });
        }
        Ok((CpuStorage::F32(y), Shape::from((n, c, oh, ow))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(arg.detach().apply_op2_no_bwd(&grad.detach().contiguous()?, &MaxPool2Grad)?))
    }
}

/// [`MaxPool2`]'s backward from the pooled input (first argument) and the output gradient (second).
struct MaxPool2Grad;

impl CustomOp2 for MaxPool2Grad {
    fn name(&self) -> &'static str {
        "hush-max-pool2-grad"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (n, c, h, w) = l1.shape().dims4()?;
        let (oh, ow) = (h / 2, w / 2);
        if l2.shape().dims4()? != (n, c, oh, ow) {
            bail!("max_pool2 gradient {:?} does not fit input {:?}", l2.shape(), l1.shape())
        }
        let (x, g) = (f32_data(s1, l1, "max_pool2 input")?, f32_data(s2, l2, "max_pool2 gradient")?);
        let mut dx = vec![0f32; n * c * h * w];
        if oh * ow > 0 {
            dx.par_chunks_mut(h * w).zip(x.par_chunks(h * w).zip(g.par_chunks(oh * ow))).for_each(
                |(dplane, (plane, gplane))| {
                    for oy in 0..oh {
                        for ox in 0..ow {
                            let at = [2 * oy * w + 2 * ox, 2 * oy * w + 2 * ox + 1, (2 * oy + 1) * w + 2 * ox];
                            let mut best = (2 * oy + 1) * w + 2 * ox + 1;
                            // The first maximum in row-major order: scan backwards, keep ties earlier.
                            for &i in at.iter().rev() {
                                if plane[i] >= plane[best] {
                                    best = i;
                                }
                            }
                            dplane[best] = gplane[oy * ow + ox];
                        }
                    }
                },
            );
        }
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

struct Upsample2Cat;

impl CustomOp2 for Upsample2Cat {
    fn name(&self) -> &'static str {
        "hush-upsample2-cat"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        // The output is written in full only for a skip of the right size.
        check_upsample2_cat(l1.shape(), l2.shape())?;
        let (n, c1, h, w) = l1.shape().dims4()?;
        let (_, c2, oh, ow) = l2.shape().dims4()?;
        let (low, skip) = (f32_data(s1, l1, "upsample2_cat input")?, f32_data(s2, l2, "upsample2_cat skip")?);
        let c = c1 + c2;
        let plane = oh * ow;
        let mut y = output_buffer(n * c * plane);
        if plane > 0 {
            y.par_chunks_mut(plane).enumerate().for_each(|(p, out)| {
                let (i, ch) = (p / c, p % c);
                if ch < c1 {
                    let src = &low[(i * c1 + ch) * h * w..][..h * w];
                    for (y2, row) in out.chunks_mut(ow).enumerate() {
                        for (o, &v) in row.chunks_mut(2).zip(&src[y2 / 2 * w..][..w]) {
                            o.fill(v);
                        }
                    }
                } else {
                    out.copy_from_slice(&skip[(i * c2 + ch - c1) * plane..][..plane]);
                }
            });
        }
        Ok((CpuStorage::F32(y), Shape::from((n, c, oh, ow))))
    }

    fn bwd(
        &self,
        low: &Tensor,
        skip: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (_, c1, _, _) = low.dims4()?;
        let (_, c2, _, _) = skip.dims4()?;
        let grad = grad.detach().contiguous()?;
        let grad_low = grad.apply_op1_no_bwd(&SumPool2 { channels: c1 })?;
        let grad_skip = grad.narrow(1, c1, c2)?.contiguous()?;
        Ok((Some(grad_low), Some(grad_skip)))
    }
}

/// The upsampling's backward: the sum over each 2×2 window of the first `channels` channels of an NCHW
/// gradient.
struct SumPool2 {
    channels: usize,
}

impl CustomOp1 for SumPool2 {
    fn name(&self) -> &'static str {
        "hush-sum-pool2"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (n, c, h, w) = l.shape().dims4()?;
        let c1 = self.channels;
        let g = f32_data(s, l, "upsample2 gradient")?;
        let (oh, ow) = (h / 2, w / 2);
        let mut dx = output_buffer(n * c1 * oh * ow);
        if oh * ow > 0 {
            dx.par_chunks_mut(oh * ow).enumerate().for_each(|(p, out)| {
                let plane = &g[((p / c1) * c + p % c1) * h * w..][..h * w];
                for (oy, row) in out.chunks_mut(ow).enumerate() {
                    let (r0, r1) = (&plane[2 * oy * w..][..w], &plane[(2 * oy + 1) * w..][..w]);
                    for (ox, o) in row.iter_mut().enumerate() {
                        *o = (r0[2 * ox] + r0[2 * ox + 1]) + (r1[2 * ox] + r1[2 * ox + 1]);
                    }
                }
            });
        }
        Ok((CpuStorage::F32(dx), Shape::from((n, c1, oh, ow))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn max_diff(a: &Tensor, b: &Tensor) -> Result<f32> {
        (a - b)?.abs()?.max_all()?.to_scalar::<f32>()
    }

    /// Values equal candle's `max_pool2d` on even and odd sizes; the gradient is the probe at each window's
    /// maximum, zero elsewhere. (Candle 0.11's own backward multiplies by the share of maxima in the
    /// window, 1/4 without ties, where it should divide by their count: a quarter of the gradient.)
    #[test]
    fn max_pool2_matches_candle_and_routes_the_gradient_to_the_maximum() -> Result<()> {
        let dev = Device::Cpu;
        for (n, c, h, w) in [(2, 3, 4, 6), (1, 2, 5, 7), (1, 1, 3, 2)] {
            let x = Var::from_tensor(&Tensor::randn(0f32, 1.0, (n, c, h, w), &dev)?)?;
            let ours = max_pool2(&x)?;
            assert_eq!(max_diff(&ours, &x.max_pool2d(2)?)?, 0.0, "values for {:?}", (n, c, h, w));
            let probe = Tensor::randn(0f32, 1.0, ours.dims(), &dev)?;
            let grads = (ours * &probe)?.sum_all()?.backward()?;
            let got = grads.get(&x).expect("grad").flatten_all()?.to_vec1::<f32>()?;
            let (xs, ps) = (x.flatten_all()?.to_vec1::<f32>()?, probe.flatten_all()?.to_vec1::<f32>()?);
            let (oh, ow) = (h / 2, w / 2);
            let mut want = vec![0f32; xs.len()];
            for plane in 0..n * c {
                for (oy, ox) in (0..oh).flat_map(|oy| (0..ow).map(move |ox| (oy, ox))) {
                    let window = [(0, 0), (0, 1), (1, 0), (1, 1)]
                        .map(|(dy, dx)| plane * h * w + (2 * oy + dy) * w + 2 * ox + dx);
                    // The first maximum: a later element must be strictly greater to win.
                    let best = window.into_iter().reduce(|a, b| if xs[b] > xs[a] { b } else { a }).expect("four");
                    want[best] = ps[(plane * oh + oy) * ow + ox];
                }
            }
            assert_eq!(got, want, "gradient for {:?}", (n, c, h, w));
        }
        Ok(())
    }

    /// The candle-ops path (other devices) has the CPU op's values and gradient (no ties in random data).
    #[test]
    fn max_pool2_from_reductions_matches_the_cpu_op() -> Result<()> {
        let dev = Device::Cpu;
        for dims in [(2, 3, 4, 6), (1, 2, 5, 7)] {
            let x = Var::from_tensor(&Tensor::randn(0f32, 1.0, dims, &dev)?)?;
            let (ours, reduced) = (max_pool2(&x)?, max_pool2_reduce(&x)?);
            assert_eq!(max_diff(&ours, &reduced)?, 0.0, "values for {dims:?}");
            let probe = Tensor::randn(0f32, 1.0, ours.dims(), &dev)?;
            let g_ours = (ours * &probe)?.sum_all()?.backward()?;
            let g_reduced = (reduced * &probe)?.sum_all()?.backward()?;
            let (a, b) = (g_ours.get(&x).expect("grad"), g_reduced.get(&x).expect("grad"));
            assert_eq!(max_diff(a, b)?, 0.0, "gradient for {dims:?}");
        }
        Ok(())
    }

    /// A tied window sends its whole gradient to the first maximum, once.
    #[test]
    fn max_pool2_gradient_goes_to_the_first_of_tied_maxima() -> Result<()> {
        let dev = Device::Cpu;
        let x = Var::from_tensor(&Tensor::new(&[[[[1f32, 2.0], [2.0, 0.0]]]], &dev)?)?;
        let grads = (max_pool2(&x)? * 3.0)?.sum_all()?.backward()?;
        let g = grads.get(&x).expect("grad").flatten_all()?.to_vec1::<f32>()?;
        assert_eq!(g, [0.0, 3.0, 0.0, 0.0]);
        Ok(())
    }

    /// Values and both gradients equal the broadcast upsampling and `Tensor::cat`.
    #[test]
    fn upsample2_cat_matches_candle_with_gradients() -> Result<()> {
        let dev = Device::Cpu;
        for (n, c1, c2, h, w) in [(2, 3, 2, 2, 3), (1, 1, 4, 1, 1), (1, 2, 1, 3, 2)] {
            let low = Var::from_tensor(&Tensor::randn(0f32, 1.0, (n, c1, h, w), &dev)?)?;
            let skip = Var::from_tensor(&Tensor::randn(0f32, 1.0, (n, c2, 2 * h, 2 * w), &dev)?)?;
            let ours = upsample2_cat(&low, &skip)?;
            let theirs = Tensor::cat(&[&upsample2(&low)?, skip.as_tensor()], 1)?;
            assert_eq!(max_diff(&ours, &theirs)?, 0.0);
            let probe = Tensor::randn(0f32, 1.0, ours.dims(), &dev)?;
            let g_ours = (ours * &probe)?.sum_all()?.backward()?;
            let g_theirs = (theirs * &probe)?.sum_all()?.backward()?;
            for v in [&low, &skip] {
                let (a, e) = (g_ours.get(v).expect("grad"), g_theirs.get(v).expect("grad"));
                // Sums of four in another order may differ in the last bit.
                assert!(max_diff(a, e)? < 1e-6, "gradient of {:?}", v.dims());
            }
        }
        Ok(())
    }

    #[test]
    fn upsample2_cat_refuses_a_skip_of_another_size() -> Result<()> {
        let dev = Device::Cpu;
        let low = Tensor::zeros((1, 2, 3, 3), DType::F32, &dev)?;
        let skip = Tensor::zeros((1, 1, 6, 5), DType::F32, &dev)?;
        let err = upsample2_cat(&low, &skip).expect_err("a mismatched skip").to_string();
        assert!(err.contains("does not fit"), "{err}");
        Ok(())
    }
}
