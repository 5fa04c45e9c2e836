//! `prism bench`: the recursive and the wavefront integrator on the same
//! scenes, alternately, and the closest-hit throughput of single-ray and
//! packet traversal.

use std::path::PathBuf;
use std::time::Instant;

use clap::ValueEnum;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use glam::{Vec2, Vec3A};
use rayon::prelude::*;
use serde::Serialize;

use prism::accel::packet::LANES;
use prism::core::error::{Error, Result};
use prism::core::math::{Ray, orthonormal_basis};
use prism::core::rng::Sampler;
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::BuildQuality;
use prism::integrators::IntegratorKind;
use prism::integrators::wavefront::StageSeconds;
use prism::io::desc::SettingsDesc;
use prism::scene::camera::{Camera, CameraRays};
use prism::scene::{RenderScene, StreamScratch};
use prism::systems::wavefront::BatchSize;
use prism::systems::{Frame, RenderConfig, Renderer};

use crate::args::{BatchPathsFlag, FrameFlags, ThreadsFlag, TransportArg, TransportFlag};
use crate::stats::RayCountsJson;

/// Options of `prism bench`.
///
/// The shared flags keep bench's own, shorter help texts (see
/// [`crate::args`]); `--transport` also keeps its two-word value
/// descriptions.
#[derive(clap::Args, Debug)]
#[command(
    mut_arg("threads", |a| a.help("Worker threads [default: one per core]")),
    mut_arg("width", |a| a.help("Image width [default: the scene's, else 640]")),
    mut_arg("height", |a| a.help("Image height [default: the scene's, else 480]")),
    mut_arg("spp", |a| a.help("Samples per pixel [default: the scene's, else 1]")),
    mut_arg("max_depth", |a| a.help("Maximum depth [default: the scene's, else 8]")),
    mut_arg("transport", |a| a.value_parser(
        PossibleValuesParser::new([
            PossibleValue::new("whitted").help("Whitted transport"),
            PossibleValue::new("path").help("Path tracing"),
        ])
        .map(|v| TransportArg::from_str(&v, false).expect("one of the values listed")),
    )),
    mut_arg("batch_paths", |a| a.help("Paths per wavefront batch")),
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
)]
pub struct BenchArgs {
    /// `prism bench rays DIR`: traversal throughput on a ray file workload.
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Scene files to measure.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Renders per integrator and scene (alternating); the median and the fastest are reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// `--threads`.
    #[command(flatten)]
    pub threads: ThreadsFlag,
    /// `--width`, `--height`, `--spp`, `--max-depth`.
    #[command(flatten)]
    pub frame: FrameFlags,
    /// `--transport`.
    #[command(flatten)]
    pub transport: TransportFlag,
    /// `--batch-paths`.
    #[command(flatten)]
    pub batch_paths: BatchPathsFlag,
    /// `--merge-meshes`.
    #[command(flatten)]
    pub merge: crate::args::MergeFlag,
    /// Structures over mesh triangles to measure, each scene loaded once
    /// per structure (comma-separated: bvh, kdtree, grid, brute).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [crate::args::AccelArg::Bvh])]
    pub accel: Vec<crate::args::AccelArg>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Subcommands of `prism bench`.
#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Closest-hit throughput of every traversal mode (single rays,
    /// packets of 8, streams) and BVH build time on a ray-tracing anchors
    /// workload (mesh.bin, primary.rays, incoherent.rays and their .ref
    /// files, see shared/traversal-anchors), with the fraction of hits
    /// that agree with the reference.
    Rays(crate::rays::RaysArgs),
}

/// One integrator on one scene.
#[derive(Serialize, Debug, Clone)]
pub struct IntegratorResult {
    /// Integrator name.
    pub integrator: &'static str,
    /// Median render seconds.
    pub median_seconds: f64,
    /// Fastest run's render seconds: on a shared machine interference only
    /// slows runs down, so this is the steadier figure.
    pub fastest_seconds: f64,
    /// Every run's render seconds, in order.
    pub runs_seconds: Vec<f64>,
    /// Rays by kind (identical in every run).
    pub rays: RayCountsJson,
    /// All rays over the median time.
    pub mrays_per_second: f64,
    /// Wavefront only: largest queue memory.
    pub peak_queue_bytes: Option<usize>,
    /// Wavefront only: stage seconds of the median run.
    pub stage_seconds: Option<StageSeconds>,
}

