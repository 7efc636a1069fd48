//! Every denoising network hush trains, behind one type: [`NetConfig`] (what a weights file records) and
//! [`Net`] (the built network), so that training, `hush denoise` and `hush eval` run a U-Net or the patch
//! MLP alike.

use candle_core::{Device, Module, Result, Tensor, bail};
use candle_nn::VarBuilder;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::patch_mlp::{PatchMlp, PatchMlpConfig};
use crate::tza::export_tza;
use crate::unet::{UNet, UNetConfig};

/// The serialized `kind` of a [`PatchMlpConfig`] (a U-Net's `kind` is its [`UNetKind`](crate::UNetKind)
/// name).
pub const PATCH_MLP_KIND: &str = "patch_mlp";

/// Which network, with its shape. Serialized as the inner configuration plus its `kind` (`unet`,
/// `unet_small`, `unet_large`, `autoencoder`, `patch_mlp`), so weight files and run configurations written
/// before the patch MLP existed (a bare [`UNetConfig`]) read unchanged.
#[derive(Clone, Debug, PartialEq)]
pub enum NetConfig {
    UNet(UNetConfig),
    PatchMlp(PatchMlpConfig),
}

impl From<UNetConfig> for NetConfig {
    fn from(cfg: UNetConfig) -> Self {
        NetConfig::UNet(cfg)
    }
}

impl From<PatchMlpConfig> for NetConfig {
    fn from(cfg: PatchMlpConfig) -> Self {
        NetConfig::PatchMlp(cfg)
    }
}

impl NetConfig {
    pub fn in_channels(&self) -> usize {
        match self {
            NetConfig::UNet(c) => c.in_channels,
            NetConfig::PatchMlp(c) => c.in_channels,
        }
    }

    pub fn out_channels(&self) -> usize {
        match self {
            NetConfig::UNet(c) => c.out_channels,
            NetConfig::PatchMlp(c) => c.out_channels,
        }
    }

    /// The U-Net's output head; the patch MLP predicts colors directly.
    pub fn head(&self) -> crate::unet::Head {
        match self {
            NetConfig::UNet(c) => c.head,
            NetConfig::PatchMlp(_) => crate::unet::Head::Direct,
        }
    }

    /// The same network for another number of input channels.
    pub fn with_in_channels(&self, in_channels: usize) -> NetConfig {
        match self {
            NetConfig::UNet(c) => NetConfig::UNet(UNetConfig { in_channels, ..c.clone() }),
            NetConfig::PatchMlp(c) => NetConfig::PatchMlp(PatchMlpConfig { in_channels, ..c.clone() }),
        }
    }

