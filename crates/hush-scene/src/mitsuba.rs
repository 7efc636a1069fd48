//! The Mitsuba 3 XML subset of the shared scenes.
//!
//! Supported: `<integrator type="path">` (`max_depth`, `rr_depth`), `<sensor type="perspective">`
//! (`fov`, `fov_axis`, `near_clip`, `far_clip`, `to_world` with `lookat`, an `independent`
//! sampler, an `hdrfilm` with `width`, `height`, a `box` rfilter), `<bsdf type="diffuse">` with an
//! `rgb`/`float` reflectance (top level with `id`, or inline), `<shape type="obj">` (`filename`,
//! `face_normals`, a `ref` or inline BSDF, an `area` emitter with `radiance`). Anything else is
//! an error naming the element and its line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use roxmltree::{Document, Node};

use crate::{Camera, Film, Material, Scene, SceneError};

impl Scene {
    /// Parses Mitsuba XML text; `path` names the file in errors and anchors relative mesh paths.
    pub fn from_mitsuba_str(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let doc = Document::parse(text).map_err(|e| {
            let pos = e.pos();
            SceneError::new(path, Some(pos.row), format!("malformed XML: {e}"))
        })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Parser { path, doc: &doc, dir, bsdfs: HashMap::new() }.scene()
    }
}

struct Parser<'a, 'input> {
    path: &'a Path,
    doc: &'a Document<'input>,
    dir: PathBuf,
    bsdfs: HashMap<String, Material>,
}

/// Mitsuba's defaults for a sensor without the corresponding element.
const DEFAULT_WIDTH: u32 = 768;
const DEFAULT_HEIGHT: u32 = 576;

impl Parser<'_, '_> {
    fn err(&self, node: Node, msg: impl Into<String>) -> SceneError {
        let line = self.doc.text_pos_at(node.range().start).row;
        SceneError::new(self.path, Some(line), msg)
    }

    fn unsupported(&self, node: Node, context: &str) -> SceneError {
        let ty = node.attribute("type").map(|t| format!(" type=\"{t}\"")).unwrap_or_default();
        let name = node.attribute("name").map(|t| format!(" name=\"{t}\"")).unwrap_or_default();
        self.err(node, format!("unsupported element <{}{ty}{name}> in {context}", node.tag_name().name()))
    }

