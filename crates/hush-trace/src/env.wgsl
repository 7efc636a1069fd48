// Images and the environment (Mitsuba's `bitmap` texture, `constant` and `envmap` emitters),
// shared by the path tracer and the probe kernel.

// ---- textures ----

// An environment map's texel (upload.rs, `push_image`): one load of four words.
fn image_texel(base: u32, width: u32, x: u32, y: u32) -> vec3<f32> {
    return aux4[base + y * width + x].xyz;
}

// An integer-valued f modulo n, in [0, n). Computed in floating point: CPU drivers have no vector
// integer division and run `%` lane by lane. Exact while |f| and n are below 2^24 (f / n is then off
// by at most one after rounding, which the selections correct; n q is exact).
fn wrap(f: f32, n: u32) -> u32 {
    let m = f32(n);
    var r = f - m * floor(f / m);
    r = select(r, r - m, r >= m);
    r = select(r, r + m, r < 0.0);
    return min(u32(r), n - 1u);
}

// A material texture's texel: three halves in two words (upload.rs, `push_texture`), loaded at once.
fn texture_texel(base: u32, width: u32, x: u32, y: u32) -> vec3<f32> {
    let p = aux_pairs[(base >> 1u) + y * width + x];
    return vec3<f32>(unpack2x16float(p.x), unpack2x16float(p.y).x);
}

// Mitsuba's `bitmap` lookup: bilinear between texel centres, repeating outside [0, 1]²;
// (0, 0) is the top-left corner of the image.
// `size` is the texture's width | height << 16 (a material's e.w).
fn texture_lookup(base: u32, size: u32, uv: vec2<f32>) -> vec3<f32> {
    let w = size & 0xffffu;
    let h = size >> 16u;
    let pos = uv * vec2<f32>(f32(w), f32(h)) - 0.5;
    let f = floor(pos);
    let t = pos - f;
    let x0 = wrap(f.x, w);
    let y0 = wrap(f.y, h);
    let x1 = select(x0 + 1u, 0u, x0 + 1u == w);
    let y1 = select(y0 + 1u, 0u, y0 + 1u == h);
    let top = mix(texture_texel(base, w, x0, y0), texture_texel(base, w, x1, y0), t.x);
    let bottom = mix(texture_texel(base, w, x0, y1), texture_texel(base, w, x1, y1), t.x);
    return mix(top, bottom, t.y);
}

// The scene's environment (upload.rs, `GpuEnv`).
struct Env {
    // ENV_*; the offsets in `aux4` of the map's image and of its sampling table; its width | height << 16.
    kind: u32,
    image: u32,
    dist: u32,
    size: u32,
    // rgb: constant radiance or the map's scale; w: probability that next-event estimation
    // samples the environment rather than a triangle light.
    radiance: vec4<f32>,
    // Columns of the linear map from the environment's frame to the world, and of its inverse.
    to_world_x: vec4<f32>,
    to_world_y: vec4<f32>,
    to_world_z: vec4<f32>,
    to_local_x: vec4<f32>,
    to_local_y: vec4<f32>,
    to_local_z: vec4<f32>,
}

@group(0) @binding(8) var<uniform> env: Env;

// ---- environment (Mitsuba's `constant` and `envmap` emitters) ----

const ENV_NONE: u32 = 0u;
// Specialization: the environment may be a map. Without it the map's code is compiled out; a
// branch on `env.kind` alone leaves it in, and CPU drivers step through its loads lane by lane
// with every lane masked off.
override HAS_ENV_MAP: bool = true;
const ENV_CONSTANT: u32 = 1u;
const ENV_MAP: u32 = 2u;

fn env_to_local(d: vec3<f32>) -> vec3<f32> {
    return normalize(env.to_local_x.xyz * d.x + env.to_local_y.xyz * d.y + env.to_local_z.xyz * d.z);
}

fn env_to_world(d: vec3<f32>) -> vec3<f32> {
    return normalize(env.to_world_x.xyz * d.x + env.to_world_y.xyz * d.y + env.to_world_z.xyz * d.z);
}

// The map's interpolation cell of a local direction and the position inside it. Mitsuba's
// envmap: u = atan2(x, -z) / 2π shifted by half a texel, v = acos(y) / π; texel columns sit at
// u = (i + 1/2) / width (the first repeated after the last), rows at v = j / (height − 1).
struct EnvCell {
    cell: vec2<u32>,
    t: vec2<f32>,
    sin_theta: f32,
}

