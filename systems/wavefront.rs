//! The wavefront integrator as ECS stage systems.
//!
//! Each queue is its own resource, so a system's signature shows exactly
//! the data it reads and writes. The algorithm is declared once, in
//! [`add_wavefront_schedules`]:
//!
//! * per batch of paths: [`generate_camera_rays`];
//! * per bounce, until no ray is left: [`intersect_closest`] ->
//!   [`handle_escaped_rays`] -> `shade_*` (one system per material class)
//!   -> [`trace_shadow_rays`] -> [`advance_bounce`];
//! * per batch, at the end: [`update_film`].
//!
//! [`render_wavefront`] drives these schedules for one frame.

use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;

use super::{Frame, RenderConfig, frame_preconditions};
use crate::core::math::Color;
use crate::image::film::PixelAccumulator;
use crate::integrators::wavefront::queues::{EscapedQueue, QueueBytes, RayQueue, ShadowSegments};
use crate::integrators::wavefront::{
    self as kernels, ClassQueues, RoutingScratch, ShadeScratch, ShadowScratch, StageSeconds,
    WavefrontReport,
};
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::scene::features::SceneFeatures;
use crate::scene::material::MaterialClass;

/// Schedule run once at the start of each batch.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct StartBatch;

/// Schedule run once per bounce while rays remain.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct Bounce;

/// Schedule run once at the end of each batch.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct FinishBatch;

/// The stages of a bounce, in order.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum WavefrontSystems {
    /// Closest hits; routing to the escaped and per-class hit queues.
    IntersectClosest,
    /// Background radiance for rays that left the scene.
    HandleEscapedRays,
    /// One shading system per material class.
    ShadeMaterials,
    /// Shadow rays, stopping at the first blocker.
    TraceShadowRays,
    /// Clearing drained queues and swapping the ray queues.
    AdvanceBounce,
}

/// Rays of the current bounce.
#[derive(Resource, Default)]
pub struct CurrentRays(pub RayQueue);

/// Rays spawned for the next bounce.
#[derive(Resource, Default)]
pub struct NextRays(pub RayQueue);

/// Rays that missed everything this bounce.
#[derive(Resource, Default)]
pub struct EscapedRays(pub EscapedQueue);

/// Hits of this bounce, one queue per material class.
#[derive(Resource, Default)]
pub struct HitQueues(pub ClassQueues);

/// Shadow rays of this bounce.
#[derive(Resource, Default)]
pub struct ShadowRays(pub ShadowSegments);

/// Radiance gathered so far by each path of the batch.
#[derive(Resource, Default)]
pub struct PathRadiance(pub Vec<Color>);

/// Per-pixel sums across batches.
#[derive(Resource, Default)]
pub struct PixelSums(pub PixelAccumulator);

/// Reusable per-ray scratch buffers of the intersection stages.
#[derive(Resource, Default)]
pub struct StageScratch {
    routing: RoutingScratch,
    shading: ShadeScratch,
    shadows: ShadowScratch,
}

impl StageScratch {
    /// Bytes the shading stages hold for reflection and refraction rays:
    /// zero when no stage ever pushed one.
    pub fn secondary_bytes(&self) -> usize {
        self.shading.iter().map(|s| s.secondary_bytes()).sum()
    }

    /// Bytes the shading stages hold for refraction rays.
    pub fn refraction_bytes(&self) -> usize {
        self.shading.iter().map(|s| s.refraction_bytes()).sum()
    }
}

/// What stays fixed during a frame: the scene, the camera rays, the
/// material classes, the batches, and which batch is running.
#[derive(Resource)]
pub struct WavefrontFrame {
    /// The scene being rendered.
    pub scene: Arc<RenderScene>,
    /// Camera rays for the image size.
    pub camera: CameraRays,
    /// Class of each material, indexed like the scene's materials.
    pub classes: Vec<MaterialClass>,
    /// `(first path, path count)` per batch.
    pub batches: Vec<(u64, usize)>,
    /// Index of the running batch.
    pub batch: usize,
    /// What the scene contains: shading systems run only for the classes
    /// present, shadow rays only when something can be lit.
    pub features: SceneFeatures,
    /// Whether shadow rays can occur (see
    /// [`SceneFeatures::needs_shadow_rays`]).
    pub shadows: bool,
}

