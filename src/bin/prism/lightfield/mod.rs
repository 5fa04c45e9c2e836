//! `prism lightfield`: capture a two-plane light field of a scene, make
//! new views from it without the scene, compare them with direct renders,
//! and sweep the grid density.

mod plot;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec3};
use serde::Serialize;

use prism::core::error::{Error, Result};
use prism::core::settings::{LightFieldSettings, RenderSettings};
use prism::geometry::mesh::BuildOptions;
use prism::image::film::Film;
use prism::image::metrics::{self, Metrics};
use prism::io::desc::{Geometry, SceneDesc, SettingsDesc};
use prism::lightfield::synth::{self, Outside, SynthOptions};
use prism::lightfield::{CaptureInfo, LightField, MANIFEST, Manifest, Rig};
use prism::scene::camera::Camera;
use prism::systems::{self, RenderConfig, RenderOrigin, Renderer};

use crate::args::{ThreadsFlag, ToneMapArg, TransportFlag, png_options};
use crate::render::progress_bar;

/// Options of `prism lightfield`.
#[derive(clap::Args, Debug)]
pub struct LightFieldArgs {
    #[command(subcommand)]
    command: LightFieldCommand,
}

#[derive(clap::Subcommand, Debug)]
enum LightFieldCommand {
    /// Render a two-plane light field of a scene: a grid of cameras on the
    /// plane through the scene camera's eye (its right and up), all
    /// looking along its view direction through one window of the focal
    /// plane; writes one .exr per camera and lightfield.json.
    Capture(CaptureArgs),
    /// Make a new view from a captured light field alone (quadrilinear
    /// interpolation in u, v, s, t; optionally depth-corrected by a proxy
    /// plane).
    Render(ViewRenderArgs),
    /// Make a new view from the light field and render the same view
    /// directly with the scene, and report the error metrics of `prism
    /// compare` (RMSE, relMSE, FLIP) and both times.
    Compare(ViewCompareArgs),
    /// Capture the scene at several grid densities over one camera-plane
    /// aperture, synthesise views between the grid cameras and write
    /// lightfield_sweep.csv and a plot of error against grid density and
    /// capture time.
    Sweep(SweepArgs),
}

/// Runs the subcommand.
pub fn run(args: LightFieldArgs) -> Result<()> {
    match args.command {
        LightFieldCommand::Capture(a) => {
            let (pool, _) = a.render.threads.pool()?;
            pool.install(|| capture(&a))
        }
        LightFieldCommand::Render(a) => {
            let (pool, _) = a.threads.pool()?;
            pool.install(|| view_render(&a))
        }
        LightFieldCommand::Compare(a) => {
            let (pool, _) = a.threads.pool()?;
            pool.install(|| view_compare(&a))
        }
        LightFieldCommand::Sweep(a) => {
            let (pool, _) = a.render.threads.pool()?;
            pool.install(|| sweep(&a))
        }
    }
}

/// `--grid`, `--spacing`, `--resolution`, `--focal-distance`.
#[derive(clap::Args, Debug, Clone, Copy)]
struct RigFlags {
    /// Cameras across and up, as CxR [default: the scene's [lightfield]
    /// grid, else 8x8].
    #[arg(long, value_name = "CxR", value_parser = parse_pair)]
    grid: Option<[u32; 2]>,
    /// Distance between neighbouring cameras, world units [default: the
    /// scene's, else a sixteenth of the focal distance].
    #[arg(long, value_name = "S")]
    spacing: Option<f64>,
    /// Width and height of every image, as WxH [default: the scene's, else
    /// 128x128].
    #[arg(long, value_name = "WxH", value_parser = parse_pair)]
    resolution: Option<[u32; 2]>,
    /// Distance from the camera plane to the focal plane [default: the
    /// scene's, else the scene camera's distance to its look_at point].
    #[arg(long, value_name = "D")]
    focal_distance: Option<f64>,
}

impl RigFlags {
    fn settings(&self) -> LightFieldSettings {
        LightFieldSettings {
            grid: self.grid,
            spacing: self.spacing,
            resolution: self.resolution,
            focal_distance: self.focal_distance,
        }
    }
}

