//! Path transport against analytic answers: the white furnace, irradiance
//! from disk, sphere and square area lights, lossless specular objects in
//! a uniform environment, and agreement with the Whitted tracer and
//! between the two integrators.

use std::path::Path;

use glam::{Vec2, Vec3, Vec3A};
use prism::core::rng::SamplerKind;
use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::camera::{Camera, CameraRays};

use crate::common::images::assert_same_image;
use crate::common::render::{config, on_one_and_two_threads, render_toml};
use crate::common::{assets, render};

/// Renders scene text (TOML) with `settings`; returns the film.
fn render_text(toml: &str, settings: &RenderSettings, kind: IntegratorKind) -> Film {
    render_toml(toml, config(settings.clone(), kind))
        .film
        .unwrap()
}

fn render_file(path: &Path, settings: &RenderSettings, kind: IntegratorKind) -> Film {
    render::render_file(path, config(settings.clone(), kind))
        .film
        .unwrap()
}

fn path_settings(size: u32, spp: u32, max_depth: u32) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        spp,
        max_depth,
        min_contribution: 0.0,
        seed: 17,
        transport: Transport::Path,
        ..Default::default()
    }
}

/// Mean and standard error of the mean of the per-pixel values of one
/// channel (pixels are independent estimates: their keys differ).
fn mean_and_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn green(film: &Film) -> Vec<f64> {
    film.pixels.iter().map(|p| p.y as f64).collect()
}

/// A closed sphere of albedo `albedo` emitting `le` everywhere, seen from
/// inside.
fn furnace(albedo: f64, le: f64) -> String {
    format!(
        r#"
[camera]
look_from = [0.1, 0.2, 0.3]
look_at = [1, 0.5, 0]
vfov = 90
[[objects]]
shape = {{ type = "sphere", radius = 2.0 }}
material = {{ color = {albedo}, emission = {le} }}
"#
    )
}

/// Inside a closed sphere of albedo `a` emitting `Le` everywhere, radiance
/// is `Le (1 + a + a^2 + ...) = Le / (1 - a)` in every direction.
#[test]
fn white_furnace_gives_le_over_one_minus_albedo_with_both_integrators() {
    for (albedo, le) in [(0.5f64, 1.0f64), (0.8, 0.25)] {
        let scene = furnace(albedo, le);
        let expected = le / (1.0 - albedo);
        // Russian roulette from bounce 5 (the default), by the classic rule
        // (weight 1) and by the default weight: unbiased either way.
        for (kind, rr_weight) in IntegratorKind::ALL
            .into_iter()
            .flat_map(|k| [(k, 1.0), (k, prism::core::settings::DEFAULT_RR_WEIGHT)])
        {
            // a^(depth+1) must be negligible against the tolerance: 0.8^121 < 1e-11.
            let settings = RenderSettings {
                rr_weight,
                ..path_settings(16, 16, 120)
            };
            let film = render_text(&scene, &settings, kind);
            assert!(film.pixels.iter().all(|p| p.is_finite()));
            let (mean, err) = mean_and_error(&green(&film));
            assert!(
                (mean - expected).abs() < 5.0 * err + 1e-6,
                "{kind:?} albedo {albedo} rr weight {rr_weight}: mean {mean} vs {expected} (standard error {err})"
            );
            // The estimate must be a real one, not a lucky constant.
            assert!(err > 0.0 && err < 0.02 * expected, "standard error {err}");
        }
    }
}

/// Radiance of a Lambertian floor of albedo `rho` lit by a light whose
/// irradiance at floor point `p` is `irradiance(p)`: `rho / pi * E`.
/// Compares the image with it, each pixel averaged over a 4x4 grid of its
/// footprint (the film jitters uniformly over the pixel).
fn assert_floor_matches(
    film: &Film,
    camera: &Camera,
    rho: f64,
    irradiance: impl Fn(Vec3A) -> f64,
    what: &str,
) {
    let rays = CameraRays::new(camera, film.width, film.height);
    let mut diffs = Vec::new();
    let mut expected_sum = 0.0;
    for y in 0..film.height {
        for x in 0..film.width {
            let mut e = 0.0;
            for k in 0..16 {
                let p = Vec2::new(
                    x as f32 + (k % 4) as f32 / 4.0 + 0.125,
                    y as f32 + (k / 4) as f32 / 4.0 + 0.125,
                );
                let ray = rays.ray(p);
                let t = -ray.origin.y / ray.direction.y;
                e += rho / std::f64::consts::PI * irradiance(ray.at(t)) / 16.0;
            }
            expected_sum += e;
            let px = film.pixels[(y * film.width + x) as usize];
            diffs.push(px.y as f64 - e);
        }
    }
    let (bias, err) = mean_and_error(&diffs);
    let mean_expected = expected_sum / diffs.len() as f64;
    assert!(
        bias.abs() < 5.0 * err + 2e-3 * mean_expected,
        "{what}: mean error {bias} (standard error {err}) on a mean radiance of {mean_expected}"
    );
}

