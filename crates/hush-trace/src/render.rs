use std::collections::{HashMap, VecDeque};
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bytemuck::{Pod, Zeroable};
use hush_dataset::Image;
use hush_scene::{EnvMap, Environment, Mesh, PixelFilter, Scene, Texture};
use wgpu::util::DeviceExt;

use crate::scan::{SceneLiterals, scene_source};
use crate::upload::{GpuLight, GpuMaterial, GpuNormals, GpuShape, GpuTri, KernelFeatures, flatten};
use crate::wide::GpuWideNode;
use crate::{GpuContext, TraceError};

/// The WGSL source of the generic path-tracing kernel (validated by a test with naga).
pub const KERNEL_SOURCE: &str = concat!(
    include_str!("bsdf.wgsl"),
    include_str!("env.wgsl"),
    include_str!("path.wgsl"),
    include_str!("shapes.wgsl"),
    include_str!("scene_scan.wgsl"),
    include_str!("scene_material.wgsl"),
    include_str!("scene_light.wgsl"),
);

/// The kernel without its access to the scene (`scene_*.wgsl`), which a kernel specialized to a
/// scene replaces (`scan.rs`).
const KERNEL_BODY: &str = concat!(
    include_str!("bsdf.wgsl"),
    include_str!("env.wgsl"),
    include_str!("path.wgsl"),
    include_str!("shapes.wgsl")
);

/// The WGSL source the renderer compiles for `scene`: the generic source, or with `generic` false,
/// the source with what of the scene is small enough written in as literals (see `scan.rs`).
/// Which features are compiled out is set by pipeline constants, not in the source.
pub fn kernel_source(scene: &Scene, generic: bool) -> Result<String, TraceError> {
    let flat = flatten(scene)?;
    Ok(match scene_source(&flat, scene_literals(&flat, generic)) {
        Some(access) => format!("{KERNEL_BODY}{access}"),
        None => KERNEL_SOURCE.to_string(),
    })
}

/// What of `flat` a kernel holds as literals: nothing for the generic one.
fn scene_literals(flat: &crate::upload::GpuScene, generic: bool) -> SceneLiterals {
    if generic { SceneLiterals::default() } else { crate::scan::literals(flat) }
}

/// Floats per pixel in the accumulation buffer; mirrors `ACCUM_STRIDE` in the kernel.
const ACCUM_STRIDE: usize = 19;
/// Paths per dispatch to aim for. Every dispatch ends with the lanes that finished early waiting for
/// the longest paths and with a wait for the device: on lavapipe, spheres under a sky (256×192,
/// 256 spp) rendered 1.10× as many paths per CPU-second with 4 dispatches of 2^22 paths as with 16 of
/// 2^20 (alternating runs). On lavapipe a dispatch is then a fraction of a second on light scenes and
/// several seconds on the heaviest; on a GPU, milliseconds.
const PATHS_PER_DISPATCH: u64 = 1 << 22;
/// Paths per dispatch under a time limit: a pass is the unit a limit can stop at, so it is
/// smaller, about a second of work on lavapipe or less.
const PATHS_PER_TIMED_DISPATCH: u64 = 1 << 17;
/// Samples one invocation takes per dispatch, at most. On lavapipe, invocations that looped
/// over 255 or more samples in one dispatch lost part of their work (images came out 16 %
/// and more too dark, worse in later rows) while 128 were exact; the Mitsuba comparisons
/// in the tests hold this bound to account.
const MAX_SAMPLES_PER_DISPATCH: u64 = 64;
/// [`MAX_SAMPLES_PER_DISPATCH`] under a time limit, whose passes stay small: a pass is the unit a
/// limit can stop at.
const MAX_SAMPLES_PER_TIMED_DISPATCH: u64 = 16;

/// What to render beyond the scene itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderSettings {
    /// Samples (paths) per pixel; at least 1.
    pub spp: u32,
    /// The same seed gives the same image.
    pub seed: u64,
    /// Where in the pixel's filter each sample's camera ray starts.
    pub pixel_sampler: PixelSampler,
}

impl RenderSettings {
    /// `spp` samples per pixel from `seed`, with the default [`PixelSampler`].
    pub fn new(spp: u32, seed: u64) -> RenderSettings {
        RenderSettings { spp, seed, pixel_sampler: PixelSampler::default() }
    }
}

