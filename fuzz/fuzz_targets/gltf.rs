//! Fuzzes the glTF loading path (`.gltf` JSON and `.glb` containers, told
//! apart by the GLB magic): any bytes must give a scene or an error, never
//! a panic, a hang or an allocation beyond the limits.
//!
//! External buffers and images resolve in an empty folder, so the target
//! does not wander the file system.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use prism::io::gltf::load_gltf_bytes;
use prism::geometry::mesh::BuildQuality;

fn gltf_path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join("prism-fuzz-empty");
        std::fs::create_dir_all(&dir).expect("create the fuzz folder");
        dir.join("fuzz.gltf")
    })
}

fuzz_target!(|data: &[u8]| {
    let _ = load_gltf_bytes(data, gltf_path(), BuildQuality::Fastest);
});
