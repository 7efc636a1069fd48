//! Each `to_world` element against a hand-computed image of the rectangle's corner (-1, -1, 0),
//! and their composition in Mitsuba's order (later elements apply after earlier ones).

use std::path::Path;

use glam::Vec3;
use hush_scene::Scene;

use crate::scene3;

/// The world position of the rectangle's first corner, object-space (-1, -1, 0).
fn corner(transform: &str) -> Vec3 {
    let body = format!(r#"<shape type="rectangle"><transform name="to_world">{transform}</transform></shape>"#);
    let scene = Scene::from_mitsuba_str(&scene3(&body), Path::new("t.xml")).unwrap();
    scene.meshes[0].positions[0]
}

fn check(transform: &str, expect: Vec3) {
    let got = corner(transform);
    assert!(got.abs_diff_eq(expect, 1e-5), "{transform}: {got}, expected {expect}");
}

#[test]
fn translate() {
    check(r#"<translate x="1" y="2" z="3"/>"#, Vec3::new(0.0, 1.0, 3.0));
    check(r#"<translate value="1, 2, 3"/>"#, Vec3::new(0.0, 1.0, 3.0));
}

#[test]
fn rotate() {
    // 90° about +y: (x, y, z) → (z, y, -x).
    check(r#"<rotate y="1" angle="90"/>"#, Vec3::new(0.0, -1.0, 1.0));
    // 90° about +x: (x, y, z) → (x, -z, y).
    check(r#"<rotate value="1 0 0" angle="90"/>"#, Vec3::new(-1.0, 0.0, -1.0));
}

#[test]
fn scale() {
    check(r#"<scale value="2"/>"#, Vec3::new(-2.0, -2.0, 0.0));
    check(r#"<scale x="2" y="3"/>"#, Vec3::new(-2.0, -3.0, 0.0));
}

#[test]
fn matrix_is_row_major() {
    check(r#"<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>"#, Vec3::new(4.0, 5.0, 7.0));
    check(r#"<matrix value="0 -1 0  1 0 0  0 0 1"/>"#, Vec3::new(1.0, -1.0, 0.0));
}

#[test]
fn lookat_maps_z_to_the_view_direction() {
    // origin (0,0,5) looking at -z with +y up: local x = up × dir = (-1, 0, 0).
    check(r#"<lookat origin="0,0,5" target="0,0,0" up="0,1,0"/>"#, Vec3::new(1.0, -1.0, 5.0));
}

#[test]
fn composition_applies_later_elements_last() {
    check(r#"<scale value="2"/><translate x="1"/>"#, Vec3::new(-1.0, -2.0, 0.0));
    check(r#"<translate x="1"/><scale value="2"/>"#, Vec3::new(0.0, -2.0, 0.0));
    check(r#"<rotate z="1" angle="90"/><translate x="10"/>"#, Vec3::new(11.0, -1.0, 0.0));
}

#[test]
fn variables_substitute_in_attributes() {
    let xml = format!(
        r#"<scene version="3.0.0"><default name="tx" value="4"/>{}
        <shape type="rectangle"><transform name="to_world"><translate x="$tx"/></transform></shape></scene>"#,
        crate::SENSOR
    );
    let scene = Scene::from_mitsuba_str(&xml, Path::new("t.xml")).unwrap();
    assert_eq!(scene.meshes[0].positions[0], Vec3::new(3.0, -1.0, 0.0));
}

#[test]
fn mitsuba06_camera_from_lookat_in_a_camel_case_transform() {
    let xml = r#"<scene version="0.5.0"><integrator type="path"><integer name="maxDepth" value="5"/></integrator>
      <sensor type="perspective"><float name="fov" value="90"/><string name="fovAxis" value="y"/>
        <transform name="toWorld"><lookAt origin="1,2,3" target="1,2,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="7"/></sampler>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="10"/><rfilter type="box"/></film></sensor>
      <shape type="sphere"/></scene>"#;
    let s = Scene::from_mitsuba_str(xml, Path::new("t.xml")).unwrap();
    assert_eq!((s.max_depth, s.spp), (5, Some(7)));
    assert_eq!(s.camera.origin, Vec3::new(1.0, 2.0, 3.0));
    assert!((s.camera.target - s.camera.origin).normalize().abs_diff_eq(-Vec3::Z, 1e-6));
    assert!((s.camera.fov_y_deg - 90.0).abs() < 1e-4);
    // Image right is forward × up = +x here, as in Mitsuba (its local +x, the image's left, is -x).
    let (_, right, _) = s.camera.basis();
    assert!(right.abs_diff_eq(Vec3::X, 1e-6), "{right}");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}