/// How a pixel's samples are placed in it (and its filter, by filter importance sampling). Either way each
/// sample's position is uniform, so the pixel's estimate has the same expectation; every other random number
/// of a path is independent of its position and of the other samples.
///
/// The default stays [`PixelSampler::Independent`]: hush's shipped models were trained on such renders, and
/// on stratified ones (a tent film's sub-pixel light, veach-mis) they fall behind OIDN by more than the
/// bar they ship under, even retrained on stratified renders (`docs/results/train-default/`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PixelSampler {
    /// The pixel's samples are the points of a base-2 (0, 2)-sequence under a random digital shift of the
    /// pixel's own: any 2^k of them from the first fill the 2^k elementary intervals of the square (a 4 × 4
    /// grid at 16 spp), so the noise that comes from where in the pixel a sample lies (an edge, an emitter's
    /// rim, a texture) falls faster than 1/n. Pixels stay independent of each other.
    Stratified,
    /// Each position independent of the others (Mitsuba's `independent` sampler).
    #[default]
    Independent,
}

impl PixelSampler {
    /// Every sampler.
    pub const ALL: [PixelSampler; 2] = [PixelSampler::Independent, PixelSampler::Stratified];

    /// Its name on the command line and in a dataset's manifest.
    pub fn name(self) -> &'static str {
        match self {
            PixelSampler::Stratified => "stratified",
            PixelSampler::Independent => "independent",
        }
    }

    /// The sampler of a name ([`PixelSampler::name`]); an error lists the names.
    pub fn parse(name: &str) -> Result<PixelSampler, String> {
        PixelSampler::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or_else(|| format!("unknown pixel sampler '{name}' (independent or stratified)"))
    }
}

/// A rendered image and its auxiliary features, all averaged over the pixel's samples.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Beauty, linear RGB radiance.
    pub color: Image,
    /// Per channel, the estimated variance of each pixel's mean (sample variance / spp).
    pub color_variance: Image,
    /// Reflectance at the first hit that is not a delta (mirror or smooth glass) surface: the features follow
    /// those, as OIDN recommends (for diffuse surfaces, the diffuse reflectance).
    pub albedo: Image,
    /// Diffuse reflectance k_d at that hit.
    pub diffuse: Image,
    /// Specular reflectance k_s at that hit (0 for purely diffuse surfaces).
    pub specular: Image,
    /// World-space shading normal at that hit, averaged and renormalized; 0 where every
    /// sample escaped.
    pub normal: Image,
    /// Samples per pixel actually rendered: `settings.spp`, or fewer when a time limit ended
    /// the render first.
    pub spp: u32,
    /// Dispatches (passes) it took; each pass adds the same number of samples per pixel to
    /// every pixel, except a last one cut short by `settings.spp`.
    pub passes: u32,
    /// Non-finite path samples the kernel discarded (0 in a correct render).
    pub discarded_samples: u64,
    /// What of the scene the kernel held as literals (nothing for the generic kernel).
    pub literals: SceneLiterals,
    /// Wall-clock seconds spent tracing (read-back included, and building the scene's device data where this
    /// render built it rather than finding it kept from an earlier render of the scene; compiling the kernel
    /// specialized to the scene, once per set of features and scene data written in, is not).
    pub seconds: f64,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Params {
    origin: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    forward: [f32; 4],
    width: u32,
    height: u32,
    sample_offset: u32,
    samples_per_dispatch: u32,
    seed_lo: u32,
    seed_hi: u32,
    max_depth: u32,
    tri_count: u32,
    light_count: u32,
    filter_kind: u32,
    filter_width: f32,
    pixel_sampler: u32,
}

/// Compiled kernels on one device: the generic kernel and the specialized ones rendered so far,
/// one per set of [`KernelFeatures`] and, for scenes small enough to have their data written in,
/// per scene ([`MAX_CACHED_KERNELS`] of those at most: the oldest is dropped).
#[derive(Debug)]
pub struct Renderer<'a> {
    gpu: &'a GpuContext,
    module: wgpu::ShaderModule,
    /// Every binding of the kernel, explicitly: a specialized kernel may leave buffers unused.
    bind_layout: wgpu::BindGroupLayout,
    layout: wgpu::PipelineLayout,
    generic: bool,
    pipelines: Mutex<Pipelines>,
    /// The last scenes' device data ([`Upload`]) with their [`scene_key`]s, oldest first.
    uploads: Mutex<VecDeque<(u64, Arc<Upload>)>>,
    /// Scenes flattened and uploaded so far ([`Renderer::scenes_uploaded`]).
    uploaded: std::sync::atomic::AtomicUsize,
    /// Kernels compiled so far ([`Renderer::kernels_compiled`]).
    compiled: std::sync::atomic::AtomicUsize,
}

