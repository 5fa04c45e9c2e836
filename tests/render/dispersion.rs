//! Spectral path transport: scenes with a dispersive material trace one
//! wavelength per path ([`prism::core::spectrum`]).

use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;

use crate::common::assets;
use crate::common::images::film_bits;
use crate::common::render::{config, render_file, render_toml};

fn settings(width: u32, height: u32, spp: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp,
        max_depth: 64,
        transport: Transport::Path,
        ..Default::default()
    }
}

/// A glass ball (with the material `glass`) in a uniform environment of
/// radiance 1, or in an orange one when `lit`.
fn ball(glass: &str, lit: bool) -> String {
    // Lit: a coloured environment, tinted glass (less noise than an area
    // light, so a bias of a few percent stands out).
    let world = if lit {
        "[environment]\ncolor = [0.9, 0.6, 0.3]\n"
    } else {
        "[environment]\ncolor = 1.0\n"
    };
    format!(
        r#"
[camera]
look_from = [0, 0, 4]
look_at = [0, 0, 0]
vfov = 40
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {glass}
{world}"#
    )
}

/// A white furnace: a dispersive (N-BK7) glass ball in a uniform
/// environment of radiance 1 is invisible at every wavelength, so the
/// image stays white: its mean is 1 in each channel within 1% (the only
/// noise is the wavelength's, stratified over 64 samples a pixel).
#[test]
fn a_dispersive_ball_in_a_white_furnace_stays_white() {
    let scene = ball(
        "{ color = 1.0, diffuse = 0.0, transmission = 1.0, sellmeier = \"N-BK7\" }",
        false,
    );
    for kind in IntegratorKind::ALL {
        let film = render_toml(&scene, config(settings(16, 16, 64), kind))
            .film
            .unwrap();
        let mean = film.pixels.iter().copied().sum::<glam::Vec3>() / film.pixels.len() as f32;
        assert!(
            (mean - glam::Vec3::ONE).abs().max_element() < 1e-2,
            "{kind:?}: {mean}"
        );
    }
}

/// A material with no dispersion to speak of (Abbe number 1e12) makes the
/// scene spectral; it must render the RGB image within noise. The paths
/// are the same in both modes (the wavelength has its own sampler
/// dimension), so the per-pixel difference is the wavelength's noise
/// alone; each 4x4 block's mean difference is within 5 standard errors
/// of the block's differences (plus 1e-4 for exact agreement). Its power:
/// spectral weights 5 % too high (`wavelength_weight` times 1.05) put the
/// image's red mean 0.0397 off against a standard error of 0.0020 (20
/// standard errors), and the test fails.
#[test]
fn a_non_dispersive_material_renders_the_rgb_image_in_spectral_mode() {
    let plain = "{ color = [0.8, 0.9, 1.0], diffuse = 0.0, transmission = 1.0, ior = 1.5 }";
    let flat =
        "{ color = [0.8, 0.9, 1.0], diffuse = 0.0, transmission = 1.0, ior = 1.5, abbe = 1e12 }";
    let s = settings(16, 16, 64);
    let rgb = render_toml(
        &ball(plain, true),
        config(s.clone(), IntegratorKind::Recursive),
    );
    let spectral = render_toml(&ball(flat, true), config(s, IntegratorKind::Recursive));
    let (a, b) = (rgb.film.unwrap(), spectral.film.unwrap());
    assert_ne!(film_bits(&a), film_bits(&b), "spectral mode did not run");
    // The whole image: 256 pixel differences.
    let diffs: Vec<glam::Vec3> = (0..256).map(|p| b.pixels[p] - a.pixels[p]).collect();
    let mean = diffs.iter().copied().sum::<glam::Vec3>() / 256.0;
    let var = diffs
        .iter()
        .map(|d| (*d - mean) * (*d - mean))
        .sum::<glam::Vec3>()
        / 255.0;
    let se = (var / 256.0).powf(0.5);
    let level = a.pixels.iter().copied().sum::<glam::Vec3>() / 256.0;
    for c in 0..3 {
        assert!(
            mean[c].abs() <= 5.0 * se[c] + 1e-4,
            "image channel {c}: mean difference {} vs se {} (level {})",
            mean[c],
            se[c],
            level[c]
        );
    }
    for by in 0..4 {
        for bx in 0..4 {
            let diffs: Vec<glam::Vec3> = (0..16)
                .map(|i| {
                    let (x, y) = (bx * 4 + i % 4, by * 4 + i / 4);
                    let p = y * 16 + x;
                    b.pixels[p] - a.pixels[p]
                })
                .collect();
            let mean = diffs.iter().copied().sum::<glam::Vec3>() / 16.0;
            let var = diffs
                .iter()
                .map(|d| (*d - mean) * (*d - mean))
                .sum::<glam::Vec3>()
                / 15.0;
            let se = (var / 16.0).powf(0.5);
            for c in 0..3 {
                assert!(
                    mean[c].abs() <= 5.0 * se[c] + 1e-4,
                    "block ({bx}, {by}) channel {c}: {} vs se {}",
                    mean[c],
                    se[c]
                );
            }
        }
    }
}