/// How the views are rendered (capture, sweep).
#[derive(clap::Args, Debug, Clone, Copy)]
struct CaptureRenderFlags {
    /// Which scene camera defines the rig, counting from 0 in file order.
    #[arg(long, default_value_t = 0)]
    camera: usize,
    /// Samples per pixel [default: the scene's, else 1].
    #[arg(long)]
    spp: Option<u32>,
    /// Maximum bounces [default: the scene's, else 8].
    #[arg(long)]
    max_depth: Option<u32>,
    /// Seed for pixel jitter [default: the scene's, else 0].
    #[arg(long)]
    seed: Option<u64>,
    /// `--transport`.
    #[command(flatten)]
    transport: TransportFlag,
    /// `--threads`.
    #[command(flatten)]
    threads: ThreadsFlag,
}

/// Options of `prism lightfield capture`.
#[derive(clap::Args, Debug)]
struct CaptureArgs {
    /// Scene file (.toml, .gltf or .glb).
    scene: PathBuf,
    /// Folder for the images and lightfield.json (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// `--grid`, `--spacing`, `--resolution`, `--focal-distance`.
    #[command(flatten)]
    rig: RigFlags,
    /// `--camera`, `--spp`, ...
    #[command(flatten)]
    render: CaptureRenderFlags,
    /// No progress bar or summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// `WxH`-style pair of positive integers.
fn parse_pair(s: &str) -> std::result::Result<[u32; 2], String> {
    let (a, b) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected two numbers as AxB, got {s:?}"))?;
    let n = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|e| format!("{t:?} in {s:?}: {e}"))
    };
    Ok([n(a)?, n(b)?])
}

/// A loaded scene, its render settings and the rig of its camera.
struct Prepared {
    desc: SceneDesc,
    settings: RenderSettings,
    rig: Rig,
    /// Seconds spent building mesh BVHs at load.
    mesh_bvh_seconds: f64,
}

fn prepare(
    scene: &Path,
    rig_flags: &LightFieldSettings,
    flags: &CaptureRenderFlags,
) -> Result<Prepared> {
    rig_flags.validate().map_err(Error::Invalid)?;
    let desc = prism::io::load(scene, BuildOptions::default())?;
    let mut settings = SettingsDesc {
        spp: flags.spp,
        max_depth: flags.max_depth,
        seed: flags.seed,
        transport: flags.transport.get(),
        ..Default::default()
    }
    .resolve(&desc.settings);
    // Lines are drawn over one image; the projection is the rig's.
    settings.lines = None;
    settings.panorama = None;
    if desc.cameras.is_empty() {
        return Err(Error::load(
            scene,
            "the scene has no camera to place the light field's rig (add a [camera] table)",
        ));
    }
    let camera = desc.cameras.get(flags.camera).ok_or_else(|| {
        Error::Invalid(format!(
            "--camera {}: the scene has {} camera(s), numbered from 0",
            flags.camera,
            desc.cameras.len()
        ))
    })?;
    let rig = Rig::from_camera(
        camera,
        &rig_flags.or(desc.settings.lightfield.unwrap_or_default()),
    )
    .map_err(|e| Error::Invalid(format!("{}: {e}", scene.display())))?;
    settings.width = rig.resolution[0];
    settings.height = rig.resolution[1];
    settings.validate().map_err(|e| {
        Error::Invalid(format!("{}: invalid render settings: {e}", scene.display()))
    })?;
    let mut seen = std::collections::HashSet::new();
    let mut mesh_bvh_seconds = 0.0;
    for o in &desc.objects {
        if let Geometry::Mesh(m) = &o.geometry
            && seen.insert(Arc::as_ptr(m))
        {
            mesh_bvh_seconds += m.build_seconds;
        }
    }
    Ok(Prepared {
        desc,
        settings,
        rig,
        mesh_bvh_seconds,
    })
}

