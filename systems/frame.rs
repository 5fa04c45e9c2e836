//! The resources of a frame: what to render ([`RenderConfig`]), what was
//! extracted and built from the world, progressive accumulation, and the
//! finished [`Frame`].

use std::sync::Arc;

use bevy_ecs::prelude::*;

use crate::accel::tlas::{TlasCounters, TlasUpdate};
use crate::core::math::Color;
use crate::core::settings::RenderSettings;
use crate::geometry::mesh::BuildQuality;
use crate::image::film::{Film, PixelAccumulator};
use crate::image::lines::LineOverlay;
use crate::integrators::IntegratorKind;
use crate::integrators::counters::RenderCounters;
use crate::integrators::progressive::Accumulator;
use crate::integrators::wavefront::WavefrontReport;
use crate::scene::RenderScene;
use crate::scene::camera::Camera;
use crate::scene::environment::Environment;

/// Called with the number of image rows finished.
pub type ProgressFn = Arc<dyn Fn(u64) + Send + Sync>;

/// How frames are rendered.
#[derive(Resource, Clone)]
pub struct RenderConfig {
    /// Image size, samples, depth, threshold, seed.
    pub settings: RenderSettings,
    /// Integrator.
    pub integrator: IntegratorKind,
    /// Which camera entity to render from; the first camera (lowest
    /// entity id) when `None`.
    pub camera: Option<Entity>,
    /// BVH build preset for the top level.
    pub bvh_quality: BuildQuality,
    /// Radiance of escaped rays.
    pub background: Color,
    /// Light from infinitely far away; escaped rays bring back its
    /// radiance instead of `background` when present.
    pub environment: Option<Environment>,
    /// The medium outside every object (global fog), if any.
    pub fog: Option<crate::core::medium::Medium>,
    /// Optional progress callback.
    pub progress: Option<ProgressFn>,
    /// Merge the scene's mesh instances under one BVH at the first commit
    /// when every bounded instance is a single-use mesh ([`RenderScene::set_mesh_merging`](crate::scene::RenderScene::set_mesh_merging)):
    /// faster queries for scenes that stand still; undone, once, by the
    /// first change that touches a merged instance. Off by default.
    pub merge_meshes: bool,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            settings: RenderSettings::default(),
            integrator: IntegratorKind::default(),
            camera: None,
            bvh_quality: BuildQuality::default(),
            background: Color::ZERO,
            environment: None,
            fog: None,
            progress: None,
            merge_meshes: false,
        }
    }
}

/// The camera read from the world this frame, or why the frame cannot be
/// rendered.
#[derive(Resource, Default)]
pub struct ExtractedScene {
    pub(super) camera: Option<Camera>,
    pub(super) error: Option<String>,
}

/// The render-ready scene with its BVH. It persists between frames and is
/// updated in place by the systems of [`sync`](super::sync).
#[derive(Resource, Default)]
pub struct SceneAccel {
    /// The scene, once built.
    pub scene: Option<Arc<RenderScene>>,
    /// Seconds spent updating the top-level BVH this frame.
    pub build_seconds: f64,
}

/// Progressive accumulation: while nothing changes (scene, camera,
/// settings), each frame adds `spp` samples per pixel to the previous
/// ones, and frame `k` is bit for bit the image of `k * spp` samples (see
/// [`crate::integrators::progressive`]). Any change (fog included) starts
/// again from `spp` samples.
/// Applies to the recursive integrator (Whitted or path transport); the
/// wavefront renders each frame independently.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProgressiveRendering {
    /// Accumulate frames while nothing changes.
    pub enabled: bool,
}

/// What progressive sums were rendered with besides the scene: settings,
/// camera, background, environment and fog.
pub(super) type AccumulationKey = (
    RenderSettings,
    Camera,
    Color,
    Option<Environment>,
    Option<crate::core::medium::Medium>,
);

/// The running sums of progressive rendering and what they were rendered
/// with.
#[derive(Resource, Default)]
pub struct AccumulationState {
    pub(super) accumulator: Accumulator,
    pub(super) key: Option<AccumulationKey>,
}

