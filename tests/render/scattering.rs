//! Scattering media under path transport: a furnace test, Chandrasekhar's
//! semi-infinite slab, and determinism across threads and integrators.
//!
//! Every test renders with both integrators where it says so; statistical
//! tolerances come from the standard error estimated from the pixels
//! themselves (all pixels of these scenes have the same expectation, so
//! their spread is the per-pixel noise).

use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::integrators::wavefront::Stage;

use crate::common::images::film_bits;
use crate::common::render::{config, render_toml};

/// Mean and standard error of the mean of every channel of every pixel
/// of `film` (the pixels being independent estimates of one value).
fn mean_and_error(film: &Film) -> (f64, f64) {
    let v: Vec<f64> = film
        .pixels
        .iter()
        .flat_map(|p| [p.x as f64, p.y as f64, p.z as f64])
        .collect();
    // The three channels of a pixel are one estimate (grey scenes): use
    // one value per pixel for the error.
    let per_pixel: Vec<f64> = v.chunks(3).map(|c| c.iter().sum::<f64>() / 3.0).collect();
    let n = per_pixel.len() as f64;
    let mean = per_pixel.iter().sum::<f64>() / n;
    let var = per_pixel.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn path_settings(width: u32, height: u32, spp: u32, max_depth: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp,
        max_depth,
        transport: Transport::Path,
        ..Default::default()
    }
}

/// An index-matched sphere (radius 1) that only scatters, with
/// Henyey-Greenstein asymmetry `g`, in a uniform white environment,
/// filling the view.
fn furnace(g: f32) -> String {
    format!(
        r#"
[camera]
look_from = [0, 0, 3]
look_at = [0, 0, 0]
vfov = 30
[environment]
color = 1.0
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, scattering = 2.0, g = {g} }}
"#
    )
}

/// Furnace: a purely scattering, index-matched sphere (albedo 1) in a
/// white environment of radiance 1 renders 1 on every pixel, for
/// backward, isotropic and forward scattering, in both integrators: the
/// mean over the image within 4 standard errors of 1, and every pixel
/// within 5 of its own standard deviations (the pixels' spread).
#[test]
fn a_scattering_sphere_in_a_white_furnace_disappears() {
    for g in [-0.5f32, 0.0, 0.8] {
        for kind in IntegratorKind::ALL {
            let film = render_toml(&furnace(g), config(path_settings(12, 12, 16, 256), kind))
                .film
                .unwrap();
            let (mean, se) = mean_and_error(&film);
            let sd = se * (film.pixels.len() as f64).sqrt();
            assert!(sd > 0.0, "g {g} {kind:?}: no noise at all?");
            assert!(
                (mean - 1.0).abs() < 4.0 * se,
                "g {g} {kind:?}: mean {mean}, standard error {se}"
            );
            for (i, p) in film.pixels.iter().enumerate() {
                let err = (*p - glam::Vec3::ONE).abs().max_element() as f64;
                assert!(err < 5.0 * sd, "g {g} {kind:?}: pixel {i} is {p} (sd {sd})");
            }
        }
    }
}

/// A sphere of radius 1000 (the semi-infinite slab: 1000 mean free
/// paths deep, flat to 0.05 mean free paths within 10 of the axis) of an
/// isotropic medium with extinction 1 and single-scattering albedo
/// `omega`, index-matched, under a uniform white sky, seen straight down
/// by an orthographic camera.
fn chandrasekhar(omega: f32) -> String {
    subsurface_slab(&format!(
        "{{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, scattering = {omega}, absorption = {} }}",
        1.0 - omega
    ))
}

/// Chandrasekhar's H-function results for a semi-infinite isotropic
/// medium under uniform illumination of radiance 1, seen along the
/// normal: the reflected radiance is `1 - H(1) sqrt(1 - omega)`, which is
/// 0.285255, 0.414947 and 0.752721 for omega 0.8, 0.9 and 0.99. Both
/// integrators within 1%; the test first checks that its standard error
/// is below a third of that, so that 1% is a 3-sigma band at least.
#[test]
fn a_semi_infinite_slab_reflects_chandrasekhars_radiance() {
    for (omega, expected) in [(0.8f32, 0.285255f64), (0.9, 0.414947), (0.99, 0.752721)] {
        for kind in IntegratorKind::ALL {
            let film = render_toml(
                &chandrasekhar(omega),
                config(path_settings(32, 32, 64, 1024), kind),
            )
            .film
            .unwrap();
            let (mean, se) = mean_and_error(&film);
            let tol = 0.01 * expected;
            assert!(
                se < tol / 3.0,
                "omega {omega} {kind:?}: standard error {se} too large for a 1% test"
            );
            assert!(
                (mean - expected).abs() < tol,
                "omega {omega} {kind:?}: {mean} (se {se}) vs {expected}"
            );
        }
    }
}

