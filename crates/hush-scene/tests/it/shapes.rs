//! Tessellated shapes: areas (an emitter's power is radiance × the tessellated area, so these
//! match the analytic areas Mitsuba uses), orientation, normals.

use std::f64::consts::PI;
use std::path::Path;

use glam::Vec3;
use hush_scene::{Mesh, Scene};

use crate::scene3;

fn shape(body: &str) -> Mesh {
    let scene = Scene::from_mitsuba_str(&scene3(body), Path::new("t.xml")).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    scene.meshes.into_iter().next().unwrap()
}

fn front(mesh: &Mesh, tri: usize) -> Vec3 {
    let [a, b, c] = mesh.indices[tri].map(|i| mesh.positions[i as usize]);
    (b - a).cross(c - a).normalize()
}

fn assert_rel(got: f64, expect: f64, tol: f64) {
    assert!((got / expect - 1.0).abs() < tol, "area {got}, expected {expect}");
}

#[test]
fn rectangle_area_and_facing() {
    let m = shape(r#"<shape type="rectangle"/>"#);
    assert_eq!(m.indices.len(), 2);
    assert_rel(m.area(), 4.0, 1e-6);
    assert!(front(&m, 0).abs_diff_eq(Vec3::Z, 1e-6));
    let m = shape(r#"<shape type="rectangle"><transform name="to_world"><scale x="2" y="3"/></transform></shape>"#);
    assert_rel(m.area(), 24.0, 1e-6);
}

#[test]
fn cube_area_and_outward_faces() {
    let m = shape(r#"<shape type="cube"/>"#);
    assert_eq!(m.indices.len(), 12);
    assert_rel(m.area(), 24.0, 1e-6);
    for t in 0..12 {
        let [a, b, c] = m.indices[t].map(|i| m.positions[i as usize]);
        let centre = (a + b + c) / 3.0;
        assert!(front(&m, t).dot(centre) > 0.0, "face {t} points inwards");
    }
}

#[test]
fn disk_has_the_analytic_area() {
    let m = shape(r#"<shape type="disk"/>"#);
    assert_eq!(m.indices.len(), 64);
    assert_rel(m.area(), PI, 1e-5);
    assert!(front(&m, 0).abs_diff_eq(Vec3::Z, 1e-6));
    let m = shape(r#"<shape type="disk"><transform name="to_world"><scale value="0.5"/></transform></shape>"#);
    assert_rel(m.area(), PI * 0.25, 1e-5);
}

#[test]
fn sphere_has_the_analytic_area_and_smooth_radial_normals() {
    let m = shape(
        r#"<shape type="sphere"><point name="center" x="1" y="2" z="3"/><float name="radius" value="2"/></shape>"#,
    );
    assert_eq!(m.indices.len(), 3968);
    assert_rel(m.area(), 16.0 * PI, 1e-5);
    let normals = m.normals.as_ref().unwrap();
    let centre = Vec3::new(1.0, 2.0, 3.0);
    for (p, n) in m.positions.iter().zip(normals) {
        assert!((n.length() - 1.0).abs() < 1e-5);
        assert!((*p - centre).normalize().abs_diff_eq(*n, 1e-5));
    }
    for t in 0..m.indices.len() {
        let c = m.indices[t].map(|i| m.positions[i as usize]).iter().sum::<Vec3>() / 3.0;
        assert!(front(&m, t).dot(c - centre) > 0.0, "triangle {t} faces inwards");
    }
}

#[test]
fn flip_normals_turns_the_front_around() {
    let m = shape(r#"<shape type="rectangle"><boolean name="flip_normals" value="true"/></shape>"#);
    assert!(front(&m, 0).abs_diff_eq(-Vec3::Z, 1e-6));
    assert!(m.normals.unwrap()[0].abs_diff_eq(-Vec3::Z, 1e-6));
}

#[test]
fn a_mirroring_transform_keeps_the_front_on_the_normals_side() {
    let m = shape(
        r#"<shape type="rectangle"><transform name="to_world"><scale z="-1" x="-1" y="-1"/></transform></shape>"#,
    );
    let n = m.normals.as_ref().unwrap()[0];
    assert!(n.abs_diff_eq(-Vec3::Z, 1e-6), "{n}");
    assert!(front(&m, 0).abs_diff_eq(n, 1e-6));
}

#[test]
fn face_normals_drops_obj_vertex_normals() {
    let dir = crate::scratch("face-normals");
    std::fs::write(dir.join("t.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n").unwrap();
    let obj = |extra: &str| {
        let xml = scene3(&format!(r#"<shape type="obj"><string name="filename" value="t.obj"/>{extra}</shape>"#));
        crate::load_xml(&dir, &xml).meshes.remove(0)
    };
    assert!(obj("").normals.is_some());
    assert!(obj(r#"<boolean name="face_normals" value="true"/>"#).normals.is_none());
}