fn prism_film(kind: IntegratorKind, threads: usize, spp: u32) -> Film {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let s = RenderSettings {
        width: 48,
        height: 24,
        spp,
        transport: Transport::Path,
        ..Default::default()
    };
    pool.install(|| {
        render_file(&assets().join("prism.toml"), config(s, kind))
            .film
            .unwrap()
    })
}

/// The prism scene is bit-identical on 1 and 2 threads in each
/// integrator, and the integrators agree (to 1e-4 relative).
#[test]
fn spectral_images_are_bit_identical_across_threads_and_integrators_agree() {
    let rec = prism_film(IntegratorKind::Recursive, 1, 4);
    let wav = prism_film(IntegratorKind::Wavefront, 1, 4);
    assert_eq!(
        film_bits(&rec),
        film_bits(&prism_film(IntegratorKind::Recursive, 2, 4))
    );
    assert_eq!(
        film_bits(&wav),
        film_bits(&prism_film(IntegratorKind::Wavefront, 2, 4))
    );
    crate::common::images::assert_same_image(&rec, &wav, "prism: recursive vs wavefront");
    // The spectrum is there: at 64 samples a pixel (where a slit seen
    // without dispersion is white), some pixel is clearly red, another
    // clearly blue.
    let rec = prism_film(IntegratorKind::Recursive, 1, 64);
    let red = rec
        .pixels
        .iter()
        .any(|p| p.x > 2.0 * p.z.max(0.0) && p.x > 0.5);
    let blue = rec
        .pixels
        .iter()
        .any(|p| p.z > 2.0 * p.x.max(0.0) && p.z > 0.5);
    assert!(red && blue, "no spectrum in the prism image");
}

