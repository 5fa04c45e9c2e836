//! `prism render`: one scene file to one image, with optional statistics.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use prism::core::error::{Error, Result};
use prism::core::settings::RenderSettings;
use prism::core::window::RenderWindow;
use prism::geometry::mesh::BuildQuality;
use prism::image::output::OutputFormat;
use prism::image::shard::Manifest;
use prism::io::desc::{Geometry, SettingsDesc};
use prism::scene::environment::{Environment, EnvironmentSource};
use prism::systems::wavefront::BatchSize;
use prism::systems::{self, Frame, RenderConfig, Renderer, SceneAccel};

use crate::args::StyleArg;
use crate::args::{
    BatchPathsFlag, FrameFlags, IntegratorFlag, MinContributionFlag, PathFlags, PhotonFlags,
    QualityArg, SeedFlag, ThreadsFlag, ToneMapArg, TransportFlag, png_options,
};
use crate::shard::{self, PixelBounds, ShardSpec};
use crate::stats::{RenderStats, WavefrontStatsJson};
use crate::vector::{self, OverlayRequest};
use prism::core::settings::{GoochParams, LineSettings};
use prism::integrators::overlay::{self, OverlayKind};

/// `--render-origin`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum RenderOriginArg {
    /// At the camera.
    Camera,
    /// At the world origin.
    World,
}

/// The environment to render with: the scene's, replaced by `--env` and
/// adjusted by `--env-intensity` and `--env-rotation`.
fn environment(args: &RenderArgs, scene: Option<Environment>) -> Result<Option<Environment>> {
    if let Some(x) = args.env_intensity
        && !(x.is_finite() && x >= 0.0)
    {
        return Err(Error::Invalid(format!(
            "--env-intensity must be finite and non-negative, got {x}"
        )));
    }
    if let Some(r) = args.env_rotation
        && !r.is_finite()
    {
        return Err(Error::Invalid(format!(
            "--env-rotation must be finite, got {r}"
        )));
    }
    let (intensity, rotation) = scene
        .as_ref()
        .map_or((1.0, 0.0), |e| (e.intensity(), e.rotation()));
    let intensity = args.env_intensity.unwrap_or(intensity);
    let rotation = args.env_rotation.map_or(rotation, f32::to_radians);
    let source = match (&args.env, scene) {
        (Some(path), _) => {
            EnvironmentSource::Map(prism::io::environment::load_environment_map(path)?)
        }
        (None, Some(e)) => e.source().clone(),
        (None, None) if args.env_intensity.is_some() || args.env_rotation.is_some() => {
            return Err(Error::Invalid(
                "--env-intensity and --env-rotation need an environment: give --env FILE or an [environment] in the scene".into(),
            ));
        }
        (None, None) => return Ok(None),
    };
    Ok(Some(Environment::new(source, intensity, rotation)))
}

/// Camera overrides of `prism render`, applied to the chosen camera
/// (the scene's, or the automatic one of a scene without a camera).
#[derive(clap::Args, Debug, Default)]
pub struct ViewFlags {
    /// Eye position X,Y,Z (world coordinates) [default: the camera's; a
    /// scene without a camera is framed from +Z, see the README].
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    look_from: Option<Vec<f64>>,
    /// Point looked at X,Y,Z [default: the camera's; the centre of the
    /// scene's bounds for the automatic camera].
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    look_at: Option<Vec<f64>>,
    /// Vertical field of view in degrees, in (0, 180) [default: the
    /// camera's; 40 for the automatic camera].
    #[arg(long, value_name = "DEG")]
    fov: Option<f32>,
    /// Depth of field: radius of the thin lens's aperture in scene units
    /// (0: pinhole, the same image bit for bit) [default: the camera's, 0].
    #[arg(long, value_name = "R", conflicts_with = "f_number")]
    aperture_radius: Option<f32>,
    /// Depth of field: the aperture as an f-number N, radius f/(2N) with
    /// the focal length f of a 36x24 mm camera of the same field of view.
    #[arg(long, value_name = "N")]
    f_number: Option<f32>,
    /// Depth of field: distance of the plane in focus along the viewing
    /// direction [default: the camera's, else the distance to its look-at
    /// point].
    #[arg(long, value_name = "D")]
    focus_distance: Option<f32>,
}

