//! Light fields: views synthesised from captured images against the
//! captured images themselves and against direct renders, and bad light
//! fields refused with a reason.

use glam::{DVec3, Vec3};
use prism::core::settings::{LightFieldSettings, RenderSettings};
use prism::image::film::Film;
use prism::io::desc::SceneDesc;
use prism::lightfield::synth::{Outside, SynthOptions, synthesise};
use prism::lightfield::{CaptureInfo, LightField, Manifest, Rig};
use prism::scene::camera::Camera;
use prism::systems::lightfield::capture_light_field;
use prism::systems::{RenderConfig, RenderOrigin, Renderer};

use crate::common::scenes::load_toml;

/// Spheres at several depths in front of a back wall, lit by a point
/// light: parallax between cameras, occlusion edges, smooth shading.
const DEPTH_SCENE: &str = r#"
[settings]
background = [0.1, 0.1, 0.15]
[camera]
look_from = [0, 1, 6]
look_at = [0, 1, 0]
vfov = 40
[[objects]]
shape = { type = "plane" }
material = { color = [0.8, 0.7, 0.6] }
rotate = [90, 0, 0]
translate = [0, 0, -2]
[[objects]]
shape = { type = "sphere", radius = 0.6 }
material = { color = [0.9, 0.2, 0.2] }
translate = [-0.7, 1.2, 0]
[[objects]]
shape = { type = "sphere", radius = 0.4 }
material = { color = [0.2, 0.8, 0.3] }
translate = [0.6, 0.6, 1.5]
[[objects]]
shape = { type = "sphere", radius = 0.5 }
material = { color = [0.3, 0.4, 0.9] }
translate = [0.9, 1.6, -1]
[[lights]]
type = "point"
position = [2, 5, 6]
intensity = 60
"#;

fn settings(w: u32, h: u32) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        spp: 1,
        max_depth: 2,
        ..Default::default()
    }
}

/// Captures `desc` with `rig` in memory.
fn capture(desc: SceneDesc, rig: &Rig) -> LightField {
    let [w, h] = rig.resolution;
    let config = RenderConfig {
        settings: settings(w, h),
        ..Default::default()
    };
    let mut images = Vec::new();
    let report = capture_light_field(desc, config, 0, rig, |_, _, f| {
        images.push(f);
        Ok(())
    })
    .unwrap();
    assert_eq!(
        report.rebuilds, 0,
        "the top level was rebuilt between views"
    );
    LightField::new(Manifest::new(rig.clone(), CaptureInfo::default()), images).unwrap()
}

/// Direct renders of `cameras` at `w` x `h` in the rig's frame (as the
/// capture renders).
fn direct(desc: SceneDesc, rig: &Rig, cameras: &[Camera], w: u32, h: u32) -> Vec<Film> {
    let mut desc = desc;
    desc.cameras = vec![cameras[0].clone()];
    let config = RenderConfig {
        settings: settings(w, h),
        ..Default::default()
    };
    let mut r = Renderer::with_scene(desc, config, 0).unwrap();
    r.insert_resource(RenderOrigin::Fixed(rig.centre));
    let e = r.cameras()[0];
    cameras
        .iter()
        .map(|c| {
            r.world_mut().entity_mut(e).insert(c.clone());
            r.render().unwrap().film.unwrap()
        })
        .collect()
}

fn rig_of(desc: &SceneDesc, grid: u32, spacing: f64, res: [u32; 2]) -> Rig {
    Rig::from_camera(
        &desc.cameras[0],
        &LightFieldSettings {
            grid: Some([grid, grid]),
            spacing: Some(spacing),
            resolution: Some(res),
            focal_distance: None,
        },
    )
    .unwrap()
}

/// Root mean square of the per-channel difference.
fn rmse(a: &Film, b: &Film) -> f64 {
    let s: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| ((*x - *y) * (*x - *y)).element_sum() as f64)
        .sum();
    (s / (3 * a.pixels.len()) as f64).sqrt()
}

