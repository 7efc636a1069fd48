//! Training losses and the SSIM metric, on NCHW tensors. Every function checks shapes first and returns a
//! scalar (rank-0) tensor through which gradients flow. The set is OIDN's (`training/loss.py`): L1, MSE
//! (`l2`), MAPE, SMAPE, SSIM, MS-SSIM, L1 + MS-SSIM (the thesis' mix) and L1 + gradient (`l1_grad`), and
//! one of hush's own, [`log_mse`], the objective of a mean PSNR over images.
//!
//! Losses take what the network sees, i.e. images after [`crate::prepare_color`], whose sanitization policy
//! (non-finite → 0, then the transfer and the ≤ 1 clamp) keeps raw radiance of any magnitude, NaN and ±Inf
//! out of them; every loss and its gradient are then finite (tested on constant, black, 1e-8, 1e6, NaN,
//! ±Inf and single-firefly images). A NaN the network itself produces is not hidden: the loss is NaN and
//! training stops there.
//!
//! SSIM follows Open Image Denoise's `training/ssim.py` (itself pytorch-msssim): an 11-tap Gaussian window
//! with σ = 1.5 applied separably as a *valid* convolution, K1 = 0.01, K2 = 0.03, data range 1, per image and
//! channel, then averaged. MS-SSIM uses 5 scales with 2×2 average pooling between them, contrast-structure
//! at scales 1–4 and full SSIM at scale 5, each clamped at 0 (ReLU) before being raised to its weight.
//!
//! Three deliberate differences from OIDN:
//! * Outputs below 0: the luminance term uses max(μ1·μ2, 0), which changes nothing for images ≥ 0 (every
//!   target and metric input). Unclamped, a channel whose output mean falls below 0 has a negative SSIM at
//!   the coarsest scale, which MS-SSIM clamps to 0 with a zero gradient (the channel never recovers), and an
//!   inverted channel below 0 scores SSIM ≈ 1 (negative luminance × negative contrast). Training runs from
//!   initializations with a negative output channel collapsed that way.
//! * Numerical stability: σ² = `E[x²] − E[x]²` cancels catastrophically in f32 for large values
//!   (1e4 + noise). Variance and covariance are shift invariant, so each image channel is first shifted
//!   by a constant, the mean of `(x + y) / 2` over that channel, before filtering; the constant is added
//!   back to the local means for the luminance term. Values are unchanged in exact arithmetic.
//! * Small images: OIDN asserts a side > 160 px. Here MS-SSIM uses as many scales as fit (the smallest
//!   side must stay ≥ 11 after each halving, halving rounds down, so 5 scales need a side ≥ 176) with the
//!   weights of those scales renormalized to sum to 1; one scale is plain SSIM. Sides < 11 are an error.
//!   When every scale fits the weights are used as given, like pytorch-msssim and OIDN (Wang's weights
//!   sum to 1.0001). Odd sides drop their last row/column when halved (OIDN pads them instead).

use candle_core::{CpuStorage, CustomOp1, DType, Layout, Result, Shape, Tensor, bail};
use serde::{Deserialize, Serialize};

use crate::transfer::{Transfer, display_tensor};

/// Side of the Gaussian window.
pub const SSIM_WINDOW: usize = 11;
/// Standard deviation of the Gaussian window, in pixels.
pub const SSIM_SIGMA: f64 = 1.5;
const K1: f64 = 0.01;
const K2: f64 = 0.03;
const DATA_RANGE: f64 = 1.0;
const C1: f64 = (K1 * DATA_RANGE) * (K1 * DATA_RANGE);
const C2: f64 = (K2 * DATA_RANGE) * (K2 * DATA_RANGE);

/// Wang et al.'s MS-SSIM scale weights, finest scale first.
pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// Weight of L1 in [`mix`] (the rest goes to 1 − MS-SSIM): thesis eq. 7.1, OIDN's `l1_msssim`.
pub const MIX_L1_WEIGHT: f64 = 0.16;