    fn elements<'n>(node: Node<'n, 'n>) -> impl Iterator<Item = Node<'n, 'n>> {
        node.children().filter(Node::is_element)
    }

    fn attr<'n>(&self, node: Node<'n, '_>, name: &str) -> Result<&'n str, SceneError> {
        node.attribute(name)
            .ok_or_else(|| self.err(node, format!("<{}> needs a '{name}' attribute", node.tag_name().name())))
    }

    fn float(&self, node: Node) -> Result<f32, SceneError> {
        let v = self.attr(node, "value")?;
        v.trim()
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.err(node, format!("'{v}' is not a finite number")))
    }

    fn int(&self, node: Node) -> Result<i64, SceneError> {
        let v = self.attr(node, "value")?;
        v.trim().parse::<i64>().map_err(|_| self.err(node, format!("'{v}' is not an integer")))
    }

    fn boolean(&self, node: Node) -> Result<bool, SceneError> {
        match self.attr(node, "value")?.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            v => Err(self.err(node, format!("'{v}' is not 'true' or 'false'"))),
        }
    }

    fn vec3(&self, node: Node, text: &str) -> Result<Vec3, SceneError> {
        let parts: Result<Vec<f32>, _> = text
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(str::parse::<f32>)
            .collect();
        match parts.as_deref() {
            Ok([x]) if x.is_finite() => Ok(Vec3::splat(*x)),
            Ok([x, y, z]) if [x, y, z].iter().all(|v| v.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
            _ => Err(self.err(node, format!("'{text}' is not one or three finite numbers"))),
        }
    }

    /// A colour given as `<rgb value="r, g, b"/>` or `<float value="x"/>`.
    fn color(&self, node: Node) -> Result<Vec3, SceneError> {
        match node.tag_name().name() {
            "rgb" | "float" => self.vec3(node, self.attr(node, "value")?),
            _ => Err(self.unsupported(node, "a colour (use <rgb> or <float>)")),
        }
    }

    fn scene(mut self) -> Result<Scene, SceneError> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "scene" {
            return Err(self.err(root, "the root element must be <scene>"));
        }
        let mut camera = None;
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT };
        let mut spp = None;
        let mut max_depth = u32::MAX;
        let mut meshes = Vec::new();
        for node in Self::elements(root) {
            match node.tag_name().name() {
                "integrator" => max_depth = self.integrator(node)?,
                "sensor" => {
                    let (c, f, s) = self.sensor(node)?;
                    camera = Some(c);
                    film = f;
                    spp = s;
                }
                "bsdf" => {
                    let id = self.attr(node, "id")?.to_string();
                    let material = self.bsdf(node)?;
                    self.bsdfs.insert(id, material);
                }
                "shape" => meshes.push(self.shape(node)?),
                _ => return Err(self.unsupported(node, "<scene>")),
            }
        }
        let camera = camera.ok_or_else(|| self.err(root, "the scene has no <sensor type=\"perspective\">"))?;
        camera.validate().map_err(|m| self.err(root, m))?;
        Ok(Scene { camera, film, max_depth, spp, meshes })
    }

    fn integrator(&self, node: Node) -> Result<u32, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "path" {
            return Err(self.unsupported(node, "<scene> (hush implements the 'path' integrator)"));
        }
        let mut max_depth = u32::MAX;
        for child in Self::elements(node) {
            match (child.tag_name().name(), child.attribute("name")) {
                ("integer", Some("max_depth")) => {
                    let d = self.int(child)?;
                    max_depth = match d {
                        -1 => u32::MAX,
                        d if d >= 1 => d.min(u32::MAX as i64) as u32,
                        _ => return Err(self.err(child, "max_depth must be -1 (unlimited) or at least 1")),
                    };
                }
                // Russian roulette's start changes variance, never the expected image.
                ("integer", Some("rr_depth")) => {
                    self.int(child)?;
                }
                _ => return Err(self.unsupported(child, "<integrator type=\"path\">")),
            }
        }
        Ok(max_depth)
    }

    fn sensor(&self, node: Node) -> Result<(Camera, Film, Option<u32>), SceneError> {
        if self.attr(node, "type")? != "perspective" {
            return Err(self.unsupported(node, "<scene> (hush has a perspective pinhole camera)"));
        }
        let mut fov = None;
        let mut fov_axis = "x".to_string();
        let mut lookat = None;
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT };
        let mut spp = None;
        for child in Self::elements(node) {
            match (child.tag_name().name(), child.attribute("name")) {
                ("float", Some("fov")) => fov = Some((self.float(child)?, child)),
                ("string", Some("fov_axis")) => fov_axis = self.attr(child, "value")?.to_string(),
                ("float", Some("near_clip" | "far_clip")) => {
                    self.float(child)?;
                }
                ("transform", Some("to_world")) => lookat = Some(self.lookat(child)?),
                ("sampler", _) => spp = self.sampler(child)?,
                ("film", _) => film = self.film(child)?,
                _ => return Err(self.unsupported(child, "<sensor>")),
            }
        }
        let (fov, fov_node) = fov.ok_or_else(|| self.err(node, "the sensor needs <float name=\"fov\">"))?;
        let (origin, target, up) =
            lookat.ok_or_else(|| self.err(node, "the sensor needs <transform name=\"to_world\"> with a <lookat>"))?;
        let (w, h) = (film.width as f32, film.height as f32);
        let half = (fov.to_radians() * 0.5).tan();
        // Convert the field of view along `fov_axis` to the vertical one.
        let tan_y = match fov_axis.as_str() {
            "x" => half * h / w,
            "y" => half,
            "smaller" if w < h => half * h / w,
            "smaller" => half,
            "larger" if w > h => half * h / w,
            "larger" => half,
            "diagonal" => half * h / (w * w + h * h).sqrt(),
            other => {
                return Err(self.err(fov_node, format!("unknown fov_axis '{other}' (x, y, smaller, larger, diagonal)")));
            }
        };
        let camera = Camera { origin, target, up, fov_y_deg: 2.0 * tan_y.atan().to_degrees() };
        Ok((camera, film, spp))
    }

    fn lookat(&self, node: Node) -> Result<(Vec3, Vec3, Vec3), SceneError> {
        let mut found = None;
        for child in Self::elements(node) {
            if child.tag_name().name() != "lookat" || found.is_some() {
                return Err(self.unsupported(child, "the sensor's to_world (hush reads one <lookat>)"));
            }
            let origin = self.vec3(child, self.attr(child, "origin")?)?;
            let target = self.vec3(child, self.attr(child, "target")?)?;
            let up = match child.attribute("up") {
                Some(u) => self.vec3(child, u)?,
                None => Vec3::Y,
            };
            found = Some((origin, target, up));
        }
        found.ok_or_else(|| self.err(node, "to_world needs a <lookat>"))
    }

    fn sampler(&self, node: Node) -> Result<Option<u32>, SceneError> {
        if self.attr(node, "type")? != "independent" {
            return Err(self.unsupported(node, "<sensor> (hush samples independently)"));
        }
        let mut spp = None;
        for child in Self::elements(node) {
            match (child.tag_name().name(), child.attribute("name")) {
                ("integer", Some("sample_count")) => {
                    let n = self.int(child)?;
                    if n < 1 {
                        return Err(self.err(child, "sample_count must be at least 1"));
                    }
                    spp = Some(n.min(u32::MAX as i64) as u32);
                }
                _ => return Err(self.unsupported(child, "<sampler>")),
            }
        }
        Ok(spp)
    }

    fn film(&self, node: Node) -> Result<Film, SceneError> {
        if self.attr(node, "type")? != "hdrfilm" {
            return Err(self.unsupported(node, "<sensor>"));
        }
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT };
        for child in Self::elements(node) {
            match (child.tag_name().name(), child.attribute("name")) {
                ("integer", Some(dim @ ("width" | "height"))) => {
                    let v = self.int(child)?;
                    if !(1..=65536).contains(&v) {
                        return Err(self.err(child, format!("film {dim} {v} is not in 1..=65536")));
                    }
                    if dim == "width" { film.width = v as u32 } else { film.height = v as u32 }
                }
                ("rfilter", _) => {
                    if self.attr(child, "type")? != "box" {
                        return Err(self.unsupported(child, "<film> (hush has the box pixel filter)"));
                    }
                }
                ("string", Some("pixel_format")) => match self.attr(child, "value")? {
                    "rgb" | "rgba" => {}
                    _ => return Err(self.unsupported(child, "<film> (pixel_format rgb)")),
                },
                _ => return Err(self.unsupported(child, "<film>")),
            }
        }
        Ok(film)
    }

    fn bsdf(&self, node: Node) -> Result<Material, SceneError> {
        match self.attr(node, "type")? {
            "diffuse" => {
                let mut reflectance = Vec3::splat(0.5);
                for child in Self::elements(node) {
                    match child.attribute("name") {
                        Some("reflectance") => reflectance = self.color(child)?,
                        _ => return Err(self.unsupported(child, "<bsdf type=\"diffuse\">")),
                    }
                }
                if reflectance.min_element() < 0.0 || reflectance.max_element() > 1.0 {
                    return Err(self.err(node, format!("diffuse reflectance {reflectance} is outside [0, 1]")));
                }
                Ok(Material::Diffuse { reflectance })
            }
            _ => Err(self.unsupported(node, "this version of hush (diffuse BSDFs only)")),
        }
    }

    fn shape(&self, node: Node) -> Result<crate::Mesh, SceneError> {
        if self.attr(node, "type")? != "obj" {
            return Err(self.unsupported(node, "<scene> (hush reads 'obj' shapes)"));
        }
        let mut filename = None;
        let mut face_normals = false;
        let mut material = None;
        let mut emission = None;
        for child in Self::elements(node) {
            match (child.tag_name().name(), child.attribute("name")) {
                ("string", Some("filename")) => filename = Some(self.attr(child, "value")?),
                ("boolean", Some("face_normals")) => face_normals = self.boolean(child)?,
                ("ref", _) => {
                    let id = self.attr(child, "id")?;
                    let m = self.bsdfs.get(id).ok_or_else(|| {
                        self.err(child, format!("no <bsdf id=\"{id}\"> is defined before this shape"))
                    })?;
                    material = Some(*m);
                }
                ("bsdf", _) => material = Some(self.bsdf(child)?),
                ("emitter", _) => emission = Some(self.area_emitter(child)?),
                _ => return Err(self.unsupported(child, "<shape type=\"obj\">")),
            }
        }
        let filename = filename.ok_or_else(|| self.err(node, "an obj shape needs <string name=\"filename\">"))?;
        // Mitsuba's default BSDF is a diffuse one of reflectance 0.5.
        let material = material.unwrap_or(Material::Diffuse { reflectance: Vec3::splat(0.5) });
        let file = self.dir.join(filename);
        let mut mesh = crate::load_obj(&file, material).map_err(|e| {
            let line = self.doc.text_pos_at(node.range().start).row;
            SceneError::new(self.path, Some(line), format!("shape '{filename}': {e}"))
        })?;
        if let Some(id) = node.attribute("id") {
            mesh.name = id.to_string();
        }
        if face_normals {
            mesh.normals = None;
        }
        mesh.emission = emission;
        Ok(mesh)
    }

    fn area_emitter(&self, node: Node) -> Result<Vec3, SceneError> {
        if self.attr(node, "type")? != "area" {
            return Err(self.unsupported(node, "<shape> (hush has area emitters on shapes)"));
        }
        let mut radiance = None;
        for child in Self::elements(node) {
            match child.attribute("name") {
                Some("radiance") => radiance = Some(self.color(child)?),
                _ => return Err(self.unsupported(child, "<emitter type=\"area\">")),
            }
        }
        let radiance = radiance.ok_or_else(|| self.err(node, "an area emitter needs a 'radiance'"))?;
        if radiance.min_element() < 0.0 {
            return Err(self.err(node, format!("radiance {radiance} is negative")));
        }
        Ok(radiance)
    }
}
