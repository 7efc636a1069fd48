// Mitsuba's analytic shapes (hush_scene::Analytic), intersected exactly in their object space:
// the unit sphere, the unit disk and the square [-1, 1]² in z = 0 (facing +z), and the open unit
// cylinder about z from z = 0 to 1. Each has a slot among the triangles (its `e2.w` holds the
// bits of the shape's index + 1, which no triangle has), so the flat scan and the BVH hold shapes
// beside triangles, and a light slot may be a shape.

struct Shape {
    // Rows of the world-to-object affine map, then of the object-to-world one.
    l0: vec4<f32>,
    l1: vec4<f32>,
    l2: vec4<f32>,
    w0: vec4<f32>,
    w1: vec4<f32>,
    w2: vec4<f32>,
    // Kind (bits), flipped normals (bits, 0 or 1), world area, a sphere's world radius.
    info: vec4<f32>,
}

@group(0) @binding(9) var<storage, read> shapes: array<Shape>;
// The first UNIFORM_SHAPES shapes again, in a uniform buffer: CPU drivers load a uniform
// buffer's words for all SIMD lanes at once (a gather), a storage buffer's lane by lane (hush_trace's
// `UNIFORM_SHAPES`; 585 records of 112 bytes fill the 64 KiB every device offers).
const UNIFORM_SHAPES: u32 = 585u;
@group(0) @binding(10) var<uniform> first_shapes: array<Shape, UNIFORM_SHAPES>;

// Specialization: the scene has more shapes than UNIFORM_SHAPES.
override HAS_MANY_SHAPES: bool = true;

fn shape_at(k: u32) -> Shape {
    if !HAS_MANY_SHAPES || k < UNIFORM_SHAPES {
        return first_shapes[k];
    }
    return shapes[k];
}

// Specialization: the scene has analytic shapes.
override HAS_SHAPES: bool = true;
// Specialization: which kinds of emitters the scene has (hush_trace's `KernelFeatures::light_kinds`):
// bit k for shape kind k (SHAPE_*), bit LIGHT_TRIANGLES for emitting triangles; light sampling runs
// only their code. LIGHT_SHAPES masks the shape kinds' bits.
override LIGHT_KINDS: u32 = 31u;
const LIGHT_TRIANGLES: u32 = 4u;
const LIGHT_SHAPES: u32 = 15u;

fn has_light(kind: u32) -> bool {
    return (LIGHT_KINDS & (1u << kind)) != 0u;
}

const SHAPE_SPHERE: u32 = 0u;
const SHAPE_DISK: u32 = 1u;
const SHAPE_RECTANGLE: u32 = 2u;
const SHAPE_CYLINDER: u32 = 3u;
const NO_SHAPE: u32 = 0xffffffffu;

fn affine(r0: vec4<f32>, r1: vec4<f32>, r2: vec4<f32>, p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w);
}

fn linear(r0: vec4<f32>, r1: vec4<f32>, r2: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(r0.xyz, v), dot(r1.xyz, v), dot(r2.xyz, v));
}

// The roots (smaller first) of a t² + 2 b t + c = 0, given its discriminant divided by 4,
// `disc` = b² − a c, computed by the caller without cancellation. The pair is computed so that
// neither root cancels (Press et al.; Haines et al., Ray Tracing Gems ch. 7).
fn quadratic_roots(a: f32, b: f32, c: f32, disc: f32) -> vec2<f32> {
    let q = -(b + select(-1.0, 1.0, b >= 0.0) * sqrt(max(disc, 0.0)));
    let t0 = q / a;
    let t1 = c / q;
    return vec2<f32>(min(t0, t1), max(t0, t1));
}

