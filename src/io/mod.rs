//! Scene loaders: glTF 2.0 and the project's own TOML scene format.
//!
//! [`load`] picks the loader by file extension: `.gltf` and `.glb` go to
//! [`gltf::load_gltf`], `.toml` to [`scene_file::load_scene_file`].

pub mod desc;
pub mod gltf;
pub mod scene_file;

use std::path::Path;

use crate::core::error::{Error, Result};
use crate::geometry::mesh::BuildOptions;
use crate::io::desc::SceneDesc;

/// Loads a scene file of any supported kind. `options` is a
/// [`crate::geometry::mesh::BuildQuality`] or [`BuildOptions`] (which also
/// names the structure over mesh triangles).
pub fn load(path: &Path, options: impl Into<BuildOptions>) -> Result<SceneDesc> {
    let quality = options.into();
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

/// Reads a whole file, refusing anything but a regular file: a path to a
/// device such as `/dev/zero` or `/dev/stdin`, or to a FIFO, would never
/// end (or block) and a hostile scene could name one. The error is the
/// message for the user.
pub(crate) fn read_regular_file(path: &Path) -> std::result::Result<Vec<u8>, String> {
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err(if meta.is_dir() {
            "is a directory, not a file".into()
        } else {
            "is not a regular file (a device, FIFO or socket)".into()
        });
    }
    std::fs::read(path).map_err(|e| e.to_string())
}
