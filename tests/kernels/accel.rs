//! The four structures over a mesh (BVH, kd-tree, uniform grid, brute
//! force) return the same hits, bit for bit: the same `t`, barycentrics
//! and input triangle (equal `t` going to the lowest input index), and
//! the same any-hit answers; plus the 3D DDA's edge cases.

use std::path::Path;

use glam::{Vec3, Vec3A};
use prism::core::math::Ray;
use prism::geometry::mesh::{Accel, BuildQuality, Mesh, MeshData, MeshHit, NormalMode};

use crate::common::rng::{Random, SplitMix64 as Rng};

/// A hit as compared: `t`, input triangle and barycentrics, by bits.
pub fn key(m: &Mesh, h: Option<MeshHit>) -> Option<(u32, u32, u32, u32)> {
    h.map(|h| {
        (
            h.t.to_bits(),
            m.input_triangle(h.triangle as usize),
            h.b1.to_bits(),
            h.b2.to_bits(),
        )
    })
}

/// `data` built with every structure, the BVH first.
pub fn every_structure(data: &MeshData) -> Vec<Mesh> {
    Accel::ALL
        .iter()
        .map(|&a| {
            Mesh::with_accel(
                a.name(),
                data.clone(),
                NormalMode::Flat,
                BuildQuality::Medium,
                a,
            )
            .unwrap()
        })
        .collect()
}

/// Closest and any hit of `ray` on `(t_min, t_max)` agree across
/// `meshes`; returns whether it hit.
pub fn agree(meshes: &[Mesh], ray: &Ray, t_min: f32, t_max: f32, what: &str) -> bool {
    let want = key(&meshes[0], meshes[0].intersect(ray, t_min, t_max));
    let blocked = meshes[0].occluded(ray, t_min, t_max);
    assert_eq!(
        blocked,
        want.is_some(),
        "{what}: bvh any-hit disagrees with its closest hit, {ray:?}"
    );
    for m in &meshes[1..] {
        let got = key(m, m.intersect(ray, t_min, t_max));
        assert_eq!(
            got,
            want,
            "{what}: {:?} and the BVH disagree on {ray:?} in ({t_min}, {t_max})",
            m.accel()
        );
        assert_eq!(
            m.occluded(ray, t_min, t_max),
            blocked,
            "{what}: {:?} any-hit on {ray:?}",
            m.accel()
        );
    }
    // Brute force, independently of the brute structure.
    assert_eq!(
        key(
            &meshes[0],
            meshes[0].intersect_brute_force(ray, t_min, t_max)
        ),
        want
    );
    want.is_some()
}

/// Random triangles, some sharing edges (coplanar neighbours: equal-t
/// hits on the shared edge), some axis-aligned, some large.
fn soup(rng: &mut Rng, n: usize) -> MeshData {
    let mut data = MeshData::default();
    for i in 0..n {
        let k = data.positions.len() as u32;
        let c = rng.vec(-1.0, 1.0);
        let size = if i % 13 == 0 { 1.5 } else { 0.15 };
        let mut p = [0; 3].map(|_| c + rng.vec(-size, size));
        if i % 5 == 0 {
            for q in &mut p {
                q.y = c.y;
            }
        }
        data.positions.extend(p);
        data.indices.push([k, k + 1, k + 2]);
        if i % 4 == 0 {
            // A coplanar neighbour across edge (1, 2).
            let q = p[1] + p[2] - p[0];
            data.positions.push(q);
            data.indices.push([k + 2, k + 1, k + 3]);
        }
    }
    data
}

fn random_ray(rng: &mut Rng, inside: bool) -> Ray {
    let o = if inside {
        rng.vec(-1.0, 1.0)
    } else {
        rng.dir() * rng.range(2.0, 6.0)
    };
    let target = rng.vec(-1.0, 1.0);
    let mut d = target - o;
    match rng.below(8) {
        // Axis-aligned, with signed zeros.
        0 => d = Vec3::new(d.x, 0.0, -0.0),
        1 => d = Vec3::new(-0.0, d.y, 0.0),
        _ => {}
    }
    Ray::new(o.into(), d.into())
}