    /// The serialized kind: a U-Net kind's name or `patch_mlp`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            NetConfig::UNet(c) => c.kind.name(),
            NetConfig::PatchMlp(_) => PATCH_MLP_KIND,
        }
    }

    /// The U-Net configuration, `None` for another network.
    pub fn as_unet(&self) -> Option<&UNetConfig> {
        match self {
            NetConfig::UNet(c) => Some(c),
            NetConfig::PatchMlp(_) => None,
        }
    }

    /// Where a kernel-predicting U-Net averages ([`UNetConfig::kernel_linear`]); `None` for any other network.
    pub fn kernel_linear(&self) -> Option<crate::transfer::Transfer> {
        self.as_unet().and_then(|c| c.kernel_linear)
    }

    /// The same network with [`UNetConfig::kernel_linear`] set to `transfer` (a U-Net's; any other network as
    /// it is). The kernel space has no weights: weights loaded from a file take the space the training asks.
    pub fn with_kernel_linear(&self, transfer: Option<crate::transfer::Transfer>) -> NetConfig {
        match self {
            NetConfig::UNet(c) => c.with_kernel_linear(transfer).into(),
            other => other.clone(),
        }
    }

    /// One line for people: `unet (width 0.25, 9 input channels)`, `unet (width 1, 9 input channels,
    /// predicting 5×5 kernels)`,
    /// `patch_mlp (17×17 patches, stride 3, hidden 127,127,127,127, tanh, σ 4.25, 12 input channels)`.
    pub fn describe(&self) -> String {
        match self {
            NetConfig::UNet(c) => match c.head {
                crate::unet::Head::Direct => {
                    format!("{} (width {}, {} input channels)", c.kind.name(), c.width, c.in_channels)
                }
                crate::unet::Head::Kernel { size } => format!(
                    "{} (width {}, {} input channels, predicting {size}×{size} kernels{})",
                    c.kind.name(),
                    c.width,
                    c.in_channels,
                    if c.kernel_linear.is_some() { " averaging in linear light" } else { "" }
                ),
            },
            NetConfig::PatchMlp(c) => format!(
                "{PATCH_MLP_KIND} ({p}×{p} patches, stride {}, hidden {}, {}, σ {}, {} input channels)",
                c.stride,
                c.hidden.iter().map(|u| u.to_string()).collect::<Vec<_>>().join(","),
                c.activation.name(),
                c.sigma,
                c.in_channels,
                p = c.patch,
            ),
        }
    }

    pub fn validate(&self) -> Result<()> {
        match self {
            NetConfig::UNet(c) => c.validate(),
            NetConfig::PatchMlp(c) => c.validate(),
        }
    }

    /// Multiply-adds of one forward pass on a `height × width` input.
    pub fn multiply_adds(&self, height: usize, width: usize) -> u64 {
        match self {
            NetConfig::UNet(c) => c.multiply_adds(height, width),
            NetConfig::PatchMlp(c) => c.multiply_adds(height, width),
        }
    }
}

impl Serialize for NetConfig {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            NetConfig::UNet(c) => c.serialize(s),
            NetConfig::PatchMlp(c) => {
                #[derive(Serialize)]
                struct Tagged<'a> {
                    kind: &'static str,
                    #[serde(flatten)]
                    cfg: &'a PatchMlpConfig,
                }
                Tagged { kind: PATCH_MLP_KIND, cfg: c }.serialize(s)
            }
        }
    }
}

impl<'de> Deserialize<'de> for NetConfig {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error;
        let mut value = serde_json::Value::deserialize(d)?;
        let is_mlp = value.get("kind").and_then(|k| k.as_str()) == Some(PATCH_MLP_KIND);
        if is_mlp {
            if let Some(map) = value.as_object_mut() {
                map.remove("kind");
            }
            serde_json::from_value(value).map(NetConfig::PatchMlp).map_err(D::Error::custom)
        } else {
            serde_json::from_value(value).map(NetConfig::UNet).map_err(|e| {
                D::Error::custom(format!(
                    "{e} (a network is a U-Net, kind unet, unet_small, unet_large or autoencoder, or the \
                     {PATCH_MLP_KIND})"
                ))
            })
        }
    }
}

/// A built network of any kind.
#[derive(Clone, Debug)]
pub enum Net {
    UNet(UNet),
    PatchMlp(PatchMlp),
}

impl Net {
    /// Builds the network `cfg` describes from (or, with a `VarMap`-backed builder, into) `vb`.
    pub fn new(vb: VarBuilder, cfg: &NetConfig) -> Result<Net> {
        Ok(match cfg {
            NetConfig::UNet(c) => Net::UNet(UNet::new(vb, c)?),
            NetConfig::PatchMlp(c) => Net::PatchMlp(PatchMlp::new(vb, c)?),
        })
    }

    /// The same network on detached copies of its weights (sharing their storage): its forward pass
    /// records no graph, so a training run's evaluation frees each activation once the next layer
    /// has used it instead of keeping them all for a backward pass that never comes.
    pub fn frozen(&self) -> Result<Net> {
        let named = self.named_tensors();
        let dtype = named.first().map_or(candle_core::DType::F32, |(_, t)| t.dtype());
        let tensors = named.into_iter().map(|(name, t)| (name, t.detach())).collect();
        let device = self.device().clone();
        Net::new(VarBuilder::from_tensors(tensors, dtype, &device), &self.config())
    }

