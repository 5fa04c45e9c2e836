//! BVH traversal against brute force: the top-level BVH over instances and
//! every mesh's triangle BVH must return exactly the closest hit that
//! testing every primitive finds, and shadow queries must agree with it.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Quat, Vec3, Vec3A};
use prism::core::math::Ray;
use prism::geometry::mesh::{BuildQuality, Mesh, MeshData, NormalMode};
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::scene::material::Material;
use prism::scene::{Instance, InstanceGeometry, RenderScene};

use crate::common::rng::{Random, SamplerRng as Rng};

/// A triangle soup of `n` random triangles in the unit cube.
fn soup(rng: &mut Rng, n: usize) -> Mesh {
    let mut data = MeshData::default();
    for i in 0..n {
        let c = rng.vec(-1.0, 1.0);
        for _ in 0..3 {
            data.positions.push(c + rng.vec(-0.2, 0.2));
        }
        let k = 3 * i as u32;
        data.indices.push([k, k + 1, k + 2]);
    }
    Mesh::new("soup", data, NormalMode::Flat, BuildQuality::Medium).unwrap()
}

/// A closed UV sphere mesh with shared vertices.
fn uv_sphere(seg: u32, rings: u32) -> Mesh {
    let mut data = MeshData::default();
    for j in 0..=rings {
        let th = PI * j as f32 / rings as f32;
        for i in 0..=seg {
            let ph = 2.0 * PI * i as f32 / seg as f32;
            data.positions.push(Vec3::new(
                th.sin() * ph.cos(),
                th.cos(),
                th.sin() * ph.sin(),
            ));
        }
    }
    for j in 0..rings {
        for i in 0..seg {
            let a = j * (seg + 1) + i;
            let b = a + seg + 1;
            data.indices.push([a, a + 1, b]);
            data.indices.push([a + 1, b + 1, b]);
        }
    }
    Mesh::new("sphere", data, NormalMode::Smooth, BuildQuality::Fast).unwrap()
}

fn all_shapes() -> Vec<Shape> {
    vec![
        Shape::Sphere { radius: 0.7 },
        Shape::Disk { radius: 0.8 },
        Shape::Polygon {
            vertices: Arc::from(vec![
                Vec3::new(-0.5, 0.0, -0.5),
                Vec3::new(-0.5, 0.0, 0.5),
                Vec3::new(0.6, 0.0, 0.4),
                Vec3::new(0.5, 0.0, -0.5),
            ]),
        },
        Shape::Cylinder {
            radius: 0.4,
            y_min: -0.5,
            y_max: 0.6,
        },
        Shape::Cone {
            radius: 0.5,
            height: 1.0,
        },
        Shape::Ellipsoid {
            radii: Vec3::new(0.8, 0.4, 0.3),
        },
        Shape::Paraboloid {
            radius: 0.5,
            height: 0.8,
        },
        Shape::Hyperboloid {
            waist_radius: 0.3,
            top_radius: 0.6,
            half_height: 0.5,
        },
    ]
}

fn random_transform(rng: &mut Rng, spread: f32) -> Transform {
    let axis = rng.dir();
    let angle = rng.range(0.0, 2.0 * PI);
    let scale = Vec3::new(
        rng.range(0.3, 2.0),
        rng.range(0.3, 2.0),
        rng.range(0.3, 2.0),
    );
    Transform::from_trs_f32(
        rng.vec(-spread, spread),
        Quat::from_axis_angle(axis, angle),
        scale,
    )
}

pub(crate) fn random_scene(rng: &mut Rng, with_plane: bool) -> RenderScene {
    let mut instances = Vec::new();
    let meshes = [Arc::new(soup(rng, 300)), Arc::new(uv_sphere(24, 12))];
    for k in 0..60 {
        let geometry = if k % 4 == 0 {
            InstanceGeometry::Mesh(meshes[(k / 4) % 2].clone())
        } else {
            let shapes = all_shapes();
            InstanceGeometry::Shape(shapes[k % shapes.len()].clone())
        };
        instances.push(Instance::new(geometry, &random_transform(rng, 6.0), 0));
    }
    if with_plane {
        instances.push(Instance::new(
            InstanceGeometry::Shape(Shape::Plane),
            &Transform::from_translation(glam::DVec3::new(0.0, -7.0, 0.0)),
            0,
        ));
    }
    RenderScene::new(
        instances,
        vec![Material::default()],
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    )
}

/// Sixteen mesh instances, each with a mesh of its own (triangle soups
/// and spheres, as [`random_scene`] places its meshes), and the plane
/// below them: `(instances, materials)`. Every bounded instance can be
/// merged.
fn merge_candidates(rng: &mut Rng, with_plane: bool) -> (Vec<Instance>, Vec<Material>) {
    let mut instances = Vec::new();
    for k in 0..MERGEABLE {
        let mesh = if k % 2 == 0 {
            soup(rng, 300)
        } else {
            uv_sphere(24, 12)
        };
        instances.push(Instance::new(
            InstanceGeometry::Mesh(Arc::new(mesh)),
            &random_transform(rng, 6.0),
            0,
        ));
    }
    if with_plane {
        instances.push(Instance::new(
            InstanceGeometry::Shape(Shape::Plane),
            &Transform::from_translation(glam::DVec3::new(0.0, -7.0, 0.0)),
            0,
        ));
    }
    (instances, vec![Material::default()])
}

/// Instances of [`merge_candidates`].
const MERGEABLE: usize = 16;

