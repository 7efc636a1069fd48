//! Seeded procedural scenes: rooms of random size with windows and doors cut into their walls,
//! furniture-like primitives (boxes, tables, shelves, spheres, cylinders, optionally meshes
//! borrowed from other scenes), random materials and random lights, written as Mitsuba 3 XML
//! that [`Scene::load`](crate::Scene::load) reads back without a warning.
//!
//! [`generate`] is pure: it returns the XML text and the assets the XML names (texture and
//! environment PNGs), to be written next to the scene file by the caller. The
//! same seed and options give byte-identical output on every platform: every number comes from
//! a SplitMix64 stream through IEEE-exact f32 arithmetic (no transcendental function reaches the
//! XML; rotations are written as angles for the loader) and is printed rounded.
//!
//! [`Ingredients`] says what the generator may use. The default, [`Ingredients::KERNEL`], is what
//! hush's path tracer renders today (diffuse, smooth and rough conductors, smooth plastic,
//! smooth and thin dielectrics, area lights); [`Ingredients::ALL`] adds rough dielectrics, rough
//! plastic, bitmap textures and environment emitters (`constant`, `envmap`).
//!
//! Every room has a style drawn from its seed: `standard` (mixed materials and lights),
//! `dark` (dark surfaces, one dim small light), `glass` (most objects glass) and `spotlit`
//! (lit mostly by tiny, very bright lights, the source of fireflies). [`GeneratorOptions::style`]
//! can ask for one instead, or for `open`: no room, objects on a ground plane under a sky, sometimes
//! with a small, very bright sun and bulbs in view.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::Vec3;
use hush_hash::SplitMix64;

use crate::PixelFilter;

/// Bumped whenever the same seed and options would give a different scene.
pub const GENERATOR_VERSION: u32 = 3;

/// What the generator may put into a scene beyond what hush's kernel renders today.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ingredients {
    /// `roughdielectric` (frosted glass).
    pub rough_dielectric: bool,
    /// `roughplastic`.
    pub rough_plastic: bool,
    /// `bitmap` textures on diffuse surfaces (generated PNGs).
    pub textures: bool,
    /// `constant` and `envmap` emitters (the envmap is a generated PNG sky).
    pub environment: bool,
}

impl Ingredients {
    /// None of the optional ingredients: smooth glass, glossy metal, plastic and diffuse surfaces lit by area
    /// lights (generator version 1's default).
    pub const BASIC: Ingredients =
        Ingredients { rough_dielectric: false, rough_plastic: false, textures: false, environment: false };
    /// Everything the generator knows.
    pub const ALL: Ingredients =
        Ingredients { rough_dielectric: true, rough_plastic: true, textures: true, environment: true };
    /// What hush's path tracer renders: since generator version 2, everything.
    pub const KERNEL: Ingredients = Ingredients::ALL;
    /// The names accepted by [`Ingredients::parse`] for the single ingredients.
    pub const NAMES: [&'static str; 4] = ["roughdielectric", "roughplastic", "textures", "environment"];

    /// `default` or `""` (= [`Ingredients::KERNEL`]), `all`, `basic` (= [`Ingredients::BASIC`]), or a
    /// comma-separated list of [`Ingredients::NAMES`]: the basic set plus those.
    pub fn parse(text: &str) -> Result<Ingredients, String> {
        if text.trim().is_empty() {
            return Ok(Ingredients::KERNEL);
        }
        let mut f = Ingredients::BASIC;
        for word in text.split(',').map(str::trim).filter(|w| !w.is_empty()) {
            match word {
                "default" | "kernel" => f = Ingredients::KERNEL,
                "all" => f = Ingredients::ALL,
                "basic" => f = Ingredients::BASIC,
                "roughdielectric" => f.rough_dielectric = true,
                "roughplastic" => f.rough_plastic = true,
                "textures" => f.textures = true,
                "environment" => f.environment = true,
                other => {
                    return Err(format!(
                        "unknown generator ingredient '{other}': use default (= all), basic, or a list of {}",
                        Ingredients::NAMES.join(", ")
                    ));
                }
            }
        }
        Ok(f)
    }

    /// The inverse of [`Ingredients::parse`]: `default`, `basic` or the list of enabled ingredients.
    pub fn describe(&self) -> String {
        if *self == Ingredients::KERNEL {
            return "default".into();
        }
        if *self == Ingredients::BASIC {
            return "basic".into();
        }
        let on = [self.rough_dielectric, self.rough_plastic, self.textures, self.environment];
        Ingredients::NAMES.iter().zip(on).filter(|(_, on)| *on).map(|(n, _)| *n).collect::<Vec<_>>().join(",")
    }
}

/// How to generate: which ingredients, the film size, and where meshes may be borrowed from.
#[derive(Clone, Debug)]
pub struct GeneratorOptions {
    pub ingredients: Ingredients,
    pub width: u32,
    pub height: u32,
    /// A folder of scenes (such as `../shared/scenes`): small OBJ meshes below its `*/models/` folders
    /// may be placed as furniture, each copied beside the scene as an asset (`borrowed-<k>.obj`, its `mtllib`
    /// lines dropped). Ignored when the folder is absent.
    pub borrow_meshes: Option<PathBuf>,
    /// The style every scene has; `None`: each room draws its own from its seed (standard, dark, glass or
    /// spotlit). The seed's draw is made either way, so a room asked for in its own style is the room.
    pub style: Option<Style>,
    /// The film's pixel filter (rooms of the dataset: box, as OIDN's training data). Another filter
    /// correlates the noise of neighbouring pixels, and turns a firefly into a blob of several pixels.
    pub filter: PixelFilter,
    /// The surface of a room's ceiling panels and lamps where they do not emit. The random draws are the
    /// same either way: a room with [`LightMaterial::Ceiling`] is the room with [`LightMaterial::Black`]
    /// whose ceiling lights look like the ceiling around them.
    pub light_material: LightMaterial,
}

/// What a room's ceiling panels and lamps are made of (bulbs and suns stay black).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightMaterial {
    /// Black: a light seen directly has albedo 0, so its edge shows in the albedo feature.
    #[default]
    Black,
    /// The ceiling's own material, as the Cornell box's light: albedo and normal show no edge where the light
    /// meets the ceiling, and only the colour tells them apart.
    Ceiling,
}

impl LightMaterial {
    pub const ALL: [LightMaterial; 2] = [LightMaterial::Black, LightMaterial::Ceiling];

    pub fn name(self) -> &'static str {
        match self {
            LightMaterial::Black => "black",
            LightMaterial::Ceiling => "ceiling",
        }
    }

    /// The light material named `name` ([`LightMaterial::name`]).
    pub fn parse(name: &str) -> Option<LightMaterial> {
        LightMaterial::ALL.into_iter().find(|m| m.name() == name)
    }
}

impl GeneratorOptions {
    /// Rooms of `ingredients` (their style drawn from each seed, a box filter) on a film of `width` ×
    /// `height`, borrowing meshes from `borrow_meshes` if given.
    pub fn rooms(ingredients: Ingredients, width: u32, height: u32, borrow_meshes: Option<PathBuf>) -> Self {
        GeneratorOptions { ingredients, width, height, borrow_meshes, ..Default::default() }
    }
}