/// Renders every view of `p.rig` and hands each image to `each`; returns
/// the capture information (its `scene` left empty).
fn capture_views(
    p: Prepared,
    camera: usize,
    bar: Option<&indicatif::ProgressBar>,
    mut each: impl FnMut(u32, u32, Film) -> Result<()>,
) -> Result<(CaptureInfo, Rig)> {
    let Prepared {
        desc,
        settings,
        rig,
        mesh_bvh_seconds,
    } = p;
    let config = RenderConfig {
        settings: settings.clone(),
        ..Default::default()
    };
    let report =
        systems::lightfield::capture_light_field(desc, config, camera, &rig, |c, r, f| {
            if !f.is_finite() {
                return Err(Error::Invalid(format!(
                    "view column {c}, row {r} has non-finite pixels"
                )));
            }
            each(c, r, f)?;
            if let Some(b) = bar {
                b.inc(1);
            }
            Ok(())
        })?;
    let info = CaptureInfo {
        scene: String::new(),
        spp: settings.spp,
        max_depth: settings.max_depth,
        transport: settings.transport.name().into(),
        seed: settings.seed,
        render_seconds: report.render_seconds,
        bvh_seconds: mesh_bvh_seconds + report.tlas_seconds,
        bvh_rebuilds: report.rebuilds + report.mesh_bvh_builds as u32,
        prism_version: env!("CARGO_PKG_VERSION").into(),
    };
    Ok((info, rig))
}

fn capture(args: &CaptureArgs) -> Result<()> {
    let wall = Instant::now();
    let p = prepare(&args.scene, &args.rig.settings(), &args.render)?;
    std::fs::create_dir_all(&args.out).map_err(|e| Error::Output {
        path: args.out.clone(),
        message: format!("cannot create the folder: {e}"),
    })?;
    // A stale manifest must not describe a half-replaced capture.
    let manifest_path = args.out.join(MANIFEST);
    match std::fs::remove_file(&manifest_path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            return Err(Error::Output {
                path: manifest_path,
                message: format!("cannot replace the old manifest: {e}"),
            });
        }
    }
    let views = p.rig.camera_count() as u64;
    let [w, h] = p.rig.resolution;
    let bar = progress_bar(
        views,
        args.quiet,
        "{spinner} capturing [{bar:40}] {pos}/{len} views {elapsed_precise} (eta {eta})",
    );
    let png = png_options(0.0, ToneMapArg::Clamp)?;
    let out = args.out.clone();
    let (mut info, rig) = capture_views(p, args.render.camera, bar.as_ref(), |c, r, film| {
        prism::image::output::write_image(&out.join(Manifest::image_name(c, r)), &film, &png)
    })?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    info.scene = args.scene.display().to_string();
    let (render_seconds, bvh_seconds, rebuilds) =
        (info.render_seconds, info.bvh_seconds, info.bvh_rebuilds);
    let manifest = Manifest::new(rig, info);
    prism::image::output::write_atomic(&manifest_path, manifest.to_json().as_bytes())?;
    if !args.quiet {
        eprintln!(
            "{}: {views} views of {w}x{h} in {render_seconds:.3} s ({:.4} s a view, {:.3} s wall); \
             BVH built once in {bvh_seconds:.4} s, {} for the other {} views",
            args.out.display(),
            render_seconds / views as f64,
            wall.elapsed().as_secs_f64(),
            if rebuilds == 0 {
                "reused".to_string()
            } else {
                format!("rebuilt {rebuilds} times")
            },
            views - 1
        );
    }
    Ok(())
}

