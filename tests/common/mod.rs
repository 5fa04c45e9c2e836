//! Helpers shared by the integration-test binaries. Each binary includes
//! this module (`mod common;`, or `#[path = "../common/mod.rs"] mod
//! common;` from a binary's own folder) and uses only part of it.
#![allow(dead_code)]

pub mod cli;
pub mod images;
pub mod prop;
pub mod render;
pub mod rng;
pub mod scenes;

use std::path::{Path, PathBuf};

/// The example scenes, `assets/`.
pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}
