//! Structure overlays: a scene's triangle edges, or the boxes, cells or
//! splitting planes of the structure its meshes are built with, as lines
//! over the image and as SVG.
//!
//! Each overlay is a list of [`WorldEdge`]s in the scene's frame, made per
//! mesh instance in object space and carried to the world by the
//! instance's transform (an affine map keeps edges straight). From there
//! the vector-line machinery does the rest ([`project_edges`]): every edge
//! is clipped against the view volume in homogeneous coordinates before
//! the divide ([`crate::core::clip::clip_line_homogeneous`]), projected,
//! and split where its visibility changes, found by casting a ray from the
//! eye to points along it. Hidden pieces are kept (drawn dashed by
//! [`rasterize`] and [`super::vector_lines::to_svg`]) or left out.
//!
//! What each overlay draws, per mesh instance:
//!
//! * [`OverlayKind::Wireframe`]: every triangle edge once (vertices
//!   welded by position, so an edge shared by two triangles is one line);
//!   degenerate edges (both ends at one position) are left out.
//! * [`OverlayKind::Bvh`]: the mesh's bounds and the boxes of the 8-wide
//!   BVH's children down to `depth` levels: level 1 is the root node's
//!   children, level `k + 1` the children of the nodes at level `k`
//!   (leaves included, as the boxes they are).
//! * [`OverlayKind::Kdtree`]: the tree's root box and the splitting planes
//!   of the interior nodes at depth `0 .. depth` (the root at depth 0), each
//!   the rectangle where the plane cuts its node's box.
//! * [`OverlayKind::Grid`]: the grid's bounds and every cell that lists a
//!   triangle, as its twelve edges; an edge shared by neighbouring cells is
//!   drawn once. (`depth` does not apply: the grid has one level.)
//!
//! Only the structure a mesh is built with can be drawn (an overlay of
//! another one is an error): the picture shows what the rays traverse.
//! Analytic shapes have no triangles and no structure; they still hide
//! lines behind them. The top level over instances (always a BVH) is not
//! drawn.

use std::collections::BTreeSet;

use glam::{DVec3, Vec3A};

use crate::accel::bvh8::{Bvh8, EMPTY, LEAF};
use crate::accel::grid::Grid;
use crate::accel::kdtree::KdTree;
use crate::core::settings::Accel;
use crate::image::lines::LineOverlay;
use crate::integrators::Progress;
use crate::integrators::vector_lines::{
    EdgeKind, VectorLines, WorldEdge, project_edges, to_svg, weld,
};
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::scene::instance::InstanceGeometry;

/// What an overlay draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OverlayKind {
    /// Every triangle edge.
    Wireframe,
    /// The BVH's boxes.
    Bvh,
    /// The uniform grid's cells that hold triangles.
    Grid,
    /// The kd-tree's splitting planes.
    Kdtree,
}

impl OverlayKind {
    /// Lower-case name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            OverlayKind::Wireframe => "wireframe",
            OverlayKind::Bvh => "bvh",
            OverlayKind::Grid => "grid",
            OverlayKind::Kdtree => "kdtree",
        }
    }

    /// The structure the meshes must be built with, `None` for the
    /// wireframe (any will do).
    pub fn accel(self) -> Option<Accel> {
        match self {
            OverlayKind::Wireframe => None,
            OverlayKind::Bvh => Some(Accel::Bvh),
            OverlayKind::Grid => Some(Accel::Grid),
            OverlayKind::Kdtree => Some(Accel::Kdtree),
        }
    }

    /// Whether the overlay has levels that a depth limits (the BVH and
    /// the kd-tree).
    pub fn has_levels(self) -> bool {
        matches!(self, OverlayKind::Bvh | OverlayKind::Kdtree)
    }
}

/// Levels drawn when no depth is given.
pub const DEFAULT_DEPTH: u32 = 4;

/// Deepest level an overlay may ask for: deeper than any tree Prism builds
/// (a kd-tree over 2^32 triangles is limited to 50 levels).
pub const MAX_DEPTH: u32 = 64;

/// Ink of the overlays: display values in `[0, 1]` (an orange that
/// stands out on most renders).
pub const COLOR: [f32; 3] = [1.0, 0.55, 0.0];

/// Stroke width in pixels.
pub const STROKE: f32 = 1.0;

/// Opacity of hidden (dashed) pieces in the raster overlay.
pub const HIDDEN_ALPHA: f32 = 0.6;

/// Dash and gap lengths of hidden pieces, in stroke widths (as in the SVG).
pub const DASH: (f32, f32) = (4.0, 3.0);

/// The twelve edges of the box `[lo, hi]`: four along x, four along y,
/// four along z.
pub fn box_edges(lo: DVec3, hi: DVec3) -> [(DVec3, DVec3); 12] {
    let corner = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let mut out = [(DVec3::ZERO, DVec3::ZERO); 12];
    let mut k = 0;
    for axis in 0..3 {
        let bit = 1 << axis;
        for i in (0..8).filter(|i| i & bit == 0) {
            out[k] = (corner(i), corner(i | bit));
            k += 1;
        }
    }
    out
}

