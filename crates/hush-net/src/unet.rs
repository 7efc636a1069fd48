//! Open Image Denoise's U-Nets (`unet`, `unet_small`, `unet_large`) and the thesis' autoencoder without skip
//! connections, layer for layer, with a width multiplier.

use candle_core::{DType, Device, Module, Result, Tensor, bail};

use crate::conv::conv3x3;
use crate::direct;
use crate::resample::{max_pool2, upsample2, upsample2_cat};
use crate::transfer::Transfer;
use candle_nn::{VarBuilder, VarMap};
use hush_hash::{SplitMix64, fnv1a};
use serde::{Deserialize, Serialize};

/// Input height and width must be multiples of this (four 2×2 poolings).
pub const ALIGNMENT: usize = 16;

/// Which network. The layer names are OIDN's (`training/model.py`), so they are the weight keys of both
/// safetensors and TZA files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UNetKind {
    /// OIDN's `unet`: encoder 32, 48, 64, 80, 96; decoder 112, 96, 64/64, 64/32; output `dec_conv0`.
    Unet,
    /// OIDN's `unet_small`: encoder 32 throughout; decoder 64, 64, 64/32, 32/32; output `dec_conv0`.
    UnetSmall,
    /// OIDN's `unet_large`: two convolutions per encoder level (`enc_conv1a`, `enc_conv1b`, ...), widths
    /// 64, 96, 128, 192, 256; decoder 192, 128, 96, 64, and `dec_conv1c` as the output layer.
    UnetLarge,
    /// The thesis' M_DAE (§7.5.2): `unet` without its skip connections, a classical convolutional
    /// autoencoder (the decoder sees only the upsampled features).
    Autoencoder,
}

impl UNetKind {
    pub const ALL: [UNetKind; 4] = [UNetKind::Unet, UNetKind::UnetSmall, UNetKind::UnetLarge, UNetKind::Autoencoder];

    /// The serialized name: `unet`, `unet_small`, `unet_large`, `autoencoder`.
    pub fn name(self) -> &'static str {
        match self {
            UNetKind::Unet => "unet",
            UNetKind::UnetSmall => "unet_small",
            UNetKind::UnetLarge => "unet_large",
            UNetKind::Autoencoder => "autoencoder",
        }
    }

    /// Parses [`UNetKind::name`].
    pub fn parse(name: &str) -> Option<UNetKind> {
        UNetKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The layers at full width: per encoder level (the last one is the bottleneck), per decoder level
    /// (coarsest first), the base output width of each convolution; then the output layer's name.
    fn plan(self) -> Plan {
        type L = &'static [(&'static str, usize)];
        const UNET_ENC: [L; 5] = [
            &[("enc_conv0", 32), ("enc_conv1", 32)],
            &[("enc_conv2", 48)],
            &[("enc_conv3", 64)],
            &[("enc_conv4", 80)],
            &[("enc_conv5a", 96), ("enc_conv5b", 96)],
        ];
        const UNET_DEC: [L; 4] = [
            &[("dec_conv4a", 112), ("dec_conv4b", 112)],
            &[("dec_conv3a", 96), ("dec_conv3b", 96)],
            &[("dec_conv2a", 64), ("dec_conv2b", 64)],
            &[("dec_conv1a", 64), ("dec_conv1b", 32)],
        ];
        match self {
            UNetKind::Unet => Plan { enc: UNET_ENC, dec: UNET_DEC, out: "dec_conv0", skips: true },
            UNetKind::Autoencoder => Plan { enc: UNET_ENC, dec: UNET_DEC, out: "dec_conv0", skips: false },
            UNetKind::UnetSmall => Plan {
                enc: [
                    &[("enc_conv0", 32), ("enc_conv1", 32)],
                    &[("enc_conv2", 32)],
                    &[("enc_conv3", 32)],
                    &[("enc_conv4", 32)],
                    &[("enc_conv5a", 32), ("enc_conv5b", 32)],
                ],
                dec: [
                    &[("dec_conv4a", 64), ("dec_conv4b", 64)],
                    &[("dec_conv3a", 64), ("dec_conv3b", 64)],
                    &[("dec_conv2a", 64), ("dec_conv2b", 32)],
                    &[("dec_conv1a", 32), ("dec_conv1b", 32)],
                ],
                out: "dec_conv0",
                skips: true,
            },
            UNetKind::UnetLarge => Plan {
                enc: [
                    &[("enc_conv1a", 64), ("enc_conv1b", 64)],
                    &[("enc_conv2a", 96), ("enc_conv2b", 96)],
                    &[("enc_conv3a", 128), ("enc_conv3b", 128)],
                    &[("enc_conv4a", 192), ("enc_conv4b", 192)],
                    &[("enc_conv5a", 256), ("enc_conv5b", 256)],
                ],
                dec: [
                    &[("dec_conv4a", 192), ("dec_conv4b", 192)],
                    &[("dec_conv3a", 128), ("dec_conv3b", 128)],
                    &[("dec_conv2a", 96), ("dec_conv2b", 96)],
                    &[("dec_conv1a", 64), ("dec_conv1b", 64)],
                ],
                out: "dec_conv1c",
                skips: true,
            },
        }
    }
}

