//! Open Image Denoise's Tensor Archive (TZA v2) format: hush reads OIDN's official weights and writes its own
//! so that OIDN's runtime can run them. Bytes in, bytes out; no file I/O.
//!
//! Layout (little-endian, OIDN's `training/tza.py` and `core/tza.cpp`): `u16` magic `0x41D7`, `u8` major
//! version (2), `u8` minor (0), `u64` offset of the table. The table: `u32` tensor count, then per tensor a
//! `u16` name length and the UTF-8 name, `u8` rank, `u32` × rank dimensions, rank ASCII layout characters
//! (`oihw` for convolution weights, `x` for biases), one ASCII dtype character (`f` f32, `h` f16, `b` i8,
//! `B` u8) and the `u64` offset of the row-major data. Data and table start at multiples of 64 bytes, the gaps
//! are zeros.
//!
//! OIDN stores f16; [`parse_tza`] widens every dtype to f32 and [`write_tza`] narrows to f16 with
//! round-to-nearest-even, so weights that came from a TZA file go back bit for bit, and the file written
//! from them is byte-identical to OIDN's (the tests check this on the official weights).

use candle_core::{DType, Device, Result, Tensor, bail};
use candle_nn::VarBuilder;

use crate::input::{Feature, InputFeatures};
use crate::transfer::Transfer;
use crate::unet::{Head, UNet, UNetConfig, UNetKind};
use crate::weights::ModelInfo;

/// The most tensors a TZA table may list: OIDN's networks have about 40, hush's at most a few hundred.
const MAX_TENSORS: usize = 4096;

const MAGIC: u16 = 0x41D7;
const VERSION: (u8, u8) = (2, 0);
const ALIGN: usize = 64;
const HEADER_LEN: usize = 12;

/// One tensor of a TZA archive, widened to f32.
#[derive(Clone, Debug, PartialEq)]
pub struct TzaTensor {
    pub name: String,
    pub dims: Vec<usize>,
    /// One character per dimension: `oihw` for convolution weights, `x` for biases.
    pub layout: String,
    /// Row-major values.
    pub values: Vec<f32>,
}

fn tza_err(msg: impl std::fmt::Display) -> candle_core::Error {
    candle_core::Error::Msg(format!("TZA: {msg}"))
}

/// A bounds-checked little-endian reader; every read names what it was reading when the bytes run out.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &dyn Fn() -> String) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or_else(|| {
            tza_err(format!(
                "truncated: {} needs {n} bytes at offset {} but the file has {} bytes",
                what(),
                self.pos,
                self.bytes.len()
            ))
        })?;
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u8(&mut self, what: &dyn Fn() -> String) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn u16(&mut self, what: &dyn Fn() -> String) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().expect("2 bytes")))
    }
    fn u32(&mut self, what: &dyn Fn() -> String) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &dyn Fn() -> String) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
}

/// Parses a TZA archive. Fails with a message naming the offset and the tensor on a wrong magic number, an
/// unsupported major version, a truncated header, table or tensor, an unknown dtype, a non-ASCII layout, a
/// layout whose length is not the rank, or a repeated name.
pub fn parse_tza(bytes: &[u8]) -> Result<Vec<TzaTensor>> {
    let mut c = Cursor { bytes, pos: 0 };
    let magic = c.u16(&|| "the header".into())?;
    if magic != MAGIC {
        bail!("TZA: not a tensor archive: magic number {magic:#06x}, expected {MAGIC:#06x}")
    }
    let (major, minor) = (c.u8(&|| "the header".into())?, c.u8(&|| "the header".into())?);
    if major != VERSION.0 {
        bail!("TZA: unsupported version {major}.{minor}; only {}.x is supported", VERSION.0)
    }
    let table = c.u64(&|| "the header".into())?;
    if table < HEADER_LEN as u64 || table >= bytes.len() as u64 {
        bail!("TZA: truncated or corrupt: the table offset {table} is outside the file of {} bytes", bytes.len())
    }
    c.pos = table as usize;
    let count = c.u32(&|| "the tensor count".into())? as usize;
    if count > MAX_TENSORS {
        bail!(
            "TZA: corrupt: the table lists {count} tensors, more than the {MAX_TENSORS} a network of hush or OIDN has"
        )
    }
    let mut tensors: Vec<TzaTensor> = Vec::with_capacity(count.min(1024));
    // The tensors' bytes together: entries that alias one range would each be widened to f32 anew.
    let mut total: u64 = 0;
    for index in 0..count {
        let entry = || format!("table entry {index} of {count}");
        let name_len = c.u16(&entry)? as usize;
        let name = std::str::from_utf8(c.take(name_len, &entry)?)
            .map_err(|_| tza_err(format!("the name of {} is not UTF-8", entry())))?
            .to_string();
        let of = || format!("tensor {name:?}");
        let rank = c.u8(&of)? as usize;
        let dims = (0..rank).map(|_| c.u32(&of).map(|d| d as usize)).collect::<Result<Vec<_>>>()?;
        let layout = c.take(rank, &of)?;
        if !layout.iter().all(|b| b.is_ascii_graphic()) {
            bail!("TZA: tensor {name:?} has a corrupt layout {layout:?}")
        }
        let layout = String::from_utf8(layout.to_vec()).expect("ASCII");
        let dtype = c.u8(&of)?;
        let elem = match dtype {
            b'f' => 4,
            b'h' => 2,
            b'b' | b'B' => 1,
            other => bail!("TZA: tensor {name:?} has the unknown dtype {:?} (f, h, b or B expected)", other as char),
        };
        let offset = c.u64(&of)?;
        let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        let size = count.and_then(|n| n.checked_mul(elem));
        let (Some(n), Some(size)) = (count, size) else { bail!("TZA: tensor {name:?} has absurd dimensions {dims:?}") };
        let end = offset.checked_add(size as u64).filter(|&e| e <= bytes.len() as u64);
        let Some(end) = end else {
            bail!(
                "TZA: truncated: tensor {name:?} ({dims:?}, {} bytes) at offset {offset} runs past the end of the \
                 file ({} bytes)",
                size,
                bytes.len()
            )
        };
        total += size as u64;
        if total > bytes.len() as u64 {
            bail!(
                "TZA: corrupt: the tensors up to {name:?} claim {total} bytes of data in a file of {} bytes (entries \
                 overlap)",
                bytes.len()
            )
        }
        if tensors.iter().any(|t| t.name == name) {
            bail!("TZA: tensor {name:?} appears twice")
        }
        let data = &bytes[offset as usize..end as usize];
        let values: Vec<f32> = match dtype {
            b'f' => data.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect(),
            b'h' => data.chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect(),
            b'b' => data.iter().map(|&b| b as i8 as f32).collect(),
            _ => data.iter().map(|&b| b as f32).collect(),
        };
        debug_assert_eq!(values.len(), n);
        tensors.push(TzaTensor { name, dims, layout, values });
    }
    Ok(tensors)
}