fn floor_scene(light: &str) -> (String, Camera) {
    let camera = Camera {
        look_from: glam::DVec3::new(0.0, 1.0, 0.0),
        look_at: glam::DVec3::ZERO,
        up: Vec3::Z,
        vfov_degrees: 60.0,
        shift: glam::Vec2::ZERO,
        name: None,
        ..Default::default()
    };
    let scene = format!(
        r#"
[camera]
look_from = [0, 1, 0]
look_at = [0, 0, 0]
up = [0, 0, 1]
vfov = 60
[[objects]]
shape = {{ type = "plane" }}
material = {{ color = 0.5 }}
{light}
"#
    );
    (scene, camera)
}

/// Direct light from three kinds of area light, by next-event estimation
/// alone (depth 0) and with MIS against BSDF rays (depth 1: the lights
/// reflect nothing, so both give direct light only), with one and four
/// light samples.
#[test]
fn area_lights_give_the_analytic_irradiance() {
    let le = 3.0f64;
    // A disk of radius 1 at height 2, seen from the floor.
    let (h, r) = (2.0f64, 1.0f64);
    let disk = format!(
        r#"[[objects]]
shape = {{ type = "disk", radius = {r} }}
translate = [0.3, {h}, -0.2]
material = {{ color = 0.0, diffuse = 0.0, emission = {le} }}"#
    );
    let disk_e = move |p: Vec3A| {
        let d2 = ((p.x as f64 - 0.3).powi(2) + (p.z as f64 + 0.2).powi(2)).max(0.0);
        let (h2, r2) = (h * h, r * r);
        std::f64::consts::PI * le / 2.0
            * (1.0 - (h2 + d2 - r2) / ((h2 + d2 + r2).powi(2) - 4.0 * r2 * d2).sqrt())
    };
    // A sphere of radius 0.5 centred at height 2, stretched by a uniform
    // scale of 1.2 (radius 0.6), above the camera and wholly above every
    // floor point's horizon: E = pi Le (R/D)^2 cos(theta).
    let sphere = format!(
        r#"[[objects]]
shape = {{ type = "sphere", radius = 0.5 }}
translate = [-0.2, 2.0, 0.1]
scale = 1.2
material = {{ color = 0.0, diffuse = 0.0, emission = {le} }}"#
    );
    let sphere_e = move |p: Vec3A| {
        let c = Vec3A::new(-0.2, 2.0, 0.1);
        let to = c - p;
        let d2 = to.length_squared() as f64;
        let cos = (to.y / to.length()) as f64;
        std::f64::consts::PI * le * 0.36 / d2 * cos
    };
    // A 1x1 square at height 1.5 facing down: irradiance by quadrature.
    let square = format!(
        r#"[[objects]]
shape = {{ type = "polygon", vertices = [[-0.5, 1.5, -0.5], [-0.5, 1.5, 0.5], [0.5, 1.5, 0.5], [0.5, 1.5, -0.5]] }}
material = {{ color = 0.0, diffuse = 0.0, emission = {le} }}"#
    );
    let square_e = move |p: Vec3A| {
        let n = 60;
        let cell = 1.0 / n as f64;
        let mut e = 0.0;
        for i in 0..n {
            for j in 0..n {
                let q = Vec3::new(
                    (-0.5 + (i as f64 + 0.5) * cell) as f32,
                    1.5,
                    (-0.5 + (j as f64 + 0.5) * cell) as f32,
                );
                let d = q - Vec3::from(p);
                let r2 = d.length_squared() as f64;
                let cos = d.y as f64 / r2.sqrt();
                e += le * cos * cos / r2 * cell * cell;
            }
        }
        e
    };
    type Irradiance = Box<dyn Fn(Vec3A) -> f64>;
    let lights: [(&str, String, Irradiance); 3] = [
        ("disk", disk, Box::new(disk_e)),
        ("sphere", sphere, Box::new(sphere_e)),
        ("square", square, Box::new(square_e)),
    ];
    for (name, light, irradiance) in &lights {
        let (scene, camera) = floor_scene(light);
        for (depth, light_samples) in [(0, 1), (1, 1), (1, 4)] {
            let settings = RenderSettings {
                light_samples,
                ..path_settings(12, 16, depth)
            };
            let film = render_text(&scene, &settings, IntegratorKind::Recursive);
            assert_floor_matches(
                &film,
                &camera,
                0.5,
                irradiance,
                &format!("{name} light, depth {depth}, {light_samples} light samples"),
            );
        }
    }
}

