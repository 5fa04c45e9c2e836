//! glTF 2.0 loader (in progress: being written; this stub only keeps the crate compiling).

/// Loads a glTF file (stub).
pub fn load_gltf(
    path: &std::path::Path,
    _quality: crate::mesh::BuildQuality,
) -> crate::Result<crate::desc::SceneDesc> {
    Err(crate::Error::load(path, "glTF loading is not implemented yet"))
}
