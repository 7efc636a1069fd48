// BSDFs of hush, after Mitsuba 3's implementations (src/bsdfs/*.cpp), evaluated in the local
// shading frame (normal = +z). Pure functions of their arguments: random numbers come in as
// parameters, so a probe kernel can test sampling against evaluation.
//
// Conventions: `wo` points away from the surface toward the previous vertex, `wi` toward the
// next one. `weight` is f·|cos θi| / pdf. Delta lobes (perfect mirrors, smooth glass) are never
// evaluated, only sampled, and report `delta = true`.

const KIND_DIFFUSE: u32 = 0u;
const KIND_CONDUCTOR: u32 = 1u;
const KIND_DIELECTRIC: u32 = 2u;
const KIND_THIN_DIELECTRIC: u32 = 3u;
const KIND_PLASTIC: u32 = 4u;

const FLAG_TWO_SIDED: u32 = 1u;
const FLAG_NONLINEAR: u32 = 2u;
// Rough lobes use the Beckmann distribution instead of GGX.
const FLAG_BECKMANN: u32 = 4u;

// Specialization (pipeline-overridable constants, set per scene by render.rs): false removes
// the code of a feature the scene does not use. The defaults give the generic kernel.
override HAS_ROUGH_DIELECTRIC: bool = true;
override HAS_ROUGH_PLASTIC: bool = true;
override HAS_BECKMANN: bool = true;
// Smooth conductors (mirrors), rough conductors, smooth dielectrics, thin dielectrics and smooth
// plastics: a CPU driver runs every kind's code in every bounce, whatever the lanes hit.
override HAS_SMOOTH_CONDUCTOR: bool = true;
override HAS_ROUGH_CONDUCTOR: bool = true;
override HAS_DIELECTRIC: bool = true;
override HAS_THIN_DIELECTRIC: bool = true;
override HAS_PLASTIC: bool = true;

// One material, as flattened by upload.rs.
//   a: rgb = diffuse reflectance (diffuse, plastic) or specular reflectance (conductor,
//      dielectric); w = microfacet alpha (0: smooth)
//   b: rgb = specular reflectance (plastic) or specular transmittance (dielectric);
//      w = relative index of refraction int/ext (dielectric, plastic)
//   c: rgb = conductor eta; w = kind | flags << 8 (bits)
//   d: rgb = conductor k; w = the plastic's specular sampling weight
//   emission: rgb = radiance; w = 1 if the surface emits
//   e: x = offset in `aux` of the texture that replaces a.rgb (bits, even; NO_TEXTURE: none);
//      y = offset in `aux` of the rough plastic's coat transmittance table (bits);
//      z = the rough plastic's internal reflectance; w = the texture's width | height << 16 (bits)
struct Material {
    a: vec4<f32>,
    b: vec4<f32>,
    c: vec4<f32>,
    d: vec4<f32>,
    emission: vec4<f32>,
    e: vec4<f32>,
}

const NO_TEXTURE: u32 = 0xffffffffu;

// Images and tables that records point into (upload.rs, `Aux`). An environment map: its linear RGB
// texels, rows top to bottom, four words each (the fourth 0), then its sampling table, four words a
// cell, each from a multiple of four words. A material texture: its texels, two words each, from an
// even offset.
@group(0) @binding(7) var<storage, read> aux: array<f32>;
// The same buffer as pairs of words: a material texture's texel in one load (CPU drivers make one per
// SIMD lane and load, so two words at once cost about what one does).
@group(0) @binding(11) var<storage, read> aux_pairs: array<vec2<u32>>;
// And as four words: an environment map's texel or sampling cell in one load.
@group(0) @binding(12) var<storage, read> aux4: array<vec4<f32>>;


fn mat_kind(m: Material) -> u32 {
    return bitcast<u32>(m.c.w) & 0xffu;
}

fn mat_flags(m: Material) -> u32 {
    return bitcast<u32>(m.c.w) >> 8u;
}

