//! Kernel tests: intersection, BVH and offset kernels against brute force
//! and f64 references, without an ECS world. One test binary (it links
//! the whole crate once):
//!
//! * `cargo test --test kernels` runs them all;
//! * `cargo test --test kernels accel::` — the BVH, kd-tree, grid and
//!   brute force give the same hits, bit for bit; the 3D DDA's edge cases;
//! * `cargo test --test kernels clip::` — the clipping kernels against
//!   each other and independent oracles;
//! * `cargo test --test kernels bvh::` — BVH traversal (top level, mesh,
//!   packets, streams) against brute force;
//! * `cargo test --test kernels watertight::` — no leaks at shared edges
//!   and vertices of closed meshes;
//! * `cargo test --test kernels properties::` — property tests of the f32
//!   shape kernels against f64 and of `offset_origin`;
//! * `cargo test --test kernels radiosity::` — form factors, the furnace,
//!   parallel plates and the solvers against closed forms and a dense
//!   solve;
//! * `cargo test --test kernels simd::` — the portable and the AVX2 code
//!   paths give bit-identical hits in every traversal mode.

#[path = "../common/mod.rs"]
mod common;

mod accel;
mod bvh;
mod clip;
mod properties;
mod radiosity;
mod simd;
mod watertight;