/// A small foggy room: fog everywhere, a spot light and a point light in
/// it, a scattering ball behind an index-matched boundary, a subsurface
/// ball, a glass ball, an emissive panel and a floor.
const FOGGY: &str = r#"
[camera]
look_from = [0, 1.5, 6]
look_at = [0, 0.8, 0]
vfov = 45
[medium]
scattering = 0.08
absorption = 0.02
g = 0.3
[[objects]]
shape = { type = "plane" }
material = { color = 0.6 }
[[objects]]
shape = { type = "sphere", radius = 0.7 }
translate = [-1, 0.7, 0]
material = { color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, scattering = [3, 4, 5], absorption = 0.2, g = -0.2 }
[[objects]]
shape = { type = "sphere", radius = 0.5 }
translate = [1.1, 0.5, 0.5]
material = { color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }
[[objects]]
shape = { type = "sphere", radius = 0.4 }
translate = [0.1, 0.45, 1.3]
material = { subsurface_color = [0.7, 0.5, 0.4], subsurface_radius = [0.1, 0.05, 0.03] }
[[objects]]
shape = { type = "polygon", vertices = [[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]] }
material = { color = 0.0, emission = 4 }
[[lights]]
type = "spot"
position = [2, 3, 1]
direction = [-2, -3, -1]
intensity = 20
inner_angle = 10
outer_angle = 20
[[lights]]
type = "point"
position = [-2, 2, 2]
intensity = 5
"#;

fn foggy(kind: IntegratorKind, threads: usize) -> Film {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        render_toml(FOGGY, config(path_settings(24, 18, 4, 12), kind))
            .film
            .unwrap()
    })
}

/// The recursive (`rec`) and wavefront (`wav`) images of one scene agree
/// to 1e-4 in every pixel (relative to the pixel, absolute below 1).
fn assert_integrators_agree(rec: &Film, wav: &Film) {
    for (i, (a, b)) in rec.pixels.iter().zip(&wav.pixels).enumerate() {
        let d = (*a - *b).abs().max_element();
        assert!(
            d <= 1e-4 * a.abs().max_element().max(1.0),
            "pixel {i}: recursive {a} wavefront {b}"
        );
    }
}

/// Media images are bit-identical on 1 and 2 threads in each integrator,
/// and the integrators agree to 1e-4 (relative to the pixel, absolute
/// below 1).
#[test]
fn media_images_are_bit_identical_across_threads_and_integrators_agree() {
    let rec = foggy(IntegratorKind::Recursive, 1);
    let wav = foggy(IntegratorKind::Wavefront, 1);
    assert_eq!(
        film_bits(&rec),
        film_bits(&foggy(IntegratorKind::Recursive, 2))
    );
    assert_eq!(
        film_bits(&wav),
        film_bits(&foggy(IntegratorKind::Wavefront, 2))
    );
    assert_integrators_agree(&rec, &wav);
    assert!(rec.pixels.iter().all(|a| a.is_finite()));
    // The fog is lit: no pixel is black (every camera ray scatters light
    // of the lights back before it reaches anything).
    assert!(rec.pixels.iter().all(|p| p.max_element() > 0.0));
}

/// Per-channel mean and standard error of the mean over the pixels.
fn channel_stats(film: &Film) -> [(f64, f64); 3] {
    let n = film.pixels.len() as f64;
    std::array::from_fn(|c| {
        let v: Vec<f64> = film.pixels.iter().map(|p| p[c] as f64).collect();
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, (var / n).sqrt())
    })
}

/// The Chandrasekhar rig (an index-matched sphere of radius 1000 seen
/// straight down under a white sky) with the subsurface material `material`.
fn subsurface_slab(material: &str) -> String {
    slab_seen_at(0.0, material)
}

