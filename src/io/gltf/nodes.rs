//! The scene graph: the node hierarchy is checked for cycles, walked
//! depth first with composed world transforms, and each node's meshes,
//! light and camera are added to the scene.

use glam::{Affine3A, DAffine3, Mat4, Quat, Vec3, Vec3A};

use crate::geometry::mesh::{BuildOptions, MAX_COORDINATE, Mesh};
use crate::geometry::transform::Transform;
use crate::io::desc::{Geometry, ObjectDesc, SceneDesc};

use super::accessors::{read_vec3, read_vec4};
use super::lights_cameras::{convert_camera, convert_light};
use super::materials::material;
use super::meshes::{mesh_name, primitive_mesh};
use super::{Ctx, State};

/// Deepest node hierarchy accepted.
pub(super) const MAX_DEPTH: usize = 1024;
/// Most node visits in one traversal (guards against node DAGs whose
/// expansion into a tree is exponentially large).
const MAX_NODE_VISITS: usize = 1 << 22;

fn node_label(node: &gltf::Node) -> String {
    match node.name() {
        Some(name) => format!("node {} ('{name}')", node.index()),
        None => format!("node {}", node.index()),
    }
}

/// The node's local transform, in f64 as written in the file. TRS
/// quaternions are normalised; the last row of a matrix is ignored (glTF
/// requires it to be `0 0 0 1`).
fn local_transform(ctx: &Ctx, node: &gltf::Node, label: &str) -> Result<DAffine3, String> {
    let single = local_transform_f32(node, label)?;
    let local = match ctx.node_transforms.get(node.index()) {
        Some(Some(exact)) => *exact,
        _ => single.as_daffine3(),
    };
    if !local.is_finite() {
        return Err(format!("{label}: transform is not finite"));
    }
    Ok(local)
}

