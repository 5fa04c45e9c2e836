//! The wavefront integrator as ECS stage systems.
//!
//! Each queue is its own resource, so a system's signature shows exactly
//! the data it reads and writes; the hit queues are one resource per
//! material class, [`Hits<C>`] for the class's marker type `C`. The
//! algorithm is declared once, in [`add_wavefront_schedules`]:
//!
//! * per batch of paths: [`generate_camera_rays`];
//! * per bounce, until no ray is left: [`intersect_closest`] ->
//!   [`handle_escaped_rays`] -> [`shade_emissive`], [`shade_diffuse`],
//!   [`shade_mirror`], [`shade_glass`], [`shade_general`] (one system per
//!   material class) -> [`trace_shadow_rays`] -> [`record_queue_bytes`]
//!   -> [`advance_bounce`];
//! * per batch, at the end: [`update_film`].
//!
//! Each stage system is named after its [`Stage`], under which it counts
//! its runs and time. [`render_wavefront`] drives these schedules for one
//! frame, in one lane per worker thread: each lane is a world with the
//! same schedules and queues ([`WavefrontLanes`]; lane 0 is the
//! renderer's own world) and runs whole batches, so a lane's stages follow
//! one another on its thread without waiting for the other threads.

use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;
use bevy_ecs::system::SystemParam;

use super::{Frame, RenderConfig, frame_preconditions};
use crate::core::math::Color;
use crate::core::rng::{KeptSlot, SamplerSeed};
use crate::core::settings::Style;
use crate::core::window::PathMap;
use crate::image::film::PixelAccumulator;
use crate::integrators::wavefront::queues::{
    ClosestHits, EscapedQueue, HitQueue, QueueBytes, RayQueue, ShadowSegments,
};
use crate::integrators::wavefront::routing::{ClassHitQueues, ShadeTargets};
use crate::integrators::wavefront::stages::{
    self as kernels, MediaScratch, MediaTargets, ShadeInput, ShadeScratch,
};
use crate::integrators::wavefront::{self, Stage, StageSeconds, WavefrontReport};
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
    /// Closest hits; routing to the escaped and per-class hit queues
    /// (with media, routing is left to the next stage).
    IntersectClosest,
    /// Rays followed through participating media, then routed (scenes
    /// with media under path transport).
    SampleMedia,
    /// Background radiance for rays that left the scene.
    HandleEscapedRays,
    /// One shading system per material class.
    ShadeMaterials,
    /// Shadow rays, stopping at the first blocker.
    TraceShadowRays,
    /// Recording queue memory, then swapping the ray queues.
    AdvanceBounce,
}

/// Rays of the current bounce.
#[derive(Resource, Default)]
pub struct CurrentRays(pub RayQueue);

/// Rays spawned for the next bounce.
#[derive(Resource, Default)]
pub struct NextRays(pub RayQueue);

/// The closest hit of each ray of this bounce, indexed like
/// [`CurrentRays`].
#[derive(Resource, Default)]
pub struct BounceHits(pub ClosestHits);

/// Rays that missed everything this bounce (their indices).
#[derive(Resource, Default)]
pub struct EscapedRays(pub EscapedQueue);

/// A material class as a type: its hits are the resource [`Hits<C>`] and
/// its shading stage is a system of its own.
pub trait ClassMarker: Send + Sync + 'static {
    /// The class.
    const CLASS: MaterialClass;
}

/// Hits of this bounce on materials of class `C`.
#[derive(Resource)]
pub struct Hits<C: ClassMarker>(pub HitQueue, PhantomData<C>);

impl<C: ClassMarker> Default for Hits<C> {
    fn default() -> Self {
        Self(HitQueue::default(), PhantomData)
    }
}