impl Default for GeneratorOptions {
    fn default() -> Self {
        GeneratorOptions {
            ingredients: Ingredients::KERNEL,
            width: 256,
            height: 256,
            borrow_meshes: None,
            style: None,
            filter: PixelFilter::Box,
            light_material: LightMaterial::Black,
        }
    }
}

/// A file the scene names, to be written next to it.
#[derive(Clone, Debug, PartialEq)]
pub struct Asset {
    /// File name relative to the scene file.
    pub file: String,
    pub bytes: Vec<u8>,
}

/// The broad kind of a surface, for reporting a dataset's material mix.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MaterialClass {
    Diffuse,
    /// Rough conductors and (rough) plastic.
    Glossy,
    Mirror,
    Glass,
    /// Diffuse with a bitmap texture.
    Textured,
}

impl MaterialClass {
    pub const ALL: [MaterialClass; 5] = [
        MaterialClass::Diffuse,
        MaterialClass::Glossy,
        MaterialClass::Mirror,
        MaterialClass::Glass,
        MaterialClass::Textured,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MaterialClass::Diffuse => "diffuse",
            MaterialClass::Glossy => "glossy",
            MaterialClass::Mirror => "mirror",
            MaterialClass::Glass => "glass",
            MaterialClass::Textured => "textured",
        }
    }
}

/// The kind of a light, for reporting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LightKind {
    /// A ceiling panel of about a square metre.
    LargeArea,
    /// A small panel or disk.
    SmallArea,
    /// A tiny sphere of very high radiance.
    BrightSmall,
    /// A panel outside a window or door, facing in.
    Window,
    /// `constant` environment.
    Constant,
    /// `envmap` environment.
    EnvMap,
}

impl LightKind {
    pub const ALL: [LightKind; 6] = [
        LightKind::LargeArea,
        LightKind::SmallArea,
        LightKind::BrightSmall,
        LightKind::Window,
        LightKind::Constant,
        LightKind::EnvMap,
    ];

    pub fn name(self) -> &'static str {
        match self {
            LightKind::LargeArea => "large_area",
            LightKind::SmallArea => "small_area",
            LightKind::BrightSmall => "bright_small",
            LightKind::Window => "window",
            LightKind::Constant => "constant",
            LightKind::EnvMap => "envmap",
        }
    }
}

/// One `<shape>` of a generated scene, in document order.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeInfo {
    pub id: String,
    /// Mitsuba's plugin name of its BSDF (`diffuse`, `roughconductor`, ...), as [`crate::Material::kind`].
    pub bsdf: &'static str,
    pub class: MaterialClass,
    pub emitter: bool,
}

/// A generated scene: the XML, its assets and what it contains.
#[derive(Clone, Debug)]
pub struct GeneratedScene {
    pub seed: u64,
    pub style: &'static str,
    pub xml: String,
    pub assets: Vec<Asset>,
    pub shapes: Vec<ShapeInfo>,
    pub lights: Vec<LightKind>,
}

impl GeneratedScene {
    /// The material class of every non-emitting shape.
    pub fn material_classes(&self) -> Vec<MaterialClass> {
        self.shapes.iter().filter(|s| !s.emitter).map(|s| s.class).collect()
    }
}

/// The seed of attempt `attempt` of scene `index` of a run seeded with `seed` (attempts follow
/// a rejected scene).
pub fn scene_seed(seed: u64, index: u64, attempt: u64) -> u64 {
    let mut r = Rng(SplitMix64(seed ^ 0x6875_7368_7363_6e65));
    let a = r.next_u64() ^ index.wrapping_mul(SplitMix64::GOLDEN);
    let mut r = Rng(SplitMix64(a));
    r.next_u64() ^ attempt.wrapping_mul(0xD1B5_4A32_D192_ED03)
}

/// Generates the scene of `seed`.
pub fn generate(seed: u64, options: &GeneratorOptions) -> GeneratedScene {
    let mut g = Gen::new(seed, options);
    g.scene();
    g.finish()
}

/// hush-hash's SplitMix64 with the draws the generator needs.
struct Rng(SplitMix64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1), a multiple of 2^-24 (exact in f32).
    fn unit(&mut self) -> f32 {
        self.0.next_f32()
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }

    /// An index drawn in proportion to `weights`.
    fn weighted(&mut self, weights: &[f32]) -> usize {
        let total: f32 = weights.iter().sum();
        let mut x = self.unit() * total;
        for (i, w) in weights.iter().enumerate() {
            if x < *w {
                return i;
            }
            x -= w;
        }
        weights.iter().rposition(|w| *w > 0.0).unwrap_or(0)
    }

    /// A color with each channel in [lo, hi).
    fn color(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// A number for the XML: 4 decimals, no negative zero.
fn num(x: f32) -> String {
    let s = format!("{x:.4}");
    let t = s.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" || t.is_empty() { "0".into() } else { t.to_string() }
}

fn v3(v: Vec3) -> String {
    format!("{}, {}, {}", num(v.x), num(v.y), num(v.z))
}

/// A scene's style. Rooms draw theirs from the seed ([`GeneratorOptions::style`] `None`); `Open` is only
/// ever asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Mixed materials and lights.
    Standard,
    /// Dark surfaces, one dim small light.
    Dark,
    /// Most objects glass.
    Glass,
    /// Lit mostly by tiny, very bright lights, the source of fireflies.
    Spotlit,
    /// No room: objects on a ground plane under a sky (`constant` or `envmap`; an overcast panel high
    /// above without the environment ingredient), sometimes with a small, very bright sun and bulbs in
    /// view.
    Open,
    /// Lights in view, as in Veach's multiple-importance scene: spheres and disks of every size from a
    /// fraction of a pixel (on a film with a wide filter) to a fifth of the frame, the smaller the brighter
    /// (radiance up to hundreds of thousands), above glossy plates of several roughnesses that reflect them
    /// toward the camera, against a dark or dim backdrop. Their rims (a very bright disk meeting a dark or
    /// noisy surround) and their glossy reflections are what a denoiser without auxiliary features must
    /// keep sharp.
    Lamps,
}

impl Style {
    /// Every style, by name.
    pub const ALL: [Style; 6] = [Style::Standard, Style::Dark, Style::Glass, Style::Spotlit, Style::Open, Style::Lamps];

    pub fn name(self) -> &'static str {
        match self {
            Style::Standard => "standard",
            Style::Dark => "dark",
            Style::Glass => "glass",
            Style::Spotlit => "spotlit",
            Style::Open => "open",
            Style::Lamps => "lamps",
        }
    }

    /// The style named `name` ([`Style::name`]).
    pub fn parse(name: &str) -> Option<Style> {
        Style::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// A footprint on the floor that other objects keep clear of.
struct Footprint {
    x: f32,
    z: f32,
    r: f32,
}

struct Gen<'a> {
    rng: Rng,
    seed: u64,
    options: &'a GeneratorOptions,
    style: Style,
    room: Vec3,
    camera: Vec3,
    body: String,
    bsdfs: String,
    assets: Vec<Asset>,
    shapes: Vec<ShapeInfo>,
    lights: Vec<LightKind>,
    footprints: Vec<Footprint>,
    materials: usize,
    environment: Option<String>,
    borrowable: Vec<(PathBuf, Vec3, Vec3)>,
    /// The ceiling's material, once the room's shell is built.
    ceiling: Option<Bsdf>,
}