/// At equal spp the Sobol sampler's error is lower than the hash
/// sampler's: a floor lit by a disk light and shadowed by a sphere (soft
/// shadows; next-event estimation and BSDF rays weighted by MIS, one
/// bounce), 16 spp against a 4096-spp reference rendered with the hash
/// sampler and another seed (so that neither estimate shares numbers with
/// it). The reference's own variance adds the same amount to both errors.
#[test]
fn sobol_sampler_has_lower_error_than_the_hash_sampler_at_equal_spp() {
    let (scene, _) = floor_scene(
        r#"[[objects]]
shape = { type = "disk", radius = 0.6 }
translate = [0.3, 1.6, -0.2]
material = { color = 0.0, diffuse = 0.0, emission = 4.0 }
[[objects]]
shape = { type = "sphere", radius = 0.15 }
translate = [0.1, 0.45, 0.0]
material = { color = 0.5 }"#,
    );
    let settings = |spp: u32, sampler: SamplerKind, seed: u64| RenderSettings {
        sampler,
        seed,
        ..path_settings(12, spp, 1)
    };
    let reference = render_text(
        &scene,
        &settings(4096, SamplerKind::Hash, 99),
        IntegratorKind::Recursive,
    );
    let mse = |f: &Film| {
        f.pixels
            .iter()
            .zip(&reference.pixels)
            .map(|(p, q)| ((p.y - q.y) as f64).powi(2))
            .sum::<f64>()
            / f.pixels.len() as f64
    };
    let sobol = mse(&render_text(
        &scene,
        &settings(16, SamplerKind::Sobol, 1),
        IntegratorKind::Recursive,
    ));
    let hash = mse(&render_text(
        &scene,
        &settings(16, SamplerKind::Hash, 1),
        IntegratorKind::Recursive,
    ));
    eprintln!(
        "16 spp: MSE sobol {sobol:.3e}, hash {hash:.3e}, ratio {:.3}",
        sobol / hash
    );
    assert!(
        hash > 0.0 && sobol < 0.7 * hash,
        "sobol {sobol} vs hash {hash}"
    );
}

/// A lossless mirror or glass sphere in a uniform environment is invisible
/// under path transport: every path escapes with weight 1 (Fresnel picks
/// reflection or refraction, each carrying the whole weight).
#[test]
fn lossless_specular_objects_vanish_in_a_uniform_environment() {
    for material in [
        "{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }",
        "{ color = 0.0, diffuse = 0.0, mirror = 1.0 }",
    ] {
        let scene = format!(
            r#"
[settings]
background = [0.7, 0.7, 0.7]
[camera]
look_from = [0, 0, 4]
look_at = [0, 0, 0]
vfov = 35
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {material}
"#
        );
        let settings = RenderSettings {
            rr_start_depth: None,
            ..path_settings(16, 4, 64)
        };
        for kind in IntegratorKind::ALL {
            let film = render_text(&scene, &settings, kind);
            // A path trapped by total internal reflection beyond depth 64
            // would come back black; none may come back anything else.
            let mut dark = 0;
            for p in &film.pixels {
                for c in p.to_array() {
                    if c == 0.0 {
                        dark += 1;
                    } else {
                        assert!((c - 0.7).abs() < 1e-5, "{material} {kind:?}: {p}");
                    }
                }
            }
            assert!(dark == 0, "{material} {kind:?}: {dark} black channels");
        }
    }
}