/// The loss functions hush trains with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Loss {
    /// Mean absolute error.
    L1,
    /// Mean squared error.
    Mse,
    /// 1 − SSIM.
    Ssim,
    /// 1 − MS-SSIM.
    MsSsim,
    /// 0.16 · L1 + 0.84 · (1 − MS-SSIM): the thesis' best loss.
    #[default]
    Mix,
    /// Mean absolute percentage error `|x − y| / (|y| + 0.01)` (OIDN's `mape`).
    Mape,
    /// Symmetric MAPE `|x − y| / (|x| + |y| + 0.01)` (OIDN's `smape`).
    Smape,
    /// 0.5 · L1 + 0.5 · [`gradient_l1`] (OIDN's `l1_grad`).
    L1Grad,
    /// [`log_mse`]: the mean over images of `ln(1 + MSE / 1e-5)`, the mean PSNR's objective.
    LogMse,
}

impl Loss {
    /// The loss of prediction `x` against target `y` (both NCHW), a scalar tensor.
    pub fn compute(&self, x: &Tensor, y: &Tensor) -> Result<Tensor> {
        match self {
            Loss::L1 => l1(x, y),
            Loss::Mse => mse(x, y),
            Loss::Ssim => ssim(x, y)?.affine(-1.0, 1.0),
            Loss::MsSsim => ms_ssim(x, y)?.affine(-1.0, 1.0),
            Loss::Mix => mix(x, y),
            Loss::Mape => mape(x, y),
            Loss::Smape => smape(x, y),
            Loss::L1Grad => l1_grad(x, y),
            Loss::LogMse => log_mse(x, y),
        }
    }

    pub const ALL: [Loss; 9] =
        [Loss::L1, Loss::Mse, Loss::Ssim, Loss::MsSsim, Loss::Mix, Loss::Mape, Loss::Smape, Loss::L1Grad, Loss::LogMse];

    /// The serialized name (`l1`, `mse`, `ssim`, `ms_ssim`, `mix`, `mape`, `smape`, `l1_grad`, `log_mse`).
    pub fn name(self) -> &'static str {
        match self {
            Loss::L1 => "l1",
            Loss::Mse => "mse",
            Loss::Ssim => "ssim",
            Loss::MsSsim => "ms_ssim",
            Loss::Mix => "mix",
            Loss::Mape => "mape",
            Loss::Smape => "smape",
            Loss::L1Grad => "l1_grad",
            Loss::LogMse => "log_mse",
        }
    }

    /// Parses [`Loss::name`] or OIDN's name for it (`l2`, `msssim`, `l1_msssim`; `mae` for L1).
    pub fn parse(name: &str) -> Option<Loss> {
        match name {
            "mae" => Some(Loss::L1),
            "l2" => Some(Loss::Mse),
            "msssim" | "ms-ssim" => Some(Loss::MsSsim),
            "l1_msssim" => Some(Loss::Mix),
            _ => Loss::ALL.into_iter().find(|l| l.name() == name),
        }
    }
}

/// Where a training loss compares the network's output with its target.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossSpace {
    /// As the network sees them, in its transfer function's space (PU for HDR color): OIDN's choice.
    #[default]
    Transfer,
    /// Back through the transfer function to exposed linear values, then OIDN's evaluation transform
    /// ([`crate::transfer::display_tensor`]: filmic curve and sRGB): where hush's metrics and OIDN's
    /// `compare_image.py` measure. With the samples' exposure (the reference's autoexposure, which the
    /// metrics use too), MSE here on a whole image is the MSE behind its PSNR.
    Tonemapped,
}

impl LossSpace {
    pub const ALL: [LossSpace; 2] = [LossSpace::Transfer, LossSpace::Tonemapped];

    /// The serialized name (`transfer`, `tonemapped`).
    pub fn name(self) -> &'static str {
        match self {
            LossSpace::Transfer => "transfer",
            LossSpace::Tonemapped => "tonemapped",
        }
    }

    /// The default, which configurations written before loss spaces existed mean.
    pub fn is_transfer(&self) -> bool {
        *self == LossSpace::Transfer
    }

    pub fn parse(name: &str) -> Option<LossSpace> {
        LossSpace::ALL.into_iter().find(|s| s.name() == name)
    }

    /// `x` (what the network sees or predicts, after `transfer`) in this space. Values above 1, which no
    /// target reaches (the transfer functions map [`crate::transfer::HDR_Y_MAX`] to 1), count as 1.
    pub fn map(self, transfer: Transfer, x: &Tensor) -> Result<Tensor> {
        match self {
            LossSpace::Transfer => Ok(x.clone()),
            LossSpace::Tonemapped => display_tensor(&transfer.inverse_tensor(&x.minimum(1.0)?)?),
        }
    }

    /// `loss` of prediction `x` against target `y` (both after `transfer`, NCHW) in this space.
    pub fn compute(self, loss: Loss, transfer: Transfer, x: &Tensor, y: &Tensor) -> Result<Tensor> {
        loss.compute(&self.map(transfer, x)?, &self.map(transfer, y)?)
    }
}

