//! The render-ready scene: instances in world space, a top-level BVH over
//! them, materials and lights. Built from ECS data by the systems module,
//! or directly from a [`crate::io::desc::SceneDesc`] in tests.

pub mod camera;
pub mod emitters;
pub mod environment;
pub mod features;
pub mod instance;
pub mod light;
pub mod material;
pub(crate) mod merged;
pub mod panorama;
pub mod polygons;
pub mod query;
pub mod render_scene;
pub mod triangles;
pub mod update;

pub use instance::{Hit, Instance, InstanceGeometry};
pub use query::StreamScratch;
pub use render_scene::RenderScene;
