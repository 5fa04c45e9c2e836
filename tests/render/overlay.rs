//! Structure overlays (`--overlay wireframe|bvh|grid|kdtree`): every
//! piece against an independent f64 projection of its own world edge,
//! inside the image, covering all of the edge the image shows, with its
//! visibility equal to brute-force ray casting; the kd-tree overlay draws
//! exactly the splitting planes down to the depth asked for.

use glam::{DVec2, DVec3, Vec3A};
use prism::accel::kdtree::KdTree;
use prism::core::math::Ray;
use prism::geometry::mesh::Mesh;
use prism::integrators::IntegratorKind;
use prism::integrators::overlay::{OverlayKind, mesh_overlay_edges, overlay_edges, overlay_svg};
use prism::integrators::vector_lines::{EdgeKind, MIN_PIECE, VISIBILITY_MARGIN, project_edges};
use prism::scene::RenderScene;
use prism::scene::camera::CameraRays;
use prism::scene::instance::InstanceGeometry;

use crate::common::render::{config, renderer, sized};
use crate::common::scenes::load_toml;
use crate::illustration::{Pinhole, cube_and_sphere_mesh};

const W: u32 = 96;
const H: u32 = 72;

/// The cube and the sphere mesh of the illustration tests, built with
/// `accel`, seen from `eye` towards the origin.
fn scene(accel: &str, eye: [f64; 3]) -> (std::sync::Arc<RenderScene>, CameraRays, Pinhole) {
    let text = format!(
        "[settings]\naccel = \"{accel}\"\n{}",
        cube_and_sphere_mesh()
    )
    .replace(
        "look_from = [3, 2.5, 4]",
        &format!("look_from = [{}, {}, {}]", eye[0], eye[1], eye[2]),
    );
    let desc = load_toml(&text).unwrap();
    let camera = desc.cameras[0].clone();
    assert_eq!(camera.look_from, DVec3::from(eye));
    let mut r = renderer(desc, config(sized(W, H), IntegratorKind::Recursive));
    r.run();
    let scene = r.scene().unwrap();
    let rays = CameraRays::relative_to(&camera, scene.origin(), W, H);
    (scene, rays, Pinhole::new(eye, [0.0; 3], 40.0, W, H))
}

/// Distance from `p` to the segment `a`-`b`.
fn to_segment(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let d = b - a;
    if d.length_squared() == 0.0 {
        return (p - a).length();
    }
    let t = ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
    (a + d * t - p).length()
}

/// Whether world point `p` (scene frame) is visible from the eye,
/// testing every object and triangle (no structure) with the vector
/// lines' margin.
fn brute_visible(scene: &RenderScene, eye: Vec3A, p: Vec3A) -> bool {
    let ray = Ray::new(eye, p - eye);
    scene
        .intersect_brute_force(&ray, 0.0, VISIBILITY_MARGIN)
        .is_none()
}

/// Film positions are within this many pixels of the f64 projection of
/// their world points. The world points are f32 (relative error 2^-24,
/// 6e-8) at distances up to about 6 from the eye, and the camera's basis
/// is built and inverted in f32: errors of a few 1e-7 in tangent units
/// of a view about 0.7 wide over 96 pixels, i.e. a few 1e-5 pixel
/// (measured: at most 1.2e-5 over these tests). 1e-3 leaves a factor of
/// about 50.
const FILM_TOL: f64 = 1e-3;