/// A BSDF written into the XML, with what it is.
#[derive(Clone)]
struct Bsdf {
    id: String,
    kind: &'static str,
    class: MaterialClass,
}

impl<'a> Gen<'a> {
    fn new(seed: u64, options: &'a GeneratorOptions) -> Self {
        let mut rng = Rng(SplitMix64(seed));
        let drawn = match rng.weighted(&[0.55, 0.15, 0.15, 0.15]) {
            0 => Style::Standard,
            1 => Style::Dark,
            2 => Style::Glass,
            _ => Style::Spotlit,
        };
        let style = options.style.unwrap_or(drawn);
        Gen {
            rng,
            seed,
            options,
            style,
            room: Vec3::ONE,
            camera: Vec3::ZERO,
            body: String::new(),
            bsdfs: String::new(),
            assets: Vec::new(),
            shapes: Vec::new(),
            lights: Vec::new(),
            footprints: Vec::new(),
            materials: 0,
            environment: None,
            borrowable: options.borrow_meshes.as_deref().map(borrowable_meshes).unwrap_or_default(),
            ceiling: None,
        }
    }

    fn scene(&mut self) {
        match self.style {
            Style::Open => return self.open_scene(),
            Style::Lamps => return self.lamps_scene(),
            _ => {}
        }
        let r = &mut self.rng;
        self.room = Vec3::new(r.range(3.0, 9.0), r.range(2.4, 4.0), r.range(3.0, 9.0));
        let room = self.room;
        // The camera stands near the z = 0 wall and looks into the room.
        self.camera = Vec3::new(
            r.range(0.25, 0.75) * room.x,
            r.range(1.0, (room.y - 0.4).min(1.8)),
            r.range(0.3, 0.9).min(0.2 * room.z),
        );
        let target = Vec3::new(r.range(0.2, 0.8) * room.x, r.range(0.4, 1.4), r.range(0.55, 0.95) * room.z);
        let fov = r.range(40.0, 75.0);
        self.footprints.push(Footprint { x: self.camera.x, z: self.camera.z, r: 0.5 });

        self.room_shell();
        self.lights_inside();
        self.furniture();
        self.environment_light();
        self.write_header(target, fov);
    }

    fn write_header(&mut self, target: Vec3, fov: f32) {
        let o = self.options;
        let mut head = String::new();
        let _ = writeln!(head, "<?xml version=\"1.0\" encoding=\"utf-8\"?>");
        let _ = writeln!(
            head,
            "<!-- hush procedural scene: generator {GENERATOR_VERSION}, seed {}, style {}, features {}{} -->",
            self.seed,
            self.style.name(),
            o.ingredients.describe(),
            match o.light_material {
                LightMaterial::Black => String::new(),
                m => format!(", lights {}", m.name()),
            }
        );
        let _ = writeln!(head, "<scene version=\"3.0.0\">");
        let _ = writeln!(head, "  <integrator type=\"path\"><integer name=\"max_depth\" value=\"8\"/></integrator>");
        let _ = writeln!(head, "  <sensor type=\"perspective\">");
        let _ = writeln!(head, "    <float name=\"fov\" value=\"{}\"/>", num(fov));
        let _ = writeln!(head, "    <string name=\"fov_axis\" value=\"y\"/>");
        let _ = writeln!(
            head,
            "    <transform name=\"to_world\"><lookat origin=\"{}\" target=\"{}\" up=\"0, 1, 0\"/></transform>",
            v3(self.camera),
            v3(target)
        );
        let _ =
            writeln!(head, "    <sampler type=\"independent\"><integer name=\"sample_count\" value=\"64\"/></sampler>");
        let rfilter = match o.filter {
            PixelFilter::Box => "<rfilter type=\"box\"/>".to_string(),
            PixelFilter::Tent { radius } => {
                format!("<rfilter type=\"tent\"><float name=\"radius\" value=\"{}\"/></rfilter>", num(radius))
            }
            PixelFilter::Gaussian { stddev } => {
                format!("<rfilter type=\"gaussian\"><float name=\"stddev\" value=\"{}\"/></rfilter>", num(stddev))
            }
        };
        let _ = writeln!(
            head,
            "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"{}\"/><integer name=\"height\" value=\"{}\"/>\
             {rfilter}</film>",
            o.width.max(1),
            o.height.max(1)
        );
        let _ = writeln!(head, "  </sensor>");
        head.push_str(&self.bsdfs);
        head.push_str(&self.body);
        if let Some(env) = &self.environment {
            head.push_str(env);
        }
        head.push_str("</scene>\n");
        self.body = head;
    }

    fn finish(self) -> GeneratedScene {
        GeneratedScene {
            seed: self.seed,
            style: self.style.name(),
            xml: self.body,
            assets: self.assets,
            shapes: self.shapes,
            lights: self.lights,
        }
    }

    // ---- materials ----

    fn bsdf(&mut self, kind: &'static str, class: MaterialClass, params: &str, two_sided: bool) -> Bsdf {
        let id = format!("bsdf{}", self.materials);
        self.materials += 1;
        let inner = format!("<bsdf type=\"{kind}\">{params}</bsdf>");
        let _ = if two_sided {
            writeln!(self.bsdfs, "  <bsdf type=\"twosided\" id=\"{id}\">{inner}</bsdf>")
        } else {
            writeln!(self.bsdfs, "  {}", inner.replacen("<bsdf ", &format!("<bsdf id=\"{id}\" "), 1))
        };
        Bsdf { id, kind, class }
    }

    fn diffuse(&mut self, albedo: Vec3) -> Bsdf {
        let p = format!("<rgb name=\"reflectance\" value=\"{}\"/>", v3(albedo));
        self.bsdf("diffuse", MaterialClass::Diffuse, &p, true)
    }

    /// A GGX `roughconductor` of a named metal.
    fn rough_conductor(&mut self, metal: &str, alpha: f32) -> Bsdf {
        let p = format!(
            "<string name=\"material\" value=\"{metal}\"/><float name=\"alpha\" value=\"{}\"/>\
             <string name=\"distribution\" value=\"ggx\"/>",
            num(alpha)
        );
        self.bsdf("roughconductor", MaterialClass::Glossy, &p, true)
    }

    /// A GGX `roughplastic` of diffuse colour `c` (with Mitsuba's interior IOR unless `ior` is given).
    fn rough_plastic(&mut self, c: Vec3, ior: Option<f32>, alpha: f32) -> Bsdf {
        let mut p = format!("<rgb name=\"diffuse_reflectance\" value=\"{}\"/>", v3(c));
        if let Some(ior) = ior {
            let _ = write!(p, "<float name=\"int_ior\" value=\"{}\"/>", num(ior));
        }
        let _ =
            write!(p, "<float name=\"alpha\" value=\"{}\"/><string name=\"distribution\" value=\"ggx\"/>", num(alpha));
        self.bsdf("roughplastic", MaterialClass::Glossy, &p, true)
    }

