//! Flags more than one subcommand takes, each declared once, and the
//! values they take.
//!
//! Every flag here is a small [`clap::Args`] struct that a subcommand
//! includes with `#[command(flatten)]` at the place it has always had in
//! that command's `--help`: `render`, `bench` and `tradeoff` list the flags
//! they share in different orders, so one struct per group of flags that
//! stays together in every command keeps each `--help` as it was.
//!
//! The doc comments are `prism render`'s help texts. `bench` and
//! `tradeoff` describe some flags in their own words (shorter, or about
//! their base configuration); they set those texts with `mut_arg` on their
//! own argument structs, so only the wording is repeated, never the flag.

use clap::ValueEnum;

use prism::core::error::{Error, Result};
use prism::core::settings::Transport;
use prism::geometry::mesh::BuildQuality;
use prism::image::output::{PngOptions, ToneMap};
use prism::integrators::IntegratorKind;
use prism::io::desc::SettingsDesc;

/// `--width`, `--height`, `--spp`, `--max-depth` (render, bench, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct FrameFlags {
    /// Image width in pixels [default: the scene's, else 640].
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels [default: the scene's, else 480].
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples per pixel; 1 traces the pixel centre, more are jittered
    /// over the pixel [default: the scene's, else 1].
    #[arg(long)]
    pub spp: Option<u32>,
    /// Maximum number of reflection/refraction bounces after the camera
    /// ray [default: the scene's, else 8].
    #[arg(long)]
    pub max_depth: Option<u32>,
}

impl FrameFlags {
    /// These flags as overrides of a scene's settings; the other settings
    /// are left to the scene.
    pub fn desc(&self) -> SettingsDesc {
        SettingsDesc {
            width: self.width,
            height: self.height,
            spp: self.spp,
            max_depth: self.max_depth,
            ..Default::default()
        }
    }
}

/// `--min-contribution` (render, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct MinContributionFlag {
    /// Do not trace secondary rays whose contribution to the pixel (largest
    /// channel of the path weight) is below this [default: the scene's, else 0.001].
    #[arg(long)]
    pub min_contribution: Option<f32>,
}

/// `--seed` (render, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct SeedFlag {
    /// Seed for pixel jitter [default: the scene's, else 0].
    #[arg(long)]
    pub seed: Option<u64>,
}

/// `--light-samples`, `--rr-depth`, `--rr-weight`, `--sampler` (render, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct PathFlags {
    /// Path tracing: shadow rays per area light at each hit
    /// [default: the scene's, else 1].
    #[arg(long)]
    pub light_samples: Option<u32>,
    /// Path tracing: bounce from which Russian roulette may end paths
    /// [default: the scene's, else 5].
    #[arg(long, value_name = "DEPTH")]
    pub rr_depth: Option<u32>,
    /// Path tracing: Russian roulette's weight. Paths whose throughput is
    /// at least this are never ended by roulette; lighter ones go on with
    /// probability throughput / weight (1: the classic rule, as Mitsuba's)
    /// [default: the scene's, else 0.25].
    #[arg(long, value_name = "WEIGHT")]
    pub rr_weight: Option<f32>,
    /// Path tracing: paths continued from the first
    /// surface each camera ray hits, each weighted 1/N, after one
    /// next-event estimate there (Arnold's diffuse samples, Cycles'
    /// branched path tracing). Where direct light is smooth and the
    /// indirect noisy, 2 reaches a given error sooner than twice the
    /// samples (see the README's "Path transport") [default: the scene's,
    /// else 1].
    #[arg(long, value_name = "N")]
    pub split: Option<u32>,
    /// Random numbers: Owen-scrambled Sobol points, stratified per pixel,
    /// or independent hashed numbers [default: the scene's, else sobol].
    #[arg(long, value_enum)]
    pub sampler: Option<SamplerArg>,
}

impl PathFlags {
    /// The sampler chosen, if one was.
    pub fn sampler(&self) -> Option<prism::core::rng::SamplerKind> {
        self.sampler.map(|s| match s {
            SamplerArg::Sobol => prism::core::rng::SamplerKind::Sobol,
            SamplerArg::Hash => prism::core::rng::SamplerKind::Hash,
        })
    }
}

/// `--sampler`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerArg {
    /// Owen-scrambled Sobol (Burley 2020), padded in sets of four.
    Sobol,
    /// Independent hashed numbers.
    Hash,
}

