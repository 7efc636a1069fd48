//! Tests of the kernel's BSDFs on the GPU, through a probe kernel that shares bsdf.wgsl.
//!
//! For each material and incident direction: sampled weights never carry more energy than
//! came in, sampled weights equal eval / pdf for the same direction, and the pdf and the
//! reflected energy agree with a uniform-sphere Monte-Carlo integral of the evaluation.
//! Statistical comparisons allow 5 standard errors (computed from the samples) plus 1e-3.

use glam::Vec3;
use hush_scene::{ComplexIor, Material, Microfacet, Reflectance};
use wgpu::util::DeviceExt;

use crate::GpuContext;
use crate::upload::{Aux, GpuEnv, GpuMaterial, environment, gpu_material};

const SOURCE: &str = concat!(include_str!("bsdf.wgsl"), include_str!("env.wgsl"), include_str!("probe.wgsl"));
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

/// Runs `entry` of the probe kernel on N invocations with `inputs` bound (binding, bytes,
/// usage) and returns the `floats` values per invocation it writes to `out_binding`.
fn dispatch(
    gpu: &GpuContext,
    entry: &str,
    inputs: &[(u32, &[u8], wgpu::BufferUsages)],
    out_binding: u32,
    floats: u64,
) -> Vec<f32> {
    let device = &gpu.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("probe"),
        source: wgpu::ShaderSource::Wgsl(SOURCE.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    let buffers: Vec<(u32, wgpu::Buffer)> = inputs
        .iter()
        .map(|&(binding, contents, usage)| {
            (binding, device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: None, contents, usage }))
        })
        .collect();
    let size = N as u64 * floats * 4;
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
    let mut entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .map(|(binding, b)| wgpu::BindGroupEntry { binding: *binding, resource: b.as_entire_binding() })
        .collect();
    entries.push(wgpu::BindGroupEntry { binding: out_binding, resource: out.as_entire_binding() });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
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
    bytemuck::cast_slice(&read.get_mapped_range(..).expect("mapped")).to_vec()
}

/// The probe kernel's parameters: direction of incidence, count, seed.
fn probe_params(wo: Vec3, seed: u32) -> [u8; 32] {
    let mut params = [0u8; 32];
    params[..16].copy_from_slice(bytemuck::cast_slice(&wo.extend(0.0).to_array()));
    params[16..20].copy_from_slice(&N.to_le_bytes());
    params[20..24].copy_from_slice(&seed.to_le_bytes());
    params
}

fn run(gpu: &GpuContext, m: &Probed, wo: Vec3) -> Stats {
    let (uniform, storage) = (wgpu::BufferUsages::UNIFORM, wgpu::BufferUsages::STORAGE);
    let params = probe_params(wo.normalize(), 7);
    let inputs = [
        (0, &params[..], uniform),
        (1, bytemuck::bytes_of(&m.material), storage),
        (7, bytemuck::cast_slice(&m.aux), storage),
    ];
    let data = dispatch(gpu, "probe_main", &inputs, 2, 12);
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

/// A material's record and the tables it reads.
struct Probed {
    material: GpuMaterial,
    aux: Vec<f32>,
}

fn material(m: Material) -> Probed {
    let mut aux = Aux::default();
    let material = gpu_material(&m, Vec3::ZERO, &[], &mut aux).unwrap();
    // Bound buffers cannot be empty.
    aux.data.push(0.0);
    Probed { material, aux: aux.data }
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
fn check_consistent(name: &str, m: &Probed, two_sided: bool) {
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
    check_consistent("diffuse", &white, false);
    let s = run(gpu(), &white, Vec3::Z);
    assert!((s.weight[0].0 - 1.0).abs() < 1e-6, "a white diffuse surface reflects everything: {}", s.weight[0].0);
    let two = material(Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::splat(0.5)), two_sided: true });
    check_consistent("twosided diffuse", &two, true);
}

