//! Mitsuba XML scenes, versions 0.6 (`version="0.5.0"`/`"0.6.0"`), 2 and 3.
//!
//! Read: `<default>` with `$variables` in any attribute; the `path` integrator (`max_depth`);
//! a `perspective` (or, without its lens, `thinlens`) sensor with any `to_world` transform,
//! `fov`/`fov_axis`, a sampler's `sample_count` and an `hdrfilm`'s size; BSDFs `diffuse`,
//! `conductor`/`roughconductor` (named metals or `eta`/`k`), `dielectric`/`thindielectric`/
//! `roughdielectric` (named or numeric IORs), `plastic`/`roughplastic`, `twosided`, with
//! `rgb`/`srgb`/`spectrum`/`float` values and `bitmap` textures; shapes `obj`, `rectangle`,
//! `cube`, `sphere`, `disk`, `cylinder` (the analytic ones as [`crate::Analytic`]) with `to_world` (`translate`, `rotate`, `scale`, `matrix`,
//! `lookat`, composed as Mitsuba does: each later element is applied after the earlier ones),
//! `flip_normals`, `face_normals`, a BSDF by `ref` or inline and an `area` emitter; `constant`
//! and `envmap` emitters.
//!
//! Before version 2, parameter names are camelCase (`toWorld`, `intIOR`); they are converted
//! to snake_case as Mitsuba 2's upgrade does (an underscore between a lower-case letter and an
//! upper-case one, then lower case).
//!
//! Policy: what hush does not support yet (another integrator, a Lanczos filter, an opacity mask,
//! a point light, a missing mesh or texture file, ...) is a warning in [`Scene::warnings`] naming
//! the element, its line and what was used instead.
//! Malformed input (not XML, a number that is not one, a missing required attribute, an
//! undefined `$variable`, an undefined `ref`, NaN vertices, a zero-area emitter) is an error
//! naming the file and the line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3, Vec4};
use roxmltree::{Document, Node};

use crate::shapes;
use crate::texture::{TextureCache, read_image, srgb_to_linear};
use crate::{
    Analytic, Camera, ComplexIor, EnvMap, Environment, Film, Material, Mesh, Microfacet, PixelFilter, Reflectance,
    Scene, SceneError, ShapeKind, named,
};

/// The longest attribute value `$variable` substitution may produce: any real scene's values are far shorter,
/// and a file of `$a$a$a...` with a long default would otherwise grow quadratically.
const MAX_SUBSTITUTED: usize = 64 * 1024;
/// The most XML nodes (elements, attributes' texts and texts) of a scene file: a real scene of a thousand shapes
/// has tens of thousands, and the parsed tree of this many takes about 50 MB.
const MAX_XML_NODES: u64 = 500_000;
/// The deepest nesting of `<bsdf>` elements (real scenes nest two or three: twosided around a mask ...).
const MAX_BSDF_NESTING: usize = 16;

impl Scene {
    /// Parses Mitsuba XML text; `path` names the file in errors and anchors relative paths.
    pub fn from_mitsuba_str(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let nodes_limit = hush_io::limit_from_env("HUSH_MAX_XML_NODES", MAX_XML_NODES).min(u64::from(u32::MAX)) as u32;
        let options = roxmltree::ParsingOptions { nodes_limit, ..Default::default() };
        let doc = Document::parse_with_options(text, options).map_err(|e| match e {
            roxmltree::Error::NodesLimitReached => SceneError::new(
                path,
                None,
                format!(
                    "the XML holds more than {nodes_limit} elements, attributes and texts; refused before it fills \
                     memory (a genuine scene this large: raise the limit with HUSH_MAX_XML_NODES=<count>)"
                ),
            ),
            e => SceneError::new(path, Some(e.pos().row), format!("malformed XML: {e}")),
        })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut parser = Parser {
            path,
            doc: &doc,
            dir,
            legacy: false,
            vars: HashMap::new(),
            bsdfs: HashMap::new(),
            textures_by_id: HashMap::new(),
            textures: TextureCache::default(),
            warnings: Vec::new(),
        };
        parser.scene()
    }
}

struct Parser<'a, 'input> {
    path: &'a Path,
    doc: &'a Document<'input>,
    dir: PathBuf,
    /// Version < 2: camelCase parameter names, Mitsuba 0.6's defaults.
    legacy: bool,
    vars: HashMap<String, String>,
    bsdfs: HashMap<String, Material>,
    textures_by_id: HashMap<String, Reflectance>,
    textures: TextureCache,
    warnings: Vec<String>,
}

/// Mitsuba's defaults for a sensor without the corresponding element.
const DEFAULT_WIDTH: u32 = 768;
const DEFAULT_HEIGHT: u32 = 576;

/// Mitsuba 2's rule for upgrading 0.6 names: `toWorld` → `to_world`, `intIOR` → `int_ior`.
fn snake_case(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 4);
    let mut prev_lower = false;
    for c in name.chars() {
        if c.is_ascii_uppercase() && prev_lower {
            out.push('_');
        }
        prev_lower = c.is_ascii_lowercase();
        out.push(c.to_ascii_lowercase());
    }
    out
}

fn elements<'n, 'i>(node: Node<'n, 'i>) -> impl Iterator<Item = Node<'n, 'i>> {
    node.children().filter(Node::is_element)
}

impl Parser<'_, '_> {
    fn line(&self, node: Node) -> u32 {
        self.doc.text_pos_at(node.range().start).row
    }

    fn err(&self, node: Node, msg: impl Into<String>) -> SceneError {
        SceneError::new(self.path, Some(self.line(node)), msg)
    }

    /// The file `filename` of `node` names, beside the scene: one outside the scene's folder is an error.
    fn referenced(&self, node: Node, filename: &str) -> Result<PathBuf, SceneError> {
        let file = self.dir.join(filename);
        crate::check_inside(&file, &self.dir).map_err(|m| self.err(node, m))?;
        Ok(file)
    }

    fn warn(&mut self, node: Node, msg: impl AsRef<str>) {
        let w = format!("{}:{}: {}", self.path.display(), self.line(node), msg.as_ref());
        self.warnings.push(w);
    }

