//! Burger, Schuler and Harmeling's plain multilayer perceptron denoiser ("Image denoising: can plain neural
//! networks compete with BM3D?", CVPR 2012), which the thesis describes in §7.5.1 but did not build: the
//! image is cut into overlapping `patch × patch` windows (17×17, stride 3, as the thesis states), one MLP
//! maps each window of input features to a window of denoised color, and the overlapping output windows are
//! averaged, each weighted by a Gaussian window centred on its patch.
//!
//! Everything is candle tensor operations with backward (`pad_with_same`, `index_select`, `matmul`,
//! `index_add`), so the training loop trains it on crops with the same losses as the U-Nets.

use candle_core::{Device, Module, Result, Tensor, bail};
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};

/// Burger et al.'s patch side and the thesis's stride (§7.5.1: kernel 17×17, stride 3).
pub const BURGER_PATCH: usize = 17;
pub const BURGER_STRIDE: usize = 3;
/// Hidden layers and units at width 1.0: four hidden layers of 2047 units, the size of Burger et al.'s
/// largest networks. A width multiplier scales the units as it scales the U-Nets' channels.
pub const BURGER_HIDDEN: [usize; 4] = [2047; 4];

/// The hidden layers' nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// Burger et al.'s choice.
    Tanh,
    Relu,
}

impl Activation {
    /// The serialized name: `tanh`, `relu`.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Tanh => "tanh",
            Activation::Relu => "relu",
        }
    }
}

/// The shape of a [`PatchMlp`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PatchMlpConfig {
    /// Channels per input pixel: the same feature channels the U-Nets take.
    pub in_channels: usize,
    /// Channels per output pixel (3, RGB).
    pub out_channels: usize,
    /// Side of the square patches, in and out.
    pub patch: usize,
    /// Distance between neighbouring patches, 1 ≤ stride ≤ patch (so that every pixel is covered).
    pub stride: usize,
    /// Units of each hidden layer, input side first (empty: a linear map).
    pub hidden: Vec<usize>,
    pub activation: Activation,
    /// Standard deviation in pixels of the Gaussian window that weights each output patch around its centre
    /// before overlapping patches are averaged. Burger et al. weight by a Gaussian window; the thesis does
    /// not give its σ, so hush uses a quarter of the patch (4.25 pixels for 17×17 patches).
    pub sigma: f64,
}

impl PatchMlpConfig {
    /// Burger et al.'s network as the thesis describes it (17×17 patches, stride 3, tanh, four hidden layers)
    /// with `max(1, ⌊2047 × width⌋)` units per hidden layer and `σ = patch / 4`.
    pub fn burger(in_channels: usize, width: f64, activation: Activation) -> Self {
        let hidden = BURGER_HIDDEN.iter().map(|&u| ((u as f64 * width + 1e-9).floor() as usize).max(1)).collect();
        PatchMlpConfig {
            in_channels,
            out_channels: 3,
            patch: BURGER_PATCH,
            stride: BURGER_STRIDE,
            hidden,
            activation,
            sigma: BURGER_PATCH as f64 / 4.0,
        }
    }