impl ViewFlags {
    /// Applies the overrides to `camera` and checks the result.
    fn apply(&self, camera: &mut prism::scene::camera::Camera) -> Result<()> {
        let point = |name: &str, v: &Option<Vec<f64>>| -> Result<Option<glam::DVec3>> {
            match v {
                None => Ok(None),
                Some(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => {
                    Ok(Some(glam::DVec3::new(v[0], v[1], v[2])))
                }
                Some(v) => Err(Error::Invalid(format!(
                    "--{name} takes three finite numbers x,y,z, got {v:?}"
                ))),
            }
        };
        if let Some(p) = point("look-from", &self.look_from)? {
            camera.look_from = p;
        }
        if let Some(p) = point("look-at", &self.look_at)? {
            camera.look_at = p;
        }
        if let Some(f) = self.fov {
            camera.vfov_degrees = f;
        }
        if let Some(d) = self.focus_distance {
            camera.focus_distance = d;
        }
        if let Some(r) = self.aperture_radius {
            camera.lens_radius = r;
        }
        if let Some(n) = self.f_number {
            if !(n.is_finite() && n > 0.0) {
                return Err(Error::Invalid(format!(
                    "--f-number must be a positive number, got {n}"
                )));
            }
            camera.set_f_number(n);
        }
        camera.validate().map_err(|e| {
            Error::Invalid(format!(
                "the camera after --look-from/--look-at/--fov/lens options: {e}"
            ))
        })
    }
}

/// Options of `prism render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file: the project's TOML format, or glTF 2.0 (.gltf/.glb).
    scene: PathBuf,
    /// Output image. `.png` is 8-bit sRGB after exposure and tone map;
    /// `.exr` is linear float radiance exactly as computed.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// `--width`, `--height`, `--spp`, `--max-depth`.
    #[command(flatten)]
    frame: FrameFlags,
    /// `--min-contribution`.
    #[command(flatten)]
    min_contribution: MinContributionFlag,
    /// `--threads`.
    #[command(flatten)]
    threads: ThreadsFlag,
    /// `--seed`.
    #[command(flatten)]
    seed: SeedFlag,
    /// Which camera to render from, counting from 0 in file order (the
    /// scene file's own camera first, then those of included glTF files).
    #[arg(long, default_value_t = 0)]
    camera: usize,
    /// `--camera-projection`.
    #[command(flatten)]
    projection: crate::args::ProjectionFlag,
    /// `--look-from`, `--look-at`, `--fov` and the lens.
    #[command(flatten)]
    view: ViewFlags,
    /// Exposure in stops for PNG output: radiance is scaled by 2^EV
    /// [default: the scene's, else 0].
    #[arg(long, value_name = "EV", allow_hyphen_values = true)]
    exposure: Option<f32>,
    /// Tone map for PNG output.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    tonemap: ToneMapArg,
    /// `--integrator`.
    #[command(flatten)]
    integrator: IntegratorFlag,
    /// `--transport`.
    #[command(flatten)]
    transport: TransportFlag,
    /// `--light-samples`, `--rr-depth`.
    #[command(flatten)]
    path: PathFlags,
    /// Radiosity's options.
    #[command(flatten)]
    radiosity: crate::radiosity_args::RadiosityFlags,
    /// `--photons`, `--photon-radius`, `--photon-alpha`,
    /// `--photon-iterations`, `--final-gather`.
    #[command(flatten)]
    photon: PhotonFlags,
    /// Path tracing: never end paths by Russian roulette (unbiased either
    /// way; roulette trades variance for speed).
    #[arg(long, conflicts_with = "rr_depth")]
    no_russian_roulette: bool,
    /// Path tracing, recursive integrator: light tracing for caustics.
    /// Each camera sample also sends one path from the area lights; where
    /// it reaches a diffuse surface through mirrors or glass, that point
    /// is connected to the eye and added to the pixel it projects to. This
    /// takes over from path tracing the caustics seen directly, which it
    /// finds only by chance (unbiased either way). Pinhole perspective
    /// cameras, whole images [default: the scene's `caustics`, else off].
    #[arg(long)]
    caustics: bool,
    /// Path tracing: no light tracing of caustics, even where the scene's
    /// `[settings]` ask for it.
    #[arg(long, conflicts_with = "caustics")]
    no_caustics: bool,
    /// BVH build preset, from fastest build to best traversal.
    #[arg(long, value_enum, default_value_t = QualityArg::Medium)]
    bvh_quality: QualityArg,
    /// Acceleration structure over each mesh's triangles: the 8-wide BVH,
    /// an SAH kd-tree, a uniform grid, or none (test every triangle).
    /// All give the same image, except that only the BVH merges mesh
    /// instances (`--merge-meshes`, whose hits may differ in their last
    /// bits). Default: the scene's `[settings] accel`, else bvh.
    #[arg(long, value_enum, value_name = "STRUCTURE")]
    accel: Option<crate::args::AccelArg>,
    /// `--batch-paths`.
    #[command(flatten)]
    batch_paths: BatchPathsFlag,
    /// `--merge-meshes`.
    #[command(flatten)]
    merge: crate::args::MergeFlag,
    /// Render only shard I of N and write it as a shard (an .exr file for
    /// `prism merge`). The image is cut into 4N bands of whole rows (fewer
    /// when it has fewer rows); shard I renders bands I, I+N, I+2N, ... so
    /// that slow and fast parts of the image spread over all shards.
    /// `auto/N` takes I from PRISM_SHARD_INDEX, SLURM_ARRAY_TASK_ID or
    /// JOB_COMPLETION_INDEX (the first set), counting from 0.
    #[arg(long, value_name = "I/N", value_parser = shard::parse_shard, conflicts_with = "pixel_bounds")]
    shard: Option<ShardSpec>,
    /// Render only columns X0..X1 of rows Y0..Y1 (integers, half-open) and
    /// write them as a shard (.exr) for `prism merge`.
    #[arg(long, value_name = "X0,X1,Y0,Y1", value_parser = shard::parse_pixel_bounds)]
    pixel_bounds: Option<PixelBounds>,
    /// Render only samples A..B (half-open, from 0) of each pixel's --spp
    /// and write a sample shard (.exr with exact sums and counts) for
    /// `prism merge`; combines with --shard or --pixel-bounds.
    #[arg(long, value_name = "A..B", value_parser = shard::parse_samples)]
    samples: Option<Range<u32>>,
    /// Shading style: `shaded` (the transport's lighting) or `gooch`
    /// (cool-to-warm tones from the key light, the scene's first light, for
    /// illustration; Whitted transport only) [default: the scene's, else shaded].
    #[arg(long, value_enum)]
    style: Option<StyleArg>,
    /// Gooch parameters b, y, alpha, beta: cool tone (0,0,b) + alpha kd,
    /// warm tone (y,y,0) + beta kd [default: the scene's, else 0.4,0.4,0.2,0.6].
    #[arg(
        long,
        value_name = "B,Y,ALPHA,BETA",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    gooch: Option<Vec<f32>>,
    /// Draw feature lines found by ray casting over the image: silhouettes,
    /// creases, borders of open meshes and material boundaries, also in
    /// mirrors and through glass (on by default when the scene's [settings]
    /// have a `lines` table, or with any other line option).
    #[arg(long)]
    lines: bool,
    /// Line width in pixels, more than 0 and at most 16 [default: the
    /// scene's, else 1]. Implies --lines.
    #[arg(long, value_name = "PX", allow_hyphen_values = true)]
    line_width: Option<f32>,
    /// Line colour as R,G,B in [0, 1] (display values for PNG) [default: the
    /// scene's, else 0,0,0]. Implies --lines.
    #[arg(
        long,
        value_name = "R,G,B",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    line_color: Option<Vec<f32>>,
    /// Crease angle in degrees, 0 to 180: neighbouring normals of one object
    /// deviating by more than this make a crease line; 180 draws no creases
    /// [default: the scene's, else 45.57, Blender Freestyle's]. Implies --lines.
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    crease_angle: Option<f32>,
    /// Also write the lines of the scene's meshes as vectors to FILE.svg:
    /// silhouette, crease and border edges, split where their visibility
    /// changes (decided by casting rays), projected and clipped to the image.
    #[arg(long, value_name = "FILE")]
    lines_svg: Option<PathBuf>,
    /// In the SVG, also draw hidden segments, dashed (by default hidden
    /// segments are left out).
    #[arg(long, requires = "lines_svg")]
    hidden_lines: bool,
    /// Draw lines over the image: `wireframe` (every triangle edge),
    /// `bvh` (the BVH's boxes), `grid` (the grid cells that hold
    /// triangles) or `kdtree` (the kd-tree's splitting planes), each with
    /// the mesh's bounds, projected with the camera and clipped to the
    /// view; pieces hidden behind surfaces (found by casting rays) are
    /// dashed. bvh, grid and kdtree build the meshes with that structure
    /// (an --accel naming another one is refused).
    #[arg(long, value_enum, value_name = "KIND")]
    overlay: Option<OverlayArg>,
    /// Levels of the BVH (child boxes below the root) or of the kd-tree
    /// (splitting planes from the root) the overlay draws, 1 to 64
    /// [default: 4].
    #[arg(long, value_name = "N", requires = "overlay")]
    overlay_depth: Option<u32>,
    /// Also write the overlay's lines as vectors to FILE.svg.
    #[arg(long, value_name = "FILE", requires = "overlay")]
    overlay_svg: Option<PathBuf>,
    /// Leave the overlay's hidden pieces out instead of dashing them.
    #[arg(long, requires = "overlay")]
    overlay_visible_only: bool,
    /// Where the single-precision frame the kernels work in is centred:
    /// at the camera (precision follows the distance to the camera,
    /// whatever the distance to the world origin), or at the world origin
    /// (precision falls with the distance to it; for comparison).
    #[arg(long, value_enum, default_value_t = RenderOriginArg::Camera)]
    render_origin: RenderOriginArg,
    /// Light the scene with an equirectangular environment map (Radiance
    /// .hdr or OpenEXR .exr, +Y up, the map's centre seen looking along +X),
    /// replacing the scene's [environment] and background. Path transport
    /// samples it as a light; Whitted transport only sees it in escaped
    /// rays (mirrors, glass and the background).
    #[arg(long, value_name = "FILE")]
    env: Option<PathBuf>,
    /// Scale of the environment's radiance [default: the scene's, else 1].
    #[arg(long, value_name = "X", allow_hyphen_values = true)]
    env_intensity: Option<f32>,
    /// Turn of the environment about +Y in degrees, right-handed
    /// [default: the scene's, else 0].
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    env_rotation: Option<f32>,
    /// Write timings, ray counts and scene sizes as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// No progress bar or summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// `--overlay`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum OverlayArg {
    /// Every triangle edge.
    Wireframe,
    /// The BVH's boxes.
    Bvh,
    /// The uniform grid's cells that hold triangles.
    Grid,
    /// The kd-tree's splitting planes.
    Kdtree,
}