/// Which view to make (render, compare).
#[derive(clap::Args, Debug, Clone)]
struct ViewFlags {
    /// Eye of the new view, X,Y,Z (world coordinates).
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        allow_hyphen_values = true,
        num_args = 1,
        required_unless_present_any = ["grid_camera", "grid_position"]
    )]
    look_from: Option<Vec<f64>>,
    /// Point the view looks at, X,Y,Z [default: straight ahead along the
    /// rig's viewing direction, at the focal distance].
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        allow_hyphen_values = true,
        num_args = 1,
        requires = "look_from"
    )]
    look_at: Option<Vec<f64>>,
    /// Up direction, X,Y,Z [default: the rig's].
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        allow_hyphen_values = true,
        num_args = 1,
        requires = "look_from"
    )]
    up: Option<Vec<f32>>,
    /// Vertical field of view in degrees [default: the rig's].
    #[arg(long, value_name = "DEG", requires = "look_from")]
    vfov: Option<f32>,
    /// The view of grid camera C,R exactly (column, row from the top
    /// left): its image is reproduced bit for bit.
    #[arg(
        long,
        value_name = "C,R",
        value_delimiter = ',',
        num_args = 1,
        conflicts_with_all = ["look_from", "grid_position"]
    )]
    grid_camera: Option<Vec<u32>>,
    /// A camera like the grid's at continuous grid position U,V (column,
    /// row; 0..C-1 and 0..R-1 span the grid), framing the focal window:
    /// a view between grid cameras.
    #[arg(
        long,
        value_name = "U,V",
        value_delimiter = ',',
        num_args = 1,
        allow_hyphen_values = true,
        conflicts_with = "look_from"
    )]
    grid_position: Option<Vec<f64>>,
    /// Image width [default: the light field's].
    #[arg(long)]
    width: Option<u32>,
    /// Image height [default: the light field's].
    #[arg(long)]
    height: Option<u32>,
    /// Depth correction: distance of a proxy plane from the camera plane
    /// (along the viewing direction). Surfaces near it stay sharp between
    /// cameras [default: none, plain quadrilinear interpolation, which is
    /// the same as a proxy at the focal distance].
    #[arg(long, value_name = "Z")]
    proxy_depth: Option<f64>,
    /// Pixels whose ray misses the light field (crosses the camera plane
    /// outside the cameras' hull, the focal plane outside the window, or
    /// points away from it): black, the nearest sample (clamp), or an
    /// error. A view that sees nothing of the light field is an error
    /// unless clamped.
    #[arg(long, value_enum, default_value_t = OutsideArg::Black)]
    outside: OutsideArg,
}

/// `--outside`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum OutsideArg {
    Black,
    Clamp,
    Error,
}

fn three<T: Copy>(name: &str, v: &[T]) -> Result<[T; 3]> {
    <[T; 3]>::try_from(v)
        .map_err(|_| Error::Invalid(format!("--{name} takes three numbers, got {}", v.len())))
}

impl ViewFlags {
    /// The camera, width and height of the view, and the synthesis
    /// options.
    fn view(&self, rig: &Rig) -> Result<(Camera, u32, u32, SynthOptions)> {
        let camera = if let Some(g) = &self.grid_camera {
            let [c, r] = <[u32; 2]>::try_from(g.as_slice()).map_err(|_| {
                Error::Invalid(format!("--grid-camera takes C,R, got {} numbers", g.len()))
            })?;
            if c >= rig.grid[0] || r >= rig.grid[1] {
                return Err(Error::Invalid(format!(
                    "--grid-camera {c},{r}: the grid is {}x{} cameras, numbered from 0",
                    rig.grid[0], rig.grid[1]
                )));
            }
            rig.camera(c, r)
        } else if let Some(g) = &self.grid_position {
            let [u, v] = <[f64; 2]>::try_from(g.as_slice()).map_err(|_| {
                Error::Invalid(format!(
                    "--grid-position takes U,V, got {} numbers",
                    g.len()
                ))
            })?;
            if !(u.is_finite() && v.is_finite()) {
                return Err(Error::Invalid(format!(
                    "--grid-position must be finite, got {u},{v}"
                )));
            }
            let (cu, cv) = (
                (rig.grid[0] as f64 - 1.0) * 0.5,
                (rig.grid[1] as f64 - 1.0) * 0.5,
            );
            rig.camera_at((u - cu) * rig.spacing, (cv - v) * rig.spacing)
        } else {
            let from = DVec3::from(three(
                "look-from",
                self.look_from.as_deref().unwrap_or_default(),
            )?);
            let at = match &self.look_at {
                Some(v) => DVec3::from(three("look-at", v)?),
                None => from + rig.forward * rig.focal_distance,
            };
            let up = match &self.up {
                Some(v) => Vec3::from(three("up", v)?),
                None => rig.up.as_vec3(),
            };
            Camera {
                look_from: from,
                look_at: at,
                up,
                vfov_degrees: self.vfov.unwrap_or(rig.vfov_degrees as f32),
                ..Default::default()
            }
        };
        camera
            .validate()
            .map_err(|e| Error::Invalid(format!("the view: {e}")))?;
        let width = self.width.unwrap_or(rig.resolution[0]);
        let height = self.height.unwrap_or(rig.resolution[1]);
        RenderSettings {
            width,
            height,
            ..Default::default()
        }
        .validate()
        .map_err(|e| Error::Invalid(format!("the view: {e}")))?;
        let options = SynthOptions {
            proxy_depth: self.proxy_depth,
            outside: match self.outside {
                OutsideArg::Black => Outside::Black,
                OutsideArg::Clamp => Outside::Clamp,
                OutsideArg::Error => Outside::Error,
            },
        };
        Ok((camera, width, height, options))
    }
}