/// Shapes that the kernel reads from a uniform buffer (`UNIFORM_SHAPES` in shapes.wgsl): 64 KiB, the
/// least every device allows. CPU drivers gather a uniform buffer's words for all SIMD lanes at once
/// but load a storage buffer's lane by lane, word by word.
pub(crate) const UNIFORM_SHAPES: usize = 585;

/// Kernels with scene data written in that a [`Renderer`] keeps compiled: a dataset renders a
/// scene many times in a row, and each scene's kernel holds at most about 100 KB of source.
pub const MAX_CACHED_KERNELS: usize = 8;

/// Scenes whose device data a [`Renderer`] keeps: the one rendering and the next one
/// [`Renderer::prepare`]d.
const MAX_CACHED_UPLOADS: usize = 2;

/// What a render builds from a scene's geometry, materials, textures, lights and pixel filter: the
/// flattened scene with its BVH (`flatten`), the device buffers that hold it and the kernel's scene
/// access. It does not depend on the camera, the film's size, `max_depth` or the spp, so every view of a
/// scene at every spp (a dataset's renders, `hush render --warm-up`'s two) shares one, as Mitsuba renders
/// a loaded scene again without building it again (living-room took 0.35 s of CPU to flatten, its BVH
/// and its textures as halves, on every render before).
#[derive(Debug)]
struct Upload {
    features: KernelFeatures,
    literals: SceneLiterals,
    access: Option<String>,
    tri_count: u32,
    light_count: u32,
    tris: wgpu::Buffer,
    normals: wgpu::Buffer,
    materials: wgpu::Buffer,
    lights: wgpu::Buffer,
    nodes: wgpu::Buffer,
    aux: wgpu::Buffer,
    env: wgpu::Buffer,
    shapes: wgpu::Buffer,
    first_shapes: wgpu::Buffer,
}

/// A hash of everything of `scene` that its [`Upload`] is built from, and of `generic`: scenes equal up
/// to their cameras, film sizes, depth limits, spp and warnings have the same key. Each struct is taken
/// apart field by field, so a field added to the scene model fails to compile here until it is hashed or
/// named as not uploaded.
fn scene_key(scene: &Scene, generic: bool) -> u64 {
    let Scene { camera: _, film, max_depth: _, spp: _, meshes, textures, environment, warnings: _ } = scene;
    let mut h = std::hash::DefaultHasher::new();
    let floats = |h: &mut std::hash::DefaultHasher, v: &[f32]| h.write(bytemuck::cast_slice(v));
    generic.hash(&mut h);
    format!("{:?}", film.filter).hash(&mut h);
    meshes.len().hash(&mut h);
    for mesh in meshes {
        let Mesh { name, positions, normals, uvs, indices, material, emission, analytic } = mesh;
        name.hash(&mut h);
        floats(&mut h, &positions.iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>());
        let normals: Option<Vec<f32>> = normals.as_ref().map(|n| n.iter().flat_map(|v| v.to_array()).collect());
        normals.is_some().hash(&mut h);
        floats(&mut h, normals.as_deref().unwrap_or_default());
        let uvs: Option<Vec<f32>> = uvs.as_ref().map(|n| n.iter().flat_map(|v| v.to_array()).collect());
        uvs.is_some().hash(&mut h);
        floats(&mut h, uvs.as_deref().unwrap_or_default());
        indices.hash(&mut h);
        // Debug writes each float's shortest exact form: equal strings are equal values.
        format!("{material:?} {emission:?} {analytic:?}").hash(&mut h);
    }
    textures.len().hash(&mut h);
    for texture in textures {
        let Texture { path, width, height, data } = texture;
        (path, width, height).hash(&mut h);
        floats(&mut h, data);
    }
    match environment {
        None => 0u8.hash(&mut h),
        Some(Environment::Constant { radiance }) => format!("constant {radiance:?}").hash(&mut h),
        Some(Environment::Map(map)) => {
            let EnvMap { path, width, height, data, scale, to_world } = map;
            (path, width, height).hash(&mut h);
            floats(&mut h, data);
            format!("map {scale:?} {to_world:?}").hash(&mut h);
        }
    }
    h.finish()
}

