//! Tests of the kernel's BSDFs on the GPU, through a probe kernel that shares bsdf.wgsl.
//!
//! For each material and incident direction: sampled weights never carry more energy than
//! came in, sampled weights equal eval / pdf for the same direction, and the pdf and the
//! reflected energy agree with a uniform-sphere Monte-Carlo integral of the evaluation.
//! Statistical comparisons allow 5 standard errors (computed from the samples) plus 1e-3.

use glam::Vec3;
use hush_scene::{ComplexIor, Material, Reflectance};
use wgpu::util::DeviceExt;

use crate::GpuContext;
use crate::upload::{GpuMaterial, gpu_material};

const SOURCE: &str = concat!(include_str!("bsdf.wgsl"), include_str!("probe.wgsl"));
const N: u32 = 1 << 16;

struct Stats {
    /// Mean sampled weight per channel and its standard error.
    weight: [(f64, f64); 3],
    valid: f64,
    delta: f64,
    max_mismatch: f64,
    /// Uniform-sphere estimate of ∫ f |cos| dω per channel, with standard errors.
    integral: [(f64, f64); 3],
    /// Uniform-sphere estimate of ∫ pdf dω.
    pdf_integral: (f64, f64),
}

fn mean_se(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = values.collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn run(gpu: &GpuContext, m: GpuMaterial, wo: Vec3) -> Stats {
    let device = &gpu.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("probe"),
        source: wgpu::ShaderSource::Wgsl(SOURCE.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("probe"),
        layout: None,
        module: &module,
        entry_point: Some("probe_main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let mut params = [0u8; 32];
    params[..16].copy_from_slice(bytemuck::cast_slice(&wo.normalize().extend(0.0).to_array()));
    params[16..20].copy_from_slice(&N.to_le_bytes());
    params[20..24].copy_from_slice(&7u32.to_le_bytes());
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: &params,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let material = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::bytes_of(&m),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = N as u64 * 12 * 4;
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let read = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: material.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: out.as_entire_binding() },
        ],
    });
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(N / 64, 1, 1);
    }
    enc.copy_buffer_to_buffer(&out, 0, &read, 0, size);
    gpu.queue.submit([enc.finish()]);
    read.map_async(wgpu::MapMode::Read, .., |r| r.expect("map"));
    device.poll(wgpu::PollType::wait_indefinitely()).expect("poll");
    let data: Vec<f32> = bytemuck::cast_slice(&read.get_mapped_range(..).expect("mapped")).to_vec();
    let rows: Vec<&[f32]> = data.chunks_exact(12).collect();
    let col = |k: usize| rows.iter().map(move |r| r[k] as f64);
    Stats {
        weight: [mean_se(col(0)), mean_se(col(1)), mean_se(col(2))],
        valid: mean_se(col(3)).0,
        delta: mean_se(col(4)).0,
        max_mismatch: col(5).fold(0.0, f64::max),
        integral: [mean_se(col(6)), mean_se(col(7)), mean_se(col(8))],
        pdf_integral: mean_se(col(9)),
    }
}

fn gpu() -> &'static GpuContext {
    static GPU: std::sync::OnceLock<GpuContext> = std::sync::OnceLock::new();
    GPU.get_or_init(|| GpuContext::new().unwrap_or_else(|e| panic!("{e}")))
}

fn material(m: Material) -> GpuMaterial {
    gpu_material(&m, Vec3::ZERO, "probe").unwrap()
}

fn close(a: (f64, f64), b: (f64, f64)) -> bool {
    (a.0 - b.0).abs() <= 5.0 * (a.1 * a.1 + b.1 * b.1).sqrt() + 1e-3
}

/// Directions of incidence: near normal, oblique, grazing, and from below (two-sided and glass).
fn directions() -> [Vec3; 4] {
    [Vec3::new(0.1, 0.05, 1.0), Vec3::new(0.8, 0.3, 0.6), Vec3::new(0.97, 0.0, 0.1), Vec3::new(0.3, -0.2, -0.7)]
}

/// Non-delta materials: weight = eval / pdf, the sampled energy matches the integral of the
/// evaluation, and the pdf integrates to the fraction of samples that are valid.
fn check_consistent(name: &str, m: GpuMaterial, two_sided: bool) {
    for wo in directions() {
        let s = run(gpu(), m, wo);
        if wo.z < 0.0 && !two_sided {
            assert_eq!(s.valid, 0.0, "{name}: one-sided material sampled from below");
            assert!(s.integral.iter().all(|c| c.0 == 0.0), "{name}: one-sided material evaluated from below");
            continue;
        }
        assert!(s.max_mismatch < 1e-3, "{name} wo {wo}: sampled weight differs from eval/pdf by {}", s.max_mismatch);
        for c in 0..3 {
            assert!(s.weight[c].0 <= 1.0 + 1e-4, "{name} wo {wo}: sampled energy {} > 1", s.weight[c].0);
            assert!(
                close(s.weight[c], s.integral[c]),
                "{name} wo {wo} channel {c}: sampled energy {:?} vs integral of eval {:?}",
                s.weight[c],
                s.integral[c]
            );
        }
        let non_delta_valid = (s.valid - s.delta).max(0.0);
        assert!(
            close(s.pdf_integral, (non_delta_valid, 0.0)),
            "{name} wo {wo}: pdf integrates to {:?}, valid non-delta fraction {non_delta_valid}",
            s.pdf_integral
        );
    }
}