fn env_cell(local: vec3<f32>) -> EnvCell {
    let w = env.size & 0xffffu;
    let h = env.size >> 16u;
    var u = atan2(local.x, -local.z) * (0.5 * INV_PI) - 0.5 / f32(w);
    u -= floor(u);
    let v = acos(clamp(local.y, -1.0, 1.0)) * INV_PI;
    let pos = vec2<f32>(u * f32(w), v * f32(h - 1u));
    let cell = min(vec2<u32>(pos), vec2<u32>(w - 1u, h - 2u));
    let sin_theta = sqrt(max(local.x * local.x + local.z * local.z, 1e-14));
    return EnvCell(cell, pos - vec2<f32>(cell), sin_theta);
}

fn env_map_eval(c: EnvCell) -> vec3<f32> {
    let base = env.image;
    let w = env.size & 0xffffu;
    let x1 = select(c.cell.x + 1u, 0u, c.cell.x + 1u == w);
    let top = mix(image_texel(base, w, c.cell.x, c.cell.y), image_texel(base, w, x1, c.cell.y), c.t.x);
    let bottom = mix(image_texel(base, w, c.cell.x, c.cell.y + 1u), image_texel(base, w, x1, c.cell.y + 1u), c.t.x);
    return mix(top, bottom, c.t.y) * env.radiance.xyz;
}

// Radiance arriving along -d (d points away from the scene, world space).
fn env_eval(d: vec3<f32>) -> vec3<f32> {
    if !HAS_ENV_MAP || env.kind == ENV_CONSTANT {
        return env.radiance.xyz;
    }
    return env_map_eval(env_cell(env_to_local(d)));
}

// The map's sampling distribution over its interpolation cells, from `dist` in `aux4`: per cell
// (row-major, width × (height − 1)) the probability of keeping it when drawn uniformly, the cell
// that replaces it otherwise (bits), and its probability (Walker's alias method, upload.rs).
fn env_cell_prob(cell: u32) -> f32 {
    return aux4[env.dist + cell].z;
}

// Solid-angle density of env_sample (before the light-picking probability).
fn env_pdf(d: vec3<f32>) -> f32 {
    if !HAS_ENV_MAP || env.kind == ENV_CONSTANT {
        return 0.25 * INV_PI;
    }
    let c = env_cell(env_to_local(d));
    let w = env.size & 0xffffu;
    let ny = (env.size >> 16u) - 1u;
    let p = env_cell_prob(c.cell.y * w + c.cell.x) * f32(w * ny);
    return p / (2.0 * PI * PI * c.sin_theta);
}

struct EnvSample {
    d: vec3<f32>,
    pdf: f32,
    radiance: vec3<f32>,
}

// A direction toward the environment: uniform over the sphere for a constant one; for a map,
// a cell picked from the piecewise-constant distribution over its interpolation cells
// (luminance × sin θ; u.x and u.y by the alias method) and a uniform point inside it (u.z, u.w).
fn env_sample(u: vec4<f32>) -> EnvSample {
    if !HAS_ENV_MAP || env.kind == ENV_CONSTANT {
        let z = 1.0 - 2.0 * u.x;
        let r = sqrt(max(0.0, 1.0 - z * z));
        let phi = 2.0 * PI * u.y;
        return EnvSample(vec3<f32>(r * cos(phi), r * sin(phi), z), 0.25 * INV_PI, env.radiance.xyz);
    }
    let w = env.size & 0xffffu;
    let ny = (env.size >> 16u) - 1u;
    let n = w * ny;
    let drawn = min(u32(u.x * f32(n)), n - 1u);
    let entry = aux4[env.dist + drawn];
    let cell = select(bitcast<u32>(entry.y), drawn, u.y < entry.x);
    // cell / w and cell % w, by a floating-point quotient corrected to the exact one (CPU drivers run
    // integer division lane by lane).
    var row = u32((f32(cell) + 0.5) / f32(w));
    row = select(row, row - 1u, row * w > cell);
    row = select(row, row + 1u, (row + 1u) * w <= cell);
    let col = cell - row * w;
    let fx = u.z;
    let fy = u.w;
    let uu = (f32(col) + fx) / f32(w) + 0.5 / f32(w);
    let v = (f32(row) + fy) / f32(ny);
    let theta = PI * v;
    let phi = 2.0 * PI * uu;
    let st = sin(theta);
    let local = vec3<f32>(sin(phi) * st, cos(theta), -cos(phi) * st);
    let sin_theta = max(st, 1e-7);
    let pdf = env_cell_prob(cell) * f32(n) / (2.0 * PI * PI * sin_theta);
    let c = EnvCell(vec2<u32>(col, row), vec2<f32>(fx, fy), sin_theta);
    return EnvSample(env_to_world(local), pdf, env_map_eval(c));
}

