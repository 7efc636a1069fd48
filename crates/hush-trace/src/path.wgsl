// hush's path tracer: one invocation per pixel, `samples_per_dispatch` paths each.
//
// Light transport follows Mitsuba 3's `path` integrator: next-event estimation combined with
// BSDF sampling by multiple importance sampling (power heuristic), Russian roulette from
// depth RR_DEPTH, and Mitsuba's `max_depth` convention (1 = emitters seen directly,
// 2 = direct light only). Auxiliary features are taken at the first hit that is not a delta surface
// (mirrors and smooth glass are followed, as OIDN recommends).

struct Params {
    origin: vec4<f32>,
    // Camera basis scaled so that a pixel-plane point (sx, sy) in [-1, 1]² maps to
    // forward + sx * right + sy * up.
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    width: u32,
    height: u32,
    sample_offset: u32,
    samples_per_dispatch: u32,
    seed_lo: u32,
    seed_hi: u32,
    max_depth: u32,
    tri_count: u32,
    light_count: u32,
    // The pixel filter: FILTER_BOX, FILTER_TENT (width: its radius) or FILTER_GAUSSIAN (width: its
    // standard deviation), in pixels.
    filter_kind: u32,
    filter_width: f32,
    // PIXEL_STRATIFIED (`pixel_point`) or PIXEL_INDEPENDENT (two numbers of the path's stream).
    pixel_sampler: u32,
}

const PIXEL_STRATIFIED: u32 = 0u;
const PIXEL_INDEPENDENT: u32 = 1u;

const FILTER_BOX: u32 = 0u;
const FILTER_TENT: u32 = 1u;
const FILTER_GAUSSIAN: u32 = 2u;

// A triangle for intersection. p0.w: material index (bits); e1.w: probability density per
// unit area of picking a point on this triangle by light sampling (0 if not emissive).
struct Tri {
    p0: vec4<f32>,
    e1: vec4<f32>,
    e2: vec4<f32>,
}

// Shading normals at the three vertices; n0.w = 1 for interpolated normals, 0 for flat.
// Texture coordinates of the vertices: uv01 = (u0, v0, u1, v1), uv2.xy = (u2, v2).
struct TriNormals {
    n0: vec4<f32>,
    n1: vec4<f32>,
    n2: vec4<f32>,
    uv01: vec4<f32>,
    uv2: vec4<f32>,
}