#[test]
fn diffuse_conserves_energy_and_samples_its_evaluation() {
    let white = material(Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::ONE), two_sided: false });
    check_consistent("diffuse", white, false);
    let s = run(gpu(), white, Vec3::Z);
    assert!((s.weight[0].0 - 1.0).abs() < 1e-6, "a white diffuse surface reflects everything: {}", s.weight[0].0);
    let two = material(Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::splat(0.5)), two_sided: true });
    check_consistent("twosided diffuse", two, true);
}

#[test]
fn rough_conductor_conserves_energy_and_samples_its_evaluation() {
    let gold = ComplexIor { eta: Vec3::new(0.143, 0.374, 1.442), k: Vec3::new(3.983, 2.385, 1.603) };
    for alpha in [0.05, 0.3, 0.8] {
        let mirror =
            material(Material::Conductor { alpha, ior: None, specular_reflectance: Vec3::ONE, two_sided: false });
        check_consistent(&format!("roughconductor alpha {alpha}"), mirror, false);
        let au =
            material(Material::Conductor { alpha, ior: Some(gold), specular_reflectance: Vec3::ONE, two_sided: true });
        check_consistent(&format!("rough gold alpha {alpha}"), au, true);
    }
}

#[test]
fn smooth_plastic_samples_its_diffuse_base_consistently() {
    for nonlinear in [false, true] {
        let m = material(Material::Plastic {
            diffuse_reflectance: Reflectance::Rgb(Vec3::new(0.9, 0.5, 0.1)),
            specular_reflectance: Vec3::ONE,
            alpha: 0.0,
            int_ior: 1.5,
            ext_ior: 1.0,
            nonlinear,
            two_sided: false,
        });
        for wo in directions() {
            let s = run(gpu(), m, wo);
            if wo.z < 0.0 {
                assert_eq!(s.valid, 0.0);
                continue;
            }
            assert!(s.max_mismatch < 1e-3, "plastic: weight vs eval/pdf {}", s.max_mismatch);
            assert!(
                s.weight.iter().all(|w| w.0 <= 1.0 + 1e-4),
                "plastic reflects more than it receives: {:?}",
                s.weight
            );
            assert!(s.delta > 0.0 && s.delta < 1.0, "plastic mixes a coat and a base: {}", s.delta);
            assert!(close(s.pdf_integral, (s.valid - s.delta, 0.0)), "{:?} vs {}", s.pdf_integral, s.valid - s.delta);
        }
    }
}

#[test]
fn smooth_dielectrics_split_energy_by_fresnel() {
    let glass = |thin| {
        material(Material::Dielectric {
            alpha: 0.0,
            int_ior: 1.5,
            ext_ior: 1.0,
            thin,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        })
    };
    for wo in directions() {
        // Thin glass absorbs nothing: reflected plus transmitted weight is exactly 1.
        let s = run(gpu(), glass(true), wo);
        assert_eq!((s.valid, s.delta), (1.0, 1.0));
        assert!((s.weight[0].0 - 1.0).abs() < 1e-5, "thin glass energy {}", s.weight[0].0);
        // Solid glass: weight 1 on reflection, 1/eta² (radiance compression) on entering, eta²
        // on leaving; the mean is R + T·scale with R the Fresnel reflectance.
        let s = run(gpu(), glass(false), wo);
        assert_eq!((s.valid, s.delta), (1.0, 1.0));
        let cos = wo.normalize().z;
        let (eta_ti, ci) = if cos > 0.0 { (1.0 / 1.5f64, cos as f64) } else { (1.5f64, -cos as f64) };
        let ct2 = 1.0 - (1.0 - ci * ci) * eta_ti * eta_ti;
        let r = if ct2 <= 0.0 {
            1.0
        } else {
            let ct = ct2.sqrt();
            let eta_it = 1.0 / eta_ti;
            let rs = (ci - eta_it * ct) / (ci + eta_it * ct);
            let rp = (eta_it * ci - ct) / (eta_it * ci + ct);
            0.5 * (rs * rs + rp * rp)
        };
        let expect = r + (1.0 - r) * eta_ti * eta_ti;
        assert!(close(s.weight[0], (expect, 0.0)), "glass wo {wo}: mean weight {:?}, expected {expect}", s.weight[0]);
    }
}
