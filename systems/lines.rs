//! The line stage: feature lines over the frame's image, run only when
//! the settings ask for lines ([`lines_requested`]).

use std::time::Instant;

use bevy_ecs::prelude::*;

use super::frame::{ExtractedScene, Frame, RenderConfig, SceneAccel};
use crate::integrators::{self, lines};

/// Run condition: the settings ask for feature lines.
pub fn lines_requested(config: Res<RenderConfig>) -> bool {
    config.settings.lines.is_some()
}

/// Stage 3, after the image: finds the feature lines by ray casting
/// ([`lines::render_lines`]) and puts their coverage in [`Frame::lines`].
/// Does nothing when the frame already failed.
pub fn render_feature_lines(world: &mut World) {
    if world.resource::<Frame>().error.is_some() {
        return;
    }
    let config = world.resource::<RenderConfig>().clone();
    let Some(line_settings) = config.settings.lines else {
        return;
    };
    let Some(camera) = world.resource::<ExtractedScene>().camera.clone() else {
        return;
    };
    let Some(scene) = world.resource::<SceneAccel>().scene.clone() else {
        return;
    };
    let start = Instant::now();
    let rays = integrators::camera_rays(&scene, &camera, &config.settings);
    let progress = config
        .progress
        .as_deref()
        .map(|p| p as integrators::Progress<'_>);
    let (overlay, report) =
        lines::render_lines(&scene, &rays, &config.settings, &line_settings, progress);
    let mut frame = world.resource_mut::<Frame>();
    frame.lines = Some(overlay);
    frame.line_rays = report.rays;
    frame.line_seconds = start.elapsed().as_secs_f64();
}
