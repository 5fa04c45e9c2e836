//! `prism tradeoff`: how much accuracy each speed knob buys or costs.
//!
//! Renders (or reads) a converged path-traced reference, then renders the
//! scene once per knob value, changing one knob at a time away from a base
//! configuration, and measures each render's time and its error against
//! the reference. Writes `tradeoff.csv` and a plot of error against time
//! (`tradeoff.png`, `tradeoff.svg`) with the Pareto front marked.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use clap::ValueEnum;
use indicatif::ProgressBar;

use prism::core::error::{Error, Result};
use prism::core::rng::SamplerKind;
use prism::core::settings::{Accel, RenderSettings, Transport};
use prism::geometry::mesh::{BuildOptions, BuildQuality};
use prism::image::film::Film;
use prism::image::metrics::{self, Metrics};
use prism::image::output::{PngOptions, write_atomic};
use prism::integrators::IntegratorKind;
use prism::io::desc::{SceneDesc, SettingsDesc};
use prism::systems::{self, RenderConfig};

use crate::args::{
    FrameFlags, IntegratorFlag, MinContributionFlag, PathFlags, PhotonFlags, SeedFlag, ThreadsFlag,
};

pub(crate) mod plot;

/// Options of `prism tradeoff`.
///
/// The shared flags set the base configuration and say so in their help
/// texts, which replace `prism render`'s (see [`crate::args`]).
#[derive(clap::Args, Debug)]
#[command(
    mut_arg("width", |a| a.help("Base image width [default: the scene's, else 640]")),
    mut_arg("height", |a| a.help("Base image height [default: the scene's, else 480]")),
    mut_arg("spp", |a| a.help("Base samples per pixel [default: the scene's, else 1]")),
    mut_arg("max_depth", |a| a.help("Base maximum depth [default: the scene's, else 8]")),
    mut_arg("min_contribution", |a| a.help(
        "Base contribution threshold [default: the scene's, else 0.001]"
    )),
    mut_arg("light_samples", |a| a.help(
        "Base light samples per area light [default: the scene's, else 1]"
    )),
    mut_arg("rr_depth", |a| a.help(
        "Base Russian roulette start depth [default: the scene's, else 5]"
    )),
    mut_arg("seed", |a| a.help("Base seed [default: the scene's, else 0]")),
    mut_arg("integrator", |a| a.help("Integrator for every render")),
    mut_arg("threads", |a| a.help("Worker threads [default: one per core]")),
)]
pub struct TradeoffArgs {
    /// Scene file (.toml, .gltf or .glb).
    pub scene: PathBuf,
    /// Folder for tradeoff.csv, tradeoff.png, tradeoff.svg and (when
    /// rendered) reference.exr; created if missing.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Use this EXR as the reference instead of rendering one. It must
    /// have the base image size.
    #[arg(long, value_name = "FILE.exr")]
    pub reference: Option<PathBuf>,
    /// Samples per pixel of the rendered reference.
    #[arg(long, default_value_t = 1024)]
    pub reference_spp: u32,
    /// Maximum depth of the rendered reference (path transport, no
    /// contribution threshold, the base's light samples and roulette).
    #[arg(long, default_value_t = 16)]
    pub reference_max_depth: u32,
    /// Seed of the rendered reference [default: the base seed + 1, so the
    /// reference's samples are independent of the sweep's].
    #[arg(long)]
    pub reference_seed: Option<u64>,
    /// Knobs to sweep, comma-separated [default: all but
    /// photon-iterations, whose renders are long].
    #[arg(long, value_enum, value_delimiter = ',')]
    pub knobs: Vec<Knob>,
    /// `--width`, `--height`, `--spp`, `--max-depth`.
    #[command(flatten)]
    pub frame: FrameFlags,
    /// `--min-contribution`.
    #[command(flatten)]
    pub min_contribution: MinContributionFlag,
    /// `--light-samples`, `--rr-depth`.
    #[command(flatten)]
    pub path: PathFlags,
    /// `--seed`.
    #[command(flatten)]
    pub seed: SeedFlag,
    /// Photon mapping's settings for the renders that use it (the
    /// `transport` and `photon-iterations` knobs).
    #[command(flatten)]
    pub photon: PhotonFlags,
    /// Radiosity's settings for the radiosity row of the `transport` knob.
    #[command(flatten)]
    pub radiosity: crate::radiosity_args::RadiosityFlags,
    /// `--integrator`.
    #[command(flatten)]
    pub integrator: IntegratorFlag,
    /// Renders per configuration; the median time is reported (the image
    /// is the same every time).
    #[arg(long, default_value_t = 1)]
    pub runs: usize,
    /// `--threads`.
    #[command(flatten)]
    pub threads: ThreadsFlag,
    /// TrueType font for the plot's text [default: DejaVu Sans from the
    /// usual system folders]. Without one the plot is drawn unlabelled.
    #[arg(long, value_name = "FILE.ttf")]
    pub font: Option<PathBuf>,
    /// No progress bar, table or summary line.
    #[arg(short, long)]
    pub quiet: bool,
}