/// [`merge_candidates`] as a scene with its single-use mesh instances
/// merged under one BVH ([`RenderScene::set_mesh_merging`]).
pub(crate) fn merged_scene(rng: &mut Rng, with_plane: bool) -> RenderScene {
    let (instances, materials) = merge_candidates(rng, with_plane);
    let mut scene = RenderScene::new(
        instances,
        materials,
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    scene.set_mesh_merging(true);
    scene.commit();
    assert_eq!(scene.merged_instances(), MERGEABLE);
    scene
}

/// `2 n` rays: in turn, one from outside (on a sphere of radius 15)
/// towards a random point of the middle, and one from anywhere inside in
/// a random direction.
fn mixed_rays(rng: &mut Rng, n: usize) -> Vec<Ray> {
    let mut rays = Vec::with_capacity(2 * n);
    for _ in 0..n {
        let o = rng.dir() * 15.0;
        let target = rng.vec(-6.0, 6.0);
        rays.push(Ray::new(o.into(), (target - o).normalize().into()));
        rays.push(Ray::new(rng.vec(-7.0, 7.0).into(), rng.dir().into()));
    }
    rays
}

/// What single rays answer for one packet's `rays`: each ray's closest
/// hit (its `Debug` text, so every bit counts), the ends of segments
/// along the rays, each at a random fraction (0.3 to 1.7) of the ray's
/// first hit or of `miss` for a ray that hits nothing (so about as many
/// are blocked as are not), and the mask of the segments blocked.
fn single_ray_answers(
    scene: &RenderScene,
    rays: &[Ray],
    rng: &mut Rng,
    miss: f32,
) -> (Vec<String>, Vec<f32>, u32) {
    let hits: Vec<_> = rays
        .iter()
        .map(|r| scene.intersect(r, 0.0, f32::INFINITY))
        .collect();
    let ends: Vec<f32> = hits
        .iter()
        .map(|h| {
            let f = 0.3 + 1.4 * rng.f32();
            h.map_or(miss * f, |h| h.t * f)
        })
        .collect();
    let blocked = (0..rays.len())
        .filter(|&l| scene.occluded(&rays[l], 0.0, ends[l]))
        .fold(0, |m, l| m | 1 << l);
    (
        hits.iter().map(|h| format!("{h:?}")).collect(),
        ends,
        blocked,
    )
}

fn check_rays(scene: &RenderScene, rays: &[Ray]) -> usize {
    let mut hits = 0;
    for (i, ray) in rays.iter().enumerate() {
        let bvh = scene.intersect(ray, 0.0, f32::INFINITY);
        let brute = scene.intersect_brute_force(ray, 0.0, f32::INFINITY);
        match (bvh, brute) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                hits += 1;
                // The same kernels run on the same floats: the distances are
                // identical; the instance may differ only on an exact tie.
                assert_eq!(a.t, b.t, "ray {i} {ray:?}");
                if a.instance != b.instance {
                    assert_eq!(a.t, b.t);
                } else {
                    assert_eq!(a, b, "ray {i}");
                }
            }
            (a, b) => panic!("ray {i} {ray:?}: bvh {a:?} brute force {b:?}"),
        }
        let occluded = scene.occluded(ray, 0.0, f32::INFINITY);
        assert_eq!(occluded, brute.is_some(), "shadow query of ray {i} {ray:?}");
        if let Some(b) = brute {
            // A segment ending just before the closest hit is unoccluded.
            assert!(
                !scene.occluded(ray, 0.0, b.t * 0.999),
                "segment before the hit of ray {i}"
            );
        }
    }
    hits
}

#[test]
fn closest_hits_equal_brute_force_on_random_rays() {
    closest_hits_equal_brute_force_on_random_rays_with(random_scene);
}

/// [`closest_hits_equal_brute_force_on_random_rays`] on a scene whose single-use mesh instances are merged.
#[test]
fn closest_hits_equal_brute_force_on_random_rays_merged() {
    closest_hits_equal_brute_force_on_random_rays_with(merged_scene);
}

fn closest_hits_equal_brute_force_on_random_rays_with(make: fn(&mut Rng, bool) -> RenderScene) {
    let mut rng = Rng::new(42);
    let scene = make(&mut rng, true);
    let rays = mixed_rays(&mut rng, 4000);
    let hits = check_rays(&scene, &rays);
    assert!(hits > 2000, "only {hits} hits: the test would prove little");
}

#[test]
fn axis_aligned_rays_with_signed_zeros() {
    axis_aligned_rays_with_signed_zeros_with(random_scene);
}

/// [`axis_aligned_rays_with_signed_zeros`] on a scene whose single-use mesh instances are merged.
#[test]
fn axis_aligned_rays_with_signed_zeros_merged() {
    axis_aligned_rays_with_signed_zeros_with(merged_scene);
}

fn axis_aligned_rays_with_signed_zeros_with(make: fn(&mut Rng, bool) -> RenderScene) {
    // Directions with exact (and negative) zero components exercise the
    // slab test's reciprocal of zero.
    let mut rng = Rng::new(7);
    let scene = make(&mut rng, false);
    let mut rays = Vec::new();
    for _ in 0..500 {
        let o = rng.vec(-7.0, 7.0);
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                for zero in [0.0f32, -0.0] {
                    let mut d = Vec3A::splat(zero);
                    d[axis] = sign;
                    rays.push(Ray::new(o.into(), d));
                }
            }
        }
    }
    let hits = check_rays(&scene, &rays);
    assert!(hits > 300, "only {hits} hits");
}

