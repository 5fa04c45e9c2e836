//! Meshes: each triangle primitive becomes one shared [`Mesh`] (strips
//! and fans become triangle lists; points and lines are skipped).

use std::sync::Arc;

use glam::{DVec3, Vec3};

use gltf::mesh::{Mode, Semantic};

use crate::geometry::mesh::{MAX_COORDINATE, Mesh, MeshData, NormalMode};

use super::accessors::{read_indices, read_vec2, read_vec3, read_vec4};
use super::{Ctx, State};

/// The shared mesh of one primitive and the offset (object space, f64)
/// its vertices were moved by, or `None` when it has nothing to render
/// (points, lines, no triangles). Place it with the node's transform times
/// a translation by the offset.
pub(super) fn primitive_mesh(
    ctx: &Ctx,
    st: &mut State,
    mesh: &gltf::Mesh,
    primitive: &gltf::Primitive,
) -> Result<Option<(Arc<Mesh>, DVec3)>, String> {
    let key = (mesh.index(), primitive.index());
    if let Some(cached) = st.meshes.get(&key) {
        return Ok(cached.clone());
    }
    let built = build_primitive(ctx, st, mesh, primitive)?.map(|(m, o)| (Arc::new(m), o));
    st.meshes.insert(key, built.clone());
    Ok(built)
}

/// Moves vertices stored far from their own origin (POSITION values of
/// ~1e7 for a mesh a few units across) next to it, and returns the offset
/// that puts them back.
///
/// Such vertices keep only the precision they were stored with (an f32 at
/// 1e7 is a multiple of 1), but traversal and intersection in object
/// space would also round every ray to that grid. Per axis, the offset is
/// the box centre rounded to a multiple of the coarsest ulp among the
/// axis's values, so every `v - offset` is exact in f32: the moved mesh is
/// the same set of points, and the instance transform (f64) adds the
/// offset back. Meshes whose box is not far from their origin compared
/// with their size are left alone (offset zero).
pub(super) fn recentre(positions: &mut [Vec3]) -> DVec3 {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for p in positions.iter().filter(|p| p.is_finite()) {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return DVec3::ZERO;
    }
    let extent = (hi - lo).max_element().max(f32::MIN_POSITIVE) as f64;
    let mut offset = DVec3::ZERO;
    for axis in 0..3 {
        let centre = 0.5 * (lo[axis] as f64 + hi[axis] as f64);
        if centre.abs() <= 4.0 * extent {
            continue;
        }
        let largest = lo[axis].abs().max(hi[axis].abs());
        let ulp = (f32::from_bits(largest.to_bits() + 1) - largest) as f64;
        offset[axis] = (centre / ulp).round() * ulp;
    }
    if offset != DVec3::ZERO {
        let o = offset.as_vec3();
        debug_assert_eq!(o.as_dvec3(), offset);
        for p in positions.iter_mut() {
            *p -= o;
        }
    }
    offset
}

pub(super) fn mesh_name(mesh: &gltf::Mesh) -> String {
    match mesh.name() {
        Some(name) => name.to_string(),
        None => format!("mesh {}", mesh.index()),
    }
}

fn build_primitive(
    ctx: &Ctx,
    st: &mut State,
    mesh: &gltf::Mesh,
    primitive: &gltf::Primitive,
) -> Result<Option<(Mesh, DVec3)>, String> {
    let name = mesh_name(mesh);
    let pi = primitive.index();
    let fail = |e: String| format!("mesh '{name}' primitive {pi}: {e}");
    let mode = primitive.mode();
    if matches!(
        mode,
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
    ) {
        st.skipped_primitives += 1;
        return Ok(None);
    }
    let mut positions = match primitive.get(&Semantic::Positions) {
        Some(a) => read_vec3(ctx, &a).map_err(|e| fail(format!("POSITION: {e}")))?,
        None => return Err(fail("no POSITION attribute".into())),
    };
    if let Some((i, p)) = positions
        .iter()
        .enumerate()
        .find(|(_, p)| p.is_finite() && p.abs().max_element() > MAX_COORDINATE)
    {
        return Err(fail(format!(
            "vertex {i} position {p} is farther than {MAX_COORDINATE:e} from the origin"
        )));
    }
    let normals = match primitive.get(&Semantic::Normals) {
        Some(a) => Some(read_vec3(ctx, &a).map_err(|e| fail(format!("NORMAL: {e}")))?),
        None => None,
    };
    let uvs = match primitive.get(&Semantic::TexCoords(0)) {
        Some(a) => Some(read_vec2(ctx, &a).map_err(|e| fail(format!("TEXCOORD_0: {e}")))?),
        None => None,
    };
    let indices = match primitive.indices() {
        Some(a) => read_indices(ctx, &a).map_err(|e| fail(format!("indices: {e}")))?,
        None => {
            let n = u32::try_from(positions.len())
                .map_err(|_| fail(format!("{} vertices is too many", positions.len())))?;
            (0..n).collect()
        }
    };
    let triangles = triangulate(mode, &indices);
    if triangles.is_empty() || positions.is_empty() {
        st.warn(format!(
            "mesh '{name}' primitive {pi} has no triangles; skipped"
        ));
        return Ok(None);
    }
    let normal_mode = if normals.is_some() {
        NormalMode::Smooth
    } else {
        NormalMode::Flat
    };
    let label = if mesh.primitives().len() > 1 {
        format!("{name}/{pi}")
    } else {
        name.clone()
    };
    let offset = recentre(&mut positions);
    let data = MeshData {
        positions,
        normals,
        uvs,
        indices: triangles,
    };
    let mesh = Mesh::with_accel(
        label,
        data,
        normal_mode,
        st.quality.quality,
        st.quality.accel.unwrap_or_default(),
    )
    .map_err(fail)?;
    // Tangents only for meshes whose material has a normal map.
    let mesh = if primitive.material().normal_texture().is_some() {
        let given = match primitive.get(&Semantic::Tangents) {
            Some(a) => Some(read_vec4(ctx, &a).map_err(|e| fail(format!("TANGENT: {e}")))?),
            None => None,
        };
        mesh.with_tangents(given).map_err(fail)?
    } else {
        mesh
    };
    Ok(Some((mesh, offset)))
}

/// Converts an index list of the given mode to triangles (glTF's vertex
/// order for strips and fans).
fn triangulate(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => idx
            .windows(3)
            .enumerate()
            .map(|(i, w)| {
                if i % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[0], w[2], w[1]]
                }
            })
            .collect(),
        Mode::TriangleFan => match idx.split_first() {
            Some((&first, rest)) => rest.windows(2).map(|w| [w[0], w[1], first]).collect(),
            None => Vec::new(),
        },
        _ => Vec::new(),
    }
}