/// The layer table of one kind (see [`UNetKind::plan`]).
struct Plan {
    enc: [&'static [(&'static str, usize)]; 5],
    dec: [&'static [(&'static str, usize)]; 4],
    out: &'static str,
    skips: bool,
}

/// One 3×3 convolution of a network: OIDN's layer name and its channels. Its tensors are
/// `<name>.weight` (`out × in × 3 × 3`, OIHW) and `<name>.bias` (`out`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConvShape {
    pub name: &'static str,
    pub in_channels: usize,
    pub out_channels: usize,
}

/// What a U-Net's output layer predicts.
///
/// * `Direct`: the denoised color itself (OIDN's networks, the thesis's).
/// * `Kernel { size }`: kernel prediction (Bako et al. 2017, "Kernel-predicting convolutional networks for
///   denoising Monte Carlo renderings"; Vogels et al. 2018): the output layer (named [`KERNEL_LAYER`])
///   gives `size²` logits per pixel, a softmax over them makes normalized weights, and the denoised pixel
///   is the weighted average of the `size × size` neighbourhood of the noisy color in the network's
///   transfer space (the input's first three channels; beyond the image's edge the nearest edge pixel).
///   The output is thus a convex combination of what was rendered: it cannot invent a colour, only
///   choose which neighbours to trust.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Head {
    #[default]
    Direct,
    Kernel {
        size: usize,
    },
}

/// The name of a kernel-predicting network's output layer (`kernel_conv.weight`, `kernel_conv.bias`):
/// another name than a direct network's, so weights of one are never read as the other's.
pub const KERNEL_LAYER: &str = "kernel_conv";

/// The largest kernel [`Head::Kernel`] takes (KPCN's 21×21).
pub const MAX_KERNEL: usize = 21;

impl Head {
    pub fn is_direct(&self) -> bool {
        *self == Head::Direct
    }

    /// `direct` or `kernel:K` (K odd, 3 to [`MAX_KERNEL`]); `kernel` alone is 5×5.
    pub fn parse(s: &str) -> Option<Head> {
        match s.trim() {
            "direct" => Some(Head::Direct),
            "kernel" | "kpcn" => Some(Head::Kernel { size: 5 }),
            other => {
                let size = other.strip_prefix("kernel:").or(other.strip_prefix("kpcn:"))?.trim().parse().ok()?;
                let head = Head::Kernel { size };
                head.validate().ok().map(|_| head)
            }
        }
    }

    /// What [`Head::parse`] reads back: `direct`, `kernel:5`.
    pub fn name(&self) -> String {
        match self {
            Head::Direct => "direct".into(),
            Head::Kernel { size } => format!("kernel:{size}"),
        }
    }

    pub fn validate(&self) -> Result<()> {
        if let Head::Kernel { size } = *self
            && (size % 2 == 0 || !(3..=MAX_KERNEL).contains(&size))
        {
            bail!("a predicted kernel is k×k with k odd, 3 to {MAX_KERNEL}; got {size}")
        }
        Ok(())
    }
}

/// The shape of a [`UNet`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UNetConfig {
    pub kind: UNetKind,
    /// Channels of the input tensor, e.g. 3 (color) + 3 per auxiliary feature.
    pub in_channels: usize,
    /// Channels of the output tensor (3 for RGB).
    pub out_channels: usize,
    /// Multiplier on every hidden layer width: `max(1, ⌊base × width⌋)`, the thesis' rule (eq. 7.2,
    /// `c1 = ⌊c·0.66⌋`). 1.0 is OIDN's network; see [`UNetConfig::thesis_m1`] and [`UNetConfig::thesis_m2`].
    pub width: f64,
    /// What the output layer predicts; not written when direct, so files from before kernel prediction read
    /// and write unchanged.
    #[serde(default, skip_serializing_if = "Head::is_direct")]
    pub head: Head,
    /// Where a kernel head averages the noisy color. `None` (what files from before this field read as): in
    /// the network's transfer space, the input's first three channels as they are. `Some(t)`, `t` the
    /// model's transfer function: in linear light, the input's color through `t`'s inverse, averaged, and the
    /// average through `t` again, so that the output is a weighted mean of the rendered radiance. An average
    /// taken after a concave transfer is darker than the transfer of the average (Jensen's inequality): at a
    /// few samples a pixel, where neighbouring values differ by much, the transfer-space average is biased
    /// dark unless the network learns to lean on the brighter neighbours.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel_linear: Option<Transfer>,
}