/// A sphere of radius 1000 (a semi-infinite slab for mean free paths of
/// order 1) of `material` under a uniform white sky, seen by an
/// orthographic camera whose axis makes the angle `degrees` with the
/// normal at the top of the sphere (the view's footprint, 1 unit across
/// the view, stays within 2.9 units of the top, where the sphere is flat
/// to 0.004).
fn slab_seen_at(degrees: f32, material: &str) -> String {
    let (s, c) = degrees.to_radians().sin_cos();
    format!(
        r#"
[camera]
look_from = [0, {}, {}]
look_at = [0, 1000, 0]
up = [0, 0, -1]
ortho_half_height = 0.5
[environment]
color = 1.0
[[objects]]
shape = {{ type = "sphere", radius = 1000.0 }}
material = {material}
"#,
        1000.0 + 5.0 * c,
        5.0 * s
    )
}

/// Subsurface scattering: a large slab of the material reflects its
/// `subsurface_color` as its diffuse albedo, so under a uniform white sky
/// of radiance 1 its radiance is that colour in every direction (as a
/// Lambertian surface's is): seen at 0, 60 and 80 degrees from the normal,
/// every channel within 2% (after checking that the standard error is
/// below a third of that), in both integrators. Chromatic mean free
/// paths, so that paths are narrowed to one channel.
#[test]
fn a_large_subsurface_slab_reflects_its_colour_in_every_direction() {
    let colour = [0.8f64, 0.5, 0.2];
    for degrees in [0.0f32, 60.0, 80.0] {
        let scene = slab_seen_at(
            degrees,
            "{ subsurface_color = [0.8, 0.5, 0.2], subsurface_radius = [1.0, 0.5, 0.25] }",
        );
        for kind in IntegratorKind::ALL {
            let film = render_toml(&scene, config(path_settings(40, 40, 80, 1024), kind))
                .film
                .unwrap();
            for (c, (mean, se)) in channel_stats(&film).into_iter().enumerate() {
                let tol = 0.02 * colour[c];
                assert!(
                    se < tol / 3.0,
                    "{degrees} degrees {kind:?} channel {c}: standard error {se}"
                );
                assert!(
                    (mean - colour[c]).abs() < tol,
                    "{degrees} degrees {kind:?} channel {c}: {mean} (se {se}) vs {}",
                    colour[c]
                );
            }
        }
    }
}

/// A ball of radius 1 of `material` under a sun (a directional light)
/// and a dim sky, its point `(0, 1, 0)` seen by an orthographic camera
/// (0.01 across) whose axis makes the angle `degrees` with the normal
/// there.
fn sunlit_ball_seen_at(degrees: f32, material: &str) -> String {
    let (s, c) = degrees.to_radians().sin_cos();
    format!(
        r#"
[camera]
look_from = [0, {}, {}]
look_at = [0, 1, 0]
up = [0, 0, -1]
ortho_half_height = 0.005
[environment]
color = 0.2
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {material}
[[lights]]
type = "directional"
direction = [-0.3, -0.8, 0.5]
illuminance = 2.0
"#,
        1.0 + 5.0 * c,
        5.0 * s
    )
}

/// A subsurface ball whose radius (mean free path, 1e-4 of the ball's
/// radius) is tiny is the Lambertian ball of its colour: lit by a sun
/// and a dim sky, seen at 0, 60 and 80 degrees from the normal, in both
/// integrators, every channel's mean over the view within 4 combined
/// standard errors of the Lambertian's (the combined standard error being
/// below 2% of the value, checked).
#[test]
fn a_subsurface_ball_of_tiny_radius_is_the_lambertian_ball() {
    let sss = "{ subsurface_color = [0.7, 0.45, 0.2], subsurface_radius = 1e-4 }";
    let lambert = "{ color = [0.7, 0.45, 0.2] }";
    for degrees in [0.0f32, 60.0, 80.0] {
        for kind in IntegratorKind::ALL {
            let render = |material: &str| {
                render_toml(
                    &sunlit_ball_seen_at(degrees, material),
                    config(path_settings(24, 24, 64, 1024), kind),
                )
                .film
                .unwrap()
            };
            let (a, b) = (channel_stats(&render(sss)), channel_stats(&render(lambert)));
            for c in 0..3 {
                let ((ma, sa), (mb, sb)) = (a[c], b[c]);
                let combined = (sa * sa + sb * sb).sqrt();
                assert!(
                    combined < 0.02 * mb,
                    "{degrees} degrees {kind:?} channel {c}: standard error {combined} of {mb}"
                );
                assert!(
                    (ma - mb).abs() < 4.0 * combined,
                    "{degrees} degrees {kind:?} channel {c}: subsurface {ma} (se {sa}) vs Lambertian {mb} (se {sb})"
                );
            }
        }
    }
}