// The nearest t in (0, t_max) at which o + t d meets a sphere or a cylinder, or T_MAX. A sphere is
// tested in the world (`cr`: its centre and radius), the cylinder |p.xy| = 1, 0 ≤ z ≤ 1 in object
// space (`o`, `d` mapped there; d is not normalized). The discriminant comes from the ray's closest
// approach to the centre or axis, l = o − (b / a) d: b² − a c = a (r² − |l|²). Every condition is an
// acceptance test, so NaNs reject.
fn round_distance(cyl: bool, cr: vec4<f32>, o: vec3<f32>, d: vec3<f32>, t_max: f32) -> f32 {
    let m = select(vec3<f32>(1.0), vec3<f32>(1.0, 1.0, 0.0), cyl);
    let om = (o - cr.xyz) * m;
    let dm = d * m;
    let r2 = cr.w * cr.w;
    let a = dot(dm, dm);
    let b = dot(om, dm);
    let c = dot(om, om) - r2;
    let l = om - (b / a) * dm;
    let disc = a * (r2 - dot(l, l));
    let r = quadratic_roots(a, b, c, disc);
    let z0 = o.z + r.x * d.z;
    let z1 = o.z + r.y * d.z;
    let in0 = !cyl || (z0 >= 0.0 && z0 <= 1.0);
    let in1 = !cyl || (z1 >= 0.0 && z1 <= 1.0);
    let first = disc >= 0.0 && in0 && r.x > 0.0 && r.x < t_max;
    let second = disc >= 0.0 && in1 && r.y > 0.0 && r.y < t_max;
    return select(select(T_MAX, r.y, second), r.x, first);
}

// Where o + t d crosses the plane of rows l0..l2 (its z = 0) and the (x, y) of that point there:
// the plane's row first, then only the two rows of the point, as Baldwin and Weber intersect
// triangles (JCGT 5(3), 2016). Returns (t, x, y); t is ±inf or NaN for a ray in the plane.
fn plane_crossing(l0: vec4<f32>, l1: vec4<f32>, l2: vec4<f32>, o: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    let t = -(dot(l2.xyz, o) + l2.w) / dot(l2.xyz, d);
    let p = o + t * d;
    return vec3<f32>(t, dot(l0.xyz, p) + l0.w, dot(l1.xyz, p) + l1.w);
}

// Updates `hit` when the shape in slot i is nearer; returns whether it was. `l0`..`l2` are the rows
// of its world-to-object map, except for a sphere, whose `l0` is its world centre and radius. The
// caller sets the slot's other fields.
fn test_shape_at(i: u32, kind: u32, l0: vec4<f32>, l1: vec4<f32>, l2: vec4<f32>, o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) -> bool {
    var t = T_MAX;
    if kind == SHAPE_SPHERE {
        t = round_distance(false, l0, o, d, (*hit).t);
    } else if kind == SHAPE_CYLINDER {
        t = round_distance(true, vec4<f32>(0.0, 0.0, 0.0, 1.0), affine(l0, l1, l2, o), linear(l0, l1, l2, d), (*hit).t);
    } else {
        let c = plane_crossing(l0, l1, l2, o, d);
        var inside = c.y * c.y + c.z * c.z <= 1.0;
        if kind == SHAPE_RECTANGLE {
            inside = abs(c.y) <= 1.0 && abs(c.z) <= 1.0;
        }
        t = select(T_MAX, c.x, inside && c.x > 0.0 && c.x < (*hit).t);
    }
    let nearer = t < (*hit).t;
    if nearer {
        (*hit).t = t;
        (*hit).tri = i;
    }
    return nearer;
}

// The triangle in slot i by its world-to-barycentric rows: (u, v, s) of a point x are
// (r0 · x + r0.w, r1 · x + r1.w, r2 · x + r2.w) with x = p0 + u e1 + v e2 + s (e1 × e2). Written into a
// specialized kernel as literals (Baldwin and Weber's test), it takes about half the arithmetic of
// Möller–Trumbore. Updates `hit` like `test_triangle_at`.
fn test_triangle_rows(i: u32, r0: vec4<f32>, r1: vec4<f32>, r2: vec4<f32>, o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) -> bool {
    let c = plane_crossing(r0, r1, r2, o, d);
    let nearer = c.y >= 0.0 && c.z >= 0.0 && c.y + c.z <= 1.0 && c.x > 0.0 && c.x < (*hit).t;
    if nearer {
        (*hit).t = c.x;
        (*hit).tri = i;
        (*hit).u = c.y;
        (*hit).v = c.z;
    }
    return nearer;
}