// Emissive triangles with the cumulative distribution for picking one by power.
struct Light {
    tri: u32,
    cdf: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> tris: array<Tri>;
@group(0) @binding(2) var<storage, read> normals: array<TriNormals>;
@group(0) @binding(3) var<storage, read> materials: array<Material>;
@group(0) @binding(4) var<storage, read> lights: array<Light>;
// Per pixel, ACCUM_STRIDE floats: beauty mean (3) and the sum of squared deviations from that mean
// (3) over the samples so far, then sums of albedo (3), diffuse (3), specular (3), normal (3), and the
// count of non-finite samples discarded (1).
@group(0) @binding(5) var<storage, read_write> accum: array<f32>;
@group(0) @binding(6) var<storage, read> nodes: array<WideNode>;

const PI: f32 = 3.14159265358979;
const INV_PI: f32 = 0.318309886183791;
const RR_DEPTH: u32 = 5u;
const ACCUM_STRIDE: u32 = 19u;
const T_MAX: f32 = 3.0e38;

// Specialization (see bsdf.wgsl): textures, the environment, vertex normals.
override HAS_TEXTURES: bool = true;
override HAS_ENV: bool = true;
// Specialization: some triangle or shape emits. Without it, next-event estimation's light side is
// compiled out (a branch on a random number alone runs it with every lane masked off on CPU drivers).
override HAS_LIGHTS: bool = true;
override HAS_SHADING_NORMALS: bool = true;
// The film's filter is a tent or a gaussian (false: a box).
override HAS_WIDE_FILTER: bool = true;
// Few triangles: every ray tests all of them in order instead of walking the BVH.
override FLAT_SCAN: bool = false;

// ---- random numbers: PCG hash (Jarzynski & Olano 2020) ----

var<private> rng_state: u32;

fn pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rand() -> f32 {
    rng_state = pcg(rng_state);
    return f32(rng_state >> 8u) * (1.0 / 16777216.0);
}

// ---- pixel positions: a scrambled (0, 2)-sequence ----

// The `index`-th point of the base-2 (0, 2)-sequence (van der Corput's radical inverse and Sobol's
// second dimension), each axis XORed with its own random 32-bit word (a random digital shift).
// Every prefix of 2^k points has one point in each of the 2^k elementary intervals of the unit
// square (a 4 × 4 grid at 16 spp, and 1 × 16, 2 × 8, ...), and each point is uniform over the
// square, so a pixel's estimate stays unbiased while the part of its variance that comes from where
// in the pixel a sample lies (an edge, an emitter's rim, a texture) falls faster than 1/n.
fn pixel_point(index: u32, scramble: vec2<u32>) -> vec2<f32> {
    var y = scramble.y;
    var v = 0x80000000u;
    for (var i = index; i != 0u; i >>= 1u) {
        if (i & 1u) != 0u {
            y ^= v;
        }
        v ^= v >> 1u;
    }
    let x = reverseBits(index) ^ scramble.x;
    return vec2<f32>(f32(x >> 8u), f32(y >> 8u)) * (1.0 / 16777216.0);
}

// ---- geometry ----

// A ray's nearest hit: distance, slot (triangle or shape), barycentrics, and of that slot its
// material, geometric normal (a triangle's cross(e1, e2), not normalized; a shape's is found after
// the trace, `shape_surface`), light-sampling density per unit area and shape (NO_SHAPE for a
// triangle).
struct Hit {
    t: f32,
    tri: u32,
    u: f32,
    v: f32,
    mat: u32,
    ng: vec3<f32>,
    area_pdf: f32,
    shape: u32,
}

// A node of the four-wide BVH (hush_trace's `GpuWideNode`, whose documentation has the layout):
// the node's lower corner and quantization steps, its children's boxes as bytes, and where their
// nodes and triangles start.
struct WideNode {
    a: vec4<u32>,
    b: vec4<u32>,
    c: vec4<u32>,
}

const NO_HIT: u32 = 0xffffffffu;
const STACK_SIZE: u32 = 96u;

// The BVH walk's stack: the entries still to visit and the distances at which the ray enters them
// (one popped behind the nearest hit so far is skipped). Private to the invocation rather than local
// to `trace_ray`: WGSL zero-initializes a function's variables on every call, which for these two
// arrays is 192 stores a ray, made lane by lane on CPU drivers (living-room rendered 1.4× as fast
// without them); a private variable is initialized once per invocation, and the walk reads no entry
// above `sp`, so what an earlier ray left there does not matter.
var<private> stack: array<u32, STACK_SIZE>;
var<private> stack_t: array<f32, STACK_SIZE>;

// Entry distance of the ray into the box [lo, hi], or T_MAX when it misses within t_max.
fn enter(lo: vec3<f32>, hi: vec3<f32>, o: vec3<f32>, inv_d: vec3<f32>, t_max: f32) -> f32 {
    let t0 = (lo - o) * inv_d;
    let t1 = (hi - o) * inv_d;
    let near = max(max(min(t0.x, t1.x), min(t0.y, t1.y)), max(min(t0.z, t1.z), 0.0));
    let far = min(min(max(t0.x, t1.x), max(t0.y, t1.y)), min(max(t0.z, t1.z), t_max));
    return select(T_MAX, near, near <= far);
}

// Byte c of each of the three words, as a vector.
fn bytes_at(x: u32, y: u32, z: u32, c: u32) -> vec3<f32> {
    return vec3<f32>(vec3<u32>(x >> (8u * c), y >> (8u * c), z >> (8u * c)) & vec3<u32>(0xffu));
}

// Child c of a wide node: its entry distance (T_MAX for a miss or an empty slot) and its stack
// entry (index << 3 | kind: 1-4 a leaf of that many triangles, 7 an interior node). `next` holds the
// next interior child's node and the next leaf's first triangle, and advances past this child.
struct Child {
    t: f32,
    entry: u32,
}

const KIND_INTERIOR: u32 = 7u;
const INDEX_MASK: u32 = 0x3ffffffu;

fn wide_child(n: WideNode, corner: vec3<f32>, step: vec3<f32>, c: u32, kind: u32, next: ptr<function, vec2<u32>>, o: vec3<f32>, inv_d: vec3<f32>, t_max: f32) -> Child {
    let lo = corner + bytes_at(n.b.x, n.b.y, n.b.z, c) * step;
    let hi = corner + bytes_at(n.b.w, n.c.x, n.c.y, c) * step;
    let t = enter(lo, hi, o, inv_d, t_max);
    var entry = 0u;
    if kind == KIND_INTERIOR {
        entry = ((*next).x << 3u) | KIND_INTERIOR;
        (*next).x += 1u;
    } else {
        entry = ((*next).y << 3u) | kind;
        (*next).y += kind;
    }
    return Child(select(t, T_MAX, kind == 0u), entry);
}

// Orders two children by distance.
fn order(a: ptr<function, Child>, b: ptr<function, Child>) {
    if (*b).t < (*a).t {
        let t = *a;
        *a = *b;
        *b = t;
    }
}

// The reciprocal of a ray direction for the BVH's slab tests: tiny components are replaced by ±1e-30 so that
// their reciprocals stay finite.
fn inverse_direction(d: vec3<f32>) -> vec3<f32> {
    let tiny = select(vec3<f32>(-1e-30), vec3<f32>(1e-30), d >= vec3<f32>(0.0));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(1e-30));
}

