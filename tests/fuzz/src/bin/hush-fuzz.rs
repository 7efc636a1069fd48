//! libFuzzer's entry: the target is named by `HUSH_FUZZ_TARGET` (one of `targets::TARGETS`); run by
//! `cargo xtask fuzz`, which builds this with sanitizer coverage. With `HUSH_FUZZ_WRITE_SEEDS=<dir>` it
//! writes the generated seeds instead (see `write_seeds`) and exits.
#![no_main]

#[path = "../../targets.rs"]
mod targets;

use std::sync::OnceLock;

/// xtask's sweep parser, compiled here as it is there (the `crate::util` it uses is this shim).
#[path = "../../../../xtask/src/sweep/spec.rs"]
#[allow(dead_code)]
mod spec;

#[allow(dead_code)]
mod util {
    pub type Result<T> = std::result::Result<T, String>;
    pub fn project_root() -> std::path::PathBuf {
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
    }
}

/// The repository's scales, which every fuzzed sweep is enumerated at.
fn scales() -> &'static [spec::Scale] {
    static SCALES: OnceLock<Vec<spec::Scale>> = OnceLock::new();
    SCALES.get_or_init(|| {
        let file = util::project_root().join("data/sweeps/scales.toml");
        spec::parse_scales(&std::fs::read_to_string(&file).expect("scales.toml"), &file).expect("scales.toml parses")
    })
}

fn target() -> &'static str {
    static TARGET: OnceLock<String> = OnceLock::new();
    TARGET.get_or_init(|| {
        let name = std::env::var("HUSH_FUZZ_TARGET").unwrap_or_default();
        assert!(
            name == "sweep" || targets::TARGETS.iter().any(|t| t.0 == name),
            "set HUSH_FUZZ_TARGET to one of {:?}",
            targets::TARGETS.iter().map(|t| t.0).collect::<Vec<_>>()
        );
        name
    })
}

libfuzzer_sys::fuzz_target!(
    init: {
        if let Some(out) = std::env::var_os("HUSH_FUZZ_WRITE_SEEDS") {
            write_seeds(std::path::Path::new(&out));
            std::process::exit(0);
        }
    },
    |data: &[u8]| {
        match target() {
            "sweep" => {
                if let Ok(text) = std::str::from_utf8(data) {
                    spec::fuzz_entry(text, scales());
                }
            }
            name => {
                targets::run(name, data);
            }
        }
    }
);

/// Writes the seeds that are not plain text files in the repository: a small EXR with the dataset's
/// layers and tiny weight files (TZA and a hush safetensors model), into `<out>/<target>/`.
fn write_seeds(out: &std::path::Path) {
    use candle_core::{DType, Device};
    use candle_nn::{VarBuilder, VarMap};
    use hush_dataset::Image;
    use hush_net::{InputFeatures, ModelInfo, UNet, UNetConfig, UNetKind};

    let dir = |t: &str| {
        let d = out.join(t);
        std::fs::create_dir_all(&d).unwrap();
        d
    };
    let img = |c: usize, v: f32| Image::new(3, 2, c, (0..3 * 2 * c).map(|i| v + i as f32 * 0.125).collect()).unwrap();
    let (color, albedo, normal) = (img(3, 0.5), img(3, 0.25), img(3, -0.5));
    hush_dataset::write_exr(dir("exr").join("layers.exr"), &[("", &color), ("albedo", &albedo), ("normal", &normal)])
        .unwrap();
    hush_dataset::write_rgb(dir("exr").join("rgb.exr"), &color).unwrap();

    let device = Device::Cpu;
    for (kind, in_channels) in [(UNetKind::Unet, 9), (UNetKind::Unet, 3)] {
        let varmap = VarMap::new();
        // 1/16 of OIDN's widths: the smallest whose channel counts a TZA reader infers back (2, 3, 4, 5, 6).
        let cfg = UNetConfig::new(kind, in_channels, 0.0625);
        let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &device), &cfg).unwrap();
        std::fs::write(dir("weights").join(format!("tiny-{in_channels}.tza")), hush_net::export_tza(&net).unwrap())
            .unwrap();
        let features = InputFeatures::parse(if in_channels == 9 { "alb,nrm" } else { "" }).unwrap();
        let info = ModelInfo { net: cfg.into(), features, transfer: hush_net::transfer::Transfer::Pu };
        let bytes = hush_net::save_weights(&varmap, &info).unwrap();
        std::fs::write(dir("weights").join(format!("tiny-{in_channels}.safetensors")), bytes).unwrap();
    }
}