/// Declares, from one list of the material classes, their marker types,
/// the system parameters that reach every class's hit queue, and the
/// functions that reach one class's queue in a world.
macro_rules! class_hit_queues {
    ($($class:ident: $field:ident),+ $(,)?) => {
        $(
            #[doc = concat!(
                "Marker of [`MaterialClass::", stringify!($class),
                "`]: its hits are [`Hits<", stringify!($class), ">`]."
            )]
            #[derive(Clone, Copy, Debug, Default)]
            pub struct $class;

            impl ClassMarker for $class {
                const CLASS: MaterialClass = MaterialClass::$class;
            }
        )+

        /// Every material class's hit queue, to read.
        #[derive(SystemParam)]
        pub struct HitQueues<'w> {
            $(
                #[doc = concat!("Hits on ", stringify!($field), " materials.")]
                pub $field: Res<'w, Hits<$class>>,
            )+
        }

        impl HitQueues<'_> {
            /// The hit queue of `class`.
            pub fn get(&self, class: MaterialClass) -> &HitQueue {
                match class {
                    $(MaterialClass::$class => &self.$field.0,)+
                }
            }
        }

        /// Every material class's hit queue, to route hits to.
        #[derive(SystemParam)]
        pub struct HitQueuesMut<'w> {
            $(
                #[doc = concat!("Hits on ", stringify!($field), " materials.")]
                pub $field: ResMut<'w, Hits<$class>>,
            )+
        }

        impl ClassHitQueues for HitQueuesMut<'_> {
            fn queue_mut(&mut self, class: MaterialClass) -> &mut HitQueue {
                match class {
                    $(MaterialClass::$class => &mut self.$field.0,)+
                }
            }

            fn all_mut(&mut self) -> [&mut HitQueue; MaterialClass::ALL.len()] {
                let queues = [$((MaterialClass::$class, &mut self.$field.0)),+];
                debug_assert!(queues.iter().enumerate().all(|(i, (c, _))| *c as usize == i));
                queues.map(|(_, q)| q)
            }
        }

        /// The hit queue of `class` in `world`.
        pub fn hit_queue(world: &World, class: MaterialClass) -> &HitQueue {
            match class {
                $(MaterialClass::$class => &world.resource::<Hits<$class>>().0,)+
            }
        }

        /// The hit queue of `class` in `world`, to change.
        pub fn hit_queue_mut(world: &mut World, class: MaterialClass) -> Mut<'_, HitQueue> {
            match class {
                $(MaterialClass::$class => world
                    .resource_mut::<Hits<$class>>()
                    .map_unchanged(|h| &mut h.0),)+
            }
        }

        /// Inserts an empty hit queue for every class.
        fn init_hit_queues(world: &mut World) {
            $(world.init_resource::<Hits<$class>>();)+
        }
    };
}

class_hit_queues!(
    Emissive: emissive,
    Diffuse: diffuse,
    Mirror: mirror,
    Glass: glass,
    General: general,
);

impl HitQueues<'_> {
    /// Bytes allocated by all hit queues.
    pub fn bytes(&self) -> usize {
        MaterialClass::ALL
            .iter()
            .map(|&c| self.get(c).bytes())
            .sum()
    }
}

/// What this bounce's shadow rays bring back: their stages trace them
/// and queue the radiance of those unblocked.
#[derive(Resource, Default)]
pub struct ShadowRays(pub ShadowSegments);

/// Sampler seed of each path of the batch (path transport only).
#[derive(Resource, Default)]
pub struct PathSeeds(pub Vec<SamplerSeed>);

/// Each path's kept Sobol set between its bounces' shading passes (path
/// transport only; see [`KeptSlot`]).
#[derive(Resource, Default)]
pub struct PathKeptSets(pub Vec<KeptSlot>);

/// Wavelength of each path of the batch (spectral path transport only).
#[derive(Resource, Default)]
pub struct PathWavelengths(pub Vec<f32>);

/// Radiance gathered so far by each path of the batch.
#[derive(Resource, Default)]
pub struct PathRadiance(pub Vec<Color>);

/// Per-pixel sums across batches, shared by the lanes of a frame (each
/// adds a finished batch under the lock; the sums are exact, so the order
/// in which batches are added does not matter).
#[derive(Resource, Default, Clone)]
pub struct PixelSums(pub Arc<Mutex<PixelAccumulator>>);

/// Reusable per-chunk scratch buffers of the parallel stages.
#[derive(Resource, Default)]
pub struct StageScratch {
    media: MediaScratch,
    shading: ShadeScratch,
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

    /// Bytes the medium stage holds (its segment updates and outputs):
    /// zero when it never ran.
    pub fn media_bytes(&self) -> usize {
        self.media.iter().map(|c| c.bytes()).sum()
    }

    /// Bytes allocated by all scratch buffers.
    pub fn bytes(&self) -> usize {
        self.media.iter().map(|c| c.bytes()).sum::<usize>()
            + self.shading.iter().map(|s| s.bytes()).sum::<usize>()
    }
}