    /// A diffuse surface with a generated texture (checks, stripes or tiles of two colors).
    fn textured(&mut self, a: Vec3, b: Vec3) -> Bsdf {
        let file = format!("texture{}.png", self.assets.len());
        let pattern = self.rng.below(3);
        let cells = [2u32, 4, 8][self.rng.below(3)];
        let size = 64u32;
        let mut rgb = Vec::with_capacity((size * size * 3) as usize);
        for y in 0..size {
            for x in 0..size {
                let (cx, cy) = (x * cells / size, y * cells / size);
                let pick = match pattern {
                    0 => (cx + cy) % 2 == 0,
                    1 => cx % 2 == 0,
                    _ => x % (size / cells) > 1 && y % (size / cells) > 1,
                };
                let c = if pick { a } else { b };
                rgb.extend([c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8));
            }
        }
        self.assets.push(Asset { file: file.clone(), bytes: png(size, size, rgb) });
        let p = format!(
            "<texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"{file}\"/></texture>"
        );
        self.bsdf("diffuse", MaterialClass::Textured, &p, true)
    }

    /// A random surface for an object; `glass_bias` raises the odds of glass.
    fn random_material(&mut self, glass_bias: f32) -> Bsdf {
        let f = self.options.ingredients;
        let dark = self.style == Style::Dark;
        let weights = [
            3.0,                                     // diffuse
            1.5,                                     // rough conductor
            1.0,                                     // smooth plastic
            if f.rough_plastic { 1.0 } else { 0.0 }, // rough plastic
            0.6,                                     // mirror
            1.0 + glass_bias,                        // smooth glass
            if f.rough_dielectric { 0.5 + glass_bias * 0.5 } else { 0.0 },
            if f.textures { 1.0 } else { 0.0 },
        ];
        let (lo, hi) = if dark { (0.02, 0.25) } else { (0.05, 0.85) };
        match self.rng.weighted(&weights) {
            0 => {
                let c = self.rng.color(lo, hi);
                self.diffuse(c)
            }
            1 => {
                let metal = ["Au", "Cu", "Al", "Ag", "Cr"][self.rng.below(5)];
                let alpha = self.rng.range(0.03, 0.4);
                self.rough_conductor(metal, alpha)
            }
            k @ (2 | 3) => {
                let c = self.rng.color(lo, hi);
                let ior = self.rng.range(1.4, 1.6);
                if k == 3 {
                    let alpha = self.rng.range(0.05, 0.4);
                    self.rough_plastic(c, Some(ior), alpha)
                } else {
                    let p = format!(
                        "<rgb name=\"diffuse_reflectance\" value=\"{}\"/><float name=\"int_ior\" value=\"{}\"/>",
                        v3(c),
                        num(ior)
                    );
                    self.bsdf("plastic", MaterialClass::Glossy, &p, true)
                }
            }
            4 => {
                let tint = self.rng.color(0.7, 1.0);
                let p = format!(
                    "<string name=\"material\" value=\"none\"/><rgb name=\"specular_reflectance\" value=\"{}\"/>",
                    v3(tint)
                );
                self.bsdf("conductor", MaterialClass::Mirror, &p, true)
            }
            5 => {
                let ior = self.rng.range(1.33, 1.7);
                let tint = if self.rng.chance(0.3) { self.rng.color(0.5, 1.0) } else { Vec3::ONE };
                let p = format!(
                    "<float name=\"int_ior\" value=\"{}\"/><rgb name=\"specular_transmittance\" value=\"{}\"/>",
                    num(ior),
                    v3(tint)
                );
                self.bsdf("dielectric", MaterialClass::Glass, &p, false)
            }
            6 => {
                let p = format!(
                    "<float name=\"int_ior\" value=\"{}\"/><float name=\"alpha\" value=\"{}\"/>\
                     <string name=\"distribution\" value=\"ggx\"/>",
                    num(self.rng.range(1.33, 1.7)),
                    num(self.rng.range(0.05, 0.3))
                );
                self.bsdf("roughdielectric", MaterialClass::Glass, &p, false)
            }
            _ => {
                let (a, b) = (self.rng.color(lo, hi), self.rng.color(lo, hi));
                self.textured(a, b)
            }
        }
    }

    /// A surface for a wall, the floor or the ceiling: mostly diffuse.
    fn surface_material(&mut self) -> Bsdf {
        let (lo, hi) = if self.style == Style::Dark { (0.02, 0.2) } else { (0.2, 0.85) };
        if self.options.ingredients.textures && self.rng.chance(0.3) {
            let (a, b) = (self.rng.color(lo, hi), self.rng.color(lo, hi));
            return self.textured(a, b);
        }
        if self.rng.chance(0.15) {
            let c = self.rng.color(lo, hi);
            let p = format!("<rgb name=\"diffuse_reflectance\" value=\"{}\"/>", v3(c));
            return self.bsdf("plastic", MaterialClass::Glossy, &p, true);
        }
        let grey = self.rng.range(lo, hi);
        let c = Vec3::splat(grey) * self.rng.color(0.8, 1.0);
        self.diffuse(c)
    }

    // ---- shapes ----

    fn shape(&mut self, ty: &str, name: &str, transform: &str, bsdf: &Bsdf, extra: &str, emission: Option<Vec3>) {
        let id = format!("{name}{}", self.shapes.len());
        let _ = write!(self.body, "  <shape type=\"{ty}\" id=\"{id}\">{extra}");
        let _ = write!(self.body, "<transform name=\"to_world\">{transform}</transform><ref id=\"{}\"/>", bsdf.id);
        if let Some(e) = emission {
            let _ = write!(self.body, "<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>", v3(e));
        }
        let _ = writeln!(self.body, "</shape>");
        self.shapes.push(ShapeInfo { id, bsdf: bsdf.kind, class: bsdf.class, emitter: emission.is_some() });
    }

    /// A rectangle centred at `c` spanning ±`u` and ±`v`, its front facing `facing`.
    fn rectangle(&mut self, name: &str, c: Vec3, [u, v]: [Vec3; 2], facing: Vec3, bsdf: &Bsdf, emission: Option<Vec3>) {
        let v = if u.cross(v).dot(facing) < 0.0 { -v } else { v };
        let n = u.cross(v).normalize();
        self.shape("rectangle", name, &basis_matrix(u, v, n, c), bsdf, "", emission);
    }

    /// `scale`, then a turn about +y by `angle` degrees, then `translate`.
    fn placed(scale: Vec3, angle: f32, at: Vec3) -> String {
        let mut t = format!("<scale value=\"{}\"/>", v3(scale));
        if angle != 0.0 {
            let _ = write!(t, "<rotate y=\"1\" angle=\"{}\"/>", num(angle));
        }
        let _ = write!(t, "<translate value=\"{}\"/>", v3(at));
        t
    }

