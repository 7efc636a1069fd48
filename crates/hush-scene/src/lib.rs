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

pub use bvh::{Bvh, BvhNode, MAX_LEAF_TRIANGLES};
pub use error::SceneError;
pub use model::{
    Analytic, Camera, ComplexIor, EnvMap, Environment, Film, Material, Mesh, Microfacet, PixelFilter, Reflectance,
    Scene, ShapeKind, Texture, TextureId,
};
pub use obj::load_obj;
