//! 3×3 convolutions (stride 1, padding 1) with bias and an optional ReLU, on the CPU: Winograd's
//! F(4×4, 3×3) where both channel counts are ≥ 16 ([`winograd`]), for the forward pass and (by the
//! transposed algorithm) the weight gradient; banded im2col + GEMM otherwise, with the bias and the
//! activation fused in.
//!
//! The output rows are cut into bands (a few rows of every output channel); bands run in parallel, each
//! one im2col copy of its rows (`9·C` rows of contiguous row copies, about 1 MiB, so it stays in cache)
//! and one single-threaded GEMM (`gemm` crate, what candle's matmul uses) `[Co × 9C] · [9C × band]`
//! written straight into the output, whose bias and ReLU are then applied while the band is in cache.
//! Every output element comes from exactly one GEMM call, so the result does not depend on the thread
//! count. (Candle's own conv2d im2cols the whole image pixel by pixel, multiplies and then transposes
//! the result into place: about 2–3× slower per layer here.)
//!
//! The im2col weight gradient is the same GEMM the other way round, `[Co × band] · [band × 9C]`, summed
//! over bands in a fixed grouping and order (deterministic again); the input gradient is the forward
//! convolution of the output gradient with the kernel rotated by 180° and its in/out channels swapped.
//!
//! Elsewhere (CUDA, other dtypes) [`conv3x3`] uses candle's own `conv2d`.

use candle_core::{CpuStorage, CustomOp2, CustomOp3, DType, Layout, Result, Shape, Tensor, bail};
use rayon::prelude::*;

/// `relu?(conv2d(x, weight, padding 1) + bias)` for NCHW `x`, OIHW `weight` (`Co × C × 3 × 3`) and `bias`
/// (`Co`). Differentiable in all three.
pub fn conv3x3(x: &Tensor, weight: &Tensor, bias: &Tensor, relu: bool) -> Result<Tensor> {
    let (_, c, _, _) = x.dims4()?;
    let (co, wc, kh, kw) = weight.dims4()?;
    if (wc, kh, kw) != (c, 3, 3) || bias.dims1()? != co {
        bail!(
            "conv3x3: input {:?}, weight {:?}, bias {:?} do not fit a 3x3 convolution",
            x.dims(),
            weight.dims(),
            bias.dims()
        )
    }
    let all_f32 = [x, weight, bias].iter().all(|t| t.dtype() == DType::F32);
    if x.device().is_cpu() && all_f32 {
        x.contiguous()?.apply_op3(&weight.contiguous()?, &bias.contiguous()?, Conv3x3Op { relu })
    } else {
        let y = x.conv2d(weight, 1, 1, 1, 1)?.broadcast_add(&bias.reshape((1, co, 1, 1))?)?;
        if relu { y.relu() } else { Ok(y) }
    }
}

/// The fused forward op behind [`conv3x3`] on the CPU.
struct Conv3x3Op {
    relu: bool,
}

/// The weight gradient `dL/dW` from the input (first argument) and the gradient at the convolution's
/// output before the activation (second argument).
struct WeightGradOp;

/// The contiguous f32 data of a CPU tensor argument.
pub(crate) fn f32_data<'a>(storage: &'a CpuStorage, layout: &Layout, what: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(data) = storage else { bail!("{what} must be f32") };
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{what} must be contiguous") };
    Ok(&data[start..end])
}

impl CustomOp3 for Conv3x3Op {
    fn name(&self) -> &'static str {
        "hush-conv3x3"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (n, c, h, w) = l1.shape().dims4()?;
        let (co, wc, kh, kw) = l2.shape().dims4()?;
        // The output is written in full (it is not cleared first) only for weights and a bias that fit.
        if (wc, kh, kw) != (c, 3, 3) || l3.shape().dims1()? != co {
            bail!(
                "conv3x3: input {:?}, weight {:?}, bias {:?} do not fit a 3x3 convolution",
                l1.shape(),
                l2.shape(),
                l3.shape()
            )
        }
        let geom = Geometry { c, h, w };
        let x = f32_data(s1, l1, "conv3x3 input")?;
        let weight = f32_data(s2, l2, "conv3x3 weight")?;
        let bias = f32_data(s3, l3, "conv3x3 bias")?;
        let y = if use_winograd(c, co) {
            winograd::F4.forward(&geom, n, x, weight, bias, co, self.relu)
        } else {
            forward(&geom, n, x, weight, bias, co, self.relu)
        };
        Ok((CpuStorage::F32(y), Shape::from((n, co, h, w))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        weight: &Tensor,
        bias: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        // Everything here is detached: `y` belongs to the forward graph, and a gradient that kept a
        // reference to it would keep every activation of the step alive in the optimizer's state.
        let grad = grad.detach().contiguous()?;
        // The gradient before the activation: ReLU passes it where the output is positive.
        let grad = if self.relu { grad.apply_op2_no_bwd(&y.detach(), &ReluGradOp)? } else { grad };
        // d/dx: the convolution of the gradient with the kernel rotated by 180° and transposed to
        // (in, out, 3, 3). Skipped when nothing upstream needs it (the network's input).
        let grad_x = if x.track_op() {
            let rev = Tensor::new(&[2u32, 1, 0], weight.device())?;
            let w_rot = weight.detach().transpose(0, 1)?.contiguous()?.index_select(&rev, 2)?.index_select(&rev, 3)?;
            let zero = Tensor::zeros(w_rot.dims()[0], DType::F32, weight.device())?;
            Some(grad.apply_op3_no_bwd(&w_rot.contiguous()?, &zero, &Conv3x3Op { relu: false })?)
        } else {
            None
        };
        let grad_w = if weight.track_op() { Some(x.detach().apply_op2_no_bwd(&grad, &WeightGradOp)?) } else { None };
        let grad_b = if bias.track_op() { Some(grad.apply_op1_no_bwd(&ChannelSumOp)?) } else { None };
        Ok((grad_x, grad_w, grad_b))
    }
}

impl CustomOp2 for WeightGradOp {
    fn name(&self) -> &'static str {
        "hush-conv3x3-weight-grad"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (n, c, h, w) = l1.shape().dims4()?;
        let (gn, co, gh, gw) = l2.shape().dims4()?;
        if (gn, gh, gw) != (n, h, w) {
            bail!("conv3x3: gradient {:?} does not fit input {:?}", l2.shape(), l1.shape())
        }
        let geom = Geometry { c, h, w };
        let (x, grad) = (f32_data(s1, l1, "conv3x3 input")?, f32_data(s2, l2, "conv3x3 gradient")?);
        let dw = if use_winograd(c, co) {
            winograd::F4.weight_grad(&geom, n, x, grad, co)
        } else {
            weight_grad(&geom, n, x, grad, co)
        };
        Ok((CpuStorage::F32(dw), Shape::from((co, c, 3, 3))))
    }
}