/// Writes tensors as a TZA v2.0 archive in the given order, every value as f16 (round to nearest even), the
/// way OIDN's `training/export.py` writes its weights. Fails on a layout whose length is not the rank, a
/// non-ASCII layout, a name longer than 65535 bytes, a value count that does not match the dimensions, or a
/// value that f16 cannot hold (|v| > 65504 or not finite).
pub fn write_tza(tensors: &[TzaTensor]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.extend_from_slice(&[VERSION.0, VERSION.1]);
    out.extend_from_slice(&0u64.to_le_bytes()); // table offset, patched below
    let pad = |out: &mut Vec<u8>| out.resize(out.len().div_ceil(ALIGN) * ALIGN, 0);
    let mut offsets = Vec::with_capacity(tensors.len());
    for t in tensors {
        if t.layout.len() != t.dims.len() || !t.layout.bytes().all(|b| b.is_ascii_graphic()) {
            bail!("TZA: tensor {:?}: layout {:?} does not fit dimensions {:?}", t.name, t.layout, t.dims)
        }
        if t.name.len() > u16::MAX as usize || t.dims.len() > u8::MAX as usize {
            bail!("TZA: tensor {:?}: name or rank too long for the format", t.name)
        }
        if t.values.len() != t.dims.iter().product::<usize>() || t.dims.iter().any(|&d| d > u32::MAX as usize) {
            bail!("TZA: tensor {:?}: {} values do not make dimensions {:?}", t.name, t.values.len(), t.dims)
        }
        if let Some(v) = t.values.iter().find(|v| !(v.is_finite() && v.abs() <= 65504.0)) {
            bail!("TZA: tensor {:?} holds {v}, which f16 cannot represent", t.name)
        }
        pad(&mut out);
        offsets.push(out.len() as u64);
        for &v in &t.values {
            out.extend_from_slice(&half::f16::from_f32(v).to_le_bytes());
        }
    }
    pad(&mut out);
    let table = out.len() as u64;
    out[4..12].copy_from_slice(&table.to_le_bytes());
    out.extend_from_slice(&(tensors.len() as u32).to_le_bytes());
    for (t, offset) in tensors.iter().zip(offsets) {
        out.extend_from_slice(&(t.name.len() as u16).to_le_bytes());
        out.extend_from_slice(t.name.as_bytes());
        out.push(t.dims.len() as u8);
        for &d in &t.dims {
            out.extend_from_slice(&(d as u32).to_le_bytes());
        }
        out.extend_from_slice(t.layout.as_bytes());
        out.push(b'h');
        out.extend_from_slice(&offset.to_le_bytes());
    }
    Ok(out)
}

