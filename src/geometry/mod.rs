//! Layer 2: shapes in object space. Analytic shapes and quadrics, the
//! watertight triangle test, triangle meshes with their BVH, transforms
//! and procedural meshes.

pub mod mesh;
pub mod procedural;
pub mod shapes;
pub mod transform;
pub mod triangle;
