//! Layer 4: light transport kernels shared by both integrators: the
//! surface interaction at a hit, Whitted's direct light and specular
//! scattering, and path tracing's BSDF sampling, next-event estimation and
//! roulette.

pub mod caustic;
pub mod gooch;
pub mod interaction;
pub mod medium;
pub mod path;
pub mod photon;
pub mod volume;
pub mod whitted;