/// What stays fixed during a frame: the scene, the camera rays, the
/// material classes, the batches, and which batch is running.
#[derive(Resource, Clone)]
pub struct WavefrontFrame {
    /// The scene being rendered.
    pub scene: Arc<RenderScene>,
    /// Camera rays for the image size.
    pub camera: CameraRays,
    /// Class of each material, indexed like the scene's materials.
    pub classes: Vec<MaterialClass>,
    /// Where each path of the settings' window goes.
    pub paths: PathMap,
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
    /// Whether rays are followed through participating media: path
    /// transport of a scene with media ([`RenderScene::has_media`]).
    pub media: bool,
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
        Self(wavefront::DEFAULT_BATCH_PATHS)
    }
}

/// Declares the wavefront's schedules: the whole algorithm in one place.
pub fn add_wavefront_schedules(world: &mut World) {
    let mut start = Schedule::new(StartBatch);
    start.add_systems(generate_camera_rays);

    let mut bounce = Schedule::new(Bounce);
    bounce.configure_sets(
        (
            WavefrontSystems::IntersectClosest,
            WavefrontSystems::SampleMedia,
            WavefrontSystems::HandleEscapedRays,
            WavefrontSystems::ShadeMaterials,
            WavefrontSystems::TraceShadowRays,
            WavefrontSystems::AdvanceBounce,
        )
            .chain(),
    );
    bounce.add_systems((
        intersect_closest.in_set(WavefrontSystems::IntersectClosest),
        sample_media
            .run_if(media_present)
            .in_set(WavefrontSystems::SampleMedia),
        handle_escaped_rays.in_set(WavefrontSystems::HandleEscapedRays),
        (
            shade_emissive.run_if(class_present::<Emissive>),
            shade_diffuse.run_if(class_present::<Diffuse>),
            shade_mirror.run_if(class_present::<Mirror>),
            shade_glass.run_if(class_present::<Glass>),
            shade_general.run_if(class_present::<General>),
        )
            .chain()
            .in_set(WavefrontSystems::ShadeMaterials),
        trace_shadow_rays
            .run_if(shadows_possible)
            .in_set(WavefrontSystems::TraceShadowRays),
        (record_queue_bytes, advance_bounce)
            .chain()
            .in_set(WavefrontSystems::AdvanceBounce),
    ));

    let mut finish = Schedule::new(FinishBatch);
    finish.add_systems(update_film);

    world.add_schedule(start);
    world.add_schedule(bounce);
    world.add_schedule(finish);
    world.init_resource::<CurrentRays>();
    world.init_resource::<NextRays>();
    world.init_resource::<BounceHits>();
    world.init_resource::<EscapedRays>();
    init_hit_queues(world);
    world.init_resource::<ShadowRays>();
    world.init_resource::<PathSeeds>();
    world.init_resource::<PathKeptSets>();
    world.init_resource::<PathWavelengths>();
    world.init_resource::<PathRadiance>();
    world.init_resource::<PixelSums>();
    world.init_resource::<StageScratch>();
    world.init_resource::<WavefrontStats>();
    world.init_resource::<BatchSize>();
    world.init_resource::<StageGating>();
}

/// Run condition: the scene has a material of class `C`.
pub fn class_present<C: ClassMarker>(frame: Res<WavefrontFrame>, gating: Res<StageGating>) -> bool {
    gating.force_all || frame.features.has(C::CLASS)
}

/// Run condition: rays are followed through media.
pub fn media_present(frame: Res<WavefrontFrame>, gating: Res<StageGating>) -> bool {
    gating.force_all || frame.media
}

/// Run condition: the scene can produce shadow rays.
pub fn shadows_possible(frame: Res<WavefrontFrame>, gating: Res<StageGating>) -> bool {
    gating.force_all || frame.shadows
}

/// Stage: camera rays for the batch's paths.
#[allow(clippy::too_many_arguments)] // one resource per argument
pub fn generate_camera_rays(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    mut rays: ResMut<CurrentRays>,
    mut seeds: ResMut<PathSeeds>,
    mut kept: ResMut<PathKeptSets>,
    mut wavelengths: ResMut<PathWavelengths>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    let (first, count) = frame.batches[frame.batch];
    stats.0.run_stage(Stage::GenerateCameraRays, |counters| {
        radiance.0.clear();
        radiance
            .0
            .resize(count * config.settings.path_slots(), Color::ZERO);
        kernels::generate_camera_rays(
            &frame.camera,
            &config.settings,
            &frame.paths,
            first,
            count,
            &mut rays.0,
            &mut seeds.0,
            &mut kept.0,
            &mut counters.rays,
        );
        kernels::path_wavelengths(&frame.scene, &config.settings, &seeds.0, &mut wavelengths.0);
    });
}