/// The triangle edges of a mesh once each: vertices welded by position,
/// edges in order of first appearance in `triangles`, degenerate ones
/// (both ends at one position) left out.
pub fn wireframe_edges(positions: &[Vec3A], triangles: &[[u32; 3]]) -> Vec<(Vec3A, Vec3A)> {
    let (welded, reps) = weld(positions);
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for t in triangles {
        let v = t.map(|i| welded[i as usize]);
        for k in 0..3 {
            let (i, j) = (v[k], v[(k + 1) % 3]);
            if i != j && seen.insert((i.min(j), i.max(j))) {
                out.push((reps[i as usize], reps[j as usize]));
            }
        }
    }
    out
}

/// The child boxes of `bvh` at levels `1 ..= depth` (level 1: the root
/// node's children), parents before children, with their level.
pub fn bvh_boxes(bvh: &Bvh8, depth: u32) -> Vec<(Vec3A, Vec3A, u32)> {
    let mut out = Vec::new();
    if bvh.nodes.is_empty() || depth == 0 {
        return out;
    }
    let mut stack = vec![(0usize, 1u32)];
    while let Some((n, level)) = stack.pop() {
        let node = &bvh.nodes[n];
        for (c, &child) in node.child.iter().enumerate() {
            if child == EMPTY {
                continue;
            }
            let (lo, hi) = node.child_box(c);
            out.push((lo, hi, level));
            if child & LEAF == 0 && level < depth {
                stack.push((child as usize, level + 1));
            }
        }
    }
    out
}

/// A kd-tree splitting plane where it cuts its node's box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitPlane {
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// The plane's coordinate on `axis`.
    pub split: f64,
    /// The node's box.
    pub lo: DVec3,
    /// The node's box.
    pub hi: DVec3,
    /// The node's depth (the root is 0).
    pub depth: u32,
}

impl SplitPlane {
    /// The corners of the rectangle, in order around it.
    pub fn corners(&self) -> [DVec3; 4] {
        let (u, v) = ((self.axis + 1) % 3, (self.axis + 2) % 3);
        let at = |a: f64, b: f64| {
            let mut p = DVec3::ZERO;
            p[self.axis] = self.split;
            p[u] = a;
            p[v] = b;
            p
        };
        [
            at(self.lo[u], self.lo[v]),
            at(self.hi[u], self.lo[v]),
            at(self.hi[u], self.hi[v]),
            at(self.lo[u], self.hi[v]),
        ]
    }
}

/// The splitting planes of the interior nodes of `tree` at depth
/// `0 .. depth`, parents first.
pub fn kdtree_planes(tree: &KdTree, depth: u32) -> Vec<SplitPlane> {
    let mut out = Vec::new();
    tree.for_each_node(|n, lo, hi, d| {
        if !n.is_leaf() && d < depth {
            out.push(SplitPlane {
                axis: n.axis as usize,
                split: n.split,
                lo,
                hi,
                depth: d,
            });
        }
    });
    out
}

/// The edges of the cells of `grid` that list a primitive, each lattice
/// edge once, in lattice order.
pub fn grid_cell_edges(grid: &Grid) -> Vec<(DVec3, DVec3)> {
    let res = grid.resolution();
    let (lo, hi) = grid.bounds();
    if lo.cmpgt(hi).any() {
        return Vec::new();
    }
    // Lattice coordinate `i` on `axis` (the last one exactly the bound).
    let coord = |axis: usize, i: u32| {
        if i == res[axis] {
            hi[axis]
        } else {
            lo[axis] + (hi[axis] - lo[axis]) * (i as f64 / res[axis] as f64)
        }
    };
    // (axis, lattice point at the edge's lower end), sorted and unique.
    let mut edges = BTreeSet::new();
    for z in 0..res[2] {
        for y in 0..res[1] {
            for x in 0..res[0] {
                if grid.cell_prims([x, y, z]).is_empty() {
                    continue;
                }
                let c = [x, y, z];
                for axis in 0..3 {
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let mut p = c;
                        p[u] += du;
                        p[v] += dv;
                        edges.insert((axis, p[2], p[1], p[0]));
                    }
                }
            }
        }
    }
    edges
        .into_iter()
        .map(|(axis, z, y, x)| {
            let p = [x, y, z];
            let mut q = p;
            q[axis] += 1;
            let point = |p: [u32; 3]| DVec3::new(coord(0, p[0]), coord(1, p[1]), coord(2, p[2]));
            (point(p), point(q))
        })
        .collect()
}