// Möller–Trumbore; updates `hit` when triangle i (corner p0, edges e1 and e2) is nearer. One
// branch at the end: every condition is an acceptance test, so NaNs from a near-zero determinant
// reject. (On CPU drivers both sides of a branch run under a mask: early exits cost, not save.)
// Returns whether it was; the caller sets the triangle's other fields of `hit`.
fn test_triangle_at(i: u32, p0: vec3<f32>, e1: vec3<f32>, e2: vec3<f32>, o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) -> bool {
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    let inv = 1.0 / det;
    let tv = o - p0;
    let u = dot(tv, pv) * inv;
    let qv = cross(tv, e1);
    let v = dot(d, qv) * inv;
    let t = dot(e2, qv) * inv;
    let nearer = abs(det) >= 1e-20 && u >= 0.0 && u <= 1.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 && t < (*hit).t;
    if nearer {
        (*hit).t = t;
        (*hit).tri = i;
        (*hit).u = u;
        (*hit).v = v;
    }
    return nearer;
}

// Slot i of the buffer: a triangle, or the analytic shape its e2.w names (shapes.wgsl). A triangle
// loads only its corner and edges here (nine words per SIMD lane, which CPU drivers load one lane at
// a time): its material, normal and density are loaded once for the nearest hit, `finish_hit`.
fn test_triangle(i: u32, o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {
    if HAS_SHAPES {
        let tag = bitcast<u32>(tris[i].e2.w);
        if tag != 0u {
            test_shape(i, tag - 1u, bitcast<u32>(tris[i].p0.w), tris[i].e1.w, o, d, hit);
            return;
        }
    }
    if test_triangle_at(i, tris[i].p0.xyz, tris[i].e1.xyz, tris[i].e2.xyz, o, d, hit) {
        (*hit).shape = NO_SHAPE;
    }
}

// The material, geometric normal and density of a triangle `test_triangle` found nearest.
fn finish_hit(hit: ptr<function, Hit>) {
    if (*hit).tri != NO_HIT && (*hit).shape == NO_SHAPE {
        let tri = tris[(*hit).tri];
        (*hit).mat = bitcast<u32>(tri.p0.w);
        (*hit).ng = cross(tri.e1.xyz, tri.e2.xyz);
        (*hit).area_pdf = tri.e1.w;
    }
}

// What `pop` returns when no entry is left: a leaf of no triangles, which no child's entry is.
const WALK_END: u32 = 0u;

// Pops the nearest stacked entry that the ray enters before `t` (the nearest hit so far), skipping those
// behind it, or WALK_END when none is left.
fn pop(sp: ptr<function, u32>, t: f32) -> u32 {
    while *sp > 0u {
        *sp -= 1u;
        if stack_t[*sp] < t {
            return stack[*sp];
        }
    }
    return WALK_END;
}

// The nearest hit with t in (0, t_max); with `any`, the BVH walk returns the first hit it finds
// (the flat scan finds the nearest either way).
fn trace_ray(o: vec3<f32>, d: vec3<f32>, t_max: f32, any: bool) -> Hit {
    var hit = Hit(t_max, NO_HIT, 0.0, 0.0, 0u, vec3<f32>(0.0), 0.0, NO_SHAPE);
    if params.tri_count == 0u {
        return hit;
    }
    if FLAT_SCAN {
        scan_triangles(o, d, &hit);
        return hit;
    }
    let inv_d = inverse_direction(d);
    // The stack's height (`stack`, `stack_t`).
    var sp = 0u;
    var entry = KIND_INTERIOR;
    // While-while traversal (Aila and Laine 2009): each lane descends through interior nodes until it
    // reaches a leaf, then the lanes at leaves test their triangles. On CPU drivers a branch runs both
    // sides under a mask and only a loop's back edge skips work, so a step that did both an interior
    // node and a leaf paid for both in every lane.
    loop {
        loop {
            if (entry & 7u) != KIND_INTERIOR {
                break;
            }
            let n = nodes[entry >> 3u];
            let corner = bitcast<vec3<f32>>(n.a.xyz);
            let step = bitcast<vec3<f32>>((vec3<u32>(n.a.w, n.a.w >> 8u, n.a.w >> 16u) & vec3<u32>(0xffu)) << vec3<u32>(23u));
            var next = vec2<u32>(n.c.z & INDEX_MASK, n.c.w & INDEX_MASK);
            var c0 = wide_child(n, corner, step, 0u, (n.c.z >> 26u) & 7u, &next, o, inv_d, hit.t);
            var c1 = wide_child(n, corner, step, 1u, n.c.z >> 29u, &next, o, inv_d, hit.t);
            var c2 = wide_child(n, corner, step, 2u, (n.c.w >> 26u) & 7u, &next, o, inv_d, hit.t);
            var c3 = wide_child(n, corner, step, 3u, n.c.w >> 29u, &next, o, inv_d, hit.t);
            order(&c0, &c1);
            order(&c2, &c3);
            order(&c0, &c2);
            // c0 is the nearest child now. A shadow ray needs no more order: it stops at any hit (`any` is a
            // constant in each of `intersect` and `occluded`, so this is compiled in or out).
            if !any {
                order(&c1, &c3);
                order(&c1, &c2);
            }
            if c0.t < T_MAX {
                if c3.t < T_MAX {
                    stack[sp] = c3.entry;
                    stack_t[sp] = c3.t;
                    sp += 1u;
                }
                if c2.t < T_MAX {
                    stack[sp] = c2.entry;
                    stack_t[sp] = c2.t;
                    sp += 1u;
                }
                if c1.t < T_MAX {
                    stack[sp] = c1.entry;
                    stack_t[sp] = c1.t;
                    sp += 1u;
                }
                entry = c0.entry;
            } else {
                entry = pop(&sp, hit.t);
            }
        }
        if entry == WALK_END {
            break;
        }
        let first = entry >> 3u;
        let kind = entry & 7u;
        for (var k = first; k < first + kind; k++) {
            test_triangle(k, o, d, &hit);
        }
        if any && hit.tri != NO_HIT {
            return hit;
        }
        entry = pop(&sp, hit.t);
        if entry == WALK_END {
            break;
        }
    }
    if !any {
        finish_hit(&hit);
    }
    return hit;
}

fn intersect(o: vec3<f32>, d: vec3<f32>, t_max: f32) -> Hit {
    return trace_ray(o, d, t_max, false);
}

fn occluded(o: vec3<f32>, d: vec3<f32>, t_max: f32) -> bool {
    return trace_ray(o, d, t_max, true).tri != NO_HIT;
}

// Moves a ray origin off the surface, to the side of `n` that `d` points to.
fn offset_origin(p: vec3<f32>, n: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    let scale = 1e-4 * max(1.0, max(abs(p.x), max(abs(p.y), abs(p.z))));
    return p + n * select(-scale, scale, dot(n, d) > 0.0);
}

// An orthonormal basis around unit n (Duff et al. 2017).
fn basis(n: vec3<f32>) -> mat3x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bt = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return mat3x3<f32>(t, bt, n);
}

fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    return a2 / (a2 + b * b);
}

// A light slot: a triangle's corner and edges, the density per unit area of picking a point on
// it, its emitted radiance, and the analytic shape it is (NO_SHAPE for a triangle).
struct LightTri {
    p0: vec3<f32>,
    e1: vec3<f32>,
    e2: vec3<f32>,
    area_pdf: f32,
    emission: vec3<f32>,
    shape: u32,
    // The shape's record (shapes.wgsl) when `shape` is not NO_SHAPE: written in with the lights as
    // literals, where loading it took a gather per lane of every bounce's light sample.
    record: Shape,
}

struct Sample {
    radiance: vec3<f32>,
    albedo: vec3<f32>,
    diffuse: vec3<f32>,
    specular: vec3<f32>,
    normal: vec3<f32>,
}

// Albedo, diffuse (k_d) and specular (k_s) features of a material at its first non-delta hit.
// Diffuse: k_d = reflectance (textured: the texture's value), k_s = 0. Rough conductor: k_d = 0,
// k_s = specular reflectance × Fresnel at normal incidence. Plastic (smooth or rough): k_d =
// diffuse reflectance, k_s = specular reflectance × the coat's Fresnel at normal incidence.
// Rough dielectric: k_d = 0, k_s = mean of the specular reflectance and transmittance.
// Albedo = min(k_d + k_s, 1). A ray that escapes to the environment writes 0 to every feature.
fn features(m: Material) -> mat2x3<f32> {
    let kind = mat_kind(m);
    if kind == KIND_DIFFUSE {
        return mat2x3<f32>(m.a.xyz, vec3<f32>(0.0));
    }
    if HAS_ROUGH_CONDUCTOR && kind == KIND_CONDUCTOR {
        return mat2x3<f32>(vec3<f32>(0.0), m.a.xyz * fresnel_conductor(1.0, m.c.xyz, m.d.xyz));
    }
    if (HAS_PLASTIC || HAS_ROUGH_PLASTIC) && kind == KIND_PLASTIC {
        return mat2x3<f32>(m.a.xyz, m.b.xyz * fresnel_dielectric(1.0, m.b.w).r);
    }
    if HAS_ROUGH_DIELECTRIC && kind == KIND_DIELECTRIC {
        // Rough glass (smooth glass is followed, never a feature): its reflection and
        // transmission tints, averaged.
        return mat2x3<f32>(vec3<f32>(0.0), 0.5 * (m.a.xyz + m.b.xyz));
    }
    return mat2x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0));
}

