//! Environment lighting and the glTF metallic-roughness BRDF, rendered end
//! to end: furnaces in uniform and image environments, a single bright
//! texel seen in a mirror and lighting a diffuse plane, continuity across
//! the map's seam and poles, single-scattering energy of a rough metal,
//! and agreement of the integrators and thread counts.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3, Vec3A};
use prism::core::math::Color;
use prism::core::microfacet::GltfBrdf;
use prism::core::settings::{RenderSettings, Transport};
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::io::desc::{Geometry, ObjectDesc, SceneDesc};
use prism::scene::camera::{Camera, CameraRays};
use prism::scene::environment::{Environment, EnvironmentMap, EnvironmentSource};
use prism::scene::material::Material;

use crate::common::images::{assert_same_image, film_bits};
use crate::common::render::{config, on_one_and_two_threads, render_desc, render_toml};

fn settings(w: u32, h: u32, spp: u32, max_depth: u32, transport: Transport) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        spp,
        max_depth,
        min_contribution: 0.0,
        seed: 3,
        transport,
        ..Default::default()
    }
}

/// Writes a Radiance `.hdr` of `w x h` texels made by `f(column, row)`.
fn write_hdr(dir: &Path, name: &str, w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> PathBuf {
    let img = image::Rgb32FImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    let path = dir.join(name);
    image::DynamicImage::ImageRgb32F(img).save(&path).unwrap();
    path
}

fn mean_and_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Pixels of `film` whose four corners all see the unit-radius sphere at
/// the origin, with the cosine between normal and view at the centre.
fn sphere_pixels(film: &Film, camera: &Camera, radius: f32) -> Vec<(usize, f32)> {
    let rays = CameraRays::new(camera, film.width, film.height);
    let hit = |p: Vec2| {
        let r = rays.ray(p);
        let d = r.direction.normalize();
        let b = r.origin.dot(d);
        let c = r.origin.length_squared() - radius * radius;
        let disc = b * b - c;
        (disc > 0.0).then(|| {
            let t = -b - disc.sqrt();
            let n = (r.origin + d * t).normalize();
            n.dot(-d)
        })
    };
    let mut out = Vec::new();
    for y in 0..film.height {
        for x in 0..film.width {
            let (fx, fy) = (x as f32, y as f32);
            let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)];
            if corners
                .iter()
                .all(|(a, b)| hit(Vec2::new(fx + a, fy + b)).is_some())
            {
                let mu = hit(Vec2::new(fx + 0.5, fy + 0.5)).unwrap();
                out.push(((y * film.width + x) as usize, mu));
            }
        }
    }
    out
}

fn furnace_scene(environment: &str, rho: f32) -> String {
    format!(
        r#"
[camera]
look_from = [0, 0, 4]
look_at = [0, 0, 0]
vfov = 40
[environment]
{environment}
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {{ color = {rho} }}
"#
    )
}

/// A convex Lambertian sphere of albedo `rho` in a constant environment
/// `L` has radiance `rho L` everywhere: for a uniform colour and for a
/// constant image map (whose light samples are drawn from the map's
/// distribution), with both integrators.
#[test]
fn environment_furnace_gives_rho_l() {
    let dir = tempfile::tempdir().unwrap();
    let map = write_hdr(dir.path(), "grey.hdr", 16, 8, |_, _| [0.5, 0.5, 0.5]);
    let (rho, l) = (0.6f64, 1.5f64);
    for env in [
        "color = 1.5".to_string(),
        format!(
            "path = {:?}\nintensity = 3.0\nrotation = 30",
            map.display().to_string()
        ),
    ] {
        let scene = furnace_scene(&env, rho as f32);
        let s = settings(16, 16, 16, 3, Transport::Path);
        let camera = Camera {
            look_from: DVec3::new(0.0, 0.0, 4.0),
            look_at: DVec3::ZERO,
            vfov_degrees: 40.0,
            ..Default::default()
        };
        for kind in IntegratorKind::ALL {
            let film = render_toml(&scene, config(s.clone(), kind)).film.unwrap();
            let object = sphere_pixels(&film, &camera, 1.0);
            assert!(object.len() > 60, "{} sphere pixels", object.len());
            let values: Vec<f64> = object
                .iter()
                .map(|(i, _)| film.pixels[*i].y as f64)
                .collect();
            let (mean, err) = mean_and_error(&values);
            assert!(
                (mean - rho * l).abs() < 5.0 * err + 1e-5,
                "{env} {kind:?}: mean {mean} vs {} (standard error {err})",
                rho * l
            );
            // Every object pixel within noise (16 samples of a bounded
            // estimator): no pixel off by a quarter.
            for v in &values {
                assert!((v - rho * l).abs() < 0.25 * rho * l, "{env}: pixel {v}");
            }
            // The background is the environment itself.
            assert!((film.pixels[0].y as f64 - l).abs() < 1e-5, "{env}");
        }
    }
}

