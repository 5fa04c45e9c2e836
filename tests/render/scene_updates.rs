//! Incremental scene updates (ECS change detection -> persistent scene ->
//! top-level BVH leaf updates) against scenes built from scratch, and
//! progressive accumulation.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use glam::{Affine3A, Quat, Vec3, Vec3A};
use prism::accel::tlas::{MoveStrategy, TlasPolicy, TlasUpdate};
use prism::core::math::{Color, Ray};
use prism::core::settings::{RenderSettings, Transport};
use prism::geometry::mesh::{BuildQuality, Mesh, NormalMode};
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::integrators::IntegratorKind;
use prism::scene::camera::Camera;
use prism::scene::light::Light;
use prism::scene::material::Material;
use prism::scene::{Hit, RenderScene};
use prism::systems::MeshInstance;
use prism::systems::sync::{SceneSync, scene_from_scratch};
use prism::systems::{
    self, Frame, PrismPlugin, ProgressiveRendering, RenderConfig, SceneAccel, run_frame,
};

use crate::common::render::plugin_world;
use crate::common::rng::{Random, SplitMix64 as Rng};

fn meshes() -> Vec<Arc<Mesh>> {
    [(2, 3, 48, 8), (3, 4, 40, 6), (2, 5, 24, 5)]
        .into_iter()
        .map(|(p, q, seg, sides)| {
            let data = prism::geometry::procedural::torus_knot(p, q, 1.0, 0.3, seg, sides);
            Arc::new(Mesh::new("knot", data, NormalMode::Smooth, BuildQuality::Medium).unwrap())
        })
        .collect()
}

fn random_transform(rng: &mut Rng) -> Transform {
    let roll = rng.below(40);
    if roll == 0 {
        // Far beyond the BVH's coordinate limit: tested one by one.
        return Transform::from_translation(glam::DVec3::new(2e15, 0.0, 0.0));
    }
    if roll == 1 {
        // Invalid: the frame must fail until it is fixed.
        return Transform::from(Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)));
    }
    let axis = rng.vec(-1.0, 1.0).normalize_or(Vec3::Y);
    Transform::from_trs_f32(
        rng.vec(-10.0, 10.0),
        Quat::from_axis_angle(axis, rng.range(0.0, 6.3)),
        Vec3::splat(rng.range(0.3, 2.0)),
    )
}

fn random_material(rng: &mut Rng) -> Material {
    Material {
        base_color: Color::new(rng.f32(), rng.f32(), rng.f32()),
        mirror: Color::splat(if rng.below(4) == 0 { 0.8 } else { 0.0 }),
        ..Default::default()
    }
}

/// Spawns a random object; planes are rare (they are tested one by one).
fn spawn_object(world: &mut World, rng: &mut Rng, meshes: &[Arc<Mesh>]) -> Entity {
    let t = random_transform(rng);
    let m = random_material(rng);
    let mut e = world.spawn((t, m));
    match rng.below(10) {
        0..=3 => e.insert(MeshInstance(meshes[rng.below(meshes.len())].clone())),
        4..=6 => e.insert(Shape::Sphere {
            radius: rng.range(0.2, 1.5),
        }),
        7 | 8 => e.insert(Shape::Disk {
            radius: rng.range(0.2, 1.5),
        }),
        _ => e.insert(Shape::Plane),
    };
    e.id()
}

fn random_geometry(world: &mut World, e: Entity, rng: &mut Rng, meshes: &[Arc<Mesh>]) {
    let mut em = world.entity_mut(e);
    if rng.below(2) == 0 {
        em.remove::<Shape>();
        em.insert(MeshInstance(meshes[rng.below(meshes.len())].clone()));
    } else {
        em.remove::<MeshInstance>();
        em.insert(Shape::Sphere {
            radius: rng.range(0.2, 1.5),
        });
    }
}

fn new_world(spp: u32) -> (World, Schedule) {
    let (mut world, schedule) = plugin_world(PrismPlugin::new().settings(RenderSettings {
        width: 8,
        height: 6,
        spp,
        max_depth: 2,
        ..Default::default()
    }));
    world.spawn(Camera {
        look_from: glam::DVec3::new(0.0, 3.0, 25.0),
        ..Default::default()
    });
    (world, schedule)
}

fn set_policy(world: &mut World, policy: TlasPolicy) {
    let mut accel = world.resource_mut::<SceneAccel>();
    let scene = Arc::get_mut(accel.scene.as_mut().unwrap()).unwrap();
    scene.set_tlas_policy(policy);
}

