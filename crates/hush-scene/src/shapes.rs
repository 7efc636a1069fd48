//! Mitsuba's analytic shapes tessellated into triangle meshes (the tracer intersects the exact
//! shapes, [`crate::Analytic`]; a tessellation stands in where a placement has no exact form), transforms applied to meshes,
//! and the checks every mesh passes before it enters a [`crate::Scene`].
//!
//! Object-space definitions follow Mitsuba: `rectangle` is [-1, 1]² in the z = 0 plane facing
//! +z, `cube` is [-1, 1]³ facing outwards, `disk` is the unit disk in z = 0 facing +z, `sphere`
//! is centred at `center` with radius `radius`, facing outwards.
//!
//! **Areas.** The path tracer samples emitters by their triangles, so an emitter's power is its
//! radiance times the *tessellated* area, while Mitsuba uses the analytic area. A polygon
//! inscribed in a circle, or a polyhedron inscribed in a sphere, is smaller than the analytic
//! shape (by 0.16 % for the 64-gon, about 0.3 % for the 64 × 32 sphere), so the tessellations
//! here are scaled about their centre until their area equals the analytic one (πr² for a disk,
//! 4πr² for a sphere; exact to f32 rounding). Rectangles and cubes are exact anyway.

use glam::{Mat3, Mat4, Vec2, Vec3};

/// Segments around a sphere or disk; rings from pole to pole of a sphere. 64 × 32 gives 3,968
/// triangles per sphere, the count of the shared scenes' `generated/primitives.obj`.
pub(crate) const SEGMENTS: u32 = 64;
pub(crate) const RINGS: u32 = 32;

/// Geometry before it gets a material.
#[derive(Clone, Debug, Default)]
pub(crate) struct Geometry {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
}

pub(crate) fn rectangle() -> Geometry {
    let positions = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let uvs = positions.iter().map(|p| Vec2::new(p.x + 1.0, p.y + 1.0) * 0.5).collect();
    Geometry { positions, normals: Some(vec![Vec3::Z; 4]), uvs: Some(uvs), indices: vec![[0, 1, 2], [0, 2, 3]] }
}

/// Each face of the cube [-1, 1]³ as the map of the rectangle [-1, 1]² (z = 0, facing +z) onto it:
/// columns u, v, n = u × v and the translation n.
pub(crate) fn cube_face_frames() -> Vec<Mat4> {
    cube_axes()
        .into_iter()
        .map(|(n, u, v)| Mat4::from_cols(u.extend(0.0), v.extend(0.0), n.extend(0.0), n.extend(1.0)))
        .collect()
}

/// Each face's outward normal and its u and v axes.
fn cube_axes() -> [(Vec3, Vec3, Vec3); 6] {
    [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z].map(|n| {
        let u = if n.x.abs() > 0.5 { Vec3::Y } else { Vec3::X } * if n.max_element() > 0.0 { 1.0 } else { -1.0 };
        (n, u, n.cross(u))
    })
}

/// 24 vertices (4 per face, so each face is flat), 12 triangles.
pub(crate) fn cube() -> Geometry {
    let mut g = Geometry { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for (n, u, v) in cube_axes() {
        let base = g.positions.len() as u32;
        for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            g.positions.push(n + u * s + v * t);
            g.normals.as_mut().unwrap().push(n);
            g.uvs.as_mut().unwrap().push(Vec2::new(s + 1.0, t + 1.0) * 0.5);
        }
        g.indices.push([base, base + 1, base + 2]);
        g.indices.push([base, base + 2, base + 3]);
    }
    g
}

/// A fan of `SEGMENTS` triangles with the area of the unit disk. UVs are Mitsuba's polar
/// ones: (r, φ / 2π).
pub(crate) fn disk() -> Geometry {
    let n = SEGMENTS;
    let step = std::f64::consts::TAU / n as f64;
    // Area of the inscribed n-gon: n/2 · sin(2π/n); scale the rim to make it π.
    let r = (std::f64::consts::PI / (0.5 * n as f64 * step.sin())).sqrt();
    let mut g = Geometry { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    g.positions.push(Vec3::ZERO);
    g.uvs.as_mut().unwrap().push(Vec2::ZERO);
    for j in 0..=n {
        let phi = step * j as f64;
        g.positions.push(Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, 0.0));
        g.uvs.as_mut().unwrap().push(Vec2::new(1.0, j as f32 / n as f32));
    }
    g.normals = Some(vec![Vec3::Z; g.positions.len()]);
    g.indices = (0..n).map(|j| [0, j + 1, j + 2]).collect();
    g
}