/// Options of `prism lightfield render`.
#[derive(clap::Args, Debug)]
struct ViewRenderArgs {
    /// Light-field folder written by `prism lightfield capture`.
    dir: PathBuf,
    /// The view.
    #[command(flatten)]
    view: ViewFlags,
    /// Output image: .exr (linear radiance) or .png (after exposure and
    /// tone map).
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Exposure in stops for PNG output.
    #[arg(
        long,
        value_name = "EV",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    exposure: f32,
    /// Tone map for PNG output.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    tonemap: ToneMapArg,
    /// `--threads`.
    #[command(flatten)]
    threads: ThreadsFlag,
    /// No summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// Loads, synthesises, and says how long each took.
fn synthesise_view(
    dir: &Path,
    view: &ViewFlags,
) -> Result<(LightField, synth::Synthesis, f64, f64)> {
    let t = Instant::now();
    let lf = LightField::load(dir)?;
    let load_seconds = t.elapsed().as_secs_f64();
    let (camera, width, height, options) = view.view(lf.rig())?;
    let t = Instant::now();
    let s = synth::synthesise(&lf, &camera, width, height, options)?;
    Ok((lf, s, load_seconds, t.elapsed().as_secs_f64()))
}

fn outside_note(s: &synth::Synthesis) -> String {
    let total = s.film.pixels.len();
    if s.outside == 0 {
        String::new()
    } else {
        format!(
            "; {} of {total} pixels ({:.1}%) outside the light field (see --outside)",
            s.outside,
            100.0 * s.outside as f64 / total as f64
        )
    }
}

fn view_render(args: &ViewRenderArgs) -> Result<()> {
    prism::image::output::OutputFormat::from_path(&args.output)?;
    let png = png_options(args.exposure, args.tonemap)?;
    let (lf, s, load_seconds, synth_seconds) = synthesise_view(&args.dir, &args.view)?;
    prism::image::output::write_image(&args.output, &s.film, &png)?;
    if !args.quiet {
        eprintln!(
            "{}: {}x{} synthesised in {:.2} ms from {} views (loaded in {:.3} s){}",
            args.output.display(),
            s.film.width,
            s.film.height,
            synth_seconds * 1e3,
            lf.images.len(),
            load_seconds,
            outside_note(&s)
        );
    }
    Ok(())
}

/// Options of `prism lightfield compare`.
#[derive(clap::Args, Debug)]
struct ViewCompareArgs {
    /// Light-field folder written by `prism lightfield capture`.
    dir: PathBuf,
    /// The scene to render the reference from [default: the scene named
    /// in the manifest].
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// The view.
    #[command(flatten)]
    view: ViewFlags,
    /// Also write the synthesised view (.exr or .png).
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Also write the direct render (.exr or .png).
    #[arg(long, value_name = "FILE")]
    reference_output: Option<PathBuf>,
    /// Exposure in stops before FLIP and for PNG output.
    #[arg(
        long,
        value_name = "EV",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    exposure: f32,
    /// Tone map before FLIP and for PNG output.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    tonemap: ToneMapArg,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// `--threads`.
    #[command(flatten)]
    threads: ThreadsFlag,
}

/// What `prism lightfield compare --json` prints.
#[derive(Serialize)]
struct CompareReport {
    width: u32,
    height: u32,
    views: usize,
    outside_pixels: usize,
    synthesis_seconds: f64,
    direct_seconds: f64,
    #[serde(flatten)]
    metrics: Metrics,
}

/// Renders `camera` at `width` x `height` directly, with the light
/// field's capture settings.
fn direct_render(
    scene: &Path,
    info: &CaptureInfo,
    rig: &Rig,
    camera: &Camera,
    width: u32,
    height: u32,
) -> Result<(Film, f64)> {
    let mut desc = prism::io::load(scene, BuildOptions::default())?;
    let transport = match info.transport.as_str() {
        "whitted" => prism::core::settings::Transport::Whitted,
        "path" => prism::core::settings::Transport::Path,
        t => {
            return Err(Error::Invalid(format!(
                "the manifest's transport {t:?} is not whitted or path"
            )));
        }
    };
    let mut settings = SettingsDesc {
        width: Some(width),
        height: Some(height),
        spp: Some(info.spp),
        max_depth: Some(info.max_depth),
        seed: Some(info.seed),
        transport: Some(transport),
        ..Default::default()
    }
    .resolve(&desc.settings);
    settings.lines = None;
    settings.panorama = None;
    settings
        .validate()
        .map_err(|e| Error::Invalid(format!("the reference render: {e}")))?;
    desc.cameras = vec![camera.clone()];
    let mut r = Renderer::with_scene(
        desc,
        RenderConfig {
            settings,
            ..Default::default()
        },
        0,
    )?;
    // The capture's frame, so that the reference is rounded alike.
    r.insert_resource(RenderOrigin::Fixed(rig.centre));
    let frame = r.render()?;
    let film = frame
        .film
        .ok_or_else(|| Error::Invalid("the renderer produced no image".into()))?;
    Ok((film, frame.render_seconds))
}

fn view_compare(args: &ViewCompareArgs) -> Result<()> {
    let display = png_options(args.exposure, args.tonemap)?;
    for p in [&args.output, &args.reference_output].into_iter().flatten() {
        prism::image::output::OutputFormat::from_path(p)?;
    }
    let (lf, s, _, synth_seconds) = synthesise_view(&args.dir, &args.view)?;
    let scene = match &args.scene {
        Some(s) => s.clone(),
        None => PathBuf::from(&lf.manifest.capture.scene),
    };
    let (camera, width, height, _) = args.view.view(lf.rig())?;
    let (reference, direct_seconds) = direct_render(
        &scene,
        &lf.manifest.capture,
        lf.rig(),
        &camera,
        width,
        height,
    )?;
    let m = metrics::compare(&s.film, &reference, &display)?;
    if let Some(p) = &args.output {
        prism::image::output::write_image(p, &s.film, &display)?;
    }
    if let Some(p) = &args.reference_output {
        prism::image::output::write_image(p, &reference, &display)?;
    }
    if args.json {
        let report = CompareReport {
            width,
            height,
            views: lf.images.len(),
            outside_pixels: s.outside,
            synthesis_seconds: synth_seconds,
            direct_seconds,
            metrics: m,
        };
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| Error::Invalid(format!("cannot write JSON: {e}")))?;
        println!("{text}");
    } else {
        println!(
            "view:        {width}x{height} from {} views{}",
            lf.images.len(),
            outside_note(&s)
        );
        println!("synthesis:   {:.2} ms", synth_seconds * 1e3);
        println!(
            "direct:      {:.2} ms ({})",
            direct_seconds * 1e3,
            scene.display()
        );
        println!("RMSE:        {:.6e}", m.rmse);
        println!("relMSE:      {:.6e}", m.rel_mse);
        println!("FLIP:        {:.6}", m.flip);
    }
    Ok(())
}