/// Compiled pipelines keyed by the features and, for a kernel with scene data written in, its
/// scene access; those in the order they were compiled.
type PipelineKey = (KernelFeatures, Option<String>);
#[derive(Debug, Default)]
struct Pipelines {
    map: HashMap<PipelineKey, wgpu::ComputePipeline>,
    scene_order: VecDeque<PipelineKey>,
}

impl<'a> Renderer<'a> {
    /// Validates the generic kernel's source; each pipeline (the generic one, or one specialized to a
    /// scene) is built when a render first needs it. A shader the driver rejects is an error, not a panic.
    pub fn new(gpu: &'a GpuContext) -> Result<Renderer<'a>, TraceError> {
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("path.wgsl"),
            source: wgpu::ShaderSource::Wgsl(KERNEL_SOURCE.into()),
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(TraceError::Gpu(format!("the path-tracing kernel does not compile on {}: {e}", gpu.info.name)));
        }
        let buffer = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
            count: None,
        };
        let (uniform, read) = (wgpu::BufferBindingType::Uniform, wgpu::BufferBindingType::Storage { read_only: true });
        let bind_layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("path"),
            entries: &[
                buffer(0, uniform),
                buffer(1, read),
                buffer(2, read),
                buffer(3, read),
                buffer(4, read),
                buffer(5, wgpu::BufferBindingType::Storage { read_only: false }),
                buffer(6, read),
                buffer(7, read),
                buffer(8, uniform),
                buffer(9, read),
                buffer(10, uniform),
                buffer(11, read),
                buffer(12, read),
            ],
        });
        let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("path"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        Ok(Renderer {
            gpu,
            module,
            bind_layout,
            layout,
            generic: false,
            pipelines: Mutex::default(),
            uploads: Mutex::default(),
            uploaded: 0.into(),
            compiled: 0.into(),
        })
    }

    /// With `true`, every scene renders with the generic kernel (all features compiled in)
    /// instead of one specialized to the scene: the same image up to the rare ties between equally
    /// distant hits, which a flat scan and a BVH walk may break differently, and last-bit differences
    /// where the compiler folds literals differently from values it loads; for speed comparisons.
    pub fn with_generic_kernel(mut self, generic: bool) -> Self {
        self.generic = generic;
        self
    }

    /// The kernel specialized to `features` (pipeline-overridable constants) and, with `access`, to
    /// a scene's data, compiled once.
    ///
    /// The lock on the cache is not held while the driver compiles, so that [`Renderer::prepare`] on another
    /// thread does not hold up renders of kernels already built; two threads that miss the same kernel at once
    /// both compile it and the first to finish is kept.
    fn pipeline(&self, features: KernelFeatures, access: Option<String>) -> Result<wgpu::ComputePipeline, TraceError> {
        let lock = || self.pipelines.lock().map_err(|_| TraceError::Gpu("a render panicked".into()));
        let key = (features, access);
        if let Some(p) = lock()?.map.get(&key) {
            return Ok(p.clone());
        }
        let flag = |b: bool| if b { 1.0 } else { 0.0 };
        let constants = [
            ("HAS_TEXTURES", flag(features.textures)),
            ("HAS_ENV", flag(features.environment)),
            ("HAS_ENV_MAP", flag(features.environment_map)),
            ("HAS_LIGHTS", flag(features.lights())),
            ("LIGHT_KINDS", features.light_kinds as f64),
            ("HAS_ROUGH_DIELECTRIC", flag(features.rough_dielectric)),
            ("HAS_ROUGH_PLASTIC", flag(features.rough_plastic)),
            ("HAS_BECKMANN", flag(features.beckmann)),
            ("HAS_SMOOTH_CONDUCTOR", flag(features.smooth_conductor)),
            ("HAS_ROUGH_CONDUCTOR", flag(features.rough_conductor)),
            ("HAS_DIELECTRIC", flag(features.dielectric)),
            ("HAS_THIN_DIELECTRIC", flag(features.thin_dielectric)),
            ("HAS_PLASTIC", flag(features.plastic)),
            ("FLAT_SCAN", flag(features.flat_scan)),
            ("HAS_SHAPES", flag(features.shapes)),
            ("HAS_MANY_SHAPES", flag(features.many_shapes)),
            ("HAS_SHADING_NORMALS", flag(features.shading_normals)),
            ("HAS_WIDE_FILTER", flag(features.wide_filter)),
        ];
        let device = &self.gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let specialized = key.1.as_ref().map(|access| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("path.wgsl with the scene's data"),
                source: wgpu::ShaderSource::Wgsl(format!("{KERNEL_BODY}{access}").into()),
            })
        });
        self.compiled.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("path"),
            layout: Some(&self.layout),
            module: specialized.as_ref().unwrap_or(&self.module),
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(TraceError::Gpu(format!(
                "the path-tracing kernel ({features:?}) does not compile on {}: {e}",
                self.gpu.info.name
            )));
        }
        let mut pipelines = lock()?;
        if let Some(p) = pipelines.map.get(&key) {
            return Ok(p.clone());
        }
        if key.1.is_some() {
            pipelines.scene_order.push_back(key.clone());
            if pipelines.scene_order.len() > MAX_CACHED_KERNELS
                && let Some(oldest) = pipelines.scene_order.pop_front()
            {
                pipelines.map.remove(&oldest);
            }
        }
        pipelines.map.insert(key, pipeline.clone());
        Ok(pipeline)
    }

    /// How many kernel compilations this renderer has started so far: each scene's once while it stays in the
    /// cache (two threads that miss the same kernel at once both count, as does a compilation that failed).
    pub fn kernels_compiled(&self) -> usize {
        self.compiled.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many scenes this renderer has flattened and uploaded so far: a scene's renders share one while it
    /// stays among the last [`MAX_CACHED_UPLOADS`] (its views, spp and references alike).
    pub fn scenes_uploaded(&self) -> usize {
        self.uploaded.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Builds the kernel and the device data [`Renderer::render`] needs for `scene` (the generic kernel, or
    /// one specialized to the scene's data) if they are not built yet, without rendering: a caller with a list
    /// of scenes can have the next scene prepared on another thread while the current scene renders (on
    /// lavapipe the driver compiles on one core while the other idles). The camera, the film's size and the
    /// depth limit enter neither (the pixel filter does), so every view of the scene uses them. An error here
    /// is the one its render would report.
    pub fn prepare(&self, scene: &Scene) -> Result<(), TraceError> {
        let upload = self.upload(scene)?;
        self.pipeline(upload.features, upload.access.clone()).map(|_| ())
    }

    /// The scene's [`Upload`]: the kept one of an equal scene ([`scene_key`]), or a new one. The lock is not
    /// held while flattening, as for kernels.
    fn upload(&self, scene: &Scene) -> Result<Arc<Upload>, TraceError> {
        let lock = || self.uploads.lock().map_err(|_| TraceError::Gpu("a render panicked".into()));
        let key = scene_key(scene, self.generic);
        if let Some((_, upload)) = lock()?.iter().find(|(k, _)| *k == key) {
            return Ok(upload.clone());
        }
        let flat = flatten(scene)?;
        let device = &self.gpu.device;
        let limit = device.limits().max_storage_buffer_binding_size;
        let aux_bytes = flat.aux.len() as u64 * 4;
        if aux_bytes > limit {
            return Err(TraceError::Invalid(format!(
                "the scene's textures and tables take {aux_bytes} bytes; this device binds at most {limit}: \
                 use smaller textures"
            )));
        }
        let storage = |label: &str, bytes: &[u8]| {
            // Empty storage buffers are not allowed: bind one zeroed element instead.
            let padded;
            let contents = if bytes.is_empty() {
                padded = vec![0u8; 256];
                &padded[..]
            } else {
                bytes
            };
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let first_shapes = {
            let mut bytes = vec![0u8; UNIFORM_SHAPES * std::mem::size_of::<GpuShape>()];
            let first = &flat.shapes[..flat.shapes.len().min(UNIFORM_SHAPES)];
            bytes[..std::mem::size_of_val(first)].copy_from_slice(bytemuck::cast_slice::<GpuShape, u8>(first));
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("first shapes"),
                contents: &bytes,
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let literals = scene_literals(&flat, self.generic);
        let upload = Arc::new(Upload {
            features: if self.generic { KernelFeatures::ALL } else { flat.features },
            literals,
            access: scene_source(&flat, literals),
            tri_count: flat.tris.len() as u32,
            light_count: flat.lights.len() as u32,
            tris: storage("tris", bytemuck::cast_slice::<GpuTri, u8>(&flat.tris)),
            normals: storage("normals", bytemuck::cast_slice::<GpuNormals, u8>(&flat.normals)),
            materials: storage("materials", bytemuck::cast_slice::<GpuMaterial, u8>(&flat.materials)),
            lights: storage("lights", bytemuck::cast_slice::<GpuLight, u8>(&flat.lights)),
            nodes: storage("bvh", bytemuck::cast_slice::<GpuWideNode, u8>(&flat.nodes)),
            aux: storage("aux", bytemuck::cast_slice::<f32, u8>(&flat.aux)),
            env: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("env"),
                contents: bytemuck::bytes_of(&flat.env.uniform()),
                usage: wgpu::BufferUsages::UNIFORM,
            }),
            shapes: storage("shapes", bytemuck::cast_slice::<GpuShape, u8>(&flat.shapes)),
            first_shapes,
        });
        self.uploaded.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut uploads = lock()?;
        if let Some((_, kept)) = uploads.iter().find(|(k, _)| *k == key) {
            return Ok(kept.clone());
        }
        uploads.push_back((key, upload.clone()));
        if uploads.len() > MAX_CACHED_UPLOADS {
            uploads.pop_front();
        }
        Ok(upload)
    }

    /// Renders `scene` with `settings.spp` paths per pixel. `progress(done, total)` is called
    /// with the samples per pixel finished so far.
    pub fn render(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<RenderOutput, TraceError> {
        self.render_within(scene, settings, None, progress)
    }

    /// Renders pass after pass until `time_limit` is spent or `settings.spp` (then a cap) is
    /// reached, whichever comes first; [`RenderOutput::spp`] says how many samples per pixel
    /// that was. A pass starts only while the time spent tracing is below the limit, so the
    /// render takes at least one pass and overshoots the limit by at most one pass; the passes
    /// hold fewer paths than without a limit (about 2^17), and the image equals `render`'s at the
    /// spp reached up to floating-point rounding.
    pub fn render_within(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        time_limit: Option<Duration>,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<RenderOutput, TraceError> {
        let mut start = Instant::now();
        let (w, h) = (scene.film.width, scene.film.height);
        if settings.spp == 0 {
            return Err(TraceError::Invalid("--spp must be at least 1".into()));
        }
        if w == 0 || h == 0 {
            return Err(TraceError::Invalid(format!("image size {w}×{h} is empty")));
        }
        if scene.max_depth == 0 {
            return Err(TraceError::Invalid("max_depth must be at least 1".into()));
        }
        scene.camera.validate().map_err(TraceError::Invalid)?;
        let pixels = w as u64 * h as u64;
        let accum_bytes = pixels * (ACCUM_STRIDE * 4) as u64;
        let limit = self.gpu.device.limits().max_storage_buffer_binding_size;
        if accum_bytes > limit {
            return Err(TraceError::Invalid(format!(
                "{w}×{h} needs {accum_bytes} bytes of accumulation buffer; this device allows {limit}: render a smaller image"
            )));
        }

        let upload = self.upload(scene)?;
        let device = &self.gpu.device;
        let accum = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("accum"),
            size: accum_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: accum_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let params_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let compile = Instant::now();
        let pipeline = self.pipeline(upload.features, upload.access.clone())?;
        start += compile.elapsed();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("path"),
            layout: &self.bind_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: params_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: upload.tris.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: upload.normals.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: upload.materials.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: upload.lights.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: accum.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 6, resource: upload.nodes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 7, resource: upload.aux.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 8, resource: upload.env.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 9, resource: upload.shapes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 10, resource: upload.first_shapes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 11, resource: upload.aux.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 12, resource: upload.aux.as_entire_binding() },
            ],
        });

        let cam = &scene.camera;
        let (forward, right, up) = cam.basis();
        let tan_y = (cam.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = w as f32 / h as f32;
        let mut params = Params {
            origin: cam.origin.extend(0.0).to_array(),
            right: (right * tan_y * aspect).extend(0.0).to_array(),
            up: (up * tan_y).extend(0.0).to_array(),
            forward: forward.extend(0.0).to_array(),
            width: w,
            height: h,
            sample_offset: 0,
            samples_per_dispatch: 0,
            seed_lo: settings.seed as u32,
            seed_hi: (settings.seed >> 32) as u32,
            max_depth: scene.max_depth,
            tri_count: upload.tri_count,
            light_count: upload.light_count,
            filter_kind: match scene.film.filter {
                PixelFilter::Box => 0,
                PixelFilter::Tent { .. } => 1,
                PixelFilter::Gaussian { .. } => 2,
            },
            filter_width: match scene.film.filter {
                PixelFilter::Box => 0.0,
                PixelFilter::Tent { radius } => radius,
                PixelFilter::Gaussian { stddev } => stddev,
            },
            pixel_sampler: match settings.pixel_sampler {
                PixelSampler::Stratified => 0,
                PixelSampler::Independent => 1,
            },
        };
        let (paths_per_dispatch, max_samples) = match time_limit {
            Some(_) => (PATHS_PER_TIMED_DISPATCH, MAX_SAMPLES_PER_TIMED_DISPATCH),
            None => (PATHS_PER_DISPATCH, MAX_SAMPLES_PER_DISPATCH),
        };
        let per_dispatch = (paths_per_dispatch / pixels).clamp(1, max_samples) as u32;
        let (mut done, mut passes) = (0u32, 0u32);
        while done < settings.spp && (passes == 0 || time_limit.is_none_or(|limit| start.elapsed() < limit)) {
            let n = per_dispatch.min(settings.spp - done);
            params.sample_offset = done;
            params.samples_per_dispatch = n;
            self.gpu.queue.write_buffer(&params_buf, 0, bytemuck::bytes_of(&params));
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("path") });
            {
                let mut pass = encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("path"), timestamp_writes: None });
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
            }
            self.gpu.queue.submit([encoder.finish()]);
            device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| TraceError::Gpu(format!("waiting for the render: {e}")))?;
            done += n;
            passes += 1;
            progress(done, settings.spp);
        }

        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_buffer_to_buffer(&accum, 0, &readback, 0, accum_bytes);
        self.gpu.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        readback.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| TraceError::Gpu(format!("reading the image back: {e}")))?;
        rx.recv()
            .map_err(|_| TraceError::Gpu("read-back never completed".into()))?
            .map_err(|e| TraceError::Gpu(format!("reading the image back: {e}")))?;
        let view = readback.get_mapped_range(..).map_err(|e| TraceError::Gpu(format!("mapping the image: {e}")))?;
        let data: Vec<f32> = bytemuck::cast_slice(&view).to_vec();
        drop(view);
        readback.unmap();

        let mut out = unpack(&data, w as usize, h as usize, done);
        out.passes = passes;
        out.literals = upload.literals;
        out.seconds = start.elapsed().as_secs_f64();
        Ok(out)
    }
}