impl From<OverlayArg> for OverlayKind {
    fn from(a: OverlayArg) -> Self {
        match a {
            OverlayArg::Wireframe => OverlayKind::Wireframe,
            OverlayArg::Bvh => OverlayKind::Bvh,
            OverlayArg::Grid => OverlayKind::Grid,
            OverlayArg::Kdtree => OverlayKind::Kdtree,
        }
    }
}

impl RenderArgs {
    /// The overlay asked for, checked: a depth only for the BVH and the
    /// kd-tree and within 1 ..= MAX_DEPTH, an SVG path that can be written,
    /// and no --accel other than the structure drawn.
    fn overlay(&self) -> Result<Option<OverlayRequest>> {
        let Some(arg) = self.overlay else {
            return Ok(None);
        };
        let kind = OverlayKind::from(arg);
        if let Some(d) = self.overlay_depth {
            if !kind.has_levels() {
                return Err(Error::Invalid(format!(
                    "--overlay-depth: the {} overlay has no levels (only bvh and kdtree do)",
                    kind.name()
                )));
            }
            if !(1..=overlay::MAX_DEPTH).contains(&d) {
                return Err(Error::Invalid(format!(
                    "--overlay-depth {d}: must be 1 to {}",
                    overlay::MAX_DEPTH
                )));
            }
        }
        if let (Some(want), Some(given)) = (kind.accel(), self.accel) {
            let given: prism::core::settings::Accel = given.into();
            if given != want {
                return Err(Error::Invalid(format!(
                    "--overlay {} draws the {} the meshes are built with, but --accel {} asks for another structure",
                    kind.name(),
                    want.name(),
                    given.name()
                )));
            }
        }
        if let Some(svg) = &self.overlay_svg {
            vector::check_svg_path(svg, "--overlay-svg")?;
        }
        Ok(Some(OverlayRequest {
            kind,
            depth: self.overlay_depth.unwrap_or(overlay::DEFAULT_DEPTH),
            hidden: !self.overlay_visible_only,
            svg: self.overlay_svg.clone(),
        }))
    }