/// A white beam through the prism spreads over the analytic range of
/// angles: by reciprocity, the camera of `assets/prism.toml` sees the slit
/// (a white source subtending 0.2 degrees) through the prism exactly in
/// the directions that the slit's light leaves the prism in, so the band
/// of lit columns of the image is the beam's fan of exit angles as it
/// would fall on a screen at the eye. The expected band is computed here
/// independently, in f64: for each column (in 1/20 pixel steps) and each
/// wavelength of the sampled range (380-780 nm in 1 nm steps), the
/// central camera ray is refracted by Snell's law into and out of the
/// prism (N-BK7 by Sellmeier) and tested against the slit. The render
/// (eight central rows, 320x160, 64 spp: each column's 12 nm of the
/// spectrum gets about 15 samples) must light every column of the band
/// more than 1.5 pixels from its ends and nothing within 20 pixels
/// outside it beyond 1.5 pixels (the slit's reflection in the entry face,
/// white since reflection does not disperse, lies further left); the
/// column of 650 nm must be red and that of 450 nm blue.
#[test]
fn a_white_beam_through_the_prism_spreads_over_the_analytic_angles() {
    use glam::DVec2;
    use prism::core::spectrum::{LAMBDA_MAX, LAMBDA_MIN, Sellmeier};
    let (w, h) = (320u32, 160u32);
    // The scene's prism (x, z of its vertical edges), slit and camera.
    let tri = [
        DVec2::new(0.326896, -0.114627),
        DVec2::new(-0.064178, 0.340413),
        DVec2::new(-0.262717, -0.225786),
    ];
    let slit = [
        DVec2::new(-2.502751, -3.1203),
        DVec2::new(-2.493379, -3.127794),
    ];
    let eye = DVec2::new(0.0, 3.0);
    let half_w = (3f64.to_radians()).tan() * w as f64 / h as f64;
    // Ray-segment intersection: distance along the ray, if it crosses.
    let cross = |o: DVec2, d: DVec2, a: DVec2, b: DVec2| -> Option<f64> {
        let e = b - a;
        let den = d.perp_dot(e);
        if den.abs() < 1e-15 {
            return None;
        }
        let t = (a - o).perp_dot(e) / den;
        let s = (a - o).perp_dot(d) / den;
        (t > 1e-9 && (0.0..=1.0).contains(&s)).then_some(t)
    };
    let centroid = (tri[0] + tri[1] + tri[2]) / 3.0;
    // Closest face hit: (distance, outward unit normal).
    let hit = |o: DVec2, d: DVec2| -> Option<(f64, DVec2)> {
        (0..3)
            .filter_map(|i| {
                let (a, b) = (tri[i], tri[(i + 1) % 3]);
                let t = cross(o, d, a, b)?;
                let mut n = (b - a).perp().normalize();
                if n.dot(a - centroid) < 0.0 {
                    n = -n;
                }
                Some((t, n))
            })
            .min_by(|x, y| x.0.total_cmp(&y.0))
    };
    // Snell's law: d unit, n unit facing against d, eta = n_from / n_to.
    let refract = |d: DVec2, n: DVec2, eta: f64| -> Option<DVec2> {
        let c = -d.dot(n);
        let k = 1.0 - eta * eta * (1.0 - c * c);
        (k >= 0.0).then(|| (eta * d + (eta * c - k.sqrt()) * n).normalize())
    };
    let sees_slit = |x: f64, lambda: f64| -> bool {
        let sx = 2.0 * x / w as f64 - 1.0;
        let d = DVec2::new(sx * half_w, -1.0).normalize();
        let n_glass = Sellmeier::N_BK7.ior_f64(lambda);
        let Some((t1, n1)) = hit(eye, d) else {
            return false;
        };
        let p1 = eye + d * t1;
        let Some(d1) = refract(d, n1, 1.0 / n_glass) else {
            return false;
        };
        let Some((t2, n2)) = hit(p1 + d1 * 1e-9, d1) else {
            return false;
        };
        let p2 = p1 + d1 * t2;
        let Some(d2) = refract(d1, -n2, n_glass) else {
            return false;
        };
        cross(p2, d2, slit[0], slit[1]).is_some()
    };
    let steps = (LAMBDA_MAX - LAMBDA_MIN) as usize;
    let lambdas = || (0..=steps).map(|i| LAMBDA_MIN as f64 + i as f64);
    let columns_of = |lambda: f64| -> Vec<f64> {
        (0..w * 20)
            .map(|i| (i as f64 + 0.5) / 20.0)
            .filter(|&x| sees_slit(x, lambda))
            .collect()
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for lambda in lambdas() {
        for x in columns_of(lambda) {
            lo = lo.min(x);
            hi = hi.max(x);
        }
    }
    assert!(hi - lo > 10.0, "band {lo}..{hi}");
    let centre_of = |lambda: f64| {
        let c = columns_of(lambda);
        c.iter().sum::<f64>() / c.len() as f64
    };
    let s = RenderSettings {
        width: w,
        height: h,
        spp: 64,
        max_depth: 8,
        transport: Transport::Path,
        ..Default::default()
    };
    let film = render_file(
        &assets().join("prism.toml"),
        config(s, IntegratorKind::Recursive),
    )
    .film
    .unwrap();
    // Central rows: the rays there are within 0.08 degrees of the plane
    // the model traces in.
    let column = |x: u32| {
        (h / 2 - 4..h / 2 + 4)
            .map(|y| film.get(x, y))
            .fold(prism::core::math::Color::ZERO, |a, c| a + c)
    };
    let lit = |x: u32| column(x).abs().max_element() > 1e-3;
    eprintln!("expected band: columns {lo:.2} to {hi:.2}");
    for x in 0..w {
        let c = x as f64 + 0.5;
        if c > lo + 1.5 && c < hi - 1.5 {
            assert!(
                lit(x),
                "column {x} inside the band {lo:.2}..{hi:.2} is dark"
            );
        }
        if (c < lo - 1.5 && c > lo - 20.0) || (c > hi + 1.5 && c < hi + 20.0) {
            assert!(
                !lit(x),
                "column {x} outside the band {lo:.2}..{hi:.2} is lit: {}",
                column(x)
            );
        }
    }
    let red = column(centre_of(650.0) as u32);
    let blue = column(centre_of(450.0) as u32);
    assert!(red.x > 2.0 * red.z.max(0.0), "650 nm column: {red}");
    assert!(blue.z > 2.0 * blue.x.max(0.0), "450 nm column: {blue}");
}
