//! Light tracing of caustics (`--caustics`): the same image in
//! expectation as path tracing alone, bit for bit across thread counts,
//! and refused where it cannot run.

use std::path::PathBuf;

use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;

use crate::common::images::film_bits;
use crate::common::render::{config, render_file, renderer};
use crate::common::scenes;

fn spheres() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets/gltf/spheres.gltf")
}

fn settings(spp: u32, caustics: bool) -> RenderSettings {
    RenderSettings {
        width: 64,
        height: 48,
        spp,
        max_depth: 16,
        seed: 1,
        transport: Transport::Path,
        caustics,
        ..Default::default()
    }
}

/// Mean over the rows `rows` of every channel.
fn mean_rows(f: &Film, rows: std::ops::Range<u32>) -> f64 {
    let mut s = 0.0;
    for y in rows.clone() {
        for x in 0..f.width {
            let c = f.get(x, y);
            s += (c.x + c.y + c.z) as f64;
        }
    }
    s / (3 * f.width * (rows.end - rows.start)) as f64
}

/// The glass-and-mirror scene's caustics (5% of its mean, most of it on
/// the floor and the wall) come out the same by light tracing as by path
/// tracing: the image's mean and its lower half's agree.
///
/// Tolerance: at 64 x 48 and 64 spp four seeds gave image means with a
/// relative standard deviation of 0.34% without light tracing and 0.29%
/// with it (release build of `prism render`); at 256 spp that is about
/// 0.17%, so the difference of the two has a deviation of about 0.23%.
/// 1% is four of those. Counting the splats twice moves the mean by
/// about 5% (tried: this test failed).
#[test]
fn light_tracing_agrees_with_path_tracing() {
    let frame = |caustics| {
        render_file(
            &spheres(),
            config(settings(256, caustics), IntegratorKind::Recursive),
        )
        .film
        .unwrap()
    };
    let (pt, lt) = (frame(false), frame(true));
    for rows in [0..48, 24..48] {
        let (a, b) = (mean_rows(&pt, rows.clone()), mean_rows(&lt, rows.clone()));
        assert!(a > 0.05, "{a}");
        assert!(
            (b / a - 1.0).abs() < 0.01,
            "rows {rows:?}: path tracing {a}, with light tracing {b}"
        );
    }
}

/// The light subpaths run in chunks on the worker threads: one thread and
/// two give the same bits.
#[test]
fn light_tracing_is_bit_identical_across_thread_counts() {
    let films: Vec<Film> = [1, 2]
        .into_iter()
        .map(|threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    render_file(
                        &spheres(),
                        config(settings(8, true), IntegratorKind::Recursive),
                    )
                    .film
                    .unwrap()
                })
        })
        .collect();
    assert_eq!(film_bits(&films[0]), film_bits(&films[1]));
}

/// The wavefront integrator refuses light tracing with a message that
/// names the way out, and a render window is refused by the settings.
#[test]
fn light_tracing_is_refused_where_it_cannot_run() {
    let mut r = renderer(
        scenes::load(&spheres()),
        config(settings(1, true), IntegratorKind::Wavefront),
    );
    let Err(e) = r.render() else {
        panic!("the wavefront rendered light tracing");
    };
    let e = e.to_string();
    assert!(e.contains("--integrator recursive"), "{e}");
    let mut s = settings(1, true);
    s.window = Some(prism::core::window::RenderWindow::full(8, 8, 1));
    let e = s.validate().unwrap_err();
    assert!(e.contains("render window"), "{e}");
}

/// `film_density` is the change of variables from a surface's area to
/// film positions that light tracing's splats use: the footprint of a
/// pixel on a tilted plane, between the points where the rays through the
/// pixel's corners meet it, has an area of one over the density at its
/// centre. The footprint is not quite a parallelogram, and the rays are
/// f32; over one pixel of a 64 x 48 image that came to at most 2.3e-5
/// here, and 1e-3 is allowed. Without the `cos^3` of the image plane the
/// corner pixels read 0.14 (tried: this test failed; the agreement test
/// above did not, the caustics there being near the image's centre).
#[test]
fn film_density_is_one_over_a_pixels_footprint() {
    use glam::{DVec3, Vec2, Vec3A};
    use prism::scene::camera::{Camera, CameraRays};
    let camera = Camera {
        look_from: DVec3::new(1.0, 4.0, 1.5),
        look_at: DVec3::new(0.0, -1.0, 0.0),
        vfov_degrees: 90.0,
        ..Default::default()
    };
    let cam = CameraRays::new(&camera, 64, 48);
    let n = Vec3A::new(0.3, 1.0, 0.2).normalize();
    let p0 = Vec3A::new(0.0, -1.0, 0.0);
    let hit = |x: f32, y: f32| {
        let r = cam.ray(Vec2::new(x, y));
        let t = (p0 - r.origin).dot(n) as f64 / r.direction.dot(n) as f64;
        assert!(t > 0.0);
        r.origin.as_dvec3() + r.direction.as_dvec3() * t
    };
    let mut worst = 0.0f64;
    for (x, y) in [(0, 0), (63, 0), (0, 47), (63, 47), (32, 24), (10, 40)] {
        let (x, y) = (x as f32, y as f32);
        let c = [
            hit(x, y),
            hit(x + 1.0, y),
            hit(x + 1.0, y + 1.0),
            hit(x, y + 1.0),
        ];
        let area = 0.5 * (c[2] - c[0]).cross(c[3] - c[1]).length();
        let centre = hit(x + 0.5, y + 0.5).as_vec3a();
        let density = prism::transport::caustic::film_density(&cam, centre, n).unwrap() as f64;
        eprintln!("pixel ({x}, {y}): density x footprint = {}", density * area);
        worst = worst.max((density * area - 1.0).abs());
    }
    assert!(worst < 1e-3, "{worst}");
    eprintln!("worst relative difference {worst:.2e}");
}