/// The node's local transform as the `gltf` crate reads it (f32): the
/// checks and error messages, and the fallback when the JSON cannot be
/// re-read in f64.
fn local_transform_f32(node: &gltf::Node, label: &str) -> Result<Affine3A, String> {
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
pub(super) fn build_scene(
    ctx: &Ctx,
    st: &mut State,
    quality: BuildOptions,
) -> Result<SceneDesc, String> {
    st.quality = quality;
    for w in &ctx.extension_warnings {
        st.warn(w.clone());
    }
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
    let mut stack: Vec<(usize, DAffine3, usize)> = roots
        .iter()
        .rev()
        .map(|&i| (i, DAffine3::IDENTITY, 0))
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
        let local = local_transform(ctx, node, &label)?;
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
    world: DAffine3,
) -> Result<(), String> {
    let transform = Transform(world);
    if let Some(mesh) = node.mesh() {
        // EXT_mesh_gpu_instancing: the mesh once per instance transform,
        // each applied before the node's own.
        let placements = match ctx.node_instancing.get(node.index()).copied().flatten() {
            Some(attributes) => instance_transforms(ctx, attributes, label)?
                .into_iter()
                .map(|local| world * local)
                .collect(),
            None => vec![world],
        };
        for placement in placements {
            if !Transform(placement).is_valid() {
                st.warn(format!(
                    "{label}: transform is not invertible (zero scale?); its mesh is skipped"
                ));
                continue;
            }
            for primitive in mesh.primitives() {
                let Some((geometry, offset)) = primitive_mesh(ctx, st, &mesh, &primitive)? else {
                    continue;
                };
                let world = placement * DAffine3::from_translation(offset);
                let transform = Transform(world);
                check_world_bounds(&geometry, &world, label)?;
                let material = material(ctx, st, &primitive.material())?;
                scene.objects.push(ObjectDesc {
                    name: Some(node.name().map_or_else(|| mesh_name(&mesh), str::to_string)),
                    transform,
                    geometry: Geometry::Mesh(geometry),
                    material,
                });
            }
        }
    }
    if let Some(light) = node.light() {
        scene.lights.push(convert_light(&light, label, transform)?);
    }
    if let Some(camera) = node.camera()
        && let Some(c) = convert_camera(&camera, label, world)?
    {
        scene.cameras.push(c);
    }
    Ok(())
}

/// Most instances one node may ask for with `EXT_mesh_gpu_instancing`.
const MAX_INSTANCES: usize = 1 << 22;

/// The per-instance local transforms of a node's `EXT_mesh_gpu_instancing`
/// attributes (translation, rotation, scale; each optional, all of the
/// same count), checked: finite values, unit-length-able quaternions.
fn instance_transforms(
    ctx: &Ctx,
    attributes: super::container::Instancing,
    label: &str,
) -> Result<Vec<DAffine3>, String> {
    let accessor = |index: Option<usize>, what: &str| -> Result<Option<gltf::Accessor>, String> {
        index
            .map(|i| {
                ctx.document.accessors().nth(i).ok_or_else(|| {
                    format!(
                        "{label}: EXT_mesh_gpu_instancing {what} refers to missing accessor {i}"
                    )
                })
            })
            .transpose()
    };
    let fail = |what: &str, e: String| format!("{label}: EXT_mesh_gpu_instancing {what}: {e}");
    let translations = match accessor(attributes.translation, "TRANSLATION")? {
        Some(a) => Some(read_vec3(ctx, &a).map_err(|e| fail("TRANSLATION", e))?),
        None => None,
    };
    let rotations = match accessor(attributes.rotation, "ROTATION")? {
        Some(a) => Some(read_vec4(ctx, &a).map_err(|e| fail("ROTATION", e))?),
        None => None,
    };
    let scales = match accessor(attributes.scale, "SCALE")? {
        Some(a) => Some(read_vec3(ctx, &a).map_err(|e| fail("SCALE", e))?),
        None => None,
    };
    let counts: Vec<usize> = [
        translations.as_ref().map(Vec::len),
        rotations.as_ref().map(Vec::len),
        scales.as_ref().map(Vec::len),
    ]
    .into_iter()
    .flatten()
    .collect();
    let Some(&count) = counts.first() else {
        return Err(format!(
            "{label}: EXT_mesh_gpu_instancing has no TRANSLATION, ROTATION or SCALE attribute"
        ));
    };
    if counts.iter().any(|&c| c != count) {
        return Err(format!(
            "{label}: EXT_mesh_gpu_instancing attributes have different counts {counts:?}"
        ));
    }
    if count > MAX_INSTANCES {
        return Err(format!(
            "{label}: EXT_mesh_gpu_instancing asks for {count} instances, more than {MAX_INSTANCES}"
        ));
    }
    (0..count)
        .map(|i| {
            let t = translations.as_ref().map_or(Vec3::ZERO, |v| v[i]);
            let r = rotations.as_ref().map_or(glam::Vec4::W, |v| v[i]);
            let s = scales.as_ref().map_or(Vec3::ONE, |v| v[i]);
            let q = Quat::from_vec4(r);
            let length = q.length();
            if !(t.is_finite() && s.is_finite() && length.is_finite() && length > 0.0) {
                return Err(format!(
                    "{label}: EXT_mesh_gpu_instancing instance {i} has a non-finite or invalid \
                     transform (translation {t}, rotation {r}, scale {s})"
                ));
            }
            Ok(DAffine3::from_scale_rotation_translation(
                s.as_dvec3(),
                (q / length).as_dquat(),
                t.as_dvec3(),
            ))
        })
        .collect()
}

/// Fails if a mesh placed by `world` reaches farther than
/// [`MAX_COORDINATE`] from the origin.
fn check_world_bounds(mesh: &Mesh, world: &DAffine3, node: &str) -> Result<(), String> {
    let Some((lo, hi)) = mesh.bounds() else {
        return Ok(());
    };
    for i in 0..8 {
        let corner = Vec3A::select(
            glam::BVec3A::new(i & 1 != 0, i & 2 != 0, i & 4 != 0),
            hi,
            lo,
        );
        let p = world.transform_point3(corner.as_dvec3());
        if !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE as f64) {
            return Err(format!(
                "{node}: mesh '{}' reaches farther than {MAX_COORDINATE:e} from the origin \
                 in world space",
                mesh.name
            ));
        }
    }
    Ok(())
}