    fn room_shell(&mut self) {
        let room = self.room;
        let (w, h, d) = (room.x, room.y, room.z);
        let floor = self.surface_material();
        let half = Vec3::new(w / 2.0, 0.0, d / 2.0);
        self.rectangle("floor", half, [Vec3::X * half.x, Vec3::Z * half.z], Vec3::Y, &floor, None);
        let ceiling = self.surface_material();
        self.rectangle("ceiling", half + Vec3::Y * h, [Vec3::X * half.x, Vec3::Z * half.z], -Vec3::Y, &ceiling, None);
        self.ceiling = Some(ceiling);
        let wall = self.surface_material();
        // Walls: (corner, direction along the wall, length, inward normal).
        let walls = [
            (Vec3::ZERO, Vec3::X, w, Vec3::Z),
            (Vec3::new(0.0, 0.0, d), Vec3::X, w, -Vec3::Z),
            (Vec3::ZERO, Vec3::Z, d, Vec3::X),
            (Vec3::new(w, 0.0, 0.0), Vec3::Z, d, -Vec3::X),
        ];
        let openings = match self.style {
            Style::Dark => self.rng.below(2),
            _ => self.rng.below(4),
        };
        let mut with_opening = [false; 4];
        for _ in 0..openings {
            with_opening[self.rng.below(4)] = true;
        }
        for (k, &(p0, t, len, n)) in walls.iter().enumerate() {
            let wall_bsdf = if self.rng.chance(0.2) { self.surface_material() } else { wall.clone() };
            if !with_opening[k] || len < 1.6 {
                self.wall_piece(p0, t, n, [0.0, len], [0.0, h], &wall_bsdf);
                continue;
            }
            let door = self.rng.chance(0.35);
            let width = self.rng.range(0.7, (len - 0.6).min(2.5));
            let a0 = self.rng.range(0.3, len - 0.3 - width);
            let a1 = a0 + width;
            let (b0, b1) = if door {
                (0.0, self.rng.range(1.8, (h - 0.2).max(1.9)).min(h - 0.1))
            } else {
                let b0 = self.rng.range(0.6, 1.1);
                (b0, self.rng.range(b0 + 0.6, h - 0.2).max(b0 + 0.5).min(h - 0.1))
            };
            self.wall_piece(p0, t, n, [0.0, a0], [0.0, h], &wall_bsdf);
            self.wall_piece(p0, t, n, [a1, len], [0.0, h], &wall_bsdf);
            if b0 > 0.0 {
                self.wall_piece(p0, t, n, [a0, a1], [0.0, b0], &wall_bsdf);
            }
            self.wall_piece(p0, t, n, [a0, a1], [b1, h], &wall_bsdf);
            let centre = p0 + t * (a0 + a1) / 2.0 + Vec3::Y * (b0 + b1) / 2.0;
            let (hu, hv) = ((a1 - a0) / 2.0, (b1 - b0) / 2.0);
            // A glass pane in some windows (always in glass scenes).
            if !door && (self.style == Style::Glass || self.rng.chance(0.3)) {
                let p = "<float name=\"int_ior\" value=\"1.5\"/>";
                let pane = self.bsdf("thindielectric", MaterialClass::Glass, p, false);
                self.rectangle("pane", centre, [t * hu, Vec3::Y * hv], n, &pane, None);
            }
            // Daylight: a panel outside, facing in (not in dark scenes, not always).
            if self.style != Style::Dark && self.rng.chance(0.7) {
                let dist = self.rng.range(0.5, 2.5);
                let grow = 1.0 + dist;
                let sky = Vec3::new(0.55, 0.75, 1.0) * self.rng.range(0.7, 1.0) + self.rng.color(0.0, 0.3);
                let radiance = sky * self.rng.range(1.0, 8.0);
                let black = self.black();
                self.rectangle(
                    "daylight",
                    centre - n * dist,
                    [t * hu * grow, Vec3::Y * hv * grow],
                    n,
                    &black,
                    Some(radiance),
                );
                self.lights.push(LightKind::Window);
            }
        }
    }

    fn black(&mut self) -> Bsdf {
        self.diffuse(Vec3::ZERO)
    }

    /// The surface of a ceiling panel or lamp ([`GeneratorOptions::light_material`]).
    fn light_surface(&mut self) -> Bsdf {
        match (self.options.light_material, &self.ceiling) {
            (LightMaterial::Ceiling, Some(ceiling)) => ceiling.clone(),
            _ => self.black(),
        }
    }

    fn wall_piece(&mut self, p0: Vec3, t: Vec3, n: Vec3, a: [f32; 2], b: [f32; 2], bsdf: &Bsdf) {
        if a[1] - a[0] < 1e-3 || b[1] - b[0] < 1e-3 {
            return;
        }
        let c = p0 + t * (a[0] + a[1]) / 2.0 + Vec3::Y * (b[0] + b[1]) / 2.0;
        self.rectangle("wall", c, [t * (a[1] - a[0]) / 2.0, Vec3::Y * (b[1] - b[0]) / 2.0], n, bsdf, None);
    }

    /// A point on the ceiling at least `margin` from the walls.
    fn ceiling_point(&mut self, margin: f32) -> Vec3 {
        let room = self.room;
        Vec3::new(self.rng.range(margin, room.x - margin), room.y - 0.002, self.rng.range(margin, room.z - margin))
    }

    fn lights_inside(&mut self) {
        let warm = |r: &mut Rng| Vec3::new(1.0, r.range(0.75, 1.0), r.range(0.5, 0.95));
        let (large, small, bright) = match self.style {
            Style::Standard => (1 + self.rng.below(2), self.rng.below(3), self.rng.below(2)),
            Style::Glass => (1, self.rng.below(2), self.rng.below(3)),
            Style::Spotlit => (0, self.rng.below(2), 1 + self.rng.below(3)),
            Style::Dark => (0, 1, 0),
            // Open scenes have no room: `open_scene` and `lamps_scene` light them.
            Style::Open | Style::Lamps => (0, 0, 0),
        };
        for _ in 0..large {
            let (hx, hz) = (self.rng.range(0.3, 1.0), self.rng.range(0.3, 1.0));
            let c = self.ceiling_point(hx.max(hz) + 0.1);
            let radiance = warm(&mut self.rng) * self.rng.range(2.0, 12.0);
            let surface = self.light_surface();
            self.rectangle("panel", c, [Vec3::X * hx, Vec3::Z * hz], -Vec3::Y, &surface, Some(radiance));
            self.lights.push(LightKind::LargeArea);
        }
        for _ in 0..small {
            let size = self.rng.range(0.05, 0.2);
            let radiance = warm(&mut self.rng)
                * if self.style == Style::Dark { self.rng.range(3.0, 20.0) } else { self.rng.range(20.0, 200.0) };
            let surface = self.light_surface();
            if self.rng.chance(0.5) {
                let c = self.ceiling_point(size + 0.1);
                // A disk faces +z: turned about +x by 90° it faces down.
                let t = format!(
                    "<scale value=\"{}\"/><rotate x=\"1\" angle=\"90\"/><translate value=\"{}\"/>",
                    v3(Vec3::new(size, size, 1.0)),
                    v3(c)
                );
                self.shape("disk", "lamp", &t, &surface, "", Some(radiance));
            } else {
                let c = self.ceiling_point(size + 0.1);
                self.rectangle("lamp", c, [Vec3::X * size, Vec3::Z * size], -Vec3::Y, &surface, Some(radiance));
            }
            self.lights.push(LightKind::SmallArea);
        }
        for _ in 0..bright {
            let r = self.rng.range(0.02, 0.08);
            let room = self.room;
            let c = Vec3::new(
                self.rng.range(0.3, room.x - 0.3),
                self.rng.range(1.4, room.y - 0.2),
                self.rng.range(0.4, 0.9) * room.z,
            );
            let radiance = warm(&mut self.rng) * self.rng.range(300.0, 3000.0);
            self.bright_sphere("bulb", c, r, radiance);
        }
    }

