//! Command-line tests: the `prism` binary run as a user would. One test
//! binary (it links the whole crate once):
//!
//! * `cargo test --test cli` runs them all;
//! * `cargo test --test cli render::` — `prism render` and `prism bench`:
//!   bad input gives a clear message and a non-zero exit, never a panic
//!   or an output file; help, statistics and the benchmark's JSON;
//! * `cargo test --test cli lightfield::` — `prism lightfield`: capture,
//!   a grid view synthesised from the folder alone bit for bit, bad
//!   folders and views refused;
//! * `cargo test --test cli merge::` — `prism render --shard` and
//!   `prism merge`: merged shards are the single render byte for byte, bad
//!   sets of shards are refused naming the file, with nothing written;
//! * `cargo test --test cli tools::` — the measuring tools: the error
//!   trend against samples per pixel, `prism compare`, `prism tradeoff`
//!   and `prism bench rays` on a small synthetic workload.

#[path = "../common/mod.rs"]
mod common;

mod lightfield;
mod merge;
mod render;
mod tools;
