//! What each kind of change costs, by the counters of the frame: moving an
//! object builds no mesh BVH and updates one top-level leaf; changing a
//! material touches no BVH at all.
//!
//! This file holds a single test: the mesh BVH counter is process-wide,
//! and no other test may build meshes while it runs, so
//! `cargo test --test update_counters` is a binary of its own.

mod common;

use std::sync::Arc;

use bevy_ecs::prelude::*;
use prism::accel::tlas::{TlasCounters, TlasUpdate};
use prism::core::math::{Color, Ray};
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::{BuildQuality, Mesh, NormalMode, mesh_bvh_builds};
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::integrators::IntegratorKind;
use prism::scene::camera::Camera;
use prism::scene::light::Light;
use prism::scene::material::Material;
use prism::systems::MeshInstance;
use prism::systems::sync::SceneSync;
use prism::systems::wavefront::BatchSize;
use prism::systems::{Frame, PrismPlugin, RenderConfig, RenderOrigin, SceneAccel, run_frame};

use common::render::plugin_world;

fn knot(p: u32, q: u32) -> Arc<Mesh> {
    let data = prism::geometry::procedural::torus_knot(p, q, 1.0, 0.3, 64, 8);
    Arc::new(Mesh::new("knot", data, NormalMode::Smooth, BuildQuality::Medium).unwrap())
}

fn counters(world: &World) -> (TlasCounters, TlasUpdate, u64) {
    let u = world.resource::<Frame>().update;
    (u.tlas_counters, u.tlas, u.mesh_bvh_builds)
}

/// The material of the first hit along `ray` (in world coordinates: moved
/// into the scene's frame, centred on its render origin).
fn material_hit(world: &World, ray: &Ray) -> Color {
    let scene = world.resource::<SceneAccel>().scene.clone().unwrap();
    let origin = (ray.origin.as_dvec3() - scene.origin()).as_vec3a();
    let ray = Ray::new(origin, ray.direction);
    let hit = scene.intersect(&ray, 0.0, f32::INFINITY).expect("hit");
    scene.materials()[hit.material as usize].base_color
}

#[test]
fn each_change_does_only_its_own_work() {
    let knots = [knot(2, 3), knot(3, 5)];
    check(&knots, IntegratorKind::Recursive);
    // The wavefront on two threads with small batches runs two lanes
    // (worlds of their own), whose frame resources must not keep the
    // scene shared into the next frame's sync.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    pool.install(|| check(&knots, IntegratorKind::Wavefront));
}