/// A view from a grid camera's eye, frame and size reads exactly one
/// sample per pixel with weight one: the synthesised image is the
/// captured image bit for bit, for every camera of a 3x3 grid, with and
/// without a proxy plane (at a camera's own eye every proxy point
/// projects back to the pixel it came from, within the snap distance).
#[test]
fn view_at_a_grid_camera_is_the_captured_image() {
    let desc = load_toml(DEPTH_SCENE).unwrap();
    let rig = rig_of(&desc, 3, 0.4, [40, 30]);
    let lf = capture(desc, &rig);
    for row in 0..3 {
        for column in 0..3 {
            for proxy_depth in [None, Some(4.0)] {
                let s = synthesise(
                    &lf,
                    &rig.camera(column, row),
                    40,
                    30,
                    SynthOptions {
                        proxy_depth,
                        outside: Outside::Error,
                    },
                )
                .unwrap();
                assert_eq!(s.outside, 0);
                let captured = lf.image(column, row);
                let same =
                    s.film.pixels.iter().zip(&captured.pixels).all(|(a, b)| {
                        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
                    });
                assert!(same, "camera {column},{row} proxy {proxy_depth:?} differs");
            }
        }
    }
}

/// Test eyes between grid cameras, as fractions of the half aperture (on
/// no grid of 2, 3 or 5 cameras a side).
const EYES: [(f64, f64); 4] = [(0.31, -0.17), (-0.43, 0.29), (0.13, 0.41), (-0.23, -0.37)];

/// Views between grid cameras against direct renders: the RMSE falls at
/// every step from 2x2 to 3x3 to 5x5 cameras over the same aperture (the
/// ghosting of out-of-focus depths shrinks with the spacing), and at 5x5
/// it is under half that of 2x2. Measured: see the message.
#[test]
fn error_between_grid_cameras_falls_with_density() {
    let desc = load_toml(DEPTH_SCENE).unwrap();
    let aperture = 1.2;
    let res = [40, 40];
    let probe = rig_of(&desc, 2, aperture, res);
    let eyes: Vec<Camera> = EYES
        .iter()
        .map(|&(x, y)| probe.camera_at(x * aperture / 2.0, y * aperture / 2.0))
        .collect();
    let references = direct(desc.clone(), &probe, &eyes, res[0], res[1]);
    let mut errors = Vec::new();
    for n in [2, 3, 5] {
        let rig = rig_of(&desc, n, aperture / (n - 1) as f64, res);
        let lf = capture(desc.clone(), &rig);
        let e: f64 = eyes
            .iter()
            .zip(&references)
            .map(|(eye, r)| {
                let s = synthesise(
                    &lf,
                    eye,
                    res[0],
                    res[1],
                    SynthOptions {
                        proxy_depth: None,
                        outside: Outside::Error,
                    },
                )
                .unwrap();
                rmse(&s.film, r)
            })
            .sum::<f64>()
            / eyes.len() as f64;
        errors.push(e);
    }
    eprintln!("RMSE at 2x2, 3x3, 5x5: {errors:?}");
    assert!(
        errors[0] > errors[1] && errors[1] > errors[2] && errors[2] < 0.5 * errors[0],
        "RMSE did not fall with density: {errors:?}"
    );
}

/// A Lambertian plane lying on the focal plane, lit by a point light:
/// every camera sees a point of it at the same pixel with the same
/// radiance, so a view from anywhere inside the camera plane's hull
/// (corners, edges, inside; framing the window or turned and narrowed) is
/// the bilinear interpolation of one smooth image. The interpolation error
/// of a smooth `f` is at most `h^2 |f''| / 8` for a pixel of size `h`,
/// here far below 1% (the radiance `I cos / r^2` changes by under 1% per
/// pixel at this distance): every pixel is within 1% of the direct render.
#[test]
fn lambertian_plane_on_the_focal_plane_within_one_percent() {
    let text = r#"
[camera]
look_from = [0, 2, 0]
look_at = [0, 0, 0]
up = [0, 0, -1]
vfov = 50
[[objects]]
shape = { type = "plane" }
material = { color = [0.7, 0.6, 0.5] }
[[lights]]
type = "point"
position = [0.4, 1.5, 0.3]
intensity = 8
"#;
    let desc = load_toml(text).unwrap();
    let rig = rig_of(&desc, 3, 0.3, [48, 48]);
    assert!((rig.focal_distance - 2.0).abs() < 1e-12);
    let lf = capture(desc.clone(), &rig);
    let half = 0.3;
    let mut views = Vec::new();
    for (a, b) in [
        (-half, -half),
        (half, half),
        (half, -0.1),
        (0.05, 0.17),
        (-0.29, 0.0),
    ] {
        // Framing the focal window from there.
        views.push(rig.camera_at(a, b));
        // Turned towards a point of the window, with a narrower view.
        let eye = rig.centre + rig.right * a + rig.up * b;
        views.push(Camera {
            look_from: eye,
            look_at: DVec3::new(0.2, 0.0, -0.1),
            up: Vec3::new(0.0, 0.0, -1.0),
            vfov_degrees: 20.0,
            ..Default::default()
        });
    }
    let (w, h) = (32, 32);
    let references = direct(desc, &rig, &views, w, h);
    let mut worst = 0.0f32;
    for (v, r) in views.iter().zip(&references) {
        let s = synthesise(
            &lf,
            v,
            w,
            h,
            SynthOptions {
                proxy_depth: None,
                outside: Outside::Error,
            },
        )
        .unwrap();
        for (a, b) in s.film.pixels.iter().zip(&r.pixels) {
            assert!(b.min_element() > 0.0);
            worst = worst.max(((*a - *b).abs() / *b).max_element());
        }
    }
    eprintln!("largest relative error on the focal plane: {worst:.5}");
    assert!(worst < 0.01, "relative error {worst}");
}

