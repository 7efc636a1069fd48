use std::path::PathBuf;

use glam::{Mat4, Vec2, Vec3};

/// A pinhole camera. `fov_y_deg` is the vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub origin: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
}

impl Camera {
    /// Unit forward, right and up vectors. Image +x is `right`, image +y (downwards rows) is `-up`.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.origin).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        (forward, right, up)
    }

    /// Checks that the camera spans a frame: distinct origin and target, `up` not parallel
    /// to the view direction, a field of view in (0, 180).
    pub fn validate(&self) -> Result<(), String> {
        let v = [self.origin, self.target, self.up];
        if v.iter().any(|x| !x.is_finite()) || !self.fov_y_deg.is_finite() {
            return Err("camera has a non-finite origin, target, up or fov".into());
        }
        let d = self.target - self.origin;
        if d.length() < 1e-12 {
            return Err("camera origin and target coincide".into());
        }
        if d.normalize().cross(self.up).length() < 1e-6 {
            return Err("camera up vector is parallel to the view direction".into());
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(format!("field of view {} is not in (0, 180) degrees", self.fov_y_deg));
        }
        Ok(())
    }
}

/// Image size in pixels and the pixel filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub filter: PixelFilter,
}

/// How a pixel weighs the radiance around it (Mitsuba's `rfilter`), in pixels from its centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PixelFilter {
    /// The pixel's square, uniformly.
    #[default]
    Box,
    /// `max(0, 1 − |x| / radius) · max(0, 1 − |y| / radius)`, normalized (Mitsuba's `tent`; radius 1 by
    /// default): neighbouring pixels share samples near their border.
    Tent { radius: f32 },
    /// `g(x) · g(y)` with `g(x) = max(0, exp(−x² / 2σ²) − exp(−8))`, zero beyond 4σ, normalized (Mitsuba's
    /// `gaussian`, the filter of a Mitsuba film that names none; σ = 0.5 by default).
    Gaussian { stddev: f32 },
}

impl PixelFilter {
    /// Mitsuba's filter when a film names none.
    pub const MITSUBA_DEFAULT: PixelFilter = PixelFilter::Gaussian { stddev: 0.5 };
}

/// Index of a [`Texture`] in [`Scene::textures`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TextureId(pub u32);

/// A reflectance: a constant linear RGB color or a texture looked up by the mesh's UVs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reflectance {
    Rgb(Vec3),
    Texture(TextureId),
}

impl From<Vec3> for Reflectance {
    fn from(v: Vec3) -> Self {
        Reflectance::Rgb(v)
    }
}

/// A decoded image texture: linear RGB, rows top to bottom, `width × height × 3` floats.
///
/// 8-bit images (PNG, JPEG) are taken as sRGB-encoded and converted to linear, as Mitsuba's
/// `bitmap` does by default (`raw = false`); float images (EXR) are kept as they are.
/// Texture coordinates follow Mitsuba: (0, 0) is the top-left corner of the image, u grows to
/// the right and v downwards (OBJ files store v upwards; their loader flips it, as Mitsuba's
/// `flip_tex_coords` does by default). Lookups repeat outside [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl Texture {
    /// The texel at column `x`, row `y` (row 0 at the top).
    pub fn texel(&self, x: u32, y: u32) -> Vec3 {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        Vec3::new(self.data[i], self.data[i + 1], self.data[i + 2])
    }

    /// The mean texel value (a stand-in color where a texture cannot be used).
    pub fn mean(&self) -> Vec3 {
        let mut sum = [0f64; 3];
        for px in self.data.chunks_exact(3) {
            for c in 0..3 {
                sum[c] += px[c] as f64;
            }
        }
        let n = (self.data.len() / 3).max(1) as f64;
        Vec3::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32)
    }
}

