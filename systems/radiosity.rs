//! The render stage under radiosity transport: solve once, view every
//! frame.
//!
//! [`render_radiosity`] keeps the solution in [`RadiosityState`] and
//! solves again only when the scene itself changed (objects added,
//! removed, moved, re-shaped or re-materialed, lights changed, or a fresh
//! scene) or the radiosity options did. A moving camera, including the
//! render origin following it, reuses the solution: the view pass shifts
//! its rays into the solution's frame. Progressive accumulation does not
//! apply (each frame is rendered whole from the solution).

use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;

use super::frame::{Frame, RenderConfig};
use super::render::frame_preconditions;
use crate::core::settings::Transport;
use crate::integrators;
use crate::radiosity::{RadiositySettings, Solution};

/// Called while solving with (form factor rows done, rows in the pass).
pub type SolveProgressFn = Arc<dyn Fn(u64, u64) + Send + Sync>;

/// The radiosity solution kept between frames.
#[derive(Resource, Default)]
pub struct RadiosityState {
    /// The solution, once solved.
    pub solution: Option<Arc<Solution>>,
    /// The options it was solved with.
    pub key: Option<RadiositySettings>,
    /// Solves run since the world was set up (a counter for tests: moving
    /// the camera must not add to it).
    pub solves: u64,
    /// True when this frame solved (false when it reused the solution).
    pub solved_this_frame: bool,
    /// Optional progress callback for the solve.
    pub progress: Option<SolveProgressFn>,
}

/// Run condition: the configured transport is radiosity.
pub fn transport_is_radiosity(config: Res<RenderConfig>) -> bool {
    config.settings.transport == Transport::Radiosity
}

/// Stage 3 under radiosity transport (either integrator): solves when
/// needed, then renders the view from the solution.
pub fn render_radiosity(world: &mut World) {
    let Some((scene, camera)) = frame_preconditions(world) else {
        return;
    };
    let config = world.resource::<RenderConfig>().clone();
    let update = world.resource::<Frame>().update;
    // Rebasing (the origin following the camera) is not a scene change.
    let scene_changed = update.reset
        || update.removed + update.added + update.moved + update.regeometry + update.rematerial > 0
        || update.lights_changed;
    world.init_resource::<RadiosityState>();
    let solve_start = Instant::now();
    let (stale, progress) = {
        let mut state = world.resource_mut::<RadiosityState>();
        state.solved_this_frame = false;
        let stale = scene_changed
            || state.solution.is_none()
            || state.key.as_ref() != Some(&config.settings.radiosity);
        (stale, state.progress.clone())
    };
    if stale {
        let p = progress
            .as_deref()
            .map(|f| f as crate::radiosity::SolveProgress<'_>);
        let result = crate::radiosity::solve(&scene, &config.settings.radiosity, p);
        let mut state = world.resource_mut::<RadiosityState>();
        match result {
            Ok(s) => {
                state.solution = Some(Arc::new(s));
                state.key = Some(config.settings.radiosity);
                state.solves += 1;
                state.solved_this_frame = true;
            }
            Err(e) => {
                state.solution = None;
                state.key = None;
                world.resource_mut::<Frame>().error = Some(e);
                return;
            }
        }
    }
    let state = world.resource::<RadiosityState>();
    let solved = state.solved_this_frame;
    let solution = state.solution.clone().expect("solved above");
    let start = Instant::now();
    let progress = config
        .progress
        .as_deref()
        .map(|p| p as integrators::Progress<'_>);
    let (film, counters) =
        integrators::radiosity::render(&scene, &solution, &camera, &config.settings, progress);
    let mut frame = world.resource_mut::<Frame>();
    // A frame that solves took that long too (the solve's own times are in
    // the solution's stats).
    frame.render_seconds = if solved {
        solve_start.elapsed().as_secs_f64()
    } else {
        start.elapsed().as_secs_f64()
    };
    frame.film = Some(film);
    frame.counters = counters;
    frame.samples = config.settings.spp;
}
