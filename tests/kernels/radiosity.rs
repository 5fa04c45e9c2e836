//! Radiosity kernels against closed forms: form factors of unit squares
//! (facing and perpendicular), row sums of a closed room, reciprocity,
//! the furnace inside a closed polyhedron, two parallel plates, and the
//! iterative solvers against a dense solve.

use glam::{DVec3, Vec3A};
use prism::core::math::Color;
use prism::radiosity::patches::{BaseTriangle, Patches};
use prism::radiosity::{
    FormFactorMethod, FormFactors, RadiositySettings, Solver, System, base_mesh, form_factor,
    solve_triangles,
};

/// Two triangles of the quad `a b c d` (counter-clockwise seen from the
/// side its normal points to), in group `g`.
fn quad(out: &mut Vec<BaseTriangle>, groups: &mut Vec<u32>, q: [Vec3A; 4], g: u32) {
    for tri in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
        out.push(BaseTriangle {
            corners: tri,
            normal: n,
            instance: g,
            material: 0,
            surfaces: [None, None],
        });
        groups.push(g);
    }
}

fn v(x: f32, y: f32, z: f32) -> Vec3A {
    Vec3A::new(x, y, z)
}

/// Patches and form factors of `bases` (reflectance 0.5, no emission).
fn patches_and_ff(
    bases: Vec<BaseTriangle>,
    groups: &[u32],
    patch_size: f32,
    method: FormFactorMethod,
) -> (Patches, FormFactors) {
    let mut lo = Vec3A::splat(f32::INFINITY);
    let mut hi = Vec3A::splat(f32::NEG_INFINITY);
    for b in &bases {
        for c in b.corners {
            lo = lo.min(c);
            hi = hi.max(c);
        }
    }
    let mesh = base_mesh(&bases).unwrap();
    let shading = vec![(Color::splat(0.5), Color::ZERO); bases.len()];
    let p = Patches::build(bases, groups, patch_size, (lo, hi), &shading, 100_000).unwrap();
    let ff = form_factor::compute(&p, &mesh, method, &|_| {});
    (p, ff)
}

/// Area-weighted form factor from the patches of instance `from` to those
/// of instance `to`.
fn between(p: &Patches, ff: &FormFactors, from: u32, to: u32) -> f64 {
    let inst = |q: usize| p.bases[p.surfaces[p.surface[q] as usize].base as usize].instance;
    let (mut num, mut area) = (0.0f64, 0.0f64);
    for i in 0..p.len() {
        if inst(i) != from {
            continue;
        }
        area += p.area[i] as f64;
        for (j, f) in ff.row(i) {
            if inst(j) == to {
                num += p.area[i] as f64 * f as f64;
            }
        }
    }
    num / area
}

/// Unit square at y = 0 facing up (instance 0) and a second unit square
/// (instance 1): facing it at y = 1, or standing on their shared edge
/// x = 0 facing +x.
fn two_squares(facing: bool) -> (Vec<BaseTriangle>, Vec<u32>) {
    let (mut b, mut g) = (Vec::new(), Vec::new());
    quad(
        &mut b,
        &mut g,
        [v(0., 0., 0.), v(0., 0., 1.), v(1., 0., 1.), v(1., 0., 0.)],
        0,
    );
    let second = if facing {
        [v(0., 1., 0.), v(1., 1., 0.), v(1., 1., 1.), v(0., 1., 1.)]
    } else {
        [v(0., 0., 0.), v(0., 1., 0.), v(0., 1., 1.), v(0., 0., 1.)]
    };
    quad(&mut b, &mut g, second, 1);
    (b, g)
}

/// Howell's catalogue: parallel unit squares at distance 1 exchange
/// F = 0.199825; perpendicular unit squares sharing an edge F = 0.200044.
const FACING: f64 = 0.199825;
const PERPENDICULAR: f64 = 0.200044;

#[test]
fn unit_squares_match_the_closed_forms_with_the_ray_cast_estimator() {
    let level = RadiositySettings::default().raycast_level;
    for (facing, exact) in [(true, FACING), (false, PERPENDICULAR)] {
        let (b, g) = two_squares(facing);
        let (p, ff) = patches_and_ff(b, &g, 0.25, FormFactorMethod::Raycast { level });
        let f01 = between(&p, &ff, 0, 1);
        let f10 = between(&p, &ff, 1, 0);
        eprintln!("facing {facing}: F = {f01:.6} (and {f10:.6} back), exact {exact}");
        assert!(
            (f01 - exact).abs() < 1e-3,
            "facing {facing}: F = {f01}, want {exact}"
        );
        // Equal areas: reciprocity makes the two directions equal.
        assert!((f01 - f10).abs() < 1e-6, "{f01} vs {f10}");
    }
}