/// A setting that trades speed against accuracy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Knob {
    /// Samples per pixel: 1, 2, 4, 8, 16, 32, 64.
    Spp,
    /// Maximum depth: 0, 1, 2, 4, 6, 8, 12.
    MaxDepth,
    /// Contribution threshold: 0, 0.001, 0.01, 0.03, 0.1, 0.3.
    MinContribution,
    /// Shadow rays per area light per hit: 1, 2, 4, 8.
    LightSamples,
    /// Russian roulette: off, from bounce 1, from the base depth (3).
    RussianRoulette,
    /// Russian roulette's weight: 1 (the classic rule), 0.5, 0.25 (the
    /// default), 0.125.
    RrWeight,
    /// BVH build preset, fastest to very slow (the scene is reloaded).
    Bvh,
    /// Light transport: Whitted, path tracing, photon mapping, radiosity.
    Transport,
    /// Random numbers: Owen-scrambled Sobol against independent hashes.
    Sampler,
    /// Structure over mesh triangles: bvh, kdtree, grid (the scene is
    /// reloaded; the image is the same, only the time changes).
    Accel,
    /// Photon mapping's iterations (photon transport): 1, 2, 4, 8, 16, 32,
    /// 64; the error should fall as they grow.
    PhotonIterations,
    /// Paths continued from each camera ray's first hit (path transport):
    /// 1, 2, 4.
    Split,
}

impl Knob {
    /// Every knob, in sweep order.
    pub const ALL: [Knob; 12] = [
        Knob::Spp,
        Knob::MaxDepth,
        Knob::MinContribution,
        Knob::LightSamples,
        Knob::RussianRoulette,
        Knob::RrWeight,
        Knob::Bvh,
        Knob::Transport,
        Knob::Sampler,
        Knob::Accel,
        Knob::PhotonIterations,
        Knob::Split,
    ];

    /// Name as written in the CSV and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Knob::Spp => "spp",
            Knob::MaxDepth => "max-depth",
            Knob::MinContribution => "min-contribution",
            Knob::LightSamples => "light-samples",
            Knob::RussianRoulette => "russian-roulette",
            Knob::RrWeight => "rr-weight",
            Knob::Bvh => "bvh",
            Knob::Transport => "transport",
            Knob::Sampler => "sampler",
            Knob::Accel => "accel",
            Knob::PhotonIterations => "photon-iterations",
            Knob::Split => "split",
        }
    }
}