/// Options of `prism lightfield sweep`.
#[derive(clap::Args, Debug)]
struct SweepArgs {
    /// Scene file (.toml, .gltf or .glb).
    scene: PathBuf,
    /// Folder for lightfield_sweep.csv, .png and .svg (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Cameras per side of the square grids to try (at least 2 each).
    #[arg(
        long,
        value_name = "N,N,...",
        value_delimiter = ',',
        default_value = "2,3,5,9,17"
    )]
    grids: Vec<u32>,
    /// Side of the square camera-plane aperture every grid spans [default:
    /// the scene rig's grid extent, (cameras - 1) x spacing along its
    /// right].
    #[arg(long, value_name = "A")]
    aperture: Option<f64>,
    /// Resolution of the captured and the test views, WxH [default: the
    /// scene's [lightfield], else 128x128].
    #[arg(long, value_name = "WxH", value_parser = parse_pair)]
    resolution: Option<[u32; 2]>,
    /// Distance from the camera plane to the focal plane [default: as for
    /// capture].
    #[arg(long, value_name = "D")]
    focal_distance: Option<f64>,
    /// Also synthesise with this proxy-plane depth (a second series).
    #[arg(long, value_name = "Z")]
    proxy_depth: Option<f64>,
    /// Number of test views (eyes at fixed points between grid cameras,
    /// 1 to 8).
    #[arg(long, default_value_t = 4)]
    views: usize,
    /// `--camera`, `--spp`, ...
    #[command(flatten)]
    render: CaptureRenderFlags,
    /// TrueType font for the plot's text [default: DejaVu Sans from the
    /// usual system folders; without one the plot has no text].
    #[arg(long, value_name = "FILE")]
    font: Option<PathBuf>,
    /// No progress bar or table.
    #[arg(short, long)]
    quiet: bool,
}