/// The finished frame.
#[derive(Resource, Default)]
pub struct Frame {
    /// The image, or `None` if the frame failed: the whole image, or the
    /// window's pixels (its columns by its rows, in order) when the
    /// settings have a [`window`](RenderSettings::window).
    pub film: Option<Film>,
    /// Each window pixel's exact sum and sample count, laid out like
    /// `film`: only for windowed one-shot frames (shards), whose sample
    /// ranges are merged by adding sums.
    pub sums: Option<PixelAccumulator>,
    /// Why the frame failed.
    pub error: Option<String>,
    /// Rays traced and non-finite samples caught.
    pub counters: RenderCounters,
    /// Seconds spent tracing.
    pub render_seconds: f64,
    /// Stage times and queue memory, for wavefront frames.
    pub wavefront: Option<WavefrontReport>,
    /// What the scene update did this frame, with its timings and BVH
    /// work counters.
    pub update: SceneUpdateReport,
    /// Samples per pixel in the image (more than `spp` when progressive
    /// frames accumulated).
    pub samples: u32,
    /// Feature-line coverage, when the settings ask for lines.
    pub lines: Option<LineOverlay>,
    /// Rays cast by the line stage (not in `counters`).
    pub line_rays: u64,
    /// Seconds spent finding lines.
    pub line_seconds: f64,
    /// What the photon passes did, for photon-mapped frames.
    pub photon: Option<crate::integrators::photon::PhotonReport>,
}

/// Where the render origin (floating origin) goes. Entities keep their
/// [`Transform`](crate::geometry::transform::Transform)s and cameras in
/// world coordinates, in f64; before a frame, every placement is made
/// relative to the render origin in f64 and only then rounded to the f32
/// the kernels use, so precision depends on the distance to the render
/// origin, not to the world origin. Moving the origin re-expresses every
/// instance and light (a top-level BVH update; mesh BVHs live in object
/// space and are never rebuilt). Insert this resource to change the
/// default; the origin in use is reported in
/// [`SceneUpdateReport::origin`].
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub enum RenderOrigin {
    /// Follow the active camera: the origin starts exactly at the camera
    /// and jumps to it again whenever the camera is farther than
    /// `recenter_distance` world units from it. Between jumps the camera
    /// is at most that far from the origin, so everything within a
    /// distance `r` of the camera is represented to about
    /// `(recenter_distance + r) * 6e-8` (half an f32 ulp), whatever its
    /// distance to the world origin.
    FollowCamera {
        /// How far the camera may move before the origin follows.
        recenter_distance: f64,
    },
    /// A fixed world point.
    Fixed(glam::DVec3),
}

impl Default for RenderOrigin {
    /// Follows the camera, recentring after it has moved 64 units.
    fn default() -> Self {
        RenderOrigin::FollowCamera {
            recenter_distance: 64.0,
        }
    }
}

/// What the last frame's scene update did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SceneUpdateReport {
    /// Objects removed from the scene.
    pub removed: u32,
    /// Objects added to the scene.
    pub added: u32,
    /// Objects whose transform changed.
    pub moved: u32,
    /// Objects whose shape or mesh changed.
    pub regeometry: u32,
    /// Objects whose material changed.
    pub rematerial: u32,
    /// The lights were gathered again.
    pub lights_changed: bool,
    /// The render origin moved this frame: every instance and light was
    /// re-expressed relative to it (a top-level update, no mesh BVH build).
    pub rebased: bool,
    /// The render origin (world coordinates) the frame was rendered in.
    pub origin: glam::DVec3,
    /// The scene was created afresh (first frame, BVH quality change, or
    /// the previous scene still shared elsewhere).
    pub reset: bool,
    /// What happened to the top-level BVH.
    pub tlas: TlasUpdate,
    /// Cumulative top-level work since the scene was created.
    pub tlas_counters: TlasCounters,
    /// Mesh BVHs built by the process so far
    /// ([`crate::geometry::mesh::mesh_bvh_builds`]); scene updates never add to it.
    pub mesh_bvh_builds: u64,
    /// Seconds spent applying ECS changes to the scene.
    pub sync_seconds: f64,
    /// Seconds spent updating the top-level BVH.
    pub accel_seconds: f64,
}

impl SceneUpdateReport {
    /// True when anything in the scene changed this frame.
    pub fn changed(&self) -> bool {
        self.reset
            || self.removed + self.added + self.moved + self.regeometry + self.rematerial > 0
            || self.lights_changed
            || self.rebased
    }
}