/// Closest-hit traversal throughput, Mrays/s.
#[derive(Serialize, Debug, Clone, Copy)]
pub struct Throughput {
    /// Camera rays, one at a time.
    pub camera_single: f64,
    /// Camera rays through pixel centres, packets of eight neighbouring
    /// pixels of a row. (The integrators trace camera rays sixteen at a
    /// time on the AVX-512 path, `RenderScene::intersect_coherent`, and
    /// the wavefront takes them in path order: at 16 spp and above a
    /// packet is one pixel's samples.)
    pub camera_packets: f64,
    /// Camera rays through the top level in packets and every mesh as
    /// streams of 1024 rays (a mode of the kernel no integrator uses since
    /// meshes have their own packet traversal).
    pub camera_streams: f64,
    /// Incoherent secondary rays (cosine-distributed from the camera hits), one at a time.
    pub secondary_single: f64,
    /// The same secondary rays in packets of eight consecutive rays,
    /// meshes traversed as packets too (what the wavefront does with
    /// eight bounce rays that share an octant).
    pub secondary_packets: f64,
    /// The same packets through the top level, meshes one lane at a time.
    pub secondary_top_level_packets: f64,
    /// The same secondary rays through the top level in packets and every
    /// mesh as streams of 1024 rays split by direction octant (a mode no
    /// integrator uses any more).
    pub secondary_streams: f64,
    /// Number of secondary rays.
    pub secondary_rays: usize,
}