/// The network a set of TZA tensors holds: the kind whose layer table matches the tensor names and shapes
/// exactly, its input channels from the first convolution, its width from that convolution's outputs.
pub fn infer_config(tensors: &[TzaTensor]) -> Result<UNetConfig> {
    let dims_of = |name: &str| tensors.iter().find(|t| t.name == name).map(|t| t.dims.as_slice());
    let mut tried = Vec::new();
    for kind in UNetKind::ALL {
        let probe = UNetConfig { out_channels: 1, ..UNetConfig::new(kind, 1, 1.0) };
        let shapes = probe.conv_shapes();
        let (first, last) = (&shapes[0], &shapes[shapes.len() - 1]);
        let (Some(&[f_out, f_in, 3, 3]), Some(&[l_out, _, 3, 3])) =
            (dims_of(&format!("{}.weight", first.name)), dims_of(&format!("{}.weight", last.name)))
        else {
            continue;
        };
        let width = f_out as f64 / first.out_channels as f64;
        let cfg = UNetConfig { out_channels: l_out, ..UNetConfig::new(kind, f_in, width) };
        match check_shapes(&cfg, tensors) {
            Ok(()) => return Ok(cfg),
            Err(e) => tried.push(format!("{}: {e}", kind.name())),
        }
    }
    if tried.is_empty() {
        bail!("TZA: no known network: neither enc_conv0.weight nor enc_conv1a.weight with a matching output layer")
    }
    bail!("TZA: the tensors match no known network ({})", tried.join("; "))
}

/// Checks that `tensors` are exactly the weights and biases of `cfg` (names and shapes, nothing extra).
fn check_shapes(cfg: &UNetConfig, tensors: &[TzaTensor]) -> std::result::Result<(), String> {
    let shapes = cfg.conv_shapes();
    for s in &shapes {
        for (suffix, want) in [("weight", vec![s.out_channels, s.in_channels, 3, 3]), ("bias", vec![s.out_channels])] {
            let name = format!("{}.{suffix}", s.name);
            match tensors.iter().find(|t| t.name == name) {
                None => return Err(format!("{name} is missing")),
                Some(t) if t.dims != want => return Err(format!("{name} is {:?}, expected {want:?}", t.dims)),
                Some(_) => {}
            }
        }
    }
    if tensors.len() != 2 * shapes.len() {
        let extra: Vec<&str> = tensors
            .iter()
            .map(|t| t.name.as_str())
            .filter(|n| !shapes.iter().any(|s| *n == format!("{}.weight", s.name) || *n == format!("{}.bias", s.name)))
            .collect();
        return Err(format!("unexpected tensors {extra:?}"));
    }
    Ok(())
}

/// The input features of an OIDN weight file, from its input channel count: 3 → color, 6 → color + albedo,
/// 9 → color + albedo + normal (OIDN's `rt_hdr`, `rt_hdr_alb`, `rt_hdr_alb_nrm` and their variants).
pub fn oidn_features(in_channels: usize) -> Result<InputFeatures> {
    match in_channels {
        3 => InputFeatures::new(vec![]),
        6 => InputFeatures::new(vec![Feature::Albedo]),
        9 => InputFeatures::new(vec![Feature::Albedo, Feature::Normal]),
        c => bail!(
            "TZA: the first convolution takes {c} channels; a TZA file does not say which features those are \
             (3 = color, 6 = color+albedo, 9 = color+albedo+normal are OIDN's); pass the features explicitly"
        ),
    }
}

/// Builds the network in a TZA archive (OIDN's official weights or [`export_tza`]'s output) on `device` in
/// f32. `features` names the input features; `None` infers them with [`oidn_features`]. The transfer
/// function is PU: OIDN's `hdr` weights (its `ldr` weights need [`Transfer::Srgb`]; set `info.transfer`).
pub fn load_tza(bytes: &[u8], features: Option<InputFeatures>, device: &Device) -> Result<(UNet, ModelInfo)> {
    let tensors = parse_tza(bytes)?;
    let net = infer_config(&tensors)?;
    let features = match features {
        Some(f) => f,
        None => oidn_features(net.in_channels)?,
    };
    let info = ModelInfo { net: net.clone().into(), features, transfer: Transfer::Pu };
    info.validate()?;
    let map = tensors
        .into_iter()
        .map(|t| Ok((t.name, Tensor::from_vec(t.values, t.dims, device)?)))
        .collect::<Result<std::collections::HashMap<_, _>>>()?;
    let unet = UNet::new(VarBuilder::from_tensors(map, DType::F32, device), &net)?;
    Ok((unet, info))
}

/// Writes a network's weights as a TZA archive in OIDN's layout (layer order, `oihw`/`x`, f16), for OIDN's
/// runtime (`oidnSetSharedFilterData(filter, "weights", ...)`). Fails if a weight does not fit f16.
pub fn export_tza(net: &UNet) -> Result<Vec<u8>> {
    if let Head::Kernel { size } = net.config().head {
        bail!(
            "TZA export: OIDN's runtime runs U-Nets that predict colors and cannot apply a network's predicted \
             {size}×{size} kernels (--head kernel:{size}); use its .safetensors file with `hush denoise` or \
             `hush eval` instead"
        )
    }
    let tensors = net
        .named_tensors()
        .into_iter()
        .map(|(name, t)| {
            let layout = if t.rank() == 4 { "oihw" } else { "x" }.to_string();
            let values = t.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
            Ok(TzaTensor { name, dims: t.dims().to_vec(), layout, values })
        })
        .collect::<Result<Vec<_>>>()?;
    write_tza(&tensors)
}