/// Bad light fields and views: a clear error naming the problem, or the
/// documented fallback (black or clamped pixels, counted).
#[test]
fn bad_light_fields_and_views_are_refused() {
    let desc = load_toml(DEPTH_SCENE).unwrap();
    let rig = rig_of(&desc, 2, 0.4, [16, 12]);
    let lf = capture(desc, &rig);
    let manifest = lf.manifest.clone();

    // Images of different sizes.
    let mut images = lf.images.clone();
    images[1] = Film::new(15, 12);
    let e = LightField::new(manifest.clone(), images)
        .unwrap_err()
        .to_string();
    assert!(e.contains("15x12") && e.contains("different sizes"), "{e}");

    // Too few images, a camera listed twice, another version.
    let e = LightField::new(manifest.clone(), lf.images[..3].to_vec())
        .unwrap_err()
        .to_string();
    assert!(e.contains("3 images"), "{e}");
    let mut m = manifest.clone();
    m.images[1] = m.images[0].clone();
    assert!(m.check().unwrap_err().contains("listed twice"));
    let mut m = manifest.clone();
    m.version = 99;
    assert!(m.check().unwrap_err().contains("version 99"));
    let mut m = manifest.clone();
    m.images[0].file = "../escape.exr".into();
    assert!(m.check().unwrap_err().contains("plain file name"));
    let mut m = manifest.clone();
    m.rig.spacing = f64::NAN;
    assert!(m.check().unwrap_err().contains("spacing"));

    // A view looking away from the focal plane sees nothing of it.
    let away = Camera {
        look_from: rig.centre,
        look_at: rig.centre - rig.forward,
        ..Default::default()
    };
    let e = synthesise(&lf, &away, 8, 8, SynthOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("sees nothing"), "{e}");

    // An eye behind the grid with a wide view: rays near the middle cross
    // the camera plane inside the hull, those near the edges outside.
    // Black and counted, clamped and counted, or an error.
    let beside = Camera {
        look_from: rig.centre - rig.forward,
        look_at: rig.centre + rig.forward,
        vfov_degrees: 60.0,
        ..Default::default()
    };
    let black = synthesise(&lf, &beside, 16, 12, SynthOptions::default()).unwrap();
    assert!(black.outside > 0 && black.outside < 16 * 12);
    let clamped = synthesise(
        &lf,
        &beside,
        16,
        12,
        SynthOptions {
            proxy_depth: None,
            outside: Outside::Clamp,
        },
    )
    .unwrap();
    assert_eq!(clamped.outside, black.outside);
    let lit = |f: &Film| f.pixels.iter().filter(|p| p.max_element() > 0.0).count();
    assert!(lit(&clamped.film) > lit(&black.film));
    let e = synthesise(
        &lf,
        &beside,
        16,
        12,
        SynthOptions {
            proxy_depth: None,
            outside: Outside::Error,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("outside the light field's valid region"), "{e}");

    // A proxy plane behind the camera plane.
    let e = synthesise(
        &lf,
        &rig.camera(0, 0),
        16,
        12,
        SynthOptions {
            proxy_depth: Some(-1.0),
            outside: Outside::Black,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("proxy"), "{e}");
}