#[test]
fn random_soups_give_the_same_hits_in_every_structure() {
    let mut rng = Rng(17);
    let mut hits = 0;
    let mut rays = 0;
    for n in [1, 5, 40, 300, 2000] {
        let data = soup(&mut rng, n);
        let meshes = every_structure(&data);
        for k in 0..3000 {
            let ray = random_ray(&mut rng, k % 3 == 0);
            let (t_min, t_max) = match k % 4 {
                0 => (0.0, f32::INFINITY),
                1 => (rng.range(0.0, 0.5), rng.range(0.5, 1.5)),
                2 => (0.0, rng.range(0.0, 1.0)),
                _ => (1e-4, f32::INFINITY),
            };
            hits += agree(&meshes, &ray, t_min, t_max, &format!("soup of {n}")) as u32;
            rays += 1;
        }
    }
    assert!(hits > rays / 4, "only {hits} of {rays} rays hit");
}

/// Rays through shared vertices and edges of a flat grid of coplanar
/// triangles: every hit has two to six candidates of exactly equal `t`,
/// and every structure must pick the lowest input index.
#[test]
fn equal_t_ties_go_to_the_lowest_input_triangle() {
    let mut data = MeshData::default();
    let n = 12;
    for j in 0..=n {
        for i in 0..=n {
            data.positions
                .push(Vec3::new(i as f32 / n as f32, 0.25, j as f32 / n as f32));
        }
    }
    // Triangles in a scrambled input order, so BVH leaf order differs.
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            tris.push([a, a + 1, a + n + 1]);
            tris.push([a + 1, a + n + 2, a + n + 1]);
        }
    }
    let mut rng = Rng(5);
    for i in (1..tris.len()).rev() {
        tris.swap(i, rng.below(i + 1));
    }
    data.indices = tris;
    let meshes = every_structure(&data);
    let mut ties = 0;
    for v in 0..data.positions.len() {
        let target = data.positions[v];
        for _ in 0..4 {
            let o = target
                + Vec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(0.5, 2.0),
                    rng.range(-1.0, 1.0),
                );
            let ray = Ray::new(o.into(), (target - o).into());
            if agree(&meshes, &ray, 0.0, f32::INFINITY, "flat grid") {
                ties += 1;
            }
        }
    }
    assert!(ties > 400, "{ties}");
}

/// Every triangle mesh of the scenes in `assets/`.
#[test]
fn asset_meshes_give_the_same_hits_in_every_structure() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
    let mut scenes = vec![
        root.join("whitted.toml"),
        root.join("quadrics.toml"),
        root.join("cornell.toml"),
        root.join("gltf/showroom.gltf"),
    ];
    for e in std::fs::read_dir(root.join("bench")).unwrap() {
        scenes.push(e.unwrap().path());
    }
    let mut meshes_seen = 0;
    for path in scenes {
        check_scene_meshes(&path, 400, &mut meshes_seen);
    }
    assert!(meshes_seen >= 5, "{meshes_seen}");
}

/// The real meshes of `../shared/samples` (skipped when absent).
#[test]
fn sample_meshes_give_the_same_hits_in_every_structure() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/samples");
    if !root.is_dir() {
        eprintln!("skipped: ../shared/samples not found");
        return;
    }
    let mut seen = 0;
    for name in [
        "Box/glTF/Box.gltf",
        "Avocado/glTF/Avocado.gltf",
        "DamagedHelmet/glTF/DamagedHelmet.gltf",
        "CornellBox/CornellBox.glb",
    ] {
        let p = root.join(name);
        if p.exists() {
            check_scene_meshes(&p, 300, &mut seen);
        } else {
            eprintln!("skipped {name}: not found");
        }
    }
    assert!(seen > 0);
}