/// ReLU's backward in one pass: the gradient (first argument) where the output (second) is positive.
/// (As tensor ops, a comparison, a conversion and a product: three passes and two temporaries.)
struct ReluGradOp;

impl CustomOp2 for ReluGradOp {
    fn name(&self) -> &'static str {
        "hush-relu-grad"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (grad, y) = (f32_data(s1, l1, "relu gradient")?, f32_data(s2, l2, "relu output")?);
        if grad.len() != y.len() {
            bail!("relu gradient: {:?} does not fit {:?}", l1.shape(), l2.shape())
        }
        let out = grad.iter().zip(y).map(|(&g, &v)| if v > 0.0 { g } else { 0.0 }).collect();
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }
}

/// The bias gradient: the sum of an NCHW gradient over everything but its channels, in one pass. (Candle's
/// `sum((0, 2, 3))` walks a strided index per element: 10 % of a training step here.)
struct ChannelSumOp;

impl candle_core::CustomOp1 for ChannelSumOp {
    fn name(&self) -> &'static str {
        "hush-channel-sum"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (_, co, h, w) = l.shape().dims4()?;
        let mut sums = vec![0f32; co];
        for (plane, values) in f32_data(s, l, "bias gradient")?.chunks(h * w).enumerate() {
            sums[plane % co] += values.iter().sum::<f32>();
        }
        Ok((CpuStorage::F32(sums), Shape::from(co)))
    }
}

/// Channels and size of one input image.
struct Geometry {
    c: usize,
    h: usize,
    w: usize,
}

impl Geometry {
    /// Output rows per band: enough columns for an efficient GEMM, an im2col block of about 1 MiB
    /// (`9·C` rows of f32) so that it stays in cache ([`rows_per_band`]).
    fn band_rows(&self) -> usize {
        let target_cols = ((1usize << 20) / (36 * self.c)).max(256);
        rows_per_band(target_cols, self.w, self.h)
    }

    /// The bands `(image, first row, rows)` of a batch of `n` images.
    fn bands(&self, n: usize) -> Vec<(usize, usize, usize)> {
        bands(n, self.h, self.band_rows())
    }

    /// The im2col block of the output rows `y0..y0+rows` of one image (`C × H × W`): `9·C` rows of
    /// `rows·W` columns, row `ci·9 + ky·3 + kx` (the OIHW weight order) holding input pixel
    /// `(y + ky − 1, x + kx − 1)` of channel `ci` for output pixel `(y, x)`, zero outside the image.
    fn im2col(&self, image: &[f32], y0: usize, rows: usize, out: &mut Vec<f32>) {
        let (h, w) = (self.h, self.w);
        // Every element is written below (zeros included): resizing a reused buffer needs no clearing.
        out.resize(9 * self.c * rows * w, 0.0);
        for (r, block) in out.chunks_mut(rows * w).enumerate() {
            let (ci, ky, kx) = (r / 9, r % 9 / 3, r % 3);
            let channel = &image[ci * h * w..(ci + 1) * h * w];
            for (dy, dst) in block.chunks_mut(w).enumerate() {
                let Some(sy) = (y0 + dy + ky).checked_sub(1).filter(|&sy| sy < h) else {
                    dst.fill(0.0);
                    continue;
                };
                let src = &channel[sy * w..(sy + 1) * w];
                match kx {
                    0 => {
                        dst[0] = 0.0;
                        dst[1..].copy_from_slice(&src[..w - 1]);
                    }
                    1 => dst.copy_from_slice(src),
                    _ => {
                        dst[..w - 1].copy_from_slice(&src[1..]);
                        dst[w - 1] = 0.0;
                    }
                }
            }
        }
    }
}

/// Rows (of pixels, or of Winograd tiles) per band: about `target` units of `row_len` each, and at least 4
/// bands per image where possible, so that two or more threads share small images.
fn rows_per_band(target: usize, row_len: usize, rows: usize) -> usize {
    (target / row_len).clamp(1, rows.div_ceil(4).max(1))
}

/// The bands `(image, first row, rows)` of `n` images of `rows` rows, `per_band` rows each (the last fewer).
fn bands(n: usize, rows: usize, per_band: usize) -> Vec<(usize, usize, usize)> {
    (0..n).flat_map(|i| (0..rows).step_by(per_band).map(move |r0| (i, r0, per_band.min(rows - r0)))).collect()
}

/// A raw pointer that bands (and `direct`'s tasks) may share because each writes disjoint elements.
#[derive(Clone, Copy)]
pub(crate) struct SharedMut(pub(crate) *mut f32);
// SAFETY: used only to write disjoint elements from different threads (see `forward` and the call sites
// in `direct`).
#[allow(unsafe_code)]
unsafe impl Send for SharedMut {}
#[allow(unsafe_code)]
unsafe impl Sync for SharedMut {}

impl SharedMut {
    /// The pointer (a method, so that closures capture the whole `Send` wrapper, not its field).
    pub(crate) fn get(self) -> *mut f32 {
        self.0
    }
}

/// A buffer of `len` values for an output that the caller writes in full before anything reads it: no
/// clearing pass over memory that is about to be overwritten. Measured with `hush bench inference`
/// (512² `unet`, 2 threads, alternating, idle): 0.52–0.56 s with zeroed outputs, 0.50–0.51 s with these.
#[allow(unsafe_code, clippy::uninit_vec)]
pub(crate) fn output_buffer(len: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(len);
    // SAFETY: the elements are uninitialized. That is sound only because every caller writes each of them
    // before anything reads it: the convolutions (after checking that weight and bias fit) write every
    // output row of every channel once, the resampling ops every output element (after checking shapes),
    // and `direct`'s operations every interior element of their outputs (whose borders they zero).
    // Candle's CPU backend allocates its own outputs the same way.
    unsafe { v.set_len(len) };
    v
}