/// The floor of [`color_mean`]'s denominator: a channel's image mean in the evaluation's display space below
/// it (a nearly black crop) counts its difference in absolute terms rather than relative ones.
pub const COLOR_MEAN_FLOOR: f64 = 0.01;

/// The colour-mean term: per image and channel, the squared relative difference of the image means of `x`
/// and `y` (NCHW, means over H and W), `((mean(x) − mean(y)) / (mean(y) + `[`COLOR_MEAN_FLOOR`]`))²`, averaged
/// over images and channels: zero exactly when each channel's mean is the target's. Weighted beside a per-pixel
/// loss it pulls what per-pixel losses leave free, the brightness of a whole crop (a kernel that drops a crop's
/// fireflies, or an L1 loss that prefers the median to the mean where the noise is skewed, shifts the image
/// mean; the colour-cast guards measure exactly this on the display images). Squared, so that what minimizes it
/// over noisy crops is each crop mean's conditional *mean* (unbiased image means), not its median: with the
/// absolute difference the skewed spread of a 1-spp crop's mean pulls towards a biased median.
pub fn color_mean(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("color_mean", x, y)?;
    if x.rank() != 4 {
        bail!("color_mean: expected NCHW tensors, got {:?}", x.dims())
    }
    let means = |t: &Tensor| t.mean_keepdim(3)?.mean_keepdim(2);
    let (mx, my) = (means(x)?, means(y)?);
    ((mx - &my)? / (my + COLOR_MEAN_FLOOR)?)?.sqr()?.mean_all()
}

fn check_same_shape(op: &str, x: &Tensor, y: &Tensor) -> Result<()> {
    if x.dims() != y.dims() {
        bail!("{op}: shapes differ: prediction {:?} vs target {:?}", x.dims(), y.dims())
    }
    if x.dtype() != y.dtype() {
        bail!("{op}: dtypes differ: prediction {:?} vs target {:?}", x.dtype(), y.dtype())
    }
    Ok(())
}

fn check_images(op: &str, x: &Tensor, y: &Tensor) -> Result<(usize, usize, usize, usize)> {
    check_same_shape(op, x, y)?;
    let dims = x.dims();
    if dims.len() != 4 {
        bail!("{op}: expected NCHW tensors, got prediction {:?} vs target {:?}", x.dims(), y.dims())
    }
    let (n, c, h, w) = (dims[0], dims[1], dims[2], dims[3]);
    if h < SSIM_WINDOW || w < SSIM_WINDOW {
        bail!("{op}: images of {h}x{w} are smaller than the {SSIM_WINDOW}x{SSIM_WINDOW} SSIM window")
    }
    Ok((n, c, h, w))
}

/// Mean absolute error.
pub fn l1(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("l1", x, y)?;
    (x - y)?.abs()?.mean_all()
}

/// Mean squared error.
pub fn mse(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("mse", x, y)?;
    (x - y)?.sqr()?.mean_all()
}

/// The MSE below which [`log_mse`] stops weighting an image up: 1e-5, 50 dB of PSNR for values in [0, 1].
pub const LOG_MSE_FLOOR: f64 = 1e-5;

/// The mean over the batch's images (NCHW) of `ln(1 + MSE_i / LOG_MSE_FLOOR)`, each image's own MSE.
///
/// A mean of PSNRs is a mean of `−10·log10(MSE_i)`: lowering it by training weighs each image's squared
/// errors by `1 / MSE_i`, so that a 64-spp image, whose MSE is a hundred times smaller than a 4-spp one's,
/// counts as much, as it does in the mean PSNR; MSE or L1 over the batch let the noisiest images decide.
/// The floor keeps images already above 50 dB from dominating (the gradient weight is `1 / (MSE_i +
/// floor)`) and the loss positive. In the tonemapped loss space ([`LossSpace::Tonemapped`]) on whole
/// images this is the objective of `hush eval`'s mean PSNR.
pub fn log_mse(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("log_mse", x, y)?;
    if x.rank() != 4 {
        bail!("log_mse: expected NCHW tensors, got {:?}", x.dims());
    }
    let per_image = (x - y)?.sqr()?.flatten_from(1)?.mean(1)?;
    (per_image / LOG_MSE_FLOOR)?.affine(1.0, 1.0)?.log()?.mean_all()
}