/// The thesis' M1 capacity (§7.5.2, eq. 7.2): every width `⌊c·0.66⌋`.
pub const THESIS_M1_WIDTH: f64 = 0.66;
/// The thesis' M2 capacity (eq. 7.3): `⌊c1·0.5⌋` with `c1` of M1, which for every base width of these
/// networks equals `⌊c·0.33⌋` (a unit test checks each).
pub const THESIS_M2_WIDTH: f64 = 0.33;

impl UNetConfig {
    /// OIDN's `unet` at full width with 3 output channels.
    pub fn oidn(in_channels: usize) -> Self {
        UNetConfig {
            kind: UNetKind::Unet,
            in_channels,
            out_channels: 3,
            width: 1.0,
            head: Head::Direct,
            kernel_linear: None,
        }
    }

    /// A U-Net of `kind` at width multiplier `width` with 3 output channels, predicting them directly.
    pub fn new(kind: UNetKind, in_channels: usize, width: f64) -> Self {
        UNetConfig { kind, in_channels, out_channels: 3, width, head: Head::Direct, kernel_linear: None }
    }

    /// The same network with another output head (a direct one averages nothing: no kernel space).
    pub fn with_head(&self, head: Head) -> Self {
        let kernel_linear = if head.is_direct() { None } else { self.kernel_linear };
        UNetConfig { head, kernel_linear, ..self.clone() }
    }

    /// The same network with its kernels averaging in linear light through `transfer`'s inverse (`Some`) or
    /// in the transfer space (`None`); see [`UNetConfig::kernel_linear`].
    pub fn with_kernel_linear(&self, transfer: Option<Transfer>) -> Self {
        UNetConfig { kernel_linear: transfer, ..self.clone() }
    }

    /// The thesis' M1: OIDN's `unet` with every hidden width `⌊c·0.66⌋`.
    pub fn thesis_m1(in_channels: usize) -> Self {
        UNetConfig { width: THESIS_M1_WIDTH, ..UNetConfig::oidn(in_channels) }
    }

    /// The thesis' M2: OIDN's `unet` with every hidden width `⌊⌊c·0.66⌋·0.5⌋`.
    pub fn thesis_m2(in_channels: usize) -> Self {
        UNetConfig { width: THESIS_M2_WIDTH, ..UNetConfig::oidn(in_channels) }
    }

    /// The thesis' M_DAE: OIDN's `unet` without skip connections, full width.
    pub fn thesis_dae(in_channels: usize) -> Self {
        UNetConfig { kind: UNetKind::Autoencoder, ..UNetConfig::oidn(in_channels) }
    }

    /// Checks the fields; [`UNet::new`] calls it.
    pub fn validate(&self) -> Result<()> {
        if self.in_channels == 0 || self.out_channels == 0 {
            bail!("UNetConfig: in_channels ({}) and out_channels ({}) must be > 0", self.in_channels, self.out_channels)
        }
        if !(self.width.is_finite() && self.width > 0.0) {
            bail!("UNetConfig: width must be a finite number > 0, got {}", self.width)
        }
        self.head.validate()?;
        if self.head.is_direct() && self.kernel_linear.is_some() {
            bail!("UNetConfig: a kernel space is set, but the network predicts colors directly (no kernels to average)")
        }
        if !self.head.is_direct() && (self.out_channels != 3 || self.in_channels < 3) {
            bail!(
                "UNetConfig: a kernel-predicting network filters the input's 3 color channels into 3 output \
                 channels; got {} in and {} out",
                self.in_channels,
                self.out_channels
            )
        }
        Ok(())
    }

    /// A hidden width after scaling: `max(1, ⌊base × width⌋)`. The tiny epsilon keeps products that are
    /// integers in exact arithmetic (0.1 × 80) from rounding down to the integer below.
    fn scaled(&self, base: usize) -> usize {
        ((base as f64 * self.width + 1e-9).floor() as usize).max(1)
    }

