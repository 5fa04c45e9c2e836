//! What `prism render --stats FILE.json` writes, and the ray counts
//! `prism bench --json` prints.

use serde::Serialize;

use prism::integrators::counters::RayCounts;
use prism::integrators::wavefront::{StageRuns, StageSeconds};
use prism::scene::features::SceneFeatures;

/// Ray counts with their total, as serialised.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct RayCountsJson {
    /// Primary rays.
    pub camera: u64,
    /// Shadow rays.
    pub shadow: u64,
    /// Reflection rays.
    pub reflection: u64,
    /// Refraction rays.
    pub refraction: u64,
    /// All rays.
    pub total: u64,
}

/// Everything `--stats` reports.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    /// Scene file.
    pub scene: String,
    /// Integrator name.
    pub integrator: String,
    /// Light transport name.
    pub transport: String,
    /// Photon passes (photon transport only): photons, radii, time and
    /// peak map memory.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub photon: Option<prism::integrators::photon::PhotonReport>,
    /// What the scene contains, which decides the stages that run.
    pub features: SceneFeatures,
    /// Whole run, from start to written image.
    pub wall_seconds: f64,
    /// Reading and parsing scene files, building mesh BVHs included.
    pub load_seconds: f64,
    /// Building bottom-level (mesh) and top-level BVHs.
    pub bvh_build_seconds: f64,
    /// Structure over mesh triangles (`bvh`, `kdtree`, `grid`, `brute`).
    pub accel: &'static str,
    /// Bytes of the mesh structures (nodes or cells and triangle lists;
    /// the top level not counted; the merged group's copy counted).
    pub accel_bytes: usize,
    /// Mesh instances traced under one merged BVH (`--merge-meshes`).
    pub merged_instances: usize,
    /// Rendering pixels.
    pub render_seconds: f64,
    /// Rays by kind.
    pub rays: RayCountsJson,
    /// Millions of rays (all kinds) per second of render time.
    pub mrays_per_second: f64,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Maximum depth.
    pub max_depth: u32,
    /// Worker threads.
    pub threads: usize,
    /// Triangles over all instances.
    pub triangles: usize,
    /// Instances (shapes and mesh instances).
    pub primitives: usize,
    /// Lights.
    pub lights: usize,
    /// Samples that were NaN or infinite, kept out of the image.
    pub nonfinite_samples: u64,
    /// Seconds of the feature-line stage, when lines were drawn.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line_seconds: Option<f64>,
    /// Rays cast by the feature-line stage (not in `rays`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line_rays: Option<u64>,
    /// Radiosity only: patches, iterations, residual, time and memory of
    /// the solve.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radiosity: Option<prism::radiosity::RadiosityStats>,
    /// Wavefront only: time per stage and queue memory.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wavefront: Option<WavefrontStatsJson>,
}

/// The wavefront integrator's own figures.
#[derive(Clone, Debug, Serialize)]
pub struct WavefrontStatsJson {
    /// Seconds per stage, summed over the lanes (thread time).
    pub stage_seconds: StageSeconds,
    /// Largest total of bytes held by one lane's queues at once.
    pub peak_queue_bytes: usize,
    /// Number of batches.
    pub batches: usize,
    /// Lanes that ran batches side by side (one per worker thread).
    pub lanes: usize,
    /// Paths per batch.
    pub batch_paths: usize,
    /// The stage systems that ran (stages the scene does not need do not).
    pub stages_run: Vec<&'static str>,
    /// Runs of each stage system.
    pub stage_runs: StageRuns,
}

impl From<RayCounts> for RayCountsJson {
    fn from(r: RayCounts) -> Self {
        Self {
            camera: r.camera,
            shadow: r.shadow,
            reflection: r.reflection,
            refraction: r.refraction,
            total: r.total(),
        }
    }
}