    /// A small sphere of very high radiance (a bulb, a sun), black where it does not emit.
    fn bright_sphere(&mut self, name: &str, c: Vec3, r: f32, radiance: Vec3) {
        let black = self.black();
        let extra =
            format!("<point name=\"center\" value=\"{}\"/><float name=\"radius\" value=\"{}\"/>", v3(c), num(r));
        self.shape("sphere", name, "", &black, &extra, Some(radiance));
        self.lights.push(LightKind::BrightSmall);
    }

    /// Finds a free spot on the floor for an object of footprint radius `r`.
    fn free_spot(&mut self, r: f32) -> Option<(f32, f32)> {
        let room = self.room;
        if room.x < 2.0 * r + 0.2 || room.z < 2.0 * r + 0.2 {
            return None;
        }
        for _ in 0..24 {
            let x = self.rng.range(r + 0.1, room.x - r - 0.1);
            let z = self.rng.range(r + 0.1, room.z - r - 0.1);
            if self.footprints.iter().all(|f| (f.x - x).powi(2) + (f.z - z).powi(2) > (f.r + r + 0.05).powi(2)) {
                self.footprints.push(Footprint { x, z, r });
                return Some((x, z));
            }
        }
        None
    }

    fn furniture(&mut self) {
        let count = 2 + self.rng.below(7);
        let glass_bias = if self.style == Style::Glass { 6.0 } else { 0.0 };
        for _ in 0..count {
            let borrow = if self.borrowable.is_empty() { 0.0 } else { 1.0 };
            match self.rng.weighted(&[2.0, 1.5, 1.0, 2.0, 1.5, borrow]) {
                0 => self.a_box(glass_bias),
                1 => self.table(glass_bias),
                2 => self.shelf(glass_bias),
                3 => self.a_sphere(glass_bias, None),
                4 => self.a_cylinder(glass_bias),
                _ => self.borrowed(glass_bias),
            }
        }
    }

    fn a_box(&mut self, glass_bias: f32) {
        let half = Vec3::new(self.rng.range(0.15, 0.7), self.rng.range(0.15, 0.8), self.rng.range(0.15, 0.7));
        let angle = self.rng.range(0.0, 90.0);
        let Some((x, z)) = self.free_spot(half.x.max(half.z) * 1.42) else { return };
        let m = self.random_material(glass_bias);
        let t = Self::placed(half, angle, Vec3::new(x, half.y, z));
        self.shape("cube", "box", &t, &m, "", None);
    }