/// Counters and timings of the frame.
#[derive(Resource, Default)]
pub struct WavefrontStats(pub WavefrontReport);

/// Number of paths per batch.
#[derive(Resource, Clone, Copy, Debug)]
pub struct BatchSize(pub usize);

/// Stage gating: by default a stage runs only when the scene has its
/// feature; `force_all` runs every stage (with empty queues where nothing
/// feeds them), to measure what gating saves.
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct StageGating {
    /// Run every stage whatever the scene contains.
    pub force_all: bool,
}

impl Default for BatchSize {
    fn default() -> Self {
        Self(kernels::DEFAULT_BATCH_PATHS)
    }
}

fn timed(slot: &mut f64, f: impl FnOnce()) {
    let start = Instant::now();
    f();
    *slot += start.elapsed().as_secs_f64();
}

/// Declares the wavefront's schedules: the whole algorithm in one place.
pub fn add_wavefront_schedules(world: &mut World) {
    let mut start = Schedule::new(StartBatch);
    start.add_systems(generate_camera_rays);

    let mut bounce = Schedule::new(Bounce);
    bounce.configure_sets(
        (
            WavefrontSystems::IntersectClosest,
            WavefrontSystems::HandleEscapedRays,
            WavefrontSystems::ShadeMaterials,
            WavefrontSystems::TraceShadowRays,
            WavefrontSystems::AdvanceBounce,
        )
            .chain(),
    );
    bounce.add_systems((
        intersect_closest.in_set(WavefrontSystems::IntersectClosest),
        handle_escaped_rays.in_set(WavefrontSystems::HandleEscapedRays),
        (
            shade_class_system::<{ MaterialClass::Emissive as u8 }>
                .run_if(class_present::<{ MaterialClass::Emissive as u8 }>),
            shade_class_system::<{ MaterialClass::Diffuse as u8 }>
                .run_if(class_present::<{ MaterialClass::Diffuse as u8 }>),
            shade_class_system::<{ MaterialClass::Mirror as u8 }>
                .run_if(class_present::<{ MaterialClass::Mirror as u8 }>),
            shade_class_system::<{ MaterialClass::Glass as u8 }>
                .run_if(class_present::<{ MaterialClass::Glass as u8 }>),
            shade_class_system::<{ MaterialClass::General as u8 }>
                .run_if(class_present::<{ MaterialClass::General as u8 }>),
        )
            .chain()
            .in_set(WavefrontSystems::ShadeMaterials),
        trace_shadow_rays
            .run_if(shadows_possible)
            .in_set(WavefrontSystems::TraceShadowRays),
        advance_bounce.in_set(WavefrontSystems::AdvanceBounce),
    ));

    let mut finish = Schedule::new(FinishBatch);
    finish.add_systems(update_film);

    world.add_schedule(start);
    world.add_schedule(bounce);
    world.add_schedule(finish);
    world.init_resource::<CurrentRays>();
    world.init_resource::<NextRays>();
    world.init_resource::<EscapedRays>();
    world.init_resource::<HitQueues>();
    world.init_resource::<ShadowRays>();
    world.init_resource::<PathRadiance>();
    world.init_resource::<PixelSums>();
    world.init_resource::<StageScratch>();
    world.init_resource::<WavefrontStats>();
    world.init_resource::<BatchSize>();
    world.init_resource::<StageGating>();
}

fn class_from_u8(c: u8) -> MaterialClass {
    MaterialClass::ALL[c as usize]
}

