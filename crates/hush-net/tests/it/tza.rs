//! TZA import and export, against OIDN's official weight files (`data/weights/oidn-2.5.1/`) and
//! hand-made archives.

use candle_core::{DType, Device, Module, Result};
use candle_nn::{VarBuilder, VarMap};
use hush_net::{
    Feature, InputFeatures, TzaTensor, UNet, UNetConfig, UNetKind, export_tza, infer_config, init_weights, load_tza,
    parse_tza, write_tza,
};

use crate::{det_tensor, max_abs_diff};

const OFFICIAL: [&str; 5] =
    ["rt_hdr", "rt_hdr_alb", "rt_hdr_alb_nrm", "rt_hdr_alb_nrm_small", "rt_hdr_calb_cnrm_large"];

fn official(name: &str) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/weights/oidn-2.5.1")
        .join(format!("{name}.tza"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// OIDN's files: import → export gives the very same bytes (f16 → f32 → f16 is exact; same order,
/// alignment, layouts and zero padding as OIDN's writer).
#[test]
fn official_weights_export_byte_identical() -> Result<()> {
    for name in OFFICIAL {
        let bytes = official(name);
        let tensors = parse_tza(&bytes)?;
        assert!(tensors.iter().all(|t| t.layout == if t.dims.len() == 4 { "oihw" } else { "x" }), "{name}");
        assert!(write_tza(&tensors)? == bytes, "{name}: write_tza(parse_tza(file)) differs from the file");
        let (net, _) = load_tza(&bytes, None, &Device::Cpu)?;
        assert!(export_tza(&net)? == bytes, "{name}: export_tza(load_tza(file)) differs from the file");
    }
    Ok(())
}

#[test]
fn official_weights_kind_and_features_are_inferred() -> Result<()> {
    use Feature::{Albedo, Normal};
    let cases: [(&str, UNetKind, usize, Vec<Feature>); 5] = [
        ("rt_hdr", UNetKind::Unet, 3, vec![]),
        ("rt_hdr_alb", UNetKind::Unet, 6, vec![Albedo]),
        ("rt_hdr_alb_nrm", UNetKind::Unet, 9, vec![Albedo, Normal]),
        ("rt_hdr_alb_nrm_small", UNetKind::UnetSmall, 9, vec![Albedo, Normal]),
        ("rt_hdr_calb_cnrm_large", UNetKind::UnetLarge, 9, vec![Albedo, Normal]),
    ];
    for (name, kind, in_channels, aux) in cases {
        let (net, info) = load_tza(&official(name), None, &Device::Cpu)?;
        assert_eq!(info.net, UNetConfig::new(kind, in_channels, 1.0).into(), "{name}");
        assert_eq!(info.net.as_unet(), Some(net.config()));
        assert_eq!(info.features.aux, aux, "{name}");
    }
    // InputFeatures can be given instead of inferred (a 9-channel file read as diffuse, specular).
    let diff_spec = InputFeatures::parse("diff,spec").unwrap();
    let (_, info) = load_tza(&official("rt_hdr_alb_nrm"), Some(diff_spec.clone()), &Device::Cpu)?;
    assert_eq!(info.features, diff_spec);
    let err = load_tza(&official("rt_hdr_alb_nrm"), Some(InputFeatures::parse("alb").unwrap()), &Device::Cpu);
    assert!(err.unwrap_err().to_string().contains("9 input channels"));
    Ok(())
}

fn hush_net(kind: UNetKind, in_channels: usize, width: f64, seed: u64) -> Result<(VarMap, UNet)> {
    let varmap = VarMap::new();
    let cfg = UNetConfig::new(kind, in_channels, width);
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
    init_weights(&varmap, seed)?;
    Ok((varmap, net))
}

/// hush weights: export → import → export. The import holds the f16-rounded weights, so the second export
/// is byte-identical to the first and the network's output moves only by the rounding (relative 2⁻¹¹).
#[test]
fn hush_weights_round_trip() -> Result<()> {
    for (kind, width) in [(UNetKind::Unet, 0.25), (UNetKind::Autoencoder, 0.25), (UNetKind::UnetLarge, 0.125)] {
        let (_, net) = hush_net(kind, 9, width, 11)?;
        let first = export_tza(&net)?;
        let (back, info) = load_tza(&first, None, &Device::Cpu)?;
        assert_eq!(info.net, net.config().clone().into(), "{kind:?}");
        assert!(export_tza(&back)? == first, "{kind:?}: second export differs");
        for ((name, a), (_, b)) in net.named_tensors().iter().zip(back.named_tensors()) {
            let d = max_abs_diff(a, &b)?;
            assert!(d <= a.abs()?.max_all()?.to_scalar::<f32>()? / 2048.0, "{kind:?} {name}: {d}");
        }
        let x = det_tensor(&[1, 9, 16, 32], 0.0, 1.0, 12)?;
        let (y, y_back) = (net.forward(&x)?, back.forward(&x)?);
        let d = max_abs_diff(&y, &y_back)?;
        assert!(d > 0.0 && d < 1e-2, "{kind:?}: outputs differ by {d}");
    }
    // The thesis' M1 (⌊c·0.66⌋) is recognized from its shapes too.
    let (_, m1) = hush_net(UNetKind::Unet, 12, 0.66, 13)?;
    let (_, info) = load_tza(&export_tza(&m1)?, Some(InputFeatures::parse("diff,spec,nrm").unwrap()), &Device::Cpu)?;
    assert_eq!(info.net.as_unet().map(|c| c.conv_shapes()), Some(m1.config().conv_shapes()));
    Ok(())
}

/// A hand-made archive, byte by byte as the format describes it, with every dtype.
fn handmade() -> Vec<u8> {
    let mut b = vec![0u8; 64];
    b[0..2].copy_from_slice(&0x41D7u16.to_le_bytes());
    b[2] = 2;
    b[3] = 0;
    // Data: "a" f32 [2] at 64, "b" f16 [1, 2] at 128, "c" i8 [3] at 192, "d" u8 [2] at 256.
    b.extend_from_slice(&1.5f32.to_le_bytes());
    b.extend_from_slice(&(-2.0f32).to_le_bytes());
    b.resize(128, 0);
    b.extend_from_slice(&[0x00, 0x3C, 0x00, 0xC0]); // f16 1.0, -2.0
    b.resize(192, 0);
    b.extend_from_slice(&[0x01, 0xFF, 0x80]); // i8 1, -1, -128
    b.resize(256, 0);
    b.extend_from_slice(&[7, 255]);
    b.resize(320, 0);
    b[4..12].copy_from_slice(&320u64.to_le_bytes());
    b.extend_from_slice(&4u32.to_le_bytes());
    for (name, dims, layout, dtype, offset) in [
        ("a", vec![2u32], "x", b'f', 64u64),
        ("b", vec![1, 2], "oi", b'h', 128),
        ("c", vec![3], "x", b'b', 192),
        ("d", vec![2], "x", b'B', 256),
    ] {
        b.extend_from_slice(&(name.len() as u16).to_le_bytes());
        b.extend_from_slice(name.as_bytes());
        b.push(dims.len() as u8);
        for d in &dims {
            b.extend_from_slice(&d.to_le_bytes());
        }
        b.extend_from_slice(layout.as_bytes());
        b.push(dtype);
        b.extend_from_slice(&offset.to_le_bytes());
    }
    b
}

#[test]
fn handmade_archive_parses() -> Result<()> {
    let t = parse_tza(&handmade())?;
    let tensor = |name: &str, dims: &[usize], layout: &str, values: &[f32]| TzaTensor {
        name: name.into(),
        dims: dims.to_vec(),
        layout: layout.into(),
        values: values.to_vec(),
    };
    assert_eq!(
        t,
        vec![
            tensor("a", &[2], "x", &[1.5, -2.0]),
            tensor("b", &[1, 2], "oi", &[1.0, -2.0]),
            tensor("c", &[3], "x", &[1.0, -1.0, -128.0]),
            tensor("d", &[2], "x", &[7.0, 255.0]),
        ]
    );
    // Written back as f16 (with OIDN's alignment), the values survive: all are f16-representable.
    assert_eq!(parse_tza(&write_tza(&t)?)?, t);
    Ok(())
}

fn err(bytes: &[u8]) -> String {
    parse_tza(bytes).unwrap_err().to_string()
}

#[test]
fn corrupt_archives_are_clear_errors() {
    let good = handmade();
    // Every truncation is an error, never a panic.
    for len in 0..good.len() {
        assert!(parse_tza(&good[..len]).is_err(), "truncated to {len} bytes was accepted");
    }
    assert!(err(&good[..5]).contains("truncated"), "{}", err(&good[..5]));
    assert!(err(&good[..300]).contains("table offset 320"), "{}", err(&good[..300]));
    let e = err(&good[..good.len() - 3]);
    assert!(e.contains("truncated") && e.contains("\"d\""), "{e}");

    let mut bad = good.clone();
    bad[0] = 0;
    assert!(err(&bad).contains("magic number 0x4100"), "{}", err(&bad));
    let mut bad = good.clone();
    bad[2] = 3;
    assert!(err(&bad).contains("version 3.0"), "{}", err(&bad));
    // The dtype of "a" (after count, name length, "a", rank, one dim, layout "x").
    let dtype_at = 320 + 4 + 2 + 1 + 1 + 4 + 1;
    let mut bad = good.clone();
    bad[dtype_at] = b'q';
    assert!(err(&bad).contains("unknown dtype 'q'"), "{}", err(&bad));
    // Its data offset pointing past the end.
    let mut bad = good.clone();
    bad[dtype_at + 1..dtype_at + 9].copy_from_slice(&10_000u64.to_le_bytes());
    let e = err(&bad);
    assert!(e.contains("\"a\"") && e.contains("runs past the end"), "{e}");
    // A repeated name.
    let mut bad = good.clone();
    let d_name = bad.len() - (8 + 1 + 1 + 4 + 1 + 1);
    bad[d_name] = b'a';
    assert!(err(&bad).contains("appears twice"), "{}", err(&bad));
}

#[test]
fn mismatched_archives_are_clear_errors() -> Result<()> {
    // Shapes that fit no network.
    let mut tensors = parse_tza(&official("rt_hdr_alb_nrm_small"))?;
    tensors.retain(|t| t.name != "dec_conv2b.bias");
    let e = infer_config(&tensors).unwrap_err().to_string();
    assert!(e.contains("dec_conv2b.bias is missing"), "{e}");
    // A channel count OIDN's names do not cover, without explicit features.
    let (_, net) = hush_net(UNetKind::Unet, 12, 0.125, 1)?;
    let e = load_tza(&export_tza(&net)?, None, &Device::Cpu).unwrap_err().to_string();
    assert!(e.contains("12 channels") && e.contains("features"), "{e}");
    // Not a TZA file at all.
    assert!(load_tza(b"not a tensor archive", None, &Device::Cpu).unwrap_err().to_string().contains("magic"));
    // Weights f16 cannot hold.
    let big = TzaTensor { name: "w".into(), dims: vec![1], layout: "x".into(), values: vec![1e5] };
    assert!(write_tza(&[big]).unwrap_err().to_string().contains("f16"));
    let bad_layout = TzaTensor { name: "w".into(), dims: vec![1, 1], layout: "x".into(), values: vec![1.0] };
    assert!(write_tza(&[bad_layout]).unwrap_err().to_string().contains("layout"));
    Ok(())
}

/// Hostile tables are refused before any tensor is widened: a count no network has, and entries that all
/// point at one range of data (each would be copied to f32 anew: a small file could ask for terabytes).
#[test]
fn hostile_tables_are_refused() {
    let mut bad = handmade();
    bad[320..324].copy_from_slice(&1_000_000u32.to_le_bytes());
    assert!(err(&bad).contains("1000000 tensors, more than the 4096"), "{}", err(&bad));
    // Four entries over the same 256 bytes at offset 64: 1024 bytes claimed in a file of about 400.
    let mut b = handmade()[..320].to_vec();
    b.extend_from_slice(&4u32.to_le_bytes());
    for name in ["a", "b", "c", "d"] {
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(name.as_bytes());
        b.push(1);
        b.extend_from_slice(&256u32.to_le_bytes());
        b.push(b'x');
        b.push(b'B');
        b.extend_from_slice(&64u64.to_le_bytes());
    }
    let e = err(&b);
    assert!(e.contains("overlap") && e.contains("\"b\""), "{e}");
}