#[test]
fn hemicube_form_factors_converge_with_resolution() {
    for (facing, exact) in [(true, FACING), (false, PERPENDICULAR)] {
        let errors: Vec<f64> = [4, 16, 64]
            .iter()
            .map(|&resolution| {
                let (b, g) = two_squares(facing);
                let (p, ff) =
                    patches_and_ff(b, &g, 0.125, FormFactorMethod::Hemicube { resolution });
                (between(&p, &ff, 0, 1) - exact).abs()
            })
            .collect();
        eprintln!("facing {facing}: hemicube errors at 4, 16, 64 pixels: {errors:?}");
        assert!(errors[2] < errors[0], "{errors:?}");
        assert!(errors[2] < 3e-3, "{errors:?}");
    }
}

/// A closed box `w x h x d` with its faces' normals pointing inwards.
fn closed_box(w: f32, h: f32, d: f32) -> (Vec<BaseTriangle>, Vec<u32>) {
    let (mut b, mut g) = (Vec::new(), Vec::new());
    let faces = [
        [v(0., 0., 0.), v(0., 0., d), v(w, 0., d), v(w, 0., 0.)], // floor, up
        [v(0., h, 0.), v(w, h, 0.), v(w, h, d), v(0., h, d)],     // ceiling, down
        [v(0., 0., 0.), v(w, 0., 0.), v(w, h, 0.), v(0., h, 0.)], // z = 0, +z
        [v(0., 0., d), v(0., h, d), v(w, h, d), v(w, 0., d)],     // z = d, -z
        [v(0., 0., 0.), v(0., h, 0.), v(0., h, d), v(0., 0., d)], // x = 0, +x
        [v(w, 0., 0.), v(w, 0., d), v(w, h, d), v(w, h, 0.)],     // x = w, -x
    ];
    for (k, f) in faces.into_iter().enumerate() {
        quad(&mut b, &mut g, f, k as u32);
    }
    (b, g)
}

#[test]
fn rows_of_a_closed_room_sum_to_one_and_are_reciprocal() {
    for method in [
        FormFactorMethod::Raycast { level: 1 },
        FormFactorMethod::Hemicube { resolution: 64 },
    ] {
        let (b, g) = closed_box(2.0, 1.5, 1.0);
        let (p, ff) = patches_and_ff(b, &g, 0.5, method);
        assert!(p.len() > 50, "{} patches", p.len());
        let tolerance = match method {
            FormFactorMethod::Raycast { .. } => 1e-3,
            // Pixel-centre sampling of the hemicube.
            FormFactorMethod::Hemicube { .. } => 5e-3,
        };
        let mut worst = 0.0f64;
        for i in 0..p.len() {
            let sum: f64 = ff.row(i).map(|(_, f)| f as f64).sum();
            worst = worst.max((sum - 1.0).abs());
        }
        eprintln!("{method:?}: worst row sum error {worst:e}");
        assert!(worst < tolerance, "{method:?}: row sum off by {worst}");
        if matches!(method, FormFactorMethod::Hemicube { .. }) {
            // Hemicube rows are kept as measured (see form_factor's docs).
            continue;
        }
        for i in 0..p.len() {
            for (j, f) in ff.row(i) {
                let a = p.area[i] as f64 * f as f64;
                let b = p.area[j] as f64 * ff.get(j, i) as f64;
                assert!(
                    (a - b).abs() <= 1e-6 * a.max(b),
                    "A_i F_ij {a} vs A_j F_ji {b}"
                );
            }
        }
    }
}