// Shape k of the buffer, in slot i, with the slot's material and light density.
fn test_shape(i: u32, k: u32, mat: u32, area_pdf: f32, o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {
    let s = shape_at(k);
    let kind = bitcast<u32>(s.info.x);
    let l0 = select(s.l0, vec4<f32>(s.w0.w, s.w1.w, s.w2.w, s.info.w), kind == SHAPE_SPHERE);
    if test_shape_at(i, kind, l0, s.l1, s.l2, o, d, hit) {
        (*hit).mat = mat;
        (*hit).area_pdf = area_pdf;
        (*hit).shape = k;
    }
}

fn wrap_turns(phi: f32) -> f32 {
    let u = phi * (0.5 * INV_PI);
    return select(u, u + 1.0, u < 0.0);
}

// A shape's unit normal (on its front side, as `flip_normals` leaves it) and texture coordinates
// at world point p on it, as Mitsuba defines them.
struct ShapeSurface {
    n: vec3<f32>,
    uv: vec2<f32>,
}

fn shape_surface(k: u32, p: vec3<f32>) -> ShapeSurface {
    let s = shape_at(k);
    let kind = bitcast<u32>(s.info.x);
    let pl = affine(s.l0, s.l1, s.l2, p);
    var n = vec3<f32>(0.0);
    var uv = vec2<f32>(0.0);
    if kind == SHAPE_SPHERE {
        n = normalize(p - vec3<f32>(s.w0.w, s.w1.w, s.w2.w));
        let z = clamp(pl.z / length(pl), -1.0, 1.0);
        uv = vec2<f32>(wrap_turns(atan2(pl.y, pl.x)), acos(z) * INV_PI);
    } else if kind == SHAPE_CYLINDER {
        // The object-space normal (x, y, 0) by the inverse transpose: the rows of world-to-object.
        n = normalize(pl.x * s.l0.xyz + pl.y * s.l1.xyz);
        uv = vec2<f32>(wrap_turns(atan2(pl.y, pl.x)), pl.z);
    } else {
        n = normalize(s.l2.xyz);
        if kind == SHAPE_DISK {
            uv = vec2<f32>(length(pl.xy), wrap_turns(atan2(pl.y, pl.x)));
        } else {
            uv = 0.5 * (pl.xy + vec2<f32>(1.0));
        }
    }
    if bitcast<u32>(s.info.y) != 0u {
        n = -n;
    }
    return ShapeSurface(n, uv);
}

// 1 − cos θ for sin² θ = s2 (θ ≤ π/2), without cancellation for small angles.
fn one_minus_cos(s2: f32) -> f32 {
    return s2 / (1.0 + sqrt(max(0.0, 1.0 - s2)));
}

// Whether point p is outside sphere k's light-sampling cone test (as Mitsuba's `sphere`: the cone
// of directions it subtends from outside; uniform area sampling from inside).
fn sphere_light_outside(s: Shape, p: vec3<f32>) -> bool {
    let dc = vec3<f32>(s.w0.w, s.w1.w, s.w2.w) - p;
    let r = s.info.w * select(1.0 - 1e-4, 1.0 + 1e-4, bitcast<u32>(s.info.y) != 0u);
    return dot(dc, dc) > r * r;
}

// The solid-angle density, from p, with which `shape_light_sample` picks the point `q` of shape s
// (its record; normal n) seen along unit wi at distance dist; `pick` is the probability per unit area the
// light slot has (its pick probability over the shape's area).
fn shape_light_pdf(s: Shape, pick: f32, p: vec3<f32>, wi: vec3<f32>, dist: f32, n: vec3<f32>) -> f32 {
    if has_light(SHAPE_SPHERE) && bitcast<u32>(s.info.x) == SHAPE_SPHERE && sphere_light_outside(s, p) {
        let dc = vec3<f32>(s.w0.w, s.w1.w, s.w2.w) - p;
        let s2 = min(s.info.w * s.info.w / dot(dc, dc), 1.0);
        return pick * s.info.z / (2.0 * PI * one_minus_cos(s2));
    }
    return pick * dist * dist / abs(dot(n, wi));
}

struct ShapeLightSample {
    q: vec3<f32>,
    n: vec3<f32>,
}

// A point on shape s (its record) for light sampling from p: a sphere by the cone it subtends (Mitsuba's
// `sample_direction`, after akalin.com/sampling-visible-sphere) when p is outside it, every
// other case uniformly by area; `shape_light_pdf` gives the density.
fn shape_light_sample(s: Shape, p: vec3<f32>, u: vec2<f32>) -> ShapeLightSample {
    let kind = bitcast<u32>(s.info.x);
    let phi = 2.0 * PI * u.y;
    if has_light(SHAPE_SPHERE) && kind == SHAPE_SPHERE {
        let c = vec3<f32>(s.w0.w, s.w1.w, s.w2.w);
        let r = s.info.w;
        var dir = vec3<f32>(0.0);
        if sphere_light_outside(s, p) {
            let dc = c - p;
            let inv_dc = inverseSqrt(dot(dc, dc));
            let sin_max = min(r * inv_dc, 1.0);
            let sin_max2 = sin_max * sin_max;
            // cos θ uniform in [cos θ_max, 1]; then the angle α at the centre between −dc and the point.
            let omc = u.x * one_minus_cos(sin_max2);
            let sin_t2 = omc * (2.0 - omc);
            let cos_t = 1.0 - omc;
            let cos_a = sin_t2 / sin_max + cos_t * sqrt(max(0.0, 1.0 - sin_t2 / sin_max2));
            let sin_a = sqrt(max(0.0, 1.0 - cos_a * cos_a));
            dir = basis(-dc * inv_dc) * vec3<f32>(cos(phi) * sin_a, sin(phi) * sin_a, cos_a);
        } else {
            let z = 1.0 - 2.0 * u.x;
            let sr = sqrt(max(0.0, 1.0 - z * z));
            dir = vec3<f32>(sr * cos(phi), sr * sin(phi), z);
        }
        let flip = select(1.0, -1.0, bitcast<u32>(s.info.y) != 0u);
        return ShapeLightSample(c + r * dir, flip * dir);
    }
    var local = vec3<f32>(0.0);
    if has_light(SHAPE_DISK) && kind == SHAPE_DISK {
        let rr = sqrt(u.x);
        local = vec3<f32>(rr * cos(phi), rr * sin(phi), 0.0);
    } else if has_light(SHAPE_RECTANGLE) && kind == SHAPE_RECTANGLE {
        local = vec3<f32>(2.0 * u.x - 1.0, 2.0 * u.y - 1.0, 0.0);
    } else if has_light(SHAPE_CYLINDER) {
        local = vec3<f32>(cos(phi), sin(phi), u.x);
    }
    let q = affine(s.w0, s.w1, s.w2, local);
    // The normal as `shape_surface` gives it, for the planar shapes and the cylinder.
    var n = normalize(s.l2.xyz);
    if has_light(SHAPE_CYLINDER) && kind == SHAPE_CYLINDER {
        let pl = affine(s.l0, s.l1, s.l2, q);
        n = normalize(pl.x * s.l0.xyz + pl.y * s.l1.xyz);
    }
    if bitcast<u32>(s.info.y) != 0u {
        n = -n;
    }
    return ShapeLightSample(q, n);
}
