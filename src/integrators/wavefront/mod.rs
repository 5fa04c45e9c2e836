//! The wavefront integrator's kernels: each stage drains one queue and
//! fills others.
//!
//! * [`queues`]: the structure-of-arrays queues;
//! * [`stages`]: the stage kernels, plain functions over the queues, which
//!   the ECS systems in `systems/wavefront.rs` call (the order of the
//!   stages is declared there, once);
//! * [`routing`]: which queue a ray, a hit or a shading result goes to
//!   next, decided in one place;
//! * [`drain`]: how a stage drains its queue in parallel. Every parallel
//!   stage splits its queue into fixed-size chunks and joins the chunks'
//!   output in chunk order, so queue contents, and therefore images, do
//!   not depend on the number of threads;
//! * here: the chunk and batch sizes, the list of stages ([`Stage`]) and
//!   what the wavefront reports ([`WavefrontReport`]).
//!
//! The math is the recursive tracer's: [`scene::RenderScene::intersect`],
//! [`shading::Interaction`], [`shading::direct_light`] and
//! [`shading::scatter`]. Only the control flow differs.
//!
//! [`scene::RenderScene::intersect`]: crate::scene::RenderScene::intersect
//! [`shading::Interaction`]: crate::transport::interaction::Interaction
//! [`shading::direct_light`]: crate::transport::whitted::direct_light
//! [`shading::scatter`]: crate::transport::whitted::scatter

pub mod drain;
pub mod queues;
pub mod routing;
pub mod stages;

use std::time::Instant;

use serde::ser::{Serialize, SerializeMap, Serializer};

use crate::core::settings::RenderSettings;
use crate::integrators::counters::RenderCounters;
use crate::scene::material::MaterialClass;

/// Items per parallel work chunk: large enough to amortise scheduling,
/// small enough to balance two to a few dozen threads.
pub const CHUNK: usize = 1024;

/// Default number of paths (pixel samples) per batch: render time hardly
/// depends on it over a wide range, but queue memory grows with it, so
/// the default is small (the measurements are in the README's notes).
pub const DEFAULT_BATCH_PATHS: usize = 1 << 13;

/// Where each batch starts and how many paths it has.
pub fn batch_ranges(
    settings: &RenderSettings,
    batch_paths: usize,
) -> impl Iterator<Item = (u64, usize)> {
    let total = settings.path_map().path_count();
    let step = batch_paths.max(1) as u64;
    (0..total.div_ceil(step)).map(move |b| {
        let first = b * step;
        (first, (total - first).min(step) as usize)
    })
}