/// Run condition: the scene has a material of class `C`.
pub fn class_present<const C: u8>(frame: Res<WavefrontFrame>, gating: Res<StageGating>) -> bool {
    gating.force_all || frame.features.classes[C as usize]
}

/// Run condition: the scene can produce shadow rays.
pub fn shadows_possible(frame: Res<WavefrontFrame>, gating: Res<StageGating>) -> bool {
    gating.force_all || frame.shadows
}

/// Stage: camera rays for the batch's paths.
pub fn generate_camera_rays(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    mut rays: ResMut<CurrentRays>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    let (first, count) = frame.batches[frame.batch];
    let stats = &mut stats.0;
    stats.runs.generate_camera_rays += 1;
    timed(&mut stats.stages.generate_camera_rays, || {
        radiance.0.clear();
        radiance.0.resize(count, Color::ZERO);
        kernels::generate_camera_rays(
            &frame.camera,
            &config.settings,
            first,
            count,
            &mut rays.0,
            &mut stats.counters.rays,
        );
    });
}

/// Stage: closest hits of the current rays, routed to queues.
pub fn intersect_closest(
    frame: Res<WavefrontFrame>,
    rays: Res<CurrentRays>,
    mut scratch: ResMut<StageScratch>,
    mut escaped: ResMut<EscapedRays>,
    mut hits: ResMut<HitQueues>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.runs.intersect_closest += 1;
    timed(&mut stats.0.stages.intersect_closest, || {
        kernels::intersect_closest(
            &frame.scene,
            &frame.classes,
            &rays.0,
            &mut scratch.routing,
            &mut escaped.0,
            &mut hits.0,
        )
    });
}

/// Stage: background radiance for escaped rays; drains the escaped queue.
pub fn handle_escaped_rays(
    frame: Res<WavefrontFrame>,
    mut escaped: ResMut<EscapedRays>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.runs.handle_escaped_rays += 1;
    timed(&mut stats.0.stages.handle_escaped_rays, || {
        kernels::handle_escaped_rays(&escaped.0, frame.scene.background, &mut radiance.0);
        escaped.0.clear();
    });
}

/// Stage: shades the hits of material class `C`; drains that queue.
#[allow(clippy::too_many_arguments)]
pub fn shade_class_system<const C: u8>(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    mut hits: ResMut<HitQueues>,
    mut scratch: ResMut<StageScratch>,
    mut radiance: ResMut<PathRadiance>,
    mut shadows: ResMut<ShadowRays>,
    mut next: ResMut<NextRays>,
    mut stats: ResMut<WavefrontStats>,
) {
    let class = class_from_u8(C);
    let first = frame.batches[frame.batch].0;
    let stats = &mut stats.0;
    *stats.runs.shade_mut(class) += 1;
    timed(&mut stats.stages.shade, || {
        let queue = &mut hits.0.queues[C as usize];
        kernels::shade_class(
            class,
            &frame.scene,
            &config.settings,
            first,
            queue,
            &mut scratch.shading,
            &mut radiance.0,
            &mut shadows.0,
            &mut next.0,
            &mut stats.counters.rays,
        );
        queue.clear();
    });
}

/// Stage: traces the shadow rays; drains the shadow queue.
pub fn trace_shadow_rays(
    frame: Res<WavefrontFrame>,
    mut shadows: ResMut<ShadowRays>,
    mut scratch: ResMut<StageScratch>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.runs.trace_shadow_rays += 1;
    timed(&mut stats.0.stages.trace_shadow_rays, || {
        kernels::trace_shadow_rays(
            &frame.scene,
            &shadows.0,
            &mut scratch.shadows,
            &mut radiance.0,
        );
        shadows.0.clear();
    });
}

