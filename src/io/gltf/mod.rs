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
//! * **Meshes.** Every triangle primitive becomes one [`Mesh`], built once
//!   and shared ([`Arc`]) between the nodes that instance it. `POSITION`,
//!   `NORMAL` (vertex normals give smooth shading, their absence flat
//!   shading), `TEXCOORD_0` and the indices are read, including sparse and
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
//!   0 leaves a Lambertian surface).
//!   Primitives without a material get the glTF default material (white,
//!   metallic 1, roughness 1). `KHR_texture_transform` is honoured.
//! * **Textures.** PNG and JPEG images (external files, data URIs or
//!   buffer views) are decoded once per image into linear RGB
//!   [`ImageTexture`]s; colour textures (base colour, emissive) are
//!   converted from sRGB, data textures (metallic-roughness) are not.
//!   8- and 16-bit grey, grey-alpha, RGB and RGBA images are accepted,
//!   float images are taken as linear; alpha is dropped.
//! * **Lights** (`KHR_lights_punctual`): point and spot lights become
//!   [`Light::Point`] / [`Light::Spot`] with intensity `color * intensity`
//!   in candela, directional lights [`Light::Directional`] with illuminance
//!   `color * intensity` in lux, placed by the node's world transform
//!   (position = origin, direction = local `-Z`). Negative or non-finite
//!   values are errors.
//! * **Cameras.** Perspective cameras become [`Camera`]s looking along the
//!   node's local `-Z` with `+Y` up and the file's vertical field of view,
//!   in traversal order. The aspect ratio and clipping planes are ignored
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
//! Normal, occlusion, transmission, specular and other extension textures;
//! alpha modes and alpha (everything is opaque); `doubleSided` (nothing is
//! culled, so winding and negative-determinant transforms do not matter);
//! `KHR_materials_volume` (thickness and attenuation); texture sampler
//! settings (lookups are always bilinear with repeat wrapping);
//! texture coordinate sets other than 0 (set 0 is used, with a warning);
//! light `range` (lights fall off with the inverse square law forever);
//! orthographic cameras (the renderer is pinhole only; skipped with a
//! warning); animations, skins (skinned meshes render in their bind pose
//! with the node's transform), morph targets (the base geometry is used)
//! and `EXT_mesh_gpu_instancing` (the node is drawn once, with its own
//! transform).
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
//! [`Light::Point`]: crate::scene::light::Light::Point
//! [`Light::Spot`]: crate::scene::light::Light::Spot
//! [`Light::Directional`]: crate::scene::light::Light::Directional

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Affine3A, Mat4, Quat, Vec3, Vec3A};

use crate::core::error::Error;
use crate::geometry::mesh::{BuildQuality, MAX_COORDINATE, Mesh};
use crate::geometry::transform::Transform;
use crate::io::desc::{Geometry, ObjectDesc, SceneDesc};
use crate::scene::material::{ImageTexture, Material};

mod accessors;
mod container;
mod lights_cameras;
mod materials;
mod meshes;
#[cfg(test)]
mod tests;
mod textures;

use container::open;
use lights_cameras::{convert_camera, convert_light};
use materials::material;
use meshes::{mesh_name, primitive_mesh};

/// Deepest node hierarchy accepted.
const MAX_DEPTH: usize = 1024;
/// Most node visits in one traversal (guards against node DAGs whose
/// expansion into a tree is exponentially large).
const MAX_NODE_VISITS: usize = 1 << 22;

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
pub fn load_gltf(path: &Path, quality: BuildQuality) -> crate::Result<SceneDesc> {
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
    quality: BuildQuality,
) -> crate::Result<SceneDesc> {
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
}

/// Caches and warnings accumulated while building the scene.
#[derive(Default)]
struct State {
    quality: BuildQuality,
    meshes: HashMap<(usize, usize), Option<Arc<Mesh>>>,
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

// ---------------------------------------------------------------------------
// Scene graph
// ---------------------------------------------------------------------------

fn node_label(node: &gltf::Node) -> String {
    match node.name() {
        Some(name) => format!("node {} ('{name}')", node.index()),
        None => format!("node {}", node.index()),
    }
}

/// The node's local transform. TRS quaternions are normalised; the last
/// row of a matrix is ignored (glTF requires it to be `0 0 0 1`).
fn local_transform(node: &gltf::Node, label: &str) -> Result<Affine3A, String> {
    let local = match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            Affine3A::from_mat4(Mat4::from_cols_array_2d(&matrix))
        }
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let rotation = Quat::from_array(rotation);
            let length = rotation.length();
            if !(length.is_finite() && length > 0.0) {
                return Err(format!(
                    "{label}: rotation {rotation} is not a valid quaternion"
                ));
            }
            Affine3A::from_scale_rotation_translation(
                Vec3::from(scale),
                rotation / length,
                Vec3::from(translation),
            )
        }
    };
    if !local.is_finite() {
        return Err(format!("{label}: transform is not finite"));
    }
    Ok(local)
}

