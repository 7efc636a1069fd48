//! A trained model loaded from its file, applied to images: what `hush denoise` and the evaluation run.

use std::path::Path;

use anyhow::{Context, Result, bail};
use candle_core::Device;
use hush_dataset::Image;
use hush_net::{Feature, ModelInfo, Net, load_model, load_tza};

/// The auxiliary image of a dataset view for one feature. Fails for the variance where the dataset stores
/// none for that render (it was rendered before hush wrote variance files).
pub fn aux_of(view: &hush_dataset::ViewImages, f: Feature) -> Result<&Image> {
    Ok(match f {
        Feature::Albedo => &view.albedo,
        Feature::Normal => &view.normal,
        Feature::Diffuse => &view.diffuse,
        Feature::Specular => &view.specular,
        Feature::Variance => view.variance.as_ref().context(
            "the dataset stores no variance for this render (it was rendered before hush wrote variance files): \
             render the dataset again into a new folder, or train without the variance feature",
        )?,
    })
}

/// Writes the pixels of `color` whose every sample agreed into the denoised `out` ([`hush_net::keep_exact_pixels`]:
/// variance 0 and a positive color over the pixel's 3×3 neighbourhood); returns how many. `variance` is the
/// render's per-pixel variance of its mean (`hush render`'s `variance` layer).
pub fn keep_exact(out: &mut Image, color: &Image, variance: &Image) -> Result<usize> {
    check_sizes(out, color, variance, "keeping exact pixels")?;
    Ok(hush_net::keep_exact_pixels(&mut out.data, &color.data, &variance.data, out.width, out.height)?)
}

/// Mixes the noisy `color` back into the denoised `out` by each pixel's standard error
/// ([`hush_net::blend_input`], over a 5×5 window) with `tau` the network's relative error; returns the mean
/// weight of the input. `variance` as for [`keep_exact`].
pub fn blend_input(out: &mut Image, color: &Image, variance: &Image, tau: f32) -> Result<f32> {
    check_sizes(out, color, variance, "blending the input back")?;
    Ok(hush_net::blend_input(&mut out.data, &color.data, &variance.data, out.width, out.height, tau, BLEND_RADIUS)?)
}

/// The mean of several estimates of one image (a model's poses, an ensemble's members), then, with
/// `restore = Some(sigma)` and the render's `variance`, the input's low band put back where they disagree
/// ([`hush_net::ensemble::restore_low_band`]); returns the image and that step's mean weight.
pub fn combine(
    outputs: &[Image],
    color: &Image,
    variance: Option<&Image>,
    restore: Option<f32>,
) -> Result<(Image, Option<f32>)> {
    let first = outputs.first().context("no estimates to combine")?;
    let mut out = first.clone();
    for o in &outputs[1..] {
        if (o.width, o.height, o.channels) != (out.width, out.height, out.channels) {
            bail!("estimates of different sizes: {}×{} and {}×{}", out.width, out.height, o.width, o.height);
        }
        out.data.iter_mut().zip(&o.data).for_each(|(s, v)| *s += v);
    }
    let n = outputs.len() as f32;
    out.data.iter_mut().for_each(|v| *v /= n);
    let weight = match (restore, variance) {
        (Some(sigma), Some(variance)) if outputs.len() > 1 => {
            check_sizes(&out, color, variance, "restoring the input's low band")?;
            let refs: Vec<&[f32]> = outputs.iter().map(|o| o.data.as_slice()).collect();
            Some(hush_net::ensemble::restore_low_band(
                &mut out.data,
                &refs,
                &color.data,
                &variance.data,
                out.width,
                out.height,
                sigma,
            )?)
        }
        _ => None,
    };
    Ok((out, weight))
}

/// The window of [`blend_input`]'s variance: 5×5.
pub const BLEND_RADIUS: usize = 2;