#[test]
fn mesh_bvh_equals_brute_force_for_every_build_preset() {
    let mut rng = Rng::new(3);
    let data = {
        let mut d = MeshData::default();
        for i in 0..2000u32 {
            let c = rng.vec(-1.0, 1.0);
            for _ in 0..3 {
                d.positions.push(c + rng.vec(-0.1, 0.1));
            }
            d.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        d
    };
    for q in [
        BuildQuality::Fastest,
        BuildQuality::VeryFast,
        BuildQuality::Fast,
        BuildQuality::Medium,
        BuildQuality::Slow,
        BuildQuality::VerySlow,
    ] {
        let mesh = Mesh::new("soup", data.clone(), NormalMode::Flat, q).unwrap();
        assert_eq!(mesh.triangle_count(), 2000);
        let mut hits = 0;
        for _ in 0..3000 {
            let o = rng.dir() * 3.0;
            let ray = Ray::new(o.into(), (rng.vec(-1.0, 1.0) - o).normalize().into());
            let a = mesh.intersect(&ray, 0.0, f32::INFINITY);
            let b = mesh.intersect_brute_force(&ray, 0.0, f32::INFINITY);
            assert_eq!(a.map(|h| h.t), b.map(|h| h.t), "{q:?} {ray:?}");
            assert_eq!(mesh.occluded(&ray, 0.0, f32::INFINITY), b.is_some());
            hits += a.is_some() as usize;
        }
        assert!(hits > 1000, "{q:?}: {hits}");
    }
}

#[test]
fn empty_and_degenerate_scenes() {
    let empty = RenderScene::new(vec![], vec![], vec![], Vec3::ZERO, BuildQuality::Medium);
    let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
    assert!(empty.intersect(&ray, 0.0, f32::INFINITY).is_none());
    assert!(!empty.occluded(&ray, 0.0, f32::INFINITY));
    // A mesh whose only triangle has zero area can never be hit.
    let flat = Mesh::new(
        "degenerate",
        MeshData {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        },
        NormalMode::Smooth,
        BuildQuality::Medium,
    )
    .unwrap();
    let ray = Ray::new(Vec3A::new(1.0, 1.0, 0.0), -Vec3A::Y);
    assert!(flat.intersect(&ray, 0.0, f32::INFINITY).is_none());
}

/// Packet traversal must find exactly what single-ray traversal finds,
/// for coherent packets (shared origin, nearby directions) and for
/// incoherent ones, including partly filled packets, whether meshes are
/// traversed as packets or one lane at a time.
#[test]
fn packets_equal_single_rays() {
    packets_equal_single_rays_with(random_scene);
}

/// [`packets_equal_single_rays`] on a scene whose single-use mesh instances are merged.
#[test]
fn packets_equal_single_rays_merged() {
    packets_equal_single_rays_with(merged_scene);
}

fn packets_equal_single_rays_with(make: fn(&mut Rng, bool) -> RenderScene) {
    use prism::accel::packet::LANES;
    let mut rng = Rng::new(99);
    let scene = make(&mut rng, true);
    let mut checked = 0;
    let mut hits = 0;
    for k in 0..3000 {
        let n = 1 + k % LANES;
        let rays: Vec<Ray> = if k % 2 == 0 {
            let o = rng.dir() * 14.0;
            let aim = (rng.vec(-5.0, 5.0) - o).normalize();
            (0..n)
                .map(|_| Ray::new(o.into(), (aim + rng.vec(-0.05, 0.05)).normalize().into()))
                .collect()
        } else {
            (0..n)
                .map(|_| Ray::new(rng.vec(-7.0, 7.0).into(), rng.dir().into()))
                .collect()
        };
        let mut out = [None; LANES];
        scene.intersect_packet(&rays, &mut out);
        // The top level as a packet, meshes one lane at a time: the same.
        let mut hybrid = [None; LANES];
        scene.intersect_packet_with(&rays, &mut hybrid, false);
        assert_eq!(out, hybrid, "packet {k}: mesh lanes one at a time");
        let t_max: Vec<f32> = (0..n).map(|_| rng.range(0.5, 30.0)).collect();
        let blocked = scene.occluded_packet(&rays, &t_max);
        assert_eq!(blocked >> n, 0, "unused lanes are never blocked");
        assert_eq!(
            scene.occluded_packet_with(&rays, &t_max, false),
            blocked,
            "shadow packet {k}: mesh lanes one at a time"
        );
        for (l, ray) in rays.iter().enumerate() {
            let single = scene.intersect(ray, 0.0, f32::INFINITY);
            match (out[l], single) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert_eq!(a.t, b.t, "packet {k} lane {l}");
                    assert_eq!(a.instance, b.instance, "packet {k} lane {l}");
                }
                (a, b) => panic!("packet {k} lane {l}: packet {a:?} single {b:?}"),
            }
            assert_eq!(
                (blocked >> l) & 1 == 1,
                scene.occluded(ray, 0.0, t_max[l]),
                "shadow packet {k} lane {l}"
            );
            checked += 1;
        }
    }
    assert!(
        checked > 10_000 && hits > 4000,
        "{checked} rays, {hits} hits"
    );
}

/// Packets of 16 through the scene ([`RenderScene::intersect_packet16`],
/// and [`RenderScene::intersect_coherent`], which the integrators use for
/// camera rays) must give every lane the hit single-ray traversal gives,
/// bit for bit (distance, instance, point, normals, texture coordinates),
/// on every SIMD path this CPU has (portable, AVX2, AVX-512): on the
/// random scene (shapes, small meshes, an unbounded plane) with coherent
/// packets from one origin, incoherent ones and partly filled ones, and on
/// a transformed 9,000-triangle sphere filling a pinhole camera's 4x4 and
/// 16x1 pixel blocks, where the lanes test the mesh's leaves together.
/// Occlusion queries of segments along the same rays in packets of 16
/// ([`RenderScene::occluded_packet16`], [`RenderScene::occluded_coherent`])
/// must give [`RenderScene::occluded`]'s answers on every path too.
/// (The path is switched process-wide: a test running meanwhile may
/// switch it too, which can mislabel a failure's path but not hide one.)
#[test]
fn packets_of_16_equal_single_rays_on_every_path() {
    packets_of_16_equal_single_rays_on_every_path_with(random_scene);
}

/// [`packets_of_16_equal_single_rays_on_every_path`] on a scene whose single-use mesh instances are merged.
#[test]
fn packets_of_16_equal_single_rays_on_every_path_merged() {
    packets_of_16_equal_single_rays_on_every_path_with(merged_scene);
}