    /// Every convolution in the order the network applies them (encoder, decoder, output layer), which is
    /// also the order of OIDN's weight files.
    pub fn conv_shapes(&self) -> Vec<ConvShape> {
        let plan = self.kind.plan();
        let mut shapes = Vec::new();
        let mut c = self.in_channels;
        // Channels of the skip tensors: the input, then each pooled encoder level (pool1, pool2, pool3).
        let mut skips = vec![self.in_channels];
        for (level, layers) in plan.enc.iter().enumerate() {
            for &(name, base) in layers.iter() {
                let out = self.scaled(base);
                shapes.push(ConvShape { name, in_channels: c, out_channels: out });
                c = out;
            }
            if level < 3 {
                skips.push(c);
            }
        }
        for layers in plan.dec.iter() {
            let skip = skips.pop().expect("one skip per decoder level");
            for (i, &(name, base)) in layers.iter().enumerate() {
                let out = self.scaled(base);
                let in_channels = if i == 0 && plan.skips { c + skip } else { c };
                shapes.push(ConvShape { name, in_channels, out_channels: out });
                c = out;
            }
        }
        shapes.push(match self.head {
            Head::Direct => ConvShape { name: plan.out, in_channels: c, out_channels: self.out_channels },
            Head::Kernel { size } => ConvShape { name: KERNEL_LAYER, in_channels: c, out_channels: size * size },
        });
        shapes
    }

    /// Multiply-adds of one forward pass on a `height × width` input (already a multiple of
    /// [`ALIGNMENT`]): every 3×3 convolution at the resolution it runs at (encoder level `l` at
    /// `1/2^l`, the decoder levels at 1/8, 1/4, 1/2, 1, the output layer at full size). Pooling,
    /// upsampling, biases and activations are not counted. OIDN's `unet` on 9 channels does about 125k
    /// per pixel (`../shared/docs/anchors.md`). A kernel head adds its filtering, `size² × 3` per pixel
    /// (the softmax is not counted).
    pub fn multiply_adds(&self, height: usize, width: usize) -> u64 {
        let plan = self.kind.plan();
        let enc = plan.enc.iter().enumerate().flat_map(|(l, layers)| layers.iter().map(move |_| l));
        let dec = plan.dec.iter().enumerate().flat_map(|(l, layers)| layers.iter().map(move |_| 3 - l));
        let levels = enc.chain(dec).chain(std::iter::once(0));
        let convs: u64 = self
            .conv_shapes()
            .iter()
            .zip(levels)
            .map(|(s, level)| {
                let pixels = ((height >> level) * (width >> level)) as u64;
                (s.in_channels * s.out_channels * 9) as u64 * pixels
            })
            .sum();
        let filter = match self.head {
            Head::Direct => 0,
            Head::Kernel { size } => (size * size * 3 * height * width) as u64,
        };
        convs + filter
    }

    /// The number of weights and biases.
    pub fn parameter_count(&self) -> usize {
        self.conv_shapes().iter().map(|s| s.out_channels * (s.in_channels * 9 + 1)).sum()
    }
}

/// A 3×3 convolution with padding 1 and a bias: OIDN's `Conv`. Its tensors are `<name>.weight` (OIHW) and
/// `<name>.bias`.
#[derive(Clone, Debug)]
struct Conv3x3 {
    name: &'static str,
    weight: Tensor,
    bias: Tensor,
}

impl Conv3x3 {
    fn new(vb: &VarBuilder, shape: &ConvShape) -> Result<Self> {
        let vb = vb.pp(shape.name);
        let (in_c, out_c) = (shape.in_channels, shape.out_channels);
        // PyTorch's default initialisation of nn.Conv2d (kaiming_uniform with a = sqrt(5)) is
        // U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for both weight and bias, which is what OIDN trains from.
        let bound = 1.0 / ((in_c * 9) as f64).sqrt();
        let init = candle_nn::Init::Uniform { lo: -bound, up: bound };
        let weight = vb.get_with_hints((out_c, in_c, 3, 3), "weight", init)?;
        let bias = vb.get_with_hints(out_c, "bias", init)?;
        Ok(Conv3x3 { name: shape.name, weight, bias })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        conv3x3(x, &self.weight, &self.bias, false)
    }

    fn forward_relu(&self, x: &Tensor) -> Result<Tensor> {
        conv3x3(x, &self.weight, &self.bias, true)
    }
}

/// OIDN's U-Nets (`training/model.py`, `UNet`, `UNetSmall`, `UNetLarge`): 3×3 convolutions + ReLU, 2×2 max
/// pooling, nearest ×2 upsampling, skip connections by channel concatenation `[upsampled, skip]` (the
/// pooled encoder levels 3, 2, 1 and the input), no activation after the output layer. Input and output are
/// NCHW; see [`UNet::forward_padded`] for arbitrary sizes.
#[derive(Clone, Debug)]
pub struct UNet {
    cfg: UNetConfig,
    /// Per encoder level; levels 0–3 end in a 2×2 max pooling, level 4 is the bottleneck.
    enc: Vec<Vec<Conv3x3>>,
    /// Per decoder level, coarsest first; each starts with an upsampling (and a concatenation).
    dec: Vec<Vec<Conv3x3>>,
    out: Conv3x3,
    skips: bool,
    /// The inference path's packed weights and buffers ([`direct`]), shared by clones.
    direct: std::sync::Arc<DirectCache>,
}