// Whether every lobe of the material is a delta lobe (no next-event estimation there).
fn mat_is_delta(m: Material) -> bool {
    let k = mat_kind(m);
    return ((k == KIND_CONDUCTOR || k == KIND_DIELECTRIC) && m.a.w == 0.0) || k == KIND_THIN_DIELECTRIC;
}

struct BsdfSample {
    wi: vec3<f32>,
    weight: vec3<f32>,
    pdf: f32,
    delta: bool,
    valid: bool,
}

fn no_sample() -> BsdfSample {
    return BsdfSample(vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(0.0), 0.0, false, false);
}

// ---- Fresnel ----

// Unpolarized Fresnel reflectance of a dielectric interface; `cos_i` is signed (negative from
// inside), `eta` = int/ext. Also returns cos θt (signed opposite to cos_i), eta_it and eta_ti.
struct Fresnel {
    r: f32,
    cos_t: f32,
    eta_it: f32,
    eta_ti: f32,
}

fn fresnel_dielectric(cos_i_in: f32, eta: f32) -> Fresnel {
    let outside = cos_i_in >= 0.0;
    let eta_it = select(1.0 / eta, eta, outside);
    let eta_ti = select(eta, 1.0 / eta, outside);
    let cos_i = abs(cos_i_in);
    let cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
    if cos_t2 <= 0.0 {
        return Fresnel(1.0, 0.0, eta_it, eta_ti);
    }
    let cos_t = sqrt(cos_t2);
    let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
    let a_p = (eta_it * cos_i - cos_t) / (eta_it * cos_i + cos_t);
    let r = 0.5 * (a_s * a_s + a_p * a_p);
    return Fresnel(r, select(cos_t, -cos_t, outside), eta_it, eta_ti);
}

// Unpolarized Fresnel reflectance of a conductor with complex index eta + i k (per channel),
// the exact formula Mitsuba's fresnel_conductor uses.
fn fresnel_conductor(cos_i_in: f32, eta: vec3<f32>, k: vec3<f32>) -> vec3<f32> {
    let cos_i = clamp(cos_i_in, 0.0, 1.0);
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let eta2 = eta * eta;
    let k2 = k * k;
    let t0 = eta2 - k2 - vec3<f32>(sin2);
    let a2b2 = sqrt(max(t0 * t0 + 4.0 * eta2 * k2, vec3<f32>(0.0)));
    let t1 = a2b2 + vec3<f32>(cos2);
    let a = sqrt(max(0.5 * (a2b2 + t0), vec3<f32>(0.0)));
    let t2 = 2.0 * cos_i * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = cos2 * a2b2 + vec3<f32>(sin2 * sin2);
    let t4 = t2 * sin2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5 * (rp + rs);
}

// ---- microfacet distributions (isotropic GGX and Beckmann, Mitsuba's formulas) ----

fn mf_beckmann(m: Material) -> bool {
    return HAS_BECKMANN && (mat_flags(m) & FLAG_BECKMANN) != 0u;
}

fn mf_d(m: vec3<f32>, alpha: f32, beckmann: bool) -> f32 {
    if m.z <= 0.0 {
        return 0.0;
    }
    let cos2 = m.z * m.z;
    let a2 = alpha * alpha;
    let xy2 = m.x * m.x + m.y * m.y;
    var r = 0.0;
    if beckmann {
        r = exp(-xy2 / (a2 * cos2)) / (PI * a2 * cos2 * cos2);
    } else {
        let t = xy2 / a2 + cos2;
        r = 1.0 / (PI * a2 * t * t);
    }
    return select(0.0, r, r * m.z > 1e-20);
}

// Smith's G1; Beckmann through Mitsuba's rational fit.
fn mf_g1(v: vec3<f32>, m: vec3<f32>, alpha: f32, beckmann: bool) -> f32 {
    if dot(v, m) * v.z <= 0.0 {
        return 0.0;
    }
    let xy = alpha * alpha * (v.x * v.x + v.y * v.y);
    if xy == 0.0 {
        return 1.0;
    }
    let t2 = xy / (v.z * v.z);
    if beckmann {
        let a = inverseSqrt(t2);
        if a >= 1.6 {
            return 1.0;
        }
        return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a);
    }
    return 2.0 / (1.0 + sqrt(1.0 + t2));
}

