//! glTF 2.0 loader: `.gltf` (JSON with external or embedded buffers) and
//! `.glb` (binary container) files become a [`SceneDesc`].
//!
//! # What is read
//!
//! * **Scene graph.** The default scene (or the first scene, or, when the
//!   file has no scenes, every node that is nobody's child) is walked depth
//!   first and node transforms are composed into world transforms. A cycle
//!   anywhere in the node hierarchy, a hierarchy deeper than
//!   1024 levels, or a non-finite transform is an error naming the node.
//!   Nodes whose world transform is not invertible (for example scaled to
//!   zero, a common way to hide objects) are skipped with a warning.
//!   `EXT_mesh_gpu_instancing` places a node's mesh once per instance
//!   (per-instance `TRANSLATION`, `ROTATION`, `SCALE` applied before the
//!   node's transform; counts must agree; at most 2^22 instances a node).
//! * **Meshes.** Every triangle primitive becomes one [`Mesh`], built once
//!   and shared ([`Arc`]) between the nodes that instance it. `POSITION`,
//!   `NORMAL` (vertex normals give smooth shading, their absence flat
//!   shading), `TEXCOORD_0`, `TANGENT` (for normal maps; generated from
//!   the texture coordinates when absent, see
//!   [`Mesh::with_tangents`]) and the indices are read, including sparse and
//!   quantized (normalized integer) accessors. Triangle strips and fans
//!   are converted to triangle lists; point and line primitives are
//!   skipped with one warning per file.
//! * **Materials.** The metallic-roughness model is mapped through
//!   [`Material::from_metallic_roughness`]: base colour factor and texture,
//!   metallic and roughness factors and texture (roughness in G, metallic
//!   in B), emissive factor and texture scaled by
//!   `KHR_materials_emissive_strength`, `KHR_materials_transmission`
//!   (factor), `KHR_materials_ior`, and `KHR_materials_specular` (factor
//!   and colour: the dielectric F0 is `((ior-1)/(ior+1))^2 * specularFactor *
//!   specularColorFactor`, 0.04 for the default ior of 1.5, so a factor of
//!   0 leaves a Lambertian surface). `KHR_materials_volume` gives the
//!   interior an absorption coefficient `-ln(attenuationColor) /
//!   attenuationDistance` (Beer-Lambert along the distance a ray really
//!   travels inside, see [`crate::transport::medium`]); a thin-walled
//!   surface (`thicknessFactor` 0) absorbs nothing, as the extension says.
//!   Primitives without a material get the glTF default material (white,
//!   metallic 1, roughness 1). `KHR_texture_transform` is honoured.
//!   Normal maps (`normalTexture` with its scale, tangent space, green
//!   "up") perturb the shading normal. `alphaMode` `MASK` (with
//!   `alphaCutoff`) cuts the surface away where the base colour alpha
//!   (factor times texture alpha) is below the cutoff, for every ray,
//!   shadow rays included; `BLEND` lets rays through with probability
//!   `1 - alpha` (stochastic transparency).
//! * **Textures.** PNG and JPEG images (external files, data URIs or
//!   buffer views) are decoded once per image into linear RGB
//!   [`ImageTexture`]s; colour textures (base colour, emissive) are
//!   converted from sRGB, data textures (metallic-roughness) are not.
//!   8- and 16-bit grey, grey-alpha, RGB and RGBA images are accepted,
//!   float images are taken as linear; alpha is kept for alpha modes.
//!   Samplers: `wrapS`/`wrapT` (repeat, mirrored repeat, clamp to edge)
//!   and nearest or linear filtering by `magFilter`.
//! * **Lights** (`KHR_lights_punctual`): point and spot lights become
//!   [`Light::Point`] / [`Light::Spot`] with intensity `color * intensity`
//!   in candela, directional lights [`Light::Directional`] with illuminance
//!   `color * intensity` in lux, placed by the node's world transform
//!   (position = origin, direction = local `-Z`). Negative or non-finite
//!   values are errors.
//! * **Cameras.** Perspective cameras become [`Camera`]s looking along the
//!   node's local `-Z` with `+Y` up and the file's vertical field of view,
//!   in traversal order; orthographic ones are orthographic cameras of
//!   half height `ymag` (`xmag` follows from the image's aspect ratio).
//! * **Extensions.** An extension in `extensionsRequired` that Prism does
//!   not read is an error naming it; one only in `extensionsUsed` is a
//!   warning (its content is ignored). The aspect ratio and clipping planes are ignored
//!   (the image size decides the aspect ratio).
//!
//! # Units
//!
//! glTF's units pass through unchanged: metres for geometry, candela and
//! lux for lights. Emission (`emissiveFactor * emissiveStrength` times the
//! emissive texture) is used directly as emitted radiance.
//!
//! # What is ignored
//!
//! Occlusion, transmission, specular and other extension textures;
//! `KHR_texture_transform` on normal textures; `doubleSided` (nothing is
//! culled, so winding and negative-determinant transforms do not matter);
//! `KHR_materials_volume`'s thickness texture and, for volumes, its
//! thickness (the traced distance inside is used; see below); the
//! minification filter's choice (a linear magnification filter means
//! trilinear mipmapping by ray cones whatever the minification filter
//! says, a nearest one no mipmapping);
//! texture coordinate sets other than 0 (set 0 is used, with a warning);
//! light `range` (lights fall off with the inverse square law forever);
//! animations, skins (skinned meshes render in their bind pose
//! with the node's transform), morph targets (the base geometry is used).
//!
//! # Errors
//!
//! Every problem is reported as [`Error::Load`] for the glTF file with a
//! message saying what is wrong: unreadable or malformed files, missing or
//! short buffers, missing or undecodable images, accessors that read
//! outside their buffers, out-of-range vertex indices, invalid numbers
//! (non-finite transforms, factors or light values; negative colours,
//! factors or intensities; vertex positions farther than 10^12 from the
//! origin in object or world space, which would overflow BVH costs).
//! The loader never panics on malformed input: it does its own buffer,
//! image and accessor decoding with bounds checks instead of relying on
//! the `gltf` crate's importer.
//!
//! [`Camera`]: crate::scene::camera::Camera
//! [`Mesh::with_tangents`]: crate::geometry::mesh::Mesh::with_tangents
//! [`Light::Point`]: crate::scene::light::Light::Point
//! [`Light::Spot`]: crate::scene::light::Light::Spot
//! [`Light::Directional`]: crate::scene::light::Light::Directional

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::core::error::Error;
use crate::geometry::mesh::{BuildOptions, Mesh};
use crate::io::desc::SceneDesc;
use crate::scene::material::{ImageTexture, Material};