/// Test eyes, as fractions of the half aperture: none is on a grid of 2,
/// 3, 5, 9, 17 or 33 cameras a side (those lie on multiples of 1/16 of
/// the half aperture).
const TEST_EYES: [(f64, f64); 8] = [
    (0.31, -0.17),
    (-0.43, 0.29),
    (0.13, 0.41),
    (-0.23, -0.37),
    (0.57, 0.09),
    (-0.07, -0.61),
    (0.71, -0.47),
    (-0.67, 0.53),
];

/// One row of lightfield_sweep.csv.
#[derive(Clone, Debug, Serialize)]
pub struct SweepRow {
    /// `quadrilinear` or `proxy`.
    pub method: &'static str,
    /// Cameras per side.
    pub grid: u32,
    /// Distance between cameras.
    pub spacing: f64,
    /// Seconds to render every view of the grid.
    pub capture_seconds: f64,
    /// Mean seconds to synthesise one test view.
    pub synthesis_seconds: f64,
    /// Errors averaged over the test views.
    pub metrics: Metrics,
}

fn sweep(args: &SweepArgs) -> Result<()> {
    if args.grids.is_empty() || args.grids.iter().any(|&n| n < 2) {
        return Err(Error::Invalid(
            "--grids needs one or more sizes, each at least 2 cameras a side".into(),
        ));
    }
    if !(1..=TEST_EYES.len()).contains(&args.views) {
        return Err(Error::Invalid(format!(
            "--views must be 1 to {}, got {}",
            TEST_EYES.len(),
            args.views
        )));
    }
    if let Some(a) = args.aperture
        && !(a.is_finite() && a > 0.0)
    {
        return Err(Error::Invalid(format!(
            "--aperture must be finite and positive, got {a}"
        )));
    }
    std::fs::create_dir_all(&args.out).map_err(|e| Error::Output {
        path: args.out.clone(),
        message: format!("cannot create the folder: {e}"),
    })?;
    let base_flags = LightFieldSettings {
        resolution: args.resolution,
        focal_distance: args.focal_distance,
        ..Default::default()
    };
    let base = prepare(&args.scene, &base_flags, &args.render)?;
    let aperture = args
        .aperture
        .unwrap_or((base.rig.grid[0] as f64 - 1.0) * base.rig.spacing);
    let half = aperture * 0.5;
    let eyes: Vec<Camera> = TEST_EYES[..args.views]
        .iter()
        .map(|&(x, y)| base.rig.camera_at(x * half, y * half))
        .collect();
    let [w, h] = base.rig.resolution;
    let display = png_options(0.0, ToneMapArg::Clamp)?;
    // References: each test view rendered directly, once.
    let mut references = Vec::new();
    {
        let config = RenderConfig {
            settings: base.settings.clone(),
            ..Default::default()
        };
        let mut desc = base.desc.clone();
        desc.cameras = vec![eyes[0].clone()];
        let mut r = Renderer::with_scene(desc, config, 0)?;
        r.insert_resource(RenderOrigin::Fixed(base.rig.centre));
        let entity = r.cameras()[0];
        for eye in &eyes {
            r.world_mut().entity_mut(entity).insert(eye.clone());
            let frame = r.render()?;
            references.push(
                frame
                    .film
                    .ok_or_else(|| Error::Invalid("the renderer produced no image".into()))?,
            );
        }
    }
    let total_views: u64 = args.grids.iter().map(|&n| (n * n) as u64).sum();
    let bar = progress_bar(
        total_views,
        args.quiet,
        "{spinner} sweeping [{bar:40}] {pos}/{len} views {elapsed_precise} (eta {eta})",
    );
    let mut rows = Vec::new();
    for &n in &args.grids {
        let spacing = aperture / (n - 1) as f64;
        let flags = LightFieldSettings {
            grid: Some([n, n]),
            spacing: Some(spacing),
            ..base_flags
        };
        let p = prepare(&args.scene, &flags, &args.render)?;
        let mut images = Vec::with_capacity((n * n) as usize);
        let (info, rig) = capture_views(p, args.render.camera, bar.as_ref(), |_, _, f| {
            images.push(f);
            Ok(())
        })?;
        let lf = LightField::new(Manifest::new(rig, info.clone()), images)?;
        let methods: Vec<(&'static str, Option<f64>)> = match args.proxy_depth {
            Some(z) => vec![("quadrilinear", None), ("proxy", Some(z))],
            None => vec![("quadrilinear", None)],
        };
        for (method, proxy_depth) in methods {
            let mut sum = Metrics {
                rmse: 0.0,
                rel_mse: 0.0,
                flip: 0.0,
            };
            let mut seconds = 0.0;
            for (eye, reference) in eyes.iter().zip(&references) {
                let t = Instant::now();
                let s = synth::synthesise(
                    &lf,
                    eye,
                    w,
                    h,
                    SynthOptions {
                        proxy_depth,
                        outside: Outside::Error,
                    },
                )?;
                seconds += t.elapsed().as_secs_f64();
                let m = metrics::compare(&s.film, reference, &display)?;
                sum.rmse += m.rmse;
                sum.rel_mse += m.rel_mse;
                sum.flip += m.flip;
            }
            let k = eyes.len() as f64;
            rows.push(SweepRow {
                method,
                grid: n,
                spacing,
                capture_seconds: info.render_seconds,
                synthesis_seconds: seconds / k,
                metrics: Metrics {
                    rmse: sum.rmse / k,
                    rel_mse: sum.rel_mse / k,
                    flip: sum.flip / k,
                },
            });
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let csv_path = args.out.join("lightfield_sweep.csv");
    prism::image::output::write_atomic(&csv_path, sweep_csv(&rows).as_bytes())?;
    let font = crate::tradeoff::plot::load_font(args.font.as_deref());
    if let Err(e) = &font
        && !args.quiet
    {
        eprintln!("warning: {e}; the plot is drawn without text");
    }
    let title = format!(
        "{}: light-field error against grid density ({w}x{h}, {} test views)",
        args.scene.display(),
        eyes.len()
    );
    plot::write_plots(&args.out, &rows, &title, font.is_ok())?;
    if !args.quiet {
        println!(
            "method        grid  spacing    capture s  synth ms   RMSE        relMSE      FLIP"
        );
        for r in &rows {
            println!(
                "{:<12}  {:>4}  {:<9.4}  {:>9.3}  {:>8.2}   {:.4e}  {:.4e}  {:.4}",
                r.method,
                r.grid,
                r.spacing,
                r.capture_seconds,
                r.synthesis_seconds * 1e3,
                r.metrics.rmse,
                r.metrics.rel_mse,
                r.metrics.flip
            );
        }
        eprintln!(
            "wrote {}, lightfield_sweep.png and lightfield_sweep.svg",
            csv_path.display()
        );
    }
    Ok(())
}

/// The CSV text of the sweep.
fn sweep_csv(rows: &[SweepRow]) -> String {
    let mut s = String::from(
        "method,grid,cameras,spacing,capture_seconds,synthesis_seconds,rmse,rel_mse,flip\n",
    );
    for r in rows {
        s += &format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.method,
            r.grid,
            r.grid * r.grid,
            r.spacing,
            r.capture_seconds,
            r.synthesis_seconds,
            r.metrics.rmse,
            r.metrics.rel_mse,
            r.metrics.flip
        );
    }
    s
}
