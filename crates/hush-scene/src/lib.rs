//! The scene model of hush and its loaders. No GPU.
//!
//! A [`Scene`] is what the path tracer needs: a pinhole [`Camera`], the [`Film`] size, the
//! integrator's depth limit, triangle [`Mesh`]es in world space that each carry one
//! [`Material`] and an optional area emission, the [`Texture`]s they read, an optional
//! [`Environment`], and the loader's [`Scene::warnings`]. [`Scene::load`] reads Mitsuba XML
//! (versions 0.6, 2 and 3), Wavefront OBJ with MTL materials, and glTF 2.0. What a loader does
//! not support yet is a warning naming it and what was used instead; malformed input is an
//! error naming the file and, for XML, the line.
//!
//! ```
//! use hush_scene::Scene;
//! let xml = r#"<scene version="3.0.0">
//!   <sensor type="perspective">
//!     <float name="fov" value="40"/>
//!     <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
//!     <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film>
//!   </sensor>
//!   <shape type="sphere"/>
//! </scene>"#;
//! let scene = Scene::from_mitsuba_str(xml, std::path::Path::new("inline.xml")).unwrap();
//! assert_eq!((scene.film.width, scene.film.height), (64, 32));
//! assert_eq!(scene.triangle_count(), 3968);
//! ```

mod bvh;
mod error;
mod gltf;
mod mitsuba;
mod model;
mod named;
mod obj;
pub mod procedural;
mod shapes;
mod texture;

/// The largest scene, mesh, buffer or image file hush reads: 2 GiB, or the environment variable
/// `HUSH_MAX_SCENE_BYTES` (bytes). A larger file is refused before it is read (see [`hush_io::read_limited`]).
pub fn max_file_bytes() -> hush_io::Limit {
    hush_io::Limit::from_env("HUSH_MAX_SCENE_BYTES", 2 << 30)
}

/// Fails unless `file` lies inside `dir` (after resolving `..` and symbolic links), or inside
/// `HUSH_SCENE_ROOT` where that is set: a scene reads only files of its own folder. A file that does not
/// exist passes (reading it then says so).
pub(crate) fn check_inside(file: &std::path::Path, dir: &std::path::Path) -> Result<(), String> {
    let Ok(real) = file.canonicalize() else { return Ok(()) };
    let roots = [Some(dir.to_path_buf()), std::env::var_os("HUSH_SCENE_ROOT").map(std::path::PathBuf::from)];
    if roots.iter().flatten().filter_map(|r| r.canonicalize().ok()).any(|r| real.starts_with(r)) {
        return Ok(());
    }
    Err(format!(
        "{} lies outside the scene's folder {} (it resolves to {}): hush reads only files beside a scene; \
         set HUSH_SCENE_ROOT to a folder that holds both to allow it",
        file.display(),
        dir.display(),
        real.display()
    ))
}

pub use bvh::{Bvh, BvhNode, MAX_LEAF_TRIANGLES, MAX_SAH_DEPTH};
pub use error::SceneError;
pub use model::{
    Analytic, Camera, ComplexIor, EnvMap, Environment, Film, Material, Mesh, Microfacet, PixelFilter, Reflectance,
    Scene, ShapeKind, Texture, TextureId,
};
pub use obj::load_obj;