/// Defines [`Stage`] from one list of stages, in the order they run: each
/// with its doc, its name and, for a shading stage, the material class it
/// shades.
macro_rules! stages {
    ($($(#[doc = $doc:literal])+ $stage:ident = $name:literal $(shades $class:ident)?,)+) => {
        /// A stage of the wavefront: one ECS system (in
        /// `systems/wavefront.rs`) named [`Stage::name`], and one entry of
        /// `wavefront.stage_runs` in the output of `prism render --stats`.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum Stage {
            $($(#[doc = $doc])+ $stage,)+
        }

        impl Stage {
            /// Every stage, in the order they run.
            pub const ALL: [Stage; [$($name),+].len()] = [$(Stage::$stage),+];

            /// The stage's name: that of its system, and its key in
            /// `wavefront.stage_runs` and `wavefront.stages_run`.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Stage::$stage => $name,)+
                }
            }

            /// The material class a shading stage shades; `None` for the
            /// other stages.
            pub const fn class(self) -> Option<MaterialClass> {
                match self {
                    $(Stage::$stage => stages!(@class $($class)?),)+
                }
            }

            /// The stage that shades `class`.
            pub const fn shade(class: MaterialClass) -> Stage {
                match class {
                    $($(MaterialClass::$class => Stage::$stage,)?)+
                }
            }
        }
    };
    (@class $class:ident) => { Some(MaterialClass::$class) };
    (@class) => { None };
}

stages! {
    /// Camera ray generation (once per batch).
    GenerateCameraRays = "generate_camera_rays",
    /// Closest-hit traversal and routing of rays to queues (once per
    /// bounce).
    IntersectClosest = "intersect_closest",
    /// Following rays through participating media (path transport, scenes
    /// with media only).
    SampleMedia = "sample_media",
    /// Adding the background for escaped rays.
    HandleEscapedRays = "handle_escaped_rays",
    /// Shading of emissive-only materials.
    ShadeEmissive = "shade_emissive" shades Emissive,
    /// Shading of diffuse/glossy materials.
    ShadeDiffuse = "shade_diffuse" shades Diffuse,
    /// Shading of mirrors (the reflection stage).
    ShadeMirror = "shade_mirror" shades Mirror,
    /// Shading of glass (the refraction stage).
    ShadeGlass = "shade_glass" shades Glass,
    /// Shading of materials with several lobes.
    ShadeGeneral = "shade_general" shades General,
    /// Adding the light of the bounce's shadow rays to their paths (the
    /// rays are traced by the stages that make them, chunk by chunk, and
    /// the time spent tracing them counts as theirs).
    TraceShadowRays = "trace_shadow_rays",
    /// Adding finished paths to the film (once per batch).
    UpdateFilm = "update_film",
}

impl Stage {
    /// Number of stages.
    pub const COUNT: usize = Stage::ALL.len();

    /// The stage's key in `wavefront.stage_seconds`: the shading stages
    /// share one, `"shade"`.
    pub const fn seconds_key(self) -> &'static str {
        if self.class().is_some() {
            "shade"
        } else {
            self.name()
        }
    }
}

/// Wall time spent in each stage, in seconds. Serialised by
/// [`Stage::seconds_key`]: one field per stage, the shading stages summed
/// into one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageSeconds([f64; Stage::COUNT]);

impl StageSeconds {
    /// Seconds spent in `stage`.
    pub fn get(&self, stage: Stage) -> f64 {
        self.0[stage as usize]
    }

    /// Adds `seconds` to `stage`.
    pub fn add(&mut self, stage: Stage, seconds: f64) {
        self.0[stage as usize] += seconds;
    }

    /// Seconds by [`Stage::seconds_key`], in stage order: shading, all
    /// material classes, as one entry.
    pub fn by_key(&self) -> Vec<(&'static str, f64)> {
        let mut keys: Vec<(&'static str, f64)> = Vec::new();
        for stage in Stage::ALL {
            let seconds = self.get(stage);
            match keys.last_mut() {
                Some((key, sum)) if *key == stage.seconds_key() => *sum += seconds,
                _ => keys.push((stage.seconds_key(), seconds)),
            }
        }
        keys
    }

    /// Adds every stage's seconds of `other` (another lane's).
    pub fn add_all(&mut self, other: &StageSeconds) {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
    }

    /// Sum of all stages.
    pub fn total(&self) -> f64 {
        self.0.iter().sum()
    }
}

impl Serialize for StageSeconds {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let keys = self.by_key();
        let mut map = serializer.serialize_map(Some(keys.len()))?;
        for (key, seconds) in keys {
            map.serialize_entry(key, &seconds)?;
        }
        map.end()
    }
}

/// How many times each stage system ran during a frame: stages a scene
/// does not need never run. Serialised as one field per stage, named
/// [`Stage::name`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageRuns([u32; Stage::COUNT]);

impl StageRuns {
    /// Runs of `stage`.
    pub fn get(&self, stage: Stage) -> u32 {
        self.0[stage as usize]
    }

    /// Counts one run of `stage`.
    pub fn record(&mut self, stage: Stage) {
        self.0[stage as usize] += 1;
    }

    /// Adds every stage's runs of `other` (another lane's).
    pub fn add_all(&mut self, other: &StageRuns) {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
    }