/// Exact comparison of two hits, up to the numbering of instances and
/// materials (mapped to entities and compared by value).
fn same_hit(
    a: Option<Hit>,
    b: Option<Hit>,
    (sa, ea): (&RenderScene, &dyn Fn(u32) -> Entity),
    (sb, eb): (&RenderScene, &[Entity]),
    what: &str,
) {
    match (a, b) {
        (None, None) => {}
        (Some(a), Some(b)) => {
            assert_eq!(a.t, b.t, "{what}: t");
            // Two instances hit at exactly the same t (coincident
            // surfaces) may be reported either way; anything else is the
            // same surface point.
            if ea(a.instance) == eb[b.instance as usize] {
                assert_eq!(a.point, b.point, "{what}: point");
                assert_eq!(a.geometric_normal, b.geometric_normal, "{what}: normal");
                assert_eq!(a.shading_normal, b.shading_normal, "{what}: shading normal");
                assert_eq!(a.uv, b.uv, "{what}: uv");
                assert_eq!(
                    format!("{:?}", sa.materials()[a.material as usize]),
                    format!("{:?}", sb.materials()[b.material as usize]),
                    "{what}: material"
                );
            }
        }
        (a, b) => panic!("{what}: incremental {a:?} vs from scratch {b:?}"),
    }
}

fn compare_with_scratch(world: &mut World, rng: &mut Rng, step: usize) {
    let scratch = scene_from_scratch(
        world,
        world.resource::<Frame>().update.origin,
        Color::ZERO,
        BuildQuality::Medium,
    );
    let frame_error = world.resource::<Frame>().error.clone();
    let (scratch, entities) = match scratch {
        Ok(s) => {
            assert_eq!(frame_error, None, "step {step}");
            s
        }
        Err(e) => {
            // The frame fails with the same message; nothing to trace.
            assert_eq!(frame_error.as_deref(), Some(e.as_str()), "step {step}");
            return;
        }
    };
    let sync = world.resource::<SceneSync>();
    let scene = world.resource::<SceneAccel>().scene.clone().unwrap();
    assert_eq!(
        scene.instances().len(),
        scratch.instances().len(),
        "step {step}"
    );
    assert_eq!(scene.lights(), scratch.lights(), "step {step}");
    let entity_of = |i: u32| sync.entity(i).unwrap();
    let mut rays = Vec::new();
    for _ in 0..200 {
        let origin = rng.vec(-16.0, 16.0);
        let target = if rng.below(2) == 0 || scratch.instances().is_empty() {
            rng.vec(-10.0, 10.0)
        } else {
            let i = rng.below(scratch.instances().len());
            let c = scratch.instances()[i].transform.to_world.translation;
            Vec3::from(c) + rng.vec(-0.8, 0.8)
        };
        let d = Vec3A::from(target - origin).normalize_or(Vec3A::Y);
        rays.push(Ray::new(origin.into(), d));
    }
    for (k, ray) in rays.iter().enumerate() {
        let what = format!("step {step} ray {k}");
        let a = scene.intersect(ray, 0.0, f32::INFINITY);
        let b = scratch.intersect(ray, 0.0, f32::INFINITY);
        same_hit(a, b, (&scene, &entity_of), (&scratch, &entities), &what);
        let t_max = rng.range(0.0, 30.0);
        assert_eq!(
            scene.occluded(ray, 0.0, t_max),
            scratch.occluded(ray, 0.0, t_max),
            "{what}: occlusion"
        );
    }
    for (c, chunk) in rays.chunks(prism::accel::packet::LANES).enumerate() {
        let mut a = vec![None; chunk.len()];
        let mut b = vec![None; chunk.len()];
        scene.intersect_packet(chunk, &mut a);
        scratch.intersect_packet(chunk, &mut b);
        for l in 0..chunk.len() {
            let what = format!("step {step} packet {c} lane {l}");
            same_hit(
                a[l],
                b[l],
                (&scene, &entity_of),
                (&scratch, &entities),
                &what,
            );
        }
        let t_max: Vec<f32> = chunk.iter().map(|_| rng.range(0.0, 30.0)).collect();
        assert_eq!(
            scene.occluded_packet(chunk, &t_max),
            scratch.occluded_packet(chunk, &t_max),
            "step {step} packet {c}: occlusion"
        );
    }
}