/// What [`UNet`]'s inference path keeps between calls: its weights packed on first use (the tensors of a
/// network that runs it record no gradient, so they do not change) and its scratch buffers.
#[derive(Default)]
struct DirectCache {
    plan: std::sync::OnceLock<direct::Plan>,
    scratch: direct::Scratch,
}

impl std::fmt::Debug for DirectCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DirectCache {{ packed: {}, {:?} }}", self.plan.get().is_some(), self.scratch)
    }
}

impl UNet {
    /// Builds the network, taking (or creating, with a `VarMap`-backed builder) the tensors
    /// `enc_conv0.weight`, `enc_conv0.bias`, ... under `vb`'s prefix.
    pub fn new(vb: VarBuilder, cfg: &UNetConfig) -> Result<Self> {
        cfg.validate()?;
        let plan = cfg.kind.plan();
        let shapes = cfg.conv_shapes();
        let mut convs = shapes.iter().map(|s| Conv3x3::new(&vb, s)).collect::<Result<Vec<_>>>()?.into_iter();
        let mut take = |n: usize| convs.by_ref().take(n).collect::<Vec<_>>();
        let enc = plan.enc.iter().map(|l| take(l.len())).collect();
        let dec = plan.dec.iter().map(|l| take(l.len())).collect();
        let out = take(1).pop().expect("the output layer");
        Ok(UNet { cfg: cfg.clone(), enc, dec, out, skips: plan.skips, direct: Default::default() })
    }

    pub fn config(&self) -> &UNetConfig {
        &self.cfg
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        self.out.weight.device()
    }

    /// Every weight and bias as `(name, tensor)`, in the order of [`UNetConfig::conv_shapes`]
    /// (`enc_conv0.weight`, `enc_conv0.bias`, ...): what TZA export writes.
    pub fn named_tensors(&self) -> Vec<(String, Tensor)> {
        self.convs()
            .flat_map(|c| {
                [(format!("{}.weight", c.name), c.weight.clone()), (format!("{}.bias", c.name), c.bias.clone())]
            })
            .collect()
    }

    /// Every convolution in the order of [`UNetConfig::conv_shapes`].
    fn convs(&self) -> impl Iterator<Item = &Conv3x3> {
        self.enc.iter().chain(&self.dec).flatten().chain(std::iter::once(&self.out))
    }

    /// Pads `x` (NCHW) with zeros at the bottom and right to multiples of [`ALIGNMENT`], runs the
    /// network and crops the output back to the input's height and width. This is what OIDN's runtime does
    /// for an image that fits one tile: the image sits at the top left of a zero tile.
    ///
    /// A kernel head filters the unpadded input: its kernels are cropped first, so that no pixel draws on
    /// the zero padding.
    pub fn forward_padded(&self, x: &Tensor) -> Result<Tensor> {
        let (_, _, h, w) = x.dims4()?;
        let y = crop(&self.trunk(&pad_to_multiple(x, ALIGNMENT)?)?, h, w)?;
        self.apply_head(&y, x)
    }

    /// The output layer's result applied: itself for a direct network; for a kernel-predicting one, the
    /// noisy color of `input` filtered by the kernels `y` holds as logits ([`apply_kernels`]), in the transfer
    /// space or in linear light ([`UNetConfig::kernel_linear`]).
    fn apply_head(&self, y: &Tensor, input: &Tensor) -> Result<Tensor> {
        match self.cfg.head {
            Head::Direct => Ok(y.clone()),
            Head::Kernel { size } => {
                let color = input.narrow(1, 0, 3)?;
                match self.cfg.kernel_linear {
                    None => apply_kernels(y, &color, size),
                    Some(t) => {
                        let linear = t.inverse_tensor(&color)?.maximum(0.0)?;
                        t.forward_tensor(&apply_kernels(y, &linear, size)?)
                    }
                }
            }
        }
    }
}

impl Module for UNet {
    fn forward(&self, input: &Tensor) -> Result<Tensor> {
        let y = self.trunk(input)?;
        self.apply_head(&y, input)
    }
}