    /// Names of the stages that ran at least once, in stage order.
    pub fn names_run(&self) -> Vec<&'static str> {
        Stage::ALL
            .into_iter()
            .filter(|&s| self.get(s) > 0)
            .map(Stage::name)
            .collect()
    }
}

impl Serialize for StageRuns {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(Stage::COUNT))?;
        for stage in Stage::ALL {
            map.serialize_entry(stage.name(), &self.get(stage))?;
        }
        map.end()
    }
}

/// Everything the wavefront reports beyond the image.
#[derive(Clone, Copy, Debug, Default)]
pub struct WavefrontReport {
    /// Runs of each stage system.
    pub runs: StageRuns,
    /// Rays and dropped samples.
    pub counters: RenderCounters,
    /// Time per stage, summed over the lanes that ran batches side by
    /// side (thread time: with two lanes, about twice the wall time).
    pub stages: StageSeconds,
    /// Largest total of bytes held by one lane's queues at once (the
    /// largest of the lanes'): what a batch needs. The lanes together
    /// hold at most `lanes` times as much.
    pub peak_queue_bytes: usize,
    /// Number of batches.
    pub batches: usize,
    /// Number of lanes: worlds that ran batches side by side, one per
    /// worker thread (at most one per batch).
    pub lanes: usize,
}

impl WavefrontReport {
    /// Adds the report of another lane of the same frame: runs, counters
    /// and stage seconds (which then add up the lanes' thread time) are
    /// summed, queue bytes are the larger peak.
    pub fn add_lane(&mut self, other: &WavefrontReport) {
        self.runs.add_all(&other.runs);
        self.counters.add(&other.counters);
        self.stages.add_all(&other.stages);
        self.peak_queue_bytes = self.peak_queue_bytes.max(other.peak_queue_bytes);
    }

    /// Runs `f` as one run of `stage`: counts the run and adds the time
    /// `f` takes to the stage's. `f` gets the counters to fill.
    pub fn run_stage<R>(&mut self, stage: Stage, f: impl FnOnce(&mut RenderCounters) -> R) -> R {
        self.runs.record(stage);
        let start = Instant::now();
        let r = f(&mut self.counters);
        self.stages.add(stage, start.elapsed().as_secs_f64());
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_has_one_shading_stage() {
        for class in MaterialClass::ALL {
            let stage = Stage::shade(class);
            assert_eq!(stage.class(), Some(class));
            assert_eq!(stage.seconds_key(), "shade");
        }
        let shading = Stage::ALL.iter().filter(|s| s.class().is_some()).count();
        assert_eq!(shading, MaterialClass::ALL.len());
    }

    #[test]
    fn stats_json_keeps_its_field_names() {
        let mut runs = StageRuns::default();
        runs.record(Stage::GenerateCameraRays);
        runs.record(Stage::ShadeDiffuse);
        runs.record(Stage::ShadeDiffuse);
        assert_eq!(
            serde_json::to_string(&runs).unwrap(),
            r#"{"generate_camera_rays":1,"intersect_closest":0,"sample_media":0,"handle_escaped_rays":0,"shade_emissive":0,"shade_diffuse":2,"shade_mirror":0,"shade_glass":0,"shade_general":0,"trace_shadow_rays":0,"update_film":0}"#
        );
        assert_eq!(runs.names_run(), ["generate_camera_rays", "shade_diffuse"]);
        let mut seconds = StageSeconds::default();
        seconds.add(Stage::IntersectClosest, 0.5);
        seconds.add(Stage::ShadeDiffuse, 0.25);
        seconds.add(Stage::ShadeGlass, 0.5);
        assert_eq!(
            serde_json::to_string(&seconds).unwrap(),
            r#"{"generate_camera_rays":0.0,"intersect_closest":0.5,"sample_media":0.0,"handle_escaped_rays":0.0,"shade":0.75,"trace_shadow_rays":0.0,"update_film":0.0}"#
        );
        assert_eq!(seconds.total(), 1.25);
    }
}