    /// `<tag type="t" name="n">` for messages.
    fn describe(&self, node: Node) -> String {
        let ty = node.attribute("type").map(|t| format!(" type=\"{t}\"")).unwrap_or_default();
        let name = node.attribute("name").map(|t| format!(" name=\"{t}\"")).unwrap_or_default();
        format!("<{}{ty}{name}>", node.tag_name().name())
    }

    fn ignored(&mut self, node: Node, context: &str) {
        let d = self.describe(node);
        self.warn(node, format!("{d} in {context} is not supported yet and was ignored"));
    }

    fn tag<'n>(&self, node: Node<'n, '_>) -> &'n str {
        match node.tag_name().name() {
            "lookAt" => "lookat",
            t => t,
        }
    }

    /// The `name` attribute, in Mitsuba 3's snake_case.
    fn name(&self, node: Node) -> Option<String> {
        let raw = node.attribute("name")?;
        let raw = self.substitute(node, raw).ok()?;
        Some(if self.legacy { snake_case(&raw) } else { raw })
    }

    /// Replaces `$var` by the `<default>` values; the result may not grow beyond [`MAX_SUBSTITUTED`] bytes.
    fn substitute(&self, node: Node, value: &str) -> Result<String, SceneError> {
        if !value.contains('$') {
            return Ok(value.to_string());
        }
        let mut out = String::new();
        let mut rest = value;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
            let var = &after[..len];
            let v = self.vars.get(var).ok_or_else(|| {
                self.err(
                    node,
                    format!("undefined variable '${var}': add <default name=\"{var}\" value=\"...\"/> to the scene"),
                )
            })?;
            out.push_str(v);
            if out.len() > MAX_SUBSTITUTED {
                return Err(self.err(
                    node,
                    format!("an attribute grows beyond {MAX_SUBSTITUTED} bytes as its $variables are replaced"),
                ));
            }
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    fn opt_attr(&self, node: Node, name: &str) -> Result<Option<String>, SceneError> {
        node.attribute(name).map(|v| self.substitute(node, v)).transpose()
    }

    fn attr(&self, node: Node, name: &str) -> Result<String, SceneError> {
        self.opt_attr(node, name)?
            .ok_or_else(|| self.err(node, format!("<{}> needs a '{name}' attribute", node.tag_name().name())))
    }

    fn number(&self, node: Node, text: &str) -> Result<f32, SceneError> {
        text.trim()
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.err(node, format!("'{text}' is not a finite number")))
    }

    fn float(&self, node: Node) -> Result<f32, SceneError> {
        if self.tag(node) != "float" {
            return Err(self.err(node, format!("{} should be a <float>", self.describe(node))));
        }
        let v = self.attr(node, "value")?;
        self.number(node, &v)
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

    fn string(&self, node: Node) -> Result<String, SceneError> {
        self.attr(node, "value")
    }

    fn numbers(&self, node: Node, text: &str) -> Result<Vec<f32>, SceneError> {
        text.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| self.number(node, s))
            .collect()
    }

    fn vec3(&self, node: Node, text: &str) -> Result<Vec3, SceneError> {
        match self.numbers(node, text)?.as_slice() {
            [x] => Ok(Vec3::splat(*x)),
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            _ => Err(self.err(node, format!("'{text}' is not one or three numbers"))),
        }
    }

    /// A point or vector given as `value="x, y, z"` or as `x`, `y`, `z` attributes (default `d`).
    fn xyz(&self, node: Node, d: f32) -> Result<Vec3, SceneError> {
        if let Some(v) = self.opt_attr(node, "value")? {
            return self.vec3(node, &v);
        }
        let mut out = Vec3::splat(d);
        for (i, axis) in ["x", "y", "z"].into_iter().enumerate() {
            if let Some(v) = self.opt_attr(node, axis)? {
                out[i] = self.number(node, &v)?;
            }
        }
        Ok(out)
    }