impl UNet {
    /// Every layer up to and including the output layer (for a direct network, the whole forward pass).
    fn trunk(&self, input: &Tensor) -> Result<Tensor> {
        let (_, c, h, w) = match input.dims4() {
            Ok(d) => d,
            Err(_) => bail!("UNet input must be NCHW, got shape {:?}", input.dims()),
        };
        if c != self.cfg.in_channels {
            bail!("UNet input has {c} channels but the network was built for {}", self.cfg.in_channels)
        }
        if h % ALIGNMENT != 0 || w % ALIGNMENT != 0 || h == 0 || w == 0 {
            bail!(
                "UNet input is {h}x{w} (HxW); both must be non-zero multiples of {ALIGNMENT} \
                 (use forward_padded or pad_to_multiple)"
            )
        }
        if self.runs_direct(input) {
            return self.forward_direct(input);
        }
        // skips = [input, pool1, pool2, pool3]
        let mut skips = vec![input.clone()];
        let mut x = input.clone();
        for (level, convs) in self.enc.iter().enumerate() {
            for conv in convs {
                x = conv.forward_relu(&x)?;
            }
            if level < 4 {
                x = max_pool2(&x)?;
                if level < 3 {
                    skips.push(x.clone());
                }
            }
        }
        for convs in &self.dec {
            let skip = skips.pop().expect("one skip per decoder level");
            x = if self.skips { upsample2_cat(&x, &skip)? } else { upsample2(&x)? };
            for conv in convs {
                x = conv.forward_relu(&x)?;
            }
        }
        self.out.forward(&x)
    }
}

impl UNet {
    /// Whether [`Module::forward`] takes [`direct`]'s convolutions: on a CPU with AVX-512 for f32 tensors
    /// of which none records a gradient (inference; training keeps Candle's autograd).
    fn runs_direct(&self, input: &Tensor) -> bool {
        self.weights_run_direct() && input.device().is_cpu() && input.dtype() == DType::F32 && !input.track_op()
    }

    /// Whether this CPU and these weights (f32 on the CPU, recording no gradient) take [`direct`].
    fn weights_run_direct(&self) -> bool {
        direct::available()
            && self.device().is_cpu()
            && self.convs().all(|c| {
                c.weight.dtype() == DType::F32
                    && c.bias.dtype() == DType::F32
                    && !c.weight.track_op()
                    && !c.bias.track_op()
            })
    }

    /// [`crate::DenoiseNet::forward_hwc`] through [`direct`] (the image zero-padded to multiples of
    /// [`ALIGNMENT`] at the bottom and right inside it, as [`UNet::forward_padded`] pads).
    /// The input comes back (`Err`) where [`direct`] does not run.
    pub(crate) fn forward_hwc_direct(
        &self,
        input: Vec<f32>,
        width: usize,
        height: usize,
        channels: usize,
    ) -> std::result::Result<Result<Vec<f32>>, Vec<f32>> {
        if !self.weights_run_direct() || !self.cfg.head.is_direct() {
            return Err(input);
        }
        Ok((|| {
            if channels != self.cfg.in_channels || input.len() != width * height * channels {
                bail!(
                    "UNet: {} values of {channels} channel(s) do not make a {width}x{height} input of {} channels",
                    input.len(),
                    self.cfg.in_channels
                )
            }
            let plan = self.direct_plan_cached()?;
            Ok(direct::forward_hwc(plan, &self.direct.scratch, input, (width, height, channels)))
        })())
    }

    /// The forward pass through [`direct`], the weights packed for it on the first call.
    fn forward_direct(&self, input: &Tensor) -> Result<Tensor> {
        direct::forward_tensor(self.direct_plan_cached()?, &self.direct.scratch, input)
    }

    fn direct_plan_cached(&self) -> Result<&direct::Plan> {
        Ok(match self.direct.plan.get() {
            Some(plan) => plan,
            None => {
                let plan = self.direct_plan()?;
                self.direct.plan.get_or_init(|| plan)
            }
        })
    }

    /// The layers packed for [`direct`], the decoder's first convolutions split over their two sources.
    fn direct_plan(&self) -> Result<direct::Plan> {
        let layer = |c: &Conv3x3, sources: &[usize]| direct::Layer::new(&c.weight, &c.bias, sources);
        let inputs = |c: &Conv3x3| c.weight.dims4().map(|d| d.1);
        let mut prev = self.cfg.in_channels;
        let mut enc = Vec::new();
        for convs in &self.enc {
            let mut level = Vec::new();
            for c in convs {
                level.push(layer(c, &[inputs(c)?])?);
                prev = c.weight.dims4()?.0;
            }
            enc.push(level);
        }
        let mut dec = Vec::new();
        for convs in &self.dec {
            let mut level = Vec::new();
            for (i, c) in convs.iter().enumerate() {
                let ci = inputs(c)?;
                let sources = if i == 0 && self.skips { vec![prev, ci - prev] } else { vec![ci] };
                level.push(layer(c, &sources)?);
                prev = c.weight.dims4()?.0;
            }
            dec.push(level);
        }
        let out = layer(&self.out, &[inputs(&self.out)?])?;
        Ok(direct::Plan { enc, dec, out, skips: self.skips })
    }
}