/// `volume::is_plain_segment`, by which the wavefront's medium stage only
/// routes a segment, holds only where `volume::propagate` leaves the
/// segment as it is: ending on the same hit (the same bits) with its ray
/// restarting at the hit point, or escaping along its direction, with
/// weight one, no light, no rays and no numbers drawn. Rays from all
/// over `FOGGY`'s objects without its fog (an index-matched scattering
/// ball, a glass ball, a subsurface ball, a floor, a lamp), and from
/// points on the subsurface ball's surface into it (its own entry).
/// Made to fail twice: without the index-matched boundary clause (a ray
/// that reaches the scattering ball from outside was called plain, and
/// propagation crossed into the ball and drew numbers) and without the
/// own-entry clause (a ray from the subsurface ball's surface into it).
#[test]
fn plain_segments_are_those_propagation_leaves_alone() {
    use glam::Vec3A;
    use prism::core::math::{Color, Ray};
    use prism::core::rng::Sampler;
    use prism::transport::volume::{self, SegmentEnd};

    use crate::common::rng::{Random, SplitMix64};
    let start = FOGGY.find("[[objects]]").unwrap();
    let clear = format!(
        "[camera]\nlook_from = [0, 1.5, 6]\nlook_at = [0, 0.8, 0]\n{}",
        &FOGGY[start..]
    );
    let desc = crate::common::scenes::load_toml(&clear).unwrap();
    let mut renderer = prism::systems::Renderer::with_scene(
        desc,
        config(path_settings(2, 2, 1, 4), IntegratorKind::Recursive),
        0,
    )
    .unwrap();
    renderer.render().unwrap();
    let scene = renderer.scene().unwrap();
    assert!(scene.has_media() && scene.fog().is_none());
    let mut rng = SplitMix64(45);
    let origin = Vec3A::from(scene.origin().as_vec3());
    let (mut plain, mut not_plain, mut surfaces) = (0, 0, 0);
    for k in 0..20_000u32 {
        let ray = if k % 4 == 3 {
            // From the subsurface ball's surface (centre (0.1, 0.45, 1.3),
            // radius 0.4) into it.
            let n = Vec3A::from(rng.dir());
            let p = Vec3A::new(0.1, 0.45, 1.3) + n * 0.4;
            let d = (Vec3A::from(rng.dir()) - n * 1.5).normalize();
            Ray::new(p - origin, d)
        } else {
            let o = Vec3A::from(rng.vec(-2.5, 2.5)) + Vec3A::new(0.0, 1.5, 0.5);
            Ray::new(o - origin, Vec3A::from(rng.dir()))
        };
        let hit = scene.intersect(&ray, 0.0, f32::INFINITY);
        if !volume::is_plain_segment(&scene, hit.as_ref(), ray.direction) {
            not_plain += 1;
            continue;
        }
        plain += 1;
        let mut sampler = Sampler::new(3, k, 0);
        let before = format!("{sampler:?}");
        let seg = volume::propagate(&scene, &ray, hit, 2, Color::ONE, &mut sampler);
        assert_eq!(format!("{sampler:?}"), before, "ray {k}: numbers drawn");
        assert_eq!(seg.weight, Color::ONE, "ray {k}");
        assert_eq!(seg.radiance, Color::ZERO, "ray {k}");
        assert_eq!(seg.rays, (0, 0), "ray {k}");
        match (seg.end, hit) {
            (
                SegmentEnd::Surface {
                    hit: end,
                    ray: next,
                },
                Some(h),
            ) => {
                surfaces += 1;
                assert_eq!(format!("{end:?}"), format!("{h:?}"), "ray {k}");
                assert_eq!(next.origin, h.point, "ray {k}");
                assert_eq!(next.direction, ray.direction, "ray {k}");
            }
            (SegmentEnd::Escaped(d), None) => assert_eq!(d, ray.direction, "ray {k}"),
            (end, h) => panic!("ray {k}: plain, but propagation ended {end:?} (hit {h:?})"),
        }
    }
    eprintln!("{plain} plain ({surfaces} on surfaces), {not_plain} not");
    assert!(surfaces > 5_000 && plain > surfaces && not_plain > 2_000);
}