fn check_scene_meshes(path: &Path, rays: usize, seen: &mut usize) {
    let desc = prism::io::load(path, BuildQuality::Fastest).unwrap();
    let mut rng = Rng(23);
    let mut done = std::collections::HashSet::new();
    for obj in &desc.objects {
        let prism::io::desc::Geometry::Mesh(m) = &obj.geometry else {
            continue;
        };
        if !done.insert(std::sync::Arc::as_ptr(m)) {
            continue;
        }
        let data = m.input_data();
        let meshes = every_structure(&data);
        let (lo, hi) = m.bounds().unwrap();
        let (c, r) = ((lo + hi) * 0.5, (hi - lo).length() * 0.5);
        let mut hits = 0;
        for k in 0..rays {
            // Origins around the mesh aimed at its vertices (shared edges
            // and corners) or at random points of its bounds.
            let o = c + Vec3A::from(rng.dir()) * r * rng.range(1.1, 4.0);
            let target = if k % 2 == 0 {
                m.positions()[rng.below(m.positions().len())]
            } else {
                lo + (hi - lo) * Vec3A::from(rng.vec(0.0, 1.0))
            };
            let ray = Ray::new(o, target - o);
            hits += agree(
                &meshes,
                &ray,
                0.0,
                f32::INFINITY,
                &format!("{} in {}", m.name, path.display()),
            ) as usize;
            // A secondary ray from inside the bounds.
            let o2 = lo + (hi - lo) * Vec3A::from(rng.vec(0.0, 1.0));
            agree(
                &meshes,
                &Ray::new(o2, rng.dir().into()),
                1e-4,
                f32::INFINITY,
                "inside",
            );
        }
        assert!(hits > rays / 4, "{}: {hits} of {rays}", m.name);
        *seen += 1;
    }
}

/// A mesh over the unit cube whose grid has `res` cells per axis: a
/// lattice of small triangles, one per cell, away from the cell faces.
fn lattice(res: u32) -> MeshData {
    let mut data = MeshData::default();
    let s = 1.0 / res as f32;
    for z in 0..res {
        for y in 0..res {
            for x in 0..res {
                let c = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5) * s;
                let k = data.positions.len() as u32;
                data.positions.push(c + Vec3::new(-0.3, -0.3, 0.0) * s);
                data.positions.push(c + Vec3::new(0.3, -0.3, 0.0) * s);
                data.positions.push(c + Vec3::new(0.0, 0.3, 0.0) * s);
                data.indices.push([k, k + 1, k + 2]);
            }
        }
    }
    // Corners so the bounds are exactly the unit cube.
    let k = data.positions.len() as u32;
    data.positions.extend([
        Vec3::ZERO,
        Vec3::new(1e-3, 0.0, 0.0),
        Vec3::new(0.0, 1e-3, 0.0),
    ]);
    data.positions.extend([
        Vec3::ONE,
        Vec3::new(1.0 - 1e-3, 1.0, 1.0),
        Vec3::new(1.0, 1.0 - 1e-3, 1.0),
    ]);
    data.indices.push([k, k + 1, k + 2]);
    data.indices.push([k + 3, k + 4, k + 5]);
    data
}

fn grid_mesh(data: &MeshData) -> Mesh {
    Mesh::with_accel(
        "grid",
        data.clone(),
        NormalMode::Flat,
        BuildQuality::Medium,
        Accel::Grid,
    )
    .unwrap()
}

/// Triangles that touch a cell boundary plane from both sides, and rays
/// lying exactly in that plane (and in two planes: along a cell edge).
#[test]
fn dda_ray_along_a_cell_boundary() {
    let mut data = lattice(8);
    let res = grid_mesh(&data).grid().unwrap().resolution();
    assert!(res.iter().all(|&r| r >= 8), "{res:?}");
    // Boundary y = 0.5 between cells 3 and 4 (8 cells), exactly representable.
    let yb = 0.5f32;
    for i in 0..8 {
        let x = (i as f32 + 0.5) / 8.0;
        let k = data.positions.len() as u32;
        // One triangle just below the plane, touching it; one above.
        let dy = if i % 2 == 0 { -0.02 } else { 0.02 };
        // An edge lying in the plane, the third corner off it.
        data.positions.push(Vec3::new(x, yb, 0.3));
        data.positions.push(Vec3::new(x, yb, 0.7));
        data.positions.push(Vec3::new(x, yb + dy, 0.5));
        data.indices.push([k, k + 1, k + 2]);
    }
    let meshes = every_structure(&data);
    let mut hits = 0;
    let mut rng = Rng(3);
    for _ in 0..500 {
        let z = rng.range(0.3, 0.7);
        let o = Vec3A::new(-0.5, yb, z);
        // Along x in the plane y = 0.5, tilted within the plane.
        let d = Vec3A::new(1.0, 0.0, rng.range(-0.05, 0.05));
        let h = agree(
            &meshes,
            &Ray::new(o, d),
            0.0,
            f32::INFINITY,
            "along y = 0.5",
        );
        hits += h as u32;
    }
    // Along a cell edge: y = 0.5 and z = 0.5 exactly.
    let edge = Ray::new(Vec3A::new(-0.5, 0.5, 0.5), Vec3A::X);
    assert!(agree(
        &meshes,
        &edge,
        0.0,
        f32::INFINITY,
        "along a cell edge"
    ));
    assert!(
        hits > 400,
        "{hits} of 500 rays in the boundary plane hit its triangles"
    );
}