/// Stage: closest hits of the current rays, routed to queues.
pub fn intersect_closest(
    frame: Res<WavefrontFrame>,
    rays: Res<CurrentRays>,
    mut found: ResMut<BounceHits>,
    mut escaped: ResMut<EscapedRays>,
    mut hits: HitQueuesMut,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.run_stage(Stage::IntersectClosest, |_| {
        kernels::intersect_closest(
            &frame.scene,
            &frame.classes,
            &rays.0,
            &mut found.0,
            &mut escaped.0,
            &mut hits,
            !frame.media,
        )
    });
}

/// Stage: follows the rays of a scene with media through them, updating
/// the rays and their hits in place; routes them to the escaped and hit
/// queues and adds radiance, shadow rays and the next bounce's rays of
/// scattering events.
#[allow(clippy::too_many_arguments)]
pub fn sample_media(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    mut rays: ResMut<CurrentRays>,
    seeds: Res<PathSeeds>,
    mut found: ResMut<BounceHits>,
    mut escaped: ResMut<EscapedRays>,
    mut hits: HitQueuesMut,
    mut scratch: ResMut<StageScratch>,
    mut radiance: ResMut<PathRadiance>,
    mut shadows: ResMut<ShadowRays>,
    mut next: ResMut<NextRays>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.run_stage(Stage::SampleMedia, |counters| {
        // Forced to run (`StageGating::force_all`) in a scene without
        // media, the stage has nothing to do: the closest-hit stage has
        // routed every ray already.
        if !frame.media {
            return;
        }
        let to = MediaTargets {
            escaped: &mut escaped.0,
            hits: &mut hits,
            shade: ShadeTargets {
                radiance: &mut radiance.0,
                shadows: &mut shadows.0,
                next: &mut next.0,
                rays: &mut counters.rays,
            },
        };
        kernels::sample_media(
            &frame.scene,
            &config.settings,
            &seeds.0,
            &frame.classes,
            &mut rays.0,
            &mut found.0,
            &mut scratch.media,
            to,
        );
    });
}

/// Stage: background or environment radiance for escaped rays; drains
/// the escaped queue.
pub fn handle_escaped_rays(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    rays: Res<CurrentRays>,
    mut escaped: ResMut<EscapedRays>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.run_stage(Stage::HandleEscapedRays, |_| {
        kernels::handle_escaped_rays(
            &frame.scene,
            &config.settings,
            &rays.0,
            &escaped.0,
            &mut radiance.0,
        );
        escaped.0.clear();
    });
}

/// What a shading system reads and writes besides its class's hits.
#[derive(SystemParam)]
pub struct ShadeParams<'w> {
    config: Res<'w, RenderConfig>,
    frame: Res<'w, WavefrontFrame>,
    rays: Res<'w, CurrentRays>,
    found: Res<'w, BounceHits>,
    seeds: Res<'w, PathSeeds>,
    kept: Res<'w, PathKeptSets>,
    wavelengths: Res<'w, PathWavelengths>,
    scratch: ResMut<'w, StageScratch>,
    radiance: ResMut<'w, PathRadiance>,
    shadows: ResMut<'w, ShadowRays>,
    next: ResMut<'w, NextRays>,
    stats: ResMut<'w, WavefrontStats>,
}

/// The body of every shading system: shades the hits of class `C` and
/// drains that queue.
fn shade_stage<C: ClassMarker>(mut hits: ResMut<Hits<C>>, params: ShadeParams) {
    let ShadeParams {
        config,
        frame,
        rays,
        found,
        seeds,
        kept,
        wavelengths,
        mut scratch,
        mut radiance,
        mut shadows,
        mut next,
        mut stats,
    } = params;
    stats.0.run_stage(Stage::shade(C::CLASS), |counters| {
        let to = ShadeTargets {
            radiance: &mut radiance.0,
            shadows: &mut shadows.0,
            next: &mut next.0,
            rays: &mut counters.rays,
        };
        kernels::shade_class(
            C::CLASS,
            &frame.scene,
            &config.settings,
            ShadeInput {
                rays: &rays.0,
                found: &found.0,
                hits: &hits.0,
                seeds: &seeds.0,
                wavelengths: &wavelengths.0,
                kept: &kept.0,
            },
            &mut scratch.shading,
            to,
        );
        hits.0.clear();
    });
}