/// A latitude-longitude sphere (pole on the z axis) with smooth normals and the analytic area
/// 4πr². UVs are Mitsuba's: (φ / 2π, θ / π).
pub(crate) fn sphere(center: Vec3, radius: f32) -> Geometry {
    let (n, m) = (SEGMENTS, RINGS);
    let dir = |i: u32, j: u32| {
        let theta = std::f64::consts::PI * i as f64 / m as f64;
        let phi = std::f64::consts::TAU * j as f64 / n as f64;
        [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
    };
    let idx = |i: u32, j: u32| i * (n + 1) + j;
    let mut indices = Vec::new();
    for i in 0..m {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if i + 1 < m {
                indices.push([a, b, c]);
            }
            if i > 0 {
                indices.push(if i + 1 < m { [a, c, d] } else { [a, b, d] });
            }
        }
    }
    // Area of the unit tessellation, in double precision, to scale it to 4π.
    let unit: Vec<[f64; 3]> = (0..=m).flat_map(|i| (0..=n).map(move |j| dir(i, j))).collect();
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let area: f64 = indices
        .iter()
        .map(|t| {
            let (p, q, r) = (unit[t[0] as usize], unit[t[1] as usize], unit[t[2] as usize]);
            let (e1, e2) = (sub(q, p), sub(r, p));
            let c = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
            0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
        })
        .sum();
    let scale = (4.0 * std::f64::consts::PI / area).sqrt() * radius as f64;
    let positions = unit
        .iter()
        .map(|d| center + Vec3::new((d[0] * scale) as f32, (d[1] * scale) as f32, (d[2] * scale) as f32))
        .collect();
    let normals = unit.iter().map(|d| Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)).collect();
    let uvs = (0..=m).flat_map(|i| (0..=n).map(move |j| Vec2::new(j as f32 / n as f32, i as f32 / m as f32))).collect();
    Geometry { positions, normals: Some(normals), uvs: Some(uvs), indices }
}

/// The open unit cylinder (radius 1 about the z axis, z from 0 to 1, no caps) as `SEGMENTS`
/// quads with smooth outward normals and the analytic area 2π. UVs are Mitsuba's: (φ / 2π, z).
pub(crate) fn cylinder() -> Geometry {
    let n = SEGMENTS;
    let step = std::f64::consts::TAU / n as f64;
    // The perimeter of the inscribed n-gon is 2n sin(π/n): scale the radius to make it 2π.
    let r = std::f64::consts::PI / (n as f64 * (step / 2.0).sin());
    let mut g = Geometry { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for j in 0..=n {
        let phi = step * j as f64;
        let (c, s) = (phi.cos() as f32, phi.sin() as f32);
        for z in [0.0, 1.0] {
            g.positions.push(Vec3::new(r as f32 * c, r as f32 * s, z));
            g.normals.as_mut().unwrap().push(Vec3::new(c, s, 0.0));
            g.uvs.as_mut().unwrap().push(Vec2::new(j as f32 / n as f32, z));
        }
    }
    for j in 0..n {
        let (a, b, c, d) = (2 * j, 2 * j + 2, 2 * j + 3, 2 * j + 1);
        g.indices.push([a, b, c]);
        g.indices.push([a, c, d]);
    }
    g
}

/// Two unit vectors that complete unit `n` to a right-handed orthonormal frame (s, t, n), as
/// Mitsuba's `coordinate_system` builds them (Duff et al. 2017), so that a cylinder's `p0`/`p1`
/// frame and with it its texture coordinates are Mitsuba's.
pub(crate) fn coordinate_system(n: Vec3) -> (Vec3, Vec3) {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(sign * n.x * n.x * a + 1.0, sign * b, -sign * n.x), Vec3::new(b, n.y * n.y * a + sign, -n.y))
}

impl Geometry {
    /// Applies `m` to positions and (by its inverse transpose) to normals. With
    /// `keep_orientation`, a mirroring `m` (negative determinant) also reverses the winding so
    /// the front stays on the side the transformed normals face, as for Mitsuba's analytic
    /// shapes; meshes from files keep their winding, as in Mitsuba.
    pub fn transform(&mut self, m: &Mat4, keep_orientation: bool) {
        if *m == Mat4::IDENTITY {
            return;
        }
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        let nm = Mat3::from_mat4(*m).inverse().transpose();
        if let Some(normals) = &mut self.normals {
            for n in normals.iter_mut() {
                *n = (nm * *n).normalize_or_zero();
            }
        }
        if keep_orientation && Mat3::from_mat4(*m).determinant() < 0.0 {
            for t in &mut self.indices {
                t.swap(1, 2);
            }
        }
    }

    /// Mitsuba's `flip_normals`: the back becomes the front.
    pub fn flip(&mut self) {
        for t in &mut self.indices {
            t.swap(1, 2);
        }
        if let Some(normals) = &mut self.normals {
            for n in normals.iter_mut() {
                *n = -*n;
            }
        }
    }

    /// Checks a mesh before it enters a scene: every position, normal and UV is finite (an
    /// error naming the vertex otherwise), and degenerate triangles (zero or non-finite area:
    /// they can never be hit) are dropped. Returns how many were dropped.
    pub fn check(&mut self) -> Result<usize, String> {
        if let Some(k) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {} is not finite ({}): fix or re-export the mesh", k + 1, self.positions[k]));
        }
        if let Some(normals) = &self.normals {
            if let Some(k) = normals.iter().position(|n| !n.is_finite()) {
                return Err(format!("the normal of vertex {} is not finite: fix or re-export the mesh", k + 1));
            }
            if normals.len() != self.positions.len() {
                return Err("normals and positions differ in number".into());
            }
        }
        if let Some(uvs) = &self.uvs
            && let Some(k) = uvs.iter().position(|n| !n.is_finite())
        {
            return Err(format!("the texture coordinate of vertex {} is not finite", k + 1));
        }
        let count = self.positions.len();
        if self.indices.iter().flatten().any(|&i| i as usize >= count) {
            return Err("a face index is out of range".into());
        }
        let before = self.indices.len();
        let positions = &self.positions;
        self.indices.retain(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            let area2 = (b - a).cross(c - a).length_squared();
            area2 > 0.0 && area2.is_finite()
        });
        Ok(before - self.indices.len())
    }
}