/// Axis-aligned rays just outside the grid (missing it) and just inside
/// its bounds.
#[test]
fn dda_axis_aligned_ray_that_misses_the_grid() {
    let data = lattice(6);
    let meshes = every_structure(&data);
    for (o, d) in [
        (Vec3A::new(-1.0, 1.01, 0.5), Vec3A::X),
        (Vec3A::new(0.5, -1.0, -0.01), Vec3A::Y),
        (Vec3A::new(0.5, 2.0, 1.5), -Vec3A::Y),
        (Vec3A::new(2.0, 0.5, 0.5), Vec3A::X),
        (Vec3A::new(-2.0, 0.5, 0.5), -Vec3A::X),
    ] {
        assert!(
            !agree(&meshes, &Ray::new(o, d), 0.0, f32::INFINITY, "missing ray"),
            "{o} {d}"
        );
    }
    // Through a row of lattice triangles: hits.
    let s = 1.0 / 6.0;
    let o = Vec3A::new(0.5 * s, 0.5 * s, -1.0);
    assert!(agree(
        &meshes,
        &Ray::new(o, Vec3A::Z),
        0.0,
        f32::INFINITY,
        "axis ray through a row"
    ));
}

/// Rays starting inside the grid, in every direction.
#[test]
fn dda_ray_starting_inside_the_grid() {
    let data = lattice(7);
    let meshes = every_structure(&data);
    let mut rng = Rng(9);
    let mut hits = 0;
    for _ in 0..2000 {
        let o = Vec3A::from(rng.vec(0.0, 1.0));
        let d = Vec3A::from(rng.dir());
        hits += agree(&meshes, &Ray::new(o, d), 0.0, f32::INFINITY, "from inside") as u32;
    }
    assert!(hits > 200, "{hits}");
}

/// Direction components of `-0.0` and `+0.0` give the same hits, found
/// after walking through empty cells (only the far layer of the lattice
/// is kept).
#[test]
fn dda_negative_zero_direction_components() {
    let mut data = lattice(5);
    let far: Vec<[u32; 3]> = data
        .indices
        .iter()
        .copied()
        .filter(|t| data.positions[t[0] as usize].z > 0.8 || data.positions[t[0] as usize].z == 0.0)
        .collect();
    data.indices = far;
    let meshes = every_structure(&data);
    assert!(meshes[2].grid().unwrap().resolution()[2] >= 5);
    let s = 1.0 / 5.0;
    let mut hits = 0;
    for i in 0..5 {
        for j in 0..5 {
            let o = Vec3A::new((i as f32 + 0.5) * s, (j as f32 + 0.45) * s, -0.5);
            for d in [
                Vec3A::new(0.0, 0.0, 1.0),
                Vec3A::new(-0.0, 0.0, 1.0),
                Vec3A::new(0.0, -0.0, 1.0),
                Vec3A::new(-0.0, -0.0, 1.0),
            ] {
                hits += agree(&meshes, &Ray::new(o, d), 0.0, f32::INFINITY, "signed zeros") as u32;
            }
            let a =
                meshes[2].intersect(&Ray::new(o, Vec3A::new(0.0, 0.0, 1.0)), 0.0, f32::INFINITY);
            let b = meshes[2].intersect(
                &Ray::new(o, Vec3A::new(-0.0, -0.0, 1.0)),
                0.0,
                f32::INFINITY,
            );
            assert_eq!(key(&meshes[2], a), key(&meshes[2], b));
        }
    }
    assert_eq!(hits, 100);
}

