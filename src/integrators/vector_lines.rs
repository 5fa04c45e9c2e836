//! Feature lines as vectors: the edges of the scene's meshes classified
//! for the camera in world space, split where their visibility changes
//! (decided by casting rays), projected, clipped to the image and written
//! as SVG.
//!
//! * **Classification** ([`mesh_edges`]): vertices are welded by position
//!   (so flat meshes with split vertices have shared edges); an edge with
//!   one face is a *border*, an edge between a face turned towards the eye
//!   and one turned away is a *silhouette*, and an edge whose two faces'
//!   normals deviate by more than the crease angle is a *crease*; an edge
//!   of more than two faces counts as a border.
//! * **Visibility**: a point of an edge is visible when the ray from the
//!   eye to it meets nothing before [`VISIBILITY_MARGIN`] of the way (the
//!   edge's own faces are met only at the point itself). Points are tested
//!   every half pixel of the projected edge, and each change of visibility
//!   is located by bisection to 1/64 pixel.
//! * **Projection and clipping**: edges are clipped against the view
//!   volume in homogeneous coordinates before the perspective divide
//!   ([`CameraProjection::to_clip`], [`clip_line_homogeneous`]), so nothing
//!   behind the eye is projected and only the piece inside the image is
//!   worked on; a straight edge projects to a straight segment, and points
//!   along it are found by perspective-correct interpolation.
//!
//! The same machinery draws the structure overlays
//! ([`crate::integrators::overlay`]): any list of [`WorldEdge`]s goes
//! through [`project_edges`] and [`to_svg`].
//!
//! Analytic shapes (spheres, quadrics, ...) have no edges and are not in the
//! vector output; they still hide the edges behind them.

use std::collections::HashMap;
use std::fmt::Write as _;

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use crate::core::clip::clip_line_homogeneous;
use crate::core::math::Ray;
use crate::integrators::Progress;
use crate::integrators::lines::crease_cosine_degrees;
use crate::scene::RenderScene;
use crate::scene::camera::{CameraProjection, CameraRays};
use crate::scene::instance::InstanceGeometry;

/// What makes an edge a line: a feature line of a mesh, or an edge the
/// structure overlays draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EdgeKind {
    /// Between a face turned towards the eye and one turned away.
    Silhouette,
    /// Between two faces whose normals deviate by more than the crease angle.
    Crease,
    /// An edge of only one face (the border of an open mesh), or of more
    /// than two.
    Border,
    /// A triangle edge (the wireframe overlay).
    Triangle,
    /// An edge of a mesh's bounding box (the structure overlays).
    Bounds,
    /// An edge of a BVH node's box.
    Box,
    /// An edge of a grid cell that holds triangles.
    Cell,
    /// An edge of a kd-tree splitting plane (its rectangle in the node's box).
    Plane,
}

impl EdgeKind {
    /// Lower-case name (the SVG class).
    pub fn name(self) -> &'static str {
        match self {
            EdgeKind::Silhouette => "silhouette",
            EdgeKind::Crease => "crease",
            EdgeKind::Border => "border",
            EdgeKind::Triangle => "triangle",
            EdgeKind::Bounds => "bounds",
            EdgeKind::Box => "box",
            EdgeKind::Cell => "cell",
            EdgeKind::Plane => "plane",
        }
    }
}

/// A line edge in the scene's frame (world coordinates minus
/// [`RenderScene::origin`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldEdge {
    /// One end.
    pub a: Vec3A,
    /// The other end.
    pub b: Vec3A,
    /// Why it is a line.
    pub kind: EdgeKind,
    /// Instance it belongs to.
    pub instance: u32,
}

/// A projected piece of a line edge, in film pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment2 {
    /// Start, in pixels (`(0, 0)` is the image's top-left corner).
    pub a: Vec2,
    /// End.
    pub b: Vec2,
    /// The points `a` and `b` are the projections of, in the scene's
    /// frame (world coordinates minus [`RenderScene::origin`]).
    pub world: [Vec3A; 2],
    /// Why it is a line.
    pub kind: EdgeKind,
    /// Whether the ray casting found it visible.
    pub visible: bool,
    /// Instance it belongs to.
    pub instance: u32,
}