const SPP_VALUES: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];
const DEPTH_VALUES: [u32; 7] = [0, 1, 2, 4, 6, 8, 12];
const MIN_CONTRIBUTION_VALUES: [f32; 6] = [0.0, 0.001, 0.01, 0.03, 0.1, 0.3];
const LIGHT_SAMPLE_VALUES: [u32; 4] = [1, 2, 4, 8];
// Off, from the first bounce, from bounce 3 (the default until issue 13)
// and from the default bounce (5).
const RR_VALUES: [Option<u32>; 4] = [
    None,
    Some(1),
    Some(3),
    Some(prism::core::settings::DEFAULT_RR_START_DEPTH),
];
const _: () = assert!(prism::core::settings::DEFAULT_RR_START_DEPTH != 3);
const RR_WEIGHT_VALUES: [f32; 4] = [1.0, 0.5, 0.25, 0.125];
const BVH_VALUES: [BuildQuality; 6] = [
    BuildQuality::Fastest,
    BuildQuality::VeryFast,
    BuildQuality::Fast,
    BuildQuality::Medium,
    BuildQuality::Slow,
    BuildQuality::VerySlow,
];
/// Structures over mesh triangles swept by the `accel` knob (brute force
/// is left out: hours on any real mesh).
const ACCEL_VALUES: [Accel; 3] = [Accel::Bvh, Accel::Kdtree, Accel::Grid];
const TRANSPORT_VALUES: [Transport; 4] = [
    Transport::Whitted,
    Transport::Path,
    Transport::Photon,
    Transport::Radiosity,
];
const PHOTON_ITERATION_VALUES: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];
const SAMPLER_VALUES: [SamplerKind; 2] = [SamplerKind::Sobol, SamplerKind::Hash];
const SPLIT_VALUES: [u32; 3] = [1, 2, 4];

/// The name of a BVH preset, as on `prism render --bvh-quality`.
pub fn bvh_name(q: BuildQuality) -> &'static str {
    match q {
        BuildQuality::Fastest => "fastest",
        BuildQuality::VeryFast => "very-fast",
        BuildQuality::Fast => "fast",
        BuildQuality::Medium => "medium",
        BuildQuality::Slow => "slow",
        BuildQuality::VerySlow => "very-slow",
    }
}

fn rr_name(rr: Option<u32>) -> String {
    rr.map_or_else(|| "off".to_string(), |d| d.to_string())
}

/// One render configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// Render settings.
    pub settings: RenderSettings,
    /// Mesh and top-level BVH preset.
    pub bvh: BuildQuality,
    /// Structure over mesh triangles.
    pub accel: Accel,
}

/// One planned render: which knob it varies and to what.
#[derive(Clone, Debug)]
pub struct Planned {
    /// Knob name, or `base` for the base configuration.
    pub knob: &'static str,
    /// The knob's value, as text.
    pub value: String,
    /// The configuration.
    pub config: Config,
}

impl Knob {
    /// The values swept, as text, in order (the CSV's `value` column).
    pub fn values(self) -> Vec<String> {
        match self {
            Knob::Spp => SPP_VALUES.iter().map(|v| v.to_string()).collect(),
            Knob::MaxDepth => DEPTH_VALUES.iter().map(|v| v.to_string()).collect(),
            Knob::MinContribution => MIN_CONTRIBUTION_VALUES
                .iter()
                .map(|v| v.to_string())
                .collect(),
            Knob::LightSamples => LIGHT_SAMPLE_VALUES.iter().map(|v| v.to_string()).collect(),
            Knob::RussianRoulette => RR_VALUES.iter().map(|&v| rr_name(v)).collect(),
            Knob::RrWeight => RR_WEIGHT_VALUES.iter().map(|v| v.to_string()).collect(),
            Knob::Bvh => BVH_VALUES
                .iter()
                .map(|&v| bvh_name(v).to_string())
                .collect(),
            Knob::Transport => TRANSPORT_VALUES
                .iter()
                .map(|v| v.name().to_string())
                .collect(),
            Knob::Accel => ACCEL_VALUES.iter().map(|v| v.name().to_string()).collect(),
            Knob::PhotonIterations => PHOTON_ITERATION_VALUES
                .iter()
                .map(|v| v.to_string())
                .collect(),
            Knob::Sampler => SAMPLER_VALUES
                .iter()
                .map(|v| v.name().to_string())
                .collect(),
            Knob::Split => SPLIT_VALUES.iter().map(|v| v.to_string()).collect(),
        }
    }

