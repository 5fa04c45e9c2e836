//! Fuzzes the project's TOML scene format: any bytes must give a scene or
//! an error, never a panic, a hang or an allocation beyond the limits.
//!
//! Relative paths in the scene (textures, included glTF files) resolve in
//! an empty folder, so the target does not wander the file system.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use prism::io::scene_file::parse_scene_file;
use prism::geometry::mesh::BuildQuality;

fn scene_path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join("prism-fuzz-empty");
        std::fs::create_dir_all(&dir).expect("create the fuzz folder");
        dir.join("fuzz.toml")
    })
}

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = parse_scene_file(text, scene_path(), BuildQuality::Fastest);
    }
});