// One path's state between bounces.
struct PathState {
    o: vec3<f32>,
    d: vec3<f32>,
    throughput: vec3<f32>,
    // Solid-angle pdf of the BSDF sample that produced `d`, and whether it was a delta lobe
    // (the camera ray counts as one: emitters it sees get full weight).
    prev_pdf: f32,
    prev_delta: bool,
    features_done: bool,
    depth: u32,
    out: Sample,
}

// Maps u in [0, 1) to [-1, 1] with density 1 − |x| (inverting the tent's distribution function).
fn tent(u: f32) -> f32 {
    return select(1.0 - sqrt(2.0 - 2.0 * u), sqrt(2.0 * u) - 1.0, u < 0.5);
}

// A sample in units of σ from Mitsuba's windowed Gaussian, density ∝ max(0, exp(−x²/2) − exp(−8))
// on [−4, 4], by rejection: a normal from u and a second number (Box–Muller), redrawn until it
// lies in the window, kept with probability (exp(−x²/2) − exp(−8)) / exp(−x²/2) (99.9 % on average).
fn windowed_normal(u: f32) -> f32 {
    var a = u;
    var x = 0.0;
    loop {
        x = sqrt(-2.0 * log(1.0 - a)) * cos(2.0 * PI * rand());
        if abs(x) <= 4.0 && rand() * exp(-0.5 * x * x) >= 3.3546262e-4 {
            break;
        }
        a = rand();
    }
    return x;
}