/// The microfacet normal distribution of a rough BSDF (Mitsuba's `distribution`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Microfacet {
    /// GGX (Trowbridge–Reitz); glTF's and OBJ's rough surfaces.
    #[default]
    Ggx,
    /// Beckmann: Mitsuba's default for its rough BSDFs.
    Beckmann,
}

/// The complex index of refraction of a conductor, per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ComplexIor {
    pub eta: Vec3,
    pub k: Vec3,
}

/// A surface's scattering model. A closed set: new models are new variants.
///
/// `alpha` is the microfacet roughness (Mitsuba's `alpha`, the root mean square slope) of the
/// `distribution`; `0` is a perfectly smooth surface (Mitsuba's `conductor`, `dielectric`,
/// `plastic`). `two_sided`
/// is Mitsuba's `twosided` wrapper (glTF's `doubleSided`): the back scatters like the front.
/// Without it, diffuse, conductor and plastic surfaces are black from behind. Dielectrics are
/// always two-sided: they separate an inside from an outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian reflection (`diffuse`).
    Diffuse { reflectance: Reflectance, two_sided: bool },
    /// A metal (`conductor`, `roughconductor`): Fresnel reflectance from `ior` times
    /// `specular_reflectance`; `ior: None` is Mitsuba's `material="none"`, a perfect mirror
    /// (Fresnel factor 1) tinted by `specular_reflectance`.
    Conductor {
        alpha: f32,
        distribution: Microfacet,
        ior: Option<ComplexIor>,
        specular_reflectance: Vec3,
        two_sided: bool,
    },
    /// Glass and liquids (`dielectric`, `roughdielectric`, `thindielectric`). `thin` is a
    /// sheet of zero thickness: light passes through without bending.
    Dielectric {
        alpha: f32,
        distribution: Microfacet,
        int_ior: f32,
        ext_ior: f32,
        thin: bool,
        specular_reflectance: Vec3,
        specular_transmittance: Vec3,
    },
    /// A diffuse base under a smooth or rough dielectric coating (`plastic`, `roughplastic`).
    /// `nonlinear` is Mitsuba's flag for the base's internal scattering model.
    Plastic {
        diffuse_reflectance: Reflectance,
        specular_reflectance: Vec3,
        alpha: f32,
        distribution: Microfacet,
        int_ior: f32,
        ext_ior: f32,
        nonlinear: bool,
        two_sided: bool,
    },
}

impl Material {
    /// Mitsuba's default BSDF: a diffuse one of reflectance 0.5, one-sided.
    pub const DEFAULT: Material =
        Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::splat(0.5)), two_sided: false };

    /// Mitsuba's plugin name for this material (`diffuse`, `roughconductor`, `thindielectric`, ...).
    pub fn kind(&self) -> &'static str {
        match *self {
            Material::Diffuse { .. } => "diffuse",
            Material::Conductor { alpha, .. } if alpha > 0.0 => "roughconductor",
            Material::Conductor { .. } => "conductor",
            Material::Dielectric { thin: true, .. } => "thindielectric",
            Material::Dielectric { alpha, .. } if alpha > 0.0 => "roughdielectric",
            Material::Dielectric { .. } => "dielectric",
            Material::Plastic { alpha, .. } if alpha > 0.0 => "roughplastic",
            Material::Plastic { .. } => "plastic",
        }
    }

    /// Whether the back side scatters like the front (always true for dielectrics).
    pub fn two_sided(&self) -> bool {
        match *self {
            Material::Diffuse { two_sided, .. }
            | Material::Conductor { two_sided, .. }
            | Material::Plastic { two_sided, .. } => two_sided,
            Material::Dielectric { .. } => true,
        }
    }

    /// The same material made two-sided (Mitsuba's `twosided` wrapper).
    pub fn with_two_sided(mut self, two: bool) -> Material {
        match &mut self {
            Material::Diffuse { two_sided, .. }
            | Material::Conductor { two_sided, .. }
            | Material::Plastic { two_sided, .. } => *two_sided = two,
            Material::Dielectric { .. } => {}
        }
        self
    }

    /// The texture this material reads, if any.
    pub fn texture(&self) -> Option<TextureId> {
        match *self {
            Material::Diffuse { reflectance: Reflectance::Texture(t), .. }
            | Material::Plastic { diffuse_reflectance: Reflectance::Texture(t), .. } => Some(t),
            _ => None,
        }
    }
}

