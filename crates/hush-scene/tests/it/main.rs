//! hush-scene's integration tests: the shared scenes, transforms, shapes, other formats, and
//! bad input.

mod bad_input;
mod bvh;
mod formats;
mod procedural;
mod scenes;
mod shapes;
mod transforms;

use std::path::{Path, PathBuf};

use glam::Vec3;
use hush_scene::{Material, Microfacet, Reflectance, Scene};

fn shared() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    assert!(p.is_dir(), "the shared material is expected at {} (beside the repository)", p.display());
    p
}

fn cbox() -> PathBuf {
    shared().join("reference/mitsuba-cbox/scene.xml")
}

/// A scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hush-scene-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
  <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film></sensor>"#;

/// Writes `xml` as `scene.xml` in `dir` and loads it.
fn load_xml(dir: &Path, xml: &str) -> Scene {
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    Scene::load(&path).unwrap_or_else(|e| panic!("the scene should load: {e}"))
}

/// `body` inside a Mitsuba 3 scene with a 32² sensor.
fn scene3(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>")
}

fn load_err(dir: &Path, xml: &str) -> String {
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    Scene::load(&path).expect_err("the scene should be rejected").to_string()
}

#[test]
fn loads_the_mitsuba_cornell_box() {
    let scene = Scene::load(&cbox()).unwrap();
    assert_eq!((scene.film.width, scene.film.height), (512, 512));
    assert_eq!(scene.max_depth, 8);
    assert_eq!(scene.spp, Some(64));
    assert_eq!(scene.meshes.len(), 8);
    assert_eq!(scene.triangle_count(), 36);
    // Square image and fov_axis="smaller": the vertical fov is the given one.
    assert!((scene.camera.fov_y_deg - 39.3077).abs() < 1e-3);
    assert_eq!(scene.camera.origin, Vec3::new(0.0, 0.0, 3.9));
    let light = scene.meshes.iter().find(|m| m.name == "light").unwrap();
    assert_eq!(light.emission, Some(Vec3::new(18.387, 13.9873, 6.75357)));
    let red = scene.meshes.iter().find(|m| m.name == "red-wall").unwrap();
    let reflectance = Reflectance::Rgb(Vec3::new(0.570068, 0.0430135, 0.0443706));
    assert_eq!(red.material, Material::Diffuse { reflectance, two_sided: false });
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert!(red.normals.is_none(), "face_normals=true gives flat normals");
    // The light's front (counter-clockwise) side faces down into the box.
    let [a, b, c] = light.indices[0].map(|i| light.positions[i as usize]);
    assert!((b - a).cross(c - a).normalize().y < -0.99);
    // Image right is world +x, as in Mitsuba's render (red wall on the left).
    let (_, right, up) = scene.camera.basis();
    assert!(right.abs_diff_eq(Vec3::X, 1e-6) && up.abs_diff_eq(Vec3::Y, 1e-6));
}

#[test]
fn fov_axis_x_converts_to_vertical() {
    let xml = r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="90"/>
      <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
      <film type="hdrfilm"><integer name="width" value="200"/><integer name="height" value="100"/></film></sensor></scene>"#;
    let scene = Scene::from_mitsuba_str(xml, Path::new("x.xml")).unwrap();
    // tan(fy/2) = tan(45°) · 100/200.
    let expect = 2.0 * 0.5f32.atan().to_degrees();
    assert!((scene.camera.fov_y_deg - expect).abs() < 1e-4, "{}", scene.camera.fov_y_deg);
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let err = Scene::load(Path::new("/nonexistent/scene.xml")).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/scene.xml") && err.contains("cannot read"), "{err}");
}

#[test]
fn malformed_xml_names_the_line() {
    let dir = scratch("malformed");
    let err = load_err(&dir, "<scene version=\"3.0.0\">\n<sensor type=\"perspective\">\n</scene>");
    assert!(err.contains("scene.xml:") && err.contains("malformed XML"), "{err}");
}

#[test]
fn missing_mesh_is_an_error_naming_shape_and_file() {
    let dir = scratch("missing-mesh");
    let xml = format!(
        "<scene version=\"3.0.0\">{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"gone.obj\"/></shape></scene>"
    );
    // Nothing else to render: an error that names the missing file.
    let err = load_err(&dir, &xml);
    assert!(err.contains("gone.obj") && err.contains("missing"), "{err}");
}

#[test]
fn nan_vertex_is_an_error() {
    let dir = scratch("nan");
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n").unwrap();
    let xml = format!(
        "<scene version=\"3.0.0\">{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape></scene>"
    );
    let err = load_err(&dir, &xml);
    assert!(err.contains("bad.obj") && err.contains("not finite"), "{err}");
}

#[test]
fn undefined_bsdf_reference_is_an_error() {
    let dir = scratch("ref");
    std::fs::write(dir.join("t.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let xml = format!(
        "<scene version=\"3.0.0\">{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"t.obj\"/><ref id=\"nope\"/></shape></scene>"
    );
    let err = load_err(&dir, &xml);
    assert!(err.contains("nope"), "{err}");
}

#[test]
fn degenerate_triangles_are_dropped() {
    let dir = scratch("degenerate");
    std::fs::write(dir.join("t.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n").unwrap();
    let mesh = hush_scene::load_obj(&dir.join("t.obj"), Material::DEFAULT).unwrap();
    assert_eq!(mesh.indices.len(), 1);
    // In a scene, the drop is a warning that names the shape.
    let xml = scene3(r#"<shape type="obj" id="t"><string name="filename" value="t.obj"/></shape>"#);
    let scene = load_xml(&dir, &xml);
    assert_eq!(scene.triangle_count(), 1);
    assert!(
        scene.warnings.iter().any(|w| w.contains("'t'") && w.contains("dropped 1 degenerate")),
        "{:?}",
        scene.warnings
    );
}

/// Mitsuba's rough BSDFs default to Beckmann; `distribution` picks GGX; `phong` is read as
/// Beckmann with a warning naming the line.
#[test]
fn rough_bsdfs_read_their_microfacet_distribution() {
    let with = |extra: &str| {
        let xml = format!(
            "<scene version=\"3.0.0\">{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"roughconductor\">{extra}<float name=\"alpha\" value=\"0.2\"/></bsdf></shape></scene>"
        );
        let s = Scene::from_mitsuba_str(&xml, Path::new("x.xml")).unwrap();
        let Material::Conductor { distribution, .. } = s.meshes[0].material else {
            panic!("{:?}", s.meshes[0].material)
        };
        (distribution, s.warnings)
    };
    assert_eq!(with(""), (Microfacet::Beckmann, vec![]));
    assert_eq!(with("<string name=\"distribution\" value=\"ggx\"/>"), (Microfacet::Ggx, vec![]));
    let (d, warnings) = with("<string name=\"distribution\" value=\"phong\"/>");
    assert_eq!(d, Microfacet::Beckmann);
    assert!(warnings.iter().any(|w| w.contains("phong") && w.contains("x.xml:")), "{warnings:?}");
}
