//! Tessellated shapes: areas (an emitter's power is radiance × the tessellated area, so these
//! match the analytic areas Mitsuba uses), orientation, normals.

use std::f64::consts::PI;
use std::path::Path;

use glam::Vec3;
use hush_scene::{Mesh, Scene, ShapeKind};

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

/// Analytic shapes keep their exact form (`Mesh::analytic`) beside the tessellation: Mitsuba's
/// placements (a sphere's centre and radius, a cylinder's p0, p1 and radius before `to_world`),
/// exact areas and bounds, and the tessellation facing the way the exact shape does.
#[test]
fn analytic_shapes_keep_their_exact_form() {
    let sphere = shape(
        r#"<shape type="sphere"><point name="center" x="1" y="2" z="3"/><float name="radius" value="2"/>
           <transform name="to_world"><translate x="1"/></transform></shape>"#,
    );
    let a = sphere.analytic.expect("a sphere is analytic");
    assert_eq!(a.kind, ShapeKind::Sphere);
    let (c, r) = a.sphere();
    assert!(c.abs_diff_eq(Vec3::new(2.0, 2.0, 3.0), 1e-6) && (r - 2.0).abs() < 1e-6, "{c} {r}");
    assert_rel(a.area(), 16.0 * PI, 1e-6);
    assert_eq!(a.bounds(), (Vec3::new(0.0, 0.0, 1.0), Vec3::new(4.0, 4.0, 5.0)));
    assert!(!a.flip_normals);

    let cyl = shape(
        r#"<shape type="cylinder"><point name="p0" x="0" y="1" z="0"/><point name="p1" x="0" y="4" z="0"/>
           <float name="radius" value="0.5"/></shape>"#,
    );
    let a = cyl.analytic.expect("a cylinder is analytic");
    assert_eq!(a.kind, ShapeKind::Cylinder);
    assert_rel(a.area(), 2.0 * PI * 0.5 * 3.0, 1e-6);
    assert_rel(cyl.area(), 2.0 * PI * 0.5 * 3.0, 1e-5);
    // Object-space z runs from p0 to p1; the tube faces outwards.
    assert!(a.to_world.transform_point3(Vec3::ZERO).abs_diff_eq(Vec3::Y, 1e-6));
    assert!(a.to_world.transform_point3(Vec3::Z).abs_diff_eq(Vec3::new(0.0, 4.0, 0.0), 1e-6));
    for t in 0..cyl.indices.len() {
        let c = cyl.indices[t].map(|i| cyl.positions[i as usize]).iter().sum::<Vec3>() / 3.0;
        assert!(front(&cyl, t).dot(Vec3::new(c.x, 0.0, c.z)) > 0.0, "triangle {t} faces inwards");
    }
    let (lo, hi) = a.bounds();
    assert!(lo.abs_diff_eq(Vec3::new(-0.5, 1.0, -0.5), 1e-5) && hi.abs_diff_eq(Vec3::new(0.5, 4.0, 0.5), 1e-5));

    let disk = shape(r#"<shape type="disk"><transform name="to_world"><scale x="2" y="0.5"/></transform></shape>"#);
    assert_rel(disk.analytic.unwrap().area(), PI, 1e-6);
    let rect = shape(r#"<shape type="rectangle"><transform name="to_world"><scale x="2" y="3"/></transform></shape>"#);
    assert_rel(rect.analytic.unwrap().area(), 24.0, 1e-6);
    let cube = shape(r#"<shape type="cube"><transform name="to_world"><scale x="2"/></transform></shape>"#);
    let a = cube.analytic.expect("a cube is analytic");
    assert_eq!(a.kind, ShapeKind::Cube);
    assert_rel(a.area(), cube.area(), 1e-6);
    assert_rel(a.area(), 2.0 * (8.0 + 8.0 + 4.0), 1e-6);
    // Its faces are rectangles facing out, each the face of the tessellation with the same corners.
    let faces = a.cube_faces();
    assert_eq!(faces.len(), 6);
    for (k, f) in faces.iter().enumerate() {
        assert_eq!(f.kind, ShapeKind::Rectangle);
        let centre = f.to_world.transform_point3(Vec3::ZERO);
        let n = f.to_world.inverse().transpose().transform_vector3(Vec3::Z).normalize();
        assert!(n.dot(centre) > 0.0, "face {k} faces inwards");
        let corner = f.to_world.transform_point3(Vec3::new(-1.0, -1.0, 0.0));
        assert!(corner.abs_diff_eq(cube.positions[4 * k], 1e-6), "face {k}: {corner} vs {}", cube.positions[4 * k]);
    }
}

/// As in Mitsuba, a sphere or cylinder placed by a mirroring map is turned inside out (its
/// `flip_normals` toggles) and a disk is not; the tessellation faces the same way.
#[test]
fn a_mirrored_sphere_is_turned_inside_out_as_in_mitsuba() {
    let m = shape(r#"<shape type="sphere"><transform name="to_world"><scale x="-1"/></transform></shape>"#);
    assert!(m.analytic.unwrap().flip_normals);
    let c = m.indices[0].map(|i| m.positions[i as usize]).iter().sum::<Vec3>() / 3.0;
    assert!(front(&m, 0).dot(c) < 0.0, "the tessellation faces inwards too");
    let both = shape(
        r#"<shape type="sphere"><boolean name="flip_normals" value="true"/>
           <transform name="to_world"><scale x="-1"/></transform></shape>"#,
    );
    assert!(!both.analytic.unwrap().flip_normals);
    let disk = shape(r#"<shape type="disk"><transform name="to_world"><scale x="-1"/></transform></shape>"#);
    assert!(!disk.analytic.unwrap().flip_normals);
}

/// An unevenly scaled sphere (an ellipsoid) or cylinder has no exact form here: it is tessellated,
/// with a warning that says so.
#[test]
fn an_ellipsoid_is_tessellated_with_a_warning() {
    let xml = scene3(r#"<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>"#);
    let scene = Scene::from_mitsuba_str(&xml, Path::new("t.xml")).unwrap();
    assert!(scene.meshes[0].analytic.is_none());
    assert_eq!(scene.analytic_count(), 0);
    assert_eq!(scene.mesh_triangle_count(), 3968);
    assert!(scene.warnings.iter().any(|w| w.contains("tessellated")), "{:?}", scene.warnings);
    let xml = scene3(
        r#"<shape type="cylinder"><transform name="to_world"><scale x="2"/></transform></shape>
           <shape type="cylinder"><transform name="to_world"><scale z="5"/></transform></shape>"#,
    );
    let scene = Scene::from_mitsuba_str(&xml, Path::new("t.xml")).unwrap();
    assert!(scene.meshes[0].analytic.is_none(), "x and y scaled unevenly");
    assert!(scene.meshes[1].analytic.is_some(), "a longer cylinder is still one");
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
}