/// `--camera-projection` (render, lightfield).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct ProjectionFlag {
    /// Camera projection: `perspective`, or a panorama of every direction
    /// around the eye: `equirect` (latitude-longitude, the environment
    /// map's layout; 2:1 images) or `cubemap` (six square faces side by
    /// side, +X -X +Y -Y +Z -Z of the camera frame; width = 6 x height).
    /// The panorama's +X is the camera's view direction, +Y its up
    /// [default: the scene's, else perspective].
    #[arg(long, value_enum, value_name = "PROJECTION")]
    pub camera_projection: Option<ProjectionArg>,
}

impl ProjectionFlag {
    /// The projection asked for, if one was: `Some(None)` is perspective.
    pub fn get(&self) -> Option<Option<prism::core::settings::Panorama>> {
        use prism::core::settings::Panorama;
        self.camera_projection.map(|p| match p {
            ProjectionArg::Perspective => None,
            ProjectionArg::Equirect => Some(Panorama::Equirect),
            ProjectionArg::Cubemap => Some(Panorama::Cubemap),
        })
    }
}

/// `--camera-projection`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProjectionArg {
    /// The scene camera's perspective view.
    Perspective,
    /// Latitude-longitude panorama (360 x 180 degrees).
    Equirect,
    /// Six cube faces in a horizontal strip.
    Cubemap,
}

/// `--threads` (render, bench, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct ThreadsFlag {
    /// Worker threads [default: one per core]. The image does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
}

impl ThreadsFlag {
    /// A rayon pool of that many workers (one per core by default), and
    /// the number.
    pub fn pool(&self) -> Result<(rayon::ThreadPool, usize)> {
        let threads = match self.threads {
            Some(0) => return Err(Error::Invalid("--threads must be at least 1".into())),
            Some(n) => n,
            None => std::thread::available_parallelism().map_or(1, |n| n.get()),
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start {threads} threads: {e}")))?;
        Ok((pool, threads))
    }
}

/// `--integrator` (render, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct IntegratorFlag {
    /// Integrator.
    #[arg(long, value_enum, default_value_t = IntegratorArg::Recursive)]
    pub integrator: IntegratorArg,
}

impl IntegratorFlag {
    /// The integrator chosen.
    pub fn kind(&self) -> IntegratorKind {
        self.integrator.into()
    }
}

/// `--transport` (render, bench).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct TransportFlag {
    /// Light transport [default: the scene's, else whitted].
    #[arg(long, value_enum)]
    pub transport: Option<TransportArg>,
}

impl TransportFlag {
    /// The transport chosen, if one was.
    pub fn get(&self) -> Option<Transport> {
        self.transport.map(Into::into)
    }
}

/// Photon mapping's options (render), each falling back to the scene's
/// `[settings.photon]` and then to the defaults.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct PhotonFlags {
    /// Photon transport: photons traced per iteration, shared among the
    /// lights by power [default: the scene's, else 100000].
    #[arg(long, value_name = "N")]
    pub photons: Option<u32>,
    /// Photon transport: gather radius of the first iteration, in scene
    /// units, above 0 [default: the scene's, else its bounding-box diagonal / 200].
    #[arg(long, value_name = "R", allow_hyphen_values = true)]
    pub photon_radius: Option<f32>,
    /// Photon transport: radius reduction alpha in (0, 1); iteration i+1
    /// gathers over r^2 (i + alpha) / (i + 1) [default: the scene's, else 2/3].
    #[arg(long, value_name = "ALPHA", allow_hyphen_values = true)]
    pub photon_alpha: Option<f32>,
    /// Photon transport: iterations, each with its own photons and `--spp`
    /// camera samples per pixel; the image is their mean [default: the
    /// scene's, else 16].
    #[arg(long, value_name = "N")]
    pub photon_iterations: Option<u32>,
    /// Photon transport: final-gather rays per camera sample; 0 reads the
    /// photon maps directly at the first diffuse surface seen [default: the
    /// scene's, else 0].
    #[arg(long, value_name = "N")]
    pub final_gather: Option<u32>,
}

impl PhotonFlags {
    /// The values given.
    pub fn overrides(&self) -> prism::core::photon_settings::PhotonOverrides {
        prism::core::photon_settings::PhotonOverrides {
            photons: self.photons,
            radius: self.photon_radius,
            alpha: self.photon_alpha,
            iterations: self.photon_iterations,
            gather_rays: self.final_gather,
        }
    }
}

/// `--batch-paths` (render, bench).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct BatchPathsFlag {
    /// Paths (pixel samples) per wavefront batch: bounds queue memory.
    #[arg(long, default_value_t = prism::integrators::wavefront::DEFAULT_BATCH_PATHS)]
    pub batch_paths: usize,
}

impl BatchPathsFlag {
    /// The batch size, which must be at least 1.
    pub fn get(&self) -> Result<usize> {
        if self.batch_paths == 0 {
            return Err(Error::Invalid("--batch-paths must be at least 1".into()));
        }
        Ok(self.batch_paths)
    }
}

