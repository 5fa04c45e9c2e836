//! Scene loaders: glTF 2.0 and the project's own TOML scene format.

pub mod gltf;