    fn table(&mut self, glass_bias: f32) {
        let (hx, hz) = (self.rng.range(0.4, 1.0), self.rng.range(0.3, 0.6));
        let height = self.rng.range(0.6, 0.95);
        let thick = self.rng.range(0.02, 0.05);
        let angle = [0.0, 90.0][self.rng.below(2)];
        let Some((x, z)) = self.free_spot(hx.max(hz) * 1.42) else { return };
        let top = self.random_material(glass_bias);
        let t = Self::placed(Vec3::new(hx, thick, hz), angle, Vec3::new(x, height - thick, z));
        self.shape("cube", "tabletop", &t, &top, "", None);
        let legs = self.random_material(0.0);
        let (lx, lz) = if angle == 0.0 { (hx - 0.06, hz - 0.06) } else { (hz - 0.06, hx - 0.06) };
        let leg_r = self.rng.range(0.02, 0.05);
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let at = Vec3::new(x + sx * lx, 0.0, z + sz * lz);
            let t = Self::placed(Vec3::new(leg_r, height - 2.0 * thick, leg_r), 0.0, at);
            self.cylinder_shape("leg", &t, &legs);
        }
        // Something on the table, sometimes.
        if self.rng.chance(0.6) {
            let r = self.rng.range(0.06, hz.min(0.25));
            let at = Vec3::new(x + self.rng.range(-0.5, 0.5) * lx, height + r, z + self.rng.range(-0.5, 0.5) * lz);
            self.a_sphere(glass_bias, Some((at, r)));
        }
    }

    fn shelf(&mut self, glass_bias: f32) {
        // A slab on the wall at the far end or a side.
        let room = self.room;
        let len = self.rng.range(0.5, 1.5).min(room.x * 0.4);
        let depth = self.rng.range(0.15, 0.35);
        let y = self.rng.range(0.6, (room.y - 0.5).max(0.7));
        let m = self.random_material(glass_bias);
        let x = self.rng.range(len + 0.05, room.x - len - 0.05);
        let t = Self::placed(Vec3::new(len, 0.02, depth), 0.0, Vec3::new(x, y, room.z - depth - 0.001));
        self.shape("cube", "shelf", &t, &m, "", None);
    }

    fn a_sphere(&mut self, glass_bias: f32, on: Option<(Vec3, f32)>) {
        let (c, r) = match on {
            Some(p) => p,
            None => {
                let r = self.rng.range(0.12, 0.6);
                let Some((x, z)) = self.free_spot(r) else { return };
                (Vec3::new(x, r, z), r)
            }
        };
        let m = self.random_material(glass_bias);
        let extra =
            format!("<point name=\"center\" value=\"{}\"/><float name=\"radius\" value=\"{}\"/>", v3(c), num(r));
        self.shape("sphere", "ball", "", &m, &extra, None);
    }

    fn a_cylinder(&mut self, glass_bias: f32) {
        let r = self.rng.range(0.08, 0.4);
        let h = self.rng.range(0.2, 1.6);
        let Some((x, z)) = self.free_spot(r) else { return };
        let m = self.random_material(glass_bias);
        let t = Self::placed(Vec3::new(r, h, r), 0.0, Vec3::new(x, 0.0, z));
        self.cylinder_shape("cylinder", &t, &m);
    }

    /// A closed unit cylinder (radius 1, y from 0 to 1) placed by `transform`: Mitsuba's open
    /// `cylinder` and a `disk` at each end, facing out, all analytic.
    fn cylinder_shape(&mut self, name: &str, transform: &str, bsdf: &Bsdf) {
        let extra = "<point name=\"p0\" value=\"0, 0, 0\"/><point name=\"p1\" value=\"0, 1, 0\"/>";
        self.shape("cylinder", name, transform, bsdf, extra, None);
        let bottom = format!("<rotate x=\"1\" angle=\"90\"/>{transform}");
        self.shape("disk", &format!("{name}-bottom"), &bottom, bsdf, "", None);
        let top = format!("<rotate x=\"1\" angle=\"-90\"/><translate value=\"0, 1, 0\"/>{transform}");
        self.shape("disk", &format!("{name}-top"), &top, bsdf, "", None);
    }

    fn borrowed(&mut self, glass_bias: f32) {
        let k = self.rng.below(self.borrowable.len());
        let (path, lo, hi) = self.borrowable[k].clone();
        let size = hi - lo;
        let height = self.rng.range(0.3, 1.2);
        let s = height / size.y.max(1e-3);
        let r = 0.5 * s * size.x.max(size.z) * 1.42;
        let angle = self.rng.range(0.0, 360.0);
        if r > 1.5 {
            return;
        }
        let Some((x, z)) = self.free_spot(r) else { return };
        let m = self.random_material(glass_bias);
        // Centre the mesh on its footprint and stand it on the floor.
        let centre = (lo + hi) * 0.5;
        let mut t = format!("<translate value=\"{}\"/>", v3(Vec3::new(-centre.x, -lo.y, -centre.z)));
        t.push_str(&Self::placed(Vec3::splat(s), angle, Vec3::new(x, 0.0, z)));
        // The mesh travels with the scene as an asset, since a scene reads only files of its own folder. Its
        // `mtllib` lines are dropped: the scene gives the BSDF.
        let file = format!("borrowed-{k}.obj");
        if !self.assets.iter().any(|a| a.file == file) {
            let Ok(text) = std::fs::read_to_string(&path) else { return };
            let obj: String =
                text.lines().filter(|l| !l.trim_start().starts_with("mtllib")).flat_map(|l| [l, "\n"]).collect();
            self.assets.push(Asset { file: file.clone(), bytes: obj.into_bytes() });
        }
        let extra = format!("<string name=\"filename\" value=\"{file}\"/>");
        self.shape("obj", "borrowed", &t, &m, &extra, None);
    }

    fn environment_light(&mut self) {
        if !self.options.ingredients.environment || self.style == Style::Dark || !self.rng.chance(0.5) {
            return;
        }
        self.sky();
    }

    /// Objects on a ground plane under a sky: the camera stands at the near edge of the patch they stand on
    /// and looks across it, the horizon often in view.
    fn open_scene(&mut self) {
        let r = &mut self.rng;
        self.room = Vec3::new(r.range(3.0, 7.0), 6.0, r.range(3.0, 7.0));
        let room = self.room;
        self.camera = Vec3::new(r.range(0.3, 0.7) * room.x, r.range(0.4, 2.5), r.range(-1.0, 0.3));
        let target = Vec3::new(r.range(0.3, 0.7) * room.x, r.range(0.0, 0.7), r.range(0.4, 0.8) * room.z);
        let fov = r.range(30.0, 60.0);
        self.footprints.push(Footprint { x: self.camera.x, z: self.camera.z, r: 0.5 });
        let ground = self.surface_material();
        let centre = Vec3::new(room.x / 2.0, 0.0, room.z / 2.0);
        self.rectangle("ground", centre, [Vec3::X * 60.0, Vec3::Z * 60.0], Vec3::Y, &ground, None);
        if self.options.ingredients.environment {
            self.sky();
        } else {
            let radiance = Vec3::new(0.8, 0.9, 1.0) * self.rng.range(1.0, 4.0);
            let black = self.black();
            let high = centre + Vec3::Y * 30.0;
            self.rectangle("overcast", high, [Vec3::X * 40.0, Vec3::Z * 40.0], -Vec3::Y, &black, Some(radiance));
            self.lights.push(LightKind::LargeArea);
        }
        // A sun: a small, very bright sphere far above (hard shadows, sharp highlights).
        if self.rng.chance(0.5) {
            let dir = Vec3::new(self.rng.range(-1.0, 1.0), self.rng.range(0.4, 1.5), self.rng.range(-0.5, 1.5));
            let c = centre + dir.normalize() * 40.0;
            let radius = self.rng.range(0.2, 0.8);
            let radiance = Vec3::new(1.0, self.rng.range(0.85, 1.0), self.rng.range(0.7, 0.95))
                * (self.rng.range(2000.0, 10000.0) * (0.5 / radius).powi(2));
            self.bright_sphere("sun", c, radius, radiance);
        }
        // Bulbs among the objects, sometimes: tiny and very bright, often in view or reflected.
        for _ in 0..[0, 0, 1, 2][self.rng.below(4)] {
            let rad = self.rng.range(0.02, 0.08);
            let c = Vec3::new(
                self.rng.range(0.1, 0.9) * room.x,
                self.rng.range(0.3, 2.0),
                self.rng.range(0.3, 1.0) * room.z,
            );
            let radiance =
                Vec3::new(1.0, self.rng.range(0.75, 1.0), self.rng.range(0.5, 0.95)) * self.rng.range(300.0, 3000.0);
            self.bright_sphere("bulb", c, rad, radiance);
        }
        let count = 3 + self.rng.below(6);
        for _ in 0..count {
            match self.rng.weighted(&[1.5, 1.0, 3.0, 1.5]) {
                0 => self.a_box(0.0),
                1 => self.table(0.0),
                2 => self.a_sphere(0.0, None),
                _ => self.a_cylinder(0.0),
            }
        }
        self.write_header(target, fov);
    }

    /// Lights in view above glossy plates ([`Style::Lamps`]): the camera looks across a patch of ground at a
    /// band of 2 to 5 emitting spheres or disks (radius 0.005 or 0.02 to 0.6 m, radiance × radius² = 0.2 to 8,
    /// as veach-mis's lights have 7.6, so radiance 0.6 to 320 000), with 2 to 4 plates tilted to mirror them into the camera (GGX roughness 0.01 to
    /// 0.3), a few objects on the ground, and a black, dim or lit backdrop.
    fn lamps_scene(&mut self) {
        let r = &mut self.rng;
        let dist = r.range(3.0, 6.0);
        self.room = Vec3::new(r.range(3.0, 6.0), 6.0, dist + 1.5);
        let room = self.room;
        self.camera = Vec3::new(0.5 * room.x + r.range(-0.3, 0.3), r.range(0.8, 2.0), 0.0);
        let target = Vec3::new(0.5 * room.x + r.range(-0.3, 0.3), r.range(0.6, 1.4), dist);
        // fov 35° to 50°: the frame's half-height at the target is at least 0.31 × dist.
        let fov = r.range(35.0, 50.0);
        let half = 0.3 * (target - self.camera).length();
        let forward = (target - self.camera).normalize();
        let right = forward.cross(Vec3::Y).normalize();
        let up = right.cross(forward);
        self.footprints.push(Footprint { x: self.camera.x, z: self.camera.z, r: 0.5 });
        let ground = self.surface_material();
        let centre = Vec3::new(room.x / 2.0, 0.0, room.z / 2.0);
        self.rectangle("ground", centre, [Vec3::X * 30.0, Vec3::Z * 30.0], Vec3::Y, &ground, None);
        // The backdrop: black (only the lamps light the scene), a dim constant sky, or a lit wall behind.
        match self.rng.below(3) {
            0 => {}
            1 if self.options.ingredients.environment => {
                let radiance = self.rng.color(0.02, 0.15);
                self.environment = Some(format!(
                    "  <emitter type=\"constant\"><rgb name=\"radiance\" value=\"{}\"/></emitter>\n",
                    v3(radiance)
                ));
                self.lights.push(LightKind::Constant);
            }
            _ => {
                let wall = self.surface_material();
                let at = target + forward * self.rng.range(2.0, 4.0);
                self.rectangle("backdrop", at, [right * 20.0, Vec3::Y * 20.0], -forward, &wall, None);
            }
        }
        // The lamps, spread across the upper part of the frame.
        let count = 2 + self.rng.below(4);
        let mut centres = Vec::with_capacity(count);
        for i in 0..count {
            let across = (i as f32 + 0.5) / count as f32 * 1.5 - 0.75 + self.rng.range(-0.1, 0.1);
            // Radius log-uniform from `smallest` to 0.6 m. The frame's pixels are about 3 cm across at 96²; on a
            // film with a wide filter the smallest lamps are a fraction of a pixel, as veach-mis's smallest
            // light is, which the filter spreads like a firefly. A box film keeps to lamps over a pixel
            // across: the reference's firefly filter would take a lone sub-pixel light for a firefly.
            let smallest = if self.options.filter == PixelFilter::Box { 0.02 } else { 0.005 };
            let radius = smallest * pow_exact(0.6 / smallest, self.rng.unit());
            let c = target
                + right * (across * half)
                + up * (self.rng.range(0.1, 0.7) * half)
                + forward * self.rng.range(-0.3, 1.0);
            let tint = Vec3::new(1.0, self.rng.range(0.7, 1.0), self.rng.range(0.5, 1.0));
            let radiance = tint * (self.rng.range(0.2, 8.0) / (radius * radius));
            if self.rng.chance(0.75) {
                self.bright_sphere("lamp", c, radius, radiance);
            } else {
                // A disk facing the camera: a right-handed basis takes its +z there.
                let n = (self.camera - c).normalize();
                let u = n.cross(Vec3::Y).normalize() * radius;
                let v = n.cross(u).normalize() * radius;
                let black = self.black();
                self.shape("disk", "lamp", &basis_matrix(u, v, n, c), &black, "", Some(radiance));
                self.lights.push(LightKind::SmallArea);
            }
            centres.push(c);
        }
        let lamps = centres.iter().fold(Vec3::ZERO, |a, c| a + *c) / count as f32;
        // Plates below the lamps, each tilted so that the lamps' mean mirrors into the camera.
        let plates = 2 + self.rng.below(3);
        for i in 0..plates {
            let down = -0.15 - 0.6 * (i as f32 + self.rng.range(0.0, 0.8)) / plates as f32;
            let p =
                target + up * (down * half) + forward * self.rng.range(-1.0, -0.2) + right * self.rng.range(-0.2, 0.2);
            let p = Vec3::new(p.x, p.y.max(0.05), p.z);
            let n = ((self.camera - p).normalize() + (lamps - p).normalize()).normalize();
            let u = n.cross(forward).normalize() * (self.rng.range(0.6, 1.0) * half);
            let v = n.cross(u).normalize() * (self.rng.range(0.06, 0.15) * half);
            let alpha = 0.01 * pow_exact(30.0, self.rng.unit());
            let p_bsdf = if self.rng.chance(0.6) {
                let metal = ["Al", "Ag", "Cu", "Au", "Cr"][self.rng.below(5)];
                self.rough_conductor(metal, alpha)
            } else if self.options.ingredients.rough_plastic {
                let c = self.rng.color(0.02, 0.3);
                self.rough_plastic(c, None, alpha)
            } else {
                self.random_material(0.0)
            };
            self.rectangle("plate", p, [u, v], n, &p_bsdf, None);
        }
        let count = self.rng.below(4);
        for _ in 0..count {
            match self.rng.weighted(&[1.0, 2.0, 1.0]) {
                0 => self.a_box(0.0),
                1 => self.a_sphere(0.0, None),
                _ => self.a_cylinder(0.0),
            }
        }
        self.write_header(target, fov);
    }

    /// A `constant` sky or a generated `envmap` sky with a sun spot.
    fn sky(&mut self) {
        if self.rng.chance(0.4) {
            let radiance = Vec3::new(0.6, 0.75, 1.0) * self.rng.range(0.2, 2.0);
            self.environment = Some(format!(
                "  <emitter type=\"constant\"><rgb name=\"radiance\" value=\"{}\"/></emitter>\n",
                v3(radiance)
            ));
            self.lights.push(LightKind::Constant);
        } else {
            let (w, h) = (64u32, 32u32);
            let zenith = Vec3::new(0.25, 0.45, 0.9) * self.rng.range(0.6, 1.0);
            let horizon = Vec3::new(0.85, 0.85, 0.8) * self.rng.range(0.7, 1.0);
            let ground = self.rng.color(0.1, 0.35);
            let sun = (self.rng.below(w as usize) as u32, 2 + self.rng.below(h as usize / 2 - 3) as u32);
            let mut rgb = Vec::with_capacity((w * h * 3) as usize);
            for y in 0..h {
                for x in 0..w {
                    let t = y as f32 / (h / 2) as f32;
                    let mut c = if y < h / 2 { zenith + (horizon - zenith) * t } else { ground };
                    if x.abs_diff(sun.0) <= 1 && y.abs_diff(sun.1) <= 1 {
                        c = Vec3::ONE;
                    }
                    rgb.extend([c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8));
                }
            }
            let file = "sky.png".to_string();
            self.assets.push(Asset { file: file.clone(), bytes: png(w, h, rgb) });
            self.environment = Some(format!(
                "  <emitter type=\"envmap\"><string name=\"filename\" value=\"{file}\"/>\
                 <float name=\"scale\" value=\"{}\"/></emitter>\n",
                num(self.rng.range(1.0, 6.0))
            ));
            self.lights.push(LightKind::EnvMap);
        }
    }
}