fn check_sizes(out: &Image, color: &Image, variance: &Image, doing: &str) -> Result<()> {
    for (what, image) in [("color", color), ("variance", variance)] {
        if (image.width, image.height, image.channels) != (out.width, out.height, 3) {
            bail!(
                "{doing}: the {what} image is {}×{}×{} but the denoised image is {}×{}×3",
                image.width,
                image.height,
                image.channels,
                out.width,
                out.height
            );
        }
    }
    Ok(())
}

/// A trained model (a hush model or OIDN weights) and what it expects.
#[derive(Debug)]
pub struct Denoiser {
    net: Net,
    pub info: ModelInfo,
}

impl Denoiser {
    /// Loads a hush model (`.safetensors`, self-describing: a U-Net or the patch MLP) or OIDN weights (`.tza`,
    /// e.g. OIDN's official `rt_hdr_alb_nrm.tza`). A TZA file carries no feature list: 3 input channels mean
    /// color only, 6 color + albedo, 9 color + albedo + normal; the network kind comes from its tensor names and
    /// shapes.
    pub fn load(path: &Path) -> Result<Denoiser> {
        Denoiser::load_on(path, &crate::device(None)?)
    }

    /// [`Self::load`] onto `device`.
    pub fn load_on(path: &Path, device: &Device) -> Result<Denoiser> {
        let bytes = crate::read_weight_file(path).with_context(|| format!("reading model {}", path.display()))?;
        let is_tza = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("tza"));
        Denoiser::from_bytes_on(&bytes, is_tza, device).with_context(|| format!("loading model {}", path.display()))
    }

    /// [`Self::load`] of a file's bytes: TZA where `is_tza`, else a hush safetensors model.
    pub fn from_bytes(bytes: &[u8], is_tza: bool) -> Result<Denoiser> {
        Denoiser::from_bytes_on(bytes, is_tza, &crate::device(None)?)
    }

    /// [`Self::from_bytes`] onto `device`.
    pub fn from_bytes_on(bytes: &[u8], is_tza: bool, device: &Device) -> Result<Denoiser> {
        let (net, info) = if is_tza {
            load_tza(bytes, None, device).map(|(net, info)| (Net::from(net), info))?
        } else {
            load_model(bytes, device)?
        };
        Ok(Denoiser { net, info })
    }

    /// OIDN's official weights built into hush ([`crate::official`]).
    pub fn official(weights: &crate::official::OfficialWeights) -> Result<Denoiser> {
        Denoiser::official_on(weights, &crate::device(None)?)
    }

    /// [`Self::official`] onto `device`.
    pub fn official_on(weights: &crate::official::OfficialWeights, device: &Device) -> Result<Denoiser> {
        let (net, info) = load_tza(weights.bytes, Some(weights.features()), device)
            .with_context(|| format!("loading the built-in {}", weights.method_name()))?;
        Ok(Denoiser { net: Net::from(net), info })
    }

    /// The auxiliary features the model needs, in input order.
    pub fn features(&self) -> &[Feature] {
        &self.info.features.aux
    }

    /// Denoises linear HDR `color` with the auxiliary images in the order of [`Self::features`]:
    /// OIDN's runtime pipeline (`hush_net::denoise`: autoexposure of the input, transfer, network, inverse
    /// transfer).
    pub fn denoise(&self, color: &Image, aux: &[&Image]) -> Result<Image> {
        self.check_inputs(color, aux)?;
        let aux_data: Vec<&[f32]> = aux.iter().map(|a| a.data.as_slice()).collect();
        let out = hush_net::denoise(&self.net, &self.info, color.width, color.height, &color.data, &aux_data)?;
        Ok(Image::new(color.width, color.height, 3, out)?)
    }

    /// [`Self::denoise`] in the first `poses` of the square's 8 symmetries ([`hush_net::ensemble::pose`]: 2 the
    /// x flip, 4 the flips, 8 the flips and transposes): every input turned, denoised and turned back; one
    /// image per pose, the first the plain [`Self::denoise`].
    pub fn denoise_poses(&self, color: &Image, aux: &[&Image], poses: usize) -> Result<Vec<Image>> {
        use hush_net::ensemble::{POSES, pose, unpose};
        if !(1..=POSES).contains(&poses) {
            bail!("poses must be 1 to {POSES}, got {poses}");
        }
        self.check_inputs(color, aux)?;
        let (w, h) = (color.width, color.height);
        (0..poses)
            .map(|k| {
                let (c, pw, ph) = pose(&color.data, w, h, 3, k);
                let posed: Vec<Vec<f32>> = aux.iter().map(|a| pose(&a.data, w, h, 3, k).0).collect();
                let refs: Vec<&[f32]> = posed.iter().map(|a| a.as_slice()).collect();
                let y = hush_net::denoise(&self.net, &self.info, pw, ph, &c, &refs)?;
                Ok(Image::new(w, h, 3, unpose(&y, pw, ph, 3, k))?)
            })
            .collect()
    }

    fn check_inputs(&self, color: &Image, aux: &[&Image]) -> Result<()> {
        if color.channels != 3 {
            bail!("the color image has {} channels; 3 (RGB) are needed", color.channels);
        }
        if aux.len() != self.features().len() {
            bail!(
                "the model needs {} auxiliary images ({}), {} were given",
                self.features().len(),
                self.info.features,
                aux.len()
            );
        }
        for (f, a) in self.features().iter().zip(aux) {
            if (a.width, a.height, a.channels) != (color.width, color.height, 3) {
                bail!(
                    "the {} image is {}×{}×{} but the color image is {}×{}×3",
                    f.long_name(),
                    a.width,
                    a.height,
                    a.channels,
                    color.width,
                    color.height
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shared(path: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(path)
    }

    fn weights(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/weights/oidn-2.5.1").join(name)
    }

    /// `hush denoise --model rt_hdr_alb_nrm.tza`: the features come from the channel count, the kind from
    /// the tensor names; inputs of the wrong size or channel count are clear errors. (The image itself is
    /// checked against OIDN in hush-eval's golden test.)
    #[test]
    fn loads_oidn_weights_and_checks_inputs() {
        let model = Denoiser::load(&weights("rt_hdr_alb_nrm.tza")).unwrap();
        assert_eq!(model.features(), &[Feature::Albedo, Feature::Normal]);
        assert_eq!(model.info.net.as_unet().map(|c| c.kind), Some(hush_net::UNetKind::Unet));
        let small = Denoiser::load(&weights("rt_hdr_alb_nrm_small.tza")).unwrap();
        assert_eq!(small.info.net.as_unet().map(|c| c.kind), Some(hush_net::UNetKind::UnetSmall));

        let read = |name: &str| {
            let path = shared(&format!("reference/oidn-2.5.1/input_{name}.exr"));
            hush_dataset::read_rgb(path).unwrap().crop(200, 200, 40, 24).unwrap()
        };
        let (color, albedo, normal) = (read("color"), read("albedo"), read("normal"));
        let out = model.denoise(&color, &[&albedo, &normal]).unwrap();
        assert_eq!((out.width, out.height, out.channels), (40, 24, 3));
        assert!(out.data.iter().all(|v| v.is_finite() && *v >= 0.0) && out.data.iter().any(|v| *v > 0.0));

        let err = model.denoise(&color, &[&albedo]).unwrap_err().to_string();
        assert!(err.contains("needs 2 auxiliary images"), "{err}");
        let narrow = albedo.crop(0, 0, 39, 24).unwrap();
        let err = model.denoise(&color, &[&narrow, &normal]).unwrap_err().to_string();
        assert!(err.contains("albedo image is 39×24×3") && err.contains("40×24"), "{err}");
        let grey = color.select_channels(0..1).unwrap();
        let err = model.denoise(&grey, &[&albedo, &normal]).unwrap_err().to_string();
        assert!(err.contains("1 channels"), "{err}");

        let err = Denoiser::load(&weights("README.md")).map(|_| ()).unwrap_err();
        assert!(format!("{err:#}").contains("README.md"), "{err:#}");
    }
}