    /// True when rendering part of the image or of its samples.
    fn is_shard(&self) -> bool {
        self.shard.is_some() || self.pixel_bounds.is_some() || self.samples.is_some()
    }

    /// The window of a shard and how it was asked for, checked against
    /// the image size and spp; `None` for a whole render.
    fn window(&self, settings: &RenderSettings) -> Result<Option<(RenderWindow, String)>> {
        if !self.is_shard() {
            return Ok(None);
        }
        if self.overlay.is_some() {
            return Err(Error::Invalid(
                "--overlay draws over the whole image and is not available for shards".into(),
            ));
        }
        if settings.lines.is_some() || self.lines_svg.is_some() {
            return Err(Error::Invalid(
                "feature lines (--lines and its options, --lines-svg, or a lines table in the scene's [settings]) are drawn over the whole image and are not available for shards"
                    .into(),
            ));
        }
        let (w, h) = (settings.width, settings.height);
        let mut window = RenderWindow::full(w, h, settings.spp);
        let mut spec = "whole image".to_string();
        if let Some(s) = self.shard {
            let index = match s.index {
                Some(i) => i,
                None => shard::auto_index(s.count)?,
            };
            window.rows =
                prism::core::window::shard_rows(index, s.count, h).map_err(Error::Invalid)?;
            spec = format!("--shard {index}/{}", s.count);
        }
        if let Some(b) = &self.pixel_bounds {
            if b.columns.end > w || b.rows.end > h {
                return Err(Error::Invalid(format!(
                    "--pixel-bounds {},{},{},{}: outside the {w}x{h} image",
                    b.columns.start, b.columns.end, b.rows.start, b.rows.end
                )));
            }
            window.columns = b.columns.clone();
            window.rows = vec![b.rows.clone()];
            spec = format!(
                "--pixel-bounds {},{},{},{}",
                b.columns.start, b.columns.end, b.rows.start, b.rows.end
            );
        }
        if let Some(r) = &self.samples {
            if r.end > settings.spp {
                return Err(Error::Invalid(format!(
                    "--samples {}..{}: beyond the {} samples per pixel (--spp)",
                    r.start, r.end, settings.spp
                )));
            }
            window.samples = r.clone();
        }
        Ok(Some((window, spec)))
    }
}