fn packets_of_16_equal_single_rays_on_every_path_with(make: fn(&mut Rng, bool) -> RenderScene) {
    use prism::accel::packet16::LANES16;
    use prism::core::simd::{self, Isa};
    let mut rng = Rng::new(1616);
    let scene = make(&mut rng, true);
    let sphere = RenderScene::new(
        vec![Instance::new(
            InstanceGeometry::Mesh(Arc::new(uv_sphere(96, 48))),
            &random_transform(&mut rng, 0.5),
            0,
        )],
        vec![Material::default()],
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    let mut packets: Vec<(&RenderScene, Vec<Ray>)> = Vec::new();
    for k in 0..1200 {
        let n = 1 + k % LANES16;
        let rays: Vec<Ray> = match k % 3 {
            0 => {
                let o = rng.dir() * 14.0;
                let aim = (rng.vec(-5.0, 5.0) - o).normalize();
                (0..n)
                    .map(|_| Ray::new(o.into(), (aim + rng.vec(-0.05, 0.05)).normalize().into()))
                    .collect()
            }
            1 => (0..n)
                .map(|_| Ray::new(rng.vec(-7.0, 7.0).into(), rng.dir().into()))
                .collect(),
            _ => {
                // A pinhole camera 4 units from the sphere's centre, a
                // block of 4x4 or 16x1 pixels of a 1.2-unit-wide view.
                let o = Vec3A::from(rng.dir() * 4.0);
                let w = -o.normalize();
                let u = w.cross(Vec3A::Y).normalize();
                let v = u.cross(w);
                let (cols, px) = if k % 2 == 0 { (4, 0.01) } else { (16, 0.004) };
                let corner = Vec3A::from(rng.vec(-0.12, 0.08));
                let rays = (0..LANES16)
                    .map(|l| {
                        let (x, y) = ((l % cols) as f32, (l / cols) as f32);
                        let p = w + u * (corner.x + x * px) + v * (corner.y + y * px);
                        Ray::new(o, p.normalize())
                    })
                    .collect();
                packets.push((&sphere, rays));
                continue;
            }
        };
        packets.push((&scene, rays));
    }
    let bits = |h: &Option<prism::scene::Hit>| format!("{h:?}");
    // Occlusion of segments along the same rays (the shadow rays of
    // `RenderScene::occluded_coherent`), about as many blocked as not.
    let (want, (segments, want_blocked)): (Vec<_>, (Vec<_>, Vec<_>)) = packets
        .iter()
        .map(|(s, rays)| {
            let (hits, ends, blocked) = single_ray_answers(s, rays, &mut rng, 30.0);
            (hits, (ends, blocked))
        })
        .unzip();
    let blocked_lanes: u32 = want_blocked.iter().map(|m| m.count_ones()).sum();
    let lanes: usize = packets.iter().map(|(_, r)| r.len()).sum();
    assert!(
        blocked_lanes as usize > lanes / 4 && (blocked_lanes as usize) < lanes * 3 / 4,
        "{blocked_lanes} of {lanes} segments blocked"
    );
    let mut hits = [0usize; 2];
    for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512] {
        if !simd::force(isa) {
            eprintln!("{isa:?} skipped: not on this CPU");
            continue;
        }
        for (k, (((s, rays), t), &want)) in
            packets.iter().zip(&segments).zip(&want_blocked).enumerate()
        {
            assert_eq!(
                s.occluded_packet16(rays, t),
                want,
                "{isa:?} occluded packet {k}"
            );
            assert_eq!(
                s.occluded_coherent(rays, t),
                want,
                "{isa:?} occluded coherent {k}"
            );
        }
        for (k, ((s, rays), want)) in packets.iter().zip(&want).enumerate() {
            let mut wide = [None; LANES16];
            s.intersect_packet16(rays, &mut wide);
            let mut coherent = [None; LANES16];
            s.intersect_coherent(rays, &mut coherent);
            for (l, w) in want.iter().enumerate() {
                assert_eq!(&bits(&wide[l]), w, "{isa:?} packet {k} lane {l}");
                assert_eq!(&bits(&coherent[l]), w, "{isa:?} coherent {k} lane {l}");
                if isa == Isa::Portable && wide[l].is_some() {
                    hits[std::ptr::eq(*s, &sphere) as usize] += 1;
                }
            }
            assert!(wide[rays.len()..].iter().all(Option::is_none));
        }
    }
    simd::force(simd::detected());
    // (5057 and 6400 when written; 5045 and 5505 on the merged scene,
    // whose random numbers run differently.)
    assert!(hits[0] > 4000 && hits[1] > 5000, "hits {hits:?}");
}

/// Meshes whose BVH is one leaf (the quads, panels and small solids of
/// simple scenes) are tested lane by lane without the packet traversal
/// when a packet's rays share no origin (bounce and shadow rays), and by
/// the packet's shared leaf frame when they do (camera rays): either way
/// every lane must get the hit and the occlusion answer of single-ray
/// traversal, bit for bit, in packets of 8 and 16 on every SIMD path. A
/// scene of 40 small soups (1 to 8 triangles) and a few shapes, with
/// packets of scattered rays, of rays from one origin, and partly filled
/// ones.
#[test]
fn packets_through_one_leaf_meshes_equal_single_rays() {
    use prism::accel::packet::LANES;
    use prism::accel::packet16::LANES16;
    use prism::core::simd::{self, Isa};
    let mut rng = Rng::new(4242);
    let meshes: Vec<Arc<Mesh>> = (0..40)
        .map(|k| Arc::new(soup(&mut rng, 1 + k % 8)))
        .collect();
    let one_leaf = meshes.iter().filter(|m| m.single_leaf()).count();
    assert!(one_leaf >= 30, "{one_leaf} of 40 soups are one leaf");
    let mut instances: Vec<Instance> = meshes
        .iter()
        .map(|m| {
            Instance::new(
                InstanceGeometry::Mesh(m.clone()),
                &random_transform(&mut rng, 4.0),
                0,
            )
        })
        .collect();
    for (k, shape) in all_shapes().into_iter().take(4).enumerate() {
        instances.push(Instance::new(
            InstanceGeometry::Shape(shape),
            &random_transform(&mut rng, 4.0 + k as f32),
            0,
        ));
    }
    let scene = RenderScene::new(
        instances,
        vec![Material::default()],
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    let packets: Vec<Vec<Ray>> = (0..3000)
        .map(|k| {
            let n = 1 + k % LANES16;
            if k % 2 == 0 {
                let o = rng.dir() * 9.0;
                let aim = (rng.vec(-3.0, 3.0) - o).normalize();
                (0..n)
                    .map(|_| Ray::new(o.into(), (aim + rng.vec(-0.1, 0.1)).normalize().into()))
                    .collect()
            } else {
                (0..n)
                    .map(|_| {
                        let o = rng.vec(-5.0, 5.0);
                        let aim = (rng.vec(-3.0, 3.0) - o).normalize();
                        Ray::new(o.into(), (aim + rng.vec(-0.3, 0.3)).normalize().into())
                    })
                    .collect()
            }
        })
        .collect();
    let bits = |h: &Option<prism::scene::Hit>| format!("{h:?}");
    let (want, (segments, want_blocked)): (Vec<_>, (Vec<_>, Vec<_>)) = packets
        .iter()
        .map(|rays| {
            let (hits, ends, blocked) = single_ray_answers(&scene, rays, &mut rng, 20.0);
            (hits, (ends, blocked))
        })
        .unzip();
    let mut hits = 0;
    for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512] {
        if !simd::force(isa) {
            eprintln!("{isa:?} skipped: not on this CPU");
            continue;
        }
        for (k, ((rays, want), (t, &blocked))) in packets
            .iter()
            .zip(&want)
            .zip(segments.iter().zip(&want_blocked))
            .enumerate()
        {
            let mut wide = [None; LANES16];
            scene.intersect_packet16(rays, &mut wide);
            assert_eq!(
                scene.occluded_packet16(rays, t),
                blocked,
                "{isa:?} occluded 16, {k}"
            );
            let mut eight = [None; LANES];
            let mut blocked8 = 0;
            for (c, (r, t)) in rays.chunks(LANES).zip(t.chunks(LANES)).enumerate() {
                scene.intersect_packet(r, &mut eight[..r.len()]);
                for (l, h) in eight[..r.len()].iter().enumerate() {
                    assert_eq!(
                        &bits(h),
                        &want[c * LANES + l],
                        "{isa:?} packet 8, {k}, lane {}",
                        c * LANES + l
                    );
                }
                blocked8 |= scene.occluded_packet(r, t) << (c * LANES);
            }
            assert_eq!(blocked8, blocked, "{isa:?} occluded 8, {k}");
            for (l, w) in want.iter().enumerate() {
                assert_eq!(&bits(&wide[l]), w, "{isa:?} packet 16, {k}, lane {l}");
                if isa == Isa::Portable && wide[l].is_some() {
                    hits += 1;
                }
            }
        }
    }
    simd::force(simd::detected());
    // (2244 when written.)
    assert!(hits > 1500, "{hits} hits");
}

