use glam::Vec3;

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

/// Image size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Film {
    pub width: u32,
    pub height: u32,
}

/// A surface's scattering model. A closed set: new models are new variants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian reflection, one-sided like Mitsuba's `diffuse`: black from behind.
    Diffuse { reflectance: Vec3 },
}

impl Material {
    /// The diffuse reflectance used as the albedo feature.
    pub fn albedo(&self) -> Vec3 {
        match *self {
            Material::Diffuse { reflectance } => reflectance,
        }
    }
}

/// A triangle mesh in world space with one material.
///
/// The front of a triangle is the side its counter-clockwise winding faces
/// (`(p1 - p0) × (p2 - p0)`); one-sided BSDFs and emitters act only there.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals; `None` means flat (geometric) normals.
    pub normals: Option<Vec<Vec3>>,
    pub indices: Vec<[u32; 3]>,
    pub material: Material,
    /// Radiance emitted from the front side, if the mesh is an area light.
    pub emission: Option<Vec3>,
}

impl Mesh {
    /// Area of triangle `i`.
    pub fn triangle_area(&self, i: usize) -> f32 {
        let [a, b, c] = self.indices[i].map(|k| self.positions[k as usize]);
        0.5 * (b - a).cross(c - a).length()
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
}

impl Scene {
    /// Loads a scene file; the format is chosen by extension (`.xml`: Mitsuba).
    pub fn load(path: &std::path::Path) -> Result<Scene, crate::SceneError> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("xml") => {
                let text = std::fs::read_to_string(path)
                    .map_err(|e| crate::SceneError::new(path, None, format!("cannot read scene file: {e}")))?;
                Scene::from_mitsuba_str(&text, path)
            }
            _ => Err(crate::SceneError::new(path, None, "unknown scene format: hush reads Mitsuba XML scenes (.xml)")),
        }
    }

    /// Number of triangles over all meshes.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
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