/// Light arriving from infinitely far away, where rays leave the scene.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// Mitsuba's `constant` emitter: the same radiance from every direction.
    Constant { radiance: Vec3 },
    /// Mitsuba's `envmap`: an equirectangular (latitude-longitude) RGB image.
    ///
    /// Mitsuba 3's convention (`envmap.cpp`): in the emitter's local frame +y is up, and the
    /// image point (u, v) in [0, 1]² (v = 0 the top row) is the direction
    /// `(sin θ sin φ, cos θ, -sin θ cos φ)` with θ = π·v, φ = 2π·u; conversely
    /// u = atan2(d.x, -d.z) / 2π (mod 1), v = acos(d.y) / π. `to_world` maps that frame
    /// into the scene; `scale` multiplies the radiance.
    Map(EnvMap),
}

/// An equirectangular environment map: linear RGB pixels, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
    pub scale: f32,
    pub to_world: Mat4,
}

/// The object-space form of one of Mitsuba's analytic shapes (see [`Analytic`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ShapeKind {
    /// The unit sphere about the origin, facing outwards (Mitsuba's `sphere`, its `center` and
    /// `radius` folded into `to_world`).
    Sphere,
    /// The unit disk in the z = 0 plane, facing +z (`disk`).
    Disk,
    /// The square [-1, 1]² in the z = 0 plane, facing +z (`rectangle`).
    Rectangle,
    /// The open tube of radius 1 about the z axis from z = 0 to z = 1, facing outwards, without
    /// caps (`cylinder`, its `p0`, `p1` and `radius` folded into `to_world`).
    Cylinder,
    /// The cube [-1, 1]³, facing outwards (`cube`): six rectangles ([`Analytic::cube_faces`]), which
    /// a flat scan tests in about a quarter of the time of its twelve triangles (lavapipe: 1.9 ns a
    /// rectangle, 3.6 ns a triangle).
    Cube,
}

impl ShapeKind {
    /// Mitsuba's plugin name.
    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::Sphere => "sphere",
            ShapeKind::Disk => "disk",
            ShapeKind::Rectangle => "rectangle",
            ShapeKind::Cylinder => "cylinder",
            ShapeKind::Cube => "cube",
        }
    }
}

/// A shape the path tracer intersects exactly, with exact normals, texture coordinates, area and
/// light sampling, as Mitsuba does: its [`ShapeKind`] placed by `to_world`.
///
/// Only placements that keep the shape what its sampling assumes are analytic: a similarity for a
/// sphere (no shear, the same scale on every axis), the same scale on x and y with z
/// perpendicular to them for a cylinder; any affine map of a disk or rectangle. A loader
/// tessellates the others (an ellipsoid is a mesh), with a warning.
///
/// Texture coordinates follow Mitsuba: a sphere's are (φ / 2π, θ / π) about its local z axis, a
/// disk's (r, φ / 2π), a rectangle's ((x + 1) / 2, (y + 1) / 2), a cylinder's (φ / 2π, z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Analytic {
    pub kind: ShapeKind,
    /// From the shape's object space to the world.
    pub to_world: Mat4,
    /// The front (where one-sided BSDFs and emitters act) is the side opposite to the normal the
    /// object-space form has: Mitsuba's `flip_normals`, toggled for a sphere or cylinder whose
    /// `to_world` mirrors (as Mitsuba toggles it).
    pub flip_normals: bool,
}