/// Stream traversal (the wavefront's secondary rays) must find what
/// single-ray traversal finds: for rays from outside, rays from anywhere
/// inside the scene, and rays leaving hit points on either side of the
/// surface (reflection and refraction rays, which start on a mesh and
/// often end on the same mesh), in streams of every size from one ray up.
#[test]
fn streams_equal_single_rays() {
    streams_equal_single_rays_with(random_scene);
}

/// [`streams_equal_single_rays`] on a scene whose single-use mesh instances are merged.
#[test]
fn streams_equal_single_rays_merged() {
    streams_equal_single_rays_with(merged_scene);
}

fn streams_equal_single_rays_with(make: fn(&mut Rng, bool) -> RenderScene) {
    use prism::scene::StreamScratch;
    let mut rng = Rng::new(7);
    let scene = make(&mut rng, true);
    let mut rays = Vec::new();
    while rays.len() < 6000 {
        let o = rng.dir() * 15.0;
        let target = rng.vec(-6.0, 6.0);
        let ray = Ray::new(o.into(), (target - o).normalize().into());
        rays.push(ray);
        rays.push(Ray::new(rng.vec(-7.0, 7.0).into(), rng.dir().into()));
        if let Some(h) = scene.intersect(&ray, 0.0, f32::INFINITY) {
            // Leave the hit point into either side, like a bounce does.
            let n = h.geometric_normal.normalize();
            let d: Vec3A = rng.dir().into();
            let side = if d.dot(n) > 0.0 { n } else { -n };
            rays.push(Ray::new(
                prism::core::optics::offset_origin(h.point, side),
                d,
            ));
        }
    }
    let mut scratch = StreamScratch::default();
    let mut hits = 0;
    let mut start = 0;
    let mut size = 1;
    while start < rays.len() {
        let end = (start + size).min(rays.len());
        let mut out = vec![None; end - start];
        scene.intersect_stream(&rays[start..end], &mut out, &mut scratch);
        for (k, ray) in rays[start..end].iter().enumerate() {
            let single = scene.intersect(ray, 0.0, f32::INFINITY);
            match (out[k], single) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert_eq!(a.t, b.t, "ray {}", start + k);
                    assert_eq!(a.instance, b.instance, "ray {}", start + k);
                }
                (a, b) => panic!("ray {}: stream {a:?} single {b:?}", start + k),
            }
        }
        start = end;
        size = size * 3 + 1;
    }
    assert!(hits > 3000, "{hits} hits");
}