// A position along one image axis (in pixels) for pixel `pixel` of `size`, drawn in proportion to
// the pixel filter from u and, where needed, more random numbers (filter importance sampling: every
// sample weighs the same). Box: uniform in the pixel. Tent and gaussian: around the pixel's centre,
// redrawn while outside the image, which truncates the filter at the image's border as Mitsuba's
// film does (it takes no samples beyond its border and normalizes each pixel by the weight inside).
fn filter_position(u: f32, pixel: u32, size: u32) -> f32 {
    if !HAS_WIDE_FILTER || params.filter_kind == FILTER_BOX {
        return f32(pixel) + u;
    }
    var a = u;
    var x = 0.0;
    loop {
        var offset = 0.0;
        if params.filter_kind == FILTER_TENT {
            offset = tent(a);
        } else {
            offset = windowed_normal(a);
        }
        x = f32(pixel) + 0.5 + params.filter_width * offset;
        if x >= 0.0 && x < f32(size) {
            break;
        }
        a = rand();
    }
    return x;
}

// Seeds the random stream of (pixel, sample index, seed) and starts that sample's camera ray.
fn start_path(pixel: vec2<u32>, pixel_index: u32, sample_index: u32) -> PathState {
    rng_state = pcg(pixel_index ^ pcg(sample_index ^ pcg(params.seed_lo ^ pcg(params.seed_hi))));
    // A point drawn from the pixel's filter, separably, from the pixel's sequence (its scramble one
    // pair of words per pixel and seed, the same for all its samples) or from the path's stream.
    // Row 0 is the top of the image.
    var u: vec2<f32>;
    if params.pixel_sampler == PIXEL_INDEPENDENT {
        u = vec2<f32>(rand(), rand());
    } else {
        let pixel_seed = pcg(pixel_index ^ pcg(params.seed_lo ^ pcg(params.seed_hi ^ 0x9e3779b9u)));
        u = pixel_point(sample_index, vec2<u32>(pcg(pixel_seed), pcg(pixel_seed ^ 0x85ebca6bu)));
    }
    let fx = filter_position(u.x, pixel.x, params.width) / f32(params.width);
    let fy = filter_position(u.y, pixel.y, params.height) / f32(params.height);
    let d = normalize(params.forward.xyz + (2.0 * fx - 1.0) * params.right.xyz + (1.0 - 2.0 * fy) * params.up.xyz);
    let zero = vec3<f32>(0.0);
    return PathState(params.origin.xyz, d, vec3<f32>(1.0), 0.0, true, false, 0u, Sample(zero, zero, zero, zero, zero));
}