/// Stage: shades the hits on emissive-only materials; drains their queue.
pub fn shade_emissive(hits: ResMut<Hits<Emissive>>, params: ShadeParams) {
    shade_stage(hits, params)
}

/// Stage: shades the hits on diffuse/glossy materials; drains their queue.
pub fn shade_diffuse(hits: ResMut<Hits<Diffuse>>, params: ShadeParams) {
    shade_stage(hits, params)
}

/// Stage: shades the hits on mirrors; drains their queue.
pub fn shade_mirror(hits: ResMut<Hits<Mirror>>, params: ShadeParams) {
    shade_stage(hits, params)
}

/// Stage: shades the hits on glass; drains their queue.
pub fn shade_glass(hits: ResMut<Hits<Glass>>, params: ShadeParams) {
    shade_stage(hits, params)
}

/// Stage: shades the hits on materials with several lobes; drains their
/// queue.
pub fn shade_general(hits: ResMut<Hits<General>>, params: ShadeParams) {
    shade_stage(hits, params)
}

/// Stage: adds the light of the shadow rays that the medium and shading
/// stages traced to the paths; drains the shadow queue.
pub fn trace_shadow_rays(
    mut shadows: ResMut<ShadowRays>,
    mut radiance: ResMut<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    stats.0.run_stage(Stage::TraceShadowRays, |_| {
        kernels::trace_shadow_rays(&shadows.0, &mut radiance.0);
        shadows.0.clear();
    });
}

/// Bookkeeping at the end of a bounce: records the largest total of bytes
/// the queues and scratch buffers have held.
#[allow(clippy::too_many_arguments)]
pub fn record_queue_bytes(
    rays: Res<CurrentRays>,
    next: Res<NextRays>,
    found: Res<BounceHits>,
    escaped: Res<EscapedRays>,
    hits: HitQueues,
    shadows: Res<ShadowRays>,
    scratch: Res<StageScratch>,
    radiance: Res<PathRadiance>,
    mut stats: ResMut<WavefrontStats>,
) {
    let bytes = rays.0.bytes()
        + next.0.bytes()
        + found.0.bytes()
        + escaped.0.bytes()
        + hits.bytes()
        + shadows.0.bytes()
        + scratch.bytes()
        + radiance.0.capacity() * std::mem::size_of::<Color>();
    stats.0.peak_queue_bytes = stats.0.peak_queue_bytes.max(bytes);
}

/// The next bounce's rays become current.
pub fn advance_bounce(
    mut rays: ResMut<CurrentRays>,
    mut next: ResMut<NextRays>,
    shadows: Res<ShadowRays>,
) {
    debug_assert!(shadows.0.is_empty(), "shadow rays left untraced");
    std::mem::swap(&mut rays.0, &mut next.0);
    next.0.clear();
}

/// Stage: adds the batch's paths to their pixels.
pub fn update_film(
    config: Res<RenderConfig>,
    frame: Res<WavefrontFrame>,
    radiance: Res<PathRadiance>,
    wavelengths: Res<PathWavelengths>,
    pixels: Res<PixelSums>,
    mut stats: ResMut<WavefrontStats>,
) {
    let (first, _) = frame.batches[frame.batch];
    stats.0.run_stage(Stage::UpdateFilm, |counters| {
        let mut sums = pixels.0.lock().unwrap_or_else(|e| e.into_inner());
        kernels::update_film(
            &radiance.0,
            &wavelengths.0,
            config.settings.path_slots(),
            &frame.paths,
            first,
            &mut sums,
            counters,
        )
    });
}

/// Why the wavefront integrator refuses photon transport.
pub const PHOTON_ON_WAVEFRONT: &str = "photon transport runs on the recursive integrator (--integrator recursive): \
its photon pass is already one parallel light-side pass, and its camera side (a specular chain per sample \
that reads the photon maps at diffuse surfaces, with optional final gathering) has no stage in the \
wavefront's material-class queues yet";

/// The error of a path-traced frame with caustic connections asked of the
/// wavefront integrator.
pub const CAUSTICS_ON_WAVEFRONT: &str = "caustic connections (--caustics) run on the recursive integrator \
(--integrator recursive): the wavefront has no stage for their light subpaths yet";

