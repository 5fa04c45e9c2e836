//! Scene loaders: glTF 2.0 and the project's own TOML scene format.
//!
//! [`load`] picks the loader by file extension: `.gltf` and `.glb` go to
//! [`gltf::load_gltf`], `.toml` to [`scene_file::load_scene_file`].

pub mod gltf;
pub mod scene_file;

use std::path::Path;

use crate::desc::SceneDesc;
use crate::error::{Error, Result};
use crate::mesh::BuildQuality;

/// Loads a scene file of any supported kind.
pub fn load(path: &Path, quality: BuildQuality) -> Result<SceneDesc> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("gltf") | Some("glb") => gltf::load_gltf(path, quality),
        Some("toml") => scene_file::load_scene_file(path, quality),
        _ => Err(Error::load(
            path,
            "unknown scene format: expected a .toml, .gltf or .glb file",
        )),
    }
}