// Traces the path's next segment and shades its hit; false when the path has ended.
fn bounce(st: ptr<function, PathState>) -> bool {
    let o = (*st).o;
    let d = (*st).d;
    let throughput = (*st).throughput;
    let prev_pdf = (*st).prev_pdf;
    let prev_delta = (*st).prev_delta;
    let depth = (*st).depth;
    var hit = intersect(o, d, T_MAX);
    if hit.tri == NO_HIT {
        // The environment, weighted against sampling it.
        if HAS_ENV && env.kind != ENV_NONE {
            var weight = 1.0;
            if !prev_delta {
                weight = power_heuristic(prev_pdf, env.radiance.w * env_pdf(d));
            }
            (*st).out.radiance += throughput * env_eval(d) * weight;
        }
        return false;
    }
    let p = o + d * hit.t;
    // An analytic shape's exact normal (its shading normal too) and texture coordinates.
    let on_shape = HAS_SHAPES && hit.shape != NO_SHAPE;
    var uv = vec2<f32>(0.0);
    if on_shape {
        let surface = shape_surface(hit.shape, p);
        hit.ng = surface.n;
        uv = surface.uv;
    }
    let ng = normalize(hit.ng);
    let front = dot(ng, d) < 0.0;
    var ns = ng;
    var mat = material(hit.mat);
    if (HAS_SHADING_NORMALS || HAS_TEXTURES) && !on_shape {
        let nr = normals[hit.tri];
        let w = 1.0 - hit.u - hit.v;
        if nr.n0.w > 0.5 {
            ns = normalize(w * nr.n0.xyz + hit.u * nr.n1.xyz + hit.v * nr.n2.xyz);
            // Keep the shading normal on the geometric front side.
            if dot(ns, ng) < 0.0 {
                ns = -ns;
            }
        }
        uv = w * nr.uv01.xy + hit.u * nr.uv01.zw + hit.v * nr.uv2.xy;
    }
    let tex = bitcast<u32>(mat.e.x);
    if HAS_TEXTURES && tex != NO_TEXTURE {
        mat.a = vec4<f32>(texture_lookup(tex, bitcast<u32>(mat.e.w), uv), mat.a.w);
    }
    let delta = mat_is_delta(mat);

    if !(*st).features_done && !delta {
        let f = features(mat);
        (*st).out.diffuse = f[0];
        (*st).out.specular = f[1];
        (*st).out.albedo = min(f[0] + f[1], vec3<f32>(1.0));
        (*st).out.normal = select(-ns, ns, front);
        (*st).features_done = true;
    }

    // Emission reached by the camera or by BSDF sampling, weighted against light sampling.
    if mat.emission.w > 0.5 && front {
        var weight = 1.0;
        if !prev_delta {
            var light_pdf = hit.area_pdf * hit.t * hit.t / dot(ng, -d);
            if on_shape {
                light_pdf = shape_light_pdf(shape_at(hit.shape), hit.area_pdf, o, d, hit.t, ng);
            }
            weight = power_heuristic(prev_pdf, (1.0 - env.radiance.w) * light_pdf);
        }
        (*st).out.radiance += throughput * mat.emission.xyz * weight;
    }

    let kind = mat_kind(mat);
    let one_sided = (mat_flags(mat) & FLAG_TWO_SIDED) == 0u && kind != KIND_DIELECTRIC && kind != KIND_THIN_DIELECTRIC;
    if depth + 1u >= params.max_depth || (one_sided && !front) {
        return false;
    }
    let frame = basis(ns);
    let to_local = transpose(frame);
    let wo = to_local * -d;

    // Next-event estimation: the environment with probability env_radiance.w, otherwise
    // a point on a triangle light picked by power.
    let env_pick = select(0.0, env.radiance.w, HAS_ENV);
    if (params.light_count > 0u || env_pick > 0.0) && !delta {
        var wi = vec3<f32>(0.0);
        var light_pdf = 0.0;
        var radiance = vec3<f32>(0.0);
        var lp = vec3<f32>(0.0);
        var to_env = true;
        let pick_env = rand() < env_pick;
        if !HAS_LIGHTS || pick_env {
            let es = env_sample(vec4<f32>(rand(), rand(), rand(), rand()));
            wi = es.d;
            light_pdf = env_pick * es.pdf;
            radiance = es.radiance;
        } else {
            let lt = light_triangle(rand());
            var a = rand();
            var b = rand();
            var lng = vec3<f32>(0.0);
            let on_light_shape = HAS_SHAPES && (LIGHT_KINDS & LIGHT_SHAPES) != 0u && lt.shape != NO_SHAPE;
            if on_light_shape {
                let ls = shape_light_sample(lt.record, p, vec2<f32>(a, b));
                lp = ls.q;
                lng = ls.n;
            } else if has_light(LIGHT_TRIANGLES) {
                if a + b > 1.0 {
                    a = 1.0 - a;
                    b = 1.0 - b;
                }
                lp = lt.p0 + a * lt.e1 + b * lt.e2;
                lng = normalize(cross(lt.e1, lt.e2));
            }
            to_env = false;
            let to_light = lp - p;
            let dist2 = dot(to_light, to_light);
            let dist = sqrt(dist2);
            wi = to_light / dist;
            let cos_light = dot(lng, -wi);
            if cos_light > 0.0 {
                var pdf = lt.area_pdf * dist2 / cos_light;
                if on_light_shape {
                    pdf = shape_light_pdf(lt.record, lt.area_pdf, p, wi, dist, lng);
                }
                light_pdf = (1.0 - env_pick) * pdf;
                radiance = lt.emission;
            }
        }
        let wi_local = to_local * wi;
        // The shading and geometric normals must agree on the side wi leaves from.
        if light_pdf > 0.0 && dot(ng, wi) * wi_local.z > 0.0 {
            let fp = bsdf_eval_pdf(mat, wo, wi_local);
            let f = fp.xyz;
            if any(f > vec3<f32>(0.0)) && any(radiance > vec3<f32>(0.0)) {
                let origin = offset_origin(p, ng, wi);
                // Shadow rays to a triangle light end just short of it.
                var shadow_d = wi;
                var t_max = T_MAX;
                if !to_env {
                    shadow_d = normalize(lp - origin);
                    t_max = length(lp - origin) * (1.0 - 1e-4);
                }
                if !occluded(origin, shadow_d, t_max) {
                    let weight = power_heuristic(light_pdf, fp.w);
                    (*st).out.radiance += throughput * f * radiance * weight / light_pdf;
                }
            }
        }
    }

    // BSDF sampling.
    let s = bsdf_sample(mat, wo, vec2<f32>(rand(), rand()), rand());
    if !s.valid {
        return false;
    }
    let wi = frame * s.wi;
    if dot(ng, wi) * s.wi.z <= 0.0 {
        return false;
    }
    var next = throughput * s.weight;
    let next_depth = depth + 1u;

    if next_depth >= RR_DEPTH {
        let q = min(max(next.x, max(next.y, next.z)), 0.95);
        if rand() >= q {
            return false;
        }
        next /= q;
    }
    if max(next.x, max(next.y, next.z)) <= 0.0 {
        return false;
    }
    (*st).throughput = next;
    (*st).prev_pdf = s.pdf;
    (*st).prev_delta = s.delta;
    (*st).depth = next_depth;
    (*st).o = offset_origin(p, ng, wi);
    (*st).d = normalize(wi);
    return true;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let pixel_index = gid.y * params.width + gid.x;
    let base = pixel_index * ACCUM_STRIDE;
    var acc: array<f32, 19>;
    for (var k = 0u; k < ACCUM_STRIDE; k++) {
        acc[k] = accum[base + k];
    }
    // Path regeneration: when a path ends, the invocation starts its next sample at once, so
    // the SIMD lanes that run neighbouring pixels together (8 per vector on lavapipe) stay busy
    // until all of their samples are done instead of waiting for the longest path of each sample.
    var done = 0u;
    // This dispatch's beauty samples, shifted by its first one: sums of the deviations and of their
    // squares, from which its mean and squared deviations follow without the cancellation of
    // E[x²] − E[x]² (exactly 0 for a constant pixel at any spp).
    var shift = vec3<f32>(0.0);
    var dev = vec3<f32>(0.0);
    var dev2 = vec3<f32>(0.0);
    var st = start_path(gid.xy, pixel_index, params.sample_offset);
    loop {
        if bounce(&st) {
            continue;
        }
        // A non-finite sample would poison the pixel: it is discarded and counted, and the
        // host reports the count.
        let r = st.out;
        var c = r.radiance;
        if !(all(c == c) && all(abs(c) <= vec3<f32>(3.0e38))) {
            c = vec3<f32>(0.0);
            acc[18] += 1.0;
        }
        if done == 0u {
            shift = c;
        }
        let d = c - shift;
        dev += d;
        dev2 += d * d;
        acc[6] += r.albedo.x; acc[7] += r.albedo.y; acc[8] += r.albedo.z;
        acc[9] += r.diffuse.x; acc[10] += r.diffuse.y; acc[11] += r.diffuse.z;
        acc[12] += r.specular.x; acc[13] += r.specular.y; acc[14] += r.specular.z;
        acc[15] += r.normal.x; acc[16] += r.normal.y; acc[17] += r.normal.z;
        done += 1u;
        if done >= params.samples_per_dispatch {
            break;
        }
        st = start_path(gid.xy, pixel_index, params.sample_offset + done);
    }
    // Merge this dispatch's samples into those before it (Chan, Golub & LeVeque's pairwise update):
    // every pixel has had `sample_offset` samples before this dispatch.
    let nb = f32(done);
    let mean_b = shift + dev / nb;
    let m2_b = max(dev2 - dev * dev / nb, vec3<f32>(0.0));
    let na = f32(params.sample_offset);
    let mean_a = vec3<f32>(acc[0], acc[1], acc[2]);
    let delta = mean_b - mean_a;
    let mean = mean_a + delta * (nb / (na + nb));
    let m2 = vec3<f32>(acc[3], acc[4], acc[5]) + m2_b + delta * delta * (na * nb / (na + nb));
    acc[0] = mean.x; acc[1] = mean.y; acc[2] = mean.z;
    acc[3] = m2.x; acc[4] = m2.y; acc[5] = m2.z;
    for (var k = 0u; k < ACCUM_STRIDE; k++) {
        accum[base + k] = acc[k];
    }
}