/// Checks every overlay of `kind` for the camera at `eye`; returns
/// (pieces, hidden pieces, visibility checks).
fn check_overlay(
    accel: &str,
    kind: OverlayKind,
    depth: u32,
    eye: [f64; 3],
) -> (usize, usize, usize) {
    let (scene, rays, cam) = scene(accel, eye);
    let origin = scene.origin();
    let world = |p: Vec3A| p.as_dvec3() + origin;
    let edges = overlay_edges(&scene, kind, depth).unwrap();
    assert!(!edges.is_empty());
    let (wf, hf) = (W as f64, H as f64);
    let (mut pieces, mut hidden, mut checked) = (0, 0, 0);
    for e in &edges {
        // The pieces of this edge alone.
        let v = project_edges(&scene, &rays, (W, H), std::slice::from_ref(e), None);
        let (ea, eb) = (world(e.a), world(e.b));
        let len = (eb - ea).length();
        for s in &v.segments {
            assert_eq!((s.kind, s.instance), (e.kind, e.instance));
            for (film, p) in [(s.a, s.world[0]), (s.b, s.world[1])] {
                // Clipped: inside the image, boundary included.
                assert!(
                    film.x >= 0.0 && film.x <= W as f32 && film.y >= 0.0 && film.y <= H as f32,
                    "{kind:?}: {film} outside the image"
                );
                let p = world(p);
                // On its own world edge, in front of the eye, and at its
                // independent projection.
                let t = ((p - ea).dot(eb - ea) / (len * len)).clamp(0.0, 1.0);
                assert!(
                    (ea + (eb - ea) * t - p).length() <= 1e-6 * (1.0 + len),
                    "{kind:?}: {p} off its edge {ea} {eb}"
                );
                assert!(cam.depth(p) > 0.0, "{kind:?}: {p} behind the eye");
                let want = cam.project(p);
                assert!(
                    (film.as_dvec2() - want).length() <= FILM_TOL,
                    "{kind:?}: {film} vs {want} for {p}"
                );
            }
            pieces += 1;
            hidden += !s.visible as usize;
            if (s.b - s.a).length() > 0.25 {
                let mid = (s.world[0] + s.world[1]) * 0.5;
                assert_eq!(
                    s.visible,
                    brute_visible(&scene, rays.origin(), mid),
                    "{kind:?}: {s:?}"
                );
                checked += 1;
            }
        }
        // Every point of the edge the image shows (in front of the eye,
        // projecting inside the image) is on one of its pieces, or within
        // MIN_PIECE of one: runs shorter than that are left out, and so is
        // a whole edge that projects shorter.
        let whole = if cam.depth(ea) > 0.0 && cam.depth(eb) > 0.0 {
            (cam.project(eb) - cam.project(ea)).length()
        } else {
            f64::INFINITY
        };
        if whole < MIN_PIECE as f64 {
            continue;
        }
        for i in 0..64 {
            let p = ea + (eb - ea) * ((i as f64 + 0.5) / 64.0);
            if cam.depth(p) < 1e-3 {
                continue;
            }
            let f = cam.project(p);
            let m = 0.05;
            if !(f.x > m && f.x < wf - m && f.y > m && f.y < hf - m) {
                continue;
            }
            assert!(
                v.segments
                    .iter()
                    .any(|s| to_segment(f, s.a.as_dvec2(), s.b.as_dvec2())
                        <= FILM_TOL + MIN_PIECE as f64),
                "{kind:?}: {p} (at {f}) of edge {ea} {eb} is on no piece"
            );
        }
    }
    (pieces, hidden, checked)
}

/// Outside the objects, and inside the sphere mesh's bounds (between the
/// sphere and a corner of its box, so its box and planes pass beside and
/// behind the eye).
const EYES: [[f64; 3]; 2] = [[3.0, 2.5, 4.0], [2.1, 1.95, 2.4]];

#[test]
fn wireframe_pieces_are_projected_clipped_and_ray_cast_like_brute_force() {
    for eye in EYES {
        let (pieces, hidden, checked) = check_overlay("bvh", OverlayKind::Wireframe, 4, eye);
        assert!(
            pieces > 200 && hidden > 20 && checked > 100,
            "{pieces} {hidden} {checked}"
        );
    }
}

#[test]
fn kdtree_pieces_are_projected_clipped_and_ray_cast_like_brute_force() {
    for eye in EYES {
        let (pieces, hidden, checked) = check_overlay("kdtree", OverlayKind::Kdtree, 4, eye);
        assert!(
            pieces > 40 && hidden > 5 && checked > 20,
            "{pieces} {hidden} {checked}"
        );
    }
}

#[test]
fn bvh_and_grid_pieces_are_projected_clipped_and_ray_cast_like_brute_force() {
    let (pieces, hidden, checked) = check_overlay("bvh", OverlayKind::Bvh, 2, EYES[1]);
    assert!(
        pieces > 40 && hidden > 5 && checked > 20,
        "{pieces} {hidden} {checked}"
    );
    let (pieces, hidden, checked) = check_overlay("grid", OverlayKind::Grid, 1, EYES[0]);
    assert!(
        pieces > 100 && hidden > 10 && checked > 50,
        "{pieces} {hidden} {checked}"
    );
}

/// The interior nodes of `tree` at depth below `depth`, found by walking
/// the node array from the root (left child next, right child at
/// `index`): (axis, split, the node box's bounds on the other two axes).
fn planes_by_walking(tree: &KdTree, depth: u32) -> Vec<(usize, f32, [f32; 4])> {
    fn walk(
        tree: &KdTree,
        i: usize,
        lo: DVec3,
        hi: DVec3,
        d: u32,
        depth: u32,
        out: &mut Vec<(usize, f32, [f32; 4])>,
    ) {
        let n = tree.nodes[i];
        if n.axis == 3 {
            return;
        }
        let a = n.axis as usize;
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        if d < depth {
            out.push((
                a,
                n.split as f32,
                [lo[u] as f32, lo[v] as f32, hi[u] as f32, hi[v] as f32],
            ));
        }
        let (mut lhi, mut rlo) = (hi, lo);
        lhi[a] = n.split;
        rlo[a] = n.split;
        walk(tree, i + 1, lo, lhi, d + 1, depth, out);
        walk(tree, n.index as usize, rlo, hi, d + 1, depth, out);
    }
    let mut out = Vec::new();
    if !tree.nodes.is_empty() {
        walk(tree, 0, tree.lo, tree.hi, 0, depth, &mut out);
    }
    out
}