// Density of mf_sample_visible: D_wo(m) = G1(wo, m) |wo·m| D(m) / cos θo.
fn mf_pdf_visible(wo: vec3<f32>, m: vec3<f32>, alpha: f32, beckmann: bool) -> f32 {
    return mf_d(m, alpha, beckmann) * mf_g1(wo, m, alpha, beckmann) * abs(dot(wo, m)) / abs(wo.z);
}

fn mf_sample_visible(wo: vec3<f32>, alpha: f32, beckmann: bool, u: vec2<f32>) -> vec3<f32> {
    if beckmann {
        return beckmann_sample_visible(wo, alpha, u);
    }
    return ggx_sample_visible(wo, alpha, u);
}

// erf to 1.5e-7 (Abramowitz & Stegun 7.1.26).
fn erf_approx(x: f32) -> f32 {
    let z = abs(x);
    let t = 1.0 / (1.0 + 0.3275911 * z);
    let y = 1.0 - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592) * t * exp(-z * z);
    return select(-y, y, x >= 0.0);
}

// Inverse erf (Giles 2010, single precision).
fn erfinv_approx(x: f32) -> f32 {
    var w = -log(max((1.0 - x) * (1.0 + x), 1e-30));
    var p = 0.0;
    if w < 5.0 {
        w = w - 2.5;
        p = 2.81022636e-08;
        p = 3.43273939e-07 + p * w;
        p = -3.5233877e-06 + p * w;
        p = -4.39150654e-06 + p * w;
        p = 0.00021858087 + p * w;
        p = -0.00125372503 + p * w;
        p = -0.00417768164 + p * w;
        p = 0.246640727 + p * w;
        p = 1.50140941 + p * w;
    } else {
        w = sqrt(w) - 3.0;
        p = -0.000200214257;
        p = 0.000100950558 + p * w;
        p = 0.00134934322 + p * w;
        p = -0.00367342844 + p * w;
        p = 0.00573950773 + p * w;
        p = -0.0076224613 + p * w;
        p = 0.00943887047 + p * w;
        p = 1.00167406 + p * w;
        p = 2.83297682 + p * w;
    }
    return p * x;
}

// A Beckmann visible normal (Mitsuba's sample_visible_11: the visible-slope CDF inverted by
// Newton's method in the erf domain, kept inside its interval), stretched by alpha.
fn beckmann_sample_visible(wo: vec3<f32>, alpha: f32, u_in: vec2<f32>) -> vec3<f32> {
    let v = normalize(vec3<f32>(alpha * wo.x, alpha * wo.y, wo.z));
    let u = clamp(u_in, vec2<f32>(1e-6), vec2<f32>(1.0 - 1e-6));
    let cos_t = min(v.z, 0.99999);
    let tan_t = sqrt(max(0.0, 1.0 - cos_t * cos_t)) / cos_t;
    let cot_t = 1.0 / tan_t;
    let maxval = erf_approx(cot_t);
    let inv_sqrt_pi = 0.564189583547756;
    var x = maxval - (maxval + 1.0) * erf_approx(sqrt(-log(u.x)));
    let target_value = u.x * (1.0 + maxval + inv_sqrt_pi * tan_t * exp(-cot_t * cot_t));
    for (var k = 0; k < 8; k++) {
        let slope = erfinv_approx(x);
        let value = 1.0 + x + inv_sqrt_pi * tan_t * exp(-slope * slope) - target_value;
        let derivative = 1.0 - slope * tan_t;
        x = clamp(x - value / max(derivative, 1e-6), -0.9999999, maxval);
    }
    let sx = erfinv_approx(x);
    let sy = erfinv_approx(2.0 * u.y - 1.0);
    let s = length(v.xy);
    var cos_phi = 1.0;
    var sin_phi = 0.0;
    if s > 0.0 {
        cos_phi = v.x / s;
        sin_phi = v.y / s;
    }
    let slope = vec2<f32>(cos_phi * sx - sin_phi * sy, sin_phi * sx + cos_phi * sy) * alpha;
    return normalize(vec3<f32>(-slope.x, -slope.y, 1.0));
}