/// The batched polygon test of the wavefront (`scene::polygons`) gives
/// every ray the hit the per-ray query gives, bit for bit (`t`, point,
/// normals, `uv`, instance), and every segment the same occlusion: on the
/// Cornell box seen from its camera's render frame (rays aimed at the
/// polygons' corners, where neighbours tie, and rays from points on the
/// walls in random directions, as bounces leave them), and on random
/// polygons of three to six sides under random transforms (several
/// transform groups). On every instruction set the machine has, in full
/// batches of [`BATCH_LANES`] rays and in partial ones (made to fail by
/// filling only the first eight lanes of a batch with their rays).
#[test]
fn batched_polygons_give_the_per_ray_hits() {
    use prism::core::simd::{self, Isa};
    use prism::scene::polygons::{BATCH_LANES, PolygonBatch};
    let desc = crate::common::scenes::load(&crate::common::assets().join("cornell.toml"));
    let eye = desc.cameras[0].look_from;
    let instances: Vec<Instance> = desc
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let prism::io::desc::Geometry::Shape(s) = &o.geometry else {
                unreachable!("the Cornell box is polygons")
            };
            Instance::new(InstanceGeometry::Shape(s.clone()), &o.transform, i as u32)
        })
        .collect();
    let materials = desc.objects.iter().map(|o| o.material.clone()).collect();
    let cornell = RenderScene::with_origin(
        eye,
        instances,
        materials,
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    let mut rng = Rng::new(5);
    let mut pick = crate::common::rng::SplitMix64(9);
    let transforms: Vec<Transform> = (0..4)
        .map(|k| {
            if k % 2 == 0 {
                random_transform(&mut rng, 3.0)
            } else {
                Transform::from_trs_f32(
                    rng.vec(-3.0, 3.0),
                    Quat::from_axis_angle(rng.dir(), rng.range(0.0, PI)),
                    Vec3::ONE,
                )
            }
        })
        .collect();
    let mut polygons = Vec::new();
    for k in 0..24 {
        let sides = 3 + k % 4;
        let r = rng.range(0.5, 2.0);
        let vertices: Vec<Vec3> = (0..sides)
            .map(|i| {
                let a = -2.0 * PI * i as f32 / sides as f32;
                Vec3::new(r * a.cos(), 0.0, r * a.sin())
            })
            .collect();
        let shape = Shape::Polygon {
            vertices: vertices.into(),
        };
        // Four transforms (two with scale and shear), six polygons each.
        let t = transforms[k % 4];
        polygons.push(Instance::new(InstanceGeometry::Shape(shape), &t, 0));
    }
    let random = RenderScene::new(
        polygons,
        vec![Material::default()],
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    let (mut ties, mut hits, mut blocked) = (0, 0, 0);
    for scene in [&cornell, &random] {
        let batch = PolygonBatch::new(scene).expect("a scene of polygons");
        let corners: Vec<Vec3A> = scene
            .instances()
            .iter()
            .flat_map(|inst| {
                let InstanceGeometry::Shape(Shape::Polygon { vertices }) = &inst.geometry else {
                    unreachable!()
                };
                let to_world = inst.transform.to_world;
                vertices
                    .iter()
                    .map(move |v| to_world.transform_point3a(Vec3A::from(*v)))
            })
            .collect();
        let mut rays = Vec::new();
        let mut t_max = Vec::new();
        for k in 0..4000 {
            let ray = match k % 3 {
                // From the camera (the render origin) or a random point
                // towards a corner.
                0 => Ray::new(Vec3A::ZERO, corners[pick.below(corners.len())]),
                1 => {
                    let o = Vec3A::from(rng.vec(-6.0, 6.0));
                    Ray::new(o, corners[pick.below(corners.len())] - o)
                }
                // From a point on a surface, anywhere.
                _ => {
                    let c = corners[pick.below(corners.len())];
                    let d = corners[pick.below(corners.len())];
                    let o = c + (d - c) * rng.range(0.0, 1.0);
                    Ray::new(o, Vec3A::from(rng.dir()))
                }
            };
            rays.push(ray);
            t_max.push(if k % 5 == 0 {
                f32::INFINITY
            } else {
                rng.range(0.0, 8.0)
            });
        }
        for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512] {
            if !simd::force(isa) {
                continue;
            }
            // Full batches, and partial ones whose last rays repeat.
            for size in [BATCH_LANES, 7] {
                for (group, limits) in rays.chunks(size).zip(t_max.chunks(size)) {
                    let mut got = [None; BATCH_LANES];
                    batch.intersect(scene, group, &mut got[..group.len()]);
                    let mask = batch.occluded(scene, group, limits);
                    for (l, ray) in group.iter().enumerate() {
                        let want = scene.intersect(ray, 0.0, f32::INFINITY);
                        assert_eq!(format!("{:?}", got[l]), format!("{want:?}"), "{ray:?}");
                        hits += want.is_some() as usize;
                        let occluded = scene.occluded(ray, 0.0, limits[l]);
                        assert_eq!(mask & (1 << l) != 0, occluded, "{ray:?} to {}", limits[l]);
                        blocked += occluded as usize;
                        // A tie: two polygons as near along the ray (handed to
                        // the per-ray query by the batch).
                        let mut near: Vec<u32> = scene
                            .instances()
                            .iter()
                            .filter_map(|inst| {
                                let InstanceGeometry::Shape(s) = &inst.geometry else {
                                    return None;
                                };
                                let m = &inst.transform.to_object;
                                let local = Ray::new(
                                    m.transform_point3a(ray.origin),
                                    m.transform_vector3a(ray.direction),
                                );
                                s.intersect(&local, 0.0, f32::INFINITY)
                                    .map(|h| h.t.to_bits())
                            })
                            .collect();
                        near.sort_by(|a, b| f32::from_bits(*a).total_cmp(&f32::from_bits(*b)));
                        ties += (near.len() > 1 && near[0] == near[1]) as usize;
                    }
                }
            }
        }
    }
    simd::force(simd::detected());
    eprintln!("{hits} hits, {blocked} blocked, {ties} ties");
    assert!(
        hits > 3000 && blocked > 1000 && ties > 10,
        "{hits} hits, {blocked} blocked, {ties} ties"
    );
}

/// A merged scene finds the surfaces the same scene finds unmerged: the
/// same instance, triangle (same texture coordinates and normals up to
/// rounding) and distance up to the rounding of the corners' transform
/// into the render frame, which the test bounds by a relative 1e-4 of
/// the distance (the corners are within 10 units, a few ulps of
/// rounding each; the rays are tens of units long); ties between
/// instances (coincident hits) excepted. Moving a merged instance undoes
/// the group, after which the scene answers exactly as the unmerged one,
/// bit for bit.
#[test]
fn merged_meshes_find_the_unmerged_hits() {
    let mut rng = Rng::new(4711);
    let (instances, materials) = merge_candidates(&mut rng, true);
    let plain = RenderScene::new(
        instances.clone(),
        materials.clone(),
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    let mut merged = RenderScene::new(
        instances,
        materials,
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    merged.set_mesh_merging(true);
    merged.commit();
    assert_eq!(merged.merged_instances(), MERGEABLE);
    let rays = mixed_rays(&mut rng, 3000);
    let (mut same, mut on_merged) = (0, 0);
    for (i, ray) in rays.iter().enumerate() {
        let a = merged.intersect(ray, 0.0, f32::INFINITY);
        let b = plain.intersect(ray, 0.0, f32::INFINITY);
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) if a.instance == b.instance => {
                same += 1;
                let tol = 1e-4 * b.t.max(1.0);
                assert!((a.t - b.t).abs() <= tol, "ray {i}: t {} vs {}", a.t, b.t);
                assert!((a.point - b.point).length() <= tol, "ray {i}: point");
                assert!(
                    a.geometric_normal.dot(b.geometric_normal) > 0.9999,
                    "ray {i}: normal"
                );
                assert!((a.uv - b.uv).length() <= 1e-3, "ray {i}: uv");
                assert_eq!(a.material, b.material, "ray {i}");
                if matches!(
                    plain.instances()[b.instance as usize].geometry,
                    InstanceGeometry::Mesh(_)
                ) {
                    on_merged += 1;
                }
            }
            // Another instance only where both are (nearly) equally near.
            (Some(a), Some(b)) => {
                assert!(
                    (a.t - b.t).abs() <= 1e-4 * b.t.max(1.0),
                    "ray {i}: {a:?} vs {b:?}"
                )
            }
            // A grazing ray may pass on one side of a rounded edge and
            // not the other: only where the hit is at a silhouette.
            (a, b) => panic!("ray {i}: merged {a:?} unmerged {b:?}"),
        }
        let t = rng.range(0.5, 30.0);
        let near_edge = b.is_some_and(|b| (b.t - t).abs() < 1e-3 * t);
        if !near_edge {
            assert_eq!(
                merged.occluded(ray, 0.0, t),
                plain.occluded(ray, 0.0, t),
                "ray {i}: shadow"
            );
        }
    }
    assert!(
        same > 2000 && on_merged > 300,
        "{same} hits, {on_merged} on merged meshes"
    );

    // Move a merged instance: the group is undone, and the scene answers
    // as an unmerged one built with the move, bit for bit.
    let mesh_index = plain
        .instances()
        .iter()
        .enumerate()
        .filter(|(_, inst)| matches!(inst.geometry, InstanceGeometry::Mesh(_)))
        .map(|(i, _)| i)
        .nth(5)
        .unwrap();
    let to = Transform::from_translation(glam::DVec3::new(1.0, 2.0, 3.0));
    merged.set_instance_transform(mesh_index as u32, &to);
    merged.commit();
    assert_eq!(merged.merged_instances(), 0);
    let mut moved: Vec<Instance> = plain.instances().to_vec();
    moved[mesh_index] = Instance::new(
        moved[mesh_index].geometry.clone(),
        &to,
        moved[mesh_index].material,
    );
    let moved = RenderScene::new(
        moved,
        plain.materials().to_vec(),
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    for (i, ray) in rays.iter().enumerate() {
        let a = merged.intersect(ray, 0.0, f32::INFINITY);
        let b = moved.intersect(ray, 0.0, f32::INFINITY);
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "ray {i} after the move");
    }
    // Asking again does not merge again.
    merged.set_mesh_merging(true);
    merged.commit();
    assert_eq!(merged.merged_instances(), 0);
}