/// The light subpaths' aimed directions: their density integrates to one
/// over the sphere of directions (two overlapping targets and one far
/// away; 400,000 uniform directions, so the estimate's standard error is
/// about 0.017 and 0.05 is allowed; without the division by the number
/// of targets it read 3.0: tried), and every direction `aim` draws has
/// a positive density and points into a target's cone.
#[test]
fn aimed_directions_have_a_normalised_density() {
    use glam::{Vec2, Vec3A};
    use prism::transport::caustic::{Target, aim, aim_pdf};
    let targets = [
        Target {
            centre: Vec3A::new(2.0, 1.0, 0.0),
            radius: 1.0,
        },
        Target {
            centre: Vec3A::new(2.5, 0.5, 0.5),
            radius: 0.7,
        },
        Target {
            centre: Vec3A::new(-30.0, 4.0, 9.0),
            radius: 2.0,
        },
    ];
    let p = Vec3A::new(0.0, 3.0, 0.0);
    let n = Vec3A::new(0.0, -1.0, 0.0);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let count = 400_000;
    let mut sum = 0.0f64;
    for _ in 0..count {
        let z = 1.0 - 2.0 * next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * next();
        let dir = Vec3A::new(r * phi.cos(), r * phi.sin(), z);
        sum += aim_pdf(&targets, p, n, dir) as f64;
    }
    let integral = sum / count as f64 * 4.0 * std::f64::consts::PI;
    assert!((integral - 1.0).abs() < 0.05, "{integral}");
    for _ in 0..1000 {
        let (dir, pdf) = aim(&targets, p, n, Vec2::new(next(), next()), next()).unwrap();
        assert!(pdf > 0.0);
        assert!(targets.iter().any(|t| {
            let to = t.centre - p;
            let cos_max = (to.length_squared() - t.radius * t.radius).sqrt() / to.length();
            dir.dot(to.normalize()) >= cos_max - 1e-5
        }));
    }
}

/// A scene file turns light tracing on with `caustics = true` in its
/// `[settings]`, and leaves it off without the key.
#[test]
fn scene_files_turn_light_tracing_on() {
    let scene = |settings: &str| {
        format!(
            "[settings]\ntransport = \"path\"\n{settings}\n[camera]\nlook_from = [0.0, 1.0, 4.0]\n\
             look_at = [0.0, 0.0, 0.0]\n\n[[objects]]\nshape = {{ type = \"sphere\", radius = 1.0 }}\n"
        )
    };
    let on = scenes::load_toml(&scene("caustics = true")).unwrap();
    assert!(on.settings.resolve(&Default::default()).caustics);
    let off = scenes::load_toml(&scene("")).unwrap();
    assert!(!off.settings.resolve(&Default::default()).caustics);
}

/// The light pass reports progress: a recursive render with light tracing
/// counts the image's height twice, once for the camera pass's rows and
/// once for the light subpaths (also when the scene has nothing for them
/// to trace and the pass is skipped); without it, once.
#[test]
fn light_pass_reports_progress() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU64, Ordering};
    let cornell = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets/gltf/cornell.gltf");
    for (scene, caustics, passes) in [
        (spheres(), true, 2),
        (spheres(), false, 1),
        (cornell, true, 2),
    ] {
        let count = Arc::new(AtomicU64::new(0));
        let c = count.clone();
        let mut cfg = config(settings(4, caustics), IntegratorKind::Recursive);
        cfg.progress = Some(Arc::new(move |n| {
            c.fetch_add(n, Ordering::Relaxed);
        }));
        render_file(&scene, cfg).film.unwrap();
        assert_eq!(
            count.load(Ordering::Relaxed),
            passes * 48,
            "{} caustics {caustics}",
            scene.display()
        );
    }
}