// A microfacet normal distributed as D_wo(m) ∝ G1(wo, m) max(0, wo·m) D(m) (Heitz 2018).
fn ggx_sample_visible(wo: vec3<f32>, alpha: f32, u: vec2<f32>) -> vec3<f32> {
    let vh = normalize(vec3<f32>(alpha * wo.x, alpha * wo.y, wo.z));
    let len2 = vh.x * vh.x + vh.y * vh.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if len2 > 0.0 {
        t1 = vec3<f32>(-vh.y, vh.x, 0.0) / sqrt(len2);
    }
    let t2 = cross(vh, t1);
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    let p1 = r * cos(phi);
    var p2 = r * sin(phi);
    let s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2;
    let nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3<f32>(alpha * nh.x, alpha * nh.y, max(1e-6, nh.z)));
}

fn reflect_local(w: vec3<f32>, m: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(w, m) * m - w;
}

fn cosine_local(u: vec2<f32>) -> vec3<f32> {
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
}

// Hemispherical average of the dielectric Fresnel reflectance seen from a medium of relative
// index `eta` (Mitsuba's fresnel_diffuse_reflectance polynomial fits).
fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    if eta < 1.0 {
        return -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta;
    }
    let inv = 1.0 / eta;
    let inv2 = inv * inv;
    let inv3 = inv2 * inv;
    let inv4 = inv3 * inv;
    let inv5 = inv4 * inv;
    return 0.919317 - 3.4793 * inv + 6.75335 * inv2 - 7.80989 * inv3 + 4.98554 * inv4 - 1.36881 * inv5;
}

// The plastic's diffuse base under its coat, per Mitsuba's plastic.cpp.
fn plastic_diffuse(m: Material, cos_o: f32, cos_i: f32) -> vec3<f32> {
    let eta = m.b.w;
    let f_o = fresnel_dielectric(cos_o, eta).r;
    let f_i = fresnel_dielectric(cos_i, eta).r;
    let fdr_int = fresnel_diffuse_reflectance(1.0 / eta);
    var diffuse = m.a.xyz;
    if (mat_flags(m) & FLAG_NONLINEAR) != 0u {
        diffuse = diffuse / (vec3<f32>(1.0) - diffuse * fdr_int);
    } else {
        diffuse = diffuse / (1.0 - fdr_int);
    }
    return diffuse * (1.0 - f_o) * (1.0 - f_i) / (eta * eta);
}

// ---- rough plastic (Mitsuba's roughplastic) ----

// The coat's transmittance 1 − albedo at cos θ, interpolated in the material's 64-entry table.
fn plastic_transmittance(m: Material, cos_theta: f32) -> f32 {
    let base = bitcast<u32>(m.e.y);
    let x = clamp(cos_theta, 0.0, 1.0) * 63.0;
    let i = min(u32(x), 62u);
    return mix(aux[base + i], aux[base + i + 1u], x - f32(i));
}

// Probability of sampling the coat: its reflectance × the specular sampling weight, against
// the base's transmittance × the diffuse weight; `t_o` is plastic_transmittance(m, cos θo).
fn rough_plastic_coat_prob(m: Material, t_o: f32) -> f32 {
    let ps = (1.0 - t_o) * m.d.w;
    let pd = t_o * (1.0 - m.d.w);
    return ps / (ps + pd);
}