    /// A color: `<rgb>` (linear), `<srgb>` (sRGB-encoded, or `#rrggbb`), `<float>` (grey) or
    /// `<spectrum>` (a constant, or `wavelength:value` pairs averaged to a grey, with a warning).
    fn color(&mut self, node: Node) -> Result<Vec3, SceneError> {
        match self.tag(node) {
            "rgb" | "float" | "color" => {
                let v = self.attr(node, "value")?;
                self.vec3(node, &v)
            }
            "srgb" => {
                let v = self.attr(node, "value")?;
                let c = match v.trim().strip_prefix('#') {
                    Some(hex) if hex.len() == 6 => {
                        let byte = |i: usize| u8::from_str_radix(&hex[i..i + 2], 16);
                        match (byte(0), byte(2), byte(4)) {
                            (Ok(r), Ok(g), Ok(b)) => Vec3::new(r as f32, g as f32, b as f32) / 255.0,
                            _ => return Err(self.err(node, format!("'{v}' is not a #rrggbb color"))),
                        }
                    }
                    _ => self.vec3(node, &v)?,
                };
                Ok(Vec3::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z)))
            }
            "spectrum" => {
                if node.attribute("filename").is_some() {
                    return Err(self.err(node, "spectrum files are not supported: give the color as <rgb>"));
                }
                let v = self.attr(node, "value")?;
                if !v.contains(':') {
                    return self.vec3(node, &v);
                }
                let mut values = Vec::new();
                for pair in v.split(',').map(str::trim).filter(|s| !s.is_empty()) {
                    let (_, value) = pair
                        .split_once(':')
                        .ok_or_else(|| self.err(node, format!("'{pair}' is not wavelength:value")))?;
                    values.push(self.number(node, value)?);
                }
                if values.is_empty() {
                    return Err(self.err(node, "empty spectrum"));
                }
                let mean = values.iter().sum::<f32>() / values.len() as f32;
                self.warn(
                    node,
                    format!("a sampled <spectrum> is not supported yet: its mean {mean} is used as a grey"),
                );
                Ok(Vec3::splat(mean))
            }
            _ => Err(self.err(
                node,
                format!("{} is not a color (use <rgb>, <srgb>, <spectrum> or <float>)", self.describe(node)),
            )),
        }
    }

    /// A color or a texture (`<texture type="bitmap">` or a `<ref>` to one).
    fn reflectance(&mut self, node: Node) -> Result<Reflectance, SceneError> {
        match self.tag(node) {
            "texture" => self.texture(node),
            "ref" => {
                let id = self.attr(node, "id")?;
                self.textures_by_id
                    .get(&id)
                    .copied()
                    .ok_or_else(|| self.err(node, format!("no <texture id=\"{id}\"> is defined before this reference")))
            }
            _ => Ok(Reflectance::Rgb(self.color(node)?)),
        }
    }

    fn texture(&mut self, node: Node) -> Result<Reflectance, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "bitmap" {
            self.warn(node, format!("texture type '{ty}' is not supported yet: a constant 0.5 grey is used instead"));
            return Ok(Reflectance::Rgb(Vec3::splat(0.5)));
        }
        let mut filename = None;
        let mut raw = false;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("string", Some("filename")) => filename = Some(self.string(child)?),
                ("boolean", Some("raw")) => raw = self.boolean(child)?,
                ("string", Some("filter_type")) => {
                    let f = self.string(child)?;
                    if f != "bilinear" {
                        self.warn(
                            child,
                            format!("texture filter '{f}' is not supported yet: bilinear filtering is used"),
                        );
                    }
                }
                ("string", Some("wrap_mode")) => {
                    let w = self.string(child)?;
                    if w != "repeat" {
                        self.warn(child, format!("texture wrap mode '{w}' is not supported yet: 'repeat' is used"));
                    }
                }
                ("float", Some("gamma")) => {
                    let g = self.float(child)?;
                    if g != -1.0 {
                        self.warn(child, format!("texture gamma {g} is not supported: sRGB decoding is used"));
                    }
                }
                _ => self.ignored(child, "<texture type=\"bitmap\">"),
            }
        }
        let filename = filename.ok_or_else(|| self.err(node, "a bitmap texture needs <string name=\"filename\">"))?;
        let file = self.referenced(node, &filename)?;
        match self.textures.get(&file, raw) {
            Ok(id) => Ok(Reflectance::Texture(id)),
            Err(e) => {
                self.warn(node, format!("{e}; a constant 0.5 grey is used instead"));
                Ok(Reflectance::Rgb(Vec3::splat(0.5)))
            }
        }
    }

    /// A `<transform>`: its elements composed in document order, each applied after the ones
    /// before it (Mitsuba: `M = T_k · … · T_1`).
    fn transform(&self, node: Node) -> Result<Mat4, SceneError> {
        let mut m = Mat4::IDENTITY;
        for child in elements(node) {
            let t = match self.tag(child) {
                "translate" => Mat4::from_translation(self.xyz(child, 0.0)?),
                "scale" => Mat4::from_scale(self.xyz(child, 1.0)?),
                "rotate" => {
                    let axis = self.xyz(child, 0.0)?;
                    if axis.length_squared() == 0.0 {
                        return Err(self.err(child, "rotate needs a non-zero axis (x, y, z or value)"));
                    }
                    let angle = self.attr(child, "angle")?;
                    let angle = self.number(child, &angle)?;
                    Mat4::from_axis_angle(axis.normalize(), angle.to_radians())
                }
                "matrix" => {
                    let v = self.attr(child, "value")?;
                    match self.numbers(child, &v)?.as_slice() {
                        a if a.len() == 16 => Mat4::from_cols_slice(a).transpose(),
                        a if a.len() == 9 => {
                            let r = |i: usize| Vec4::new(a[3 * i], a[3 * i + 1], a[3 * i + 2], 0.0);
                            Mat4::from_cols(r(0), r(1), r(2), Vec4::W).transpose()
                        }
                        a => return Err(self.err(child, format!("a matrix needs 16 (or 9) numbers, not {}", a.len()))),
                    }
                }
                "lookat" => {
                    let origin = self.vec3(child, &self.attr(child, "origin")?)?;
                    let target = self.vec3(child, &self.attr(child, "target")?)?;
                    let up = match self.opt_attr(child, "up")? {
                        Some(u) => self.vec3(child, &u)?,
                        None => Vec3::Y,
                    };
                    lookat(origin, target, up).ok_or_else(|| {
                        self.err(child, "lookat: origin and target coincide, or up is parallel to the view direction")
                    })?
                }
                _ => {
                    return Err(self.err(
                        child,
                        format!(
                            "{} is not a transform (translate, rotate, scale, matrix, lookat)",
                            self.describe(child)
                        ),
                    ));
                }
            };
            m = t * m;
        }
        if !m.is_finite() {
            return Err(self.err(node, "the transform is not finite"));
        }
        Ok(m)
    }

    fn scene(&mut self) -> Result<Scene, SceneError> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "scene" {
            return Err(self.err(root, "the root element must be <scene>"));
        }
        let version = root.attribute("version").unwrap_or("3.0.0");
        let major = version.split('.').next().and_then(|m| m.trim().parse::<u32>().ok());
        match major {
            Some(0) => self.legacy = true,
            Some(2 | 3) => {}
            _ => {
                let v = version.to_string();
                self.warn(root, format!("scene version '{v}' is unknown: read as Mitsuba 3"));
            }
        }
        for node in elements(root).filter(|n| n.tag_name().name() == "default") {
            let name = node.attribute("name").ok_or_else(|| self.err(node, "<default> needs a 'name'"))?;
            let value = node.attribute("value").ok_or_else(|| self.err(node, "<default> needs a 'value'"))?;
            self.vars.entry(name.to_string()).or_insert_with(|| value.to_string());
        }
        let mut camera = None;
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT, filter: PixelFilter::MITSUBA_DEFAULT };
        let mut spp = None;
        let mut max_depth = u32::MAX;
        let mut meshes = Vec::new();
        let mut environment = None;
        let mut shape_count = 0usize;
        let mut missing = Vec::new();
        for node in elements(root) {
            match self.tag(node) {
                "default" => {}
                "integrator" => max_depth = self.integrator(node)?,
                "sensor" => {
                    if camera.is_some() {
                        self.warn(node, "a second <sensor> is ignored: hush renders the first");
                        continue;
                    }
                    let (c, f, s) = self.sensor(node)?;
                    camera = Some(c);
                    film = f;
                    spp = s;
                }
                "bsdf" => {
                    let id = self.attr(node, "id")?;
                    let material = self.bsdf(node)?;
                    self.bsdfs.insert(id, material);
                }
                "texture" => {
                    let id = self.attr(node, "id")?;
                    let t = self.texture(node)?;
                    self.textures_by_id.insert(id, t);
                }
                "shape" => {
                    shape_count += 1;
                    match self.shape(node, shape_count)? {
                        ShapeResult::Mesh(m) => meshes.push(*m),
                        ShapeResult::Missing(file) => missing.push(file),
                        ShapeResult::Skipped => {}
                    }
                }
                "emitter" => {
                    if let Some(env) = self.environment(node)? {
                        if environment.is_some() {
                            self.warn(node, "a second environment emitter is ignored: hush has one");
                        } else {
                            environment = Some(env);
                        }
                    }
                }
                _ => self.ignored(node, "<scene>"),
            }
        }
        let camera = camera.ok_or_else(|| self.err(root, "the scene has no <sensor type=\"perspective\">"))?;
        camera.validate().map_err(|m| self.err(root, m))?;
        if meshes.is_empty() && environment.is_none() && !missing.is_empty() {
            return Err(
                self.err(root, format!("nothing is left to render: the mesh files {} are missing", missing.join(", ")))
            );
        }
        Ok(Scene {
            camera,
            film,
            max_depth,
            spp,
            meshes,
            textures: std::mem::take(&mut self.textures.textures),
            environment,
            warnings: std::mem::take(&mut self.warnings),
        })
    }

    fn integrator(&mut self, node: Node) -> Result<u32, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "path" {
            self.warn(
                node,
                format!("integrator '{ty}' is not supported: hush renders with 'path' (its max_depth is kept)"),
            );
        }
        let mut max_depth = u32::MAX;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("integer", Some("max_depth")) => {
                    max_depth = match self.int(child)? {
                        -1 => u32::MAX,
                        d if d >= 1 => d.min(u32::MAX as i64) as u32,
                        _ => return Err(self.err(child, "max_depth must be -1 (unlimited) or at least 1")),
                    };
                }
                // Russian roulette's start changes variance, never the expected image.
                ("integer", Some("rr_depth")) => {
                    self.int(child)?;
                }
                _ => self.ignored(child, &format!("<integrator type=\"{ty}\">")),
            }
        }
        Ok(max_depth)
    }

    fn sensor(&mut self, node: Node) -> Result<(Camera, Film, Option<u32>), SceneError> {
        let ty = self.attr(node, "type")?;
        match ty.as_str() {
            "perspective" => {}
            "thinlens" => {
                self.warn(node, "sensor 'thinlens' is not supported yet: a pinhole camera is used (no depth of field)")
            }
            _ => return Err(self.err(node, format!("sensor '{ty}' is not supported: hush has a perspective camera"))),
        }
        let mut fov = None;
        let mut fov_axis = "x".to_string();
        let mut to_world = None;
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT, filter: PixelFilter::MITSUBA_DEFAULT };
        let mut spp = None;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("float", Some("fov")) => fov = Some((self.float(child)?, child)),
                ("string", Some("fov_axis")) => fov_axis = self.string(child)?,
                ("float", Some("near_clip" | "far_clip")) => {
                    self.float(child)?;
                }
                ("float", Some("aperture_radius" | "focus_distance")) if ty == "thinlens" => {
                    self.float(child)?;
                }
                ("transform", Some("to_world")) => to_world = Some((self.transform(child)?, child)),
                ("sampler", _) => spp = self.sampler(child)?,
                ("film", _) => film = self.film(child)?,
                _ => self.ignored(child, "<sensor>"),
            }
        }
        let (fov, fov_node) = fov.ok_or_else(|| self.err(node, "the sensor needs <float name=\"fov\">"))?;
        let (m, t_node) = to_world.ok_or_else(|| self.err(node, "the sensor needs <transform name=\"to_world\">"))?;
        // Mitsuba's camera looks along local +z with local +y up and local +x to the image's left.
        let origin = m.transform_point3(Vec3::ZERO);
        let forward = m.transform_vector3(Vec3::Z).normalize_or_zero();
        let up = m.transform_vector3(Vec3::Y).normalize_or_zero();
        if glam::Mat3::from_mat4(m).determinant() < 0.0 {
            self.warn(t_node, "the sensor's to_world mirrors the image: hush renders it unmirrored");
        }
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
        let camera = Camera { origin, target: origin + forward, up, fov_y_deg: 2.0 * tan_y.atan().to_degrees() };
        camera.validate().map_err(|e| self.err(t_node, format!("the sensor's to_world: {e}")))?;
        Ok((camera, film, spp))
    }

    fn sampler(&mut self, node: Node) -> Result<Option<u32>, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "independent" {
            self.warn(
                node,
                format!(
                    "sampler '{ty}' is not supported: hush samples independently (`--pixel-sampler stratified` \
                     stratifies each pixel's sample positions)"
                ),
            );
        }
        let mut spp = None;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("integer", Some("sample_count")) => {
                    let n = self.int(child)?;
                    if n < 1 {
                        return Err(self.err(child, "sample_count must be at least 1"));
                    }
                    spp = Some(n.min(u32::MAX as i64) as u32);
                }
                ("integer", Some("seed")) => {
                    self.int(child)?;
                    self.warn(child, "the sampler's seed is ignored: pass --seed to hush");
                }
                _ => self.ignored(child, "<sampler>"),
            }
        }
        Ok(spp)
    }

    /// A `<rfilter>`: `box`, `tent` with its `radius` (Mitsuba's default 1) or `gaussian` with its
    /// `stddev` (0.5); any other is a warning and a box.
    fn rfilter(&mut self, node: Node) -> Result<PixelFilter, SceneError> {
        match self.attr(node, "type")?.as_str() {
            "box" => {
                for child in elements(node) {
                    self.ignored(child, "<rfilter type=\"box\">");
                }
                Ok(PixelFilter::Box)
            }
            "tent" => Ok(PixelFilter::Tent { radius: self.filter_width(node, "tent", "radius", 1.0, 16.0)? }),
            "gaussian" => {
                Ok(PixelFilter::Gaussian { stddev: self.filter_width(node, "gaussian", "stddev", 0.5, 4.0)? })
            }
            f => {
                self.warn(node, format!("reconstruction filter '{f}' is not supported yet: hush uses a box filter"));
                Ok(PixelFilter::Box)
            }
        }
    }

    /// The one `<float>` a filter `kind` takes, `name` (`default` when absent): positive, and at most
    /// `max` pixels (a wider one is a warning and `max`).
    fn filter_width(&mut self, node: Node, kind: &str, name: &str, default: f32, max: f32) -> Result<f32, SceneError> {
        let mut width = default;
        for child in elements(node) {
            if self.tag(child) == "float" && self.name(child).as_deref() == Some(name) {
                width = self.float(child)?;
                if !(width.is_finite() && width > 0.0) {
                    return Err(self.err(child, format!("{kind} filter {name} {width} is not a positive width")));
                }
                if width > max {
                    self.warn(
                        child,
                        format!("{kind} filter {name} {width} is wider than hush supports: hush uses {max}"),
                    );
                    width = max;
                }
            } else {
                self.ignored(child, &format!("<rfilter type=\"{kind}\">"));
            }
        }
        Ok(width)
    }

    fn film(&mut self, node: Node) -> Result<Film, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "hdrfilm" {
            self.warn(node, format!("film '{ty}' is not supported: hush writes an HDR OpenEXR film"));
        }
        let mut film = Film { width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT, filter: PixelFilter::MITSUBA_DEFAULT };
        let mut has_filter = false;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("integer", Some(dim @ ("width" | "height"))) => {
                    let v = self.int(child)?;
                    if !(1..=65536).contains(&v) {
                        return Err(self.err(child, format!("film {dim} {v} is not in 1..=65536")));
                    }
                    if dim == "width" { film.width = v as u32 } else { film.height = v as u32 }
                }
                ("rfilter", _) if has_filter => {
                    return Err(self.err(child, "a film can only have one reconstruction filter (<rfilter>)"));
                }
                ("rfilter", _) => {
                    film.filter = self.rfilter(child)?;
                    has_filter = true;
                }
                // Output encodings: hush always writes float RGB OpenEXR, without a banner.
                ("string", Some("file_format" | "pixel_format" | "component_format")) | ("boolean", Some("banner")) => {
                    self.string(child)?;
                }
                _ => self.ignored(child, "<film>"),
            }
        }
        Ok(film)
    }

    fn ior(&self, node: Node) -> Result<f32, SceneError> {
        match self.tag(node) {
            "float" => {
                let v = self.float(node)?;
                if v <= 0.0 {
                    return Err(self.err(node, format!("index of refraction {v} must be positive")));
                }
                Ok(v)
            }
            "string" => {
                let name = self.string(node)?;
                named::ior(&name).ok_or_else(|| {
                    self.err(node, format!("unknown IOR name '{name}': give a number or one of {}", named::ior_names()))
                })
            }
            _ => {
                Err(self
                    .err(node, format!("{} is not an index of refraction (<float> or <string>)", self.describe(node))))
            }
        }
    }

    /// Microfacet parameters shared by the rough BSDFs: `alpha` (isotropic), `alpha_u`/`alpha_v`
    /// (averaged geometrically, with a warning), `distribution` (`beckmann`, Mitsuba's default,
    /// or `ggx`; `phong` and `as` become Beckmann with a warning).
    fn microfacet(
        &mut self,
        child: Node,
        name: &str,
        alpha: &mut f32,
        au: &mut Option<f32>,
        av: &mut Option<f32>,
        dist: &mut Microfacet,
    ) -> Result<bool, SceneError> {
        match (self.tag(child), name) {
            ("float", "alpha") => *alpha = self.float(child)?,
            ("float", "alpha_u") => *au = Some(self.float(child)?),
            ("float", "alpha_v") => *av = Some(self.float(child)?),
            ("string", "distribution") => {
                let d = self.string(child)?;
                match d.as_str() {
                    "ggx" => *dist = Microfacet::Ggx,
                    "beckmann" => *dist = Microfacet::Beckmann,
                    "phong" | "as" => {
                        *dist = Microfacet::Beckmann;
                        self.warn(
                            child,
                            format!(
                                "microfacet distribution '{d}' is not supported yet: Beckmann with the same alpha is used"
                            ),
                        )
                    }
                    _ => return Err(self.err(child, format!("unknown microfacet distribution '{d}' (ggx, beckmann)"))),
                }
            }
            ("boolean", "sample_visible") => {
                self.boolean(child)?;
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    fn finish_alpha(&mut self, node: Node, alpha: f32, au: Option<f32>, av: Option<f32>) -> Result<f32, SceneError> {
        let a = match (au, av) {
            (None, None) => alpha,
            (u, v) => {
                let (u, v) = (u.unwrap_or(alpha), v.unwrap_or(alpha));
                if u != v {
                    self.warn(
                        node,
                        format!(
                            "anisotropic roughness ({u}, {v}) is not supported yet: alpha {} is used",
                            (u * v).sqrt()
                        ),
                    );
                }
                (u * v).sqrt()
            }
        };
        if !(0.0..=10.0).contains(&a) {
            return Err(self.err(node, format!("roughness alpha {a} must be in [0, 10]")));
        }
        Ok(a)
    }

    fn bsdf(&mut self, node: Node) -> Result<Material, SceneError> {
        // Nested BSDFs are read recursively: refuse what only a hostile file nests this deep.
        if node.ancestors().filter(|a| a.is_element() && a.tag_name().name() == "bsdf").count() > MAX_BSDF_NESTING {
            return Err(self.err(node, format!("BSDFs are nested more than {MAX_BSDF_NESTING} deep")));
        }
        let ty = self.attr(node, "type")?;
        let ctx = format!("<bsdf type=\"{ty}\">");
        let rough = ty.starts_with("rough");
        let mut alpha = if rough { 0.1 } else { 0.0 };
        let (mut au, mut av) = (None, None);
        let mut dist = Microfacet::Beckmann;
        match ty.as_str() {
            "twosided" | "mask" | "bumpmap" | "normalmap" => {
                let mut inner = Vec::new();
                for child in elements(node) {
                    match self.tag(child) {
                        "bsdf" => inner.push(self.bsdf(child)?),
                        "ref" => inner.push(self.bsdf_ref(child)?),
                        _ if ty != "twosided" => {
                            let d = self.describe(child);
                            self.warn(
                                child,
                                format!(
                                    "{d} of <bsdf type=\"{ty}\"> is not supported yet: the nested BSDF is used alone"
                                ),
                            );
                        }
                        _ => self.ignored(child, &ctx),
                    }
                }
                let first = *inner
                    .first()
                    .ok_or_else(|| self.err(node, format!("<bsdf type=\"{ty}\"> needs a nested BSDF")))?;
                if ty != "twosided" {
                    return Ok(first);
                }
                if inner.len() > 1 && inner[1] != first {
                    self.warn(node, "a twosided BSDF with a different back side is not supported yet: the front BSDF is used on both sides");
                }
                if matches!(first, Material::Dielectric { .. }) {
                    self.warn(node, "twosided around a dielectric has no effect: dielectrics are two-sided");
                }
                Ok(first.with_two_sided(true))
            }
            "diffuse" => {
                let mut reflectance = Reflectance::Rgb(Vec3::splat(0.5));
                for child in elements(node) {
                    match self.name(child).as_deref() {
                        Some("reflectance") => reflectance = self.reflectance(child)?,
                        _ => self.ignored(child, &ctx),
                    }
                }
                self.check_unit(node, reflectance, "diffuse reflectance")?;
                Ok(Material::Diffuse { reflectance, two_sided: false })
            }
            "conductor" | "roughconductor" => {
                // Mitsuba 0.6 defaults to copper, Mitsuba 2 and 3 to a perfect mirror.
                let mut ior = if self.legacy { named::conductor("Cu") } else { None };
                let (mut eta, mut k) = (None, None);
                let mut ext_eta = 1.0;
                let mut specular_reflectance = Vec3::ONE;
                for child in elements(node) {
                    let name = self.name(child).unwrap_or_default();
                    if self.microfacet(child, &name, &mut alpha, &mut au, &mut av, &mut dist)? {
                        continue;
                    }
                    match name.as_str() {
                        "material" => {
                            let m = self.string(child)?;
                            ior = if m == "none" {
                                None
                            } else {
                                Some(named::conductor(&m).ok_or_else(|| {
                                    self.err(
                                        child,
                                        format!(
                                            "unknown conductor '{m}': use eta/k or one of none, {}",
                                            named::conductor_names()
                                        ),
                                    )
                                })?)
                            };
                        }
                        "eta" => eta = Some(self.color(child)?),
                        "k" => k = Some(self.color(child)?),
                        "ext_eta" => ext_eta = self.ior(child)?,
                        "specular_reflectance" => {
                            specular_reflectance = self.constant_color(child, "specular_reflectance")?
                        }
                        _ => self.ignored(child, &ctx),
                    }
                }
                if eta.is_some() || k.is_some() {
                    let base = ior.unwrap_or(ComplexIor { eta: Vec3::ZERO, k: Vec3::ONE });
                    ior = Some(ComplexIor { eta: eta.unwrap_or(base.eta), k: k.unwrap_or(base.k) });
                }
                let ior = ior.map(|c| ComplexIor { eta: c.eta / ext_eta, k: c.k / ext_eta });
                let alpha = self.finish_alpha(node, alpha, au, av)?;
                Ok(Material::Conductor { alpha, distribution: dist, ior, specular_reflectance, two_sided: false })
            }
            "dielectric" | "thindielectric" | "roughdielectric" => {
                let mut int_ior = named::ior("bk7").unwrap_or(1.5046);
                let mut ext_ior = named::ior("air").unwrap_or(1.00028);
                let mut specular_reflectance = Vec3::ONE;
                let mut specular_transmittance = Vec3::ONE;
                for child in elements(node) {
                    let name = self.name(child).unwrap_or_default();
                    if rough && self.microfacet(child, &name, &mut alpha, &mut au, &mut av, &mut dist)? {
                        continue;
                    }
                    match name.as_str() {
                        "int_ior" => int_ior = self.ior(child)?,
                        "ext_ior" => ext_ior = self.ior(child)?,
                        "specular_reflectance" => {
                            specular_reflectance = self.constant_color(child, "specular_reflectance")?
                        }
                        "specular_transmittance" => {
                            specular_transmittance = self.constant_color(child, "specular_transmittance")?
                        }
                        _ => self.ignored(child, &ctx),
                    }
                }
                let alpha = self.finish_alpha(node, alpha, au, av)?;
                Ok(Material::Dielectric {
                    alpha,
                    distribution: dist,
                    int_ior,
                    ext_ior,
                    thin: ty == "thindielectric",
                    specular_reflectance,
                    specular_transmittance,
                })
            }
            "plastic" | "roughplastic" => {
                let mut diffuse_reflectance = Reflectance::Rgb(Vec3::splat(0.5));
                let mut specular_reflectance = Vec3::ONE;
                let mut int_ior = named::ior("polypropylene").unwrap_or(1.49);
                let mut ext_ior = named::ior("air").unwrap_or(1.00028);
                let mut nonlinear = false;
                for child in elements(node) {
                    let name = self.name(child).unwrap_or_default();
                    if rough && self.microfacet(child, &name, &mut alpha, &mut au, &mut av, &mut dist)? {
                        continue;
                    }
                    match name.as_str() {
                        "diffuse_reflectance" => diffuse_reflectance = self.reflectance(child)?,
                        "specular_reflectance" => {
                            specular_reflectance = self.constant_color(child, "specular_reflectance")?
                        }
                        "int_ior" => int_ior = self.ior(child)?,
                        "ext_ior" => ext_ior = self.ior(child)?,
                        "nonlinear" => nonlinear = self.boolean(child)?,
                        _ => self.ignored(child, &ctx),
                    }
                }
                self.check_unit(node, diffuse_reflectance, "diffuse_reflectance")?;
                let alpha = self.finish_alpha(node, alpha, au, av)?;
                Ok(Material::Plastic {
                    diffuse_reflectance,
                    specular_reflectance,
                    alpha,
                    distribution: dist,
                    int_ior,
                    ext_ior,
                    nonlinear,
                    two_sided: false,
                })
            }
            other => {
                self.warn(
                    node,
                    format!("BSDF '{other}' is not supported yet: a diffuse BSDF of reflectance 0.5 is used"),
                );
                Ok(Material::DEFAULT)
            }
        }
    }

    /// A constant color where hush has no texture support; a texture gives its mean, with a warning.
    fn constant_color(&mut self, node: Node, what: &str) -> Result<Vec3, SceneError> {
        match self.reflectance(node)? {
            Reflectance::Rgb(c) => Ok(c),
            Reflectance::Texture(id) => {
                let mean = self.textures.textures[id.0 as usize].mean();
                self.warn(node, format!("a textured {what} is not supported yet: the texture's mean {mean} is used"));
                Ok(mean)
            }
        }
    }

    fn check_unit(&self, node: Node, r: Reflectance, what: &str) -> Result<(), SceneError> {
        if let Reflectance::Rgb(c) = r
            && (c.min_element() < 0.0 || c.max_element() > 1.0)
        {
            return Err(self.err(node, format!("{what} {c} is outside [0, 1]")));
        }
        Ok(())
    }

    fn bsdf_ref(&self, node: Node) -> Result<Material, SceneError> {
        let id = self.attr(node, "id")?;
        self.bsdfs
            .get(&id)
            .copied()
            .ok_or_else(|| self.err(node, format!("no <bsdf id=\"{id}\"> is defined before this reference")))
    }

    fn shape(&mut self, node: Node, index: usize) -> Result<ShapeResult, SceneError> {
        let ty = self.attr(node, "type")?;
        let ctx = format!("<shape type=\"{ty}\">");
        if !matches!(ty.as_str(), "obj" | "rectangle" | "cube" | "sphere" | "disk" | "cylinder") {
            self.warn(node, format!("shape type '{ty}' is not supported yet: the shape is skipped"));
            return Ok(ShapeResult::Skipped);
        }
        let mut filename = None;
        let mut face_normals = false;
        let mut flip_normals = false;
        let mut flip_tex_coords = true;
        let mut to_world = Mat4::IDENTITY;
        let mut center = Vec3::ZERO;
        let mut radius = 1.0f32;
        let (mut p0, mut p1) = (Vec3::ZERO, Vec3::Z);
        let mut material = None;
        let mut emission = None;
        for child in elements(node) {
            match (self.tag(child), self.name(child).as_deref()) {
                ("string", Some("filename")) if ty == "obj" => filename = Some(self.string(child)?),
                ("boolean", Some("face_normals")) if ty == "obj" => face_normals = self.boolean(child)?,
                ("boolean", Some("flip_tex_coords")) if ty == "obj" => flip_tex_coords = self.boolean(child)?,
                ("boolean", Some("flip_normals")) => flip_normals = self.boolean(child)?,
                ("transform", Some("to_world")) => to_world = self.transform(child)?,
                ("point", Some("center")) if ty == "sphere" => center = self.xyz(child, 0.0)?,
                ("float", Some("radius")) if ty == "sphere" || ty == "cylinder" => {
                    radius = self.float(child)?;
                    if !(radius > 0.0 && radius.is_finite()) {
                        return Err(self.err(child, format!("{ty} radius {radius} must be positive")));
                    }
                }
                ("point", Some("p0")) if ty == "cylinder" => p0 = self.xyz(child, 0.0)?,
                ("point", Some("p1")) if ty == "cylinder" => p1 = self.xyz(child, 0.0)?,
                ("ref", _) => material = Some(self.bsdf_ref(child)?),
                ("bsdf", _) => material = Some(self.bsdf(child)?),
                ("emitter", _) => emission = self.area_emitter(child)?,
                _ => self.ignored(child, &ctx),
            }
        }
        let name = match (node.attribute("id"), &filename) {
            (Some(id), _) => id.to_string(),
            (None, Some(f)) => f.clone(),
            (None, None) => format!("{ty} #{index}"),
        };
        // An analytic shape's object space, placed as Mitsuba places it: a sphere's centre and radius,
        // a cylinder's end points and radius come before `to_world`.
        let kind = match ty.as_str() {
            "sphere" => Some(ShapeKind::Sphere),
            "disk" => Some(ShapeKind::Disk),
            "rectangle" => Some(ShapeKind::Rectangle),
            "cylinder" => Some(ShapeKind::Cylinder),
            "cube" => Some(ShapeKind::Cube),
            _ => None,
        };
        let placement = match ty.as_str() {
            "sphere" => to_world * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius)),
            "cylinder" => {
                let axis = p1 - p0;
                let length = axis.length();
                if !(length > 0.0 && length.is_finite()) {
                    return Err(self.err(node, format!("cylinder '{name}': p0 and p1 coincide")));
                }
                let (s, t) = shapes::coordinate_system(axis / length);
                let frame = Mat4::from_cols(s.extend(0.0), t.extend(0.0), (axis / length).extend(0.0), Vec4::W);
                to_world * Mat4::from_translation(p0) * frame * Mat4::from_scale(Vec3::new(radius, radius, length))
            }
            _ => to_world,
        };
        // Mitsuba turns a sphere or cylinder whose placement mirrors inside out.
        let mirrors = glam::Mat3::from_mat4(placement).determinant() < 0.0;
        let flip = flip_normals ^ (mirrors && matches!(ty.as_str(), "sphere" | "cylinder"));
        let analytic = kind.filter(|&k| Analytic::placement_is_exact(k, &placement)).map(|kind| Analytic {
            kind,
            to_world: placement,
            flip_normals: flip,
        });
        if let Some(kind) = kind
            && analytic.is_none()
            && glam::Mat3::from_mat4(placement).determinant() != 0.0
        {
            self.warn(
                node,
                format!(
                    "shape '{name}': its to_world {} so the {} is tessellated (exact only for {})",
                    if kind == ShapeKind::Sphere {
                        "scales unevenly or shears"
                    } else {
                        "scales x and y unevenly or shears"
                    },
                    kind.name(),
                    if kind == ShapeKind::Sphere {
                        "a similarity"
                    } else {
                        "the same scale on x and y, z perpendicular"
                    },
                ),
            );
        }
        let mut geometry = match ty.as_str() {
            "rectangle" => shapes::rectangle(),
            "cube" => shapes::cube(),
            "disk" => shapes::disk(),
            "sphere" => shapes::sphere(Vec3::ZERO, 1.0),
            "cylinder" => shapes::cylinder(),
            _ => {
                let filename =
                    filename.ok_or_else(|| self.err(node, "an obj shape needs <string name=\"filename\">"))?;
                let file = self.referenced(node, &filename)?;
                match hush_io::describe_unreadable(&file) {
                    Some(hush_io::Unreadable::Missing) => {
                        self.warn(
                            node,
                            format!("shape '{name}': mesh file {} not found: the shape is skipped", file.display()),
                        );
                        return Ok(ShapeResult::Missing(filename));
                    }
                    Some(why) => {
                        return Err(self.err(node, format!("shape '{name}': mesh file {} {why}", file.display())));
                    }
                    None => {}
                }
                let obj =
                    crate::obj::read_obj(&file, false).map_err(|e| self.err(node, format!("shape '{name}': {e}")))?;
                for w in obj.warnings {
                    self.warn(node, w);
                }
                let mut g = crate::obj::merge(obj.objects);
                if face_normals {
                    g.normals = None;
                }
                if !flip_tex_coords && let Some(uvs) = &mut g.uvs {
                    uvs.iter_mut().for_each(|uv| uv.y = 1.0 - uv.y);
                }
                g
            }
        };
        geometry.transform(&placement, ty != "obj");
        if flip {
            geometry.flip();
        }
        let dropped = geometry.check().map_err(|m| self.err(node, format!("shape '{name}': {m}")))?;
        if dropped > 0 {
            self.warn(node, format!("shape '{name}': dropped {dropped} degenerate (zero-area) triangles"));
        }
        if geometry.indices.is_empty() {
            if emission.is_some() {
                return Err(self.err(
                    node,
                    format!("shape '{name}' is an area light of zero area: fix its transform or remove its emitter"),
                ));
            }
            self.warn(node, format!("shape '{name}' has zero area and is skipped"));
            return Ok(ShapeResult::Skipped);
        }
        Ok(ShapeResult::Mesh(Box::new(Mesh {
            name,
            positions: geometry.positions,
            normals: geometry.normals,
            uvs: geometry.uvs,
            indices: geometry.indices,
            material: material.unwrap_or(Material::DEFAULT),
            emission,
            analytic,
        })))
    }

    /// An emitter attached to a shape: `area` gives its radiance; others are ignored with a warning.
    fn area_emitter(&mut self, node: Node) -> Result<Option<Vec3>, SceneError> {
        let ty = self.attr(node, "type")?;
        if ty != "area" {
            self.warn(node, format!("emitter '{ty}' on a shape is not supported: the shape does not emit"));
            return Ok(None);
        }
        let mut radiance = None;
        for child in elements(node) {
            match self.name(child).as_deref() {
                Some("radiance") => radiance = Some(self.constant_color(child, "radiance")?),
                _ => self.ignored(child, "<emitter type=\"area\">"),
            }
        }
        let radiance = radiance.ok_or_else(|| self.err(node, "an area emitter needs a 'radiance'"))?;
        if radiance.min_element() < 0.0 {
            return Err(self.err(node, format!("radiance {radiance} is negative")));
        }
        Ok(Some(radiance))
    }

    /// A top-level emitter: `constant` or `envmap`; other kinds are ignored with a warning.
    fn environment(&mut self, node: Node) -> Result<Option<Environment>, SceneError> {
        let ty = self.attr(node, "type")?;
        let ctx = format!("<emitter type=\"{ty}\">");
        match ty.as_str() {
            "constant" => {
                let mut radiance = Vec3::ONE;
                for child in elements(node) {
                    match self.name(child).as_deref() {
                        Some("radiance") => radiance = self.constant_color(child, "radiance")?,
                        _ => self.ignored(child, &ctx),
                    }
                }
                if radiance.min_element() < 0.0 {
                    return Err(self.err(node, format!("radiance {radiance} is negative")));
                }
                Ok(Some(Environment::Constant { radiance }))
            }
            "envmap" => {
                let mut filename = None;
                let mut scale = 1.0;
                let mut to_world = Mat4::IDENTITY;
                for child in elements(node) {
                    match (self.tag(child), self.name(child).as_deref()) {
                        ("string", Some("filename")) => filename = Some(self.string(child)?),
                        ("float", Some("scale")) => scale = self.float(child)?,
                        ("transform", Some("to_world")) => to_world = self.transform(child)?,
                        _ => self.ignored(child, &ctx),
                    }
                }
                let filename = filename.ok_or_else(|| self.err(node, "an envmap needs <string name=\"filename\">"))?;
                if scale < 0.0 {
                    return Err(self.err(node, format!("envmap scale {scale} is negative")));
                }
                let file = self.referenced(node, &filename)?;
                let px = match read_image(&file, false) {
                    Ok(px) => px,
                    Err(e) => {
                        self.warn(node, format!("{e}: the environment map is left out"));
                        return Ok(None);
                    }
                };
                if let Some(i) = px.data.iter().position(|v| *v < 0.0) {
                    return Err(
                        self.err(node, format!("environment map {} has a negative value at index {i}", file.display()))
                    );
                }
                Ok(Some(Environment::Map(EnvMap {
                    path: file,
                    width: px.width,
                    height: px.height,
                    data: px.data,
                    scale,
                    to_world,
                })))
            }
            _ => {
                self.warn(node, format!("emitter '{ty}' is not supported yet: it is left out"));
                Ok(None)
            }
        }
    }
}

enum ShapeResult {
    Mesh(Box<Mesh>),
    /// The mesh file is missing (a warning names it).
    Missing(String),
    Skipped,
}

/// Mitsuba's `lookat`: a frame at `origin` with local +z towards `target` and local +y along `up`.
fn lookat(origin: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - origin).normalize_or_zero();
    let left = up.cross(dir).normalize_or_zero();
    if dir == Vec3::ZERO || left == Vec3::ZERO {
        return None;
    }
    let new_up = dir.cross(left);
    Some(Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0)))
}

#[cfg(test)]
mod tests {
    #[test]
    fn snake_case_follows_mitsuba_2() {
        for (a, b) in [
            ("toWorld", "to_world"),
            ("intIOR", "int_ior"),
            ("maxDepth", "max_depth"),
            ("high_quality_edges", "high_quality_edges"),
        ] {
            assert_eq!(super::snake_case(a), b);
        }
    }
}