/// Kernel prediction's filtering: per pixel, the softmax of the `size²` logits of `logits` (`N × size² × H ×
/// W`, row-major offsets from `(−r, −r)` to `(r, r)`, `r = size / 2`) weights the `size × size`
/// neighbourhood of `color` (`N × C × H × W`; outside the image, the nearest edge pixel). Differentiable in
/// both.
pub fn apply_kernels(logits: &Tensor, color: &Tensor, size: usize) -> Result<Tensor> {
    let (n, k, h, w) = logits.dims4()?;
    let (cn, c, ch, cw) = color.dims4()?;
    if k != size * size || (cn, ch, cw) != (n, h, w) {
        bail!(
            "apply_kernels: {size}×{size} kernels need {} logits per pixel of a {n}×{h}×{w} color; got logits {:?} \
             and color {:?}",
            size * size,
            logits.dims(),
            color.dims()
        )
    }
    if !logits.track_op() && !color.track_op() && logits.device().is_cpu() && color.device().is_cpu() {
        return apply_kernels_cpu(logits, color, size);
    }
    // The softmax, shifted by the maximum (detached: the shift changes no weight, so no gradient flows
    // through it).
    let shifted = logits.broadcast_sub(&logits.max_keepdim(1)?.detach())?.exp()?;
    let weights = shifted.broadcast_div(&shifted.sum_keepdim(1)?)?;
    let r = size / 2;
    let padded = color.pad_with_same(2, r, r)?.pad_with_same(3, r, r)?;
    if weights.track_op() {
        // Training: per color channel, its `size²` shifted copies side by side (`N × size² × H × W`,
        // contiguous) times the weights, summed over the taps. The weights are never sliced, so their
        // gradient is one product per channel rather than one zero-padded tensor per tap.
        let channels = (0..c)
            .map(|ch| {
                let plane = padded.narrow(1, ch, 1)?;
                let taps = (0..size * size)
                    .map(|t| plane.narrow(2, t / size, h)?.narrow(3, t % size, w))
                    .collect::<Result<Vec<_>>>()?;
                (Tensor::cat(&taps, 1)? * &weights)?.sum_keepdim(1)
            })
            .collect::<Result<Vec<_>>>()?;
        return Tensor::cat(&channels, 1);
    }
    // Inference: tap by tap, in the memory of a few images.
    let mut out = color.zeros_like()?;
    for dy in 0..size {
        let rows = padded.narrow(2, dy, h)?;
        for dx in 0..size {
            out = (out + rows.narrow(3, dx, w)?.broadcast_mul(&weights.narrow(1, dy * size + dx, 1)?)?)?;
        }
    }
    Ok(out)
}

/// [`apply_kernels`] for inference on the CPU: per pixel, the softmax of its logits and the weighted sum of its
/// neighbourhood in one pass over the image (the tensor path makes `size²` passes over whole images, which at
/// 11×11 and 512² cost four times OIDN's network). The same operations in the same order as the tensor path.
fn apply_kernels_cpu(logits: &Tensor, color: &Tensor, size: usize) -> Result<Tensor> {
    use rayon::prelude::*;
    let (n, k, h, w) = logits.dims4()?;
    let c = color.dim(1)?;
    let dtype = color.dtype();
    let l = logits.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
    let x = color.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
    let (r, hw) = ((size / 2) as isize, h * w);
    // Rows of `c × w` values (pixel-major within a row), one per image row, filled in parallel.
    let mut rows = vec![0f32; n * h * c * w];
    rows.par_chunks_mut(c * w).enumerate().for_each(|(row, out)| {
        let (b, y) = (row / h, row % h);
        let (lb, xb) = (&l[b * k * hw..(b + 1) * k * hw], &x[b * c * hw..(b + 1) * c * hw]);
        // Each tap's weight and source pixel, computed once per pixel for every channel.
        let (mut weights, mut sources) = (vec![0f32; k], vec![0usize; k]);
        for px in 0..w {
            let at = y * w + px;
            let max = (0..k).map(|t| lb[t * hw + at]).fold(f32::NEG_INFINITY, f32::max);
            let mut sum = 0f32;
            for (t, (wt, src)) in weights.iter_mut().zip(&mut sources).enumerate() {
                *wt = (lb[t * hw + at] - max).exp();
                sum += *wt;
                // The nearest edge pixel outside the image, as `pad_with_same`.
                let sy = (y as isize + (t / size) as isize - r).clamp(0, h as isize - 1) as usize;
                let sx = (px as isize + (t % size) as isize - r).clamp(0, w as isize - 1) as usize;
                *src = sy * w + sx;
            }
            weights.iter_mut().for_each(|wt| *wt /= sum);
            for ch in 0..c {
                let plane = &xb[ch * hw..(ch + 1) * hw];
                out[ch * w + px] = weights.iter().zip(&sources).fold(0f32, |acc, (wt, &src)| acc + plane[src] * wt);
            }
        }
    });
    // (N, H, C, W) → (N, C, H, W).
    Tensor::from_vec(rows, (n, h, c, w), &Device::Cpu)?.permute((0, 2, 1, 3))?.contiguous()?.to_dtype(dtype)
}