/// `--merge-meshes` (render, bench, tradeoff).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct MergeFlag {
    /// When every bounded instance is a mesh used once (a glTF file),
    /// trace them under one BVH in the render frame instead of one BVH per
    /// instance under the top level: one traversal per ray instead of one
    /// per instance reached. Hits are the same surfaces; their last bits
    /// may differ.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = MergeArg::On)]
    pub merge_meshes: MergeArg,
}

/// Values of `--merge-meshes`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MergeArg {
    /// Merge (when at least two instances can be).
    On,
    /// One BVH per instance, under the top level.
    Off,
}

impl MergeFlag {
    /// True for `on`.
    pub fn on(&self) -> bool {
        self.merge_meshes == MergeArg::On
    }
}

/// `--tonemap` (render, compare).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ToneMapArg {
    /// Clip at 1.
    Clamp,
    /// x / (1 + x).
    Reinhard,
}

/// `--style` (render).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum StyleArg {
    /// The transport's physically based lighting.
    Shaded,
    /// Gooch cool-to-warm shading for illustration (no shadows).
    Gooch,
}

impl From<StyleArg> for prism::core::settings::Style {
    fn from(s: StyleArg) -> Self {
        match s {
            StyleArg::Shaded => prism::core::settings::Style::Shaded,
            StyleArg::Gooch => prism::core::settings::Style::Gooch,
        }
    }
}

/// `--integrator` (render, tradeoff).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum IntegratorArg {
    /// Depth-first recursive Whitted tracing, one ray at a time.
    Recursive,
    /// Breadth-first wavefront tracing over SoA queues, one ECS system per stage.
    Wavefront,
}

impl From<IntegratorArg> for IntegratorKind {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Recursive => IntegratorKind::Recursive,
            IntegratorArg::Wavefront => IntegratorKind::Wavefront,
        }
    }
}

/// `--transport` (render, bench).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum TransportArg {
    /// Whitted: point lights, mirror reflection and refraction.
    Whitted,
    /// Path tracing with next-event estimation and MIS; emissive surfaces
    /// are area lights.
    Path,
    /// Radiosity: diffuse interreflection between patches, solved once,
    /// then viewed (see the --radiosity-* and --patch-size options).
    Radiosity,
    /// Progressive photon mapping: caustic and global photon maps from
    /// every light, read at diffuse surfaces (recursive integrator).
    Photon,
}

impl From<TransportArg> for Transport {
    fn from(a: TransportArg) -> Self {
        match a {
            TransportArg::Whitted => Transport::Whitted,
            TransportArg::Path => Transport::Path,
            TransportArg::Radiosity => Transport::Radiosity,
            TransportArg::Photon => Transport::Photon,
        }
    }
}

/// `--bvh-quality` (render). The variants have no doc comments on purpose:
/// clap would list them in `--help`, which shows only the names.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum QualityArg {
    Fastest,
    VeryFast,
    Fast,
    Medium,
    Slow,
    VerySlow,
}

impl From<QualityArg> for BuildQuality {
    fn from(q: QualityArg) -> Self {
        match q {
            QualityArg::Fastest => BuildQuality::Fastest,
            QualityArg::VeryFast => BuildQuality::VeryFast,
            QualityArg::Fast => BuildQuality::Fast,
            QualityArg::Medium => BuildQuality::Medium,
            QualityArg::Slow => BuildQuality::Slow,
            QualityArg::VerySlow => BuildQuality::VerySlow,
        }
    }
}

/// `--accel` (render, bench): the structure over mesh triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AccelArg {
    Bvh,
    Kdtree,
    Grid,
    Brute,
}

impl From<AccelArg> for prism::core::settings::Accel {
    fn from(a: AccelArg) -> Self {
        use prism::core::settings::Accel;
        match a {
            AccelArg::Bvh => Accel::Bvh,
            AccelArg::Kdtree => Accel::Kdtree,
            AccelArg::Grid => Accel::Grid,
            AccelArg::Brute => Accel::Brute,
        }
    }
}

/// The display mapping of `--exposure` and `--tonemap` (render, compare);
/// the exposure must be finite.
pub fn png_options(exposure: f32, tonemap: ToneMapArg) -> Result<PngOptions> {
    if !exposure.is_finite() {
        return Err(Error::Invalid("--exposure must be finite".into()));
    }
    Ok(PngOptions {
        exposure,
        tone_map: match tonemap {
            ToneMapArg::Clamp => ToneMap::Clamp,
            ToneMapArg::Reinhard => ToneMap::Reinhard,
        },
    })
}