/// `dst (m × n, row stride dst_rs) = a (m × k, row-major, row stride a_rs) · b (k × n)` with `b` given
/// by its row and column strides; single-threaded.
///
/// # Safety
/// Every index the strides reach must lie inside the allocations behind the pointers, and `dst` must not
/// alias `a` or `b` or be written by another thread at the same elements.
#[allow(unsafe_code, clippy::too_many_arguments)]
unsafe fn sgemm(
    (m, n, k): (usize, usize, usize),
    dst: *mut f32,
    dst_rs: usize,
    accumulate: bool,
    a: *const f32,
    a_rs: usize,
    b: *const f32,
    (b_rs, b_cs): (usize, usize),
) {
    // SAFETY: forwarded to the caller.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst,
            1,
            dst_rs as isize,
            accumulate,
            a,
            1,
            a_rs as isize,
            b,
            b_cs as isize,
            b_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        )
    }
}

/// The forward convolution of a batch of `n` NCHW images: `n × co × H × W`, bias added, ReLU'd if asked.
/// Each band's GEMM writes its rows of every output channel, then adds the bias and applies the
/// activation while they are in cache.
fn forward(geom: &Geometry, n: usize, x: &[f32], weight: &[f32], bias: &[f32], co: usize, relu: bool) -> Vec<f32> {
    let (c, h, w) = (geom.c, geom.h, geom.w);
    // Each band's GEMM writes its rows of every output channel in full.
    let mut y = output_buffer(n * co * h * w);
    let out = SharedMut(y.as_mut_ptr());
    geom.bands(n).into_par_iter().for_each_init(Vec::new, |cols_buf, (i, y0, rows)| {
        geom.im2col(&x[i * c * h * w..(i + 1) * c * h * w], y0, rows, cols_buf);
        let cols = rows * w;
        #[allow(unsafe_code)]
        // SAFETY: the destination is image i's rows y0..y0+rows of every output channel (row stride H·W
        // between channels), inside `y` and touched by no other band; `weight` is co × 9c and `cols_buf`
        // 9c × cols, both row-major.
        unsafe {
            let dst = out.get().add(i * co * h * w + y0 * w);
            sgemm((co, cols, 9 * c), dst, h * w, false, weight.as_ptr(), 9 * c, cols_buf.as_ptr(), (cols, 1));
            for (o, &b) in bias.iter().enumerate() {
                let band = std::slice::from_raw_parts_mut(dst.add(o * h * w), cols);
                for v in band {
                    *v += b;
                    if relu {
                        *v = v.max(0.0);
                    }
                }
            }
        }
    });
    y
}

/// Whether a layer's convolutions (forward, and so the input gradient, and the weight gradient) take
/// [`winograd`] (F(4×4, 3×3)): 4× fewer multiplications, but GEMMs with only `C` (not `9·C`) as inner
/// dimension in the forward pass, which is inefficient for the first layers' few channels.
fn use_winograd(c: usize, co: usize) -> bool {
    c >= WINOGRAD_MIN_CHANNELS && co >= WINOGRAD_MIN_CHANNELS
}

/// See [`use_winograd`].
const WINOGRAD_MIN_CHANNELS: usize = 16;

/// Winograd's minimal filtering F(m×m, 3×3) (Lavin and Gray, "Fast Algorithms for Convolutional Neural
/// Networks", 2016): each m×m output tile is `Aᵀ [(G g Gᵀ) ⊙ (Bᵀ d B)] A` for the (m+2)×(m+2) input tile
/// `d` around it, and the element-wise products summed over input channels are `(m+2)²` GEMMs
/// `U[ξ] (Co × C) · V[ξ] (C × tiles)`. Bands of tile rows run in parallel as in the im2col path; every
/// output element still comes from one band, so the result does not depend on the thread count.
mod winograd {
    use super::{Geometry, SharedMut, bands, rows_per_band, sgemm};
    use rayon::prelude::*;

    /// The transforms of one F(M×M, 3×3), `A = M + 2`.
    pub(super) struct Variant<const M: usize, const A: usize> {
        bt: [[f32; A]; A],
        g: [[f32; 3]; A],
        at: [[f32; A]; M],
    }

    /// F(2×2, 3×3): 2.25× fewer multiplications than direct convolution, exact up to f32 rounding of
    /// sums of four terms. Measured slower than [`F4`] in the network (512² `unet` inference, one
    /// thread: 1.86 against 1.42 CPU-seconds), so the tests alone use it, as a second derivation.
    #[cfg(test)]
    pub(super) const F2: Variant<2, 4> = Variant {
        bt: [[1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 1.0, 0.0], [0.0, -1.0, 1.0, 0.0], [0.0, 1.0, 0.0, -1.0]],
        g: [[1.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5], [0.0, 0.0, 1.0]],
        at: [[1.0, 1.0, 1.0, 0.0], [0.0, 1.0, -1.0, -1.0]],
    };