/// One bright texel in a black map: a mirror sphere shows it exactly
/// where the analytically reflected camera ray points into it, and a
/// diffuse plane facing up receives the texel's radiance times its
/// projected solid angle, `L dphi (sin^2 theta1 - sin^2 theta0) / 2`.
#[test]
fn a_bright_texel_in_a_mirror_and_on_a_plane() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (32u32, 16u32);
    // Column 20 (phi from 2 pi (20/32 - 1/2) = 45 to 56.25 degrees),
    // row 4 (theta 45 to 56.25 degrees).
    let (ti, tj, l) = (20u32, 4u32, 64.0f32);
    let map = write_hdr(dir.path(), "texel.hdr", w, h, |x, y| {
        if (x, y) == (ti, tj) { [l; 3] } else { [0.0; 3] }
    });
    let env = format!("path = {:?}", map.display().to_string());

    // The mirror: Whitted transport, pixel centres (1 spp).
    let scene = format!(
        r#"
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
vfov = 30
[environment]
{env}
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {{ diffuse = 0, mirror = 1 }}
"#
    );
    let s = settings(96, 96, 1, 2, Transport::Whitted);
    let film = render_toml(&scene, config(s, IntegratorKind::Recursive))
        .film
        .unwrap();
    let camera = Camera {
        look_from: DVec3::new(0.0, 0.0, 5.0),
        look_at: DVec3::ZERO,
        vfov_degrees: 30.0,
        ..Default::default()
    };
    let rays = CameraRays::new(&camera, 96, 96);
    let (mut bright, mut checked) = (0, 0);
    for y in 0..96u32 {
        for x in 0..96u32 {
            let r = rays.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            let d = r.direction.normalize();
            let b = r.origin.dot(d);
            let disc = b * b - (r.origin.length_squared() - 1.0);
            let seen = if disc > 0.0 {
                let p = r.origin + d * (-b - disc.sqrt());
                let n = p.normalize();
                d - 2.0 * d.dot(n) * n
            } else {
                d
            };
            // The documented convention, written out here: u = 1/2 +
            // atan2(z, x) / 2 pi, v = acos(y) / pi.
            let seen = seen.normalize();
            let uv = Vec2::new(
                0.5 + seen.z.atan2(seen.x) / (2.0 * std::f32::consts::PI),
                seen.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI,
            ) * Vec2::new(w as f32, h as f32);
            // Skip directions within 1e-3 texel of the texel's edges.
            let margin = |c: f32, lo: u32| (c - lo as f32).min(lo as f32 + 1.0 - c);
            let inside = margin(uv.x, ti).min(margin(uv.y, tj));
            if inside.abs() < 1e-3 {
                continue;
            }
            checked += 1;
            let px = film.pixels[(y * 96 + x) as usize];
            let expected = if inside > 0.0 { l } else { 0.0 };
            bright += (inside > 0.0) as u32;
            assert!(
                (px.y - expected).abs() <= 1e-4 * l,
                "pixel ({x}, {y}): {px} where {expected} was expected (uv {uv})"
            );
        }
    }
    assert!(
        bright >= 4 && checked > 9000,
        "{bright} bright of {checked}"
    );

    // The plane: direct light only (depth 0), albedo 1.
    let scene = format!(
        r#"
[camera]
look_from = [0, 3, 0.01]
look_at = [0, 0, 0]
vfov = 40
[environment]
{env}
[[objects]]
shape = {{ type = "plane" }}
material = {{ color = 1 }}
"#
    );
    let (t0, t1) = (tj as f64 * PI / h as f64, (tj + 1) as f64 * PI / h as f64);
    let dphi = 2.0 * PI / w as f64;
    let irradiance = l as f64 * dphi * (t1.sin().powi(2) - t0.sin().powi(2)) / 2.0;
    let expected = irradiance / PI;
    for kind in IntegratorKind::ALL {
        let s = settings(16, 16, 8, 0, Transport::Path);
        let film = render_toml(&scene, config(s, kind)).film.unwrap();
        let values: Vec<f64> = film.pixels.iter().map(|p| p.y as f64).collect();
        let (mean, err) = mean_and_error(&values);
        assert!(
            (mean - expected).abs() < 5.0 * err + 1e-4 * expected,
            "{kind:?}: plane radiance {mean} vs {expected} (standard error {err})"
        );
        assert!(err < 0.02 * expected, "{err}");
    }
}

