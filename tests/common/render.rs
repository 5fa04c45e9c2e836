//! Rendering through [`Renderer`]: the world recipe (a world with Prism's
//! resources and schedule, the scene's entities, a configuration, one
//! frame) written once.

use std::path::Path;

use bevy_ecs::prelude::*;
use prism::core::settings::RenderSettings;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::io::desc::SceneDesc;
use prism::systems::{Frame, PrismPlugin, RenderConfig, Renderer};

use super::scenes;

/// `settings` rendered by `integrator`, everything else by default.
pub fn config(settings: RenderSettings, integrator: IntegratorKind) -> RenderConfig {
    RenderConfig {
        settings,
        integrator,
        ..Default::default()
    }
}

/// Default settings at `width` x `height`.
pub fn sized(width: u32, height: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        ..Default::default()
    }
}

/// A renderer of `desc` from its first camera, configured by `config`.
pub fn renderer(desc: SceneDesc, config: RenderConfig) -> Renderer {
    Renderer::with_scene(desc, config, 0).unwrap()
}

/// One frame of `desc` from its first camera.
pub fn render_desc(desc: SceneDesc, config: RenderConfig) -> Frame {
    renderer(desc, config).render().unwrap()
}

/// One frame of the scene file at `path`.
pub fn render_file(path: &Path, config: RenderConfig) -> Frame {
    render_desc(scenes::load(path), config)
}

/// One frame of scene text (TOML).
pub fn render_toml(text: &str, config: RenderConfig) -> Frame {
    render_desc(scenes::load_toml(text).unwrap(), config)
}

/// `render(kind)` for every integrator on a pool of 1, then of 2 threads:
/// `(threads, integrator, film)` in that order (recursive then wavefront
/// on 1 thread, then on 2), for tests that ask for the same image
/// whatever the integrator and the thread count.
pub fn on_one_and_two_threads(
    render: impl Fn(IntegratorKind) -> Film + Sync,
) -> Vec<(usize, IntegratorKind, Film)> {
    let mut films = Vec::new();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for kind in IntegratorKind::ALL {
            films.push((threads, kind, pool.install(|| render(kind))));
        }
    }
    films
}

/// A game's own world and schedule with `plugin` added.
pub fn plugin_world(plugin: PrismPlugin) -> (World, Schedule) {
    let mut world = World::new();
    let mut schedule = Schedule::default();
    plugin.build(&mut world, &mut schedule);
    (world, schedule)
}