// f·cos θi of both lobes (xyz) and the density with which rough_plastic_sample produces wi (w), wo
// and wi above the surface; `t_o` is plastic_transmittance(m, wo.z). One function for both, since
// next-event estimation needs both and they share the half vector, D, G1 and the table lookup.
fn rough_plastic_eval_pdf(m: Material, wo: vec3<f32>, wi: vec3<f32>, t_o: f32) -> vec4<f32> {
    let alpha = m.a.w;
    let bk = mf_beckmann(m);
    let eta = m.b.w;
    let h = normalize(wo + wi);
    let f = fresnel_dielectric(dot(wo, h), eta).r;
    let d = mf_d(h, alpha, bk);
    let g1_o = mf_g1(wo, h, alpha, bk);
    let coat = m.b.xyz * (f * d * (g1_o * mf_g1(wi, h, alpha, bk)) / (4.0 * wo.z));
    var base = m.a.xyz;
    if (mat_flags(m) & FLAG_NONLINEAR) != 0u {
        base = base / (vec3<f32>(1.0) - base * m.e.z);
    } else {
        base = base / (1.0 - m.e.z);
    }
    let t = t_o * plastic_transmittance(m, wi.z);
    let value = coat + base * (INV_PI / (eta * eta) * wi.z * t);
    let ps = rough_plastic_coat_prob(m, t_o);
    let coat_pdf = d * g1_o * abs(dot(wo, h)) / abs(wo.z) / (4.0 * dot(wo, h));
    return vec4<f32>(value, ps * coat_pdf + (1.0 - ps) * wi.z * INV_PI);
}

// `h`: a visible normal sampled for wo with `u` (bsdf_sample), which the coat reflects about.
fn rough_plastic_sample(m: Material, wo: vec3<f32>, h: vec3<f32>, u: vec2<f32>, u_lobe: f32) -> BsdfSample {
    let t_o = plastic_transmittance(m, wo.z);
    var wi = vec3<f32>(0.0);
    if u_lobe < rough_plastic_coat_prob(m, t_o) {
        wi = reflect_local(wo, h);
    } else {
        wi = cosine_local(u);
    }
    if wi.z <= 0.0 {
        return no_sample();
    }
    let fp = rough_plastic_eval_pdf(m, wo, wi, t_o);
    if !(fp.w > 0.0) {
        return no_sample();
    }
    return BsdfSample(wi, fp.xyz / fp.w, fp.w, false, true);
}

// ---- rough dielectric (Mitsuba's roughdielectric, visible normals) ----
// `wo` faces the camera side, `wi` the light side; m.b.w = int/ext.

// Generalized half vector, on the macro-surface's upper side, and the relative index
// eta = n(wi side) / n(wo side) used by the refraction Jacobian.
struct RoughHalf {
    h: vec3<f32>,
    eta: f32,
    reflect: bool,
    valid: bool,
}