/// Looking straight at the seam (-X) and at both poles, neighbouring
/// background pixels never differ by more than neighbouring texels of a
/// smooth map do (wrapping included): no seam line, no pole artefact.
#[test]
fn no_discontinuity_at_the_seam_or_the_poles() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (64u32, 32u32);
    // A smooth function of the direction, sampled at texel centres.
    let value = |x: u32, y: u32| {
        let (d, _) = prism::scene::environment::uv_to_direction(Vec2::new(
            (x as f32 + 0.5) / w as f32,
            (y as f32 + 0.5) / h as f32,
        ));
        1.0 + 0.5 * d.x + 0.3 * d.y + 0.2 * d.z
    };
    let map = write_hdr(dir.path(), "smooth.hdr", w, h, |x, y| [value(x, y); 3]);
    // The largest difference between texels that neighbouring pixels can
    // see: neighbours in a row (wrapping), a column and diagonally, and
    // any two texels of the first or last row (pixels near a pole see
    // that row at every longitude).
    let mut step = 0.0f32;
    for y in 0..h {
        for x in 0..w {
            let v = value(x, y);
            step = step.max((v - value((x + 1) % w, y)).abs());
            if y + 1 < h {
                for dx in [w - 1, 0, 1] {
                    step = step.max((v - value((x + dx) % w, y + 1)).abs());
                }
            }
            if y == 0 || y == h - 1 {
                for x2 in 0..w {
                    step = step.max((v - value(x2, y)).abs());
                }
            }
        }
    }
    // RGBE rounding: 2^-8 relative of values up to 2.
    let tolerance = step * 1.001 + 2.0 / 128.0;
    for look_at in [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]] {
        let up = if look_at[1] == 0.0 {
            [0, 1, 0]
        } else {
            [1, 0, 0]
        };
        let scene = format!(
            r#"
[camera]
look_from = [0, 0, 0]
look_at = {look_at:?}
up = {up:?}
vfov = 60
[environment]
path = {:?}
"#,
            map.display().to_string()
        );
        let film = render_toml(
            &scene,
            config(
                settings(48, 48, 1, 1, Transport::Whitted),
                IntegratorKind::Recursive,
            ),
        )
        .film
        .unwrap();
        let px = |x: u32, y: u32| film.pixels[(y * 48 + x) as usize].y;
        for y in 0..48 {
            for x in 0..47 {
                assert!(
                    (px(x, y) - px(x + 1, y)).abs() <= tolerance,
                    "looking at {look_at:?}: pixels ({x}, {y}) and ({}, {y}) jump from {} to {}",
                    x + 1,
                    px(x, y),
                    px(x + 1, y)
                );
                assert!((px(y, x) - px(y, x + 1)).abs() <= tolerance);
            }
        }
    }
}

