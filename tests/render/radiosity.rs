//! Radiosity transport end to end: the Cornell box against the path
//! tracer, the solution kept while the camera moves (and solved again when
//! the scene changes), bit-identical images for any thread count, and
//! refusals of what the solution cannot hold.

use glam::DVec3;
use prism::core::radiosity::{RadiositySettings, ViewMode};
use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::camera::Camera;
use prism::scene::material::Material;
use prism::systems::radiosity::RadiosityState;

use crate::common::cli::{assert_failed_without_panic, prism};
use crate::common::images::film_bits;
use crate::common::render::{config, renderer};
use crate::common::{assets, scenes};

fn radiosity_settings(size: u32, spp: u32, radiosity: RadiositySettings) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        spp,
        max_depth: 4,
        seed: 3,
        transport: Transport::Radiosity,
        radiosity,
        ..Default::default()
    }
}

/// Coarse patches and one round of refinement: a solve of a few hundred
/// patches, for tests about reuse and determinism rather than accuracy.
fn coarse() -> RadiositySettings {
    RadiositySettings {
        patch_size: Some(1.4),
        refine_levels: 1,
        ..Default::default()
    }
}

fn cornell(settings: RenderSettings) -> Film {
    let desc = scenes::load(&assets().join("cornell.toml"));
    renderer(desc, config(settings, IntegratorKind::Recursive))
        .render()
        .unwrap()
        .film
        .unwrap()
}

/// Mean of each `block x block` tile's luminance.
fn block_means(f: &Film, block: u32) -> Vec<f64> {
    let mut out = Vec::new();
    for by in 0..f.height / block {
        for bx in 0..f.width / block {
            let mut s = 0.0f64;
            for y in by * block..(by + 1) * block {
                for x in bx * block..(bx + 1) * block {
                    s += prism::core::math::luminance(f.get(x, y)) as f64;
                }
            }
            out.push(s / (block * block) as f64);
        }
    }
    out
}

#[test]
fn cornell_box_agrees_with_the_path_tracer() {
    let size = 32;
    let reference = cornell(RenderSettings {
        width: size,
        height: size,
        spp: 1024,
        max_depth: 64,
        min_contribution: 0.0,
        seed: 5,
        transport: Transport::Path,
        ..Default::default()
    });
    // The light panel is a thin, very bright strip at this size: its edges
    // need many view samples for the image mean to settle (view samples
    // are cheap; the solve is done once).
    let radiosity = cornell(radiosity_settings(size, 64, RadiositySettings::default()));
    let (a, b) = (block_means(&radiosity, size), block_means(&reference, size));
    let mean_error = (a[0] - b[0]).abs() / b[0];
    let (ra, rb) = (block_means(&radiosity, 8), block_means(&reference, 8));
    let block_error: f64 = ra
        .iter()
        .zip(&rb)
        .map(|(x, y)| (x - y).abs() / y.max(1e-3))
        .sum::<f64>()
        / ra.len() as f64;
    eprintln!(
        "Cornell {size}x{size}: image mean radiosity {:.5}, path {:.5} (relative error {mean_error:.4}); \
         8x8-block mean relative error {block_error:.4}",
        a[0], b[0]
    );
    assert!(mean_error < 0.01, "image means differ by {mean_error}");
    assert!(
        block_error < 0.05,
        "8x8 blocks differ by {block_error} on average"
    );
}

#[test]
fn the_solution_is_reused_while_the_camera_moves() {
    let desc = scenes::load(&assets().join("cornell.toml"));
    let settings = radiosity_settings(16, 1, coarse());
    let mut r = renderer(desc, config(settings, IntegratorKind::Recursive));
    let first = r.render().unwrap().film.unwrap();
    assert_eq!(r.world().resource::<RadiosityState>().solves, 1);
    let cam = r.cameras()[0];
    let mut images = vec![film_bits(&first)];
    for k in 1..=3 {
        r.world_mut().get_mut::<Camera>(cam).unwrap().look_from +=
            DVec3::new(0.3 * k as f64, 0.0, 0.0);
        let f = r.render().unwrap().film.unwrap();
        let state = r.world().resource::<RadiosityState>();
        assert_eq!(state.solves, 1, "frame {k} solved again");
        assert!(!state.solved_this_frame);
        images.push(film_bits(&f));
    }
    // The camera did move.
    assert_ne!(images[0], images[3]);
    // A far move recentres the render origin: still no new solve.
    r.world_mut().get_mut::<Camera>(cam).unwrap().look_from += DVec3::new(0.0, 0.0, -100.0);
    r.render().unwrap();
    assert_eq!(r.world().resource::<RadiosityState>().solves, 1);
    // A changed material is a new scene: solved again.
    let e = {
        let w = r.world_mut();
        let mut q = w.query::<(bevy_ecs::entity::Entity, &Material)>();
        q.iter(w).next().unwrap().0
    };
    r.world_mut().get_mut::<Material>(e).unwrap().base_color *= 0.5;
    r.render().unwrap();
    assert_eq!(r.world().resource::<RadiosityState>().solves, 2);
    // Changed radiosity options: solved again.
    r.config_mut().settings.radiosity.refine_levels = 0;
    r.render().unwrap();
    assert_eq!(r.world().resource::<RadiosityState>().solves, 3);
}

#[test]
fn images_are_bit_identical_for_one_and_two_threads() {
    let render = |threads: usize, view: ViewMode| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let settings = radiosity_settings(
                16,
                2,
                RadiositySettings {
                    view,
                    gather_rays: 4,
                    ..coarse()
                },
            );
            film_bits(&cornell(settings))
        })
    };
    for view in [ViewMode::Gouraud, ViewMode::Gather] {
        assert_eq!(render(1, view), render(2, view), "{view:?}");
    }
}

