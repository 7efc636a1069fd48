//! Open Image Denoise 2.5.1's official weights, built into the library (Apache-2.0; the files and their
//! licence are in `data/weights/oidn-2.5.1/`), so that every evaluation can show Intel's model beside hush's
//! and fine-tuning can start from it without a Python install or a download.

use hush_net::{Feature, InputFeatures};

/// The OIDN release the weights are from.
pub const OIDN_VERSION: &str = "2.5.1";

/// One of OIDN's official weight files.
#[derive(Clone, Copy, Debug)]
pub struct OfficialWeights {
    /// OIDN's name for it, e.g. `rt_hdr_alb_nrm`.
    pub name: &'static str,
    /// Its auxiliary features (short names) after the color.
    pub aux: &'static [Feature],
    /// The TZA archive.
    pub bytes: &'static [u8],
}

impl OfficialWeights {
    /// The features the weights take.
    pub fn features(&self) -> InputFeatures {
        InputFeatures { aux: self.aux.to_vec() }
    }

    /// How a report names the method: `oidn-2.5.1 rt_hdr_alb_nrm`.
    pub fn method_name(&self) -> String {
        format!("oidn-{OIDN_VERSION} {}", self.name)
    }
}

/// OIDN's `unet` weights for HDR renders with noisy auxiliary images, by feature set.
pub const OFFICIAL: [OfficialWeights; 3] = [
    OfficialWeights { name: "rt_hdr", aux: &[], bytes: include_bytes!("../../../data/weights/oidn-2.5.1/rt_hdr.tza") },
    OfficialWeights {
        name: "rt_hdr_alb",
        aux: &[Feature::Albedo],
        bytes: include_bytes!("../../../data/weights/oidn-2.5.1/rt_hdr_alb.tza"),
    },
    OfficialWeights {
        name: "rt_hdr_alb_nrm",
        aux: &[Feature::Albedo, Feature::Normal],
        bytes: include_bytes!("../../../data/weights/oidn-2.5.1/rt_hdr_alb_nrm.tza"),
    },
];

/// The official weights whose features are `features`; for a feature set OIDN has no weights for, the most
/// informed of those that can start a network taking it ([`hush_net::Pretrained::adapt`]): every feature
/// of theirs is in `features`, albedo standing in for diffuse. So the thesis's diffuse + specular + normal
/// and albedo + normal + variance get `rt_hdr_alb_nrm`, color + variance `rt_hdr`.
pub fn official_for(features: &InputFeatures) -> OfficialWeights {
    let covered =
        |f: &Feature| features.aux.contains(f) || (*f == Feature::Albedo && features.aux.contains(&Feature::Diffuse));
    OFFICIAL
        .iter()
        .find(|w| w.aux == features.aux.as_slice())
        .or_else(|| OFFICIAL.iter().rev().find(|w| w.aux.iter().all(covered)))
        .copied()
        .unwrap_or(OFFICIAL[0])
}

/// The official weights called `name` (`rt_hdr`, `rt_hdr_alb`, `rt_hdr_alb_nrm`).
pub fn official(name: &str) -> Option<OfficialWeights> {
    OFFICIAL.iter().find(|w| w.name == name).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in bytes are the vendored files, and each holds a `unet` taking its features.
    #[test]
    fn built_in_weights_are_the_vendored_files() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/weights/oidn-2.5.1");
        for w in OFFICIAL {
            assert_eq!(w.bytes, std::fs::read(dir.join(format!("{}.tza", w.name))).unwrap().as_slice(), "{}", w.name);
            let p = hush_net::Pretrained::read(w.bytes, &candle_core::Device::Cpu).unwrap();
            assert_eq!(p.info.features, w.features(), "{}", w.name);
        }
        let dsnn = InputFeatures::parse("diff,spec,nrm").unwrap();
        assert_eq!(official_for(&dsnn).name, "rt_hdr_alb_nrm");
        assert_eq!(official_for(&InputFeatures::default()).name, "rt_hdr");
        let name = |f: &str| official_for(&InputFeatures::parse(f).unwrap()).name;
        assert_eq!(name("alb,nrm,var"), "rt_hdr_alb_nrm");
        assert_eq!(name("var"), "rt_hdr", "weights with albedo cannot start a network without it");
        assert_eq!(name("alb,var"), "rt_hdr_alb");
        assert_eq!(name("nrm"), "rt_hdr", "OIDN takes a normal only with an albedo");
        assert_eq!(name("diff,nrm"), "rt_hdr_alb_nrm");
    }
}
