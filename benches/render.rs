//! Criterion benchmarks of whole frames, through the ECS stages, for both
//! integrators on the same scenes and the same image.
//!
//! `cargo bench --bench render`. The `stage_gating` groups compare the
//! wavefront's feature-gated schedule with one forced to run every stage.
//! Each scene is loaded and spawned once;
//! every iteration runs one frame (extraction, top-level BVH, rendering)
//! at 320x240, one sample per pixel. Throughput is in camera rays
//! (pixels) per second; `prism bench` reports rays of every kind.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::BuildQuality;
use prism::integrators::IntegratorKind;
use prism::systems::{RenderConfig, Renderer};

const W: u32 = 320;
const H: u32 = 240;

fn prepare(name: &str) -> Renderer {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name);
    let desc = prism::io::load(&path, BuildQuality::Medium).expect("load scene");
    let max_depth = desc.settings.max_depth.unwrap_or(8);
    let config = RenderConfig {
        settings: RenderSettings {
            width: W,
            height: H,
            spp: 1,
            max_depth,
            ..Default::default()
        },
        ..Default::default()
    };
    Renderer::with_scene(desc, config, 0).expect("the scene has a camera")
}

fn bench_scenes(c: &mut Criterion) {
    for name in [
        "whitted.toml",
        "bench/camera_only.toml",
        "bench/glass_mirror.toml",
        "bench/many_lights.toml",
    ] {
        let mut group = c.benchmark_group(name);
        group.sample_size(10);
        group.throughput(Throughput::Elements((W * H) as u64));
        let mut renderer = prepare(name);
        for kind in IntegratorKind::ALL {
            renderer.config_mut().integrator = kind;
            group.bench_function(kind.name(), |b| {
                b.iter(|| assert!(renderer.run().film.is_some()))
            });
        }
        group.finish();
    }
}

/// Stage gating: the wavefront on a diffuse-only scene with its stages
/// gated by the scene's features, against the same schedule forced to run
/// every stage (the extra stages find empty queues).
fn bench_stage_gating(c: &mut Criterion) {
    use prism::core::settings::Transport;
    use prism::systems::wavefront::StageGating;
    for transport in [Transport::Whitted, Transport::Path] {
        let mut group = c.benchmark_group(format!("stage_gating/{}", transport.name()));
        group.sample_size(20);
        let mut renderer = prepare("bench/diffuse_only.toml");
        {
            let mut config = renderer.config_mut();
            config.integrator = IntegratorKind::Wavefront;
            config.settings.transport = transport;
        }
        for (name, force_all) in [("gated", false), ("every_stage", true)] {
            renderer.insert_resource(StageGating { force_all });
            group.bench_function(name, |b| b.iter(|| assert!(renderer.run().film.is_some())));
        }
        group.finish();
    }
}

criterion_group!(benches, bench_scenes, bench_stage_gating);
criterion_main!(benches);