/// With no bounce (`max_depth` 0) the path tracer is direct lighting from
/// the same shading kernels as the Whitted tracer: on scenes lit only by
/// point, spot and directional lights the images are identical.
#[test]
fn single_bounce_path_tracing_is_the_whitted_image() {
    // (The showroom has emissive surfaces: path transport lights with them.)
    for scene in ["whitted.toml", "quadrics.toml"] {
        let path = assets().join(scene);
        let whitted = RenderSettings {
            width: 48,
            height: 36,
            spp: 2,
            max_depth: 0,
            seed: 3,
            ..Default::default()
        };
        let path_traced = RenderSettings {
            transport: Transport::Path,
            ..whitted.clone()
        };
        for kind in IntegratorKind::ALL {
            let a = render_file(&path, &whitted, kind);
            let b = render_file(&path, &path_traced, kind);
            let differ = a.pixels.iter().zip(&b.pixels).position(|(p, q)| p != q);
            assert_eq!(differ, None, "{scene} {kind:?}: first differing pixel");
            assert!(a.pixels.iter().any(|p| p.max_element() > 0.0));
        }
    }
}

/// Both integrators draw the same numbers for the same path and so give
/// the same path-traced image; each is bit-identical whatever the thread
/// count; for both samplers (and the two samplers give different images).
#[test]
fn path_traced_images_agree_between_integrators_and_thread_counts() {
    let mut per_sampler = Vec::new();
    for (scene, sampler) in [
        ("cornell.toml", SamplerKind::Sobol),
        ("whitted.toml", SamplerKind::Sobol),
        ("cornell.toml", SamplerKind::Hash),
        ("whitted.toml", SamplerKind::Hash),
    ] {
        let path = assets().join(scene);
        let settings = RenderSettings {
            light_samples: 2,
            sampler,
            ..path_settings(24, 4, 6)
        };
        let mut films = on_one_and_two_threads(|kind| render_file(&path, &settings, kind));
        let (_, _, reference) = &films[0];
        assert!(reference.pixels.iter().any(|p| p.max_element() > 0.0));
        for (threads, kind, film) in &films {
            assert_same_image(
                film,
                reference,
                &format!("{scene}, {kind:?} on {threads} threads"),
            );
        }
        // Same integrator, other thread count: bit for bit.
        assert!(films[0].2.pixels == films[2].2.pixels, "{scene} recursive");
        assert!(films[1].2.pixels == films[3].2.pixels, "{scene} wavefront");
        per_sampler.push(films.swap_remove(0).2);
    }
    assert!(
        per_sampler[0].pixels != per_sampler[2].pixels,
        "the sampler is used"
    );
    assert!(
        per_sampler[1].pixels != per_sampler[3].pixels,
        "the sampler is used"
    );
}

/// Split paths (`RenderSettings::split`): each of the `k` parts
/// continued from a camera ray's first hit counts `1 / k`, so the white
/// furnace still gives `Le / (1 - a)` with both integrators; the image is
/// the same bit for bit with both integrators on one and two threads, for
/// both samplers; and it differs from the unsplit one.
#[test]
fn split_paths_keep_the_white_furnace_and_agree_between_integrators() {
    let (albedo, le) = (0.8f64, 0.25f64);
    let scene = furnace(albedo, le);
    let expected = le / (1.0 - albedo);
    for (split, kind) in [2, 3]
        .into_iter()
        .flat_map(|s| IntegratorKind::ALL.map(|k| (s, k)))
    {
        let settings = RenderSettings {
            split,
            ..path_settings(16, 8, 120)
        };
        let film = render_text(&scene, &settings, kind);
        let (mean, err) = mean_and_error(&green(&film));
        assert!(
            (mean - expected).abs() < 5.0 * err + 1e-6,
            "{kind:?} split {split}: mean {mean} vs {expected} (standard error {err})"
        );
        assert!(err > 0.0 && err < 0.02 * expected, "standard error {err}");
    }
    for (scene, sampler) in [
        ("cornell.toml", SamplerKind::Sobol),
        ("cornell.toml", SamplerKind::Hash),
        ("fog.toml", SamplerKind::Sobol),
    ] {
        let path = assets().join(scene);
        let settings = RenderSettings {
            split: 2,
            sampler,
            ..path_settings(24, 4, 6)
        };
        let films = on_one_and_two_threads(|kind| render_file(&path, &settings, kind));
        let (_, _, reference) = &films[0];
        assert!(reference.pixels.iter().any(|p| p.max_element() > 0.0));
        for (threads, kind, film) in &films {
            assert!(
                film.pixels == reference.pixels,
                "{scene} {sampler:?}: split paths, {kind:?} on {threads} threads"
            );
        }
        let unsplit = RenderSettings {
            split: 1,
            ..settings
        };
        let plain = render_file(&path, &unsplit, IntegratorKind::Recursive);
        assert!(
            plain.pixels != reference.pixels,
            "{scene} {sampler:?}: the split is used"
        );
    }
}
