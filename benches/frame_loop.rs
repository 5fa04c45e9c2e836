//! The game-style frame loop, and the top-level update it relies on.
//!
//! `cargo bench --bench frame_loop`
//!
//! * `frame_loop/{recursive,wavefront}`: one frame of the animated demo
//!   scene (`prism::systems::demo`: four torus knots of 25,000 triangles,
//!   16 orbiting spheres, a mirror, a ground plane, two point lights, one
//!   of them moving) at 640x360, Whitted with shadows, `max_depth` 2, one
//!   sample per pixel. Each iteration advances the animation and runs the
//!   whole schedule (animation, scene sync, BVH update, render). After
//!   each function the share of the frame spent updating the scene, the
//!   rays per frame and the kind of top-level updates are printed.
//!   `recursive_rebuild_every_frame` forces a top-level rebuild each frame
//!   instead of leaf reinsertion, to compare tree quality (render time).
//! * `tlas_update/...`: the top level of 1,000 instances after moving a
//!   fraction of them, updated leaf by leaf (`reinsert`, `refit`) or
//!   rebuilt (`rebuild`): the measurement behind
//!   `prism::accel::tlas::DEFAULT_REBUILD_FRACTION`.

use std::sync::Arc;
use std::time::Duration;

use bevy_ecs::prelude::*;
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use glam::Vec3;
use prism::accel::tlas::{MoveStrategy, TlasPolicy, TlasUpdate};
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::BuildQuality;
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::integrators::IntegratorKind;
use prism::scene::material::Material;
use prism::scene::{Instance, InstanceGeometry, RenderScene};
use prism::systems::demo::{AnimationTime, DemoScene, add_animation};
use prism::systems::{Frame, PrismPlugin, RenderConfig, run_frame};

fn frame_loop(c: &mut Criterion) {
    let mut group = c.benchmark_group("frame_loop");
    group.sample_size(20);
    group.measurement_time(Duration::from_secs(8));
    let variants = [
        (IntegratorKind::Recursive, None),
        (IntegratorKind::Wavefront, None),
        (
            IntegratorKind::Recursive,
            Some(TlasPolicy {
                rebuild_fraction: 0.0,
                ..Default::default()
            }),
        ),
    ];
    for (kind, policy) in variants {
        let name = match policy {
            None => kind.name().to_string(),
            Some(_) => format!("{}_rebuild_every_frame", kind.name()),
        };
        let mut world = World::new();
        let mut schedule = Schedule::default();
        add_animation(&mut world, &mut schedule);
        let demo = DemoScene::default();
        let triangles = demo.triangle_count();
        let camera = demo.spawn(&mut world);
        PrismPlugin::new()
            .config(RenderConfig {
                settings: RenderSettings {
                    width: 640,
                    height: 360,
                    spp: 1,
                    max_depth: 2,
                    ..Default::default()
                },
                integrator: kind,
                camera: Some(camera),
                ..Default::default()
            })
            .build(&mut world, &mut schedule);
        run_frame(&mut world, &mut schedule);
        if let Some(p) = policy {
            let mut accel = world.resource_mut::<prism::systems::SceneAccel>();
            Arc::get_mut(accel.scene.as_mut().unwrap())
                .unwrap()
                .set_tlas_policy(p);
        }
        let mut frame_no = 1u32;
        let mut sums = [0.0f64; 3];
        let mut rays = 0u64;
        let mut updates = std::collections::BTreeMap::new();
        let mut frames = 0u32;
        group.bench_function(&name, |b| {
            b.iter(|| {
                world.resource_mut::<AnimationTime>().0 = frame_no as f32 / 30.0;
                frame_no += 1;
                run_frame(&mut world, &mut schedule);
                let f = world.resource::<Frame>();
                assert!(f.error.is_none() && f.film.is_some());
                assert!(
                    f.update.moved > 0 && f.update.mesh_bvh_builds > 0,
                    "frame {frame_no}: {:?}",
                    f.update
                );
                sums[0] += f.update.sync_seconds;
                sums[1] += f.update.accel_seconds;
                sums[2] += f.render_seconds;
                rays += f.counters.rays.total();
                *updates.entry(format!("{:?}", f.update.tlas)).or_insert(0) += 1;
                frames += 1;
            })
        });
        if frames == 0 {
            // Filtered out on the command line: nothing ran, nothing to say.
            continue;
        }
        let [sync, accel, render] = sums.map(|s| s / frames.max(1) as f64);
        let total = sync + accel + render;
        let n = frames.max(1) as f64;
        eprintln!(
            "frame_loop/{name}: {triangles} triangles, {} threads; mean over {frames} frames: \
             sync {:.3} ms, BVH {:.3} ms ({updates:?}), render {:.1} ms ({:.2} Mrays, \
             {:.1} Mrays/s) -> {:.2} fps (stages only); scene update {:.2}% of the frame",
            rayon::current_num_threads(),
            sync * 1e3,
            accel * 1e3,
            render * 1e3,
            rays as f64 / n / 1e6,
            rays as f64 / n / 1e6 / render,
            1.0 / total,
            100.0 * (sync + accel) / total
        );
    }
    group.finish();
}

/// 1,000 spheres scattered in a 100-unit cube.
fn scattered(n: usize) -> (RenderScene, Vec<Vec3>) {
    let mut state = 7u64;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut positions = Vec::new();
    let mut instances = Vec::new();
    for i in 0..n {
        let p = Vec3::new(next(), next(), next()) * 100.0;
        positions.push(p);
        instances.push(Instance::new(
            InstanceGeometry::Shape(Shape::Sphere { radius: 0.5 }),
            &Transform::from_translation(p.as_dvec3()),
            i as u32,
        ));
    }
    let materials = vec![Material::default(); n];
    (
        RenderScene::new(
            instances,
            materials,
            Vec::new(),
            Vec3::ZERO,
            BuildQuality::Medium,
        ),
        positions,
    )
}

fn tlas_update(c: &mut Criterion) {
    const N: usize = 1000;
    let mut group = c.benchmark_group("tlas_update");
    group.sample_size(30);
    group.measurement_time(Duration::from_secs(3));
    for percent in [1usize, 5, 10, 25, 50, 100] {
        let moved = N * percent / 100;
        for (name, policy) in [
            (
                "reinsert",
                TlasPolicy {
                    moves: MoveStrategy::Reinsert,
                    rebuild_fraction: f32::INFINITY,
                    rebuild_below: 0,
                },
            ),
            (
                "refit",
                TlasPolicy {
                    moves: MoveStrategy::Refit,
                    rebuild_fraction: f32::INFINITY,
                    rebuild_below: 0,
                },
            ),
            (
                "rebuild",
                TlasPolicy {
                    rebuild_fraction: 0.0,
                    ..Default::default()
                },
            ),
        ] {
            let (mut scene, positions) = scattered(N);
            scene.set_tlas_policy(policy);
            let mut step = 0u32;
            group.bench_function(format!("{name}/{percent}%"), |b| {
                b.iter_batched(
                    || (),
                    |()| {
                        // Small moves, as from one frame to the next.
                        step += 1;
                        let d = Vec3::new(0.3, 0.0, 0.2) * ((step % 20) as f32 - 10.0) * 0.05;
                        for i in 0..moved {
                            let k = (i * 7 + step as usize) % N;
                            let t = Transform::from_translation((positions[k] + d).as_dvec3());
                            scene.set_instance_transform(k as u32, &t);
                        }
                        let u = scene.commit();
                        assert_ne!(u, TlasUpdate::Unchanged);
                    },
                    BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, frame_loop, tlas_update);
criterion_main!(benches);