/// Random sequences of spawn, despawn, move, re-mesh, re-material and
/// light moves; after each frame the incrementally updated scene answers
/// every ray exactly like a scene built from scratch.
fn random_sequence(seed: u64, policy: TlasPolicy, steps: usize) {
    let meshes = meshes();
    let mut rng = Rng(seed);
    let (mut world, mut schedule) = new_world(1);
    let mut objects: Vec<Entity> = (0..12)
        .map(|_| spawn_object(&mut world, &mut rng, &meshes))
        .collect();
    let light = world
        .spawn((
            Transform::from_translation(glam::DVec3::new(0.0, 8.0, 0.0)),
            Light::Point {
                intensity: Color::splat(100.0),
            },
        ))
        .id();
    run_frame(&mut world, &mut schedule);
    set_policy(&mut world, policy);
    compare_with_scratch(&mut world, &mut rng, 0);
    let mut counts = [0usize; 6];
    for step in 1..=steps {
        // A few operations per frame, sometimes many (to cross the churn
        // threshold).
        let ops = if rng.below(8) == 0 {
            12
        } else {
            1 + rng.below(3)
        };
        for _ in 0..ops {
            let op = rng.below(6);
            counts[op] += 1;
            match op {
                0 => objects.push(spawn_object(&mut world, &mut rng, &meshes)),
                1 if !objects.is_empty() => {
                    let e = objects.swap_remove(rng.below(objects.len()));
                    world.despawn(e);
                }
                2 if !objects.is_empty() => {
                    let e = objects[rng.below(objects.len())];
                    let t = random_transform(&mut rng);
                    *world.get_mut::<Transform>(e).unwrap() = t;
                }
                3 if !objects.is_empty() => {
                    let e = objects[rng.below(objects.len())];
                    random_geometry(&mut world, e, &mut rng, &meshes);
                }
                4 if !objects.is_empty() => {
                    let e = objects[rng.below(objects.len())];
                    if rng.below(5) == 0 {
                        world.entity_mut(e).remove::<Material>();
                    } else {
                        let m = random_material(&mut rng);
                        world.entity_mut(e).insert(m);
                    }
                }
                _ => {
                    let p = rng.vec(-8.0, 8.0);
                    *world.get_mut::<Transform>(light).unwrap() =
                        Transform::from_translation(p.as_dvec3());
                }
            }
        }
        run_frame(&mut world, &mut schedule);
        assert!(!world.resource::<Frame>().update.reset, "step {step}");
        compare_with_scratch(&mut world, &mut rng, step);
    }
    let c = world.resource::<Frame>().update.tlas_counters;
    assert!(
        counts.iter().all(|&n| n > 0),
        "every operation ran: {counts:?}"
    );
    // The incremental paths were exercised, not only rebuilds.
    assert!(c.inserts > 0 && c.removes > 0, "{c:?}");
    match policy.moves {
        MoveStrategy::Refit => assert!(c.refits > 0, "{c:?}"),
        MoveStrategy::Reinsert => assert!(c.reinserts > 0, "{c:?}"),
    }
}

#[test]
fn random_updates_match_scratch_with_reinsertion() {
    for seed in [1, 2, 3] {
        random_sequence(seed, TlasPolicy::default(), 60);
    }
}

#[test]
fn random_updates_match_scratch_with_refits_and_no_rebuilds() {
    let policy = TlasPolicy {
        moves: MoveStrategy::Refit,
        rebuild_fraction: f32::INFINITY,
        rebuild_below: 0,
    };
    for seed in [4, 5, 6] {
        random_sequence(seed, policy, 60);
    }
}

#[test]
fn random_updates_match_scratch_with_reinsertion_and_no_rebuilds() {
    let policy = TlasPolicy {
        rebuild_fraction: f32::INFINITY,
        ..Default::default()
    };
    for seed in [7, 8] {
        random_sequence(seed, policy, 80);
    }
}

/// Renders `world`'s scene once, from scratch, with `spp` samples.
fn reference_film(world: &mut World, spp: u32) -> prism::image::film::Film {
    let (mut scene, _) = scene_from_scratch(
        world,
        world.resource::<Frame>().update.origin,
        Color::ZERO,
        BuildQuality::Medium,
    )
    .unwrap();
    scene.set_fog(world.resource::<RenderConfig>().fog);
    let mut settings = world.resource::<RenderConfig>().settings.clone();
    settings.spp = spp;
    let mut q = world.query::<&Camera>();
    let camera = q.single(world).unwrap().clone();
    prism::integrators::recursive::render(&scene, &camera, &settings, None).0
}