/// A glTF sphere of `material` at the origin in a uniform environment of
/// radiance 1, seen from (0, 0, 4).
fn gltf_sphere(material: Material, environment: Environment) -> (SceneDesc, Camera) {
    let camera = Camera {
        look_from: DVec3::new(0.0, 0.0, 4.0),
        look_at: DVec3::ZERO,
        vfov_degrees: 35.0,
        ..Default::default()
    };
    let desc = SceneDesc {
        objects: vec![ObjectDesc {
            name: None,
            transform: Transform::default(),
            geometry: Geometry::Shape(Shape::Sphere { radius: 1.0 }),
            material,
        }],
        cameras: vec![camera.clone()],
        environment: Some(environment),
        ..Default::default()
    };
    (desc, camera)
}

/// Directional albedo of a BRDF at `cos_o` by a midpoint rule over
/// `(cos theta, phi)`.
fn albedo(b: &GltfBrdf, cos_o: f32) -> f64 {
    let wo = Vec3A::new((1.0 - cos_o * cos_o).max(0.0).sqrt(), 0.0, cos_o);
    let (nt, np) = (600, 240);
    let mut sum = 0.0;
    for i in 0..nt {
        let c = (i as f64 + 0.5) / nt as f64;
        let s = (1.0 - c * c).sqrt();
        for j in 0..np {
            let phi = PI * (j as f64 + 0.5) / np as f64;
            let wi = Vec3A::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
            sum += b.eval_cos(Vec3A::Z, wo, wi).y as f64;
        }
    }
    // Symmetric in phi: the half turn counted twice.
    2.0 * sum * (1.0 / nt as f64) * (PI / np as f64)
}

/// A rough metal of F0 = 1 in a uniform environment of radiance 1: a
/// convex object never sees itself, so every pixel is the BRDF's
/// single-scattering directional albedo at its viewing angle, integrated
/// numerically here (and below 1: the energy single scattering loses).
/// A rough dielectric with specular 0 and albedo 1 keeps all energy.
#[test]
fn gltf_furnaces() {
    let roughness = 0.6f32;
    let metal =
        Material::from_metallic_roughness(Color::ONE, 1.0, roughness, Color::splat(0.04), 0.0, 1.5);
    let brdf = metal
        .sample(Vec2::ZERO)
        .gltf
        .expect("a metal has a specular layer");
    // Expected albedo by viewing cosine, interpolated from a table.
    let table: Vec<f64> = (0..=40)
        .map(|k| albedo(&brdf, (k as f32 / 40.0).max(1e-3)))
        .collect();
    let e = |mu: f32| {
        let x = (mu.clamp(0.0, 1.0) * 40.0) as f64;
        let k = (x as usize).min(39);
        table[k] + (table[k + 1] - table[k]) * (x - k as f64)
    };
    assert!(table[40] < 0.99 && table[40] > 0.8, "{}", table[40]);
    let (desc, camera) = gltf_sphere(metal, Environment::uniform(Color::ONE));
    let s = settings(24, 24, 32, 2, Transport::Path);
    let film = render_desc(desc, config(s, IntegratorKind::Recursive))
        .film
        .unwrap();
    let pixels = sphere_pixels(&film, &camera, 1.0);
    let diffs: Vec<f64> = pixels
        .iter()
        .map(|(i, mu)| film.pixels[*i].y as f64 - e(*mu))
        .collect();
    let (mean, err) = mean_and_error(&diffs);
    assert!(
        mean.abs() < 5.0 * err + 2e-3,
        "rendered minus integrated albedo: {mean} (standard error {err})"
    );
    // Near normal view, where the albedo varies slowly within a pixel.
    let centre: Vec<f64> = pixels
        .iter()
        .filter(|(_, mu)| *mu > 0.9)
        .map(|(i, mu)| film.pixels[*i].y as f64 - e(*mu))
        .collect();
    let (m, err) = mean_and_error(&centre);
    assert!(m.abs() < 5.0 * err + 2e-3, "centre: {m} +- {err}");

    let mut plastic =
        Material::from_metallic_roughness(Color::ONE, 0.0, 0.7, Color::ZERO, 0.0, 1.5);
    if let Some(mr) = plastic.metallic_roughness.as_mut() {
        mr.specular_factor = 0.0;
    }
    assert!(plastic.sample(Vec2::ZERO).gltf.is_none());
    let (desc, camera) = gltf_sphere(plastic, Environment::uniform(Color::splat(2.0)));
    let s = settings(16, 16, 16, 4, Transport::Path);
    for kind in IntegratorKind::ALL {
        let film = render_desc(desc.clone(), config(s.clone(), kind))
            .film
            .unwrap();
        let values: Vec<f64> = sphere_pixels(&film, &camera, 1.0)
            .iter()
            .map(|(i, _)| film.pixels[*i].y as f64)
            .collect();
        let (mean, err) = mean_and_error(&values);
        assert!(
            (mean - 2.0).abs() < 5.0 * err + 1e-5,
            "{kind:?}: {mean} +- {err}"
        );
    }
}