    /// Checks the fields; [`PatchMlp::new`] calls it.
    pub fn validate(&self) -> Result<()> {
        if self.in_channels == 0 || self.out_channels == 0 {
            bail!(
                "PatchMlpConfig: in_channels ({}) and out_channels ({}) must be > 0",
                self.in_channels,
                self.out_channels
            )
        }
        if self.patch == 0 || self.stride == 0 || self.stride > self.patch {
            bail!(
                "PatchMlpConfig: need 1 ≤ stride ≤ patch so that the patches cover every pixel, got patch {} and \
                 stride {}",
                self.patch,
                self.stride
            )
        }
        if self.hidden.contains(&0) {
            bail!("PatchMlpConfig: every hidden layer needs at least one unit, got {:?}", self.hidden)
        }
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            bail!("PatchMlpConfig: the Gaussian window's sigma must be finite and > 0, got {}", self.sigma)
        }
        Ok(())
    }

    /// `(name, inputs, outputs)` of every fully connected layer: `hidden0`, `hidden1`, ..., `output`. Their
    /// tensors are `<name>.weight` (`outputs × inputs`) and `<name>.bias`.
    pub fn layers(&self) -> Vec<(String, usize, usize)> {
        let area = self.patch * self.patch;
        let mut layers = Vec::new();
        let mut inputs = area * self.in_channels;
        for (i, &units) in self.hidden.iter().enumerate() {
            layers.push((format!("hidden{i}"), inputs, units));
            inputs = units;
        }
        layers.push(("output".to_string(), inputs, area * self.out_channels));
        layers
    }

    /// The number of weights and biases.
    pub fn parameter_count(&self) -> usize {
        self.layers().iter().map(|(_, i, o)| o * (i + 1)).sum()
    }

    /// Multiply-adds of one forward pass on a `height × width` image: one MLP evaluation per patch of the
    /// grid [`PatchMlp::forward`] lays over the image (the merge is not counted).
    pub fn multiply_adds(&self, height: usize, width: usize) -> u64 {
        let grid = Grid::new(height, width, self.patch, self.stride);
        let per_patch: usize = self.layers().iter().map(|(_, i, o)| i * o).sum();
        (grid.rows * grid.cols * per_patch) as u64
    }

    /// The Gaussian window over one patch, row-major, `exp(−d² / 2σ²)` with `d` the distance to the centre.
    fn window(&self) -> Vec<f32> {
        let c = (self.patch as f64 - 1.0) / 2.0;
        let mut w = Vec::with_capacity(self.patch * self.patch);
        for y in 0..self.patch {
            for x in 0..self.patch {
                let d2 = (y as f64 - c).powi(2) + (x as f64 - c).powi(2);
                w.push((-d2 / (2.0 * self.sigma * self.sigma)).exp() as f32);
            }
        }
        w
    }
}

/// Where the patches of one image lie: the image is padded (replicating its border pixels) by `top`/`left`
/// and to `height × width` so that a `rows × cols` grid of patches at the stride covers it exactly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Grid {
    rows: usize,
    cols: usize,
    height: usize,
    width: usize,
    top: usize,
    left: usize,
}

impl Grid {
    fn new(h: usize, w: usize, patch: usize, stride: usize) -> Grid {
        // Per axis: the fewest patches at the stride that cover `n` pixels; the extra pixels are split
        // between both sides so that the image sits in the middle of the grid.
        let axis = |n: usize| {
            let count = if n <= patch { 1 } else { (n - patch).div_ceil(stride) + 1 };
            let padded = (count - 1) * stride + patch;
            (count, padded, (padded - n) / 2)
        };
        let ((rows, height, top), (cols, width, left)) = (axis(h), axis(w));
        Grid { rows, cols, height, width, top, left }
    }

    /// For the patches `range` (row-major over the grid) and every pixel of each (row-major): the pixel's
    /// index in the padded image, `y × width + x`.
    fn indices(&self, patch: usize, stride: usize, range: std::ops::Range<usize>) -> Vec<u32> {
        let mut ids = Vec::with_capacity(range.len() * patch * patch);
        for k in range {
            let (py, px) = (k / self.cols, k % self.cols);
            for dy in 0..patch {
                let row = (py * stride + dy) * self.width + px * stride;
                ids.extend((0..patch).map(|dx| (row + dx) as u32));
            }
        }
        ids
    }
}

/// One fully connected layer, `y = x Wᵀ + b`.
#[derive(Clone, Debug)]
struct Dense {
    name: String,
    weight: Tensor,
    bias: Tensor,
}

impl Dense {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        x.matmul(&self.weight.t()?)?.broadcast_add(&self.bias)
    }
}