fn progressive_world(spp: u32, transport: Transport) -> (World, Schedule, Entity) {
    let meshes = meshes();
    let mut rng = Rng(11);
    let (mut world, schedule) = plugin_world(
        PrismPlugin::new()
            .settings(RenderSettings {
                width: 24,
                height: 16,
                spp,
                max_depth: 2,
                seed: 3,
                transport,
                ..Default::default()
            })
            .progressive(true),
    );
    let objects: Vec<Entity> = (0..8)
        .map(|_| spawn_object(&mut world, &mut rng, &meshes))
        .collect();
    for o in &objects {
        // Keep every transform valid and bounded.
        let t = Transform::from_translation(rng.vec(-6.0, 6.0).as_dvec3());
        *world.get_mut::<Transform>(*o).unwrap() = t;
    }
    world.spawn((
        Transform::from_translation(glam::DVec3::new(2.0, 9.0, 6.0)),
        Light::Point {
            intensity: Color::splat(300.0),
        },
    ));
    world.spawn(Camera {
        look_from: glam::DVec3::new(0.0, 4.0, 22.0),
        ..Default::default()
    });
    (world, schedule, objects[0])
}

/// Frame k of an unchanged scene is bit for bit the image of k * spp
/// samples; any change starts again from spp samples.
#[test]
fn progressive_frames_equal_renders_of_all_their_samples() {
    for (spp, transport) in [
        (1, Transport::Whitted),
        (2, Transport::Whitted),
        (1, Transport::Path),
        (3, Transport::Path),
    ] {
        let (mut world, mut schedule, object) = progressive_world(spp, transport);
        for k in 1..=4 {
            run_frame(&mut world, &mut schedule);
            let frame = world.resource::<Frame>();
            assert_eq!(frame.error, None);
            assert_eq!(frame.samples, k * spp, "spp {spp} {transport:?} frame {k}");
            let film = frame.film.clone().unwrap();
            assert_eq!(
                film,
                reference_film(&mut world, k * spp),
                "spp {spp} {transport:?} frame {k}"
            );
        }
        // An object moves: back to spp samples, of the new scene.
        world.get_mut::<Transform>(object).unwrap().0.translation.y += 0.5;
        run_frame(&mut world, &mut schedule);
        let film = world.resource::<Frame>().film.clone().unwrap();
        assert_eq!(world.resource::<Frame>().samples, spp);
        assert_eq!(
            film,
            reference_film(&mut world, spp),
            "spp {spp} after a move"
        );
        // A material changes.
        world.entity_mut(object).insert(Material {
            base_color: Color::new(0.9, 0.1, 0.1),
            ..Default::default()
        });
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, spp);
        // Accumulates again, then the camera moves.
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, 2 * spp);
        let mut q = world.query::<&mut Camera>();
        q.single_mut(&mut world).unwrap().look_from.x += 1.0;
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, spp);
        let film = world.resource::<Frame>().film.clone().unwrap();
        assert_eq!(
            film,
            reference_film(&mut world, spp),
            "spp {spp} after the camera"
        );
        // Settings change.
        world.resource_mut::<RenderConfig>().settings.seed = 9;
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, spp);
        // A fog appears (path transport renders it; Whitted attenuates).
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, 2 * spp);
        world.resource_mut::<RenderConfig>().fog = Some(
            prism::core::medium::Medium::checked(Color::splat(0.05), Color::splat(0.2), 0.0)
                .unwrap(),
        );
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, spp, "after the fog");
        let film = world.resource::<Frame>().film.clone().unwrap();
        assert_eq!(
            film,
            reference_film(&mut world, spp),
            "spp {spp} after the fog"
        );
        // Turned off: plain frames of spp samples.
        world.resource_mut::<ProgressiveRendering>().enabled = false;
        run_frame(&mut world, &mut schedule);
        run_frame(&mut world, &mut schedule);
        assert_eq!(world.resource::<Frame>().samples, spp);
    }
}

