//! Layer 1: acceleration structures over boxes. BVH build presets and
//! padded boxes, the one conservative node test, and the single-ray,
//! packet and stream traversals that share it, and the top-level BVH over
//! placements. Knows nothing of what the boxes contain.

pub mod build;
pub mod node;
pub mod packet;
pub mod single;
pub mod stream;
pub mod tlas;