/// An icosahedron subdivided `levels` times and pushed onto the unit
/// sphere, its triangles wound to face the centre.
fn inward_sphere(levels: u32) -> Vec<[Vec3A; 3]> {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let p = [
        v(-1., t, 0.),
        v(1., t, 0.),
        v(-1., -t, 0.),
        v(1., -t, 0.),
        v(0., -1., t),
        v(0., 1., t),
        v(0., -1., -t),
        v(0., 1., -t),
        v(t, 0., -1.),
        v(t, 0., 1.),
        v(-t, 0., -1.),
        v(-t, 0., 1.),
    ]
    .map(|q| q.normalize());
    let idx = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut tris: Vec<[Vec3A; 3]> = idx.iter().map(|&[a, b, c]| [p[a], p[b], p[c]]).collect();
    for _ in 0..levels {
        tris = tris
            .into_iter()
            .flat_map(|[a, b, c]| {
                let (ab, bc, ca) = (
                    ((a + b) * 0.5).normalize(),
                    ((b + c) * 0.5).normalize(),
                    ((c + a) * 0.5).normalize(),
                );
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    // The icosahedron's winding faces outwards: reverse it.
    tris.into_iter().map(|[a, b, c]| [a, c, b]).collect()
}

fn bases_of(tris: &[[Vec3A; 3]]) -> (Vec<BaseTriangle>, Vec<u32>) {
    let bases = tris
        .iter()
        .map(|&t| BaseTriangle {
            corners: t,
            normal: (t[1] - t[0]).cross(t[2] - t[0]).normalize(),
            instance: 0,
            material: 0,
            surfaces: [None, None],
        })
        .collect::<Vec<_>>();
    let groups = (0..tris.len() as u32).collect();
    (bases, groups)
}

#[test]
fn furnace_inside_a_closed_sphere_gives_e_over_one_minus_rho() {
    let tris = inward_sphere(1);
    assert!(tris.iter().all(|t| {
        let n = (t[1] - t[0]).cross(t[2] - t[0]);
        n.dot(t[0]) < 0.0
    }));
    let (bases, groups) = bases_of(&tris);
    // Each face split once: 320 patches inside (and 320 outside, which
    // see nothing).
    let (p, ff) = patches_and_ff(bases, &groups, 0.4, FormFactorMethod::Raycast { level: 1 });
    let inner: Vec<usize> = (0..p.len())
        .filter(|&q| p.surfaces[p.surface[q] as usize].side == 0)
        .collect();
    assert_eq!(inner.len(), 320);
    let sums: Vec<f64> = inner
        .iter()
        .map(|&i| ff.row(i).map(|(_, f)| f as f64).sum::<f64>())
        .collect();
    eprintln!(
        "row sums inside the sphere: {:?} .. {:?}",
        sums.iter().copied().fold(f64::INFINITY, f64::min),
        sums.iter().copied().fold(0.0, f64::max)
    );
    let e_value = 1.0;
    let e = vec![Color::splat(e_value); p.len()];
    for rho in [0.5f32, 0.8, 0.9] {
        let rhos = vec![Color::splat(rho); p.len()];
        let system = System {
            ff: &ff,
            rho: &rhos,
            e: &e,
            area: &p.area,
        };
        let exact = e_value / (1.0 - rho);
        for (name, (b, report)) in [
            ("progressive", system.progressive(1e-6, 10_000_000)),
            ("gauss-seidel", system.gauss_seidel(1e-6, 100_000)),
        ] {
            assert!(report.converged, "{name}: {report:?}");
            let worst = inner
                .iter()
                .map(|&q| ((b[q].x - exact) / exact).abs())
                .fold(0.0, f32::max);
            eprintln!("rho {rho}, {name}: worst relative error {worst:e}");
            assert!(worst < 5e-3, "{name} rho {rho}: off by {worst} relative");
        }
    }
}

#[test]
fn parallel_plates_exchange_as_infinite_plates_do() {
    // Infinite plates see only each other (F = 1): B1 = E1 + rho B2,
    // B2 = rho B1, so B1 = 1 / (1 - 1/4) = 4/3 and B2 = 2/3. Plates 200
    // wide at a gap of 1 are infinite for their middle patches.
    let half = 100.0;
    let (mut b, mut g) = (Vec::new(), Vec::new());
    quad(
        &mut b,
        &mut g,
        [
            v(-half, 0., -half),
            v(-half, 0., half),
            v(half, 0., half),
            v(half, 0., -half),
        ],
        0,
    );
    quad(
        &mut b,
        &mut g,
        [
            v(-half, 1., -half),
            v(half, 1., -half),
            v(half, 1., half),
            v(-half, 1., half),
        ],
        1,
    );
    let shading = vec![
        (Color::splat(0.5), Color::ONE),
        (Color::splat(0.5), Color::ONE),
        (Color::splat(0.5), Color::ZERO),
        (Color::splat(0.5), Color::ZERO),
    ];
    let settings = RadiositySettings {
        patch_size: Some(12.5),
        solver: Solver::GaussSeidel,
        tolerance: 1e-6,
        refine_levels: 0,
        ..Default::default()
    };
    let sol = solve_triangles(b, &g, &shading, DVec3::ZERO, &settings, None).unwrap();
    let mut checked = 0;
    for p in 0..sol.patches.len() {
        let c = sol.patches.corners(p);
        let mid = (c[0] + c[1] + c[2]) / 3.0;
        if mid.x.abs() > 25.0 || mid.z.abs() > 25.0 {
            continue;
        }
        let want = if mid.y < 0.5 { 4.0 / 3.0 } else { 2.0 / 3.0 };
        let got = sol.radiosity[p].x;
        assert!(
            (got - want).abs() / want < 5e-3,
            "patch at {mid}: B = {got}, want {want}"
        );
        checked += 1;
    }
    assert!(checked >= 16, "{checked}");
}

/// A closed box with a block standing in it, lit by an emissive ceiling.
fn small_room() -> (Vec<BaseTriangle>, Vec<u32>, Vec<(Color, Color)>) {
    let (mut b, mut g) = closed_box(2.0, 1.5, 1.0);
    // A block 0.5 x 0.5 x 0.5 on the floor, outward normals.
    let (x0, x1, z0, z1, y1) = (0.5f32, 1.0, 0.25, 0.75, 0.5);
    let faces = [
        [v(x0, y1, z0), v(x0, y1, z1), v(x1, y1, z1), v(x1, y1, z0)],
        [v(x0, 0., z0), v(x1, 0., z0), v(x1, y1, z0), v(x0, y1, z0)],
        [v(x0, 0., z1), v(x0, y1, z1), v(x1, y1, z1), v(x1, 0., z1)],
        [v(x0, 0., z0), v(x0, y1, z0), v(x0, y1, z1), v(x0, 0., z1)],
        [v(x1, 0., z0), v(x1, 0., z1), v(x1, y1, z1), v(x1, y1, z0)],
    ];
    for (k, f) in faces.into_iter().enumerate() {
        let mut q = f;
        // Outward: flip those wound inwards (normal towards the centre).
        let c = (q[0] + q[1] + q[2] + q[3]) / 4.0;
        let n = (q[1] - q[0]).cross(q[2] - q[0]);
        if n.dot(c - v(0.75, 0.25, 0.5)) < 0.0 {
            q.reverse();
        }
        quad(&mut b, &mut g, q, 6 + k as u32);
    }
    let shading = b
        .iter()
        .map(|t| {
            let ceiling = t.corners.iter().all(|c| c.y == 1.5);
            let red = t.corners.iter().all(|c| c.x == 0.0);
            match (ceiling, red) {
                (true, _) => (Color::splat(0.7), Color::splat(5.0)),
                (_, true) => (Color::new(0.6, 0.1, 0.1), Color::ZERO),
                _ => (Color::splat(0.7), Color::ZERO),
            }
        })
        .collect();
    (b, g, shading)
}

#[test]
fn progressive_refinement_and_gauss_seidel_reach_the_dense_solution() {
    let (b, g, shading) = small_room();
    let mut lo = Vec3A::splat(f32::INFINITY);
    let mut hi = Vec3A::splat(f32::NEG_INFINITY);
    for t in &b {
        for c in t.corners {
            lo = lo.min(c);
            hi = hi.max(c);
        }
    }
    let mesh = base_mesh(&b).unwrap();
    let p = Patches::build(b, &g, 0.5, (lo, hi), &shading, 10_000).unwrap();
    let ff = form_factor::compute(&p, &mesh, FormFactorMethod::Raycast { level: 1 }, &|_| {});
    let rho: Vec<Color> = (0..p.len()).map(|i| p.reflectance(i)).collect();
    let e: Vec<Color> = (0..p.len()).map(|i| p.exitance(i)).collect();
    let system = System {
        ff: &ff,
        rho: &rho,
        e: &e,
        area: &p.area,
    };
    let dense = system.dense();
    let scale = dense.iter().map(|c| c.max_element()).fold(0.0, f32::max);
    for (name, (b, report)) in [
        ("progressive", system.progressive(1e-6, 10_000_000)),
        ("gauss-seidel", system.gauss_seidel(1e-6, 100_000)),
    ] {
        assert!(
            report.converged && report.residual < 1e-6,
            "{name}: {report:?}"
        );
        let worst = b
            .iter()
            .zip(&dense)
            .map(|(x, y)| (*x - *y).abs().max_element())
            .fold(0.0, f32::max);
        eprintln!("{name}: {report:?}, largest difference from dense {worst:e} (scale {scale})");
        assert!(worst < 1e-4 * scale, "{name}: {worst} off the dense solve");
    }
}

#[test]
fn the_solution_does_not_depend_on_the_thread_count() {
    let solve = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (b, g, shading) = small_room();
            let settings = RadiositySettings {
                patch_size: Some(0.5),
                refine_levels: 1,
                ..Default::default()
            };
            let s = solve_triangles(b, &g, &shading, DVec3::ZERO, &settings, None).unwrap();
            s.radiosity
                .iter()
                .flat_map(|c| c.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        })
    };
    assert_eq!(solve(1), solve(2));
}

#[test]
fn the_patch_size_sets_how_finely_surfaces_are_cut() {
    // A 2 x 2 x 2 box: 12 triangles of area 2, split until a patch's area
    // is at most s^2 / 2, so into 4^d with 2 / 4^d <= s^2 / 2.
    for (s, depth) in [(2.0f32, 0u32), (1.0, 1), (0.5, 2), (0.3, 3)] {
        let (b, g) = closed_box(2.0, 2.0, 2.0);
        let shading = vec![(Color::splat(0.5), Color::ZERO); b.len()];
        let bounds = (Vec3A::ZERO, Vec3A::splat(2.0));
        let p = Patches::build(b, &g, s, bounds, &shading, 100_000).unwrap();
        assert_eq!(p.len(), 12 << (2 * depth), "patch size {s}");
        let largest = p.area.iter().copied().fold(0.0, f32::max);
        assert!(
            largest <= 0.5 * s * s * (1.0 + 1e-5),
            "patch size {s}: area {largest}"
        );
        // Only the inside of the box is a surface.
        assert!((0..p.len()).all(|q| p.surfaces[p.surface[q] as usize].side == 0));
    }
}

#[test]
fn adaptive_subdivision_splits_patches_where_radiosity_changes_fast() {
    // The small room lit by its ceiling: radiosity changes fastest on the
    // floor around the block (its contact shadow) and in the room's
    // corners; the open middle of the floor is smooth.
    let (b, g, shading) = small_room();
    let settings = RadiositySettings {
        patch_size: Some(0.25),
        refine_levels: 1,
        ..Default::default()
    };
    let sol = solve_triangles(b, &g, &shading, DVec3::ZERO, &settings, None).unwrap();
    assert_eq!(sol.stats.passes, 2, "{:?}", sol.stats);
    assert!(sol.stats.refined > 0, "{:?}", sol.stats);
    let p = &sol.patches;
    // The floor's triangles (area 1) are cut into 64 by the patch size;
    // a refined patch is a quarter of that.
    let full = 1.0 / 64.0;
    // Floor patches (y = 0, facing up): split ones within 0.25 of the
    // block, along the walls (the room's corners), and in the open.
    let (mut near, mut walls, mut open) = (0, 0, 0);
    let mut open_area = 0.0f32;
    for q in 0..p.len() {
        let c = p.corners(q);
        if !(c.iter().all(|x| x.y == 0.0) && p.normal(q).y > 0.5) {
            continue;
        }
        let m = (c[0] + c[1] + c[2]) / 3.0;
        // Distance to the block's footprint [0.5, 1] x [0.25, 0.75].
        let dx = (0.5 - m.x).max(m.x - 1.0).max(0.0);
        let dz = (0.25 - m.z).max(m.z - 0.75).max(0.0);
        let by_block = (dx * dx + dz * dz).sqrt() < 0.25;
        let by_wall = m.x.min(2.0 - m.x).min(m.z).min(1.0 - m.z) < 0.25;
        let split = p.area[q] < 0.5 * full;
        if !by_block && !by_wall {
            open_area += p.area[q];
        }
        if split {
            match (by_block, by_wall) {
                (true, _) => near += 1,
                (false, true) => walls += 1,
                (false, false) => open += 1,
            }
        }
    }
    eprintln!(
        "floor patches from splits: {near} by the block, {walls} along the walls, {open} in the \
         open (area {open_area:.3}); {:?}",
        sol.stats
    );
    assert!(near >= 16, "{near} patches from splits around the block");
    assert!(
        open_area > 0.2 && open == 0,
        "{open} split in the open middle of the floor"
    );
}