#[test]
fn rough_conductor_conserves_energy_and_samples_its_evaluation() {
    let gold = ComplexIor { eta: Vec3::new(0.143, 0.374, 1.442), k: Vec3::new(3.983, 2.385, 1.603) };
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        for alpha in [0.05, 0.3, 0.8] {
            let mirror = material(Material::Conductor {
                alpha,
                distribution,
                ior: None,
                specular_reflectance: Vec3::ONE,
                two_sided: false,
            });
            check_consistent(&format!("roughconductor {distribution:?} alpha {alpha}"), &mirror, false);
            let au = material(Material::Conductor {
                alpha,
                distribution,
                ior: Some(gold),
                specular_reflectance: Vec3::ONE,
                two_sided: true,
            });
            check_consistent(&format!("rough gold {distribution:?} alpha {alpha}"), &au, true);
        }
    }
}

#[test]
fn smooth_plastic_samples_its_diffuse_base_consistently() {
    for nonlinear in [false, true] {
        let m = material(Material::Plastic {
            diffuse_reflectance: Reflectance::Rgb(Vec3::new(0.9, 0.5, 0.1)),
            specular_reflectance: Vec3::ONE,
            alpha: 0.0,
            distribution: Microfacet::Ggx,
            int_ior: 1.5,
            ext_ior: 1.0,
            nonlinear,
            two_sided: false,
        });
        for wo in directions() {
            let s = run(gpu(), &m, wo);
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

/// Rough glass (GGX and Beckmann, visible normals): weight = eval / pdf, the mean weight matches the
/// integral of the evaluation and the pdf integrates to the fraction of valid samples. From
/// outside no more energy leaves than comes in; from inside, radiance may grow by at most the
/// refraction's eta² (its solid-angle compression).
#[test]
fn rough_dielectric_samples_its_evaluation() {
    for (alpha, distribution) in [
        (0.05, Microfacet::Ggx),
        (0.15, Microfacet::Ggx),
        (0.5, Microfacet::Ggx),
        (0.1, Microfacet::Beckmann),
        (0.4, Microfacet::Beckmann),
    ] {
        let glass = material(Material::Dielectric {
            alpha,
            distribution,
            int_ior: 1.5,
            ext_ior: 1.0,
            thin: false,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        });
        for wo in directions() {
            let s = run(gpu(), &glass, wo);
            let name = format!("roughdielectric {distribution:?} alpha {alpha} wo {wo}");
            assert_eq!(s.delta, 0.0, "{name}: no delta lobes");
            // Single-scattering microfacets lose the light that would scatter again: at alpha
            // 0.5 from inside about 18 % of the samples, far less at lower roughness.
            assert!(s.valid > 0.7, "{name}: only {} of the samples are valid", s.valid);
            assert!(s.max_mismatch < 1e-3, "{name}: sampled weight differs from eval/pdf by {}", s.max_mismatch);
            let bound = if wo.z > 0.0 { 1.0 } else { 1.5 * 1.5 };
            assert!(s.weight[0].0 <= bound + 1e-4, "{name}: sampled energy {}", s.weight[0].0);
            assert!(
                close(s.weight[0], s.integral[0]),
                "{name}: sampled {:?} vs integral {:?}",
                s.weight[0],
                s.integral[0]
            );
            assert!(close(s.pdf_integral, (s.valid, 0.0)), "{name}: pdf integrates to {:?}", s.pdf_integral);
        }
    }
}

/// Mitsuba's rough plastic: both lobes sampled consistently with their evaluation, never more
/// energy out than in.
#[test]
fn rough_plastic_conserves_energy_and_samples_its_evaluation() {
    for (alpha, nonlinear, distribution) in [
        (0.05, false, Microfacet::Ggx),
        (0.2, true, Microfacet::Ggx),
        (0.6, false, Microfacet::Ggx),
        (0.1, false, Microfacet::Beckmann),
        (0.5, true, Microfacet::Beckmann),
    ] {
        let m = material(Material::Plastic {
            diffuse_reflectance: Reflectance::Rgb(Vec3::new(0.95, 0.5, 0.1)),
            specular_reflectance: Vec3::ONE,
            alpha,
            distribution,
            int_ior: 1.49,
            ext_ior: 1.0,
            nonlinear,
            two_sided: false,
        });
        check_consistent(&format!("roughplastic {distribution:?} alpha {alpha}"), &m, false);
    }
}

#[test]
fn smooth_dielectrics_split_energy_by_fresnel() {
    let glass = |thin| {
        material(Material::Dielectric {
            alpha: 0.0,
            distribution: Microfacet::Ggx,
            int_ior: 1.5,
            ext_ior: 1.0,
            thin,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        })
    };
    for wo in directions() {
        // Thin glass absorbs nothing: reflected plus transmitted weight is exactly 1.
        let s = run(gpu(), &glass(true), wo);
        assert_eq!((s.valid, s.delta), (1.0, 1.0));
        assert!((s.weight[0].0 - 1.0).abs() < 1e-5, "thin glass energy {}", s.weight[0].0);
        // Solid glass: weight 1 on reflection, 1/eta² (radiance compression) on entering, eta²
        // on leaving; the mean is R + T·scale with R the Fresnel reflectance.
        let s = run(gpu(), &glass(false), wo);
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

/// Per channel: mean sampled radiance / pdf and the uniform-direction estimate of the same
/// integral (each with its standard error); the fraction of samples whose reported pdf differs
/// from env_pdf of their direction by more than 0.1 % (rounding can move a point on a cell's
/// edge into its neighbour); the uniform estimate of ∫ env_pdf dω.
struct EnvStats {
    sampled: [(f64, f64); 3],
    uniform: [(f64, f64); 3],
    mismatched: f64,
    pdf_integral: (f64, f64),
}

fn run_env(gpu: &GpuContext, env: GpuEnv, aux: &[f32]) -> EnvStats {
    let (uniform, storage) = (wgpu::BufferUsages::UNIFORM, wgpu::BufferUsages::STORAGE);
    let params = probe_params(Vec3::ZERO, 11);
    let env = env.uniform();
    let inputs =
        [(0, &params[..], uniform), (8, bytemuck::bytes_of(&env), uniform), (12, bytemuck::cast_slice(aux), storage)];
    let data = dispatch(gpu, "env_probe_main", &inputs, 9, 8);
    let rows: Vec<&[f32]> = data.chunks_exact(8).collect();
    let col = |k: usize| rows.iter().map(move |r| r[k] as f64);
    EnvStats {
        sampled: [mean_se(col(0)), mean_se(col(1)), mean_se(col(2))],
        uniform: [mean_se(col(4)), mean_se(col(5)), mean_se(col(6))],
        mismatched: col(3).filter(|&m| m > 1e-3).count() as f64 / rows.len() as f64,
        pdf_integral: mean_se(col(7)),
    }
}

/// A small map with a bright "sun" texel, a smooth sky and a black row, rotated and scaled
/// by `to_world`: env_pdf integrates to 1 over the sphere, agrees with the density of the
/// samples, and importance-sampled radiance / pdf estimates the same integral as uniform
/// directions. The constant environment passes the same checks.
#[test]
fn environment_sampling_matches_its_pdf_and_radiance() {
    let (w, h) = (16u32, 9u32);
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let sky = if y == 6 { [0.0; 3] } else { [0.2 + 0.05 * x as f32, 0.3, 0.5 + 0.1 * y as f32] };
            let sun = if (x, y) == (11, 2) { 200.0 } else { 0.0 };
            data.extend(sky.map(|c| c + sun));
        }
    }
    let to_world = glam::Mat4::from_rotation_x(0.4) * glam::Mat4::from_rotation_y(1.1);
    let map = hush_scene::EnvMap { path: "probe.exr".into(), width: w, height: h, data, scale: 1.5, to_world };
    let constant = hush_scene::Environment::Constant { radiance: Vec3::new(0.5, 1.0, 2.0) };
    for (name, e) in [("envmap", hush_scene::Environment::Map(map)), ("constant", constant)] {
        let mut aux = Aux::default();
        let env = environment(Some(&e), &mut aux, false).unwrap();
        // Never empty, and whole four-word texels (as `flatten` leaves it).
        aux.data.push(0.0);
        aux.align4();
        assert_eq!(env.pick, 1.0, "{name}: without triangle lights the environment is always sampled");
        let s = run_env(gpu(), env, &aux.data);
        assert!(close(s.pdf_integral, (1.0, 0.0)), "{name}: the pdf integrates to {:?}", s.pdf_integral);
        assert!(s.mismatched < 1e-3, "{name}: sampled pdf and env_pdf differ for {} of the samples", s.mismatched);
        for c in 0..3 {
            assert!(
                close(s.sampled[c], s.uniform[c]),
                "{name} channel {c}: importance-sampled {:?} vs uniform {:?}",
                s.sampled[c],
                s.uniform[c]
            );
        }
    }
}