/// Fails if any node is its own ancestor.
fn check_cycles(nodes: &[gltf::Node]) -> Result<(), String> {
    let children: Vec<Vec<usize>> = nodes
        .iter()
        .map(|n| n.children().map(|c| c.index()).collect())
        .collect();
    // 0 = unvisited, 1 = on the current path, 2 = done.
    let mut state = vec![0u8; nodes.len()];
    for start in 0..nodes.len() {
        if state[start] != 0 {
            continue;
        }
        state[start] = 1;
        let mut stack: Vec<(usize, usize)> = vec![(start, 0)];
        while let Some(top) = stack.last_mut() {
            let (v, next) = *top;
            top.1 += 1;
            match children.get(v).and_then(|c| c.get(next)) {
                Some(&c) => match state.get(c) {
                    Some(0) => {
                        state[c] = 1;
                        stack.push((c, 0));
                    }
                    Some(1) => {
                        let name =
                            |i: usize| nodes.get(i).map_or_else(|| format!("node {i}"), node_label);
                        return Err(if v == c {
                            format!(
                                "the node hierarchy has a cycle: {} lists itself as a child",
                                name(v)
                            )
                        } else {
                            format!(
                                "the node hierarchy has a cycle: {} lists {} as a child, \
                                 but that node is also its ancestor",
                                name(v),
                                name(c)
                            )
                        });
                    }
                    _ => {}
                },
                None => {
                    state[v] = 2;
                    stack.pop();
                }
            }
        }
    }
    Ok(())
}

/// Walks the scene and assembles the description.
fn build_scene(ctx: &Ctx, st: &mut State, quality: BuildQuality) -> Result<SceneDesc, String> {
    st.quality = quality;
    let doc = &ctx.document;
    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    check_cycles(&nodes)?;
    let roots: Vec<usize> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().map(|n| n.index()).collect(),
        None => {
            let mut is_child = vec![false; nodes.len()];
            for n in &nodes {
                for c in n.children() {
                    if let Some(flag) = is_child.get_mut(c.index()) {
                        *flag = true;
                    }
                }
            }
            (0..nodes.len()).filter(|&i| !is_child[i]).collect()
        }
    };

    let mut scene = SceneDesc::default();
    let mut stack: Vec<(usize, Affine3A, usize)> = roots
        .iter()
        .rev()
        .map(|&i| (i, Affine3A::IDENTITY, 0))
        .collect();
    let mut visits = 0usize;
    while let Some((index, parent, depth)) = stack.pop() {
        let node = nodes
            .get(index)
            .ok_or_else(|| format!("node {index} does not exist"))?;
        let label = node_label(node);
        if depth >= MAX_DEPTH {
            return Err(format!(
                "{label}: node hierarchy is deeper than {MAX_DEPTH} levels"
            ));
        }
        visits += 1;
        if visits > MAX_NODE_VISITS {
            return Err(format!(
                "the node hierarchy expands to more than {MAX_NODE_VISITS} node instances"
            ));
        }
        let local = local_transform(node, &label)?;
        let world = parent * local;
        if !world.is_finite() {
            return Err(format!("{label}: world transform is not finite"));
        }
        visit_node(ctx, st, &mut scene, node, &label, world)?;
        let children: Vec<usize> = node.children().map(|c| c.index()).collect();
        for &c in children.iter().rev() {
            stack.push((c, world, depth + 1));
        }
    }
    Ok(scene)
}

/// Adds a node's meshes, light and camera.
fn visit_node(
    ctx: &Ctx,
    st: &mut State,
    scene: &mut SceneDesc,
    node: &gltf::Node,
    label: &str,
    world: Affine3A,
) -> Result<(), String> {
    let transform = Transform(world);
    if let Some(mesh) = node.mesh() {
        if transform.is_valid() {
            for primitive in mesh.primitives() {
                let Some(geometry) = primitive_mesh(ctx, st, &mesh, &primitive)? else {
                    continue;
                };
                check_world_bounds(&geometry, &world, label)?;
                let material = material(ctx, st, &primitive.material())?;
                scene.objects.push(ObjectDesc {
                    name: Some(node.name().map_or_else(|| mesh_name(&mesh), str::to_string)),
                    transform,
                    geometry: Geometry::Mesh(geometry),
                    material,
                });
            }
        } else {
            st.warn(format!(
                "{label}: transform is not invertible (zero scale?); its mesh is skipped"
            ));
        }
    }
    if let Some(light) = node.light() {
        scene.lights.push(convert_light(&light, label, transform)?);
    }
    if let Some(camera) = node.camera()
        && let Some(c) = convert_camera(st, &camera, label, world)?
    {
        scene.cameras.push(c);
    }
    Ok(())
}

/// Fails if a mesh placed by `world` reaches farther than
/// [`MAX_COORDINATE`] from the origin.
fn check_world_bounds(mesh: &Mesh, world: &Affine3A, node: &str) -> Result<(), String> {
    let Some((lo, hi)) = mesh.bounds() else {
        return Ok(());
    };
    for i in 0..8 {
        let corner = Vec3A::select(
            glam::BVec3A::new(i & 1 != 0, i & 2 != 0, i & 4 != 0),
            hi,
            lo,
        );
        let p = world.transform_point3a(corner);
        if !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE) {
            return Err(format!(
                "{node}: mesh '{}' reaches farther than {MAX_COORDINATE:e} from the origin \
                 in world space",
                mesh.name
            ));
        }
    }
    Ok(())
}