/// The wavefront follows a walk through a lit scattering medium in one
/// pass of its medium stage too: each scattering event's shadow rays are
/// traced and their light added at once, and the walk goes on in the
/// stage. A ball of index-matched boundary (the ray enters without
/// refraction) filled with a dense, nearly white scattering medium under a
/// white sky (one batch of 8x8 pixels, 4 samples): every event can see
/// the sky, so each makes a shadow ray; the walks take on average at least
/// 10 steps, the image and counts are the recursive tracer's, and the
/// batch's longest path needs at most 4 bounces of the queues (the camera
/// ray, the walk from the boundary, the ray that left). When a lit event
/// handed its next ray to the queues, this took as many bounces as the
/// longest walk has steps (with that, this test failed: 358 bounces for walks
/// of 27.7 steps on average).
#[test]
fn the_wavefront_walks_through_a_lit_medium_in_one_bounce() {
    let (counters, paths) = walks_in_one_bounce(
        "{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, scattering = 40.0, absorption = 0.4 }",
    );
    assert!(
        counters.rays.shadow as f64 >= 10.0 * paths as f64,
        "{} shadow rays",
        counters.rays.shadow
    );
}

/// The wavefront follows a random walk inside a subsurface material in
/// one pass of its medium stage: no light reaches the walk's scattering
/// events, so they make no shadow rays, and a walk of many steps costs one
/// bounce of the queues. A ball of mean free path 1/40 of its radius,
/// nearly white, under a white sky (one batch of 8x8 pixels, 4 samples):
/// its walks take on average at least 10 steps (the reflection rays
/// counted per path; the walks do not depend on the integrator, whose
/// counts and image agree), yet the batch's longest path needs at most 4
/// bounces of the queues: the camera ray meets the ball and enters it,
/// the walk reaches the surface from inside, the path leaves and
/// escapes (the ball is convex). Queued step by step, the walks made as
/// many bounces as the longest of them has steps.
#[test]
fn the_wavefront_walks_through_a_subsurface_material_in_one_bounce() {
    walks_in_one_bounce("{ subsurface_color = 0.95, subsurface_radius = 0.025 }");
}

/// A unit ball of `material` under a white sky, path traced by both
/// integrators (one batch of 8x8 pixels, 4 samples, depth 1024): the
/// counts and images agree, the walks inside take on average at least 10
/// steps (the reflection rays counted per path), and the wavefront's
/// batch needs at most 4 bounces of the queues. Returns the wavefront's
/// counters and the number of paths.
fn walks_in_one_bounce(material: &str) -> (prism::integrators::counters::RenderCounters, u64) {
    let scene = format!(
        r#"
[camera]
look_from = [0, 0, 3]
look_at = [0, 0, 0]
vfov = 30
[environment]
color = 1.0
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {material}
"#
    );
    let s = path_settings(8, 8, 4, 1024);
    let paths = 8 * 8 * 4;
    let wav = render_toml(&scene, config(s.clone(), IntegratorKind::Wavefront));
    let rec = render_toml(&scene, config(s, IntegratorKind::Recursive));
    assert_eq!(rec.counters, wav.counters);
    assert_integrators_agree(rec.film.as_ref().unwrap(), wav.film.as_ref().unwrap());
    let report = wav.wavefront.unwrap();
    assert_eq!(report.batches, 1);
    let steps = wav.counters.rays.reflection as f64 / paths as f64;
    assert!(steps >= 10.0, "{steps} walk steps per path");
    let bounces = report.runs.get(Stage::IntersectClosest);
    assert!(bounces <= 4, "{bounces} bounces for walks of {steps} steps");
    (wav.counters, paths)
}