/// A large slanted triangle listed in the first cell the ray enters is
/// hit far along the ray, in a later cell; a small triangle in between
/// is nearer. The walk must not stop at the first hit found.
#[test]
fn dda_closest_hit_in_a_later_cell_than_the_first_found() {
    let mut data = lattice(8);
    let k = data.positions.len() as u32;
    // Big: spans the grid, crossed by the ray near x = 0.9.
    data.positions.extend([
        Vec3::new(0.9, -0.1, -0.1),
        Vec3::new(0.9, 1.1, -0.1),
        Vec3::new(0.0, 0.5, 1.1),
    ]);
    // Small: facing the ray at x = 0.5.
    data.positions.extend([
        Vec3::new(0.5, 0.46, -0.05),
        Vec3::new(0.5, 0.54, -0.05),
        Vec3::new(0.5, 0.5, 0.05),
    ]);
    data.indices.push([k, k + 1, k + 2]);
    data.indices.push([k + 3, k + 4, k + 5]);
    let mesh = grid_mesh(&data);
    let ray = Ray::new(Vec3A::new(0.01, 0.5, 0.0), Vec3A::new(1.0, 0.0, 0.0));
    let h = mesh.intersect(&ray, 0.0, f32::INFINITY).expect("a hit");
    assert_eq!(
        mesh.input_triangle(h.triangle as usize),
        data.indices.len() as u32 - 1,
        "{h:?}"
    );
    assert!((h.t - 0.49).abs() < 1e-5, "{h:?}");
    // The big one is hit beyond: without the small one it is found.
    let mut without = data.clone();
    without.indices.pop();
    let mesh = grid_mesh(&without);
    let far = mesh
        .intersect(&ray, 0.0, f32::INFINITY)
        .expect("the big triangle");
    assert!(far.t > 0.6, "{far:?}");
    let meshes = every_structure(&data);
    assert!(agree(&meshes, &ray, 0.0, f32::INFINITY, "later cell"));
}

/// A flat sheet whose shared edges lie on the grid's cell boundaries,
/// seen from 10^5 away: the watertight test's rounding of `vertex -
/// origin` (several 1e-3 here, from origins 5e4 away along x and y) gives rays that pass just left of an edge to
/// the triangle on its right, whose cells start at that boundary. The
/// walk must visit the neighbour cells within the margin to find it, as
/// the BVH's padded boxes do.
#[test]
fn dda_far_rays_across_edges_on_cell_boundaries() {
    let m = 54u32;
    let mut data = MeshData::default();
    for j in 0..=m {
        for i in 0..=m {
            data.positions
                .push(Vec3::new(i as f32 / m as f32, j as f32 / m as f32, 0.0));
        }
    }
    for j in 0..m {
        for i in 0..m {
            let a = j * (m + 1) + i;
            data.indices.push([a, a + 1, a + m + 1]);
            data.indices.push([a + 1, a + m + 2, a + m + 1]);
        }
    }
    // Two specks give the grid a depth of 1 (54 thin layers of cells).
    let k = data.positions.len() as u32;
    for z in [-0.5, 0.5] {
        data.positions.extend([
            Vec3::new(0.5, 0.5, z),
            Vec3::new(0.5001, 0.5, z),
            Vec3::new(0.5, 0.5001, z),
        ]);
    }
    data.indices
        .extend([[k, k + 1, k + 2], [k + 3, k + 4, k + 5]]);
    let meshes = every_structure(&data);
    assert_eq!(meshes[2].grid().unwrap().resolution(), [m, m, m]);
    let mut rng = Rng(31);
    let mut hits = 0;
    for _ in 0..4000 {
        let i = 1 + rng.below(m as usize - 1);
        let x = i as f32 / m as f32 + rng.range(-1e-2, 1e-2);
        let target = Vec3::new(x, rng.range(0.05, 0.95), 0.0);
        let o = target + Vec3::new(rng.range(-5e4, 5e4), rng.range(-5e4, 5e4), 1e5);
        hits += agree(
            &meshes,
            &Ray::new(o.into(), (target - o).into()),
            0.0,
            f32::INFINITY,
            "far sheet",
        ) as u32;
    }
    assert!(hits > 3900, "{hits}");
}