/// Scene text: an emissive quad over a floor, with `extra` appended.
fn lit_room(extra: &str) -> String {
    format!(
        r#"
[settings]
width = 8
height = 8
transport = "radiosity"

[camera]
look_from = [0, 1, 3]
look_at = [0, 0, 0]

[materials.white]
color = 0.5

[materials.light]
color = 0.5
emission = 2.0

[[objects]]
shape = {{ type = "polygon", vertices = [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]] }}
material = "white"

[[objects]]
shape = {{ type = "polygon", vertices = [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]] }}
material = "light"
{extra}
"#
    )
}

fn render_scene_text(text: &str, radiosity: RadiositySettings) -> Result<Film, String> {
    let desc = scenes::load_toml(text).map_err(|e| e.to_string())?;
    let mut settings = radiosity_settings(8, 1, radiosity);
    settings.radiosity = radiosity;
    let mut r = renderer(desc, config(settings, IntegratorKind::Recursive));
    r.render()
        .map(|f| f.film.unwrap())
        .map_err(|e| e.to_string())
}

#[test]
fn what_the_solution_cannot_hold_is_refused_with_a_message() {
    let ok = render_scene_text(&lit_room(""), RadiositySettings::default()).unwrap();
    assert!(ok.pixels.iter().any(|p| p.max_element() > 0.0));
    let sphere = lit_room(
        "[[objects]]\nshape = { type = \"sphere\", radius = 0.3 }\nmaterial = \"white\"\n",
    );
    let e = render_scene_text(&sphere, RadiositySettings::default()).unwrap_err();
    assert!(
        e.contains("polygons and meshes") && e.contains("sphere"),
        "{e}"
    );
    let light = lit_room("[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = 1.0\n");
    let e = render_scene_text(&light, RadiositySettings::default()).unwrap_err();
    assert!(e.contains("punctual light"), "{e}");
    for bad in [0.0, f32::NAN, -1.0, f32::INFINITY] {
        let e = render_scene_text(
            &lit_room(""),
            RadiositySettings {
                patch_size: Some(bad),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.contains("patch size"), "{bad}: {e}");
    }
    let e = render_scene_text(
        &lit_room(""),
        RadiositySettings {
            patch_size: Some(1e-4),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(e.contains("more than") && e.contains("patches"), "{e}");
}

#[test]
fn the_command_line_refuses_a_zero_patch_size() {
    for bad in ["0", "nan", "-2"] {
        let out = prism()
            .args([
                "render",
                "--transport",
                "radiosity",
                "--patch-size",
                bad,
                "-q",
                "-o",
            ])
            .arg(std::env::temp_dir().join("prism-radiosity-never-written.png"))
            .arg(assets().join("cornell.toml"))
            .output()
            .unwrap();
        let err = assert_failed_without_panic(&out);
        assert!(
            err.contains("error") && err.contains("patch size"),
            "{bad}: {err}"
        );
    }
    // The same options in a scene file's [settings.radiosity].
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("never.png");
    for (table, words) in [
        ("patch_size = 0.0", &["patch size"][..]),
        ("tolerance = nan", &["tolerance", "NaN"][..]),
        ("hemicube_resolution = 3", &["hemicube resolution"][..]),
        ("solver = \"jacobi\"", &["jacobi"][..]),
    ] {
        let scene = dir.path().join("bad.toml");
        std::fs::write(
            &scene,
            format!("{}\n[settings.radiosity]\n{table}\n", lit_room("")),
        )
        .unwrap();
        let out = prism()
            .args(["render", "-q", "-o"])
            .arg(&png)
            .arg(&scene)
            .output()
            .unwrap();
        let err = assert_failed_without_panic(&out);
        for w in words {
            assert!(err.contains(w), "{table}: {err}");
        }
        assert!(!png.exists(), "{table}: an image was written");
    }
}

/// `prism render --transport radiosity` on the Cornell box: no default
/// light is added (the emissive panel lights it), the stats report the
/// solve's patches, iterations, residual, time and memory, and the image
/// is written.
#[test]
fn the_command_line_reports_the_solve_in_the_stats() {
    let dir = tempfile::tempdir().unwrap();
    let (png, stats) = (dir.path().join("c.png"), dir.path().join("s.json"));
    let out = prism()
        .args(["render", "--transport", "radiosity", "--patch-size", "1.4"])
        .args([
            "--refine-levels",
            "1",
            "--width",
            "16",
            "--height",
            "16",
            "--spp",
            "1",
        ])
        .arg("-o")
        .arg(&png)
        .arg("--stats")
        .arg(&stats)
        .arg(assets().join("cornell.toml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        !err.contains("no light"),
        "a default light was added: {err}"
    );
    assert!(png.exists());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let r = &json["radiosity"];
    assert!(r["patches"].as_u64().unwrap() > 38, "{r}");
    assert!(r["iterations"].as_u64().unwrap() > 0, "{r}");
    assert!(r["residual"].as_f64().unwrap() < 1e-4, "{r}");
    assert_eq!(r["converged"], true, "{r}");
    assert!(r["total_seconds"].as_f64().unwrap() > 0.0, "{r}");
    assert!(r["peak_bytes"].as_u64().unwrap() >= r["form_factor_bytes"].as_u64().unwrap());
    assert!(r["form_factor_bytes"].as_u64().unwrap() > 0, "{r}");
}