    /// Sets this knob in `c` to its `i`-th value.
    fn apply(self, i: usize, c: &mut Config) {
        let s = &mut c.settings;
        match self {
            Knob::Spp => s.spp = SPP_VALUES[i],
            Knob::MaxDepth => s.max_depth = DEPTH_VALUES[i],
            Knob::MinContribution => s.min_contribution = MIN_CONTRIBUTION_VALUES[i],
            Knob::LightSamples => s.light_samples = LIGHT_SAMPLE_VALUES[i],
            Knob::RussianRoulette => s.rr_start_depth = RR_VALUES[i],
            Knob::RrWeight => s.rr_weight = RR_WEIGHT_VALUES[i],
            Knob::Bvh => c.bvh = BVH_VALUES[i],
            Knob::Accel => c.accel = ACCEL_VALUES[i],
            Knob::Transport => s.transport = TRANSPORT_VALUES[i],
            Knob::Sampler => s.sampler = SAMPLER_VALUES[i],
            Knob::Split => s.split = SPLIT_VALUES[i],
            Knob::PhotonIterations => {
                s.transport = Transport::Photon;
                s.photon.iterations = PHOTON_ITERATION_VALUES[i];
            }
        }
    }

    /// This knob's value in `c`, as text.
    pub fn value_of(self, c: &Config) -> String {
        let s = &c.settings;
        match self {
            Knob::Spp => s.spp.to_string(),
            Knob::MaxDepth => s.max_depth.to_string(),
            Knob::MinContribution => s.min_contribution.to_string(),
            Knob::LightSamples => s.light_samples.to_string(),
            Knob::RussianRoulette => rr_name(s.rr_start_depth),
            Knob::RrWeight => s.rr_weight.to_string(),
            Knob::Bvh => bvh_name(c.bvh).to_string(),
            Knob::Accel => c.accel.name().to_string(),
            Knob::Transport => s.transport.name().to_string(),
            Knob::Sampler => s.sampler.name().to_string(),
            Knob::Split => s.split.to_string(),
            Knob::PhotonIterations => match s.transport {
                Transport::Photon => s.photon.iterations.to_string(),
                _ => "-".to_string(),
            },
        }
    }

    /// The knob called `name`.
    pub fn from_name(name: &str) -> Option<Knob> {
        Knob::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// The renders of a sweep: the base first, then each knob's values that
/// differ from the base, one knob at a time.
pub fn plan(base: &Config, knobs: &[Knob]) -> Vec<Planned> {
    let mut out = vec![Planned {
        knob: "base",
        value: String::new(),
        config: base.clone(),
    }];
    for &knob in knobs {
        for (i, value) in knob.values().into_iter().enumerate() {
            let mut config = base.clone();
            knob.apply(i, &mut config);
            if config != *base {
                out.push(Planned {
                    knob: knob.name(),
                    value,
                    config,
                });
            }
        }
    }
    out
}

/// One finished render.
#[derive(Clone, Debug)]
pub struct Row {
    /// What was rendered.
    pub planned: Planned,
    /// Median render seconds (tracing only, not loading or BVH builds).
    pub seconds: f64,
    /// Rays traced.
    pub rays: u64,
    /// Error against the reference.
    pub metrics: Metrics,
}

/// The CSV header.
pub const CSV_HEADER: &str = "knob,value,transport,spp,max_depth,min_contribution,light_samples,\
russian_roulette,bvh,integrator,seconds,rays,rmse,rel_mse,flip,accel,rr_weight,split";

fn csv(rows: &[Row], integrator: IntegratorKind) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        let c = &r.planned.config.settings;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.planned.knob,
            r.planned.value,
            c.transport.name(),
            c.spp,
            c.max_depth,
            c.min_contribution,
            c.light_samples,
            rr_name(c.rr_start_depth),
            bvh_name(r.planned.config.bvh),
            integrator.name(),
            r.seconds,
            r.rays,
            r.metrics.rmse,
            r.metrics.rel_mse,
            r.metrics.flip,
            r.planned.config.accel.name(),
            c.rr_weight,
            c.split,
        );
    }
    s
}