/// Stage: the next bounce's rays become current; records peak memory.
#[allow(clippy::too_many_arguments)]
pub fn advance_bounce(
    mut rays: ResMut<CurrentRays>,
    mut next: ResMut<NextRays>,
    escaped: Res<EscapedRays>,
    hits: Res<HitQueues>,
    shadows: Res<ShadowRays>,
    scratch: Res<StageScratch>,
    radiance: Res<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    let bytes = rays.0.bytes()
        + next.0.bytes()
        + escaped.0.bytes()
        + hits.0.bytes()
        + shadows.0.bytes()
        + scratch
            .routing
            .iter()
            .map(|(e, h, s)| e.bytes() + h.bytes() + s.bytes())
            .sum::<usize>()
        + scratch.shadows.bytes()
        + scratch.shading.iter().map(|s| s.bytes()).sum::<usize>()
        + radiance.0.capacity() * std::mem::size_of::<Color>();
    stats.0.peak_queue_bytes = stats.0.peak_queue_bytes.max(bytes);
    debug_assert!(shadows.0.is_empty(), "shadow rays left untraced");
    std::mem::swap(&mut rays.0, &mut next.0);
    next.0.clear();
}

/// Stage: adds the batch's paths to their pixels.
pub fn update_film(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    radiance: Res<PathRadiance>,
    mut pixels: ResMut<PixelSums>,
    mut stats: ResMut<WavefrontStats>,
) {
    let (first, _) = frame.batches[frame.batch];
    let stats = &mut stats.0;
    stats.runs.update_film += 1;
    timed(&mut stats.stages.update_film, || {
        kernels::update_film(
            &radiance.0,
            first,
            config.settings.spp,
            &mut pixels.0,
            &mut stats.counters,
        )
    });
}

/// Renders one frame with the wavefront integrator: runs the batch and
/// bounce schedules until every path is finished, then writes [`Frame`].
pub fn render_wavefront(world: &mut World) {
    let Some((scene, camera)) = frame_preconditions(world) else {
        return;
    };
    let config = world.resource::<RenderConfig>().clone();
    let settings = &config.settings;
    let classes: Vec<MaterialClass> = scene.materials.iter().map(|m| m.class()).collect();
    let features = SceneFeatures::of(&scene);
    let shadows = features.needs_shadow_rays(settings.transport);
    let batch_size = world.resource::<BatchSize>().0;
    let batches: Vec<(u64, usize)> = kernels::batch_ranges(settings, batch_size).collect();
    world.insert_resource(WavefrontFrame {
        scene,
        camera: CameraRays::new(&camera, settings.width, settings.height),
        classes,
        batches: batches.clone(),
        batch: 0,
        features,
        shadows,
    });
    world.insert_resource(PixelSums(PixelAccumulator::new(
        settings.width,
        settings.height,
    )));
    world.insert_resource(WavefrontStats::default());

    let start = Instant::now();
    let rows_per_path = 1.0 / (settings.width as f64 * settings.spp as f64);
    let mut rows_reported = 0u64;
    for (b, &(first, count)) in batches.iter().enumerate() {
        world.resource_mut::<WavefrontFrame>().batch = b;
        world.run_schedule(StartBatch);
        while !world.resource::<CurrentRays>().0.is_empty() {
            world.run_schedule(Bounce);
        }
        world.run_schedule(FinishBatch);
        if let Some(p) = &config.progress {
            let rows = ((first + count as u64) as f64 * rows_per_path) as u64;
            p(rows - rows_reported);
            rows_reported = rows;
        }
    }
    let render_seconds = start.elapsed().as_secs_f64();
    let film = world.resource::<PixelSums>().0.resolve();
    let mut report = world.resource::<WavefrontStats>().0;
    report.batches = batches.len();
    let mut frame = world.resource_mut::<Frame>();
    frame.film = Some(film);
    frame.counters = report.counters;
    frame.render_seconds = render_seconds;
    frame.wavefront = Some(report);
}

/// Stage times of the last frame (zero for the recursive integrator).
pub fn last_stage_seconds(world: &World) -> StageSeconds {
    world
        .get_resource::<WavefrontStats>()
        .map(|s| s.0.stages)
        .unwrap_or_default()
}
