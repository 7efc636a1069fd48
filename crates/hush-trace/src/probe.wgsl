// Probes the BSDF functions of bsdf.wgsl: per invocation, one sample and one uniformly random
// direction, so the host can check energy, sampling against evaluation, and pdf normalization.

const PI: f32 = 3.14159265358979;
const INV_PI: f32 = 0.318309886183791;

struct ProbeParams {
    wo: vec4<f32>,
    count: u32,
    seed: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> probe: ProbeParams;
@group(0) @binding(1) var<storage, read> probe_material: array<Material>;
// Per invocation 12 floats: sample weight (3), valid, delta, |weight − eval/pdf| relative,
// uniform-direction eval / p_uniform (3), pdf / p_uniform, unused (2).
@group(0) @binding(2) var<storage, read_write> probe_out: array<f32>;

fn hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn unit(v: u32) -> f32 {
    return f32(v >> 8u) * (1.0 / 16777216.0);
}

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= probe.count {
        return;
    }
    let m = probe_material[0];
    let wo = normalize(probe.wo.xyz);
    var h = hash(i ^ hash(probe.seed));
    var u: array<f32, 5>;
    for (var k = 0u; k < 5u; k++) {
        h = hash(h);
        u[k] = unit(h);
    }
    let s = bsdf_sample(m, wo, vec2<f32>(u[0], u[1]), u[2]);
    var mismatch = 0.0;
    if s.valid && !s.delta {
        let f = bsdf_eval(m, wo, s.wi);
        let pdf = bsdf_pdf(m, wo, s.wi);
        let expect = f / max(pdf, 1e-30);
        mismatch = length(s.weight - expect) / max(length(expect), 1e-6);
    }
    // A uniformly random direction on the sphere (p = 1 / 4π).
    let z = 1.0 - 2.0 * u[3];
    let r = sqrt(max(0.0, 1.0 - z * z));
    let phi = 2.0 * PI * u[4];
    let wu = vec3<f32>(r * cos(phi), r * sin(phi), z);
    let inv_p = 4.0 * PI;
    let fu = bsdf_eval(m, wo, wu) * inv_p;
    let pu = bsdf_pdf(m, wo, wu) * inv_p;
    let base = i * 12u;
    let w = select(vec3<f32>(0.0), s.weight, s.valid);
    probe_out[base + 0u] = w.x;
    probe_out[base + 1u] = w.y;
    probe_out[base + 2u] = w.z;
    probe_out[base + 3u] = select(0.0, 1.0, s.valid);
    probe_out[base + 4u] = select(0.0, 1.0, s.delta);
    probe_out[base + 5u] = mismatch;
    probe_out[base + 6u] = fu.x;
    probe_out[base + 7u] = fu.y;
    probe_out[base + 8u] = fu.z;
    probe_out[base + 9u] = pu;
}

// Probes the environment: per invocation, one sample of env_sample and one uniformly random
// direction, so the host can check that env_pdf integrates to 1, that it agrees with the
// density env_sample reports, and that sampled radiance / pdf estimates the same integral as
// uniform directions do.
// Per invocation 8 floats: radiance / pdf of the sample (3), |pdf − env_pdf(d)| / pdf,
// uniform-direction radiance / p_uniform (3), env_pdf / p_uniform.
@group(0) @binding(9) var<storage, read_write> env_out: array<f32>;

@compute @workgroup_size(64, 1, 1)
fn env_probe_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= probe.count {
        return;
    }
    var h = hash(i ^ hash(probe.seed));
    var u: array<f32, 6>;
    for (var k = 0u; k < 6u; k++) {
        h = hash(h);
        u[k] = unit(h);
    }
    let s = env_sample(vec4<f32>(u[0], u[1], u[2], u[3]));
    var w = vec3<f32>(0.0);
    var mismatch = 0.0;
    if s.pdf > 0.0 {
        w = s.radiance / s.pdf;
        mismatch = abs(s.pdf - env_pdf(s.d)) / s.pdf;
    }
    let z = 1.0 - 2.0 * u[4];
    let r = sqrt(max(0.0, 1.0 - z * z));
    let phi = 2.0 * PI * u[5];
    let wu = vec3<f32>(r * cos(phi), r * sin(phi), z);
    let inv_p = 4.0 * PI;
    let lu = env_eval(wu) * inv_p;
    let base = i * 8u;
    env_out[base + 0u] = w.x;
    env_out[base + 1u] = w.y;
    env_out[base + 2u] = w.z;
    env_out[base + 3u] = mismatch;
    env_out[base + 4u] = lu.x;
    env_out[base + 5u] = lu.y;
    env_out[base + 6u] = lu.z;
    env_out[base + 7u] = env_pdf(wu) * inv_p;
}