/// OIDN's `mape`: mean of `|x − y| / (|y| + 0.01)`, an L1 relative to the target.
pub fn mape(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("mape", x, y)?;
    ((x - y)?.abs()? / (y.abs()? + 1e-2)?)?.mean_all()
}

/// OIDN's `smape`: mean of `|x − y| / (|x| + |y| + 0.01)`, in [0, 1) per sample.
pub fn smape(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("smape", x, y)?;
    ((x - y)?.abs()? / ((x.abs()? + y.abs()?)? + 1e-2)?)?.mean_all()
}

/// Forward differences of an NCHW tensor on the `(H − 1) × (W − 1)` grid, vertical then horizontal,
/// concatenated along the channels: OIDN's `tensor_gradient` (`training/util.py`).
fn image_gradient(x: &Tensor) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    let x0 = x.narrow(2, 0, h - 1)?.narrow(3, 0, w - 1)?;
    let didy = (x.narrow(2, 1, h - 1)?.narrow(3, 0, w - 1)? - &x0)?;
    let didx = (x.narrow(2, 0, h - 1)?.narrow(3, 1, w - 1)? - &x0)?;
    Tensor::cat(&[&didy, &didx], 1)
}

/// OIDN's gradient loss: mean absolute difference of the images' forward differences ([`image_gradient`]).
/// Images need at least 2×2 pixels.
pub fn gradient_l1(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_same_shape("gradient_l1", x, y)?;
    let dims = x.dims();
    if dims.len() != 4 || dims[2] < 2 || dims[3] < 2 {
        bail!("gradient_l1: expected NCHW tensors of at least 2x2 pixels, got {dims:?}")
    }
    (image_gradient(x)? - image_gradient(y)?)?.abs()?.mean_all()
}

/// OIDN's `l1_grad`: 0.5 · L1 + 0.5 · [`gradient_l1`].
pub fn l1_grad(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    let g = gradient_l1(x, y)?;
    (l1(x, y)? * 0.5)? + (g * 0.5)?
}

/// Mean SSIM over the batch and channels of two NCHW tensors (1 = identical). Works for a single image
/// (N = 1), so the evaluation code uses it as a metric too.
pub fn ssim(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_images("ssim", x, y)?;
    let (ssim, _cs) = ssim_per_channel(x, y)?;
    ssim.mean_all()
}

/// MS-SSIM with [`MS_SSIM_WEIGHTS`] (1 = identical); see the module docs for images too small for 5 scales.
pub fn ms_ssim(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    ms_ssim_weighted(x, y, &MS_SSIM_WEIGHTS)
}

/// How many MS-SSIM scales fit an `h`×`w` image (at most `max_scales`; 0 if it is smaller than the window).
pub fn ms_ssim_scales(h: usize, w: usize, max_scales: usize) -> usize {
    let mut side = h.min(w);
    let mut scales = 0;
    while scales < max_scales && side >= SSIM_WINDOW {
        scales += 1;
        side /= 2;
    }
    scales
}

/// MS-SSIM with custom scale weights, finest first (OIDN's `RT` filter trains with `[0.2; 5]`). If the image
/// is too small for all of them, only the weights of the scales that fit are used, renormalized to sum to 1.
pub fn ms_ssim_weighted(x: &Tensor, y: &Tensor, weights: &[f64]) -> Result<Tensor> {
    let (_, _, h, w) = check_images("ms_ssim", x, y)?;
    if weights.is_empty() || weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) {
        bail!("ms_ssim: weights must be a non-empty list of finite values >= 0, got {weights:?}")
    }
    let scales = ms_ssim_scales(h, w, weights.len());
    let used: f64 = weights[..scales].iter().sum();
    let total = if scales == weights.len() { 1.0 } else { used };
    if used <= 0.0 {
        bail!("ms_ssim: the weights of the {scales} scales that fit {h}x{w} sum to 0")
    }
    let (mut x, mut y) = (x.clone(), y.clone());
    let mut product: Option<Tensor> = None;
    for (level, &weight) in weights[..scales].iter().enumerate() {
        let (ssim, cs) = ssim_per_channel(&x, &y)?;
        let last = level + 1 == scales;
        let term = relu_pow(if last { &ssim } else { &cs }, weight / total)?;
        product = Some(match product {
            None => term,
            Some(p) => (p * term)?,
        });
        if !last {
            x = x.avg_pool2d(2)?;
            y = y.avg_pool2d(2)?;
        }
    }
    product.expect("at least one scale").mean_all()
}

