//! # Prism
//!
//! A data-oriented ray tracer whose scene is a [`bevy_ecs`] world.
//!
//! The crate is split in two halves:
//!
//! * **Kernels** (this `src/` tree): geometry, intersection, BVH queries,
//!   shading, cameras, image output and scene loaders. They are plain
//!   functions over plain data and never touch an ECS schedule. Some data
//!   types derive [`bevy_ecs::component::Component`] so that they can be
//!   spawned directly, but no kernel queries a world.
//! * **Systems** (the top-level `systems/` tree, compiled as the
//!   [`systems`] module): ECS components, resources and the systems that
//!   turn a world into a [`scene::RenderScene`] and render it by calling
//!   the kernels.
//!
//! The quickest way in is [`systems::render_scene_desc`], or the `prism`
//! command-line program.

#![warn(missing_docs)]
// Unsafe code only where a measurement justifies it, each with a local
// `#[allow(unsafe_code)]` and a SAFETY comment.
#![deny(unsafe_code)]
// Checks such as `!(x > 0.0)` are written that way on purpose: they also
// reject NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accel;
pub mod core;
pub mod geometry;
pub mod image;
pub mod integrators;
pub mod io;
pub mod lightfield;
pub mod radiosity;
pub mod scene;
pub mod transport;

#[path = "../systems/mod.rs"]
pub mod systems;

pub use crate::core::error::{Error, Result};

/// The README's code examples, compiled as doctests.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