fn check(knots: &[Arc<Mesh>; 2], integrator: IntegratorKind) {
    let built = mesh_bvh_builds();
    assert!(built >= 2);
    let (mut world, mut schedule) = plugin_world(PrismPlugin::new().config(RenderConfig {
        settings: RenderSettings {
            width: 16,
            height: 12,
            max_depth: 2,
            ..Default::default()
        },
        integrator,
        ..Default::default()
    }));
    world.insert_resource(BatchSize(32));
    // 20 objects on a grid: one change is 5% churn, below the threshold.
    let mut objects = Vec::new();
    for i in 0..20 {
        let t = Transform::from_translation(glam::DVec3::new(
            (i % 5) as f64 * 3.0,
            (i / 5) as f64 * 3.0,
            0.0,
        ));
        let mut e = world.spawn((t, Material::default()));
        if i % 2 == 0 {
            e.insert(MeshInstance(knots[i % 4 / 2].clone()));
        } else {
            e.insert(Shape::Sphere { radius: 1.0 });
        }
        objects.push(e.id());
    }
    world.spawn((
        Transform::from_translation(glam::DVec3::new(0.0, 5.0, 10.0)),
        Light::Point {
            intensity: Color::splat(100.0),
        },
    ));
    world.spawn(Camera {
        look_from: glam::DVec3::new(6.0, 4.5, 30.0),
        look_at: glam::DVec3::new(6.0, 4.5, 0.0),
        ..Default::default()
    });
    run_frame(&mut world, &mut schedule);
    if integrator == IntegratorKind::Wavefront {
        let lanes = world.resource::<Frame>().wavefront.unwrap().lanes;
        assert_eq!(lanes, 2, "the wavefront ran {lanes} lanes");
    }
    let (c0, u0, m0) = counters(&world);
    assert_eq!(u0, TlasUpdate::Rebuilt);
    assert_eq!(m0, built, "the first frame built a mesh BVH");
    assert_eq!(c0.rebuilds, 1);
    assert_eq!(world.resource::<Frame>().update.added, 20);

    // Nothing changes: no work at all.
    run_frame(&mut world, &mut schedule);
    assert_eq!(counters(&world), (c0, TlasUpdate::Unchanged, m0));
    assert!(!world.resource::<Frame>().update.changed());

    // Move one mesh object: one leaf reinserted, one conversion, no mesh
    // BVH built, no rebuild.
    world
        .get_mut::<Transform>(objects[0])
        .unwrap()
        .0
        .translation
        .z -= 4.0;
    run_frame(&mut world, &mut schedule);
    let (c1, u1, m1) = counters(&world);
    assert_eq!(u1, TlasUpdate::Incremental);
    assert_eq!(m1, m0, "moving an object built a mesh BVH");
    assert_eq!(
        c1,
        TlasCounters {
            reinserts: c0.reinserts + 1,
            conversions: c0.conversions + 1,
            ..c0
        }
    );
    assert_eq!(world.resource::<Frame>().update.moved, 1);

    // Change a material: no BVH touched, and the new material is hit.
    let ray = Ray::new(
        glam::Vec3A::new(3.0, 0.0, 20.0),
        glam::Vec3A::new(0.0, 0.0, -1.0),
    );
    assert_eq!(material_hit(&world, &ray), Color::splat(0.8));
    world.entity_mut(objects[1]).insert(Material {
        base_color: Color::new(0.1, 0.2, 0.9),
        ..Default::default()
    });
    run_frame(&mut world, &mut schedule);
    assert_eq!(counters(&world), (c1, TlasUpdate::Unchanged, m1));
    assert_eq!(world.resource::<Frame>().update.rematerial, 1);
    assert!(world.resource::<Frame>().update.changed());
    assert_eq!(material_hit(&world, &ray), Color::new(0.1, 0.2, 0.9));

    // Re-mesh: the other (already built) mesh; one leaf, no mesh BVH.
    world
        .entity_mut(objects[0])
        .insert(MeshInstance(knots[1].clone()));
    run_frame(&mut world, &mut schedule);
    let (c2, u2, m2) = counters(&world);
    assert_eq!(u2, TlasUpdate::Incremental);
    assert_eq!(m2, m1, "re-meshing built a mesh BVH");
    assert_eq!(c2.reinserts, c1.reinserts + 1);
    assert_eq!(c2.rebuilds, c1.rebuilds);
    assert_eq!(world.resource::<Frame>().update.regeometry, 1);

    // Spawn and despawn: one insert, one removal.
    let extra = world
        .spawn((
            Transform::from_translation(glam::DVec3::new(20.0, 0.0, 0.0)),
            Shape::Sphere { radius: 0.5 },
        ))
        .id();
    world.despawn(objects[3]);
    run_frame(&mut world, &mut schedule);
    let (c3, u3, m3) = counters(&world);
    assert_eq!(u3, TlasUpdate::Incremental);
    assert_eq!(m3, m2);
    assert_eq!(
        c3,
        TlasCounters {
            inserts: c2.inserts + 1,
            removes: c2.removes + 1,
            conversions: c2.conversions + 1,
            ..c2
        }
    );
    let u = world.resource::<Frame>().update;
    assert_eq!((u.added, u.removed), (1, 1));
    assert!(world.resource::<SceneSync>().instance(extra).is_some());
    assert!(world.resource::<SceneSync>().instance(objects[3]).is_none());

    // Churn above the threshold (more leaf changes than instances at the
    // last commit: 5 of the 20 despawned, the other 15 moved, 2 spawned):
    // one rebuild.
    let live: Vec<Entity> = objects
        .iter()
        .copied()
        .filter(|&e| e != objects[3])
        .chain([extra])
        .collect();
    assert_eq!(live.len(), 20);
    for &e in &live[..5] {
        world.despawn(e);
    }
    for &e in &live[5..] {
        world.get_mut::<Transform>(e).unwrap().0.translation.y += 0.5;
    }
    for x in [30.0, 33.0] {
        world.spawn((
            Transform::from_translation(glam::DVec3::new(x, 0.0, 0.0)),
            Shape::Sphere { radius: 0.5 },
        ));
    }
    run_frame(&mut world, &mut schedule);
    let (c4, u4, m4) = counters(&world);
    assert_eq!(u4, TlasUpdate::Rebuilt);
    assert_eq!(c4.rebuilds, c3.rebuilds + 1);
    assert_eq!(m4, m3, "a top-level rebuild built a mesh BVH");
    let u = world.resource::<Frame>().update;
    assert_eq!((u.removed, u.added, u.moved), (5, 2, 15));
    assert_eq!(mesh_bvh_builds(), built);

    // The camera moves within the recentring distance: the render origin
    // stays, nothing is re-committed.
    let origin = world.resource::<Frame>().update.origin;
    let camera = world
        .query_filtered::<Entity, With<Camera>>()
        .single(&world)
        .unwrap();
    world.get_mut::<Camera>(camera).unwrap().look_from.x += 10.0;
    run_frame(&mut world, &mut schedule);
    let (c5, u5, m5) = counters(&world);
    assert_eq!(u5, TlasUpdate::Unchanged);
    assert_eq!((c5, m5), (c4, m4));
    assert_eq!(world.resource::<Frame>().update.origin, origin);
    assert!(!world.resource::<Frame>().update.rebased);

    // The camera travels 1e7 units: the render origin follows it. Every
    // instance and light is re-expressed relative to it (a top-level
    // update of every leaf, or a rebuild above the churn threshold), and
    // no mesh BVH is built.
    let far = glam::DVec3::new(1e7, -2e7, 3e7);
    world.get_mut::<Camera>(camera).unwrap().look_from += far;
    world.get_mut::<Camera>(camera).unwrap().look_at += far;
    run_frame(&mut world, &mut schedule);
    let (c6, u6, m6) = counters(&world);
    let u = world.resource::<Frame>().update;
    assert!(u.rebased && u.changed());
    assert_eq!(u.origin, origin + glam::DVec3::new(10.0, 0.0, 0.0) + far);
    let leaves = (c6.reinserts + c6.refits) - (c5.reinserts + c5.refits);
    assert!(
        (u6 == TlasUpdate::Rebuilt && c6.rebuilds == c5.rebuilds + 1)
            || (u6 == TlasUpdate::Incremental && leaves == 17),
        "{u6:?} {c5:?} {c6:?}"
    );
    assert_eq!(m6, m5, "moving the render origin built a mesh BVH");
    assert_eq!(mesh_bvh_builds(), built);

    // A fixed origin chosen by the game: the same, once.
    world.insert_resource(RenderOrigin::Fixed(glam::DVec3::new(5.0, 5.0, 5.0)));
    run_frame(&mut world, &mut schedule);
    let u = world.resource::<Frame>().update;
    assert!(u.rebased);
    assert_eq!(u.origin, glam::DVec3::splat(5.0));
    assert_eq!(u.mesh_bvh_builds, built);
    run_frame(&mut world, &mut schedule);
    assert!(!world.resource::<Frame>().update.rebased);
    assert_eq!(world.resource::<Frame>().update.tlas, TlasUpdate::Unchanged);
}