/// A group is made only when every bounded instance can join it: one
/// shape, one instance of a mesh used twice, or one instance whose
/// material has an alpha mode keeps the scene unmerged (each would leave
/// a top level beside the group, and a ray would traverse both); the
/// unbounded plane does not count.
#[test]
fn merging_needs_every_bounded_instance() {
    let mut rng = Rng::new(31);
    let (instances, materials) = merge_candidates(&mut rng, true);
    let cut_out = Material {
        // Opaque everywhere (factor 1 above the cutoff), but an alpha
        // mode all the same.
        alpha: Some(prism::scene::material::Alpha {
            mode: prism::scene::material::AlphaMode::Mask { cutoff: 0.5 },
            factor: 1.0,
            texture: None,
        }),
        ..Material::default()
    };
    let merged = |instances: Vec<Instance>| {
        let mut scene = RenderScene::new(
            instances,
            vec![materials[0].clone(), cut_out.clone()],
            vec![],
            Vec3::ZERO,
            BuildQuality::Medium,
        );
        scene.set_mesh_merging(true);
        scene.commit();
        scene.merged_instances()
    };
    assert_eq!(merged(instances.clone()), MERGEABLE, "meshes and a plane");
    let mut with_shape = instances.clone();
    with_shape.push(Instance::new(
        InstanceGeometry::Shape(Shape::Sphere { radius: 1.0 }),
        &random_transform(&mut rng, 6.0),
        0,
    ));
    assert_eq!(merged(with_shape), 0, "a shape");
    let mut shared = instances.clone();
    shared.push(Instance::new(
        shared[0].geometry.clone(),
        &random_transform(&mut rng, 6.0),
        0,
    ));
    assert_eq!(merged(shared), 0, "a mesh used twice");
    let mut alpha = instances.clone();
    alpha[3].material = 1;
    assert_eq!(merged(alpha), 0, "an alpha material");
    let mut one = instances;
    one.truncate(1);
    assert_eq!(merged(one), 0, "a single instance");
}

/// A box of two triangles per face (shared corners, coplanar pairs).
fn cube() -> Mesh {
    let mut data = MeshData::default();
    for i in 0..8u32 {
        let c = |b: u32| if i >> b & 1 == 1 { 1.0 } else { -1.0 };
        data.positions.push(Vec3::new(c(0), c(1), c(2)));
    }
    for [a, b, c, d] in [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ] {
        data.indices.push([a, b, c]);
        data.indices.push([a, c, d]);
    }
    Mesh::new("cube", data, NormalMode::Flat, BuildQuality::Medium).unwrap()
}

/// `instances` with the default material, mesh merging asked for or not,
/// committed.
fn committed_scene(instances: Vec<Instance>, merge: bool) -> RenderScene {
    let mut scene = RenderScene::new(
        instances,
        vec![Material::default()],
        vec![],
        Vec3::ZERO,
        BuildQuality::Medium,
    );
    scene.set_mesh_merging(merge);
    scene.commit();
    scene
}