impl Analytic {
    /// Whether `to_world` keeps `kind` analytic (see [`Analytic`]): a relative tolerance of 1e-4
    /// on lengths and angles.
    pub fn placement_is_exact(kind: ShapeKind, to_world: &Mat4) -> bool {
        let m = glam::Mat3::from_mat4(*to_world);
        if !m.is_finite() || m.determinant() == 0.0 {
            return false;
        }
        let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
        let same = |a: f32, b: f32| (a - b).abs() <= 1e-4 * a.max(b);
        let perpendicular = |a: Vec3, b: Vec3| a.dot(b).abs() <= 1e-4 * a.length() * b.length();
        match kind {
            ShapeKind::Disk | ShapeKind::Rectangle | ShapeKind::Cube => true,
            ShapeKind::Cylinder => {
                same(x.length(), y.length()) && perpendicular(x, y) && perpendicular(x, z) && perpendicular(y, z)
            }
            ShapeKind::Sphere => {
                same(x.length(), y.length())
                    && same(x.length(), z.length())
                    && perpendicular(x, y)
                    && perpendicular(x, z)
                    && perpendicular(y, z)
            }
        }
    }

    /// The sphere's centre and radius in the world (meaningful for a sphere only).
    pub fn sphere(&self) -> (Vec3, f32) {
        (self.to_world.transform_point3(Vec3::ZERO), self.to_world.transform_vector3(Vec3::X).length())
    }

    /// The exact surface area in the world.
    pub fn area(&self) -> f64 {
        let m = &self.to_world;
        let (x, y, z) = (m.transform_vector3(Vec3::X), m.transform_vector3(Vec3::Y), m.transform_vector3(Vec3::Z));
        let cross = x.as_dvec3().cross(y.as_dvec3()).length();
        match self.kind {
            ShapeKind::Sphere => 4.0 * std::f64::consts::PI * (x.length() as f64).powi(2),
            ShapeKind::Disk => std::f64::consts::PI * cross,
            ShapeKind::Rectangle => 4.0 * cross,
            ShapeKind::Cylinder => std::f64::consts::TAU * x.length() as f64 * z.length() as f64,
            ShapeKind::Cube => self.cube_faces().iter().map(Analytic::area).sum(),
        }
    }

    /// A cube's six faces as rectangles, in the order and with the texture coordinates of its
    /// tessellation (each face's u and v axes are the rectangle's x and y); empty for other shapes.
    pub fn cube_faces(&self) -> Vec<Analytic> {
        if self.kind != ShapeKind::Cube {
            return Vec::new();
        }
        crate::shapes::cube_face_frames()
            .into_iter()
            .map(|face| Analytic {
                kind: ShapeKind::Rectangle,
                to_world: self.to_world * face,
                flip_normals: self.flip_normals,
            })
            .collect()
    }

    /// Axis-aligned world bounds (min, max): exact for a sphere, the box of the transformed
    /// object-space bounds otherwise.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        if self.kind == ShapeKind::Sphere {
            let (c, r) = self.sphere();
            return (c - Vec3::splat(r), c + Vec3::splat(r));
        }
        let (z0, z1) = match self.kind {
            ShapeKind::Cylinder => (0.0, 1.0),
            ShapeKind::Cube => (-1.0, 1.0),
            _ => (0.0, 0.0),
        };
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for corner in 0..8 {
            let x = if corner & 1 == 0 { -1.0 } else { 1.0 };
            let y = if corner & 2 == 0 { -1.0 } else { 1.0 };
            let z = if corner & 4 == 0 { z0 } else { z1 };
            let p = self.to_world.transform_point3(Vec3::new(x, y, z));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (lo, hi)
    }
}