/// Renders `config` `runs` times; returns the image, the median seconds
/// and the rays.
fn render(
    desc: &SceneDesc,
    config: &Config,
    integrator: IntegratorKind,
    runs: usize,
    bar: &Option<ProgressBar>,
) -> Result<(Film, f64, u64)> {
    let mut times = Vec::with_capacity(runs);
    let mut result = None;
    for _ in 0..runs {
        let spp = config.settings.spp as u64;
        let progress: Option<systems::ProgressFn> = bar.clone().map(|b| {
            let f: systems::ProgressFn = Arc::new(move |rows| b.inc(rows * spp));
            f
        });
        let frame = systems::render_scene_desc(
            desc.clone(),
            RenderConfig {
                settings: config.settings.clone(),
                integrator,
                bvh_quality: config.bvh,
                progress,
                // As `prism render` renders by default.
                merge_meshes: true,
                ..Default::default()
            },
            0,
        )?;
        times.push(frame.render_seconds);
        if result.is_none() {
            let film = frame
                .film
                .ok_or_else(|| Error::Invalid("the renderer produced no image".into()))?;
            result = Some((film, frame.counters.rays.total()));
        }
    }
    times.sort_by(f64::total_cmp);
    let (film, rays) = result.ok_or_else(|| Error::Invalid("--runs must be at least 1".into()))?;
    Ok((film, times[times.len() / 2], rays))
}

/// Runs the sweep and writes the CSV and plots.
pub fn run(args: TradeoffArgs) -> Result<()> {
    let wall = Instant::now();
    if args.runs == 0 {
        return Err(Error::Invalid("--runs must be at least 1".into()));
    }
    if args.reference_spp == 0 {
        return Err(Error::Invalid("--reference-spp must be at least 1".into()));
    }
    let (pool, _threads) = args.threads.pool()?;
    pool.install(|| run_in_pool(&args, wall))
}