/// Burger et al.'s patch MLP on NCHW images of any size; see the module documentation. The output has
/// `out_channels` and the input's height and width.
#[derive(Clone, Debug)]
pub struct PatchMlp {
    cfg: PatchMlpConfig,
    layers: Vec<Dense>,
    /// The Gaussian window, `1 × 1 × patch² × 1`, in the weights' dtype.
    window: Tensor,
}

impl PatchMlp {
    /// Builds the network, taking (or creating, with a `VarMap`-backed builder) `hidden0.weight`,
    /// `hidden0.bias`, ..., `output.bias` under `vb`'s prefix. New weights and biases are uniform in
    /// ±1/√inputs (PyTorch's default for `nn.Linear`, as [`init_weights`](crate::init_weights) draws them).
    pub fn new(vb: VarBuilder, cfg: &PatchMlpConfig) -> Result<Self> {
        cfg.validate()?;
        let layers = cfg
            .layers()
            .into_iter()
            .map(|(name, inputs, outputs)| {
                let vb = vb.pp(&name);
                let bound = 1.0 / (inputs as f64).sqrt();
                let init = candle_nn::Init::Uniform { lo: -bound, up: bound };
                let weight = vb.get_with_hints((outputs, inputs), "weight", init)?;
                let bias = vb.get_with_hints(outputs, "bias", init)?;
                Ok(Dense { name, weight, bias })
            })
            .collect::<Result<Vec<_>>>()?;
        let area = cfg.patch * cfg.patch;
        let window = Tensor::from_vec(cfg.window(), (1, 1, area, 1), vb.device())?.to_dtype(vb.dtype())?;
        Ok(PatchMlp { cfg: cfg.clone(), layers, window })
    }

    pub fn config(&self) -> &PatchMlpConfig {
        &self.cfg
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        self.window.device()
    }

    /// Every weight and bias as `(name, tensor)`, input layer first.
    pub fn named_tensors(&self) -> Vec<(String, Tensor)> {
        self.layers
            .iter()
            .flat_map(|l| {
                [(format!("{}.weight", l.name), l.weight.clone()), (format!("{}.bias", l.name), l.bias.clone())]
            })
            .collect()
    }