/// Pads an NCHW tensor with zeros at the bottom and right so that H and W are multiples of `multiple`.
pub fn pad_to_multiple(x: &Tensor, multiple: usize) -> Result<Tensor> {
    if multiple == 0 {
        bail!("pad_to_multiple: multiple must be > 0")
    }
    let (_, _, h, w) = x.dims4()?;
    let ph = h.div_ceil(multiple).max(1) * multiple - h;
    let pw = w.div_ceil(multiple).max(1) * multiple - w;
    let x = if ph > 0 { x.pad_with_zeros(2, 0, ph)? } else { x.clone() };
    if pw > 0 { x.pad_with_zeros(3, 0, pw) } else { Ok(x) }
}

/// The top-left `h`×`w` window of an NCHW tensor (undoes [`pad_to_multiple`]).
pub fn crop(x: &Tensor, h: usize, w: usize) -> Result<Tensor> {
    let (_, _, xh, xw) = x.dims4()?;
    if h > xh || w > xw {
        bail!("crop: cannot crop {xh}x{xw} to {h}x{w}")
    }
    x.narrow(2, 0, h)?.narrow(3, 0, w)
}

/// An interleaved HWC image (`data[(y * width + x) * channels + c]`) as a `1×C×H×W` f32 tensor.
pub fn hwc_to_nchw(data: &[f32], width: usize, height: usize, channels: usize, device: &Device) -> Result<Tensor> {
    if data.len() != width * height * channels {
        bail!("hwc_to_nchw: {} samples do not make a {width}x{height}x{channels} image", data.len())
    }
    Tensor::from_slice(data, (1, height, width, channels), device)?.permute((0, 3, 1, 2))?.contiguous()
}

/// A `1×C×H×W` tensor as an interleaved HWC f32 buffer (the inverse of [`hwc_to_nchw`]).
pub fn nchw_to_hwc(x: &Tensor) -> Result<Vec<f32>> {
    let (n, _, _, _) = x.dims4()?;
    if n != 1 {
        bail!("nchw_to_hwc: expected a batch of one image, got shape {:?}", x.dims())
    }
    x.to_dtype(candle_core::DType::F32)?.permute((0, 2, 3, 1))?.flatten_all()?.to_vec1::<f32>()
}

/// Re-initializes every variable of `varmap` reproducibly from `seed`, with PyTorch's default for
/// `nn.Conv2d` (what OIDN trains from): weight and bias uniform in ±1/√fan_in, where fan_in is the
/// product of a weight's dimensions after the first (for `x.bias`, that of `x.weight`).
///
/// Candle's CPU random generator cannot be seeded, so reproducible training calls this after
/// [`UNet::new`]. Each tensor draws from its own stream keyed by `seed` and its name, so the result does
/// not depend on the order of the map.
pub fn init_weights(varmap: &VarMap, seed: u64) -> Result<()> {
    let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
    for (name, var) in vars.iter() {
        let fan_in_of = |dims: &[usize]| dims.iter().skip(1).product::<usize>();
        let fan_in = if var.rank() >= 2 {
            fan_in_of(var.dims())
        } else if let Some(w) = name.strip_suffix(".bias").and_then(|p| vars.get(&format!("{p}.weight"))) {
            fan_in_of(w.dims())
        } else {
            bail!("init_weights: cannot tell the fan-in of {name} with shape {:?}", var.dims())
        };
        let bound = 1.0 / (fan_in.max(1) as f64).sqrt();
        let mut rng = SplitMix64(seed ^ fnv1a(name.as_bytes()));
        let values: Vec<f32> = (0..var.elem_count()).map(|_| ((rng.next_f64() * 2.0 - 1.0) * bound) as f32).collect();
        let t = Tensor::from_vec(values, var.dims(), var.device())?.to_dtype(var.dtype())?;
        var.set(&t)?;
    }
    Ok(())
}
