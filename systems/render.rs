//! The render stage's one-shot and progressive helpers for the recursive
//! integrator, and the preconditions every integrator checks first.

use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;

use super::frame::{
    AccumulationState, ExtractedScene, Frame, ProgressiveRendering, RenderConfig, SceneAccel,
};
use crate::core::settings::Transport;
use crate::integrators::progressive::Accumulator;
use crate::integrators::{self, IntegratorKind};
use crate::scene::RenderScene;
use crate::scene::camera::Camera;

/// Run condition: the configured integrator is `kind`.
pub fn integrator_is(kind: IntegratorKind) -> impl Fn(Res<RenderConfig>) -> bool + Clone {
    move |config: Res<RenderConfig>| config.integrator == kind
}

/// Checks what every integrator needs before it can trace: a valid
/// camera, valid settings and a built scene. On failure it records the
/// reason in [`Frame`] and returns `None`.
pub fn frame_preconditions(world: &mut World) -> Option<(Arc<RenderScene>, Camera)> {
    {
        let mut frame = world.resource_mut::<Frame>();
        let update = frame.update;
        *frame = Frame {
            update,
            ..Default::default()
        };
    }
    let extracted = world.resource::<ExtractedScene>();
    let result = (|| {
        if let Some(e) = &extracted.error {
            return Err(e.clone());
        }
        let camera = extracted
            .camera
            .clone()
            .ok_or_else(|| "the scene has no camera".to_string())?;
        camera.validate()?;
        world.resource::<RenderConfig>().settings.validate()?;
        let scene = world
            .resource::<SceneAccel>()
            .scene
            .clone()
            .ok_or_else(|| "no acceleration structure was built".to_string())?;
        let transport = world.resource::<RenderConfig>().settings.transport;
        if scene.has_media() && matches!(transport, Transport::Photon | Transport::Radiosity) {
            return Err(format!(
                "{} transport does not render participating media (the scene has a [medium] fog or \
a scattering interior): use --transport path, or whitted (which attenuates by Beer-Lambert only)",
                transport.name()
            ));
        }
        Ok((scene, camera))
    })();
    match result {
        Ok(v) => Some(v),
        Err(e) => {
            world.resource_mut::<Frame>().error = Some(e);
            None
        }
    }
}

/// Stage 3, recursive integrator: renders every pixel depth-first.
pub fn render_recursive(world: &mut World) {
    let Some((scene, camera)) = frame_preconditions(world) else {
        return;
    };
    let config = world.resource::<RenderConfig>().clone();
    if config.settings.transport == Transport::Photon {
        render_photon(world, &scene, &camera, &config);
        return;
    }
    let progressive = world
        .get_resource::<ProgressiveRendering>()
        .is_some_and(|p| p.enabled);
    if progressive {
        if config.settings.window.is_some() {
            world.resource_mut::<Frame>().error = Some(
                "progressive rendering covers the whole image: it takes no render window".into(),
            );
            return;
        }
        render_progressive(world, &scene, camera, &config);
        return;
    }
    let start = Instant::now();
    let progress = config
        .progress
        .as_deref()
        .map(|p| p as integrators::Progress<'_>);
    let (film, sums, counters) = if config.settings.window.is_some() {
        let (sums, counters) =
            integrators::recursive::render_sums(&scene, &camera, &config.settings, progress);
        (sums.resolve(), Some(sums), counters)
    } else {
        let (film, counters) =
            integrators::recursive::render(&scene, &camera, &config.settings, progress);
        (film, None, counters)
    };
    let mut frame = world.resource_mut::<Frame>();
    frame.render_seconds = start.elapsed().as_secs_f64();
    frame.film = Some(film);
    frame.sums = sums;
    frame.counters = counters;
    frame.samples = config.settings.spp;
}

/// Photon transport: every frame runs all its iterations (progressive
/// accumulation does not apply; the iterations already refine the image).
fn render_photon(world: &mut World, scene: &RenderScene, camera: &Camera, config: &RenderConfig) {
    let start = Instant::now();
    let progress = config
        .progress
        .as_deref()
        .map(|p| p as integrators::Progress<'_>);
    let result = integrators::photon::render(scene, camera, &config.settings, progress);
    let mut frame = world.resource_mut::<Frame>();
    match result {
        Ok((film, counters, report)) => {
            frame.render_seconds = start.elapsed().as_secs_f64();
            frame.film = Some(film);
            frame.counters = counters;
            frame.samples = config
                .settings
                .spp
                .saturating_mul(config.settings.photon.iterations);
            frame.photon = Some(report);
        }
        Err(e) => frame.error = Some(e),
    }
}

/// Adds `spp` samples to the running sums, after starting them again if
/// anything changed: the scene (this frame's update), the camera, the
/// settings, the background, the environment or the fog.
fn render_progressive(
    world: &mut World,
    scene: &RenderScene,
    camera: Camera,
    config: &RenderConfig,
) {
    let changed = world.resource::<Frame>().update.changed();
    let key = (
        config.settings.clone(),
        camera,
        config.background,
        config.environment.clone(),
        config.fog,
    );
    let mut state = world.resource_mut::<AccumulationState>();
    if changed || state.key.as_ref() != Some(&key) {
        state.accumulator = Accumulator::new(config.settings.width, config.settings.height);
        state.key = Some(key);
    }
    let (settings, camera, ..) = state.key.clone().expect("just set");
    let start = Instant::now();
    let counters = state.accumulator.add_samples(scene, &camera, &settings);
    let film = state.accumulator.film();
    let samples = state.accumulator.samples();
    if let Some(p) = &config.progress {
        p(settings.height as u64);
    }
    let mut frame = world.resource_mut::<Frame>();
    frame.render_seconds = start.elapsed().as_secs_f64();
    frame.film = Some(film);
    frame.counters = counters;
    frame.samples = samples;
}