/// With an image environment and glTF metal, plastic and Lambertian
/// spheres and an area light, both integrators give the same image, each
/// bit-identical on one and two threads.
#[test]
fn integrators_and_thread_counts_agree_with_an_environment() {
    let texels: Vec<Color> = (0..16 * 8)
        .map(|k| Color::new(0.2 + (k % 7) as f32, 0.5, 0.1 + (k % 3) as f32))
        .collect();
    let map = Arc::new(EnvironmentMap::new(16, 8, texels).unwrap());
    let env = Environment::new(EnvironmentSource::Map(map), 0.5, 1.0);
    let sphere = |x: f32, material: Material| ObjectDesc {
        name: None,
        transform: Transform::from_trs_f32(
            Vec3::new(x, 0.0, 0.0),
            glam::Quat::IDENTITY,
            Vec3::splat(0.5),
        ),
        geometry: Geometry::Shape(Shape::Sphere { radius: 1.0 }),
        material,
    };
    let mr = |m: f32, r: f32| {
        Material::from_metallic_roughness(
            Color::new(0.9, 0.6, 0.3),
            m,
            r,
            Color::splat(0.04),
            0.0,
            1.5,
        )
    };
    let camera = Camera {
        look_from: DVec3::new(0.0, 1.0, 4.0),
        look_at: DVec3::ZERO,
        vfov_degrees: 40.0,
        ..Default::default()
    };
    let desc = SceneDesc {
        objects: vec![
            sphere(-1.1, mr(1.0, 0.3)),
            sphere(0.0, mr(0.0, 0.5)),
            sphere(
                1.1,
                Material {
                    emission: Color::splat(2.0),
                    ..Default::default()
                },
            ),
        ],
        cameras: vec![camera],
        environment: Some(env),
        ..Default::default()
    };
    let s = RenderSettings {
        light_samples: 2,
        ..settings(24, 18, 4, 4, Transport::Path)
    };
    let films = on_one_and_two_threads(|kind| {
        render_desc(desc.clone(), config(s.clone(), kind))
            .film
            .unwrap()
    });
    let reference = &films[0].2;
    assert!(reference.pixels.iter().all(|p| p.is_finite()));
    for (threads, kind, film) in &films {
        assert_same_image(film, reference, &format!("{kind:?} on {threads} threads"));
    }
    assert_eq!(film_bits(&films[0].2), film_bits(&films[2].2), "recursive");
    assert_eq!(film_bits(&films[1].2), film_bits(&films[3].2), "wavefront");
}