/// Renders the scene and writes the image (and the statistics).
pub fn run(args: RenderArgs) -> Result<()> {
    let wall = Instant::now();
    // Fail on a bad output name before spending time on the render.
    let format = OutputFormat::from_path(&args.output)?;
    if args.is_shard() && format != OutputFormat::Exr {
        return Err(Error::Invalid(format!(
            "{}: a shard (--shard, --pixel-bounds, --samples) is written as an .exr file; `prism merge` makes the PNG from all shards",
            args.output.display()
        )));
    }
    if let Some(svg) = &args.lines_svg {
        vector::check_svg_path(svg, "--lines-svg")?;
    }
    let overlay_request = args.overlay()?;
    if let Some(s) = &args.stats
        && s.extension().and_then(|e| e.to_str()) != Some("json")
    {
        return Err(Error::Invalid(format!(
            "--stats {}: the statistics file must end in .json",
            s.display()
        )));
    }
    let (pool, threads) = args.threads.pool()?;
    pool.install(|| render_with_pool(&args, overlay_request, threads, wall))
}

fn render_with_pool(
    args: &RenderArgs,
    overlay_request: Option<OverlayRequest>,
    threads: usize,
    wall: Instant,
) -> Result<()> {
    let quality: BuildQuality = args.bvh_quality.into();
    let load_start = Instant::now();
    let options = prism::geometry::mesh::BuildOptions {
        quality,
        // A structure overlay builds the meshes with the structure it draws.
        accel: args
            .accel
            .map(Into::into)
            .or(overlay_request.as_ref().and_then(|o| o.kind.accel())),
    };
    let (mut desc, scene_hash) = if args.is_shard() {
        let (desc, hash) = prism::io::load_with_digest(&args.scene, options)?;
        (desc, Some(hash))
    } else {
        (prism::io::load(&args.scene, options)?, None)
    };
    desc.environment = environment(args, desc.environment.take())?;
    // What the meshes were built with (the scene's choice when no --accel).
    let mut mesh_accel = options.accel.or(desc.settings.accel).unwrap_or_default();
    let mut accel_bytes = 0;
    let load_seconds = load_start.elapsed().as_secs_f64();
    let mut mesh_build_seconds = 0.0;
    let mut seen = std::collections::HashSet::new();
    for o in &desc.objects {
        if let Geometry::Mesh(m) = &o.geometry
            && seen.insert(Arc::as_ptr(m))
        {
            mesh_build_seconds += m.build_seconds;
            accel_bytes += m.accel_bytes();
            mesh_accel = m.accel();
        }
    }

    let s = &desc.settings;
    if let Some(g) = &args.gooch
        && g.len() != 4
    {
        return Err(Error::Invalid(format!(
            "--gooch takes four numbers b,y,alpha,beta, got {}",
            g.len()
        )));
    }
    if let Some(c) = &args.line_color
        && c.len() != 3
    {
        return Err(Error::Invalid(format!(
            "--line-color takes three numbers r,g,b, got {}",
            c.len()
        )));
    }
    let gooch = args.gooch.as_ref().map(|g| GoochParams {
        b: g[0],
        y: g[1],
        alpha: g[2],
        beta: g[3],
    });
    let lines_asked = args.lines
        || args.line_width.is_some()
        || args.line_color.is_some()
        || args.crease_angle.is_some();
    let lines = match (lines_asked, s.lines) {
        (false, scene) => scene,
        (true, scene) => {
            let base = scene.unwrap_or_default();
            Some(LineSettings {
                width: args.line_width.unwrap_or(base.width),
                color: args
                    .line_color
                    .as_ref()
                    .map_or(base.color, |c| [c[0], c[1], c[2]]),
                crease_degrees: args.crease_angle.unwrap_or(base.crease_degrees),
            })
        }
    };
    let settings = SettingsDesc {
        style: args.style.map(Into::into),
        gooch,
        lines,
        min_contribution: args.min_contribution.min_contribution,
        seed: args.seed.seed,
        transport: args.transport.get(),
        light_samples: args.path.light_samples,
        rr_weight: args.path.rr_weight,
        split: args.path.split,
        sampler: args.path.sampler(),
        radiosity: args.radiosity.desc(),
        panorama: args.projection.get(),
        photon: args.photon.overrides(),
        caustics: if args.no_caustics {
            Some(false)
        } else {
            args.caustics.then_some(true)
        },
        rr_start_depth: if args.no_russian_roulette {
            Some(None)
        } else {
            args.path.rr_depth.map(Some)
        },
        ..args.frame.desc()
    }
    .resolve(s);
    let mut settings = settings;
    // The image size and spp are checked before the window is made from them.
    settings.validate().map_err(|e| {
        Error::Invalid(format!(
            "{}: invalid render settings (from the command line or the scene's [settings]): {e}",
            args.scene.display()
        ))
    })?;
    let window = args.window(&settings)?;
    settings.window = window.as_ref().map(|(w, _)| w.clone());
    settings.validate().map_err(|e| {
        Error::Invalid(format!(
            "{}: invalid render settings (from the command line or the scene's [settings]): {e}",
            args.scene.display()
        ))
    })?;
    let png = png_options(args.exposure.or(s.exposure).unwrap_or(0.0), args.tonemap)?;
    // A bare model gets a camera framing it and a light, like in a glTF
    // viewer; the CLI's own words for camera problems, before
    // Renderer::with_scene would give its more general ones.
    let aspect = settings.width as f64 / settings.height as f64;
    if let Some(n) = desc.ensure_camera(aspect) {
        eprintln!("notice: {}: {n}", args.scene.display());
    }
    let camera_count = desc.cameras.len();
    if args.camera >= camera_count {
        return Err(Error::Invalid(format!(
            "--camera {}: the scene has {camera_count} camera(s), numbered from 0",
            args.camera
        )));
    }
    if let (Some(p), Some(_)) = (settings.panorama, &args.lines_svg) {
        return Err(Error::Invalid(format!(
            "--lines-svg projects onto the perspective camera's image; it does not combine \
             with the {} panorama",
            p.name()
        )));
    }
    args.view.apply(&mut desc.cameras[args.camera])?;
    let chosen = desc.cameras[args.camera].clone();
    if let Some(n) = desc.ensure_light(&chosen, settings.transport) {
        eprintln!("notice: {}: {n}", args.scene.display());
    }
    let light_count = desc.lights.len();
    let camera = desc.cameras[args.camera].clone();

    // The line stage reports its rows on the same bar.
    let passes = 1 + settings.lines.is_some() as u64;
    let bar = if settings.transport == prism::core::settings::Transport::Photon {
        // Each iteration's photon pass and camera pass report a share each.
        progress_bar(
            prism::integrators::photon::progress_steps(&settings)
                + settings.lines.is_some() as u64 * settings.height as u64,
            args.quiet,
            "{spinner} photon mapping [{bar:40}] {percent}% {elapsed_precise} (eta {eta})",
        )
    } else {
        // Light tracing of caustics (recursive integrator) reports a
        // pass of as many rows.
        let light = match args.integrator.kind() {
            prism::integrators::IntegratorKind::Recursive => {
                prism::transport::caustic::light_pass_rows(&settings)
            }
            _ => 0,
        };
        progress_bar(
            settings.window().row_count() as u64 * passes + light,
            args.quiet,
            "{spinner} rendering [{bar:40}] {pos}/{len} rows {elapsed_precise} (eta {eta})",
        )
    };
    let progress: Option<systems::ProgressFn> = bar.clone().map(|b| {
        let f: systems::ProgressFn = Arc::new(move |n| b.inc(n));
        f
    });
    // The radiosity solve has its own bar, above the render's.
    let solve_bar = (settings.transport == prism::core::settings::Transport::Radiosity)
        .then(|| {
            progress_bar(
                0,
                args.quiet,
                "{spinner} radiosity form factors, pass {msg} [{bar:40}] {pos}/{len} rows {elapsed_precise}",
            )
        })
        .flatten();
    let mut renderer = Renderer::with_scene(
        desc,
        RenderConfig {
            settings: settings.clone(),
            integrator: args.integrator.kind(),
            bvh_quality: quality,
            progress,
            merge_meshes: args.merge.on(),
            ..Default::default()
        },
        args.camera,
    )?;
    let batch_paths = args.batch_paths.get()?;
    renderer.insert_resource(BatchSize(batch_paths));
    if let Some(b) = solve_bar.clone() {
        let pass = std::sync::atomic::AtomicU64::new(0);
        let f: systems::radiosity::SolveProgressFn = Arc::new(move |done, total| {
            if b.length() != Some(total) || done < b.position() {
                let p = pass.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                b.set_message(p.to_string());
                b.set_length(total);
            }
            b.set_position(done);
        });
        renderer
            .world_mut()
            .resource_mut::<systems::radiosity::RadiosityState>()
            .progress = Some(f);
    }
    if args.render_origin == RenderOriginArg::World {
        renderer.insert_resource(systems::RenderOrigin::Fixed(glam::DVec3::ZERO));
    }
    renderer.run();
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    if let Some(b) = &solve_bar {
        b.finish_and_clear();
    }
    let radiosity = renderer
        .world()
        .get_resource::<systems::radiosity::RadiosityState>()
        .and_then(|r| r.solution.as_ref().map(|s| s.stats));

    let accel = renderer.world().resource::<SceneAccel>();
    let tlas_seconds = accel.build_seconds;
    let (triangles, primitives) = accel
        .scene
        .as_ref()
        .map_or((0, 0), |s| (s.triangle_count(), s.instances().len()));
    let (merged_instances, merged_bytes) = accel
        .scene
        .as_ref()
        .map_or((0, 0), |s| (s.merged_instances(), s.merged_bytes()));
    let features = accel
        .scene
        .as_ref()
        .map(|s| prism::scene::features::SceneFeatures::of(s))
        .unwrap_or_default();
    let frame = renderer.world().resource::<Frame>();
    if let Some(e) = &frame.error {
        return Err(Error::Invalid(format!("{}: {e}", args.scene.display())));
    }
    let Some(film) = &frame.film else {
        return Err(Error::Invalid("the renderer produced no image".into()));
    };
    let overlay_mask = match &overlay_request {
        Some(req) => {
            let scene = accel
                .scene
                .as_ref()
                .ok_or_else(|| Error::Invalid("no scene was built".into()))?;
            Some(vector::overlay_lines(
                req, scene, &camera, &settings, args.quiet,
            )?)
        }
        None => None,
    };
    match (&window, scene_hash) {
        (Some((w, spec)), Some(scene_hash)) => {
            let manifest = Manifest {
                version: env!("CARGO_PKG_VERSION").to_string(),
                scene_hash,
                settings: shard::settings_text(
                    &settings,
                    args.integrator.kind().name(),
                    args.camera,
                    &format!(
                        "{:?} accel={} render_origin={:?}",
                        args.bvh_quality,
                        mesh_accel.name(),
                        args.render_origin
                    )
                    .to_lowercase(),
                ),
                seed: settings.seed,
                spp: settings.spp,
                shard: spec.clone(),
                samples: w.samples.clone(),
            };
            let shard = prism::image::shard::Shard::from_window(
                manifest,
                &settings,
                w,
                film,
                frame.sums.as_ref(),
            );
            prism::image::shard::write_shard(&args.output, &shard)?;
        }
        _ => {
            let mut overlays: Vec<&prism::image::lines::LineOverlay> = frame.lines.iter().collect();
            overlays.extend(overlay_mask.as_ref().map(|(mask, _)| mask));
            prism::image::output::write_image_with_overlays(&args.output, film, &overlays, &png)?;
            if let (Some(req), Some((_, Some(svg)))) = (&overlay_request, &overlay_mask)
                && let Some(path) = &req.svg
            {
                prism::image::output::write_atomic(path, svg.as_bytes())?;
            }
        }
    }
    if let Some(svg) = &args.lines_svg {
        let scene = accel
            .scene
            .as_ref()
            .ok_or_else(|| Error::Invalid("no scene was built".into()))?;
        vector::write_svg(
            svg,
            scene,
            &camera,
            &settings,
            args.hidden_lines,
            args.quiet,
        )?;
    }

    let rays = frame.counters.rays;
    let render_seconds = frame.render_seconds;
    let stats = RenderStats {
        scene: args.scene.display().to_string(),
        integrator: args.integrator.kind().name().into(),
        transport: settings.transport.name().into(),
        features,
        wall_seconds: wall.elapsed().as_secs_f64(),
        load_seconds,
        accel: mesh_accel.name(),
        accel_bytes: accel_bytes + merged_bytes,
        merged_instances,
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
        line_seconds: frame.lines.as_ref().map(|_| frame.line_seconds),
        line_rays: frame.lines.as_ref().map(|_| frame.line_rays),
        radiosity: radiosity
            .filter(|_| settings.transport == prism::core::settings::Transport::Radiosity),
        photon: frame.photon,
        wavefront: frame.wavefront.map(|w| WavefrontStatsJson {
            stage_seconds: w.stages,
            peak_queue_bytes: w.peak_queue_bytes,
            batches: w.batches,
            lanes: w.lanes,
            batch_paths,
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
        if let Some(r) = &stats.radiosity {
            eprintln!(
                "radiosity: {} patches ({} passes, {} split), {} iterations to residual {:.2e}{}, \
                 form factors {:.3} s ({} entries, {:.1} MB), solve {:.3} s, total {:.3} s, peak {:.1} MB",
                r.patches,
                r.passes,
                r.refined,
                r.iterations,
                r.residual,
                if r.converged { "" } else { " (NOT converged)" },
                r.form_factor_seconds,
                r.form_factors,
                r.form_factor_bytes as f64 / 1e6,
                r.solve_seconds,
                r.total_seconds,
                r.peak_bytes as f64 / 1e6
            );
        }
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