/// Renders one frame with the wavefront integrator: runs the batch and
/// bounce schedules until every path is finished, then writes [`Frame`].
pub fn render_wavefront(world: &mut World) {
    let Some((scene, camera)) = frame_preconditions(world) else {
        return;
    };
    let config = world.resource::<RenderConfig>().clone();
    let settings = &config.settings;
    if settings.transport == crate::core::settings::Transport::Photon {
        world.resource_mut::<Frame>().error = Some(PHOTON_ON_WAVEFRONT.into());
        return;
    }
    if settings.transport == crate::core::settings::Transport::Path && settings.caustics {
        world.resource_mut::<Frame>().error = Some(CAUSTICS_ON_WAVEFRONT.into());
        return;
    }
    let classes: Vec<MaterialClass> = scene.materials().iter().map(|m| m.class()).collect();
    let features = SceneFeatures::of(&scene);
    let media = scene.has_media() && settings.transport == crate::core::settings::Transport::Path;
    // Gooch shading traces no shadow rays; scattering events in media do.
    let shadows =
        (features.needs_shadow_rays(settings.transport) && settings.style != Style::Gooch) || media;
    let batch_size = world.resource::<BatchSize>().0;
    let batches: Vec<(u64, usize)> = wavefront::batch_ranges(settings, batch_size).collect();
    let paths = settings.path_map();
    let (window_width, window_rows) = (paths.columns(), paths.rows().len() as u32);
    let camera = crate::integrators::camera_rays(&scene, &camera, settings);
    world.insert_resource(WavefrontFrame {
        paths,
        scene,
        camera,
        classes,
        batches: batches.clone(),
        batch: 0,
        features,
        shadows,
        media,
    });
    let sums = PixelSums(Arc::new(Mutex::new(PixelAccumulator::new(
        window_width,
        window_rows,
    ))));
    world.insert_resource(sums.clone());
    world.insert_resource(WavefrontStats::default());

    // One lane per worker thread, each a world of its own running whole
    // batches through the same schedules: a lane's stages run back to
    // back on its thread, with no wait for the other threads between
    // stages. Lane 0 is this world.
    let lanes = rayon::current_num_threads().min(batches.len()).max(1);
    let mut extra = world
        .remove_resource::<WavefrontLanes>()
        .unwrap_or_default();
    extra.prepare(world, lanes - 1);

    let start = Instant::now();
    let rows_per_path =
        1.0 / (window_width as f64 * (world.resource::<WavefrontFrame>().paths.samples()) as f64);
    let progress = LaneProgress {
        report: config.progress.clone(),
        rows_per_path,
        paths_done: AtomicU64::new(0),
        rows_reported: AtomicU64::new(0),
    };
    // Batch 0 goes to lane 0 (so this world's queues always see a batch);
    // the others go to whichever lane asks first. Each batch's paths are
    // a pure function of the batch and pixel sums are exact, so the image
    // does not depend on which lane ran which batch.
    let next = AtomicUsize::new(1);
    let (progress, next, batches) = (&progress, &next, &batches[..]);
    rayon::scope(|s| {
        for lane in extra.0.iter_mut() {
            s.spawn(move |_| run_lane(lane, None, next, batches, progress));
        }
        run_lane(world, Some(0), next, batches, progress);
    });
    let render_seconds = start.elapsed().as_secs_f64();
    let mut report = world.resource::<WavefrontStats>().0;
    for lane in &extra.0 {
        report.add_lane(&lane.resource::<WavefrontStats>().0);
    }
    report.batches = batches.len();
    report.lanes = lanes;
    extra.release();
    world.insert_resource(extra);
    let sums = std::mem::take(&mut *sums.0.lock().unwrap_or_else(|e| e.into_inner()));
    let film = sums.resolve();
    let mut frame = world.resource_mut::<Frame>();
    frame.film = Some(film);
    frame.sums = settings.window.is_some().then_some(sums);
    frame.counters = report.counters;
    frame.render_seconds = render_seconds;
    frame.wavefront = Some(report);
}

/// The worlds of the wavefront's lanes besides the main world, kept
/// between frames (with their schedules and grown queues).
#[derive(Resource, Default)]
pub struct WavefrontLanes(Vec<World>);

