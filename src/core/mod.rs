//! Layer 0: numbers and the words every other layer uses. Vectors, rays
//! and colours, random numbers and sampling warps, a huge-page allocator, optics formulas (the glTF
//! microfacet BRDF among them), errors, the SIMD code path chosen at run
//! time, and the render settings with their limits. Imports nothing of the crate.

pub mod alloc;
pub mod clip;
pub mod counters;
pub mod error;
pub mod math;
pub mod medium;
pub mod microfacet;
pub mod optics;
pub mod photon_settings;
pub mod radiosity;
pub mod rng;
pub mod sampling;
pub mod settings;
pub mod simd;
pub mod spectrum;
pub mod window;
