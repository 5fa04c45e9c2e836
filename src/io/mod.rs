//! Scene loaders: glTF 2.0 and the project's own TOML scene format.
//!
//! [`load`] picks the loader by file extension: `.gltf` and `.glb` go to
//! [`gltf::load_gltf`], `.toml` to [`scene_file::load_scene_file`].

pub mod desc;
pub mod environment;
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

thread_local! {
    /// The digest of the files read so far by [`load_with_digest`] on this
    /// thread, when one is running.
    static SOURCES: std::cell::RefCell<Option<sha2::Sha256>> = const { std::cell::RefCell::new(None) };
}

/// Loads a scene like [`load`] and also returns the SHA-256 (hex) of its
/// content: every file the loaders read (the scene file, included glTF
/// files, their buffers and textures), in the order they were read, each
/// as its length and bytes. Paths do not enter it, so a copied scene
/// folder hashes the same; an edit to any of its files does not.
pub fn load_with_digest(
    path: &Path,
    options: impl Into<BuildOptions>,
) -> Result<(SceneDesc, String)> {
    use sha2::Digest;
    SOURCES.with(|s| *s.borrow_mut() = Some(sha2::Sha256::new()));
    let result = load(path, options);
    let digest = SOURCES
        .with(|s| s.borrow_mut().take())
        .expect("set above")
        .finalize();
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    result.map(|desc| (desc, hex))
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
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    SOURCES.with(|s| {
        if let Some(h) = s.borrow_mut().as_mut() {
            use sha2::Digest;
            h.update((bytes.len() as u64).to_le_bytes());
            h.update(&bytes);
        }
    });
    Ok(bytes)
}