    /// F(4×4, 3×3): 4× fewer multiplications; its larger coefficients (up to 8 and 1/24) cost about a
    /// decimal digit of f32 precision, which the tests bound.
    pub(super) const F4: Variant<4, 6> = Variant {
        bt: [
            [4.0, 0.0, -5.0, 0.0, 1.0, 0.0],
            [0.0, -4.0, -4.0, 1.0, 1.0, 0.0],
            [0.0, 4.0, -4.0, -1.0, 1.0, 0.0],
            [0.0, -2.0, -1.0, 2.0, 1.0, 0.0],
            [0.0, 2.0, -1.0, -2.0, 1.0, 0.0],
            [0.0, 4.0, 0.0, -5.0, 0.0, 1.0],
        ],
        g: [
            [1.0 / 4.0, 0.0, 0.0],
            [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
            [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
            [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
            [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
            [0.0, 0.0, 1.0],
        ],
        at: [
            [1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
            [0.0, 1.0, -1.0, 2.0, -2.0, 0.0],
            [0.0, 1.0, 1.0, 4.0, 4.0, 0.0],
            [0.0, 1.0, -1.0, 8.0, -8.0, 1.0],
        ],
    };

    /// Runs `f` compiled for AVX-512 where the CPU has it, else as built (baseline x86-64 vectors: SSE2).
    /// The transforms below are inlined into it (`#[inline(always)]`), so their fixed 16-wide blocks become
    /// single AVX-512 instructions; the GEMMs choose their kernels at run time themselves.
    #[inline(always)]
    fn with_simd<R>(f: impl FnOnce() -> R) -> R {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            #[target_feature(enable = "avx512f")]
            fn avx512<R>(f: impl FnOnce() -> R) -> R {
                f()
            }
            // SAFETY: the CPU has AVX-512F, checked just above.
            #[allow(unsafe_code)]
            return unsafe { avx512(f) };
        }
        f()
    }

    /// Splits a row by phase: column `p = x + pad` (`pad` is 1 for an input row, whose tiles start one
    /// column before the image, and 0 for a gradient row) goes to element `p div M` of phase `p mod M`
    /// (phases `phase` apart in `row`; elements no column reaches are left as they are). A strided copy
    /// per phase, without per-element index arithmetic.
    #[inline(always)]
    fn split_row<const M: usize>(src: &[f32], row: &mut [f32], phase: usize, pad: usize) {
        // Tiles t0..t1 of every phase, one strided copy each.
        let strided = |row: &mut [f32], t0: usize, t1: usize| {
            for (r, dst) in row.chunks_mut(phase).enumerate().take(M) {
                // p = M·t + r, so x = M·t + r − pad (phase r < pad has no tile 0 column: the padding).
                let t0 = t0.max(usize::from(r < pad));
                if t0 < t1 {
                    let from = src.iter().skip(M * t0 + r - pad).step_by(M);
                    for (d, &e) in dst[t0..t1].iter_mut().zip(from) {
                        *d = e;
                    }
                }
            }
        };
        // For F(4×4, 3×3), blocks of 16 tiles after the first: 64 columns read at once and shuffled
        // into the four phases (vectorized). Block b covers x = 64b − pad .. 64b + 64 − pad.
        let mut blocks_end = 0;
        if M == 4 {
            let blocks = (1..phase / 16).take_while(|b| 64 * b + 64 - pad <= src.len());
            for b in blocks {
                let block: &[f32; 64] = src[64 * b - pad..64 * b + 64 - pad].try_into().expect("64 columns");
                for r in 0..4 {
                    let dst: &mut [f32; 16] = (&mut row[r * phase + 16 * b..][..16]).try_into().expect("16 tiles");
                    for (t, d) in dst.iter_mut().enumerate() {
                        *d = block[4 * t + r];
                    }
                }
                blocks_end = 16 * (b + 1);
            }
        }
        if blocks_end > 0 {
            strided(row, 0, 16);
            strided(row, blocks_end, phase);
        } else {
            strided(row, 0, phase);
        }
    }

    /// The inverse of [`split_row`] for an output row: column `M·t + k` from element `t` of phase `k`
    /// (phases `phase` apart), ReLU'd if asked. For F(4×4, 3×3), 64 columns at a time from registers.
    #[inline(always)]
    fn merge_row<const M: usize>(phases: &[f32], phase: usize, relu: bool, out: &mut [f32]) {
        let act = |v: f32| if relu { v.max(0.0) } else { v };
        let mut done = 0;
        if M == 4 {
            for (b, block) in out.chunks_exact_mut(64).enumerate() {
                let p: [&[f32; 16]; 4] =
                    std::array::from_fn(|k| phases[k * phase + 16 * b..][..16].try_into().expect("16 tiles"));
                let block: &mut [f32; 64] = block.try_into().expect("64 columns");
                for (x, o) in block.iter_mut().enumerate() {
                    *o = act(p[x % 4][x / 4]);
                }
                done += 64;
            }
        }
        for (x, o) in out.iter_mut().enumerate().skip(done) {
            *o = act(phases[(x % M) * phase + x / M]);
        }
    }

    /// `outs[k][i] = init + Σⱼ coef[k][j] · ins[j][i]` for `i < n`: one pass in which every output element
    /// is computed from its inputs in registers, 16 elements at a time (fixed-size arrays the compiler keeps
    /// in vector registers), zero coefficients skipped. (A pass per coefficient, as sums of scaled runs, loads and stores each
    /// output once per term: several times slower.)
    #[inline(always)]
    fn combine<const I: usize, const O: usize>(
        coef: &[[f32; I]; O],
        ins: [&[f32]; I],
        outs: &mut [&mut [f32]; O],
        n: usize,
        init: f32,
    ) {
        const L: usize = 16;
        let full = n / L * L;
        for i in (0..full).step_by(L) {
            // Fixed-size copies: registers, not calls to memcpy.
            let x: [[f32; L]; I] = std::array::from_fn(|j| ins[j][i..i + L].try_into().expect("L values"));
            for (ck, out) in coef.iter().zip(outs.iter_mut()) {
                let mut acc = [init; L];
                for (&cj, xj) in ck.iter().zip(&x) {
                    if cj != 0.0 {
                        for (a, &e) in acc.iter_mut().zip(xj) {
                            *a += cj * e;
                        }
                    }
                }
                let dst: &mut [f32; L] = (&mut out[i..i + L]).try_into().expect("L values");
                *dst = acc;
            }
        }
        for i in full..n {
            for (ck, out) in coef.iter().zip(outs.iter_mut()) {
                out[i] =
                    init + ck.iter().zip(&ins).filter(|(c, _)| **c != 0.0).map(|(&c, src)| c * src[i]).sum::<f32>();
            }
        }
    }

    impl<const M: usize, const A: usize> Variant<M, A> {
        /// `G g Gᵀ` for every (output, input) channel pair: `A² × co × c`, ξ-major.
        fn transform_weights(&self, weight: &[f32], co: usize, c: usize) -> Vec<f32> {
            let mut u = vec![0f32; A * A * co * c];
            for (pair, g) in weight.chunks(9).enumerate() {
                // t = G g (A×3), then u = t Gᵀ (A×A).
                let mut t = [[0f32; 3]; A];
                for (tr, gr) in t.iter_mut().zip(&self.g) {
                    for (j, e) in tr.iter_mut().enumerate() {
                        *e = (0..3).map(|k| gr[k] * g[k * 3 + j]).sum();
                    }
                }
                for (r, tr) in t.iter().enumerate() {
                    for (k, gk) in self.g.iter().enumerate() {
                        u[(r * A + k) * co * c + pair] = (0..3).map(|j| tr[j] * gk[j]).sum();
                    }
                }
            }
            u
        }

        /// `Bᵀ d B` of the input tiles of tile rows `ty0..ty0+rows` of one image (`C × H × W`):
        /// `A² × C × tiles`, ξ-major, tile `t = (ty − ty0)·tiles_x + tx` covering input rows
        /// `M·ty − 1 .. M·ty − 1 + A` and the same columns, zero outside the image.
        ///
        /// Each input row is first split by phase: padded column `p = x + 1` goes to phase `p mod M`, index
        /// `p div M`, so that column `M·tx + j` of tile `tx` is element `tx + j div M` of phase `j mod M`. Both
        /// transforms are then sums of whole contiguous runs (over columns for `Bᵀ d`, over tiles for
        /// `(Bᵀ d) B`) that the compiler vectorizes; a per-tile loop over strided columns does not.
        #[inline(always)]
        fn transform_input(
            &self,
            geom: &Geometry,
            image: &[f32],
            (ty0, rows): (usize, usize),
            tiles_x: usize,
            v: &mut Vec<f32>,
        ) {
            let (c, h, w) = (geom.c, geom.h, geom.w);
            let tiles = rows * tiles_x;
            // One phase holds tiles_x + 1 columns (a tile reaches A ≤ 2M columns); a split row M phases.
            let phase = tiles_x + 1;
            let len = M * phase;
            // Every element is written below: resizing a reused buffer needs no clearing.
            v.resize(A * A * c * tiles, 0.0);
            // The band's input rows M·ty0 − 1 .. M·(ty0 + rows) + 1, each split once (neighbouring tile rows
            // share two). Padding columns are never written, so they stay zero.
            let band_rows = M * (rows - 1) + A;
            let mut split = vec![0f32; band_rows * len];
            let mut m = vec![0f32; A * len];
            for ci in 0..c {
                let channel = &image[ci * h * w..(ci + 1) * h * w];
                for (r, row) in split.chunks_mut(len).enumerate() {
                    match (M * ty0 + r).checked_sub(1).filter(|&y| y < h) {
                        Some(y) => split_row::<M>(&channel[y * w..(y + 1) * w], row, phase, 1),
                        None => row.fill(0.0),
                    }
                }
                for ty in ty0..ty0 + rows {
                    let d = &split[M * (ty - ty0) * len..][..A * len];
                    // Bᵀ d on whole (split) rows.
                    let mut rows_out: [&mut [f32]; A] = {
                        let mut it = m.chunks_mut(len);
                        std::array::from_fn(|_| it.next().expect("A rows"))
                    };
                    combine(&self.bt, std::array::from_fn(|j| &d[j * len..(j + 1) * len]), &mut rows_out, len, 0.0);
                    // (Bᵀ d) B along the tile row, all tiles at once: tile tx's column j is element
                    // tx + j div M of phase j mod M.
                    let t0 = (ty - ty0) * tiles_x;
                    for (r, mr) in m.chunks(len).enumerate() {
                        let ins: [&[f32]; A] = std::array::from_fn(|j| &mr[(j % M) * phase + j / M..][..tiles_x]);
                        let mut outs: [&mut [f32]; A] = {
                            let mut it = v[r * A * c * tiles..(r + 1) * A * c * tiles].chunks_mut(c * tiles);
                            std::array::from_fn(|_| &mut it.next().expect("A blocks")[ci * tiles + t0..][..tiles_x])
                        };
                        combine(&self.bt, ins, &mut outs, tiles_x, 0.0);
                    }
                }
            }
        }

        /// `Aᵀ m A` of one output channel's transformed tiles (`m[ξ·stride + t]`) of `rows` tile rows,
        /// plus `bias`, ReLU'd if asked, into `out` (that channel's output rows of the band,
        /// `h_band × w`). Both transforms run over all tiles of a tile row at once, and the output row is
        /// gathered from its M phases last (the reverse of [`Self::transform_input`]'s split).
        #[allow(clippy::too_many_arguments)]
        #[inline(always)]
        fn transform_output(
            &self,
            m: &[f32],
            stride: usize,
            (rows, tiles_x): (usize, usize),
            (h_band, w): (usize, usize),
            bias: f32,
            relu: bool,
            out: &mut [f32],
        ) {
            // s = Aᵀ m: M rows of A columns, each a run over the tile row.
            let mut s = vec![0f32; M * A * tiles_x];
            // One output row in phases: column M·tx + k is element tx of phase k.
            let mut phases = vec![0f32; M * tiles_x];
            for tr in 0..rows {
                let t0 = tr * tiles_x;
                for k in 0..A {
                    let ins: [&[f32]; A] = std::array::from_fn(|j| &m[(j * A + k) * stride + t0..][..tiles_x]);
                    // Rows r·A + k of s, r < M.
                    let mut outs: [&mut [f32]; M] = {
                        let mut it = s.chunks_mut(tiles_x).skip(k).step_by(A);
                        std::array::from_fn(|_| it.next().expect("M rows"))
                    };
                    combine(&self.at, ins, &mut outs, tiles_x, 0.0);
                }
                for r in 0..M {
                    let yy = M * tr + r;
                    if yy >= h_band {
                        break;
                    }
                    // (Aᵀ m) A, plus the bias.
                    let ins: [&[f32]; A] = std::array::from_fn(|j| &s[(r * A + j) * tiles_x..][..tiles_x]);
                    let mut outs: [&mut [f32]; M] = {
                        let mut it = phases.chunks_mut(tiles_x);
                        std::array::from_fn(|_| it.next().expect("M phases"))
                    };
                    combine(&self.at, ins, &mut outs, tiles_x, bias);
                    merge_row::<M>(&phases, tiles_x, relu, &mut out[yy * w..(yy + 1) * w]);
                }
            }
        }

        /// `A z Aᵀ` of the output-gradient tiles of tile rows `ty0..ty0+rows` of one image (`co × H × W`):
        /// `A² × co × tiles`, ξ-major, tile `t` covering rows `M·ty .. M·ty + M` and the same columns
        /// (the output tile of [`Self::transform_input`]'s input tile), zero outside the image. Split by
        /// phase as there, so that both transforms are sums of contiguous runs.
        #[inline(always)]
        fn transform_gradient(
            &self,
            (co, h, w): (usize, usize, usize),
            grad: &[f32],
            (ty0, rows): (usize, usize),
            tiles_x: usize,
            out: &mut Vec<f32>,
        ) {
            let tiles = rows * tiles_x;
            // Column M·tx + j is element tx of phase j; columns past the image stay zero.
            let len = M * tiles_x;
            out.resize(A * A * co * tiles, 0.0);
            let mut z = vec![0f32; M * len];
            let mut r = vec![0f32; A * len];
            // A = (Aᵀ)ᵀ, A × M.
            let a: [[f32; M]; A] = std::array::from_fn(|p| std::array::from_fn(|i| self.at[i][p]));
            for o in 0..co {
                let channel = &grad[o * h * w..(o + 1) * h * w];
                for ty in ty0..ty0 + rows {
                    for (i, row) in z.chunks_mut(len).enumerate() {
                        let y = M * ty + i;
                        if y < h {
                            split_row::<M>(&channel[y * w..(y + 1) * w], row, tiles_x, 0);
                        } else {
                            row.fill(0.0);
                        }
                    }
                    // A z on whole (split) rows: row p is Σᵢ Aᵀ[i][p] zᵢ.
                    let mut rows_out: [&mut [f32]; A] = {
                        let mut it = r.chunks_mut(len);
                        std::array::from_fn(|_| it.next().expect("A rows"))
                    };
                    combine(&a, std::array::from_fn(|i| &z[i * len..(i + 1) * len]), &mut rows_out, len, 0.0);
                    // (A z) Aᵀ along the tile row, all tiles at once.
                    let t0 = (ty - ty0) * tiles_x;
                    for (p, rp) in r.chunks(len).enumerate() {
                        let ins: [&[f32]; M] = std::array::from_fn(|j| &rp[j * tiles_x..][..tiles_x]);
                        let mut outs: [&mut [f32]; A] = {
                            let mut it = out[p * A * co * tiles..(p + 1) * A * co * tiles].chunks_mut(co * tiles);
                            std::array::from_fn(|_| &mut it.next().expect("A blocks")[o * tiles + t0..][..tiles_x])
                        };
                        combine(&a, ins, &mut outs, tiles_x, 0.0);
                    }
                }
            }
        }

        /// The bands `(image, first tile row, tile rows)` of [`Self::weight_grad`]: transformed blocks of
        /// about 2 MiB each, at least 4 bands per image where possible.
        pub(super) fn grad_bands(&self, geom: &Geometry, n: usize, co: usize) -> Vec<(usize, usize, usize)> {
            let (tiles_x, tiles_y) = (geom.w.div_ceil(M), geom.h.div_ceil(M));
            let target_tiles = ((2usize << 20) / (4 * A * A * geom.c.max(co))).max(64);
            bands(n, tiles_y, rows_per_band(target_tiles, tiles_x, tiles_y))
        }

        /// `dL/dW` (`co × C × 3 × 3`) as [`super::weight_grad`] computes it, by the transposed algorithm
        /// F(3×3, M×M): per tile, `Gᵀ [(A z Aᵀ) ⊙ (Bᵀ d B)] G` for the output-gradient tile `z` and the
        /// input tile `d` of the forward pass (the 1-D identity: `F(M, 3)` computes the trilinear form
        /// `Σᵢₖ zᵢ gₖ dᵢ₊ₖ = Σ_ξ (A z)_ξ (G g)_ξ (Bᵀ d)_ξ`, whose derivative in `g` is this). The sums over
        /// tiles are `A²` GEMMs `Z[ξ] (co × tiles) · V[ξ]ᵀ (tiles × C)` with the tiles as inner dimension,
        /// accumulated per fixed group of bands and then summed in order (thread-count independent);
        /// `Gᵀ · G` runs once per channel pair at the end. 4× fewer multiplications than im2col for F4.
        pub(super) fn weight_grad(&self, geom: &Geometry, n: usize, x: &[f32], grad: &[f32], co: usize) -> Vec<f32> {
            let (c, h, w) = (geom.c, geom.h, geom.w);
            let tiles_x = w.div_ceil(M);
            let bands = self.grad_bands(geom, n, co);
            let per_group = bands.len().div_ceil(super::GRAD_GROUPS);
            let partials: Vec<Vec<f32>> = bands
                .par_chunks(per_group)
                .map(|group| {
                    let mut dw = vec![0f32; A * A * co * c];
                    let (mut v, mut z) = (Vec::new(), Vec::new());
                    for &(i, ty0, rows) in group {
                        let image = &x[i * c * h * w..(i + 1) * c * h * w];
                        with_simd(
                            #[inline(always)]
                            || self.transform_input(geom, image, (ty0, rows), tiles_x, &mut v),
                        );
                        let g = &grad[i * co * h * w..(i + 1) * co * h * w];
                        with_simd(
                            #[inline(always)]
                            || self.transform_gradient((co, h, w), g, (ty0, rows), tiles_x, &mut z),
                        );
                        let tiles = rows * tiles_x;
                        for xi in 0..A * A {
                            // SAFETY: dw[ξ] is co × c (row-major), z[ξ] co × tiles (row-major) and v[ξ]
                            // c × tiles, read transposed (row stride 1, column stride tiles); all inside
                            // their buffers, dw owned by this group.
                            #[allow(unsafe_code)]
                            unsafe {
                                sgemm(
                                    (co, c, tiles),
                                    dw.as_mut_ptr().add(xi * co * c),
                                    c,
                                    true,
                                    z.as_ptr().add(xi * co * tiles),
                                    tiles,
                                    v.as_ptr().add(xi * c * tiles),
                                    (1, tiles),
                                );
                            }
                        }
                    }
                    dw
                })
                .collect();
            let mut total = vec![0f32; A * A * co * c];
            for p in &partials {
                for (t, v) in total.iter_mut().zip(p) {
                    *t += v;
                }
            }
            // Gᵀ X G per (output, input) channel pair: dW[ky][kx] = Σ_pq G[p][ky] X[p][q] G[q][kx].
            let pairs = co * c;
            let mut dw = vec![0f32; pairs * 9];
            for (pair, out) in dw.chunks_mut(9).enumerate() {
                for (p, gp) in self.g.iter().enumerate() {
                    for (q, gq) in self.g.iter().enumerate() {
                        let e = total[(p * A + q) * pairs + pair];
                        for ky in 0..3 {
                            for kx in 0..3 {
                                out[ky * 3 + kx] += gp[ky] * e * gq[kx];
                            }
                        }
                    }
                }
            }
            dw
        }

        /// The forward convolution, as [`super::forward`] computes it.
        #[allow(clippy::too_many_arguments)]
        pub(super) fn forward(
            &self,
            geom: &Geometry,
            n: usize,
            x: &[f32],
            weight: &[f32],
            bias: &[f32],
            co: usize,
            relu: bool,
        ) -> Vec<f32> {
            let (c, h, w) = (geom.c, geom.h, geom.w);
            let (tiles_x, tiles_y) = (w.div_ceil(M), h.div_ceil(M));
            let u = self.transform_weights(weight, co, c);
            // Tile rows per band: a transformed-input block of about 2 MiB, at least 4 bands per image
            // where possible.
            let target_tiles = ((2usize << 20) / (4 * A * A * c)).max(64);
            let bands = bands(n, tiles_y, rows_per_band(target_tiles, tiles_x, tiles_y));
            // The bands' output transforms write every output element.
            let mut y = super::output_buffer(n * co * h * w);
            let out = SharedMut(y.as_mut_ptr());
            bands.into_par_iter().for_each_init(
                || (Vec::new(), Vec::new()),
                |(v, m), (i, ty0, rows)| {
                    {
                        let image = &x[i * c * h * w..(i + 1) * c * h * w];
                        with_simd(
                            #[inline(always)]
                            || self.transform_input(geom, image, (ty0, rows), tiles_x, v),
                        );
                        let tiles = rows * tiles_x;
                        // The GEMMs overwrite every element: no clearing needed.
                        m.resize(A * A * co * tiles, 0.0);
                        for xi in 0..A * A {
                            // SAFETY: u[ξ] is co × c, v[ξ] c × tiles and m[ξ] co × tiles, all row-major and
                            // inside their buffers; m is this band's own.
                            #[allow(unsafe_code)]
                            unsafe {
                                sgemm(
                                    (co, tiles, c),
                                    m.as_mut_ptr().add(xi * co * tiles),
                                    tiles,
                                    false,
                                    u.as_ptr().add(xi * co * c),
                                    c,
                                    v.as_ptr().add(xi * c * tiles),
                                    (tiles, 1),
                                );
                            }
                        }
                        let (y0, y1) = (M * ty0, (M * (ty0 + rows)).min(h));
                        for (o, &b) in bias.iter().enumerate() {
                            // SAFETY: output rows y0..y1 of channel o of image i, inside `y`; they belong to
                            // this band only.
                            #[allow(unsafe_code)]
                            let dst = unsafe {
                                std::slice::from_raw_parts_mut(
                                    out.get().add(((i * co + o) * h + y0) * w),
                                    (y1 - y0) * w,
                                )
                            };
                            let shape = (rows, tiles_x);
                            let m = &m[o * tiles..];
                            with_simd(
                                #[inline(always)]
                                || self.transform_output(m, co * tiles, shape, (y1 - y0, w), b, relu, dst),
                            );
                        }
                    }
                },
            );
            y
        }
    }
}

/// Bands are summed in this many fixed groups (in parallel, then in order), so the weight gradient is the
/// same whatever the thread count.
const GRAD_GROUPS: usize = 8;

/// `dL/dW` (`co × C × 3 × 3`) from the input batch and the output gradient `grad` (`n × co × H × W`, before
/// the activation).
fn weight_grad(geom: &Geometry, n: usize, x: &[f32], grad: &[f32], co: usize) -> Vec<f32> {
    let (c, h, w) = (geom.c, geom.h, geom.w);
    let bands = geom.bands(n);
    let per_group = bands.len().div_ceil(GRAD_GROUPS);
    let k = 9 * c;
    let partials: Vec<Vec<f32>> = bands
        .par_chunks(per_group)
        .map(|group| {
            let mut dw = vec![0f32; co * k];
            let mut cols_buf = Vec::new();
            for &(i, y0, rows) in group {
                geom.im2col(&x[i * c * h * w..(i + 1) * c * h * w], y0, rows, &mut cols_buf);
                let cols = rows * w;
                #[allow(unsafe_code)]
                // SAFETY: dw is co × 9c (row stride 9c), owned by this group; the gradient block is image
                // i's rows y0..y0+rows of co channels (row stride H·W), inside `grad`; the im2col block
                // (9c × cols, row-major) is read transposed (cols × 9c: row stride 1, column stride cols).
                unsafe {
                    let g = grad.as_ptr().add(i * co * h * w + y0 * w);
                    sgemm((co, k, cols), dw.as_mut_ptr(), k, true, g, h * w, cols_buf.as_ptr(), (1, cols));
                }
            }
            dw
        })
        .collect();
    let mut total = vec![0f32; co * k];
    for p in &partials {
        for (t, v) in total.iter_mut().zip(p) {
            *t += v;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// A reproducible tensor of unit-variance values (uniform in ±√3): candle's CPU generator cannot be
    /// seeded, and a test on unseeded values fails at random where a ReLU mask flips.
    fn det(dims: &[usize], seed: u64) -> Result<Tensor> {
        let mut rng = hush_hash::SplitMix64(seed);
        let n: usize = dims.iter().product();
        let v: Vec<f32> = (0..n).map(|_| ((rng.next_f64() * 2.0 - 1.0) * 3f64.sqrt()) as f32).collect();
        Tensor::from_vec(v, dims, &Device::Cpu)
    }

    fn max_diff(a: &Tensor, b: &Tensor) -> Result<f32> {
        (a - b)?.abs()?.max_all()?.to_scalar::<f32>()
    }

    /// Values and gradients (input, weight, bias) equal candle's conv2d + bias (+ ReLU), on shapes that
    /// give one band and several bands per image.
    #[test]
    fn conv3x3_matches_candle_with_gradients() -> Result<()> {
        for (n, c, co, h, w, relu) in
            [(2, 3, 4, 5, 7, false), (1, 5, 6, 33, 9, true), (3, 2, 3, 1, 1, true), (2, 16, 17, 12, 11, false)]
        {
            let seed = (n * 1000 + c * 100 + co) as u64;
            let x = Var::from_tensor(&det(&[n, c, h, w], seed)?)?;
            let wt = Var::from_tensor(&det(&[co, c, 3, 3], seed + 1)?)?;
            let b = Var::from_tensor(&det(&[co], seed + 2)?)?;
            let probe = det(&[n, co, h, w], seed + 3)?;
            let ours = conv3x3(&x, &wt, &b, relu)?;
            let theirs = x.conv2d(&wt, 1, 1, 1, 1)?.broadcast_add(&b.reshape((1, co, 1, 1))?)?;
            let theirs = if relu { theirs.relu()? } else { theirs };
            // Relative to the largest value: F(4×4, 3×3) (the last shape) rounds to about 2e-5 (see
            // `winograd_matches_im2col`). That shape has no ReLU, whose mask could flip at outputs within
            // rounding of zero and make the gradients differ by a whole probe value.
            let scale = theirs.abs()?.max_all()?.to_scalar::<f32>()?;
            assert!(max_diff(&ours, &theirs)? < 2e-5 * scale, "values differ for {:?}", (n, c, co, h, w));
            let g_ours = (ours * &probe)?.sum_all()?.backward()?;
            let g_theirs = (theirs * &probe)?.sum_all()?.backward()?;
            for v in [&x, &wt, &b] {
                let (a, e) = (g_ours.get(v).expect("grad"), g_theirs.get(v).expect("grad"));
                let d = max_diff(a, e)?;
                let scale = e.abs()?.max_all()?.to_scalar::<f32>()?;
                assert!(d < 2e-5 * scale, "gradient of {:?} differs by {d} for {:?}", v.dims(), (n, c, co, h, w));
            }
        }
        Ok(())
    }

    /// The output (of the Winograd path) and the weight gradient are bit for bit the same on one thread
    /// and on three.
    #[test]
    fn results_do_not_depend_on_the_thread_count() -> Result<()> {
        let x = det(&[3, 16, 40, 24], 11)?;
        let wt = det(&[17, 16, 3, 3], 12)?;
        let b = det(&[17], 13)?;
        let grad = det(&[3, 17, 40, 24], 14)?;
        let run = |threads: usize| -> Result<(Vec<f32>, Vec<f32>)> {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
            pool.install(|| {
                let y = conv3x3(&x, &wt, &b, true)?.flatten_all()?.to_vec1::<f32>()?;
                let dw = x.apply_op2_no_bwd(&grad, &WeightGradOp)?.flatten_all()?.to_vec1::<f32>()?;
                Ok((y, dw))
            })
        };
        let geom = Geometry { c: 16, h: 40, w: 24 };
        assert!(winograd::F4.grad_bands(&geom, 3, 17).len() > GRAD_GROUPS, "the test must span several groups");
        assert!(use_winograd(16, 17));
        assert_eq!(run(1)?, run(3)?);
        Ok(())
    }

    /// Gradients carry no graph: one that referenced the forward pass would keep its activations alive
    /// (in an optimizer's moments, step after step).
    #[test]
    fn gradients_are_detached() -> Result<()> {
        let x = Var::from_tensor(&det(&[1, 2, 4, 4], 21)?)?;
        let wt = Var::from_tensor(&det(&[3, 2, 3, 3], 22)?)?;
        let b = Var::from_tensor(&det(&[3], 23)?)?;
        let grads = conv3x3(&x, &wt, &b, true)?.sqr()?.sum_all()?.backward()?;
        for v in [&x, &wt, &b] {
            assert!(!grads.get(v).expect("grad").track_op(), "the gradient of {:?} tracks the graph", v.dims());
        }
        Ok(())
    }

    /// Reproducible values in [−0.5, 0.5).
    fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut rng = hush_hash::SplitMix64(seed);
        move || rng.next_f64() as f32 - 0.5
    }

    /// (images, input channels, output channels, height, width) for the Winograd tests: one pixel, sizes
    /// that are and are not multiples of the tile, several bands and groups (3 × 40 rows), and 150 and 190
    /// columns, which reach the 64-column block paths of the row split and merge.
    const WINOGRAD_SHAPES: [(usize, usize, usize, usize, usize); 6] = [
        (1, 16, 16, 1, 1),
        (2, 17, 20, 9, 6),
        (3, 32, 24, 40, 33),
        (1, 16, 16, 5, 3),
        (1, 16, 16, 6, 150),
        // The second block would need 191 columns: the strided copy takes the rest of the row.
        (1, 16, 16, 5, 190),
    ];

    /// Both Winograd variants give the im2col path's values (to f32 rounding of their transforms) on
    /// sizes that are and are not multiples of the tile, one tile row and several bands.
    #[test]
    fn winograd_matches_im2col() {
        let mut rnd = uniform(1);
        for (n, c, co, h, w) in WINOGRAD_SHAPES {
            let geom = Geometry { c, h, w };
            let x: Vec<f32> = (0..n * c * h * w).map(|_| rnd()).collect();
            let weight: Vec<f32> = (0..co * c * 9).map(|_| rnd()).collect();
            let bias: Vec<f32> = (0..co).map(|_| rnd()).collect();
            for relu in [false, true] {
                let a = forward(&geom, n, &x, &weight, &bias, co, relu);
                let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
                let f2 = winograd::F2.forward(&geom, n, &x, &weight, &bias, co, relu);
                let f4 = winograd::F4.forward(&geom, n, &x, &weight, &bias, co, relu);
                let diff = |b: &[f32]| a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0f32, f32::max) / scale;
                // Relative to the largest output: a few f32 ulps of a sum of 9·C products for F(2×2),
                // ~10× that for F(4×4), whose transforms carry coefficients up to 8 and 1/24.
                assert!(diff(&f2) < 2e-6, "F2 {:?} differs by {}", (n, c, co, h, w, relu), diff(&f2));
                assert!(diff(&f4) < 2e-5, "F4 {:?} differs by {}", (n, c, co, h, w, relu), diff(&f4));
            }
        }
    }

    /// The Winograd weight gradient (both variants) equals the im2col one, to f32 rounding of its
    /// transforms, on sizes that are and are not multiples of the tile, one band and several groups.
    #[test]
    fn winograd_weight_grad_matches_im2col() {
        let mut rnd = uniform(7);
        for (n, c, co, h, w) in WINOGRAD_SHAPES {
            let geom = Geometry { c, h, w };
            let x: Vec<f32> = (0..n * c * h * w).map(|_| rnd()).collect();
            let grad: Vec<f32> = (0..n * co * h * w).map(|_| rnd()).collect();
            let a = weight_grad(&geom, n, &x, &grad, co);
            let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
            let diff = |b: &[f32]| a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0f32, f32::max) / scale;
            let f2 = winograd::F2.weight_grad(&geom, n, &x, &grad, co);
            let f4 = winograd::F4.weight_grad(&geom, n, &x, &grad, co);
            // As in `winograd_matches_im2col`: relative to the largest value, a few ulps of the sums for
            // F(2×2), about 10× that for F(4×4)'s larger coefficients.
            assert!(diff(&f2) < 2e-6, "F2 {:?} differs by {}", (n, c, co, h, w), diff(&f2));
            assert!(diff(&f4) < 2e-5, "F4 {:?} differs by {}", (n, c, co, h, w), diff(&f4));
        }
    }

    /// Bands follow the rows: every row of every image belongs to exactly one band.
    #[test]
    fn bands_cover_every_row_once() {
        for (c, h, w) in [(9, 512, 512), (160, 32, 32), (3, 7, 2), (64, 1, 300)] {
            let geom = Geometry { c, h, w };
            let bands = geom.bands(2);
            for i in 0..2 {
                let rows: usize = bands.iter().filter(|b| b.0 == i).map(|b| b.2).sum();
                assert_eq!(rows, h, "{:?}", (c, h, w));
            }
            assert!(bands.windows(2).all(|p| p[0].0 < p[1].0 || p[0].1 + p[0].2 == p[1].1));
        }
    }
}