/// A triangle mesh in world space with one material, or one of Mitsuba's analytic shapes.
///
/// The front of a triangle is the side its counter-clockwise winding faces
/// (`(p1 - p0) × (p2 - p0)`); one-sided BSDFs and emitters act only there.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals; `None` means flat (geometric) normals.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates ((0, 0) = top-left of the image; see [`Texture`]).
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
    pub material: Material,
    /// Radiance emitted from the front side, if the mesh is an area light.
    pub emission: Option<Vec3>,
    /// The exact shape, when the mesh is one of Mitsuba's analytic shapes: the path tracer
    /// intersects and samples that, and the triangles above are its tessellation (bounds and
    /// whatever else needs triangles), facing the same way.
    pub analytic: Option<Analytic>,
}

impl Mesh {
    /// Area of triangle `i`.
    pub fn triangle_area(&self, i: usize) -> f32 {
        let [a, b, c] = self.indices[i].map(|k| self.positions[k as usize]);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Total surface area, summed in double precision.
    pub fn area(&self) -> f64 {
        (0..self.indices.len()).map(|i| self.triangle_area(i) as f64).sum()
    }
}

/// Everything the path tracer needs.
#[derive(Clone, Debug)]
pub struct Scene {
    pub camera: Camera,
    pub film: Film,
    /// Mitsuba's convention: 1 = emitters seen directly, 2 = direct light only, 8 = up to 7 bounces.
    pub max_depth: u32,
    /// The scene file's sample count, if it names one.
    pub spp: Option<u32>,
    pub meshes: Vec<Mesh>,
    /// Images referenced by [`Reflectance::Texture`], each loaded once.
    pub textures: Vec<Texture>,
    /// Light from where rays leave the scene, if any.
    pub environment: Option<Environment>,
    /// What the loader did not support and what it used instead, one line each
    /// (`file:line: ...`). Nothing is dropped without an entry here.
    pub warnings: Vec<String>,
}

impl Scene {
    /// Loads a scene file; the format is chosen by extension: `.xml` (Mitsuba 0.6, 2 or 3),
    /// `.obj` (Wavefront OBJ with its MTL materials), `.gltf`/`.glb` (glTF 2.0).
    pub fn load(path: &std::path::Path) -> Result<Scene, crate::SceneError> {
        let mut scene = Scene::load_format(path)?;
        let emits = scene.meshes.iter().any(|m| m.emission.is_some_and(|e| e.max_element() > 0.0));
        if !emits && scene.environment.is_none() {
            scene.warnings.push(format!(
                "{}: nothing emits light (no area light, emissive material or environment): every image of it is \
                 black; add an emitter",
                path.display()
            ));
        }
        Ok(scene)
    }

    fn load_format(path: &std::path::Path) -> Result<Scene, crate::SceneError> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("xml") => {
                let bytes = hush_io::read_limited_bare(path, crate::max_file_bytes())
                    .map_err(|e| crate::SceneError::new(path, None, format!("cannot read the scene file: {e}")))?;
                let text = String::from_utf8(bytes)
                    .map_err(|_| crate::SceneError::new(path, None, "the scene file is not UTF-8 text"))?;
                Scene::from_mitsuba_str(&text, path)
            }
            Some("obj") => crate::obj::load_obj_scene(path),
            Some("gltf" | "glb") => crate::gltf::load_gltf(path),
            _ => Err(crate::SceneError::new(
                path,
                None,
                "unknown scene format: hush reads Mitsuba XML (.xml), Wavefront OBJ (.obj) and glTF 2.0 (.gltf, .glb)",
            )),
        }
    }

    /// Number of triangles over all meshes (analytic shapes count their tessellation).
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }

    /// Number of triangles of the meshes that are not analytic shapes: those the tracer intersects.
    pub fn mesh_triangle_count(&self) -> usize {
        self.meshes.iter().filter(|m| m.analytic.is_none()).map(|m| m.indices.len()).sum()
    }

    /// Number of analytic shapes.
    pub fn analytic_count(&self) -> usize {
        self.meshes.iter().filter(|m| m.analytic.is_some()).count()
    }

    /// Axis-aligned bounds of all geometry (min, max).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in self.meshes.iter().flat_map(|m| m.positions.iter()) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        (lo, hi)
    }
}
