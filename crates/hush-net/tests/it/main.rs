//! hush-net's integration tests: one binary, one module per area. Tiny sizes; the whole binary runs in
//! seconds on the CPU.

mod input;
mod kernel;
mod loss;
mod transfer;
mod tza;
mod unet;
mod weights;

use candle_core::{Result, Tensor};

/// Largest absolute element-wise difference of two tensors of the same shape.
pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f32> {
    (a - b)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()
}

/// A deterministic pseudo-random tensor in [lo, hi) (tests must not depend on luck).
pub fn det_tensor(dims: &[usize], lo: f32, hi: f32, seed: u64) -> Result<Tensor> {
    let n: usize = dims.iter().product();
    let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            lo + (hi - lo) * ((s >> 40) as f32 / (1u64 << 24) as f32)
        })
        .collect();
    Tensor::from_vec(v, dims, &candle_core::Device::Cpu)
}
