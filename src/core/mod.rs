//! Layer 0: numbers and the words every other layer uses. Vectors, rays
//! and colours, random numbers and sampling warps, optics formulas, errors,
//! and the render settings with their limits. Imports nothing of the crate.

pub mod clip;
pub mod error;
pub mod math;
pub mod optics;
pub mod photon_settings;
pub mod rng;
pub mod sampling;
pub mod settings;
pub mod window;
