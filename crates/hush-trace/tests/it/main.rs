//! hush-trace's integration tests. Those that render need a Vulkan adapter (lavapipe on a
//! machine without a GPU: `apt-get install -y libvulkan1 mesa-vulkan-drivers`); they fail,
//! never skip, without one, since CI installs it.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use hush_dataset::{Image, read_rgb};
use hush_scene::Scene;
use hush_trace::{GpuContext, KernelFeatures, PixelSampler, RenderOutput, RenderSettings, Renderer};

fn shared() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    assert!(p.is_dir(), "the shared material is expected at {} (beside the repository)", p.display());
    p
}

fn cbox_dir() -> PathBuf {
    shared().join("reference/mitsuba-cbox")
}

fn gpu() -> &'static GpuContext {
    static GPU: OnceLock<GpuContext> = OnceLock::new();
    GPU.get_or_init(|| GpuContext::new().unwrap_or_else(|e| panic!("{e}")))
}

fn render(scene: &Scene, spp: u32, seed: u64) -> RenderOutput {
    Renderer::new(gpu()).unwrap().render(scene, &RenderSettings::new(spp, seed), &mut |_, _| {}).unwrap()
}

fn cbox(size: u32) -> Scene {
    let mut scene = Scene::load(&cbox_dir().join("scene.xml")).unwrap();
    scene.film.width = size;
    scene.film.height = size;
    scene
}

#[test]
fn kernel_validates_with_naga() {
    let module = naga::front::wgsl::parse_str(hush_trace::KERNEL_SOURCE).expect("WGSL parses");
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .expect("WGSL validates");
}

/// The kernel with the box's 36 triangles written in validates too, and holds all of them.
#[test]
fn specialized_kernel_validates_with_naga() {
    let source = hush_trace::kernel_source(&cbox(16), false).unwrap();
    assert_eq!(source.matches("test_triangle_rows(").count() - 1, 36, "the declaration, 36 literal calls");
    let module = naga::front::wgsl::parse_str(&source).expect("WGSL parses");
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .expect("WGSL validates");
    assert_eq!(hush_trace::kernel_source(&cbox(16), true).unwrap(), hush_trace::KERNEL_SOURCE);
    // A scene of analytic shapes only: each is a literal call too.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba/analytic");
    let scene = Scene::load(&dir.join("scene.xml")).unwrap();
    let source = hush_trace::kernel_source(&scene, false).unwrap();
    assert_eq!(source.matches("test_shape_at(").count() - 2, scene.meshes.len(), "the declaration, the buffer call");
    let module = naga::front::wgsl::parse_str(&source).expect("WGSL parses");
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .expect("WGSL validates");
}

/// The box at 256 spp against Mitsuba 3's 3156-spp render.
///
/// hush renders at 128² instead of 512²: with a box filter, a 128² pixel's expected value is
/// exactly the mean of the 4×4 Mitsuba pixels it covers, so each 32×32 block of the 512²
/// reference is an 8×8 block here. Tolerance per block and channel: 4 standard errors of
/// hush's block mean (from its own per-pixel sample variance) plus 0.5 % of the reference,
/// which covers the reference's own noise (3156 spp, its block SE is below 0.1 %) and f32
/// accumulation. Each channel's image mean must agree within 0.5 %.
#[test]
fn cornell_box_is_unbiased_against_mitsuba() {
    let out = render(&cbox(128), 256, 1);
    let reference = read_rgb(cbox_dir().join("mitsuba_3156spp.exr")).unwrap();
    let reference = reference.downsample_box(4).unwrap();
    assert_eq!((reference.width, reference.height), (128, 128));
    let block = 8;
    let mut worst = 0.0f64;
    for by in 0..128 / block {
        for bx in 0..128 / block {
            for c in 0..3 {
                let (mut ours, mut theirs, mut var) = (0.0f64, 0.0f64, 0.0f64);
                for y in by * block..(by + 1) * block {
                    for x in bx * block..(bx + 1) * block {
                        ours += out.color.pixel(x, y)[c] as f64;
                        theirs += reference.pixel(x, y)[c] as f64;
                        var += out.color_variance.pixel(x, y)[c] as f64;
                    }
                }
                let n = (block * block) as f64;
                let (ours, theirs, se) = (ours / n, theirs / n, var.sqrt() / n);
                let tol = 4.0 * se + 0.005 * theirs.abs();
                worst = worst.max((ours - theirs).abs() / tol.max(1e-12));
                assert!(
                    (ours - theirs).abs() <= tol,
                    "block ({bx},{by}) channel {c}: hush {ours:.5} vs Mitsuba {theirs:.5}, tolerance {tol:.5} (SE {se:.5})"
                );
            }
        }
    }
    let (ours, theirs) = (out.color.mean(), reference.mean());
    for c in 0..3 {
        let rel = (ours[c] - theirs[c]).abs() / theirs[c];
        assert!(
            rel < 0.005,
            "channel {c} image mean: hush {} vs Mitsuba {} ({:.3} %)",
            ours[c],
            theirs[c],
            rel * 100.0
        );
    }
    eprintln!("worst block deviation: {:.2} of its tolerance", worst);
}