/// The scene persists across frames rendered by either integrator: the
/// wavefront's per-frame copy of the scene does not force a rebuild, and
/// both integrators agree on the updated scene.
#[test]
fn integrators_share_the_persistent_scene() {
    let (mut world, mut schedule, object) = progressive_world(1, Transport::Whitted);
    world.resource_mut::<ProgressiveRendering>().enabled = false;
    let mut films = Vec::new();
    for step in 0..4 {
        for kind in IntegratorKind::ALL {
            world.resource_mut::<RenderConfig>().integrator = kind;
            run_frame(&mut world, &mut schedule);
            let frame = world.resource::<Frame>();
            assert_eq!(frame.error, None);
            assert_eq!(frame.update.reset, step == 0 && films.is_empty());
            assert_eq!(
                frame.update.tlas_counters.rebuilds, 1,
                "{step} {kind:?} {:?}",
                frame.update
            );
            films.push(frame.film.clone().unwrap());
        }
        let n = films.len();
        let (a, b) = (&films[n - 2], &films[n - 1]);
        for (p, q) in a.pixels.iter().zip(&b.pixels) {
            assert!((*p - *q).abs().max_element() <= 1e-4 * p.abs().max_element().max(1.0));
        }
        world.get_mut::<Transform>(object).unwrap().0.translation.x += 0.25;
    }
}

/// An invalid transform fails the frame with a message naming the entity;
/// fixing it brings the object back.
#[test]
fn invalid_transforms_fail_the_frame_until_fixed() {
    let (mut world, mut schedule) = new_world(1);
    let e = world
        .spawn((
            Transform::from(Affine3A::from_scale(Vec3::new(f32::NAN, 1.0, 1.0))),
            Shape::Sphere { radius: 1.0 },
        ))
        .id();
    run_frame(&mut world, &mut schedule);
    let err = world.resource::<Frame>().error.clone().unwrap();
    assert!(err.contains(&format!("entity {e}")), "{err}");
    assert!(world.resource::<Frame>().film.is_none());
    *world.get_mut::<Transform>(e).unwrap() = Transform::default();
    run_frame(&mut world, &mut schedule);
    assert_eq!(world.resource::<Frame>().error, None);
    assert_eq!(world.resource::<Frame>().update.added, 1);
    assert_eq!(world.resource::<SceneSync>().instance(e), Some(0));
}

/// A change of BVH quality starts a fresh scene (rebuilt once).
#[test]
fn quality_change_resets_the_scene() {
    let (mut world, mut schedule, _) = progressive_world(1, Transport::Whitted);
    run_frame(&mut world, &mut schedule);
    run_frame(&mut world, &mut schedule);
    assert!(!world.resource::<Frame>().update.reset);
    assert_eq!(world.resource::<Frame>().update.tlas, TlasUpdate::Unchanged);
    world.resource_mut::<RenderConfig>().bvh_quality = BuildQuality::Fast;
    run_frame(&mut world, &mut schedule);
    let u = world.resource::<Frame>().update;
    assert!(u.reset);
    assert_eq!(u.added, 8);
    assert_eq!(u.tlas, TlasUpdate::Rebuilt);
    let _ = systems::setup;
}

/// Every pixel of `film` within 1e-4 relative (1e-6 absolute) of
/// `reference`'s: what the integrators agree to.
fn assert_films_agree(film: &[Color], reference: &[Color], what: &str) {
    for (p, r) in film.iter().zip(reference) {
        let d = (*p - *r).abs().max_element();
        assert!(
            d <= 1e-6 || d <= 1e-4 * r.max_element(),
            "{what}: {p} vs {r}"
        );
    }
}