fn run_in_pool(args: &TradeoffArgs, wall: Instant) -> Result<()> {
    let integrator = args.integrator.kind();
    let knobs: Vec<Knob> = if args.knobs.is_empty() {
        Knob::ALL
            .into_iter()
            .filter(|&k| k != Knob::PhotonIterations)
            .collect()
    } else {
        let mut k: Vec<Knob> = Vec::new();
        for &x in &args.knobs {
            if !k.contains(&x) {
                k.push(x);
            }
        }
        k
    };
    let base_desc = prism::io::load(&args.scene, BuildQuality::Medium)?;
    // The base's structure: the scene's [settings] accel, else the BVH.
    let base_accel = base_desc.settings.accel.unwrap_or_default();
    if base_desc.cameras.is_empty() {
        return Err(Error::load(&args.scene, "the scene has no camera"));
    }
    let mut settings = SettingsDesc {
        min_contribution: args.min_contribution.min_contribution,
        seed: args.seed.seed,
        transport: Some(Transport::Path),
        light_samples: args.path.light_samples,
        rr_start_depth: args.path.rr_depth.map(Some),
        rr_weight: args.path.rr_weight,
        split: args.path.split,
        sampler: args.path.sampler(),
        photon: args.photon.overrides(),
        radiosity: args.radiosity.desc(),
        ..args.frame.desc()
    }
    .resolve(&base_desc.settings);
    if settings.rr_start_depth.is_none() {
        // A scene that turns roulette off still gets the usual base.
        settings.rr_start_depth = Some(prism::core::settings::DEFAULT_RR_START_DEPTH);
    }
    let invalid = |what: &str, e: String| {
        Error::Invalid(format!(
            "{}: invalid {what} settings (from the command line or the scene's [settings]): {e}",
            args.scene.display()
        ))
    };
    settings.validate().map_err(|e| invalid("base", e))?;
    let base = Config {
        settings,
        bvh: BuildQuality::Medium,
        accel: base_accel,
    };
    let reference_config = Config {
        settings: RenderSettings {
            spp: args.reference_spp,
            max_depth: args.reference_max_depth,
            min_contribution: 0.0,
            seed: args
                .reference_seed
                .unwrap_or(base.settings.seed.wrapping_add(1)),
            ..base.settings.clone()
        },
        bvh: BuildQuality::Medium,
        accel: base_accel,
    };
    reference_config
        .settings
        .validate()
        .map_err(|e| invalid("reference", e))?;
    let planned = plan(&base, &knobs);

    // Check everything that can be checked before the long part.
    if args.out.exists() && !args.out.is_dir() {
        return Err(Error::Output {
            path: args.out.clone(),
            message: "exists and is not a folder".into(),
        });
    }
    let given_reference = match &args.reference {
        Some(path) => {
            let film = metrics::read_exr(path)?;
            let (w, h) = (base.settings.width, base.settings.height);
            if (film.width, film.height) != (w, h) {
                return Err(Error::Invalid(format!(
                    "{}: the reference is {}x{} but the base renders {w}x{h}; \
                     pass --width {} --height {}",
                    path.display(),
                    film.width,
                    film.height,
                    film.width,
                    film.height
                )));
            }
            Some(film)
        }
        None => None,
    };
    std::fs::create_dir_all(&args.out).map_err(|e| Error::Output {
        path: args.out.clone(),
        message: e.to_string(),
    })?;
    let font = plot::load_font(args.font.as_deref());
    if let Err(e) = &font
        && !args.quiet
    {
        eprintln!("warning: {e}; the plot will have no labels");
    }

    // Progress in sample-rows: each render adds height x spp per run.
    let work = |c: &Config| {
        let passes = match c.settings.transport {
            // Photon and camera passes of every iteration.
            Transport::Photon => 2 * c.settings.photon.iterations as u64,
            _ => 1,
        };
        c.settings.height as u64 * c.settings.spp as u64 * passes * args.runs as u64
    };
    let mut total: u64 = planned.iter().map(|p| work(&p.config)).sum();
    if given_reference.is_none() {
        total += reference_config.settings.height as u64 * reference_config.settings.spp as u64;
    }
    let bar = crate::render::progress_bar(
        total,
        args.quiet,
        "{spinner} tradeoff [{bar:30}] {percent}% {elapsed_precise} (eta {eta}) {msg}",
    );

    let reference = match given_reference {
        Some(f) => f,
        None => {
            if let Some(b) = &bar {
                b.set_message(format!("reference, {} spp", args.reference_spp));
            }
            let (film, seconds, _) = render(&base_desc, &reference_config, integrator, 1, &bar)?;
            let path = args.out.join("reference.exr");
            prism::image::output::write_image(&path, &film, &PngOptions::default())?;
            if let Some(b) = &bar {
                // Shown on any stderr, not only on a terminal like the bar.
                b.suspend(|| {
                    eprintln!(
                        "reference: {} spp in {seconds:.2} s -> {}",
                        args.reference_spp,
                        path.display()
                    )
                });
            }
            film
        }
    };

    let display = PngOptions::default();
    let mut rows = Vec::with_capacity(planned.len());
    let mut loaded: Option<((BuildQuality, Accel), SceneDesc)> = None;
    for p in planned {
        if let Some(b) = &bar {
            b.set_message(format!("{} {}", p.knob, p.value));
        }
        let desc = if p.config.bvh == BuildQuality::Medium && p.config.accel == base_accel {
            &base_desc
        } else {
            let key = (p.config.bvh, p.config.accel);
            if loaded.as_ref().map(|(k, _)| *k) != Some(key) {
                let options = BuildOptions {
                    quality: p.config.bvh,
                    accel: Some(p.config.accel),
                };
                loaded = Some((key, prism::io::load(&args.scene, options)?));
            }
            &loaded.as_ref().expect("just loaded").1
        };
        let (film, seconds, rays) = match render(desc, &p.config, integrator, args.runs, &bar) {
            Ok(r) => r,
            // Radiosity holds only polygons, meshes and emissive surfaces:
            // other scenes leave its row out rather than the whole sweep.
            Err(e) if p.config.settings.transport == Transport::Radiosity => {
                if let Some(b) = &bar {
                    b.suspend(|| eprintln!("warning: no radiosity row: {e}"));
                } else if !args.quiet {
                    eprintln!("warning: no radiosity row: {e}");
                }
                continue;
            }
            Err(e) => return Err(e),
        };
        let metrics = metrics::compare(&film, &reference, &display)?;
        rows.push(Row {
            planned: p,
            seconds,
            rays,
            metrics,
        });
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }

    let csv_path = args.out.join("tradeoff.csv");
    write_atomic(&csv_path, csv(&rows, integrator).as_bytes())?;
    let title = format!(
        "{}: error against time, {}x{}",
        args.scene.file_name().map_or_else(
            || args.scene.display().to_string(),
            |n| n.to_string_lossy().into()
        ),
        base.settings.width,
        base.settings.height
    );
    let font_ok = font.is_ok();
    let skipped = plot::write_plots(&args.out, &rows, &title, font_ok)?;
    if !args.quiet {
        if skipped > 0 {
            eprintln!(
                "warning: {skipped} render(s) with zero relMSE cannot be shown on the log scale"
            );
        }
        print_table(&rows);
        eprintln!(
            "{} renders in {:.1} s total -> {}, tradeoff.png, tradeoff.svg",
            rows.len() + usize::from(args.reference.is_none()),
            wall.elapsed().as_secs_f64(),
            csv_path.display()
        );
    }
    Ok(())
}