/// A `<matrix>` taking the object's x, y and z axes to `u`, `v` and `n` and its origin to `c`.
fn basis_matrix(u: Vec3, v: Vec3, n: Vec3, c: Vec3) -> String {
    let m = [[u.x, v.x, n.x, c.x], [u.y, v.y, n.y, c.y], [u.z, v.z, n.z, c.z], [0.0, 0.0, 0.0, 1.0]];
    let values: Vec<String> = m.iter().flatten().map(|x| num(*x)).collect();
    format!("<matrix value=\"{}\"/>", values.join(" "))
}

/// base^u for base > 0 and u in [0, 1): a product of base^(2^-k) over the bits of u (square roots are exact
/// in IEEE arithmetic, so the value is the same on every platform).
fn pow_exact(base: f32, u: f32) -> f32 {
    let (mut x, mut root, mut out) = (u, base, 1.0f32);
    for _ in 0..16 {
        x *= 2.0;
        root = root.sqrt();
        if x >= 1.0 {
            x -= 1.0;
            out *= root;
        }
    }
    out
}

/// An 8-bit RGB PNG in memory.
fn png(width: u32, height: u32, rgb: Vec<u8>) -> Vec<u8> {
    let img = image::RgbImage::from_raw(width, height, rgb).expect("width × height × 3 bytes");
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png).expect("PNG encoding into memory cannot fail");
    bytes.into_inner()
}

/// Small OBJ meshes (at most 400 kB) below `dir/*/models/`, with their bounds, sorted by path.
fn borrowable_meshes(dir: &Path) -> Vec<(PathBuf, Vec3, Vec3)> {
    const MAX_BYTES: u64 = 400_000;
    let Ok(scenes) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut files: Vec<PathBuf> = scenes
        .filter_map(|e| e.ok())
        .filter_map(|e| std::fs::read_dir(e.path().join("models")).ok())
        .flat_map(|r| r.filter_map(|e| e.ok()).map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")))
        .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.len() <= MAX_BYTES))
        .collect();
    files.sort();
    files
        .into_iter()
        .filter_map(|path| {
            let path = path.canonicalize().ok()?;
            let obj = crate::obj::read_obj(&path, false).ok()?;
            let g = crate::obj::merge(obj.objects);
            if g.indices.len() < 12 {
                return None;
            }
            let lo = g.positions.iter().fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p));
            let hi = g.positions.iter().fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
            let size = hi - lo;
            // Skip flat pieces (walls, floors): furniture has some extent in every direction.
            (lo.is_finite() && hi.is_finite() && size.min_element() > 0.05 * size.max_element())
                .then_some((path, lo, hi))
        })
        .collect()
}