/// A tolerance that can fail: the same comparison rejects the box with its light 2 % dimmer.
#[test]
fn unbiasedness_check_detects_a_two_percent_error() {
    let mut scene = cbox(64);
    let light = scene.meshes.iter_mut().find(|m| m.emission.is_some()).unwrap();
    light.emission = light.emission.map(|e| e * 0.98);
    let out = render(&scene, 256, 2);
    let reference = read_rgb(cbox_dir().join("mitsuba_3156spp.exr")).unwrap().downsample_box(8).unwrap();
    let (ours, theirs) = (out.color.mean(), reference.mean());
    let rel = (ours[0] - theirs[0]).abs() / theirs[0];
    assert!(rel > 0.005, "a 2 % dimmer light went unnoticed: {:.3} %", rel * 100.0);
}

fn assert_finite(name: &str, image: &Image) {
    assert_eq!(image.count_non_finite(), 0, "{name} holds NaN or Inf");
}

#[test]
fn auxiliary_features_are_exact() {
    let out = render(&cbox(64), 8, 3);
    for (name, img) in [
        ("color", &out.color),
        ("variance", &out.color_variance),
        ("albedo", &out.albedo),
        ("diffuse", &out.diffuse),
        ("specular", &out.specular),
        ("normal", &out.normal),
    ] {
        assert_finite(name, img);
    }
    assert_eq!(out.discarded_samples, 0);
    // A pixel well inside the red wall (left side, mid height) sees only the red wall.
    let red = [0.570068f32, 0.0430135, 0.0443706];
    let albedo = out.albedo.pixel(4, 32);
    for c in 0..3 {
        assert!((albedo[c] - red[c]).abs() < 1e-4, "red wall albedo {albedo:?}");
        assert!((out.diffuse.pixel(4, 32)[c] - red[c]).abs() < 1e-4);
    }
    // The red wall is the plane x = -1 facing +x.
    let n = out.normal.pixel(4, 32);
    assert!((n[0] - 1.0).abs() < 1e-5 && n[1].abs() < 1e-5 && n[2].abs() < 1e-5, "{n:?}");
    // Diffuse-only scene: no specular reflectance anywhere.
    assert!(out.specular.data.iter().all(|&v| v == 0.0));
    // Wherever something was hit, the normal has unit length.
    for y in 0..64 {
        for x in 0..64 {
            let n = out.normal.pixel(x, y);
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let hit = out.albedo.pixel(x, y).iter().any(|&a| a > 0.0);
            if hit {
                assert!((len - 1.0).abs() < 1e-5, "normal at ({x},{y}) has length {len}");
            }
        }
    }
}

#[test]
fn max_depth_one_sees_only_the_light() {
    let mut scene = cbox(64);
    scene.max_depth = 1;
    let out = render(&scene, 4, 4);
    let emission = [18.387f32, 13.9873, 6.75357];
    let mut lit = 0;
    for px in out.color.data.chunks_exact(3) {
        if px[0] > 0.0 {
            lit += 1;
            // Only pixels entirely on the light are exactly its radiance; edges average.
            for c in 0..3 {
                assert!(px[c] <= emission[c] * (1.0 + 1e-5), "{px:?}");
            }
        } else {
            assert_eq!(px, [0.0, 0.0, 0.0]);
        }
    }
    assert!(lit > 0, "the light should be visible");
    assert!(out.color.data.chunks_exact(3).any(|p| (p[0] - emission[0]).abs() < 1e-4));
}

#[test]
fn same_seed_same_image_other_seed_other_image() {
    let scene = cbox(32);
    let a = render(&scene, 4, 11);
    let b = render(&scene, 4, 11);
    let c = render(&scene, 4, 12);
    assert_eq!(a.color.data, b.color.data);
    assert_ne!(a.color.data, c.color.data);
}

#[test]
fn zero_spp_is_an_error() {
    let gpu = gpu();
    let err = Renderer::new(gpu).unwrap().render(&cbox(8), &RenderSettings::new(0, 0), &mut |_, _| {}).unwrap_err();
    assert!(err.to_string().contains("spp"), "{err}");
}

/// A closed cube whose inner walls have diffuse albedo `a` and emit radiance `l` toward the
/// inside: every path sees the same radiance, l · (1 − a^D) / (1 − a) for max_depth D (one
/// emission term per vertex, D vertices), and l / (1 − a) without a limit.
fn furnace(dir: &Path, a: f32, l: f32, max_depth: i64) -> Scene {
    // Corners of [-1, 1]³; each face's triangles wind counter-clockwise seen from inside.
    let obj = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
               f 1 2 3\nf 1 3 4\nf 5 8 7\nf 5 7 6\nf 1 5 6\nf 1 6 2\nf 4 3 7\nf 4 7 8\nf 1 4 8\nf 1 8 5\nf 2 6 7\nf 2 7 3\n";
    std::fs::write(dir.join("cube.obj"), obj).unwrap();
    let body = format!(
        r#"<shape type="obj"><string name="filename" value="cube.obj"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="{a}, {a}, {a}"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="{l}, {l}, {l}"/></emitter></shape>"#
    );
    furnace_scene(&dir.join(format!("furnace-{max_depth}.xml")), max_depth, &body)
}

/// A furnace's scene file: `body` seen from inside by a 32² camera, at `max_depth`.
fn furnace_scene(path: &Path, max_depth: i64, body: &str) -> Scene {
    let xml = format!(
        r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
  <sensor type="perspective"><float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0.1,0.2,0.3" target="0.5,-0.3,-1" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film></sensor>
  {body}
</scene>"#
    );
    std::fs::write(path, xml).unwrap();
    Scene::load(path).unwrap()
}