/// The planes the overlay's `Plane` edges draw, read back from the edges:
/// four per rectangle, its constant coordinate the axis.
fn planes_drawn(edges: &[(Vec3A, Vec3A, EdgeKind)]) -> Vec<(usize, f32, [f32; 4])> {
    let planes: Vec<_> = edges.iter().filter(|e| e.2 == EdgeKind::Plane).collect();
    assert_eq!(planes.len() % 4, 0);
    planes
        .chunks(4)
        .map(|r| {
            // A closed loop of four edges.
            for k in 0..4 {
                assert_eq!(r[k].1, r[(k + 1) % 4].0, "not a closed rectangle: {r:?}");
            }
            let corners: Vec<Vec3A> = r.iter().map(|e| e.0).collect();
            let a = (0..3)
                .find(|&a| corners.iter().all(|c| c[a] == corners[0][a]))
                .expect("a rectangle in an axis plane");
            let (u, v) = ((a + 1) % 3, (a + 2) % 3);
            let lo = corners.iter().fold(Vec3A::INFINITY, |m, c| m.min(*c));
            let hi = corners.iter().fold(Vec3A::NEG_INFINITY, |m, c| m.max(*c));
            (a, corners[0][a], [lo[u], lo[v], hi[u], hi[v]])
        })
        .collect()
}

fn sorted(mut v: Vec<(usize, f32, [f32; 4])>) -> Vec<(usize, f32, [f32; 4])> {
    v.sort_by(|x, y| {
        (x.0, x.1, x.2)
            .partial_cmp(&(y.0, y.1, y.2))
            .expect("finite planes")
    });
    v
}

#[test]
fn kdtree_overlay_draws_exactly_the_splitting_planes_down_to_the_depth() {
    let (scene, rays, _) = scene("kdtree", EYES[0]);
    let meshes: Vec<&Mesh> = scene
        .instances()
        .iter()
        .filter_map(|i| match &i.geometry {
            InstanceGeometry::Mesh(m) => Some(&**m),
            _ => None,
        })
        .collect();
    assert_eq!(meshes.len(), 2);
    // The sphere's tree has levels to count (the cube's is one leaf).
    let deepest = meshes.iter().map(|m| m.kdtree().unwrap().depth).max();
    assert!(deepest >= Some(4), "{deepest:?}");
    for mesh in meshes {
        let tree = mesh.kdtree().expect("built with the kd-tree");
        let mut previous = 0;
        for depth in 1..=tree.depth + 1 {
            let edges = mesh_overlay_edges(mesh, OverlayKind::Kdtree, depth).unwrap();
            let want = sorted(planes_by_walking(tree, depth));
            let got = sorted(planes_drawn(&edges));
            assert_eq!(got.len(), want.len(), "{}: depth {depth}", mesh.name);
            assert_eq!(got, want, "{}: depth {depth}", mesh.name);
            // Each level adds planes down to the deepest interior node
            // (one level above the deepest leaf).
            assert!(want.len() > previous || depth > tree.depth);
            previous = want.len();
            // And the root box, once.
            let bounds = edges.iter().filter(|e| e.2 == EdgeKind::Bounds).count();
            assert_eq!(bounds, 12);
            assert_eq!(edges.len(), 12 + 4 * want.len());
        }
        let interior = tree.nodes.iter().filter(|n| !n.is_leaf()).count();
        assert_eq!(previous, interior, "the whole tree at its depth");
    }
    // Hidden pieces are in the SVG only when asked for.
    let edges = overlay_edges(&scene, OverlayKind::Kdtree, 3).unwrap();
    let v = project_edges(&scene, &rays, (W, H), &edges, None);
    let hidden = v.segments.iter().filter(|s| !s.visible).count();
    assert!(hidden > 0);
    let with = overlay_svg(&v, true);
    assert_eq!(with.matches("<line ").count(), v.segments.len());
    assert_eq!(with.matches("hidden\"").count(), hidden);
    let without = overlay_svg(&v, false);
    assert_eq!(without.matches("<line ").count(), v.segments.len() - hidden);
}

#[test]
fn overlays_of_a_structure_the_meshes_are_not_built_with_are_refused() {
    let (scene, _, _) = scene("grid", EYES[0]);
    for kind in [OverlayKind::Bvh, OverlayKind::Kdtree] {
        let e = overlay_edges(&scene, kind, 2).unwrap_err();
        assert!(e.contains("grid") && e.contains(kind.name()), "{e}");
    }
    assert!(overlay_edges(&scene, OverlayKind::Grid, 1).is_ok());
    assert!(overlay_edges(&scene, OverlayKind::Wireframe, 1).is_ok());
}