/// Everything measured on one scene.
#[derive(Serialize, Debug, Clone)]
pub struct SceneResult {
    /// Scene file.
    pub scene: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Maximum depth.
    pub max_depth: u32,
    /// Threads.
    pub threads: usize,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Structure over mesh triangles.
    pub accel: &'static str,
    /// Seconds building the mesh structures.
    pub accel_build_seconds: f64,
    /// Bytes of the mesh structures.
    pub accel_bytes: usize,
    /// Recursive, then wavefront.
    pub integrators: Vec<IntegratorResult>,
    /// Recursive median over wavefront median.
    pub speedup_wavefront: f64,
    /// Recursive fastest run over wavefront fastest run.
    pub speedup_wavefront_fastest: f64,
    /// Traversal throughput.
    pub closest_hit_mrays: Throughput,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Runs the benchmark and prints the report.
pub fn run(args: BenchArgs) -> Result<()> {
    if let Some(BenchCommand::Rays(rays)) = args.command {
        return crate::rays::run(rays);
    }
    if args.runs == 0 {
        return Err(Error::Invalid("--runs must be at least 1".into()));
    }
    let batch_paths = args.batch_paths.get()?;
    let (pool, threads) = args.threads.pool()?;
    // A scene that cannot be measured (unreadable, or refusing the
    // transport asked for) is reported and skipped; the others are still
    // measured, and the command fails at the end.
    let mut results = Vec::new();
    let mut failed = 0;
    for scene in &args.scenes {
        for &accel in &args.accel {
            match pool.install(|| bench_scene(scene, &args, accel.into(), batch_paths, threads)) {
                Ok(r) => {
                    if !args.json {
                        print_table(&r);
                    }
                    results.push(r);
                }
                Err(e) => {
                    eprintln!("error: {e} (skipped)");
                    failed += 1;
                }
            }
        }
    }
    if args.json {
        let text = serde_json::to_string_pretty(&results)
            .map_err(|e| Error::Invalid(format!("cannot write JSON: {e}")))?;
        println!("{text}");
    }
    if failed > 0 {
        return Err(Error::Invalid(format!(
            "{failed} of {} measurements failed (see above)",
            failed + results.len()
        )));
    }
    Ok(())
}

fn bench_scene(
    path: &PathBuf,
    args: &BenchArgs,
    accel: prism::core::settings::Accel,
    batch_paths: usize,
    threads: usize,
) -> Result<SceneResult> {
    let desc = prism::io::load(
        path,
        prism::geometry::mesh::BuildOptions {
            quality: BuildQuality::Medium,
            accel: Some(accel),
        },
    )?;
    let (mut accel_build_seconds, mut accel_bytes) = (0.0, 0);
    let mut seen = std::collections::HashSet::new();
    for o in &desc.objects {
        if let prism::io::desc::Geometry::Mesh(m) = &o.geometry
            && seen.insert(std::sync::Arc::as_ptr(m))
        {
            accel_build_seconds += m.build_seconds;
            accel_bytes += m.accel_bytes();
        }
    }
    let settings = SettingsDesc {
        transport: args.transport.get(),
        ..args.frame.desc()
    }
    .resolve(&desc.settings);
    settings
        .validate()
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    if desc.cameras.is_empty() {
        return Err(Error::load(path, "the scene has no camera"));
    }
    let mut renderer = Renderer::with_scene(
        desc,
        RenderConfig {
            settings: settings.clone(),
            merge_meshes: args.merge.on(),
            ..Default::default()
        },
        0,
    )?;
    renderer.insert_resource(BatchSize(batch_paths));

    let mut times = [Vec::new(), Vec::new()];
    let mut frames: [Vec<Frame>; 2] = [Vec::new(), Vec::new()];
    for _ in 0..args.runs {
        for (k, kind) in IntegratorKind::ALL.into_iter().enumerate() {
            renderer.config_mut().integrator = kind;
            let frame = renderer
                .render()
                .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
            times[k].push(frame.render_seconds);
            frames[k].push(frame);
        }
    }
    let scene = renderer
        .scene()
        .ok_or_else(|| Error::Invalid("no scene was built".into()))?;
    let camera = renderer
        .world()
        .get::<Camera>(renderer.cameras()[0])
        .cloned()
        .ok_or_else(|| Error::Invalid("camera entity vanished".into()))?;

    let mut integrators = Vec::new();
    for (k, kind) in IntegratorKind::ALL.into_iter().enumerate() {
        let med = median(&times[k]);
        let idx = times[k].iter().position(|&t| t == med).unwrap_or(0);
        let f = &frames[k][idx];
        integrators.push(IntegratorResult {
            integrator: kind.name(),
            median_seconds: med,
            fastest_seconds: times[k].iter().copied().fold(f64::INFINITY, f64::min),
            runs_seconds: times[k].clone(),
            rays: f.counters.rays.into(),
            mrays_per_second: f.counters.rays.total() as f64 / med.max(1e-9) / 1e6,
            peak_queue_bytes: f.wavefront.map(|w| w.peak_queue_bytes),
            stage_seconds: f.wavefront.map(|w| w.stages),
        });
    }
    let speedup = integrators[0].median_seconds / integrators[1].median_seconds.max(1e-12);
    let speedup_fastest =
        integrators[0].fastest_seconds / integrators[1].fastest_seconds.max(1e-12);
    Ok(SceneResult {
        scene: path.display().to_string(),
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        max_depth: settings.max_depth,
        threads,
        triangles: scene.triangle_count(),
        accel: accel.name(),
        accel_build_seconds,
        accel_bytes,
        integrators,
        speedup_wavefront: speedup,
        speedup_wavefront_fastest: speedup_fastest,
        closest_hit_mrays: throughput(&scene, &camera, &settings, args.runs),
    })
}

/// Times `f` `runs` times over `n` rays and returns the best Mrays/s.
fn best_rate(n: usize, runs: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    n as f64 / best.max(1e-12) / 1e6
}

fn trace_single(scene: &RenderScene, rays: &[Ray]) -> usize {
    rays.par_chunks(1024)
        .map(|c| {
            c.iter()
                .filter(|r| scene.intersect(r, 0.0, f32::INFINITY).is_some())
                .count()
        })
        .sum()
}

fn trace_packets(scene: &RenderScene, rays: &[Ray], mesh_packets: bool) -> usize {
    rays.par_chunks(1024)
        .map(|c| {
            let mut out = [None; LANES];
            c.chunks(LANES)
                .map(|p| {
                    scene.intersect_packet_with(p, &mut out, mesh_packets);
                    out[..p.len()].iter().filter(|h| h.is_some()).count()
                })
                .sum::<usize>()
        })
        .sum()
}

fn trace_streams(scene: &RenderScene, rays: &[Ray]) -> usize {
    rays.par_chunks(1024)
        .map_init(
            || (StreamScratch::default(), Vec::new()),
            |(scratch, out), c| {
                out.clear();
                out.resize(c.len(), None);
                scene.intersect_stream(c, out, scratch);
                out.iter().filter(|h| h.is_some()).count()
            },
        )
        .sum()
}

/// Closest-hit throughput of camera rays and of incoherent secondary rays
/// leaving the camera rays' hits in cosine-distributed directions.
fn throughput(scene: &RenderScene, camera: &Camera, s: &RenderSettings, runs: usize) -> Throughput {
    let cam = CameraRays::relative_to(camera, scene.origin(), s.width, s.height);
    let camera_rays: Vec<Ray> = (0..s.height)
        .flat_map(|y| (0..s.width).map(move |x| (x, y)))
        .map(|(x, y)| cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5)))
        .collect();
    let secondary: Vec<Ray> = camera_rays
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let h = scene.intersect(r, 0.0, f32::INFINITY)?;
            let n = if h.geometric_normal.dot(r.direction) < 0.0 {
                h.geometric_normal
            } else {
                -h.geometric_normal
            };
            let mut rng = Sampler::new(1, i as u32, 0);
            let (u1, u2) = (rng.next_f32(), rng.next_f32());
            let (r2, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
            let (t, b) = orthonormal_basis(n);
            let d: Vec3A = t * (r2 * phi.cos()) + b * (r2 * phi.sin()) + n * (1.0 - u1).sqrt();
            Some(Ray::new(
                prism::core::optics::offset_origin(h.point, n),
                d.normalize(),
            ))
        })
        .collect();
    Throughput {
        camera_single: best_rate(camera_rays.len(), runs, || {
            std::hint::black_box(trace_single(scene, &camera_rays));
        }),
        camera_packets: best_rate(camera_rays.len(), runs, || {
            std::hint::black_box(trace_packets(scene, &camera_rays, true));
        }),
        camera_streams: best_rate(camera_rays.len(), runs, || {
            std::hint::black_box(trace_streams(scene, &camera_rays));
        }),
        secondary_single: best_rate(secondary.len(), runs, || {
            std::hint::black_box(trace_single(scene, &secondary));
        }),
        secondary_packets: best_rate(secondary.len(), runs, || {
            std::hint::black_box(trace_packets(scene, &secondary, true));
        }),
        secondary_top_level_packets: best_rate(secondary.len(), runs, || {
            std::hint::black_box(trace_packets(scene, &secondary, false));
        }),
        secondary_streams: best_rate(secondary.len(), runs, || {
            std::hint::black_box(trace_streams(scene, &secondary));
        }),
        secondary_rays: secondary.len(),
    }
}