/// 0.16 · L1 + 0.84 · (1 − MS-SSIM).
pub fn mix(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    check_images("mix", x, y)?;
    let l1 = l1(x, y)?;
    let ms = ms_ssim(x, y)?;
    (l1 * MIX_L1_WEIGHT)? + (ms.affine(-1.0, 1.0)? * (1.0 - MIX_L1_WEIGHT))?
}

/// `max(v, 0)^e` with a finite gradient everywhere: `powf`'s gradient at 0 is infinite for e < 1, and
/// candle's ReLU gradient is a multiplication by a 0/1 mask, which would turn it into NaN.
fn relu_pow(v: &Tensor, e: f64) -> Result<Tensor> {
    let positive = v.gt(0.0)?;
    let safe = positive.where_cond(v, &v.ones_like()?)?;
    positive.where_cond(&safe.powf(e)?, &v.zeros_like()?)
}

/// Per-image, per-channel SSIM and contrast-structure, each of shape (N, C).
fn ssim_per_channel(x: &Tensor, y: &Tensor) -> Result<(Tensor, Tensor)> {
    let (n, c, h, w) = x.dims4()?;
    let b = n * c;
    let x = x.reshape((b, 1, h, w))?;
    let y = y.reshape((b, 1, h, w))?;
    // A constant per image channel; see "Numerical stability" in the module docs.
    let shift = ((x.mean_keepdim((2, 3))? + y.mean_keepdim((2, 3))?)? * 0.5)?.detach();
    let xs = x.broadcast_sub(&shift)?;
    let ys = y.broadcast_sub(&shift)?;
    let stacked = Tensor::cat(&[&xs, &ys, &xs.sqr()?, &ys.sqr()?, &(&xs * &ys)?], 0)?;
    let filtered = gaussian_filter(&stacked)?;
    let mu1s = filtered.narrow(0, 0, b)?;
    let mu2s = filtered.narrow(0, b, b)?;
    let e_xx = filtered.narrow(0, 2 * b, b)?;
    let e_yy = filtered.narrow(0, 3 * b, b)?;
    let e_xy = filtered.narrow(0, 4 * b, b)?;
    let mu1 = mu1s.broadcast_add(&shift)?;
    let mu2 = mu2s.broadcast_add(&shift)?;
    let sigma1_sq = (e_xx - mu1s.sqr()?)?;
    let sigma2_sq = (e_yy - mu2s.sqr()?)?;
    let sigma12 = (e_xy - (&mu1s * &mu2s)?)?;

    let cs_map = (((sigma12 * 2.0)? + C2)? / ((sigma1_sq + sigma2_sq)? + C2)?)?;
    // Local means of images ≥ 0 have μ1·μ2 ≥ 0, where the clamp changes nothing. A network's output can go
    // below 0: there the unclamped term is negative, MS-SSIM's clamp at 0 then zeroes the whole channel with
    // no gradient, and the channel stays dead. Clamped, the term stays positive and its gradient (through the
    // denominator) raises the negative mean towards the target's.
    let luminance = ((((&mu1 * &mu2)?.relu()? * 2.0)? + C1)? / ((mu1.sqr()? + mu2.sqr()?)? + C1)?)?;
    let ssim_map = (luminance * &cs_map)?;
    let ssim = ssim_map.mean((1, 2, 3))?.reshape((n, c))?;
    let cs = cs_map.mean((1, 2, 3))?.reshape((n, c))?;
    Ok((ssim, cs))
}

