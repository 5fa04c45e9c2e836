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
/// of the block's differences (plus 1e-4 for exact agreement).
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
