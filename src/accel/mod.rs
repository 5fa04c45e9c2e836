//! Layer 1: acceleration structures over boxes. BVH build presets and
//! padded boxes, Prism's 8-wide node layout, the one conservative node
//! test, the single-ray, packet and stream traversals that share it, the
//! top-level BVH over placements (the SIMD code path they take is chosen
//! in [`crate::core::simd`]). Knows nothing of what the boxes contain.

pub mod build;
pub mod bvh8;
pub(crate) mod frustum;
pub mod grid;
pub mod kdtree;
pub mod mailbox;
pub mod node;
pub mod packet;
pub mod packet16;
pub mod single;
pub mod stream;
pub mod tlas;