fn print_table(rows: &[Row]) {
    let front = plot::pareto_front(rows);
    println!(
        "{:<17} {:>10} {:>10} {:>12} {:>12} {:>12} {:>9}",
        "knob", "value", "seconds", "rays", "rmse", "rel_mse", "flip"
    );
    for (i, r) in rows.iter().enumerate() {
        println!(
            "{:<17} {:>10} {:>10.3} {:>12} {:>12.4e} {:>12.4e} {:>9.5}{}",
            r.planned.knob,
            r.planned.value,
            r.seconds,
            r.rays,
            r.metrics.rmse,
            r.metrics.rel_mse,
            r.metrics.flip,
            if front.contains(&i) { "  pareto" } else { "" }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_varies_one_knob_at_a_time() {
        let base = Config {
            settings: RenderSettings {
                spp: 16,
                max_depth: 8,
                transport: Transport::Path,
                rr_start_depth: Some(prism::core::settings::DEFAULT_RR_START_DEPTH),
                ..Default::default()
            },
            bvh: BuildQuality::Medium,
            accel: Accel::Bvh,
        };
        let p = plan(&base, &Knob::ALL);
        assert_eq!(p[0].knob, "base");
        // Every value but the base's, for each knob.
        let count = |k: &str| p.iter().filter(|x| x.knob == k).count();
        assert_eq!(count("spp"), SPP_VALUES.len() - 1);
        assert_eq!(count("max-depth"), DEPTH_VALUES.len() - 1);
        assert_eq!(count("min-contribution"), MIN_CONTRIBUTION_VALUES.len() - 1);
        assert_eq!(count("light-samples"), LIGHT_SAMPLE_VALUES.len() - 1);
        assert_eq!(count("russian-roulette"), RR_VALUES.len() - 1);
        assert_eq!(count("rr-weight"), RR_WEIGHT_VALUES.len() - 1);
        assert_eq!(count("bvh"), BVH_VALUES.len() - 1);
        assert_eq!(count("accel"), ACCEL_VALUES.len() - 1);
        assert_eq!(count("transport"), TRANSPORT_VALUES.len() - 1);
        assert_eq!(count("photon-iterations"), PHOTON_ITERATION_VALUES.len());
        assert_eq!(count("sampler"), 1);
        assert_eq!(count("split"), SPLIT_VALUES.len() - 1);
        for x in &p[1..] {
            let mut c = x.config.clone();
            // Undo the one knob: the rest must be the base.
            match x.knob {
                "spp" => c.settings.spp = base.settings.spp,
                "max-depth" => c.settings.max_depth = base.settings.max_depth,
                "min-contribution" => c.settings.min_contribution = base.settings.min_contribution,
                "light-samples" => c.settings.light_samples = base.settings.light_samples,
                "russian-roulette" => c.settings.rr_start_depth = base.settings.rr_start_depth,
                "rr-weight" => c.settings.rr_weight = base.settings.rr_weight,
                "bvh" => c.bvh = base.bvh,
                "accel" => c.accel = base.accel,
                "transport" => c.settings.transport = base.settings.transport,
                "sampler" => c.settings.sampler = base.settings.sampler,
                "split" => c.settings.split = base.settings.split,
                "photon-iterations" => {
                    c.settings.transport = base.settings.transport;
                    c.settings.photon.iterations = base.settings.photon.iterations;
                }
                k => panic!("unexpected knob {k}"),
            }
            assert_eq!(c, base, "{} {}", x.knob, x.value);
            assert_ne!(x.config, base);
        }
    }
}
