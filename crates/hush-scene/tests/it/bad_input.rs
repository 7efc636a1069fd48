//! What is not supported is a warning naming it; malformed input is an error naming file and line.

use hush_scene::Scene;

use crate::{load_err, load_xml, scene3, scratch};

const RECT: &str = r#"<shape type="rectangle"/>"#;

/// Loads `body` (plus a rectangle) and returns the warnings.
fn warnings(dir: &std::path::Path, body: &str) -> Vec<String> {
    load_xml(dir, &scene3(&format!("{RECT}\n{body}"))).warnings
}

fn assert_warned(warnings: &[String], words: &[&str]) {
    assert!(warnings.iter().any(|w| words.iter().all(|k| w.contains(k))), "no warning with {words:?} in {warnings:?}");
}

#[test]
fn unsupported_elements_are_named_warnings() {
    let dir = scratch("unsupported");
    // The body starts on line 6 (after the scene line, the sensor's 3 lines and the rectangle).
    assert_warned(&warnings(&dir, r#"<emitter type="point"/>"#), &["scene.xml:6:", "emitter 'point'"]);
    assert_warned(
        &warnings(&dir, r#"<medium type="homogeneous"/>"#),
        &["scene.xml:6:", "<medium type=\"homogeneous\">"],
    );
    assert_warned(
        &warnings(&dir, r#"<shape type="ply"><string name="filename" value="x.ply"/></shape>"#),
        &["shape type 'ply'", "skipped"],
    );
    assert_warned(
        &warnings(&dir, r#"<shape type="cube"><bsdf type="principled"/></shape>"#),
        &["BSDF 'principled'", "diffuse"],
    );
    assert_warned(
        &warnings(
            &dir,
            r#"<shape type="cube"><bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.4"/></bsdf></shape>"#,
        ),
        &["anisotropic", "0.2"],
    );
    let xml = r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="40"/>
      <transform name="to_world"><lookat origin="0,0,4" target="0,0,0"/></transform>
      <sampler type="stratified"/>
      <film type="hdrfilm"><rfilter type="lanczos"/></film></sensor><shape type="cube"/></scene>"#;
    let w = load_xml(&dir, xml).warnings;
    assert_warned(&w, &["scene.xml:4:", "lanczos", "box filter"]);
    assert_warned(&w, &["scene.xml:3:", "stratified", "independently"]);
    // A tent takes its radius (Mitsuba's default 1), a gaussian its stddev (0.5), and a film without a
    // filter gets Mitsuba's, the gaussian; a width that is no size is an error on its line.
    let tent = |inner: &str| {
        format!(
            r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="40"/>
      <transform name="to_world"><lookat origin="0,0,4" target="0,0,0"/></transform><film type="hdrfilm">
      <rfilter type="tent">{inner}</rfilter></film></sensor><shape type="cube"/></scene>"#
        )
    };
    assert_eq!(load_xml(&dir, &tent("")).film.filter, hush_scene::PixelFilter::Tent { radius: 1.0 });
    let unfiltered = load_xml(&dir, &tent("").replace(r#"<rfilter type="tent"></rfilter>"#, ""));
    assert_eq!(unfiltered.film.filter, hush_scene::PixelFilter::Gaussian { stddev: 0.5 });
    assert!(!unfiltered.warnings.iter().any(|w| w.contains("filter")), "{:?}", unfiltered.warnings);
    let gaussian = tent(r#"<float name="stddev" value="0.3"/>"#).replace(r#"type="tent""#, r#"type="gaussian""#);
    assert_eq!(load_xml(&dir, &gaussian).film.filter, hush_scene::PixelFilter::Gaussian { stddev: 0.3 });
    let err = load_err(&dir, &gaussian.replace("0.3", "-1"));
    assert!(err.contains("scene.xml:3:") && err.contains("stddev -1") && err.contains("positive"), "{err}");
    let wide = load_xml(&dir, &tent(r#"<float name="radius" value="1.5"/>"#));
    assert_eq!(wide.film.filter, hush_scene::PixelFilter::Tent { radius: 1.5 });
    let err = load_err(&dir, &tent("\n<float name=\"radius\" value=\"0\"/>"));
    assert!(err.contains("scene.xml:4:") && err.contains("radius 0"), "{err}");
    let wide = load_xml(&dir, &tent(r#"<float name="radius" value="40"/>"#));
    assert_eq!(wide.film.filter, hush_scene::PixelFilter::Tent { radius: 16.0 });
    assert_warned(&wide.warnings, &["scene.xml:3:", "radius 40", "hush uses 16"]);
    let err = load_err(&dir, &tent("").replace("</film>", "<rfilter type=\"box\"/></film>"));
    assert!(err.contains("scene.xml:3:") && err.contains("one reconstruction filter"), "{err}");
}

#[test]
fn malformed_values_are_errors_with_the_line() {
    let dir = scratch("malformed-values");
    let err = load_err(&dir, &scene3("<shape type=\"sphere\">\n<float name=\"radius\" value=\"one\"/></shape>"));
    assert!(err.contains("scene.xml:6:") && err.contains("'one'"), "{err}");
    let err = load_err(
        &dir,
        &scene3(r#"<shape type="rectangle"><transform name="to_world"><translate x="$dx"/></transform></shape>"#),
    );
    assert!(err.contains("scene.xml:5:") && err.contains("$dx") && err.contains("<default"), "{err}");
    let err =
        load_err(&dir, &scene3(r#"<shape type="rectangle"><transform name="to_world"><shear/></transform></shape>"#));
    assert!(err.contains("<shear>") && err.contains("not a transform"), "{err}");
    let err = load_err(
        &dir,
        &scene3(r#"<bsdf type="conductor" id="c"><string name="material" value="Unobtainium"/></bsdf>"#),
    );
    assert!(err.contains("Unobtainium") && err.contains("Cu"), "{err}");
    let err =
        load_err(&dir, &scene3(r#"<bsdf type="dielectric" id="d"><string name="int_ior" value="jelly"/></bsdf>"#));
    assert!(err.contains("jelly") && err.contains("bk7"), "{err}");
}

#[test]
fn named_iors_and_metals() {
    let dir = scratch("named");
    let s = load_xml(
        &dir,
        &scene3(
            r#"<shape type="cube"><bsdf type="dielectric"><string name="int_ior" value="water"/><string name="ext_ior" value="air"/></bsdf></shape>
               <shape type="cube"><bsdf type="conductor"><string name="material" value="Au"/></bsdf></shape>"#,
        ),
    );
    assert!(
        matches!(s.meshes[0].material, hush_scene::Material::Dielectric { int_ior, ext_ior, .. } if int_ior == 1.333 && ext_ior == 1.00028)
    );
    let hush_scene::Material::Conductor { ior: Some(ior), .. } = s.meshes[1].material else { panic!() };
    assert_eq!(ior.eta.x, 0.143_118_96);
}

#[test]
fn missing_mesh_beside_others_is_a_warning_naming_it() {
    let dir = scratch("missing-mesh-warning");
    let w = warnings(&dir, r#"<shape type="obj" id="water"><string name="filename" value="models/gone.obj"/></shape>"#);
    assert_warned(&w, &["scene.xml:6:", "'water'", "gone.obj", "not found"]);
}

#[test]
fn missing_texture_is_a_warning_naming_it() {
    let dir = scratch("missing-texture");
    let w = warnings(
        &dir,
        r#"<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="tex/gone.png"/></texture></bsdf></shape>"#,
    );
    assert_warned(&w, &["gone.png", "no such file", "0.5 grey"]);
}

#[test]
fn zero_area_light_is_an_error() {
    let dir = scratch("zero-area-light");
    let err = load_err(
        &dir,
        &scene3(
            r#"<shape type="rectangle" id="lamp"><transform name="to_world"><scale x="0"/></transform><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"#,
        ),
    );
    assert!(err.contains("scene.xml:5:") && err.contains("'lamp'") && err.contains("zero area"), "{err}");
}

#[test]
fn nan_vertex_in_obj_scene_is_an_error() {
    let dir = scratch("nan-obj-scene");
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n").unwrap();
    let err = Scene::load(&dir.join("bad.obj")).unwrap_err().to_string();
    assert!(err.contains("bad.obj") && err.contains("not finite"), "{err}");
}

/// A scene without any emitter loads (it is valid) but says that every image of it is black; one light is enough
/// to silence the warning.
#[test]
fn a_scene_without_light_is_a_named_warning() {
    let dir = scratch("unlit");
    let dark = warnings(&dir, "");
    assert_warned(&dark, &["nothing emits light", "add an emitter"]);
    let lit = warnings(
        &dir,
        r#"<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"#,
    );
    assert!(lit.iter().all(|w| !w.contains("nothing emits")), "{lit:?}");
    let sky = warnings(&dir, r#"<emitter type="constant"/>"#);
    assert!(sky.iter().all(|w| !w.contains("nothing emits")), "{sky:?}");
}

/// Hostile Mitsuba files are refused with the line, not followed until memory or the stack runs out: a
/// `$variable` expanded into a value thousands of times (quadratic growth from a small file), and BSDFs
/// nested thousands deep (the reader recurses on them).
#[test]
fn hostile_mitsuba_files_are_refused_early() {
    let dir = scratch("hostile-mitsuba");
    let long = "1".repeat(1000);
    let refs = "$a".repeat(200);
    let xml = scene3(&format!(
        "<default name=\"a\" value=\"{long}\"/>\n<shape type=\"sphere\"><float name=\"radius\" value=\"{refs}\"/></shape>"
    ));
    let err = load_err(&dir, &xml);
    assert!(err.contains("scene.xml:") && err.contains("grows beyond 65536 bytes"), "{err}");
    let depth = 5000;
    let nested =
        format!("{}<bsdf type=\"diffuse\"/>{}", "<bsdf type=\"twosided\">".repeat(depth), "</bsdf>".repeat(depth));
    let err = load_err(&dir, &scene3(&format!("<shape type=\"rectangle\">{nested}</shape>")));
    assert!(err.contains("nested more than 16 deep"), "{err}");
}