mod accessors;
mod container;
mod lights_cameras;
mod materials;
mod meshes;
mod nodes;
#[cfg(test)]
mod tests;
mod textures;

use container::open;
use nodes::build_scene;

/// Loads a glTF 2.0 file (`.gltf` or `.glb`) into a [`SceneDesc`].
///
/// Meshes are built with the given BVH `quality`. The background stays
/// black and no render settings are suggested. Warnings about ignored
/// content (line primitives, orthographic cameras, ...) are printed to
/// standard error once each. See the [module documentation](self) for
/// what is read and how it maps onto Prism's types.
///
/// # Errors
///
/// [`Error::Load`] naming `path` and what is wrong with the file or with
/// a file it references.
pub fn load_gltf(path: &Path, quality: impl Into<BuildOptions>) -> crate::Result<SceneDesc> {
    let bytes = crate::io::read_regular_file(path)
        .map_err(|e| Error::load(path, format!("cannot read file: {e}")))?;
    load_gltf_bytes(&bytes, path, quality)
}

/// Loads a glTF 2.0 document (`.gltf` JSON or `.glb` binary, told apart by
/// the GLB magic) from memory. `path` names the file in messages, and its
/// folder is where external buffers and images are looked up; it is not
/// read itself. This is the entry point of the glTF fuzz target (`fuzz/`).
pub fn load_gltf_bytes(
    bytes: &[u8],
    path: &Path,
    quality: impl Into<BuildOptions>,
) -> crate::Result<SceneDesc> {
    let quality = quality.into();
    let mut state = State::default();
    let result = open(bytes, path).and_then(|ctx| build_scene(&ctx, &mut state, quality));
    state.print_warnings(path);
    result.map_err(|message| Error::load(path, message))
}

/// The parsed, validated document and its buffers.
struct Ctx {
    document: gltf::Document,
    buffers: Vec<Vec<u8>>,
    base: PathBuf,
    /// Each node's local transform as written in the file, in f64 (the
    /// `gltf` crate reads them as f32, which loses a translation of 1e5 +
    /// 0.3 to within 0.004); `None` when the JSON could not be re-read.
    node_transforms: Vec<Option<glam::DAffine3>>,
    /// Each node's `EXT_mesh_gpu_instancing` attributes (empty when the
    /// JSON could not be re-read).
    node_instancing: Vec<Option<container::Instancing>>,
    /// Warnings about optional extensions that are not read.
    extension_warnings: Vec<String>,
}

/// A primitive's shared mesh and the object-space offset its vertices
/// were moved by.
type PlacedMesh = (Arc<Mesh>, glam::DVec3);

/// Caches and warnings accumulated while building the scene.
#[derive(Default)]
struct State {
    quality: BuildOptions,
    /// Each primitive's mesh and the offset its vertices were moved by
    /// (see `meshes::recentre`).
    meshes: HashMap<(usize, usize), Option<PlacedMesh>>,
    materials: HashMap<Option<usize>, Material>,
    decoded: HashMap<usize, image::DynamicImage>,
    textures: HashMap<(usize, bool), Arc<ImageTexture>>,
    warnings: Vec<String>,
    warned: HashSet<String>,
    skipped_primitives: usize,
}

impl State {
    fn warn(&mut self, message: String) {
        if self.warned.insert(message.clone()) {
            self.warnings.push(message);
        }
    }

    fn print_warnings(&mut self, path: &Path) {
        if self.skipped_primitives > 0 {
            let n = self.skipped_primitives;
            self.warn(format!(
                "skipped {n} point/line primitive{}: only triangles are rendered",
                if n == 1 { "" } else { "s" }
            ));
        }
        for w in &self.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
    }
}