fn print_table(r: &SceneResult) {
    println!(
        "{}: {}x{}, {} spp, depth {}, {} triangles, {} threads",
        r.scene, r.width, r.height, r.spp, r.max_depth, r.triangles, r.threads
    );
    println!(
        "  structure {}: built in {:.3} s, {:.2} MB",
        r.accel,
        r.accel_build_seconds,
        r.accel_bytes as f64 / 1e6
    );
    println!(
        "  {:<10} {:>9} {:>9} {:>8} {:>9} {:>9} {:>10} {:>10} {:>11}",
        "integrator",
        "median s",
        "fastest s",
        "Mrays/s",
        "camera",
        "shadow",
        "reflection",
        "refraction",
        "queue MB"
    );
    for i in &r.integrators {
        println!(
            "  {:<10} {:>9.4} {:>9.4} {:>8.2} {:>9} {:>9} {:>10} {:>10} {:>11}",
            i.integrator,
            i.median_seconds,
            i.fastest_seconds,
            i.mrays_per_second,
            i.rays.camera,
            i.rays.shadow,
            i.rays.reflection,
            i.rays.refraction,
            i.peak_queue_bytes
                .map_or("-".to_string(), |b| format!("{:.1}", b as f64 / 1e6)),
        );
    }
    if let Some(st) = r.integrators.iter().find_map(|i| i.stage_seconds) {
        let stages: Vec<String> = st
            .by_key()
            .into_iter()
            .map(|(key, seconds)| format!("{key} {seconds:.4}"))
            .collect();
        println!(
            "  wavefront stages (thread-seconds, summed over lanes): {}",
            stages.join(", ")
        );
    }
    println!(
        "  speedup of the wavefront over recursive: {:.2}x (medians), {:.2}x (fastest runs)",
        r.speedup_wavefront, r.speedup_wavefront_fastest
    );
    let t = r.closest_hit_mrays;
    println!(
        "  closest-hit Mrays/s: camera rays {:.2} single, {:.2} packets, {:.2} streams; secondary rays ({}) {:.2} single, {:.2} packets, {:.2} top-level packets, {:.2} streams",
        t.camera_single,
        t.camera_packets,
        t.camera_streams,
        t.secondary_rays,
        t.secondary_single,
        t.secondary_packets,
        t.secondary_top_level_packets,
        t.secondary_streams
    );
    println!();
}