impl WavefrontLanes {
    /// Makes `count` lane worlds ready for the frame `main` is about to
    /// render: the main world's settings, frame, pixel sums, batch size
    /// and gating, and fresh statistics.
    fn prepare(&mut self, main: &World, count: usize) {
        self.0.truncate(count);
        while self.0.len() < count {
            let mut w = World::new();
            add_wavefront_schedules(&mut w);
            self.0.push(w);
        }
        let mut config = main.resource::<RenderConfig>().clone();
        config.progress = None;
        for w in &mut self.0 {
            w.insert_resource(config.clone());
            w.insert_resource(main.resource::<WavefrontFrame>().clone());
            w.insert_resource(main.resource::<PixelSums>().clone());
            w.insert_resource(*main.resource::<BatchSize>());
            w.insert_resource(*main.resource::<StageGating>());
            w.insert_resource(WavefrontStats::default());
        }
    }
}

impl WavefrontLanes {
    /// Drops what the lanes hold of the finished frame. Their copies of
    /// [`WavefrontFrame`] share the scene: kept until the next frame, they
    /// made the scene look shared to the next scene sync, which then
    /// rebuilt everything from scratch every frame (the frame loop's
    /// moved objects became 22 fresh instances and 4 mesh BVH builds).
    fn release(&mut self) {
        for w in &mut self.0 {
            w.remove_resource::<WavefrontFrame>();
            w.remove_resource::<PixelSums>();
        }
    }
}

/// Progress of a frame rendered by several lanes: rows finished, reported
/// as batches finish in any order.
struct LaneProgress {
    report: Option<super::ProgressFn>,
    rows_per_path: f64,
    paths_done: AtomicU64,
    rows_reported: AtomicU64,
}

impl LaneProgress {
    /// Counts `paths` more finished paths and reports the rows they
    /// complete.
    fn finished(&self, paths: usize) {
        let Some(p) = &self.report else { return };
        let done = self.paths_done.fetch_add(paths as u64, Ordering::Relaxed) + paths as u64;
        let rows = (done as f64 * self.rows_per_path) as u64;
        let before = self.rows_reported.fetch_max(rows, Ordering::Relaxed);
        if rows > before {
            p(rows - before);
        }
    }
}

/// Runs batches through `world`'s schedules until none is left: `first`
/// (if any), then the next unclaimed one from `next`, in turn.
fn run_lane(
    world: &mut World,
    first: Option<usize>,
    next: &AtomicUsize,
    batches: &[(u64, usize)],
    progress: &LaneProgress,
) {
    let mut batch = first;
    loop {
        let b = match batch.take() {
            Some(b) => b,
            None => next.fetch_add(1, Ordering::Relaxed),
        };
        let Some(&(_, count)) = batches.get(b) else {
            return;
        };
        world.resource_mut::<WavefrontFrame>().batch = b;
        world.run_schedule(StartBatch);
        while !world.resource::<CurrentRays>().0.is_empty() {
            world.run_schedule(Bounce);
        }
        world.run_schedule(FinishBatch);
        progress.finished(count);
    }
}

/// Stage times of the last frame (zero for the recursive integrator).
pub fn last_stage_seconds(world: &World) -> StageSeconds {
    world
        .get_resource::<WavefrontStats>()
        .map(|s| s.0.stages)
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The system of `stage`: the match makes sure that every stage has
    /// one.
    fn system_name(stage: Stage) -> &'static str {
        use std::any::type_name_of_val as name;
        match stage {
            Stage::GenerateCameraRays => name(&generate_camera_rays),
            Stage::IntersectClosest => name(&intersect_closest),
            Stage::SampleMedia => name(&sample_media),
            Stage::HandleEscapedRays => name(&handle_escaped_rays),
            Stage::ShadeEmissive => name(&shade_emissive),
            Stage::ShadeDiffuse => name(&shade_diffuse),
            Stage::ShadeMirror => name(&shade_mirror),
            Stage::ShadeGlass => name(&shade_glass),
            Stage::ShadeGeneral => name(&shade_general),
            Stage::TraceShadowRays => name(&trace_shadow_rays),
            Stage::UpdateFilm => name(&update_film),
        }
    }

    #[test]
    fn stage_systems_are_named_after_their_stages() {
        for stage in Stage::ALL {
            let name = system_name(stage);
            assert_eq!(name.rsplit("::").next(), Some(stage.name()), "{name}");
        }
    }
}