    /// The MLP on patch rows `(N · patches) × (patch² · in_channels)`.
    fn mlp(&self, rows: &Tensor) -> Result<Tensor> {
        let mut y = rows.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            y = layer.forward(&y)?;
            if i < last {
                y = match self.cfg.activation {
                    Activation::Tanh => y.tanh()?,
                    Activation::Relu => y.relu()?,
                };
            }
        }
        Ok(y)
    }

    /// [`Module::forward`] with the patches run through the MLP `chunk` at a time per image, which bounds the
    /// memory of large images (patch indices, gathered rows, hidden activations and window weights live one
    /// chunk at a time) without changing the result.
    fn forward_chunked(&self, x: &Tensor, chunk: usize) -> Result<Tensor> {
        let (n, c, h, w) = match x.dims4() {
            Ok(d) => d,
            Err(_) => bail!("PatchMlp input must be NCHW, got shape {:?}", x.dims()),
        };
        if c != self.cfg.in_channels {
            bail!("PatchMlp input has {c} channels but the network was built for {}", self.cfg.in_channels)
        }
        if h == 0 || w == 0 {
            bail!("PatchMlp input must not be empty, got shape {:?}", x.dims())
        }
        let (p, s) = (self.cfg.patch, self.cfg.stride);
        let p2 = p * p;
        let grid = Grid::new(h, w, p, s);
        let x = x.pad_with_same(2, grid.top, grid.height - h - grid.top)?;
        let x = x.pad_with_same(3, grid.left, grid.width - w - grid.left)?;
        // Pixels as rows of channels, so that a patch is `patch²` gathered rows: `N × (H · W) × C`.
        let pixels = x.permute((0, 2, 3, 1))?.contiguous()?.reshape((n, grid.height * grid.width, c))?;
        let patches = grid.rows * grid.cols;
        let mut sum = Tensor::zeros((n, grid.height * grid.width, self.cfg.out_channels), x.dtype(), x.device())?;
        // The summed weights do not depend on the data: no gradient flows through them. Every padded pixel lies
        // in at least one patch (stride ≤ patch) and the window is positive, so none is 0.
        let mut norm = Tensor::zeros((1, grid.height * grid.width, 1), x.dtype(), x.device())?;
        for start in (0..patches).step_by(chunk.max(1)) {
            let m = chunk.max(1).min(patches - start);
            let ids = Tensor::from_vec(grid.indices(p, s, start..start + m), m * p2, x.device())?;
            let rows = pixels.index_select(&ids, 1)?.reshape((n * m, p2 * c))?;
            sum = self.accumulate(&sum, &self.mlp(&rows)?, &ids)?;
            norm = norm.index_add(&ids, &self.window_rows(m)?, 1)?;
        }
        self.normalize(&sum, &norm, grid, h, w)
    }

    /// The window's weights for `m` patches, as the rows `index_add` spreads over their pixels:
    /// `1 × (m · patch²) × 1`, detached (no gradient flows through the normalization).
    fn window_rows(&self, m: usize) -> Result<Tensor> {
        let p2 = self.cfg.patch * self.cfg.patch;
        Ok(self.window.reshape((1, p2, 1))?.repeat((1, m, 1))?.detach())
    }

    /// The weighted sums `sum` (`N × pixels × C`) divided by the summed weights `norm` (`1 × pixels × 1`),
    /// cropped back to `h × w`: `N × C × h × w`.
    fn normalize(&self, sum: &Tensor, norm: &Tensor, grid: Grid, h: usize, w: usize) -> Result<Tensor> {
        let (n, _, c) = sum.dims3()?;
        let image = sum.broadcast_div(norm)?.reshape((n, grid.height, grid.width, c))?.permute((0, 3, 1, 2))?;
        image.narrow(2, grid.top, h)?.narrow(3, grid.left, w)?.contiguous()
    }

    /// Adds output rows `(N · m) × (patch² · C)` of `m` patches, each weighted by the Gaussian window, at their
    /// pixels `ids` (`m · patch²`) to `sum` (`N × pixels × C`).
    fn accumulate(&self, sum: &Tensor, rows: &Tensor, ids: &Tensor) -> Result<Tensor> {
        let p2 = self.cfg.patch * self.cfg.patch;
        let (n, _, c) = sum.dims3()?;
        let m = ids.dims1()? / p2;
        let weighted = rows.reshape((n, m, p2, c))?.broadcast_mul(&self.window)?.reshape((n, m * p2, c))?;
        sum.index_add(ids, &weighted, 1)
    }
}

/// Patches per MLP call and image in [`PatchMlp::forward`]: 4096 rows of 17²·12 inputs are 57 MB; a training
/// batch of 64² crops (289 patches each) is one call.
const CHUNK_PATCHES: usize = 4096;

impl Module for PatchMlp {
    /// `N × in_channels × H × W` to `N × out_channels × H × W`, for any `H, W ≥ 1`: pad by replicating the
    /// border so that the patch grid covers the image, gather the patches, run the MLP, weight each output
    /// patch by the Gaussian window, sum where patches overlap, divide by the summed weights, crop back.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_chunked(x, CHUNK_PATCHES)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use candle_core::{DType, IndexOp, Var};

    use super::*;

    fn config(in_channels: usize, patch: usize, stride: usize, hidden: Vec<usize>) -> PatchMlpConfig {
        PatchMlpConfig {
            in_channels,
            out_channels: 3,
            patch,
            stride,
            hidden,
            activation: Activation::Tanh,
            sigma: patch as f64 / 4.0,
        }
    }