/// The vector lines of one view.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VectorLines {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Visible and hidden pieces, in instance and edge order.
    pub segments: Vec<Segment2>,
    /// Visibility rays cast.
    pub rays: u64,
}

/// A point of an edge is hidden when something is hit before this fraction
/// of the way from the eye to it: a relative margin above the rounding of
/// hits on the edge's own faces at grazing angles.
pub const VISIBILITY_MARGIN: f32 = 1.0 - 1e-4;

/// Length in pixels below which a visible or hidden piece is left out.
pub const MIN_PIECE: f32 = 1.0 / 32.0;

/// Vertices welded by exact position (`-0.0` and `0.0` alike): the id of
/// each vertex's position, and one vertex per id.
pub fn weld(positions: &[Vec3A]) -> (Vec<u32>, Vec<Vec3A>) {
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let mut welded = Vec::with_capacity(positions.len());
    let mut reps: Vec<Vec3A> = Vec::new();
    for p in positions {
        let key = p.to_array().map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let id = *weld.entry(key).or_insert_with(|| {
            reps.push(*p);
            reps.len() as u32 - 1
        });
        welded.push(id);
    }
    (welded, reps)
}

/// The line edges of a triangle mesh for an eye at `eye`: `positions` and
/// `triangles` in world space, `cos_crease` the cosine of the crease angle
/// (below it two faces make a crease; pass less than -1 for none). Returns
/// `(a, b, kind)` per edge, in a fixed order.
pub fn mesh_edges(
    positions: &[Vec3A],
    triangles: &[[u32; 3]],
    eye: Vec3A,
    cos_crease: f32,
) -> Vec<(Vec3A, Vec3A, EdgeKind)> {
    let (welded, reps) = weld(positions);
    // Faces of each edge, in triangle order.
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    let mut order: Vec<(u32, u32)> = Vec::new();
    let mut normals = Vec::with_capacity(triangles.len());
    for (f, t) in triangles.iter().enumerate() {
        let v = t.map(|i| welded[i as usize]);
        let [p0, p1, p2] = v.map(|i| reps[i as usize]);
        normals.push((p1 - p0).cross(p2 - p0).normalize_or_zero());
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        for k in 0..3 {
            let (i, j) = (v[k], v[(k + 1) % 3]);
            let key = (i.min(j), i.max(j));
            let faces = edges.entry(key).or_default();
            if faces.is_empty() {
                order.push(key);
            }
            faces.push(f as u32);
        }
    }
    let facing = |f: u32| {
        let n = normals[f as usize];
        let p = reps[welded[triangles[f as usize][0] as usize] as usize];
        n.dot(p - eye) < 0.0
    };
    let mut out = Vec::new();
    for key in order {
        let faces = &edges[&key];
        let kind = match faces.as_slice() {
            [_] => Some(EdgeKind::Border),
            [f, g] => {
                let (nf, ng) = (normals[*f as usize], normals[*g as usize]);
                if nf == Vec3A::ZERO || ng == Vec3A::ZERO {
                    None
                } else if facing(*f) != facing(*g) {
                    Some(EdgeKind::Silhouette)
                } else if nf.dot(ng) < cos_crease {
                    Some(EdgeKind::Crease)
                } else {
                    None
                }
            }
            _ => Some(EdgeKind::Border),
        };
        if let Some(kind) = kind {
            out.push((reps[key.0 as usize], reps[key.1 as usize], kind));
        }
    }
    out
}

/// The line edges of every mesh instance of `scene` for an eye at `eye`.
pub fn scene_edges(scene: &RenderScene, eye: Vec3A, cos_crease: f32) -> Vec<WorldEdge> {
    let mut out = Vec::new();
    for (i, inst) in scene.instances().iter().enumerate() {
        let InstanceGeometry::Mesh(mesh) = &inst.geometry else {
            continue;
        };
        let m = &inst.transform.to_world;
        let world: Vec<Vec3A> = mesh
            .positions()
            .iter()
            .map(|&p| m.transform_point3a(p))
            .collect();
        for (a, b, kind) in mesh_edges(&world, mesh.triangle_indices(), eye, cos_crease) {
            out.push(WorldEdge {
                a,
                b,
                kind,
                instance: i as u32,
            });
        }
    }
    out
}

