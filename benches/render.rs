//! Criterion benchmarks of whole renders.
//!
//! `cargo bench --bench render` renders the classic Whitted scene (mirror
//! and glass spheres over a checkered plane, depth 8), the quadrics
//! showcase and the glTF showroom at 320x240, one sample per pixel, with
//! the recursive integrator. Throughput is reported in camera rays
//! (pixels) per second; `prism render --stats` gives rays of every kind.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use prism::camera::Camera;
use prism::integrator::{self, IntegratorKind, RenderSettings};
use prism::mesh::BuildQuality;
use prism::scene::RenderScene;
use prism::systems;

const W: u32 = 320;
const H: u32 = 240;

/// Loads a scene and builds its BVH once, through the ECS stages.
fn prepare(name: &str) -> (std::sync::Arc<RenderScene>, Camera) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name);
    let desc = prism::loader::load(&path, BuildQuality::Medium).expect("load scene");
    let camera = desc.cameras[0].clone();
    let mut world = bevy_ecs::world::World::new();
    let mut schedule = systems::setup(&mut world);
    world.resource_mut::<systems::RenderConfig>().background = desc.background;
    systems::spawn_scene(&mut world, desc);
    // One tiny frame builds the scene; the benchmark then renders from it.
    world.resource_mut::<systems::RenderConfig>().settings = RenderSettings {
        width: 1,
        height: 1,
        ..Default::default()
    };
    schedule.run(&mut world);
    let scene = world
        .resource::<systems::SceneAccel>()
        .scene
        .clone()
        .expect("scene built");
    (scene, camera)
}

fn bench_scenes(c: &mut Criterion) {
    let mut group = c.benchmark_group("recursive");
    group.sample_size(10);
    group.throughput(Throughput::Elements((W * H) as u64));
    for name in ["whitted.toml", "quadrics.toml", "gltf/showroom.gltf"] {
        let (scene, camera) = prepare(name);
        let settings = RenderSettings {
            width: W,
            height: H,
            spp: 1,
            max_depth: 8,
            ..Default::default()
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                integrator::render(IntegratorKind::Recursive, &scene, &camera, &settings, None)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_scenes);
criterion_main!(benches);