    pub fn config(&self) -> NetConfig {
        match self {
            Net::UNet(n) => n.config().clone().into(),
            Net::PatchMlp(n) => n.config().clone().into(),
        }
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        match self {
            Net::UNet(n) => n.device(),
            Net::PatchMlp(n) => n.device(),
        }
    }

    /// Every weight and bias as `(name, tensor)`.
    pub fn named_tensors(&self) -> Vec<(String, Tensor)> {
        match self {
            Net::UNet(n) => n.named_tensors(),
            Net::PatchMlp(n) => n.named_tensors(),
        }
    }

    /// Any height and width in, the same out: a U-Net pads to multiples of 16 and crops back
    /// ([`UNet::forward_padded`]); the patch MLP covers any size itself.
    pub fn forward_padded(&self, x: &Tensor) -> Result<Tensor> {
        match self {
            Net::UNet(n) => n.forward_padded(x),
            Net::PatchMlp(n) => n.forward(x),
        }
    }

    /// OIDN's Tensor Archive of a U-Net ([`export_tza`]). OIDN's runtime runs only its U-Nets, so any other
    /// network is refused.
    pub fn export_tza(&self) -> Result<Vec<u8>> {
        match self {
            Net::UNet(n) => export_tza(n),
            Net::PatchMlp(_) => bail!(
                "TZA export: OIDN's runtime runs only U-Nets (unet, unet_small, unet_large, autoencoder) and cannot \
                 run the {PATCH_MLP_KIND}; use its .safetensors file with `hush denoise` or `hush eval` instead"
            ),
        }
    }
}

impl From<UNet> for Net {
    fn from(n: UNet) -> Self {
        Net::UNet(n)
    }
}

impl Module for Net {
    /// The network's own forward: a U-Net needs multiples of 16 (see [`Net::forward_padded`]).
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        match self {
            Net::UNet(n) => n.forward(x),
            Net::PatchMlp(n) => n.forward(x),
        }
    }
}

/// A network [`denoise`](crate::denoise) can run: its configuration and a forward pass on any size.
pub trait DenoiseNet {
    fn net_config(&self) -> NetConfig;
    /// The device the weights live on.
    fn net_device(&self) -> &Device;
    /// `N × C × H × W` to `N × 3 × H × W` for any `H, W`.
    fn forward_any_size(&self, x: &Tensor) -> Result<Tensor>;
    /// One interleaved `height × width × channels` image to interleaved `height × width × 3`, for any
    /// size; the input is dropped as soon as the network has read it. By default through
    /// [`Self::forward_any_size`] on an NCHW tensor on the weights' device.
    fn forward_hwc(&self, input: Vec<f32>, width: usize, height: usize, channels: usize) -> Result<Vec<f32>> {
        forward_hwc_as_tensor(self, input, (width, height, channels))
    }
}

/// [`DenoiseNet::forward_hwc`] through [`DenoiseNet::forward_any_size`] on an NCHW tensor.
fn forward_hwc_as_tensor(
    net: &(impl DenoiseNet + ?Sized),
    input: Vec<f32>,
    (width, height, channels): (usize, usize, usize),
) -> Result<Vec<f32>> {
    let x = crate::unet::hwc_to_nchw(&input, width, height, channels, net.net_device())?;
    drop(input);
    crate::unet::nchw_to_hwc(&net.forward_any_size(&x)?)
}

impl DenoiseNet for Net {
    fn net_config(&self) -> NetConfig {
        self.config()
    }
    fn net_device(&self) -> &Device {
        self.device()
    }
    fn forward_any_size(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_padded(x)
    }
    fn forward_hwc(&self, input: Vec<f32>, width: usize, height: usize, channels: usize) -> Result<Vec<f32>> {
        match self {
            Net::UNet(n) => n.forward_hwc(input, width, height, channels),
            Net::PatchMlp(_) => forward_hwc_as_tensor(self, input, (width, height, channels)),
        }
    }
}