/// Turns the per-pixel accumulators (the beauty's mean and sum of squared deviations, the features' sums)
/// into means, variances of the mean and unit normals. A variance that overflowed f32 (samples above about
/// 1e19, whose squares do) is reported as the largest finite value, so that the image stays finite.
fn unpack(data: &[f32], w: usize, h: usize, spp: u32) -> RenderOutput {
    let n = spp as f64;
    let image = |channels| Image { width: w, height: h, channels, data: Vec::with_capacity(w * h * channels) };
    let (mut color, mut var, mut albedo, mut diffuse, mut specular, mut normal) =
        (image(3), image(3), image(3), image(3), image(3), image(3));
    let mut discarded = 0u64;
    for px in data.chunks_exact(ACCUM_STRIDE) {
        for c in 0..3 {
            // The kernel keeps the beauty's running mean and sum of squared deviations (merged per dispatch).
            color.data.push(px[c]);
            // Unbiased sample variance, divided by n for the variance of the mean.
            let sample_var = if spp > 1 { (px[3 + c] as f64 / (n - 1.0)).max(0.0) } else { 0.0 };
            let variance = (sample_var / n) as f32;
            var.data.push(if variance.is_finite() { variance } else { f32::MAX });
            albedo.data.push((px[6 + c] as f64 / n) as f32);
            diffuse.data.push((px[9 + c] as f64 / n) as f32);
            specular.data.push((px[12 + c] as f64 / n) as f32);
        }
        let nrm = glam::Vec3::from_slice(&px[15..18]);
        let len = nrm.length();
        let unit = if len > 1e-12 { nrm / len } else { glam::Vec3::ZERO };
        normal.data.extend_from_slice(&unit.to_array());
        discarded += px[18] as u64;
    }
    RenderOutput {
        color,
        color_variance: var,
        albedo,
        diffuse,
        specular,
        normal,
        spp,
        passes: 0,
        discarded_samples: discarded,
        literals: SceneLiterals::default(),
        seconds: 0.0,
    }
}