/// Whether world point `p` is visible from the eye.
fn visible(scene: &RenderScene, eye: Vec3A, p: Vec3A, rays: &mut u64) -> bool {
    *rays += 1;
    !scene.occluded(&Ray::new(eye, p - eye), 0.0, VISIBILITY_MARGIN)
}

/// Splits one world edge into visible and hidden pieces inside the image.
fn edge_segments(
    scene: &RenderScene,
    proj: &CameraProjection,
    size: Vec2,
    edge: &WorldEdge,
    out: &mut Vec<Segment2>,
    rays: &mut u64,
) {
    let eye = proj.origin();
    // Clip against the view volume in homogeneous coordinates, before any
    // divide: nothing behind the eye is projected, and what remains is the
    // piece inside the image. Clip coordinates are linear in the world
    // point, so the parameters are those of the world edge too.
    let (ca, cb) = (proj.to_clip(edge.a, size), proj.to_clip(edge.b, size));
    let Some((t0, t1, c0, c1)) = clip_line_homogeneous(ca, cb) else {
        return;
    };
    let (ea, eb) = (edge.a.as_dvec3(), edge.b.as_dvec3());
    let a = (ea + (eb - ea) * t0).as_vec3a();
    let b = (ea + (eb - ea) * t1).as_vec3a();
    let (fa, fb) = (
        CameraProjection::clip_to_film(c0, size),
        CameraProjection::clip_to_film(c1, size),
    );
    let (za, zb) = (c0.w as f32, c1.w as f32);
    let (s0, s1) = (0.0f32, 1.0f32);
    // World point whose projection is at film parameter `s` of `fa..fb`
    // (perspective correct: 1/depth is linear on the film).
    let at = |s: f32| {
        let u = (s / zb) / ((1.0 - s) / za + s / zb);
        a + (b - a) * u
    };
    // Kept inside the image against the rounding of the interpolation.
    let film = |s: f32| (fa + (fb - fa) * s).clamp(Vec2::ZERO, size);
    let length = (fb - fa).length() * (s1 - s0);
    let steps = ((length * 2.0).ceil() as usize).clamp(1, 1 << 14);
    let mut runs: Vec<(f32, bool)> = Vec::new(); // (start parameter, visible)
    let mut prev_s = s0;
    let mut prev_v = visible(scene, eye, at(s0), rays);
    runs.push((s0, prev_v));
    for k in 1..=steps {
        let s = s0 + (s1 - s0) * k as f32 / steps as f32;
        let v = visible(scene, eye, at(s), rays);
        if v != prev_v {
            // Bisect to 1/64 pixel.
            let (mut lo, mut hi) = (prev_s, s);
            // At most 40 halvings, and never past adjacent floats.
            for _ in 0..40 {
                if (hi - lo) * (fb - fa).length() <= 1.0 / 64.0 {
                    break;
                }
                let mid = 0.5 * (lo + hi);
                if mid <= lo || mid >= hi {
                    break;
                }
                if visible(scene, eye, at(mid), rays) == prev_v {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let cut = 0.5 * (lo + hi);
            runs.push((cut, v));
            prev_v = v;
        }
        prev_s = s;
    }
    for (k, &(start, vis)) in runs.iter().enumerate() {
        let end = runs.get(k + 1).map_or(s1, |r| r.0);
        // Pieces shorter than MIN_PIECE pixels (a hidden edge's last
        // fraction of a pixel at a vertex it shares with visible faces)
        // are left out.
        if (fb - fa).length() * (end - start) < MIN_PIECE {
            continue;
        }
        out.push(Segment2 {
            a: film(start),
            b: film(end),
            world: [at(start), at(end)],
            kind: edge.kind,
            visible: vis,
            instance: edge.instance,
        });
    }
}

/// The vector lines of `scene`'s meshes seen through `camera` (prepared in
/// the scene's frame, [`CameraRays::relative_to`] its origin) on a
/// `width` x `height` image, creases above `crease_degrees`. `progress`
/// is called with the number of edges finished.
pub fn vector_lines(
    scene: &RenderScene,
    camera: &CameraRays,
    size: (u32, u32),
    crease_degrees: f32,
    progress: Option<Progress<'_>>,
) -> VectorLines {
    let cos_crease = crease_cosine_degrees(crease_degrees);
    let edges = scene_edges(scene, camera.origin(), cos_crease);
    project_edges(scene, camera, size, &edges, progress)
}

/// Any world `edges` (in the scene's frame) seen through `camera` on a
/// `width` x `height` image: clipped to the view, projected and split
/// where their visibility changes, by ray casting against `scene`.
/// Segments come in edge order, whatever the thread count. `progress` is
/// called with the number of edges finished.
pub fn project_edges(
    scene: &RenderScene,
    camera: &CameraRays,
    (width, height): (u32, u32),
    edges: &[WorldEdge],
    progress: Option<Progress<'_>>,
) -> VectorLines {
    let proj = camera.projection();
    let size = Vec2::new(width as f32, height as f32);
    let parts: Vec<(Vec<Segment2>, u64)> = edges
        .par_chunks(256)
        .with_max_len(1)
        .map(|chunk| {
            let mut out = Vec::new();
            let mut rays = 0;
            for e in chunk {
                edge_segments(scene, &proj, size, e, &mut out, &mut rays);
            }
            if let Some(p) = progress {
                p(chunk.len() as u64);
            }
            (out, rays)
        })
        .collect();
    let mut lines = VectorLines {
        width,
        height,
        ..Default::default()
    };
    for (s, r) in parts {
        lines.segments.extend(s);
        lines.rays += r;
    }
    lines
}

/// Number of line edges `vector_lines` will process (for a progress bar).
pub fn edge_count(scene: &RenderScene, camera: &CameraRays, crease_degrees: f32) -> usize {
    let cos = crease_cosine_degrees(crease_degrees);
    scene_edges(scene, camera.origin(), cos).len()
}

/// The lines as an SVG document the image's size: visible segments solid,
/// hidden ones dashed and grey when `hidden` (left out otherwise), each a
/// `<line>` whose class names its kind and visibility. `color` is the ink
/// (display values in `[0, 1]`), `stroke` the width in pixels.
pub fn to_svg(lines: &VectorLines, color: [f32; 3], stroke: f32, hidden: bool) -> String {
    let hex = |c: f32| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let ink = format!(
        "#{:02x}{:02x}{:02x}",
        hex(color[0]),
        hex(color[1]),
        hex(color[2])
    );
    let mut s = String::new();
    let (w, h) = (lines.width, lines.height);
    let _ = writeln!(
        s,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">
<style>
line {{ stroke: {ink}; stroke-width: {stroke}; stroke-linecap: round; fill: none; }}
line.hidden {{ stroke: #909090; stroke-dasharray: {d1} {d2}; stroke-width: {hs}; }}
</style>
<rect width="{w}" height="{h}" fill="white"/>"#,
        d1 = 4.0 * stroke,
        d2 = 3.0 * stroke,
        hs = 0.75 * stroke,
    );
    // Hidden lines first, so that visible ones are drawn over them.
    for pass_visible in [false, true] {
        if !pass_visible && !hidden {
            continue;
        }
        for seg in lines.segments.iter().filter(|g| g.visible == pass_visible) {
            let _ = writeln!(
                s,
                r#"<line class="{} {}" x1="{:.3}" y1="{:.3}" x2="{:.3}" y2="{:.3}"/>"#,
                seg.kind.name(),
                if seg.visible { "visible" } else { "hidden" },
                seg.a.x,
                seg.a.y,
                seg.b.x,
                seg.b.y
            );
        }
    }
    s.push_str("</svg>\n");
    s
}