impl DenoiseNet for UNet {
    fn net_config(&self) -> NetConfig {
        self.config().clone().into()
    }
    fn net_device(&self) -> &Device {
        self.device()
    }
    fn forward_any_size(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_padded(x)
    }
    /// On a CPU with AVX-512 and weights that record no gradient, straight from the interleaved image
    /// into [`crate::direct`]'s blocked layout and back, without NCHW copies.
    fn forward_hwc(&self, input: Vec<f32>, width: usize, height: usize, channels: usize) -> Result<Vec<f32>> {
        match self.forward_hwc_direct(input, width, height, channels) {
            Ok(out) => out,
            Err(input) => forward_hwc_as_tensor(self, input, (width, height, channels)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch_mlp::Activation;
    use crate::unet::UNetKind;

    /// Configurations written before the patch MLP existed are bare U-Net configurations: they still read,
    /// and both kinds round-trip through JSON.
    #[test]
    fn serde_reads_old_unet_configs_and_round_trips_both() {
        let old = r#"{"kind":"autoencoder","in_channels":9,"out_channels":3,"width":0.5}"#;
        let cfg: NetConfig = serde_json::from_str(old).unwrap();
        let want = UNetConfig::new(UNetKind::Autoencoder, 9, 0.5);
        assert_eq!(cfg, NetConfig::UNet(want));
        assert_eq!(serde_json::to_string(&cfg).unwrap(), old);

        let mlp = NetConfig::from(PatchMlpConfig::burger(12, 0.0625, Activation::Relu));
        let json = serde_json::to_string(&mlp).unwrap();
        assert!(json.contains(r#""kind":"patch_mlp""#) && json.contains(r#""hidden":[127,127,127,127]"#), "{json}");
        assert_eq!(serde_json::from_str::<NetConfig>(&json).unwrap(), mlp);

        let err = serde_json::from_str::<NetConfig>(r#"{"kind":"resnet","in_channels":9}"#).unwrap_err();
        assert!(err.to_string().contains("patch_mlp"), "{err}");
    }

    /// A frozen copy computes what the trained network computes, without recording a graph. On a CPU
    /// with AVX-512 a frozen U-Net takes the inference path (`direct.rs`), whose sums run in another order:
    /// equal up to f32 rounding (1e-5 of the largest output, as `inference_path_matches_training_path`
    /// bounds it); elsewhere, and for the MLP, bit for bit.
    #[test]
    fn frozen_copies_compute_the_same_without_a_graph() -> Result<()> {
        for cfg in [
            NetConfig::from(UNetConfig::new(UNetKind::UnetSmall, 3, 0.25)),
            PatchMlpConfig::burger(3, 0.01, Activation::Tanh).into(),
        ] {
            let varmap = candle_nn::VarMap::new();
            let net = Net::new(VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &Device::Cpu), &cfg)?;
            crate::unet::init_weights(&varmap, 3)?;
            let x = Tensor::rand(0f32, 1f32, (1, 3, 16, 16), &Device::Cpu)?;
            let (trained, frozen) = (net.forward_padded(&x)?, net.frozen()?.forward_padded(&x)?);
            assert!(trained.track_op() && !frozen.track_op());
            let scale = trained.abs()?.max_all()?.to_scalar::<f32>()?;
            let diff = (trained - frozen)?.abs()?.max_all()?.to_scalar::<f32>()?;
            let direct = matches!(cfg, NetConfig::UNet(_)) && crate::direct::available();
            if direct {
                assert!(diff <= 1e-5 * scale, "{cfg:?}: max |diff| {diff} against max |y| {scale}");
            } else {
                assert_eq!(diff, 0.0, "{cfg:?}");
            }
        }
        Ok(())
    }

    #[test]
    fn tza_export_refuses_the_patch_mlp() -> Result<()> {
        let varmap = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &Device::Cpu);
        let net = Net::new(vb, &PatchMlpConfig::burger(3, 0.01, Activation::Tanh).into())?;
        let err = net.export_tza().unwrap_err().to_string();
        assert!(err.contains("OIDN") && err.contains("patch_mlp") && err.contains(".safetensors"), "{err}");
        Ok(())
    }
}