fn rough_half(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> RoughHalf {
    let reflect = wo.z * wi.z > 0.0;
    let eta = select(1.0 / m.b.w, m.b.w, wo.z > 0.0);
    let v = wo + wi * select(eta, 1.0, reflect);
    let len = length(v);
    if wo.z == 0.0 || wi.z == 0.0 || len < 1e-7 {
        return RoughHalf(vec3<f32>(0.0, 0.0, 1.0), eta, reflect, false);
    }
    var h = v / len;
    h = select(-h, h, h.z >= 0.0);
    // Micro- and macro-surface must agree on the side of each direction.
    let valid = dot(wo, h) * wo.z > 0.0 && dot(wi, h) * wi.z > 0.0;
    return RoughHalf(h, eta, reflect, valid);
}

// f·|cos θi| (xyz) and the density with which rough_dielectric_sample produces wi (w).
fn rough_dielectric_eval_pdf(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> vec4<f32> {
    let rh = rough_half(m, wo, wi);
    if !rh.valid {
        return vec4<f32>(0.0);
    }
    let alpha = m.a.w;
    let bk = mf_beckmann(m);
    let d = mf_d(rh.h, alpha, bk);
    // G1 and the visible-normal density are even in wo, so wo stands for rough_dielectric_sample's wo_up.
    let g1_o = mf_g1(wo, rh.h, alpha, bk);
    let g = g1_o * mf_g1(wi, rh.h, alpha, bk);
    let f = fresnel_dielectric(dot(wo, rh.h), m.b.w).r;
    let dwo = dot(wo, rh.h);
    let dwi = dot(wi, rh.h);
    let visible = d * g1_o * abs(dwo) / abs(wo.z);
    if rh.reflect {
        let value = m.a.xyz * (f * d * g / (4.0 * abs(wo.z)));
        return vec4<f32>(value, visible * f * (1.0 / (4.0 * abs(dwi))));
    }
    // Transmission; radiance compression by 1 / eta² cancels the Jacobian's eta².
    let denom = dwo + rh.eta * dwi;
    let value = m.b.xyz * ((1.0 - f) * abs(d * g * dwo * dwi / (wo.z * denom * denom)));
    return vec4<f32>(value, visible * (1.0 - f) * (rh.eta * rh.eta * abs(dwi) / (denom * denom)));
}

// wo on the side of the macro-normal, for which a rough dielectric samples its visible normals.
fn rough_dielectric_up(wo: vec3<f32>) -> vec3<f32> {
    return select(-wo, wo, wo.z > 0.0);
}

// `h`: a visible normal sampled for rough_dielectric_up(wo) (bsdf_sample).
fn rough_dielectric_sample(m: Material, wo: vec3<f32>, h: vec3<f32>, u_lobe: f32) -> BsdfSample {
    let alpha = m.a.w;
    let bk = mf_beckmann(m);
    let wo_up = rough_dielectric_up(wo);
    let fr = fresnel_dielectric(dot(wo, h), m.b.w);
    var wi = vec3<f32>(0.0);
    var weight = vec3<f32>(0.0);
    if u_lobe <= fr.r {
        wi = reflect_local(wo, h);
        if wi.z * wo.z <= 0.0 {
            return no_sample();
        }
        weight = m.a.xyz;
    } else {
        // Refraction through the microfacet; radiance scales by eta_ti².
        wi = h * (dot(wo, h) * fr.eta_ti + fr.cos_t) - wo * fr.eta_ti;
        if wi.z * wo.z >= 0.0 {
            return no_sample();
        }
        weight = m.b.xyz * fr.eta_ti * fr.eta_ti;
    }
    wi = normalize(wi);
    let g1 = mf_g1(wi, h, alpha, bk);
    // The density of wi from that of the sampled normal, as Mitsuba computes it: the visible-normal
    // density, the lobe's probability and the Jacobian of the half-vector map (the density that
    // rough_dielectric_eval_pdf finds for wi from the normal it recovers from wo and wi).
    let dwo = dot(wo, h);
    let dwi = dot(wi, h);
    let reflected = u_lobe <= fr.r;
    let eta = select(1.0 / m.b.w, m.b.w, wo.z > 0.0);
    let denom = dwo + eta * dwi;
    let jacobian = select(eta * eta * abs(dwi) / (denom * denom), 1.0 / (4.0 * abs(dwi)), reflected);
    let pdf = mf_pdf_visible(wo_up, h, alpha, bk) * select(1.0 - fr.r, fr.r, reflected) * jacobian;
    if !(pdf > 0.0) || g1 == 0.0 {
        return no_sample();
    }
    return BsdfSample(wi, weight * g1, pdf, false, true);
}

// One-sided materials are black from behind; two-sided ones mirror the frame.
fn front_frame(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> mat2x3<f32> {
    if (mat_flags(m) & FLAG_TWO_SIDED) != 0u && wo.z < 0.0 {
        return mat2x3<f32>(vec3<f32>(wo.xy, -wo.z), vec3<f32>(wi.xy, -wi.z));
    }
    return mat2x3<f32>(wo, wi);
}

// f·|cos θi| of the non-delta lobes (xyz) and the solid-angle density with which bsdf_sample
// produces wi through one of them (w): next-event estimation needs both, so they share one pass
// through the material's kind (on a SIMD CPU every kind present in a batch of lanes runs).
fn bsdf_eval_pdf(m: Material, wo_in: vec3<f32>, wi_in: vec3<f32>) -> vec4<f32> {
    let kind = mat_kind(m);
    if HAS_ROUGH_DIELECTRIC && kind == KIND_DIELECTRIC && m.a.w > 0.0 {
        return rough_dielectric_eval_pdf(m, wo_in, wi_in);
    }
    if kind == KIND_DIELECTRIC || kind == KIND_THIN_DIELECTRIC {
        return vec4<f32>(0.0);
    }
    let f = front_frame(m, wo_in, wi_in);
    let wo = f[0];
    let wi = f[1];
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return vec4<f32>(0.0);
    }
    if kind == KIND_DIFFUSE {
        return vec4<f32>(m.a.xyz * INV_PI * wi.z, wi.z * INV_PI);
    }
    if kind == KIND_CONDUCTOR {
        let alpha = m.a.w;
        if !HAS_ROUGH_CONDUCTOR || alpha == 0.0 {
            return vec4<f32>(0.0);
        }
        let bk = mf_beckmann(m);
        let h = normalize(wo + wi);
        let d = mf_d(h, alpha, bk);
        let g1_o = mf_g1(wo, h, alpha, bk);
        let g = g1_o * mf_g1(wi, h, alpha, bk);
        let fr = fresnel_conductor(dot(wo, h), m.c.xyz, m.d.xyz) * m.a.xyz;
        let pdf = d * g1_o * abs(dot(wo, h)) / abs(wo.z) / (4.0 * dot(wo, h));
        return vec4<f32>(fr * d * g / (4.0 * wo.z), pdf);
    }
    if HAS_ROUGH_PLASTIC && m.a.w > 0.0 {
        return rough_plastic_eval_pdf(m, wo, wi, plastic_transmittance(m, wo.z));
    }
    if !HAS_PLASTIC {
        return vec4<f32>(0.0);
    }
    // Plastic: only the diffuse base is non-delta.
    let f_o = fresnel_dielectric(wo.z, m.b.w).r;
    let p_spec = f_o * m.d.w;
    let p_diff = (1.0 - f_o) * (1.0 - m.d.w);
    let pdf = p_diff / (p_spec + p_diff) * wi.z * INV_PI;
    return vec4<f32>(plastic_diffuse(m, wo.z, wi.z) * INV_PI * wi.z, pdf);
}

fn bsdf_eval(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> vec3<f32> {
    return bsdf_eval_pdf(m, wo, wi).xyz;
}

fn bsdf_pdf(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> f32 {
    return bsdf_eval_pdf(m, wo, wi).w;
}

// Samples wi given wo; `u` drives the direction, `u_lobe` the choice between lobes.
fn bsdf_sample(m: Material, wo_in: vec3<f32>, u: vec2<f32>, u_lobe: f32) -> BsdfSample {
    let kind = mat_kind(m);
    let rough_dielectric = HAS_ROUGH_DIELECTRIC && kind == KIND_DIELECTRIC && m.a.w > 0.0;
    let two = (mat_flags(m) & FLAG_TWO_SIDED) != 0u && wo_in.z < 0.0;
    let wo = select(wo_in, vec3<f32>(wo_in.xy, -wo_in.z), two);
    // One visible normal serves the rough dielectric, conductor and plastic, each from its own view of
    // wo: on a SIMD CPU the code of every kind a scene has runs in every lane, so sampling it once
    // saves a sampler's work for each other rough kind a scene has.
    var h = vec3<f32>(0.0, 0.0, 1.0);
    if HAS_ROUGH_DIELECTRIC || HAS_ROUGH_CONDUCTOR || HAS_ROUGH_PLASTIC {
        h = mf_sample_visible(select(wo, rough_dielectric_up(wo_in), rough_dielectric), m.a.w, mf_beckmann(m), u);
    }
    if rough_dielectric {
        return rough_dielectric_sample(m, wo_in, h, u_lobe);
    }
    if HAS_DIELECTRIC && kind == KIND_DIELECTRIC {
        let fr = fresnel_dielectric(wo_in.z, m.b.w);
        if u_lobe <= fr.r {
            return BsdfSample(vec3<f32>(-wo_in.x, -wo_in.y, wo_in.z), m.a.xyz, fr.r, true, true);
        }
        // Refraction; radiance is scaled by eta_ti² for the solid angle's compression.
        let wi = vec3<f32>(-fr.eta_ti * wo_in.x, -fr.eta_ti * wo_in.y, fr.cos_t);
        return BsdfSample(normalize(wi), m.b.xyz * fr.eta_ti * fr.eta_ti, 1.0 - fr.r, true, true);
    }
    if HAS_THIN_DIELECTRIC && kind == KIND_THIN_DIELECTRIC {
        var r = fresnel_dielectric(abs(wo_in.z), m.b.w).r;
        let t = 1.0 - r;
        // Light bouncing inside the thin slab (Mitsuba's thindielectric).
        if r < 1.0 {
            r = r + t * t * r / (1.0 - r * r);
        }
        if u_lobe <= r {
            return BsdfSample(vec3<f32>(-wo_in.x, -wo_in.y, wo_in.z), m.a.xyz, r, true, true);
        }
        return BsdfSample(-wo_in, m.b.xyz, 1.0 - r, true, true);
    }
    if wo.z <= 0.0 {
        return no_sample();
    }
    var s = no_sample();
    if kind == KIND_DIFFUSE {
        let wi = cosine_local(u);
        s = BsdfSample(wi, m.a.xyz, wi.z * INV_PI, false, wi.z > 0.0);
    } else if kind == KIND_CONDUCTOR {
        let alpha = m.a.w;
        if HAS_SMOOTH_CONDUCTOR && (!HAS_ROUGH_CONDUCTOR || alpha == 0.0) {
            let wi = vec3<f32>(-wo.x, -wo.y, wo.z);
            s = BsdfSample(wi, fresnel_conductor(wo.z, m.c.xyz, m.d.xyz) * m.a.xyz, 1.0, true, true);
        } else {
            let bk = mf_beckmann(m);
            let wi = reflect_local(wo, h);
            if wi.z > 0.0 {
                let fr = fresnel_conductor(dot(wo, h), m.c.xyz, m.d.xyz) * m.a.xyz;
                let pdf = mf_pdf_visible(wo, h, alpha, bk) / (4.0 * dot(wo, h));
                s = BsdfSample(wi, fr * mf_g1(wi, h, alpha, bk), pdf, false, pdf > 0.0);
            }
        }
    } else if HAS_ROUGH_PLASTIC && m.a.w > 0.0 {
        s = rough_plastic_sample(m, wo, h, u, u_lobe);
    } else if HAS_PLASTIC {
        // Plastic: the specular coat with probability ∝ its Fresnel reflectance × sampling weight.
        let f_o = fresnel_dielectric(wo.z, m.b.w).r;
        let p_spec = f_o * m.d.w;
        let p_diff = (1.0 - f_o) * (1.0 - m.d.w);
        let ps = p_spec / (p_spec + p_diff);
        if u_lobe < ps {
            let wi = vec3<f32>(-wo.x, -wo.y, wo.z);
            s = BsdfSample(wi, m.b.xyz * f_o / ps, ps, true, true);
        } else {
            let wi = cosine_local(u);
            let pdf = (1.0 - ps) * wi.z * INV_PI;
            s = BsdfSample(wi, plastic_diffuse(m, wo.z, wi.z) * INV_PI * wi.z / pdf, pdf, false, wi.z > 0.0 && pdf > 0.0);
        }
    }
    if two {
        s.wi = vec3<f32>(s.wi.xy, -s.wi.z);
    }
    return s;
}