/// Area lights follow their entities: after moving an emissive square and
/// then changing its material, the incrementally updated scene renders
/// (path transport, both integrators) exactly what a scene built from
/// scratch renders.
#[test]
fn area_lights_follow_moves_and_material_changes() {
    let settings = RenderSettings {
        width: 20,
        height: 16,
        spp: 4,
        max_depth: 2,
        seed: 5,
        transport: Transport::Path,
        ..Default::default()
    };
    let (mut world, mut schedule) = plugin_world(PrismPlugin::new().settings(settings.clone()));
    world.spawn((Transform::default(), Shape::Plane, Material::default()));
    let glow = |e: f32| Material {
        base_color: Color::ZERO,
        diffuse: 0.0,
        emission: Color::splat(e),
        ..Default::default()
    };
    let light = world
        .spawn((
            Transform::from_translation(glam::DVec3::new(0.0, 2.0, 0.0)),
            // A polygon: its area-light entries are stored in world space,
            // so a stale table would light from the old place.
            Shape::Polygon {
                vertices: vec![
                    Vec3::new(-0.5, 0.0, -0.5),
                    Vec3::new(-0.5, 0.0, 0.5),
                    Vec3::new(0.5, 0.0, 0.5),
                    Vec3::new(0.5, 0.0, -0.5),
                ]
                .into(),
            },
            glow(4.0),
        ))
        .id();
    world.spawn(Camera {
        look_from: glam::DVec3::new(0.0, 1.0, 4.0),
        look_at: glam::DVec3::ZERO,
        ..Default::default()
    });
    let check = |world: &mut World, schedule: &mut Schedule, what: &str| {
        for kind in IntegratorKind::ALL {
            world.resource_mut::<RenderConfig>().integrator = kind;
            run_frame(world, schedule);
            let film = world.resource::<Frame>().film.clone().unwrap();
            let (scene, _) = scene_from_scratch(
                world,
                world.resource::<Frame>().update.origin,
                Color::ZERO,
                BuildQuality::Medium,
            )
            .unwrap();
            assert!(!scene.emitters().is_empty() || what == "dark");
            let mut q = world.query::<&Camera>();
            let camera = q.single(world).unwrap().clone();
            let reference =
                prism::integrators::recursive::render(&scene, &camera, &settings, None).0;
            assert_films_agree(&film.pixels, &reference.pixels, &format!("{what} {kind:?}"));
            assert!(film.pixels.iter().any(|p| p.max_element() > 0.0) || what == "dark");
        }
    };
    check(&mut world, &mut schedule, "first frame");
    world.get_mut::<Transform>(light).unwrap().0.translation = glam::DVec3::new(1.0, 1.5, -0.5);
    check(&mut world, &mut schedule, "moved");
    world.entity_mut(light).insert(glow(0.0));
    check(&mut world, &mut schedule, "dark");
}

/// Merged mesh instances in the frame loop (`RenderConfig::merge_meshes`):
/// three meshes of their own are merged at the first frame, which renders
/// (path transport, every integrator) what a scene built from scratch and
/// merged the same way renders; moving one of them undoes the group, and
/// the next frames render what an unmerged scene built from scratch
/// renders, as every incremental update does.
#[test]
fn merged_meshes_follow_the_frame_loop() {
    let settings = RenderSettings {
        width: 24,
        height: 16,
        spp: 4,
        max_depth: 3,
        seed: 9,
        transport: Transport::Path,
        ..Default::default()
    };
    let (mut world, mut schedule) = plugin_world(PrismPlugin::new().settings(settings.clone()));
    world.resource_mut::<RenderConfig>().merge_meshes = true;
    let knots: Vec<Entity> = meshes()
        .into_iter()
        .enumerate()
        .map(|(k, m)| {
            world
                .spawn((
                    Transform::from_translation(glam::DVec3::new(2.5 * k as f64 - 2.5, 0.0, 0.0)),
                    MeshInstance(m),
                    Material::default(),
                ))
                .id()
        })
        .collect();
    world.spawn((
        Transform::from_translation(glam::DVec3::new(0.0, 6.0, 4.0)),
        Light::Point {
            intensity: Color::splat(60.0),
        },
    ));
    world.spawn(Camera {
        look_from: glam::DVec3::new(0.0, 1.0, 9.0),
        look_at: glam::DVec3::ZERO,
        ..Default::default()
    });
    let check = |world: &mut World, schedule: &mut Schedule, merged: usize, what: &str| {
        for kind in IntegratorKind::ALL {
            world.resource_mut::<RenderConfig>().integrator = kind;
            run_frame(world, schedule);
            let scene = world.resource::<SceneAccel>().scene.clone().unwrap();
            assert_eq!(scene.merged_instances(), merged, "{what} {kind:?}");
            let film = world.resource::<Frame>().film.clone().unwrap();
            let (mut reference, _) = scene_from_scratch(
                world,
                world.resource::<Frame>().update.origin,
                Color::ZERO,
                BuildQuality::Medium,
            )
            .unwrap();
            reference.set_mesh_merging(merged > 0);
            reference.commit();
            assert_eq!(reference.merged_instances(), merged, "{what}: reference");
            let mut q = world.query::<&Camera>();
            let camera = q.single(world).unwrap().clone();
            let want =
                prism::integrators::recursive::render(&reference, &camera, &settings, None).0;
            assert_films_agree(&film.pixels, &want.pixels, &format!("{what} {kind:?}"));
            assert!(
                film.pixels.iter().any(|p| p.max_element() > 0.0),
                "{what}: black"
            );
        }
    };
    check(&mut world, &mut schedule, 3, "first frames");
    world.get_mut::<Transform>(knots[1]).unwrap().0.translation = glam::DVec3::new(0.0, 1.0, 0.0);
    check(&mut world, &mut schedule, 0, "after a move");
}
