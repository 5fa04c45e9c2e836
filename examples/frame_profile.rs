//! Runs the frame-loop benchmark's scene (`benches/frame_loop.rs`) for a
//! few frames and prints what each frame did: a driver for profilers
//! (callgrind counts per frame) and for comparing images between builds.
//!
//! ```text
//! cargo run --release --example frame_profile -- [recursive|wavefront] [FRAMES] [OUT.exr]
//! ```
//!
//! Frame `k` shows the animation at time `k / 30` s, as in the benchmark;
//! with `OUT.exr` the last frame is written there (linear radiance).

use bevy_ecs::prelude::*;
use prism::core::settings::RenderSettings;
use prism::integrators::IntegratorKind;
use prism::systems::demo::{AnimationTime, DemoScene, add_animation};
use prism::systems::{Frame, PrismPlugin, RenderConfig, run_frame};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str) {
        Some("wavefront") => IntegratorKind::Wavefront,
        _ => IntegratorKind::Recursive,
    };
    let frames: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let mut world = World::new();
    let mut schedule = Schedule::default();
    add_animation(&mut world, &mut schedule);
    let camera = DemoScene::default().spawn(&mut world);
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
    for k in 0..frames {
        world.resource_mut::<AnimationTime>().0 = k as f32 / 30.0;
        let start = std::time::Instant::now();
        run_frame(&mut world, &mut schedule);
        let wall = start.elapsed().as_secs_f64();
        let f = world.resource::<Frame>();
        assert!(f.error.is_none(), "{:?}", f.error);
        let r = &f.counters.rays;
        eprintln!(
            "frame {k}: {:.1} ms (render {:.1} ms, sync {:.3} ms, BVH {:.3} ms); rays camera {} shadow {} reflection {} refraction {}",
            wall * 1e3,
            f.render_seconds * 1e3,
            f.update.sync_seconds * 1e3,
            f.update.accel_seconds * 1e3,
            r.camera,
            r.shadow,
            r.reflection,
            r.refraction
        );
    }
    if let Some(out) = args.get(3) {
        let film = world.resource::<Frame>().film.as_ref().expect("rendered");
        prism::image::output::write_image(out.as_ref(), film, &Default::default())
            .expect("writes the image");
    }
}