/// White furnace: the image mean equals the closed form within 1 % for several depth limits.
/// The estimator's spread is small here (1 % is many standard errors at 64 spp), and an
/// off-by-one depth convention moves the mean by 7 % or more at max_depth ≤ 3.
#[test]
fn white_furnace_matches_the_closed_form() {
    let dir = std::env::temp_dir().join(format!("hush-furnace-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (a, l) = (0.5f32, 1.0f32);
    for (depth, expect) in [(1i64, 1.0f64), (2, 1.5), (3, 1.75), (8, 1.9921875), (-1, 2.0)] {
        let out = render(&furnace(&dir, a, l, depth), 64, 5);
        for c in 0..3 {
            let mean = out.color.mean()[c];
            assert!((mean - expect).abs() < 0.01 * expect, "max_depth {depth}: mean {mean}, closed form {expect}");
        }
    }
}

/// The white furnace of analytic shapes, seen from inside: a sphere with `flip_normals` (light
/// sampling from inside it is by area), and a closed can (an open cylinder with flipped normals and
/// two disks facing in), every shape diffuse with albedo 0.5 and emitting 1. Image mean within 1 %
/// of the closed form at three depth limits, as for the cube above.
#[test]
fn white_furnace_holds_for_analytic_shapes() {
    let dir = std::env::temp_dir().join(format!("hush-furnace-analytic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let material = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter>"#;
    let sphere = format!(
        r#"<shape type="sphere"><float name="radius" value="2"/><boolean name="flip_normals" value="true"/>{material}</shape>"#
    );
    let can = format!(
        r#"<shape type="cylinder"><point name="p0" value="0,-1,0"/><point name="p1" value="0,1,0"/>
    <float name="radius" value="1.5"/><boolean name="flip_normals" value="true"/>{material}</shape>
  <shape type="disk"><transform name="to_world"><scale value="1.5"/><rotate x="1" angle="-90"/><translate y="-1"/></transform>{material}</shape>
  <shape type="disk"><transform name="to_world"><scale value="1.5"/><rotate x="1" angle="90"/><translate y="1"/></transform>{material}</shape>"#
    );
    for (name, body) in [("sphere", sphere), ("can", can)] {
        for (depth, expect) in [(2i64, 1.5f64), (3, 1.75), (-1, 2.0)] {
            let scene = furnace_scene(&dir.join(format!("{name}-{depth}.xml")), depth, &body);
            assert_eq!(scene.analytic_count(), scene.meshes.len(), "{name}: analytic");
            let out = render(&scene, 64, 5);
            for c in 0..3 {
                let mean = out.color.mean()[c];
                assert!(
                    (mean - expect).abs() < 0.01 * expect,
                    "{name}, max_depth {depth}: mean {mean}, closed form {expect}"
                );
            }
        }
    }
}

/// A `cube` is six analytic rectangles in the kernel: it renders what its twelve triangles render
/// (faces, their front sides, texture coordinates, and light sampling spread over the faces of an
/// emitting cube), block by block within 4 combined standard errors of the two renders plus 0.5 %,
/// with a textured cube lit by an emitting one on a floor.
#[test]
fn a_cube_of_rectangles_renders_what_its_triangles_do() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba/textured");
    let xml = r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="2.5,2,3.5" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film></sensor>
  <shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/><translate y="-1"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
  <shape type="cube"><transform name="to_world"><scale x="0.8" y="1" z="0.6"/><rotate y="1" angle="25"/></transform>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="checker.png"/></texture></bsdf></shape>
  <shape type="cube"><transform name="to_world"><scale value="0.2"/><translate x="-1.2" y="1.2" z="1"/></transform>
    <emitter type="area"><rgb name="radiance" value="20, 18, 15"/></emitter></shape>
</scene>"#;
    let path = dir.join("cube-faces.xml");
    let scene = Scene::from_mitsuba_str(xml, &path).unwrap();
    assert!(scene.meshes.iter().all(|m| m.analytic.is_some()));
    let mut triangles = scene.clone();
    triangles.meshes.iter_mut().filter(|m| m.indices.len() == 12).for_each(|m| m.analytic = None);
    let (a, b) = (render(&scene, 1024, 3), render(&triangles, 1024, 4));
    let mut off = Vec::new();
    for by in 0..4 {
        for bx in 0..4 {
            for c in 0..3 {
                let (mut ma, mut mb, mut var) = (0.0f64, 0.0f64, 0.0f64);
                for y in by * 8..by * 8 + 8 {
                    for x in bx * 8..bx * 8 + 8 {
                        ma += a.color.pixel(x, y)[c] as f64 / 64.0;
                        mb += b.color.pixel(x, y)[c] as f64 / 64.0;
                        var += (a.color_variance.pixel(x, y)[c] + b.color_variance.pixel(x, y)[c]) as f64 / 4096.0;
                    }
                }
                if (ma - mb).abs() > 4.0 * var.sqrt() + 0.005 * mb.abs() {
                    off.push(format!("block ({bx},{by}) ch {c}: rectangles {ma:.5} triangles {mb:.5}"));
                }
            }
        }
    }
    assert!(off.is_empty(), "{} blocks off:\n{}", off.len(), off.join("\n"));
}

/// The Mitsuba 3 references of `data/tests/mitsuba` (one scene per BSDF family, rendered by
/// `render_references.py`), compared block by block: each 8×8 block mean of each channel
/// within 4 combined standard errors (hush's from its per-pixel variance, Mitsuba's from the
/// spread of its 16 passes, `reference.json`) plus 0.5 % of the reference.
fn compare_with_mitsuba(name: &str, spp: u32) -> RenderOutput {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba").join(name);
    let scene = Scene::load(&dir.join("scene.xml")).unwrap();
    let out = render(&scene, spp, 17);
    let reference = read_rgb(dir.join("mitsuba.exr")).unwrap();
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
    let block = meta["block"].as_u64().unwrap() as usize;
    let rel_se = &meta["block_rel_se"];
    assert_eq!((out.color.width, out.color.height), (reference.width, reference.height));
    let mut failures = Vec::new();
    for by in 0..reference.height / block {
        for bx in 0..reference.width / block {
            for c in 0..3 {
                let (mut ours, mut theirs, mut var) = (0.0f64, 0.0f64, 0.0f64);
                for y in by * block..(by + 1) * block {
                    for x in bx * block..(bx + 1) * block {
                        ours += out.color.pixel(x, y)[c] as f64;
                        theirs += reference.pixel(x, y)[c] as f64;
                        var += out.color_variance.pixel(x, y)[c] as f64;
                    }
                }
                let n = (block * block) as f64;
                let (ours, theirs) = (ours / n, theirs / n);
                let se_ref = rel_se[by][bx][c].as_f64().unwrap() * theirs.abs();
                let se = (var / (n * n) + se_ref * se_ref).sqrt();
                let tol = 4.0 * se + 0.005 * theirs.abs();
                if (ours - theirs).abs() > tol {
                    failures.push(format!("block ({bx},{by}) ch {c}: hush {ours:.5} Mitsuba {theirs:.5} tol {tol:.5}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{name}: {} blocks off:\n{}", failures.len(), failures.join("\n"));
    out
}

#[test]
fn matches_mitsuba_diffuse_and_twosided() {
    compare_with_mitsuba("diffuse-twosided", 256);
}

#[test]
fn matches_mitsuba_smooth_conductor() {
    compare_with_mitsuba("conductor", 256);
}

#[test]
fn matches_mitsuba_rough_conductor() {
    compare_with_mitsuba("roughconductor", 256);
}

#[test]
fn matches_mitsuba_smooth_dielectric() {
    compare_with_mitsuba("dielectric", 512);
}

#[test]
fn matches_mitsuba_thin_dielectric() {
    compare_with_mitsuba("thindielectric", 256);
}

#[test]
fn matches_mitsuba_rough_dielectric() {
    compare_with_mitsuba("roughdielectric", 512);
}

#[test]
fn matches_mitsuba_rough_plastic() {
    compare_with_mitsuba("roughplastic", 256);
}

#[test]
fn matches_mitsuba_plastic() {
    compare_with_mitsuba("plastic", 256);
}

/// Beckmann microfacets (Mitsuba's default distribution): a rough conductor and a rough plastic.
#[test]
fn matches_mitsuba_beckmann() {
    compare_with_mitsuba("beckmann", 256);
}

/// An 8-bit sRGB checkerboard (bilinear, repeat) as the diffuse reflectance of the floor and
/// the back wall: UVs of Mitsuba's `rectangle`, sRGB decoding and the bilinear lookup.
#[test]
fn matches_mitsuba_textured() {
    compare_with_mitsuba("textured", 256);
}

/// A `constant` environment is the only light: escaped rays, its uniform sampling and MIS.
#[test]
fn matches_mitsuba_constant_environment() {
    compare_with_mitsuba("constant", 256);
}

/// A 64×32 sky with a sun as the only light: Mitsuba's lat-long orientation and texel
/// placement, bilinear radiance, importance sampling and MIS.
#[test]
fn matches_mitsuba_environment_map() {
    compare_with_mitsuba("envmap", 512);
}

#[test]
fn matches_mitsuba_under_stiff_lighting() {
    compare_with_mitsuba("stiff", 512);
}

/// Mitsuba's analytic shapes, intersected exactly: a textured `sphere` (its (φ / 2π, θ / π) texture
/// coordinates under a rotation), an open `cylinder` from `p0` to `p1` capped by a `disk`, and the
/// room's `rectangle` walls, lit only by an emitting sphere (sampled by the cone it subtends) and an
/// emitting disk (sampled by area), both also seen directly and through MIS.
#[test]
fn matches_mitsuba_analytic_shapes() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba/analytic");
    let scene = Scene::load(&dir.join("scene.xml")).unwrap();
    assert_eq!(scene.analytic_count(), scene.meshes.len(), "every shape of the scene is analytic");
    assert!(KernelFeatures::of(&scene).shapes);
    compare_with_mitsuba("analytic", 512);
}

/// Four analytic spheres (diffuse, plastic, rough gold, glass) on a ground rectangle under a
/// constant sky: block by block as the other scenes, and each channel's image mean within 0.1 % of
/// Mitsuba's or, where the two renders' noise is larger than that, within 3 combined standard
/// errors (hush's from its per-pixel variance, Mitsuba's from the spread of its 16 passes,
/// `image_mean_rel_se` in `reference.json`). Tessellated spheres were 0.4 % brighter than
/// Mitsuba's on such a scene.
#[test]
fn spheres_under_a_sky_match_mitsuba_to_a_tenth_of_a_percent() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba/spheres-sky");
    let out = compare_with_mitsuba("spheres-sky", 1024);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
    let n = (out.color.width * out.color.height) as f64;
    for c in 0..3 {
        let (mut ours, mut var) = (0.0f64, 0.0f64);
        for y in 0..out.color.height {
            for x in 0..out.color.width {
                ours += out.color.pixel(x, y)[c] as f64;
                var += out.color_variance.pixel(x, y)[c] as f64;
            }
        }
        let ours = ours / n;
        let theirs = meta["image_mean"][c].as_f64().unwrap();
        let se_ref = meta["image_mean_rel_se"][c].as_f64().unwrap() * theirs;
        let se = (var / (n * n) + se_ref * se_ref).sqrt();
        let rel = ours / theirs - 1.0;
        eprintln!(
            "channel {c}: hush {ours:.6} Mitsuba {theirs:.6}: {:+.3} % ({:.2} standard errors)",
            rel * 100.0,
            (ours - theirs) / se
        );
        assert!(
            rel.abs() <= 1e-3 || (ours - theirs).abs() <= 3.0 * se,
            "channel {c}: hush's image mean {ours} is {:+.3} % from Mitsuba's {theirs} ({:.1} standard errors)",
            rel * 100.0,
            (ours - theirs).abs() / se
        );
    }
}

/// `render_within` stops at pass granularity, and neither check depends on the machine's speed:
/// a limit shorter than any pass still renders exactly one pass, the same image as `render` at
/// the spp it reached (8² pixels: 16 samples per pass under a limit; `render` of those 16 spp takes them in one pass too, so the same
/// dispatches, bit for bit); an hour's limit with an spp cap stops at the cap (40 spp is
/// 16 + 16 + 8 in three passes).
#[test]
fn time_limit_renders_whole_passes_up_to_the_spp_cap() {
    use std::time::Duration;
    let scene = cbox(8);
    let renderer = Renderer::new(gpu()).unwrap();
    let tiny = renderer
        .render_within(&scene, &RenderSettings::new(1000, 5), Some(Duration::from_nanos(1)), &mut |_, _| {})
        .unwrap();
    assert_eq!(tiny.passes, 1);
    assert!((1..1000).contains(&tiny.spp), "{} spp", tiny.spp);
    let same = renderer.render(&scene, &RenderSettings::new(tiny.spp, 5), &mut |_, _| {}).unwrap();
    assert_eq!((same.spp, same.passes), (tiny.spp, 1));
    assert_eq!(tiny.color.data, same.color.data);
    let mut reported = Vec::new();
    let capped = renderer
        .render_within(&scene, &RenderSettings::new(40, 5), Some(Duration::from_secs(3600)), &mut |d, _| {
            reported.push(d)
        })
        .unwrap();
    assert_eq!((capped.spp, capped.passes), (40, 3));
    assert_eq!(reported, [16, 32, 40]);
}

/// The kernel specialized to a scene (what it lacks compiled out, its small data written in as
/// literals) traces the same paths as the generic kernel: same random numbers, same decisions.
/// Compilers may contract floating-point operations differently, and a last-bit difference can
/// flip a Russian-roulette decision, so the check allows 2 % of the pixels to differ by more than
/// 1e-4 (relative) and the image means to differ by 0.5 %; a kernel that dropped a used feature
/// (here the rough plastic sphere and the textured floor) changes far more. The textured scene (only
/// rectangles) and the box (only triangles) also check the flat scan against the BVH walk and have
/// their shapes or triangles and their lights written in as literals; every scene here has its
/// materials as literals, and none has vertex normals.
#[test]
fn specialized_kernel_renders_what_the_generic_one_does() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba");
    // The rooms' walls are analytic rectangles; their spheres flat-shaded triangles.
    // Lit by a rectangle (light kind 2): a sphere's cone sampling and the other kinds are compiled out.
    let walls = KernelFeatures { shapes: true, light_kinds: 1 << 2, ..KernelFeatures::NONE };
    for (path, expect) in [
        (dir.join("roughplastic"), KernelFeatures { rough_plastic: true, ..walls }),
        // Only shapes: intersected by a flat scan instead of the BVH walk of the generic kernel.
        (dir.join("textured"), KernelFeatures { textures: true, flat_scan: true, ..walls }),
        // Lit by its map alone: next-event estimation's light side is compiled out; its GGX
        // conductor sphere keeps its code while the mirror's, glass's and plastic's go.
        (
            dir.join("envmap"),
            KernelFeatures { environment: true, environment_map: true, light_kinds: 0, rough_conductor: true, ..walls },
        ),
        // Lit by triangles (light kind 4).
        (cbox_dir(), KernelFeatures { flat_scan: true, light_kinds: 1 << 4, ..KernelFeatures::NONE }),
    ] {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let mut scene = Scene::load(&path.join("scene.xml")).unwrap();
        assert_eq!(KernelFeatures::of(&scene), expect, "{name}");
        let source = hush_trace::kernel_source(&scene, false).unwrap();
        assert!(
            source.contains("materials as literals, word by word.\nfn material(i: u32) -> Material {"),
            "{name}: materials as literals"
        );
        if expect.flat_scan {
            assert!(source.contains("-> LightTri {\n    var l = "), "{name}: lights as literals");
        }
        scene.film.width = 24;
        scene.film.height = 24;
        let settings = RenderSettings::new(4, 3);
        let special = Renderer::new(gpu()).unwrap().render(&scene, &settings, &mut |_, _| {}).unwrap();
        let generic =
            Renderer::new(gpu()).unwrap().with_generic_kernel(true).render(&scene, &settings, &mut |_, _| {}).unwrap();
        let differ = special
            .color
            .data
            .iter()
            .zip(&generic.color.data)
            .filter(|(a, b)| (*a - *b).abs() > 1e-4 * a.abs().max(b.abs()) + 1e-7)
            .count();
        assert!(differ * 50 <= special.color.data.len(), "{name}: {differ} values differ");
        for c in 0..3 {
            let (a, b) = (special.color.mean()[c], generic.color.mean()[c]);
            assert!((a - b).abs() <= 0.005 * b.abs(), "{name} channel {c}: specialized {a} vs generic {b}");
        }
    }
}

/// As in Mitsuba, a mesh with vertex normals emits (and reflects, if one-sided) on the side its
/// normals point to, whatever its winding: the light here is wound to face up but its normals
/// point down at the floor, so the floor is lit.
#[test]
fn vertex_normals_choose_the_front_side() {
    let dir = std::env::temp_dir().join(format!("hush-normals-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("floor.obj"), "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\nf 1 4 3\nf 1 3 2\n").unwrap();
    // Counter-clockwise seen from above (normal +y), vertex normals -y.
    std::fs::write(
        dir.join("light.obj"),
        "v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\nvn 0 -1 0\nf 1//1 4//1 3//1\nf 1//1 3//1 2//1\n",
    )
    .unwrap();
    let xml = r#"<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0,0.5,3" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>
  <shape type="obj"><string name="filename" value="floor.obj"/><bsdf type="diffuse"/></shape>
  <shape type="obj"><string name="filename" value="light.obj"/>
    <emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter></shape>
</scene>"#;
    std::fs::write(dir.join("scene.xml"), xml).unwrap();
    let scene = Scene::load(&dir.join("scene.xml")).unwrap();
    let out = render(&scene, 4, 1);
    assert!(out.color.mean()[0] > 0.01, "the floor should be lit: mean {:?}", out.color.mean());
}

/// The pixel filters against their closed forms: the camera sees an emitter of radiance 1 over the
/// right half of the image, its edge on the border between columns 7 and 8 of 16, so column c reads
/// the filter's mass beyond the edge, P(X > 7.5 − c) for the filter's density X. A tent of radius 1
/// (Mitsuba's default) gives 0, 1/8, 7/8, 1 for columns 6 to 9; the box 0, 0, 1, 1; Mitsuba's
/// windowed Gaussian (σ = 0.5, cut at 2, the filter of a Mitsuba film that names none) what a numerical
/// integral of its formula gives (0.0013, 0.1586, 0.8414, 0.9987). Each column mean holds 4 × 4096
/// samples, each 0 or 1: its standard error is at most 0.004 (p = 1/2), and the tolerance is 0.02, 5 of
/// those; a tent of radius 2 would read 0.28 beside the edge.
///
/// At the image's border the filter is cut off and renormalized, as Mitsuba's film does (it takes no
/// samples beyond its border): with the edge between columns 14 and 15 and a tent of radius 2, the
/// last column reads P(−0.5 < X < 0.5) / P(X < 0.5) = 0.609 (0.719 uncut) and column 14
/// P(0.5 < X < 1.5) / P(X < 1.5) = 0.258.
#[test]
fn pixel_filters_match_their_closed_forms() {
    let dir = std::env::temp_dir().join(format!("hush-filters-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Mitsuba's gaussian: max(0, exp(-x²/2σ²) - exp(-8)) on |x| <= 4σ; its mass beyond a, by the midpoint rule.
    let gaussian_beyond = |a: f64| {
        let g = |x: f64| ((-x * x / (2.0 * 0.25)).exp() - (-8.0f64).exp()).max(0.0);
        let n = 200_000;
        let mass = |lo: f64, hi: f64| {
            (0..n).map(|i| g(lo + (i as f64 + 0.5) * (hi - lo) / n as f64)).sum::<f64>() * (hi - lo) / n as f64
        };
        (mass(a.max(-2.0), 2.0) / mass(-2.0, 2.0)) as f32
    };
    let gaussian = [1.5, 0.5, -0.5, -1.5].map(gaussian_beyond);
    // The tent of radius 2: its distribution function.
    let tent2 = |x: f32| if x <= 0.0 { (2.0 + x).powi(2) / 8.0 } else { 1.0 - (2.0 - x).powi(2) / 8.0 };
    let cut = [(tent2(1.5) - tent2(0.5)) / tent2(1.5), (tent2(0.5) - tent2(-0.5)) / tent2(0.5)];
    for (filter, edge_column, expect) in [
        ("<rfilter type=\"tent\"/>", 8, vec![0.0, 0.125, 0.875, 1.0]),
        ("<rfilter type=\"box\"/>", 8, vec![0.0, 0.0, 1.0, 1.0]),
        ("", 8, gaussian.to_vec()),
        ("<rfilter type=\"tent\"><float name=\"radius\" value=\"2\"/></rfilter>", 15, cut.to_vec()),
    ] {
        // The edge's x on the plane z = -1: the image spans ±tan(30°) across its 16 columns.
        let edge = (2.0 * edge_column as f64 / 16.0 - 1.0) * 30f64.to_radians().tan();
        let xml = format!(
            r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="1"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, -1" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="4"/>{filter}</film>
  </sensor>
  <shape type="rectangle">
    <transform name="to_world"><scale x="10" y="10"/><translate x="{}" z="-1"/></transform>
    <emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter>
  </shape>
</scene>"#,
            edge + 10.0
        );
        std::fs::write(dir.join("scene.xml"), xml).unwrap();
        let scene = Scene::load(&dir.join("scene.xml")).unwrap();
        let out = render(&scene, 4096, 9);
        for (k, want) in expect.iter().enumerate() {
            let column = edge_column + k - expect.len() / 2;
            let mean = (0..4).map(|y| out.color.data[(y * 16 + column) * 3]).sum::<f32>() / 4.0;
            let name = if filter.is_empty() { "no rfilter (gaussian)" } else { filter };
            assert!((mean - want).abs() <= 0.02, "{name}: column {column} reads {mean}, expected {want}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The kernel reads the first 585 analytic shapes from a uniform buffer and the rest from a storage
/// buffer. A lit sphere that is shape 600 must render as when it is the only shape (up to last bits): 599 tiny
/// spheres far behind the camera push it past the uniform buffer (a ray reaching them is far rarer
/// than one in 10^9). A storage read gone wrong (a clamped or zeroed record) moves or erases it.
#[test]
fn shapes_past_the_uniform_buffer_render_as_the_first_ones() {
    let sphere = |x: f32, z: f32, r: f32, bsdf: &str| {
        format!(
            r#"<shape type="sphere"><point name="center" x="{x}" y="0" z="{z}"/><float name="radius" value="{r}"/>{bsdf}</shape>"#
        )
    };
    let head = r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/><rfilter type="box"/></film></sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 0.8, 0.6"/></emitter>"#;
    let lit = sphere(0.3, 0.0, 1.0, r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf>"#);
    let far: String = (0..599).map(|i| sphere(i as f32 * 0.01, 1.0e4, 1.0e-4, "")).collect();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shapes.xml");
    let many = Scene::from_mitsuba_str(&format!("{head}{far}{lit}</scene>"), &path).unwrap();
    let one = Scene::from_mitsuba_str(&format!("{head}{lit}</scene>"), &path).unwrap();
    assert_eq!(many.analytic_count(), 600);
    assert!(KernelFeatures::of(&many).many_shapes && !KernelFeatures::of(&one).many_shapes);
    let (a, b) = (render(&many, 16, 5), render(&one, 16, 5));
    let peak = b.color.data.iter().fold(0.0f32, |m, &v| m.max(v));
    let worst = a.color.data.iter().zip(&b.color.data).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(peak > 0.1, "the sphere is lit");
    // Last bits may differ: one kernel walks a BVH, the other scans the sphere written in.
    assert!(worst <= 1e-3 * peak, "largest difference {worst} (peak {peak})");
}

/// A 5×5 film (`filter`) looking straight at an emitting rectangle of `radiance` (and nothing else, at
/// max_depth 1) whose edge, for the translation `shift` (`x="2"`: its left edge), runs through the middle
/// of the centre pixel. Written under a folder named by `tag` and the process.
fn edge_scene(tag: &str, filter: &str, shift: &str, radiance: f64) -> Scene {
    let dir = std::env::temp_dir().join(format!("hush-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("edge-{filter}.xml"));
    std::fs::write(
        &path,
        format!(
            r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="1"/></integrator>
  <sensor type="perspective"><float name="fov" value="20"/>
    <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="5"/><integer name="height" value="5"/><rfilter type="{filter}"/></film></sensor>
  <shape type="rectangle"><transform name="to_world"><scale value="2"/><translate {shift}/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter></shape>
</scene>"#
        ),
    )
    .unwrap();
    Scene::load(&path).unwrap()
}

/// The per-pixel sample variance on analytic cases, at 65536 spp of a bright emitter (where E[x²] − E[x]²
/// from f32 sums cancels): a camera looks straight at an emitting rectangle (radiance 1000.3, max_depth 1:
/// emitters seen directly, nothing else) whose left edge runs through the middle of the centre pixel of
/// a 5×5 box-filtered image. A pixel inside the light sees 1000.3 in every sample and must have variance
/// exactly 0, as must a pixel beside it that sees nothing; the centre pixel is a Bernoulli of coverage ½
/// times the radiance: mean L/2 within 1 % (its standard error is 0.4 %) and sample variance L²/4
/// within 5 % (the sample variance of a Bernoulli of ½ has kurtosis 1: its own spread is far below that).
#[test]
fn sample_variance_is_exact_on_analytic_pixels() {
    let scene = edge_scene("variance", "box", "x=\"2\"", 1000.3);
    let spp = 65536u32;
    let out = render(&scene, spp, 9);
    let radiance = 1000.3f64;
    let n = f64::from(spp);
    for c in 0..3 {
        let (lit, dark) = (out.color_variance.pixel(3, 2)[c], out.color_variance.pixel(1, 2)[c]);
        assert_eq!(out.color.pixel(3, 2)[c], 1000.3, "inside the light");
        assert_eq!((lit, dark), (0.0, 0.0), "a constant pixel has no variance (inside, beside the light)");
        let mean = f64::from(out.color.pixel(2, 2)[c]);
        assert!((mean / radiance - 0.5).abs() < 0.005, "the edge pixel's coverage: {}", mean / radiance);
        let sample_var = f64::from(out.color_variance.pixel(2, 2)[c]) * n;
        let bernoulli = radiance * radiance * 0.25;
        assert!(
            (sample_var / bernoulli - 1.0).abs() < 0.05,
            "the edge pixel's sample variance {sample_var}, a Bernoulli of ½ gives {bernoulli}"
        );
    }
}

/// `PixelSampler::Stratified`: a pixel whose middle an emitter's edge runs through (vertically or
/// horizontally, on a box and on a tent film) gets exactly half of its 16 samples on the light at every
/// seed, as a (0, 2)-sequence puts 8 of any 16 consecutive points from 0 in each half of the square,
/// and the tent's inverse keeps each half. Independent positions give a Binomial(16, ½) count, exactly 8
/// with probability 0.196 per render (all 8 seeds of one case by chance 2e-6): the default sampler
/// misses it at some seed.
#[test]
fn pixel_positions_are_stratified() {
    for (filter, shift) in [("box", "x=\"2\""), ("tent", "x=\"2\""), ("box", "y=\"2\""), ("tent", "y=\"-2\"")] {
        let scene = edge_scene("strata", filter, shift, 16.0);
        let renderer = Renderer::new(gpu()).unwrap();
        let centre = |seed, pixel_sampler| {
            let settings = RenderSettings { spp: 16, seed, pixel_sampler };
            renderer.render(&scene, &settings, &mut |_, _| {}).unwrap().color.pixel(2, 2)[0]
        };
        for seed in 1..=8 {
            let c = centre(seed, PixelSampler::Stratified);
            assert_eq!(c, 8.0, "{filter} film, edge at {shift}, seed {seed}: {c} (16 × the light's share)");
        }
        let independent: Vec<f32> = (1..=8).map(|seed| centre(seed, PixelSampler::default())).collect();
        assert!(independent.iter().any(|&c| c != 8.0), "{filter} film, edge at {shift}: {independent:?}");
    }
}

/// `prepare` (on another thread, as a dataset runs it while the previous scene renders) compiles the kernel
/// that every render of the scene then uses: other cameras and film sizes find it; another scene compiles its own.
#[test]
fn prepare_compiles_the_kernel_every_view_of_the_scene_uses() {
    let renderer = Renderer::new(gpu()).unwrap();
    let scene = cbox(8);
    let t = std::time::Instant::now();
    std::thread::scope(|s| s.spawn(|| renderer.prepare(&scene).unwrap()).join().unwrap());
    let compile = t.elapsed();
    assert_eq!(renderer.kernels_compiled(), 1);
    let mut other_view = cbox(16);
    other_view.camera.fov_y_deg *= 0.8;
    let t = std::time::Instant::now();
    for s in [&scene, &other_view] {
        renderer.render(s, &RenderSettings::new(1, 1), &mut |_, _| {}).unwrap();
    }
    assert_eq!(renderer.kernels_compiled(), 1, "a view of a prepared scene compiled its kernel again");
    assert_eq!(renderer.scenes_uploaded(), 1, "a view of a prepared scene was flattened and uploaded again");
    eprintln!("prepare: {compile:?}; then two renders of 1 spp: {:?}", t.elapsed());
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/tests/mitsuba/analytic");
    let shapes = Scene::load(&dir.join("scene.xml")).unwrap();
    renderer.prepare(&shapes).unwrap();
    assert_eq!(renderer.kernels_compiled(), 2);
}

/// A scene's device data (its BVH, buffers and literals) is built once for all its renders: other cameras,
/// film sizes and depth limits reuse it and render what a fresh renderer renders, bit for bit; a changed
/// material or vertex builds its own.
#[test]
fn renders_of_one_scene_share_its_upload() {
    let renderer = Renderer::new(gpu()).unwrap();
    let settings = RenderSettings::new(2, 3);
    let scene = cbox(8);
    renderer.render(&scene, &settings, &mut |_, _| {}).unwrap();
    let mut view = cbox(12);
    view.camera.fov_y_deg *= 0.8;
    view.max_depth = 3;
    let kept = renderer.render(&view, &settings, &mut |_, _| {}).unwrap();
    assert_eq!(renderer.scenes_uploaded(), 1, "a view of an uploaded scene was uploaded again");
    let fresh = render(&view, 2, 3);
    assert_eq!(kept.color.data, fresh.color.data, "a kept upload renders another image than a fresh one");
    assert_eq!(kept.normal.data, fresh.normal.data);

    let mut moved = scene.clone();
    moved.meshes[0].positions[0].x += 1e-3;
    renderer.render(&moved, &settings, &mut |_, _| {}).unwrap();
    assert_eq!(renderer.scenes_uploaded(), 2, "a moved vertex rendered with the old scene's data");
    let mut recoloured = scene.clone();
    let last = recoloured.meshes.len() - 1;
    recoloured.meshes[last].emission = Some(glam::Vec3::splat(2.0));
    let lit = renderer.render(&recoloured, &settings, &mut |_, _| {}).unwrap();
    assert_eq!(renderer.scenes_uploaded(), 3, "a new emitter rendered with the old scene's data");
    assert_ne!(lit.color.data, kept.color.data);
}
