//! Procedural meshes, so that benchmark scenes with many triangles need
//! no large files.

use std::f32::consts::TAU;

use glam::{Vec2, Vec3};

use crate::geometry::mesh::MeshData;

/// A (p, q) torus knot swept by a circular tube: `segments` rings along
/// the knot, `sides` vertices per ring, `2 * segments * sides` triangles.
///
/// The knot winds `p` times around the axis and `q` times through the
/// hole of a torus of major radius `radius`; the tube has radius `tube`.
/// Vertex normals point away from the tube's centre line.
pub fn torus_knot(p: u32, q: u32, radius: f32, tube: f32, segments: u32, sides: u32) -> MeshData {
    let (p, q) = (p as f32, q as f32);
    let centre = |t: f32| {
        let r = radius * (2.0 + (q * t).cos()) / 3.0;
        Vec3::new(
            r * (p * t).cos(),
            radius * (q * t).sin() / 3.0,
            r * (p * t).sin(),
        )
    };
    let mut data = MeshData::default();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for i in 0..segments {
        let t = TAU * i as f32 / segments as f32;
        let c = centre(t);
        let tangent = (centre(t + 1e-3) - centre(t - 1e-3)).normalize();
        let side = tangent.cross(Vec3::Y).normalize_or(Vec3::X);
        let up = side.cross(tangent);
        for j in 0..sides {
            let a = TAU * j as f32 / sides as f32;
            let n = side * a.cos() + up * a.sin();
            data.positions.push(c + n * tube);
            normals.push(n);
            uvs.push(Vec2::new(
                i as f32 / segments as f32,
                j as f32 / sides as f32,
            ));
        }
    }
    for i in 0..segments {
        let i1 = (i + 1) % segments;
        for j in 0..sides {
            let j1 = (j + 1) % sides;
            let (a, b) = (i * sides + j, i * sides + j1);
            let (c, d) = (i1 * sides + j, i1 * sides + j1);
            data.indices.push([a, c, b]);
            data.indices.push([b, c, d]);
        }
    }
    data.normals = Some(normals);
    data.uvs = Some(uvs);
    data
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torus_knot_has_the_promised_size_and_a_closed_tube() {
        let m = torus_knot(2, 3, 1.0, 0.1, 100, 12);
        assert_eq!(m.indices.len(), 2 * 100 * 12);
        assert_eq!(m.positions.len(), 100 * 12);
        // Closed surface: every edge is shared by exactly two triangles.
        let mut edges = std::collections::HashMap::new();
        for t in &m.indices {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
        assert!(
            m.positions
                .iter()
                .all(|p| p.is_finite() && p.length() < 1.2)
        );
    }
}
