//! The photon-mapping integrator: probabilistic progressive photon mapping
//! (Knaus and Zwicker 2011) on the recursive integrator's camera side.
//!
//! Each iteration `i` (from 0) is independent: it traces its own photons
//! into fresh maps with the gather radius `r_i` of
//! [`PhotonSettings::radius2_at`](crate::core::photon_settings::PhotonSettings::radius2_at),
//! then takes `spp` camera samples per pixel (sample indices `i * spp ..`)
//! that read those maps, and adds them to each pixel's exact sum. The
//! image is the mean over all iterations: its variance and its kernel bias
//! both fall as iterations are added (for `alpha` in `(0, 1)`). Only one
//! iteration's maps are held at a time.
//!
//! Photons are traced in parallel in fixed chunks and concatenated in
//! photon order; pixel sums are exact; every random number is keyed by
//! (seed, iteration, photon or pixel, sample, dimension). The image is
//! therefore the same bit for bit for any thread count.

use std::time::Instant;

use rayon::prelude::*;

use super::{Progress, accumulate, camera_rays, film_sample};
use crate::core::photon_settings::AUTO_RADIUS_DIVISOR;
use crate::core::rng::Sampler;
use crate::core::settings::RenderSettings;
use crate::image::film::{Film, PixelAccumulator};
use crate::integrators::counters::RenderCounters;
use crate::scene::RenderScene;
use crate::scene::camera::Camera;
use crate::transport::photon::emit::PhotonSources;
use crate::transport::photon::{CameraContext, camera_radiance, trace_photons};

/// What the photon passes did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PhotonReport {
    /// Iterations run.
    pub iterations: u32,
    /// Photons emitted per iteration.
    pub photons_per_iteration: u32,
    /// Photons stored in caustic maps, over all iterations.
    pub caustic_photons: u64,
    /// Photons stored in global maps, over all iterations.
    pub global_photons: u64,
    /// Photon rays traced, over all iterations.
    pub photon_rays: u64,
    /// Gather radius of the first and of the last iteration.
    pub first_radius: f32,
    /// Gather radius of the last iteration.
    pub last_radius: f32,
    /// Seconds tracing photons and building maps.
    pub photon_seconds: f64,
    /// Seconds of camera passes.
    pub camera_seconds: f64,
    /// Largest memory held by one iteration's maps, in bytes.
    pub peak_map_bytes: usize,
}

/// Progress steps per iteration: the photon pass and the camera pass
/// report `rows` steps each.
pub fn progress_steps(settings: &RenderSettings) -> u64 {
    2 * settings.height as u64 * settings.photon.iterations as u64
}

/// The first gather radius: the settings' or the automatic one.
pub fn first_radius(settings: &RenderSettings, sources: &PhotonSources) -> f32 {
    settings.photon.radius.unwrap_or_else(|| {
        let (_, r) = sources.bounds();
        2.0 * r / AUTO_RADIUS_DIVISOR
    })
}

/// Renders the whole image by progressive photon mapping. Fails with a
/// message when the scene has nothing that emits photons, when the
/// settings have a render window, or when no radius can be found.
pub fn render(
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<Progress<'_>>,
) -> Result<(Film, RenderCounters, PhotonReport), String> {
    if settings.window.is_some() {
        return Err(
            "photon transport renders the whole image: it does not combine with shards or \
             render windows"
                .into(),
        );
    }
    settings.photon.validate()?;
    let sources = PhotonSources::new(scene);
    if sources.is_empty() {
        return Err(
            "photon transport needs a light: the scene has no light or emissive surface to emit \
             photons from"
                .into(),
        );
    }
    let r1 = first_radius(settings, &sources);
    if !(r1 > 0.0 && r1.is_finite()) {
        return Err(format!(
            "photon gather radius {r1} is unusable (the scene has no bounded object to size it \
             from): give one with --photon-radius"
        ));
    }
    let cam = camera_rays(scene, camera, settings);
    let (w, h) = (settings.width, settings.height);
    let spp = settings.spp;
    let iterations = settings.photon.iterations;
    let total = spp.saturating_mul(iterations);
    let mut sums = PixelAccumulator::new(w, h);
    let mut counters = RenderCounters::default();
    let mut report = PhotonReport {
        iterations,
        photons_per_iteration: settings.photon.photons,
        first_radius: r1,
        ..Default::default()
    };
    for i in 0..iterations {
        let radius = settings.photon.radius2_at(r1, i).sqrt();
        report.last_radius = radius;
        let start = Instant::now();
        let maps = trace_photons(
            scene,
            settings,
            &sources,
            i,
            radius,
            progress.map(|p| (p, h as u64)),
        );
        report.photon_seconds += start.elapsed().as_secs_f64();
        report.caustic_photons += maps.caustic.photons().len() as u64;
        report.global_photons += maps.global.photons().len() as u64;
        report.photon_rays += maps.rays;
        report.peak_map_bytes = report.peak_map_bytes.max(maps.bytes());
        let start = Instant::now();
        let pass = sums
            .pixels_mut()
            .par_chunks_mut(w as usize)
            .enumerate()
            .with_max_len(1)
            .map(|(y, row)| {
                let mut counters = RenderCounters::default();
                for (x, sum) in row.iter_mut().enumerate() {
                    let pixel = y as u32 * w + x as u32;
                    for s in 0..spp {
                        let sample = i * spp + s;
                        let mut sampler =
                            Sampler::with_kind(settings.sampler, settings.seed, pixel, sample);
                        let ray = cam.ray(film_sample(x as u32, y as u32, total, &mut sampler));
                        counters.rays.camera += 1;
                        let ctx = CameraContext {
                            scene,
                            settings,
                            maps: &maps,
                            pixel,
                            sample,
                        };
                        let l = camera_radiance(&ctx, &ray, &mut sampler, &mut counters);
                        accumulate(sum, l, &mut counters);
                    }
                }
                if let Some(p) = progress {
                    p(1);
                }
                counters
            })
            .reduce(RenderCounters::default, |mut a, b| {
                a.add(&b);
                a
            });
        counters.add(&pass);
        report.camera_seconds += start.elapsed().as_secs_f64();
    }
    Ok((sums.resolve(), counters, report))
}
