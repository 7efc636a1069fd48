//! The scene model of hush and its loaders. No GPU.
//!
//! A [`Scene`] is what the path tracer needs and nothing more: a pinhole [`Camera`], the
//! [`Film`] size, the integrator's depth limit, and triangle [`Mesh`]es that each carry one
//! [`Material`] and an optional area emission. Loaders turn files into it:
//! [`Scene::load`] reads the Mitsuba 3 XML subset of the shared scenes (`obj` shapes,
//! `diffuse` BSDFs, `area` emitters, a `perspective` sensor, `hdrfilm`, the `path`
//! integrator). An element the loader does not support is an error naming the file, the
//! line and the element: nothing is skipped silently.
//!
//! ```
//! use hush_scene::Scene;
//! let xml = r#"<scene version="3.0.0">
//!   <sensor type="perspective">
//!     <float name="fov" value="40"/>
//!     <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
//!     <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film>
//!   </sensor>
//! </scene>"#;
//! let scene = Scene::from_mitsuba_str(xml, std::path::Path::new("inline.xml")).unwrap();
//! assert_eq!((scene.film.width, scene.film.height), (64, 32));
//! ```

mod bvh;
mod error;
mod mitsuba;
mod model;
mod obj;

pub use bvh::{Bvh, BvhNode, MAX_LEAF_TRIANGLES};
pub use error::SceneError;
pub use model::{Camera, Film, Material, Mesh, Scene};
pub use obj::load_obj;