/// The object-space edges `kind` draws for one mesh, down to `depth`
/// levels for the BVH and the kd-tree; an error names the mesh when it is
/// not built with the structure asked for.
pub fn mesh_overlay_edges(
    mesh: &crate::geometry::mesh::Mesh,
    kind: OverlayKind,
    depth: u32,
) -> Result<Vec<(Vec3A, Vec3A, EdgeKind)>, String> {
    let wrong = || {
        format!(
            "mesh '{}' is built with the {}, not the {} the overlay draws",
            mesh.name,
            mesh.accel().name(),
            kind.name()
        )
    };
    let Some((lo, hi)) = mesh.bounds() else {
        return Ok(Vec::new());
    };
    let f32_edge = |(a, b): (DVec3, DVec3), k: EdgeKind| (a.as_vec3a(), b.as_vec3a(), k);
    let mut out: Vec<(Vec3A, Vec3A, EdgeKind)> = Vec::new();
    let bounds = |out: &mut Vec<_>, lo: DVec3, hi: DVec3| {
        out.extend(
            box_edges(lo, hi)
                .into_iter()
                .map(|e| f32_edge(e, EdgeKind::Bounds)),
        );
    };
    match kind {
        OverlayKind::Wireframe => {
            out.extend(
                wireframe_edges(mesh.positions(), &mesh.input_indices())
                    .into_iter()
                    .map(|(a, b)| (a, b, EdgeKind::Triangle)),
            );
        }
        OverlayKind::Bvh => {
            if mesh.accel() != Accel::Bvh {
                return Err(wrong());
            }
            bounds(&mut out, lo.as_dvec3(), hi.as_dvec3());
            for (a, b, _) in bvh_boxes(mesh.bvh(), depth) {
                out.extend(
                    box_edges(a.as_dvec3(), b.as_dvec3())
                        .into_iter()
                        .map(|e| f32_edge(e, EdgeKind::Box)),
                );
            }
        }
        OverlayKind::Kdtree => {
            let tree = mesh.kdtree().ok_or_else(wrong)?;
            bounds(&mut out, tree.lo, tree.hi);
            for p in kdtree_planes(tree, depth) {
                let c = p.corners();
                for k in 0..4 {
                    out.push(f32_edge((c[k], c[(k + 1) % 4]), EdgeKind::Plane));
                }
            }
        }
        OverlayKind::Grid => {
            let grid = mesh.grid().ok_or_else(wrong)?;
            let (glo, ghi) = grid.bounds();
            bounds(&mut out, glo, ghi);
            out.extend(
                grid_cell_edges(grid)
                    .into_iter()
                    .map(|e| f32_edge(e, EdgeKind::Cell)),
            );
        }
    }
    Ok(out)
}

/// The edges of overlay `kind` for every mesh instance of `scene`, in the
/// scene's frame, in instance order.
pub fn overlay_edges(
    scene: &RenderScene,
    kind: OverlayKind,
    depth: u32,
) -> Result<Vec<WorldEdge>, String> {
    let mut out = Vec::new();
    for (i, inst) in scene.instances().iter().enumerate() {
        let InstanceGeometry::Mesh(mesh) = &inst.geometry else {
            continue;
        };
        let m = &inst.transform.to_world;
        for (a, b, k) in mesh_overlay_edges(mesh, kind, depth)? {
            out.push(WorldEdge {
                a: m.transform_point3a(a),
                b: m.transform_point3a(b),
                kind: k,
                instance: i as u32,
            });
        }
    }
    Ok(out)
}

/// Overlay `kind` of `scene` seen through `camera` (prepared in the
/// scene's frame) on a `width` x `height` image: visible and hidden
/// pieces, found by ray casting. `progress` is called with the number of
/// edges finished.
pub fn overlay_lines(
    scene: &RenderScene,
    camera: &CameraRays,
    size: (u32, u32),
    kind: OverlayKind,
    depth: u32,
    progress: Option<Progress<'_>>,
) -> Result<VectorLines, String> {
    let edges = overlay_edges(scene, kind, depth)?;
    Ok(project_edges(scene, camera, size, &edges, progress))
}

/// The lines as an ink coverage mask the image's size: visible pieces
/// solid, hidden ones dashed at [`HIDDEN_ALPHA`] when `hidden` (left out
/// otherwise), in `color`, `stroke` pixels wide.
pub fn rasterize(lines: &VectorLines, color: [f32; 3], stroke: f32, hidden: bool) -> LineOverlay {
    let mut overlay = LineOverlay::empty(lines.width, lines.height, color);
    for s in &lines.segments {
        if s.visible {
            overlay.draw_segment(s.a, s.b, stroke, None, 1.0);
        } else if hidden {
            let dash = Some((DASH.0 * stroke, DASH.1 * stroke));
            overlay.draw_segment(s.a, s.b, stroke, dash, HIDDEN_ALPHA);
        }
    }
    overlay
}

/// [`to_svg`] in the overlays' ink and stroke.
pub fn overlay_svg(lines: &VectorLines, hidden: bool) -> String {
    to_svg(lines, COLOR, STROKE, hidden)
}
