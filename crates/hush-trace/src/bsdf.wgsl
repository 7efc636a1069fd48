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

// One material, as flattened by upload.rs.
//   a: rgb = diffuse reflectance (diffuse, plastic) or specular reflectance (conductor,
//      dielectric); w = GGX alpha (0: smooth)
//   b: rgb = specular reflectance (plastic) or specular transmittance (dielectric);
//      w = relative index of refraction int/ext (dielectric, plastic)
//   c: rgb = conductor eta; w = kind | flags << 8 (bits)
//   d: rgb = conductor k; w = the plastic's specular sampling weight
//   emission: rgb = radiance; w = 1 if the surface emits
struct Material {
    a: vec4<f32>,
    b: vec4<f32>,
    c: vec4<f32>,
    d: vec4<f32>,
    emission: vec4<f32>,
}

fn mat_kind(m: Material) -> u32 {
    return bitcast<u32>(m.c.w) & 0xffu;
}

fn mat_flags(m: Material) -> u32 {
    return bitcast<u32>(m.c.w) >> 8u;
}

// Whether every lobe of the material is a delta lobe (no next-event estimation there).
fn mat_is_delta(m: Material) -> bool {
    let k = mat_kind(m);
    return (k == KIND_CONDUCTOR && m.a.w == 0.0) || k == KIND_DIELECTRIC || k == KIND_THIN_DIELECTRIC;
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

// ---- GGX (isotropic), Smith's separable shadowing, visible-normal sampling ----

fn ggx_d(m: vec3<f32>, alpha: f32) -> f32 {
    let cos2 = m.z * m.z;
    if m.z <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = (m.x * m.x + m.y * m.y) / a2 + cos2;
    return 1.0 / (PI * a2 * t * t);
}

fn ggx_g1(v: vec3<f32>, m: vec3<f32>, alpha: f32) -> f32 {
    if dot(v, m) * v.z <= 0.0 {
        return 0.0;
    }
    let cos2 = v.z * v.z;
    let tan2 = max(0.0, 1.0 - cos2) / max(cos2, 1e-12);
    return 2.0 / (1.0 + sqrt(1.0 + alpha * alpha * tan2));
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

// One-sided materials are black from behind; two-sided ones mirror the frame.
fn front_frame(m: Material, wo: vec3<f32>, wi: vec3<f32>) -> mat2x3<f32> {
    if (mat_flags(m) & FLAG_TWO_SIDED) != 0u && wo.z < 0.0 {
        return mat2x3<f32>(vec3<f32>(wo.xy, -wo.z), vec3<f32>(wi.xy, -wi.z));
    }
    return mat2x3<f32>(wo, wi);
}

// f·|cos θi| of the non-delta lobes.
fn bsdf_eval(m: Material, wo_in: vec3<f32>, wi_in: vec3<f32>) -> vec3<f32> {
    let kind = mat_kind(m);
    if kind == KIND_DIELECTRIC || kind == KIND_THIN_DIELECTRIC {
        return vec3<f32>(0.0);
    }
    let f = front_frame(m, wo_in, wi_in);
    let wo = f[0];
    let wi = f[1];
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return vec3<f32>(0.0);
    }
    if kind == KIND_DIFFUSE {
        return m.a.xyz * INV_PI * wi.z;
    }
    if kind == KIND_CONDUCTOR {
        let alpha = m.a.w;
        if alpha == 0.0 {
            return vec3<f32>(0.0);
        }
        let h = normalize(wo + wi);
        let g = ggx_g1(wo, h, alpha) * ggx_g1(wi, h, alpha);
        let fr = fresnel_conductor(dot(wo, h), m.c.xyz, m.d.xyz) * m.a.xyz;
        return fr * ggx_d(h, alpha) * g / (4.0 * wo.z);
    }
    // Plastic: only the diffuse base is non-delta.
    return plastic_diffuse(m, wo.z, wi.z) * INV_PI * wi.z;
}

// Solid-angle density with which bsdf_sample produces wi through a non-delta lobe.
fn bsdf_pdf(m: Material, wo_in: vec3<f32>, wi_in: vec3<f32>) -> f32 {
    let kind = mat_kind(m);
    if kind == KIND_DIELECTRIC || kind == KIND_THIN_DIELECTRIC {
        return 0.0;
    }
    let f = front_frame(m, wo_in, wi_in);
    let wo = f[0];
    let wi = f[1];
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    if kind == KIND_DIFFUSE {
        return wi.z * INV_PI;
    }
    if kind == KIND_CONDUCTOR {
        let alpha = m.a.w;
        if alpha == 0.0 {
            return 0.0;
        }
        let h = normalize(wo + wi);
        return ggx_d(h, alpha) * ggx_g1(wo, h, alpha) / (4.0 * wo.z);
    }
    let f_o = fresnel_dielectric(wo.z, m.b.w).r;
    let p_spec = f_o * m.d.w;
    let p_diff = (1.0 - f_o) * (1.0 - m.d.w);
    return p_diff / (p_spec + p_diff) * wi.z * INV_PI;
}

// Samples wi given wo; `u` drives the direction, `u_lobe` the choice between lobes.
fn bsdf_sample(m: Material, wo_in: vec3<f32>, u: vec2<f32>, u_lobe: f32) -> BsdfSample {
    let kind = mat_kind(m);
    if kind == KIND_DIELECTRIC {
        let fr = fresnel_dielectric(wo_in.z, m.b.w);
        if u_lobe <= fr.r {
            return BsdfSample(vec3<f32>(-wo_in.x, -wo_in.y, wo_in.z), m.a.xyz, fr.r, true, true);
        }
        // Refraction; radiance is scaled by eta_ti² for the solid angle's compression.
        let wi = vec3<f32>(-fr.eta_ti * wo_in.x, -fr.eta_ti * wo_in.y, fr.cos_t);
        return BsdfSample(normalize(wi), m.b.xyz * fr.eta_ti * fr.eta_ti, 1.0 - fr.r, true, true);
    }
    if kind == KIND_THIN_DIELECTRIC {
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
    let two = (mat_flags(m) & FLAG_TWO_SIDED) != 0u && wo_in.z < 0.0;
    let wo = select(wo_in, vec3<f32>(wo_in.xy, -wo_in.z), two);
    if wo.z <= 0.0 {
        return no_sample();
    }
    var s = no_sample();
    if kind == KIND_DIFFUSE {
        let wi = cosine_local(u);
        s = BsdfSample(wi, m.a.xyz, wi.z * INV_PI, false, wi.z > 0.0);
    } else if kind == KIND_CONDUCTOR {
        let alpha = m.a.w;
        if alpha == 0.0 {
            let wi = vec3<f32>(-wo.x, -wo.y, wo.z);
            s = BsdfSample(wi, fresnel_conductor(wo.z, m.c.xyz, m.d.xyz) * m.a.xyz, 1.0, true, true);
        } else {
            let h = ggx_sample_visible(wo, alpha, u);
            let wi = reflect_local(wo, h);
            if wi.z > 0.0 {
                let fr = fresnel_conductor(dot(wo, h), m.c.xyz, m.d.xyz) * m.a.xyz;
                let pdf = ggx_d(h, alpha) * ggx_g1(wo, h, alpha) / (4.0 * wo.z);
                s = BsdfSample(wi, fr * ggx_g1(wi, h, alpha), pdf, false, pdf > 0.0);
            }
        }
    } else {
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
