//! A game-style frame loop: an animated `bevy_ecs` world (spheres
//! orbiting, torus knots and a glTF model turning, a light wandering)
//! rendered frame after frame, each frame updating only what moved.
//!
//! ```text
//! cargo run --release --example game_loop -- --frames 48 --out target/game_loop
//! ```
//!
//! Writes `DIR/frame_0000.png`, ... and `DIR/animation.gif`, prints each
//! frame's time for scene sync, BVH update and rendering, and the frames
//! per second at the end.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use bevy_ecs::prelude::*;
use clap::Parser;
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame as GifFrame, RgbaImage};
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::BuildQuality;
use prism::image::output::{PngOptions, to_srgb8};
use prism::integrators::IntegratorKind;
use prism::systems::demo::{AnimationTime, DemoScene, add_animation};
use prism::systems::{Frame, PrismPlugin, RenderConfig, run_frame};

/// Renders an animated scene through Prism's ECS frame loop.
#[derive(Parser, Debug)]
struct Args {
    /// Number of frames.
    #[arg(long, default_value_t = 48)]
    frames: u32,
    /// Output directory (created if missing).
    #[arg(long, default_value = "game_loop_out")]
    out: PathBuf,
    /// Image width.
    #[arg(long, default_value_t = 640)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 360)]
    height: u32,
    /// Samples per pixel per frame.
    #[arg(long, default_value_t = 1)]
    spp: u32,
    /// Maximum number of specular bounces.
    #[arg(long, default_value_t = 2)]
    max_depth: u32,
    /// Scene seconds per frame.
    #[arg(long, default_value_t = 1.0 / 12.0)]
    dt: f32,
    /// Triangles per torus knot mesh (four knots are rendered).
    #[arg(long, default_value_t = 25_000)]
    knot_triangles: u32,
    /// glTF file whose objects turn in the middle of the scene; default
    /// `assets/gltf/showroom.gltf`.
    #[arg(long)]
    gltf: Option<PathBuf>,
    /// Use the wavefront integrator instead of the recursive one.
    #[arg(long)]
    wavefront: bool,
    /// Do not write the per-frame PNG files (the GIF is still written).
    #[arg(long)]
    no_png: bool,
}

fn run(args: Args) -> Result<(), String> {
    if args.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    if !(args.dt.is_finite()) {
        return Err("--dt must be finite".into());
    }
    let settings = RenderSettings {
        width: args.width,
        height: args.height,
        spp: args.spp,
        max_depth: args.max_depth,
        ..Default::default()
    };
    settings.validate()?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    let gltf_path = args
        .gltf
        .clone()
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/gltf/showroom.gltf"));
    let gltf = prism::io::load(&gltf_path, BuildQuality::Medium)
        .map_err(|e| format!("{}: {e}", gltf_path.display()))?;

    let mut world = World::new();
    let mut schedule = Schedule::default();
    add_animation(&mut world, &mut schedule);
    let demo = DemoScene {
        knot_triangles: args.knot_triangles,
        gltf: Some(gltf),
        ..Default::default()
    };
    let camera = demo.spawn(&mut world);
    PrismPlugin::new()
        .config(RenderConfig {
            settings,
            integrator: if args.wavefront {
                IntegratorKind::Wavefront
            } else {
                IntegratorKind::Recursive
            },
            camera: Some(camera),
            ..Default::default()
        })
        .build(&mut world, &mut schedule);

    let gif_path = args.out.join("animation.gif");
    let gif_file = std::fs::File::create(&gif_path)
        .map_err(|e| format!("cannot create {}: {e}", gif_path.display()))?;
    let mut gif = GifEncoder::new_with_speed(std::io::BufWriter::new(gif_file), 10);
    gif.set_repeat(Repeat::Infinite)
        .map_err(|e| e.to_string())?;
    let delay = Delay::from_numer_denom_ms((args.dt * 1000.0).round().max(20.0) as u32, 1);

    let png = PngOptions::default();
    let mut totals = [0.0f64; 4];
    println!(
        "{:>5} {:>10} {:>10} {:>10} {:>10}  changes",
        "frame", "sync ms", "bvh ms", "render ms", "frame ms"
    );
    for f in 0..args.frames {
        world.resource_mut::<AnimationTime>().0 = f as f32 * args.dt;
        let start = Instant::now();
        run_frame(&mut world, &mut schedule);
        let wall = start.elapsed().as_secs_f64();
        let frame = world.resource::<Frame>();
        if let Some(e) = &frame.error {
            return Err(format!("frame {f}: {e}"));
        }
        let film = frame.film.as_ref().ok_or("no image")?;
        let u = frame.update;
        println!(
            "{f:>5} {:>10.3} {:>10.3} {:>10.2} {:>10.2}  +{} -{} moved {} tlas {:?}",
            u.sync_seconds * 1e3,
            u.accel_seconds * 1e3,
            frame.render_seconds * 1e3,
            wall * 1e3,
            u.added,
            u.removed,
            u.moved,
            u.tlas
        );
        if f > 0 {
            // The first frame builds everything; the loop is what follows.
            totals[0] += u.sync_seconds;
            totals[1] += u.accel_seconds;
            totals[2] += frame.render_seconds;
            totals[3] += wall;
        }
        if !args.no_png {
            let path = args.out.join(format!("frame_{f:04}.png"));
            prism::image::output::write_image(&path, film, &png).map_err(|e| e.to_string())?;
        }
        let mut rgba = RgbaImage::new(film.width, film.height);
        for (px, c) in rgba.pixels_mut().zip(&film.pixels) {
            let [r, g, b] = to_srgb8(*c, &png);
            *px = image::Rgba([r, g, b, 255]);
        }
        gif.encode_frame(GifFrame::from_parts(rgba, 0, 0, delay))
            .map_err(|e| format!("{}: {e}", gif_path.display()))?;
    }
    drop(gif);
    let loop_frames = (args.frames - 1).max(1) as f64;
    if args.frames > 1 {
        let update = totals[0] + totals[1];
        println!(
            "frames 1..{}: {:.2} frames/s; per frame: sync {:.3} ms, BVH {:.3} ms, render {:.1} ms; scene update {:.2}% of the frame",
            args.frames - 1,
            loop_frames / totals[3],
            totals[0] / loop_frames * 1e3,
            totals[1] / loop_frames * 1e3,
            totals[2] / loop_frames * 1e3,
            100.0 * update / totals[3]
        );
    }
    println!(
        "wrote {} frames to {} ({} threads)",
        args.frames,
        args.out.display(),
        rayon::current_num_threads()
    );
    Ok(())
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("game_loop: {e}");
            ExitCode::FAILURE
        }
    }
}
