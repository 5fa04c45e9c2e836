//! Rendering tests: scenes rendered end to end through the ECS world and
//! both integrators, checked against analytic answers, against each other
//! and against scenes built from scratch. One test binary (it links the
//! whole crate once):
//!
//! * `cargo test --test render` runs them all;
//! * `cargo test --test render analytic::` — small scenes against what
//!   geometry and radiometry say (Lambertian quads from TOML and glTF
//!   through the `prism` binary, mirror, lens, shadows, determinism);
//! * `cargo test --test render path::` — path transport against analytic
//!   answers (white furnace, area lights) and the Whitted tracer;
//! * `cargo test --test render photon::` — photon transport against the
//!   path tracer (Cornell box) and bit for bit across thread counts;
//! * `cargo test --test render media::` — absorbing interiors (Beer-Lambert)
//!   from TOML and glTF `KHR_materials_volume` in every transport;
//! * `cargo test --test render scattering::` — scattering media and
//!   subsurface scattering: a furnace, Chandrasekhar's semi-infinite slab,
//!   subsurface slabs and balls, thread and integrator determinism;
//! * `cargo test --test render radiosity::` — radiosity transport: the
//!   Cornell box against the path tracer, the solution reused while the
//!   camera moves, thread-count independence, refused input;
//! * `cargo test --test render robustness::` — numerical extremes (IOR,
//!   total internal reflection, coincident surfaces, scale invariance);
//! * `cargo test --test render wavefront::` — the wavefront integrator
//!   against the recursive one, and its queues;
//! * `cargo test --test render scene_updates::` — incremental scene updates
//!   against scenes built from scratch, progressive accumulation;
//! * `cargo test --test render shards::` — region and sample-range shards
//!   written, read back and merged against the single render, bit for bit;
//! * `cargo test --test render illustration::` — Gooch shading against its
//!   closed form, feature lines and their vector (SVG) form;
//! * `cargo test --test render panorama::` — equirectangular and cube-map
//!   panoramas read back as environments, and against each other;
//! * `cargo test --test render lightfield::` — views synthesised from
//!   captured light fields against the captures and direct renders, and
//!   bad light fields refused;
//! * `cargo test --test render overlay::` — the structure overlays
//!   (wireframe, BVH boxes, grid cells, kd-tree planes): projection,
//!   clipping and visibility against independent f64 and brute-force
//!   answers, and the kd-tree's planes counted;
//! * `cargo test --test render texture_lod::` — texture level of detail:
//!   grazing checkerboards without moire at 1 spp, the mipmap level a hit
//!   reads;
//! * `cargo test --test render references::` — glTF sample models against
//!   Mitsuba 3's renders of the same scenes (`tests/references/`).

#[path = "../common/mod.rs"]
mod common;

mod analytic;
mod caustics;
mod dispersion;
mod environment;
mod illustration;
mod large_worlds;
mod lightfield;
mod media;
mod models;
mod overlay;
mod panorama;
mod path;
mod photon;
mod radiosity;
mod references;
mod robustness;
mod scattering;
mod scene_updates;
mod shards;
mod texture_lod;
mod wavefront;
