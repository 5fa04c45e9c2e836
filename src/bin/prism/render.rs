//! `prism render`: one scene file to one image, with optional statistics.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use prism::core::error::{Error, Result};
use prism::geometry::mesh::BuildQuality;
use prism::image::output::{OutputFormat, PngOptions, ToneMap};
use prism::integrators::IntegratorKind;
use prism::io::desc::{Geometry, SettingsDesc};
use prism::systems::{self, Frame, RenderConfig};

use crate::args::{IntegratorArg, QualityArg, ToneMapArg, TransportArg, thread_pool};
use crate::stats::{RenderStats, WavefrontStatsJson};

/// Options of `prism render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file: the project's TOML format, or glTF 2.0 (.gltf/.glb).
    scene: PathBuf,
    /// Output image. `.png` is 8-bit sRGB after exposure and tone map;
    /// `.exr` is linear float radiance exactly as computed.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Image width in pixels [default: the scene's, else 640].
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels [default: the scene's, else 480].
    #[arg(long)]
    height: Option<u32>,
    /// Samples per pixel; 1 traces the pixel centre, more are jittered
    /// over the pixel [default: the scene's, else 1].
    #[arg(long)]
    spp: Option<u32>,
    /// Maximum number of reflection/refraction bounces after the camera
    /// ray [default: the scene's, else 8].
    #[arg(long)]
    max_depth: Option<u32>,
    /// Do not trace secondary rays whose contribution to the pixel (largest
    /// channel of the path weight) is below this [default: the scene's, else 0.001].
    #[arg(long)]
    min_contribution: Option<f32>,
    /// Worker threads [default: one per core]. The image does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Seed for pixel jitter [default: the scene's, else 0].
    #[arg(long)]
    seed: Option<u64>,
    /// Which camera to render from, counting from 0 in file order (the
    /// scene file's own camera first, then those of included glTF files).
    #[arg(long, default_value_t = 0)]
    camera: usize,
    /// Exposure in stops for PNG output: radiance is scaled by 2^EV
    /// [default: the scene's, else 0].
    #[arg(long, value_name = "EV", allow_hyphen_values = true)]
    exposure: Option<f32>,
    /// Tone map for PNG output.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    tonemap: ToneMapArg,
    /// Integrator.
    #[arg(long, value_enum, default_value_t = IntegratorArg::Recursive)]
    integrator: IntegratorArg,
    /// Light transport [default: the scene's, else whitted].
    #[arg(long, value_enum)]
    transport: Option<TransportArg>,
    /// Path tracing: shadow rays per area light at each hit
    /// [default: the scene's, else 1].
    #[arg(long)]
    light_samples: Option<u32>,
    /// Path tracing: bounce from which Russian roulette may end paths
    /// [default: the scene's, else 3].
    #[arg(long, value_name = "DEPTH", conflicts_with = "no_russian_roulette")]
    rr_depth: Option<u32>,
    /// Path tracing: never end paths by Russian roulette (unbiased either
    /// way; roulette trades variance for speed).
    #[arg(long)]
    no_russian_roulette: bool,
    /// BVH build preset, from fastest build to best traversal.
    #[arg(long, value_enum, default_value_t = QualityArg::Medium)]
    bvh_quality: QualityArg,
    /// Paths (pixel samples) per wavefront batch: bounds queue memory.
    #[arg(long, default_value_t = prism::integrators::wavefront::DEFAULT_BATCH_PATHS)]
    batch_paths: usize,
    /// Write timings, ray counts and scene sizes as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// No progress bar or summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// Renders the scene and writes the image (and the statistics).
pub fn run(args: RenderArgs) -> Result<()> {
    let wall = Instant::now();
    // Fail on a bad output name before spending time on the render.
    OutputFormat::from_path(&args.output)?;
    if let Some(s) = &args.stats
        && s.extension().and_then(|e| e.to_str()) != Some("json")
    {
        return Err(Error::Invalid(format!(
            "--stats {}: the statistics file must end in .json",
            s.display()
        )));
    }
    let (pool, threads) = thread_pool(args.threads)?;
    pool.install(|| render_with_pool(&args, threads, wall))
}

fn render_with_pool(args: &RenderArgs, threads: usize, wall: Instant) -> Result<()> {
    let quality: BuildQuality = args.bvh_quality.into();
    let load_start = Instant::now();
    let desc = prism::io::load(&args.scene, quality)?;
    let load_seconds = load_start.elapsed().as_secs_f64();
    let mut mesh_build_seconds = 0.0;
    let mut seen = std::collections::HashSet::new();
    for o in &desc.objects {
        if let Geometry::Mesh(m) = &o.geometry
            && seen.insert(Arc::as_ptr(m))
        {
            mesh_build_seconds += m.build_seconds;
        }
    }

    let s = &desc.settings;
    let settings = SettingsDesc {
        width: args.width,
        height: args.height,
        spp: args.spp,
        max_depth: args.max_depth,
        min_contribution: args.min_contribution,
        seed: args.seed,
        exposure: None,
        transport: args.transport.map(Into::into),
        light_samples: args.light_samples,
        rr_start_depth: if args.no_russian_roulette {
            Some(None)
        } else {
            args.rr_depth.map(Some)
        },
    }
    .resolve(s);
    settings.validate().map_err(|e| {
        Error::Invalid(format!(
            "{}: invalid render settings (from the command line or the scene's [settings]): {e}",
            args.scene.display()
        ))
    })?;
    let png = PngOptions {
        exposure: args.exposure.or(s.exposure).unwrap_or(0.0),
        tone_map: match args.tonemap {
            ToneMapArg::Clamp => ToneMap::Clamp,
            ToneMapArg::Reinhard => ToneMap::Reinhard,
        },
    };
    if !png.exposure.is_finite() {
        return Err(Error::Invalid("--exposure must be finite".into()));
    }
    let camera_count = desc.cameras.len();
    if camera_count == 0 {
        return Err(Error::load(
            &args.scene,
            "the scene has no camera (add a [camera] table or a glTF camera)",
        ));
    }
    if args.camera >= camera_count {
        return Err(Error::Invalid(format!(
            "--camera {}: the scene has {camera_count} camera(s), numbered from 0",
            args.camera
        )));
    }
    let background = desc.background;
    let light_count = desc.lights.len();

    let mut world = bevy_ecs::world::World::new();
    let mut schedule = systems::setup(&mut world);
    let cameras = systems::spawn_scene(&mut world, desc);
    let bar = progress_bar(
        settings.height as u64,
        args.quiet,
        "{spinner} rendering [{bar:40}] {pos}/{len} rows {elapsed_precise} (eta {eta})",
    );
    let progress: Option<systems::ProgressFn> = bar.clone().map(|b| {
        let f: systems::ProgressFn = Arc::new(move |n| b.inc(n));
        f
    });
    if args.batch_paths == 0 {
        return Err(Error::Invalid("--batch-paths must be at least 1".into()));
    }
    world.insert_resource(systems::wavefront::BatchSize(args.batch_paths));
    world.insert_resource(RenderConfig {
        settings: settings.clone(),
        integrator: args.integrator.into(),
        camera: Some(cameras[args.camera]),
        bvh_quality: quality,
        background,
        progress,
    });
    schedule.run(&mut world);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }

    let accel = world.resource::<systems::SceneAccel>();
    let tlas_seconds = accel.build_seconds;
    let (triangles, primitives) = accel
        .scene
        .as_ref()
        .map_or((0, 0), |s| (s.triangle_count(), s.instances.len()));
    let features = accel
        .scene
        .as_ref()
        .map(|s| prism::scene::features::SceneFeatures::of(s))
        .unwrap_or_default();
    let frame = world.resource::<Frame>();
    if let Some(e) = &frame.error {
        return Err(Error::Invalid(format!("{}: {e}", args.scene.display())));
    }
    let Some(film) = &frame.film else {
        return Err(Error::Invalid("the renderer produced no image".into()));
    };
    prism::image::output::write_image(&args.output, film, &png)?;

    let rays = frame.counters.rays;
    let render_seconds = frame.render_seconds;
    let stats = RenderStats {
        scene: args.scene.display().to_string(),
        integrator: IntegratorKind::from(args.integrator).name().into(),
        transport: settings.transport.name().into(),
        features,
        wall_seconds: wall.elapsed().as_secs_f64(),
        load_seconds,
        bvh_build_seconds: mesh_build_seconds + tlas_seconds,
        render_seconds,
        rays: rays.into(),
        mrays_per_second: rays.total() as f64 / render_seconds.max(1e-9) / 1e6,
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        max_depth: settings.max_depth,
        threads,
        triangles,
        primitives,
        lights: light_count,
        nonfinite_samples: frame.counters.nonfinite_samples,
        wavefront: frame.wavefront.map(|w| WavefrontStatsJson {
            stage_seconds: w.stages,
            peak_queue_bytes: w.peak_queue_bytes,
            batches: w.batches,
            batch_paths: world.resource::<systems::wavefront::BatchSize>().0,
            stages_run: w.runs.names_run(),
            stage_runs: w.runs,
        }),
    };
    if let Some(path) = &args.stats {
        write_stats(path, &stats)?;
    }
    if !args.quiet {
        eprintln!(
            "{}: {}x{} at {} spp in {:.3} s ({} rays, {:.2} Mrays/s, {} threads){}",
            args.output.display(),
            stats.width,
            stats.height,
            stats.spp,
            stats.render_seconds,
            rays.total(),
            stats.mrays_per_second,
            threads,
            if stats.nonfinite_samples > 0 {
                format!(", {} non-finite samples dropped", stats.nonfinite_samples)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// A progress bar on stderr of `total` steps drawn with the indicatif
/// `template`, or `None` when `quiet`. It is hidden automatically when
/// stderr is not a terminal.
pub(crate) fn progress_bar(total: u64, quiet: bool, template: &str) -> Option<ProgressBar> {
    if quiet {
        return None;
    }
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(template)
            .map(|s| s.progress_chars("=> "))
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    Some(bar)
}

fn write_stats(path: &Path, stats: &RenderStats) -> Result<()> {
    let json = serde_json::to_string_pretty(stats).map_err(|e| Error::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    prism::image::output::write_atomic(path, json.as_bytes())
}