/// The normalized 11-tap Gaussian (σ = 1.5), as OIDN's `_fspecial_gauss_1d`.
fn gaussian_taps() -> [f32; SSIM_WINDOW] {
    let half = (SSIM_WINDOW / 2) as f64;
    let g: [f64; SSIM_WINDOW] =
        std::array::from_fn(|i| (-((i as f64 - half).powi(2)) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp());
    let sum: f64 = g.iter().sum();
    g.map(|v| (v / sum) as f32)
}

/// Valid separable Gaussian filtering of a (B, 1, H, W) tensor → (B, 1, H − 10, W − 10).
///
/// On the CPU this is a custom op with direct loops and an explicit backward: candle's conv2d backward would
/// also compute the (unneeded) kernel gradient, a convolution with an image-sized kernel whose im2col
/// buffer takes gigabytes for a training batch. Elsewhere it is two conv2d calls.
fn gaussian_filter(x: &Tensor) -> Result<Tensor> {
    let x = x.contiguous()?;
    if x.device().is_cpu() && matches!(x.dtype(), DType::F32) {
        return x.apply_op1(GaussianValid);
    }
    let taps = Tensor::from_slice(&gaussian_taps(), SSIM_WINDOW, x.device())?.to_dtype(x.dtype())?;
    let horizontal = taps.reshape((1, 1, 1, SSIM_WINDOW))?;
    let vertical = taps.reshape((1, 1, SSIM_WINDOW, 1))?;
    x.conv2d(&horizontal, 0, 1, 1, 1)?.conv2d(&vertical, 0, 1, 1, 1)
}

/// The CPU op behind [`gaussian_filter`]: valid correlation with the separable 11×11 Gaussian over the last
/// two dimensions of a contiguous f32 tensor of rank ≥ 2.
struct GaussianValid;

impl CustomOp1 for GaussianValid {
    fn name(&self) -> &'static str {
        "hush-gaussian-valid"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let CpuStorage::F32(data) = storage else { bail!("{}: only f32 is supported", self.name()) };
        let Some((start, end)) = layout.contiguous_offsets() else {
            bail!("{}: input must be contiguous", self.name())
        };
        let data = &data[start..end];
        let dims = layout.dims();
        if dims.len() < 2 {
            bail!("{}: input must have rank >= 2, got {dims:?}", self.name())
        }
        let (h, w) = (dims[dims.len() - 2], dims[dims.len() - 1]);
        if h < SSIM_WINDOW || w < SSIM_WINDOW {
            bail!("{}: {h}x{w} is smaller than the {SSIM_WINDOW}-tap window", self.name())
        }
        let (oh, ow) = (h + 1 - SSIM_WINDOW, w + 1 - SSIM_WINDOW);
        let planes = data.len() / (h * w);
        let taps = gaussian_taps();
        let mut out = vec![0f32; planes * oh * ow];
        let mut rows = vec![0f32; h * ow];
        for (src, dst) in data.chunks_exact(h * w).zip(out.chunks_exact_mut(oh * ow)) {
            // Horizontal pass into `rows` (h × ow), then vertical pass into `dst` (oh × ow).
            for (row, tmp) in src.chunks_exact(w).zip(rows.chunks_exact_mut(ow)) {
                tmp.fill(0.0);
                for (k, &t) in taps.iter().enumerate() {
                    for (o, &v) in tmp.iter_mut().zip(&row[k..k + ow]) {
                        *o += t * v;
                    }
                }
            }
            for (y, out_row) in dst.chunks_exact_mut(ow).enumerate() {
                for (k, &t) in taps.iter().enumerate() {
                    let tmp = &rows[(y + k) * ow..][..ow];
                    for (o, &v) in out_row.iter_mut().zip(tmp) {
                        *o += t * v;
                    }
                }
            }
        }
        let mut out_dims = dims.to_vec();
        let n = out_dims.len();
        out_dims[n - 2] = oh;
        out_dims[n - 1] = ow;
        Ok((CpuStorage::F32(out), Shape::from(out_dims)))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        // The adjoint of a valid correlation is a full correlation with the flipped kernel, i.e. a valid
        // correlation of the zero-padded gradient; the Gaussian is symmetric, so the same op does it.
        let r = grad_res.rank();
        let pad = SSIM_WINDOW - 1;
        let padded = grad_res.pad_with_zeros(r - 2, pad, pad)?.pad_with_zeros(r - 1, pad, pad)?;
        Ok(Some(padded.contiguous()?.apply_op1(GaussianValid)?))
    }
}