    fn ramp(dims: (usize, usize, usize, usize), dtype: DType) -> Result<Tensor> {
        let n = dims.0 * dims.1 * dims.2 * dims.3;
        let v: Vec<f32> = (0..n).map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.3).collect();
        Tensor::from_vec(v, dims, &Device::Cpu)?.to_dtype(dtype)
    }

    /// With no hidden layer, an identity output layer and a zero bias, every output patch is its input
    /// patch: merging them must give back the image, whatever the weights of the overlaps, including at
    /// the replicated borders and for sizes that are not a multiple of the stride.
    #[test]
    fn merging_identity_patches_reproduces_the_image() -> Result<()> {
        let cfg = config(3, 17, 3, vec![]);
        let len = 17 * 17 * 3;
        let tensors = HashMap::from([
            ("output.weight".to_string(), Tensor::eye(len, DType::F32, &Device::Cpu)?),
            ("output.bias".to_string(), Tensor::zeros(len, DType::F32, &Device::Cpu)?),
        ]);
        let net = PatchMlp::new(VarBuilder::from_tensors(tensors, DType::F32, &Device::Cpu), &cfg)?;
        for (h, w) in [(32, 32), (20, 23), (5, 40), (1, 1)] {
            let x = ramp((2, 3, h, w), DType::F32)?;
            let y = net.forward(&x)?;
            let err = (&y - &x)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
            // A weighted mean of equal values: only rounding (a few ulps of values below 1) may differ.
            assert!(err < 1e-6, "{h}x{w}: identity patches merge to an image off by {err}");
        }
        Ok(())
    }

    /// Two overlapping patches, one all 1 and one all 0, merge to the Gaussian-weighted mean the documentation
    /// states: at column x of the overlap, w₀ / (w₀ + w₁) with wᵢ = exp(−dᵢ² / 2σ²) and dᵢ the distance to
    /// patch i's centre (the rows' terms cancel); outside the overlap the one patch's value.
    #[test]
    fn overlaps_are_weighted_by_the_gaussian_window() -> Result<()> {
        let cfg = config(3, 17, 3, vec![]);
        let net = PatchMlp::new(VarBuilder::from_varmap(&candle_nn::VarMap::new(), DType::F32, &Device::Cpu), &cfg)?;
        let (h, w) = (17, 20);
        let grid = Grid::new(h, w, 17, 3);
        assert_eq!((grid.rows, grid.cols, grid.top, grid.left), (1, 2, 0, 0));
        let ids = Tensor::from_vec(grid.indices(17, 3, 0..2), 2 * 17 * 17, &Device::Cpu)?;
        let rows = Tensor::cat(
            &[
                Tensor::ones((1, 17 * 17 * 3), DType::F32, &Device::Cpu)?,
                Tensor::zeros((1, 17 * 17 * 3), DType::F32, &Device::Cpu)?,
            ],
            0,
        )?;
        let sum = Tensor::zeros((1, h * w, 3), DType::F32, &Device::Cpu)?;
        let norm = Tensor::zeros((1, h * w, 1), DType::F32, &Device::Cpu)?.index_add(&ids, &net.window_rows(2)?, 1)?;
        let merged = net.normalize(&net.accumulate(&sum, &rows, &ids)?, &norm, grid, h, w)?;
        let merged = merged.i((0, 1, 5))?.to_vec1::<f32>()?;
        let s2 = 2.0 * cfg.sigma * cfg.sigma;
        for (x, &got) in merged.iter().enumerate() {
            let want = match x {
                0..3 => 1.0,
                17.. => 0.0,
                _ => {
                    let (w0, w1) = ((-(x as f64 - 8.0).powi(2) / s2).exp(), (-(x as f64 - 11.0).powi(2) / s2).exp());
                    w0 / (w0 + w1)
                }
            };
            assert!((got as f64 - want).abs() < 1e-6, "column {x}: {got} instead of {want}");
        }
        Ok(())
    }

    #[test]
    fn output_has_the_input_size() -> Result<()> {
        let varmap = candle_nn::VarMap::new();
        let cfg = config(4, 17, 3, vec![8]);
        let net = PatchMlp::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
        for (h, w) in [(1, 1), (7, 19), (17, 17), (18, 31), (33, 20), (64, 64)] {
            let x = ramp((2, 4, h, w), DType::F32)?;
            let y = net.forward(&x)?;
            assert_eq!(y.dims(), &[2, 3, h, w]);
            // Running the patches a few at a time changes only the order of the sums.
            let d = (net.forward_chunked(&x, 5)? - &y)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
            assert!(d < 1e-5, "{h}x{w}: chunked forward differs by {d}");
        }
        assert!(net.forward(&ramp((1, 3, 8, 8), DType::F32)?).unwrap_err().to_string().contains("4"));
        Ok(())
    }

    /// Autograd against central finite differences in f64 on a tiny instance (2 channels, 5×5 patches at
    /// stride 2, one hidden layer of 4, a 7×6 image), for the input and for a weight of each layer.
    #[test]
    fn gradients_match_finite_differences() -> Result<()> {
        let dev = Device::Cpu;
        let cfg = config(2, 5, 2, vec![4]);
        let varmap = candle_nn::VarMap::new();
        let net = PatchMlp::new(VarBuilder::from_varmap(&varmap, DType::F64, &dev), &cfg)?;
        let x = Var::from_tensor(&ramp((1, 2, 7, 6), DType::F64)?)?;
        let probe = ramp((1, 3, 7, 6), DType::F64)?.sin()?;
        // Three patches per MLP call: the gradient flows through several gathers and scatter-adds.
        let loss = || -> Result<f64> { (net.forward_chunked(&x, 3)? * &probe)?.sum_all()?.to_scalar::<f64>() };
        let grads = (net.forward_chunked(&x, 3)? * &probe)?.sum_all()?.backward()?;
        let eps = 1e-6;
        // Central differences in f64 are accurate to about eps² · f''' + ulp / eps ≈ 1e-10 here.
        let tolerance = 1e-7;
        let check = |name: &str, var: &Var, analytic: &Tensor| -> Result<()> {
            let analytic = analytic.flatten_all()?.to_vec1::<f64>()?;
            let base = var.as_tensor().flatten_all()?.to_vec1::<f64>()?;
            for i in (0..base.len()).step_by(base.len().div_ceil(12)) {
                let at = |d: f64| -> Result<f64> {
                    let mut v = base.clone();
                    v[i] += d;
                    var.set(&Tensor::from_vec(v, var.dims(), &dev)?)?;
                    loss()
                };
                let numeric = (at(eps)? - at(-eps)?) / (2.0 * eps);
                at(0.0)?;
                let diff = (numeric - analytic[i]).abs();
                assert!(diff < tolerance, "{name}[{i}]: autograd {} vs finite difference {numeric}", analytic[i]);
            }
            Ok(())
        };
        check("input", &x, grads.get(&x).expect("input gradient"))?;
        let vars = varmap.data().lock().unwrap().clone();
        for name in ["hidden0.weight", "output.weight", "output.bias"] {
            let var = &vars[name];
            check(name, var, grads.get(var).expect("weight gradient"))?;
        }
        Ok(())
    }

    #[test]
    fn grid_covers_the_image() {
        // 64 = 17 + 15·3 + 2: 17 patches per axis cover 65 pixels, the one extra at the bottom/right.
        let g = Grid::new(64, 10, 17, 3);
        assert_eq!((g.rows, g.height, g.top), (17, 65, 0));
        assert_eq!((g.cols, g.width, g.left), (1, 17, 3));
        assert_eq!(config(3, 17, 3, vec![10]).multiply_adds(64, 10), 17 * (17 * 17 * 3 * 10 + 10 * 17 * 17 * 3));
    }
}