/// The wavefront's batched test of a small merged mesh
/// (`scene::triangles`) gives every ray the hit the per-ray query gives,
/// bit for bit (`t`, point, normals, `uv`, instance), and every segment
/// the same occlusion, on the portable, AVX2 and AVX-512 paths: four
/// merged meshes (two boxes, a quad, a coarse sphere: 50 triangles) under
/// random transforms with scale and shear, and an axis-aligned box (62
/// triangles in all), near the origin and 3e4 away from it, with rays
/// aimed at corners (where coplanar neighbours tie and the batch hands
/// the ray to the per-ray query), rays leaving surface points in random
/// directions, axis-aligned rays with signed zeros, and rays running in
/// the planes of the axis-aligned box's faces (a zero direction
/// component, at the edge of its triangles' boxes: the padding of the
/// boxes that skip triangles keeps their hits on its edges).
#[test]
fn batched_triangles_give_the_per_ray_hits() {
    use prism::core::simd::{self, Isa};
    use prism::scene::triangles::TriangleBatch;
    let mut rng = Rng::new(77);
    let mut pick = crate::common::rng::SplitMix64(3);
    let quad = || {
        let quad = MeshData {
            positions: vec![
                Vec3::new(-3.0, 0.0, -3.0),
                Vec3::new(3.0, 0.0, -3.0),
                Vec3::new(3.0, 0.0, 3.0),
                Vec3::new(-3.0, 0.0, 3.0),
            ],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            ..MeshData::default()
        };
        Mesh::new("quad", quad, NormalMode::Flat, BuildQuality::Medium).unwrap()
    };
    let (mut hits, mut blocked) = (0, 0);
    for offset in [Vec3::ZERO, Vec3::new(3.0e4, -2.0e4, 1.0e4)] {
        let mut instances: Vec<Instance> = [cube(), cube(), quad(), uv_sphere(4, 3)]
            .into_iter()
            .map(|m| {
                let t = Transform::from_trs_f32(
                    offset + rng.vec(-2.5, 2.5),
                    Quat::from_axis_angle(rng.dir(), rng.range(0.0, 2.0 * PI)),
                    Vec3::new(
                        rng.range(0.3, 2.0),
                        rng.range(0.3, 2.0),
                        rng.range(0.3, 2.0),
                    ),
                );
                Instance::new(InstanceGeometry::Mesh(Arc::new(m)), &t, 0)
            })
            .collect();
        // An axis-aligned cube at an exact place, for rays that run in the
        // planes of its faces and meet its edges on the triangles' boxes.
        let centre = offset + Vec3::new(0.0, 6.0, 0.0);
        instances.push(Instance::new(
            InstanceGeometry::Mesh(Arc::new(cube())),
            &Transform::from_translation(centre.as_dvec3()),
            0,
        ));
        let corners: Vec<Vec3A> = instances
            .iter()
            .flat_map(|inst| {
                let InstanceGeometry::Mesh(m) = &inst.geometry else {
                    unreachable!()
                };
                let to_world = inst.transform.to_world;
                (0..m.triangle_count())
                    .flat_map(|i| m.triangle(i))
                    .map(move |p| to_world.transform_point3a(p))
                    .collect::<Vec<_>>()
            })
            .collect();
        let scene = committed_scene(instances, true);
        assert_eq!(scene.merged_instances(), 5);
        let o = Vec3A::from(offset);
        let mut rays = Vec::new();
        let mut t_max = Vec::new();
        for k in 0..3000 {
            let ray = match k % 5 {
                // In the plane of a face of the axis-aligned cube (a zero
                // direction component), towards its edges.
                4 => {
                    let a = pick.below(3);
                    let mut o = Vec3A::from(centre) + Vec3A::from(rng.vec(-3.0, 3.0));
                    o[a] = centre[a] + if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                    let mut d = Vec3A::from(centre) + Vec3A::from(rng.vec(-1.2, 1.2)) - o;
                    d[a] = if rng.f32() < 0.5 { 0.0 } else { -0.0 };
                    Ray::new(o, d)
                }
                // From a random point or the centre towards a corner.
                0 => {
                    let from = o + Vec3A::from(rng.vec(-6.0, 6.0));
                    Ray::new(from, corners[pick.below(corners.len())] - from)
                }
                1 => Ray::new(o, corners[pick.below(corners.len())] - o),
                // From a point on a triangle, anywhere.
                2 => {
                    let t = 3 * (pick.below(corners.len()) / 3);
                    let (a, b, c) = (corners[t], corners[t + 1], corners[t + 2]);
                    let (u, v) = (rng.range(0.0, 1.0), rng.range(0.0, 1.0));
                    let (u, v) = if u + v > 1.0 {
                        (1.0 - u, 1.0 - v)
                    } else {
                        (u, v)
                    };
                    Ray::new(a + (b - a) * u + (c - a) * v, Vec3A::from(rng.dir()))
                }
                // Axis-aligned, with signed zeros.
                _ => {
                    let mut d = Vec3A::ZERO;
                    let a = pick.below(3);
                    d[a] = if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                    d[(a + 1) % 3] = if rng.f32() < 0.5 { 0.0 } else { -0.0 };
                    Ray::new(o + Vec3A::from(rng.vec(-4.0, 4.0)), d)
                }
            };
            rays.push(ray);
            t_max.push(if k % 5 == 0 {
                f32::INFINITY
            } else {
                rng.range(0.0, 8.0)
            });
        }
        let want: Vec<String> = rays
            .iter()
            .map(|r| format!("{:?}", scene.intersect(r, 0.0, f32::INFINITY)))
            .collect();
        let occluded: Vec<bool> = rays
            .iter()
            .zip(&t_max)
            .map(|(r, &t)| scene.occluded(r, 0.0, t))
            .collect();
        hits += want.iter().filter(|h| *h != "None").count();
        blocked += occluded.iter().filter(|&&b| b).count();
        for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512] {
            if !simd::force(isa) {
                eprintln!("{} path skipped: not on this CPU", isa.name());
                continue;
            }
            let batch = TriangleBatch::new(&scene).expect("one small merged mesh");
            // Calls of several sizes, as the wavefront's chunks and
            // shadow groups make them.
            for size in [1, 7, 16, 100, 3000] {
                let mut got = vec![None; rays.len()];
                let mut got_blocked = vec![false; rays.len()];
                for (k, (r, t)) in rays.chunks(size).zip(t_max.chunks(size)).enumerate() {
                    let at = k * size;
                    batch.intersect(r, &mut got[at..at + r.len()]);
                    batch.occluded(r, t, &mut got_blocked[at..at + r.len()]);
                }
                for (i, ray) in rays.iter().enumerate() {
                    assert_eq!(
                        format!("{:?}", got[i]),
                        want[i],
                        "{} path, calls of {size}: {ray:?}",
                        isa.name()
                    );
                    assert_eq!(
                        got_blocked[i],
                        occluded[i],
                        "{} path, calls of {size}: {ray:?} to {}",
                        isa.name(),
                        t_max[i]
                    );
                }
            }
        }
        simd::force(simd::detected());
    }
    eprintln!("{hits} hits, {blocked} blocked");
    assert!(
        hits > 3000 && blocked > 1000,
        "{hits} hits, {blocked} blocked"
    );
}

/// The batched triangle test takes only scenes that are one merged mesh
/// of a few dozen triangles: not more triangles, not a shape beside the
/// mesh, not unmerged meshes.
#[test]
fn batched_triangles_only_for_one_small_merged_mesh() {
    use prism::scene::triangles::{MAX_TRIANGLES, TriangleBatch};
    let mut rng = Rng::new(5);
    let scene = |meshes: Vec<Mesh>, plane: bool, merge: bool, rng: &mut Rng| {
        let mut instances: Vec<Instance> = meshes
            .into_iter()
            .map(|m| {
                Instance::new(
                    InstanceGeometry::Mesh(Arc::new(m)),
                    &random_transform(rng, 3.0),
                    0,
                )
            })
            .collect();
        if plane {
            instances.push(Instance::new(
                InstanceGeometry::Shape(Shape::Plane),
                &Transform::from_translation(glam::DVec3::new(0.0, -7.0, 0.0)),
                0,
            ));
        }
        committed_scene(instances, merge)
    };
    assert!(TriangleBatch::new(&scene(vec![cube(), cube()], false, true, &mut rng)).is_some());
    assert!(TriangleBatch::new(&scene(vec![cube(), cube()], true, true, &mut rng)).is_none());
    assert!(TriangleBatch::new(&scene(vec![cube(), cube()], false, false, &mut rng)).is_none());
    let big = soup(&mut rng, MAX_TRIANGLES);
    assert!(TriangleBatch::new(&scene(vec![big, cube()], false, true, &mut rng)).is_none());
}
