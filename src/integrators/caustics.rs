//! Light tracing of caustics ([`crate::transport::caustic`]) for the
//! recursive integrator: one light subpath per camera sample, traced in
//! chunks of a fixed size on the worker threads. Each chunk keeps its
//! splats in order and the chunks are added in order, so the image does
//! not depend on the number of threads.

use rayon::prelude::*;

use crate::core::math::Color;
use crate::core::settings::RenderSettings;
use crate::image::film::Film;
use crate::integrators::Progress;
use crate::integrators::counters::RenderCounters;
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::transport::caustic;

/// Light subpaths per chunk of work.
const CHUNK: u64 = 1 << 14;

/// Chunks per wave: at most `WAVE * CHUNK` splats of 16 bytes are held.
const WAVE: usize = 64;

/// Traces `width x height x spp` light subpaths and adds their splats,
/// divided by that number, to `film` (the whole image, path traced with
/// light tracing's paths left out). Reports [`caustic::light_pass_rows`]
/// rows of progress in all, as the waves finish. Returns the rays traced.
pub fn add_splats(
    scene: &RenderScene,
    settings: &RenderSettings,
    cam: &CameraRays,
    film: &mut Film,
    progress: Option<Progress<'_>>,
) -> RenderCounters {
    let pixels = settings.width as u64 * settings.height as u64;
    let total = pixels * settings.spp as u64;
    let proj = cam.projection();
    let targets = caustic::targets(scene);
    let chunks = total.div_ceil(CHUNK) as usize;
    let mut sums = vec![[0.0f64; 3]; pixels as usize];
    let mut counters = RenderCounters::default();
    let rows = caustic::light_pass_rows(settings);
    let mut reported = 0;
    // Waves of `WAVE` chunks: each wave's splats are held until they are
    // added, in chunk order, which bounds the memory (about 16 MB).
    for wave in (0..chunks).step_by(WAVE) {
        let parts: Vec<(Vec<(u32, Color)>, RenderCounters)> = (wave..(wave + WAVE).min(chunks))
            .into_par_iter()
            .with_max_len(1)
            .map(|c| {
                let mut counters = RenderCounters::default();
                let mut out = Vec::new();
                let c = c as u64;
                for n in c * CHUNK..((c + 1) * CHUNK).min(total) {
                    let mut sampler = caustic::light_sampler(settings, pixels, n);
                    let (v, rays) = caustic::light_subpath(scene, settings, &targets, &mut sampler);
                    counters.rays.reflection += rays as u64;
                    let Some(v) = v else {
                        continue;
                    };
                    let Some((pixel, q)) = caustic::splat(settings, cam, &proj, &v) else {
                        continue;
                    };
                    counters.rays.shadow += 1;
                    if !scene.occluded(&q.ray, 0.0, q.t_max) {
                        out.push((pixel, q.radiance));
                    }
                }
                (out, counters)
            })
            .collect();
        for (out, c) in &parts {
            counters.add(c);
            for &(p, l) in out {
                let s = &mut sums[p as usize];
                s[0] += l.x as f64;
                s[1] += l.y as f64;
                s[2] += l.z as f64;
            }
        }
        if let Some(p) = progress {
            let done = (((wave + WAVE) as u64 * CHUNK).min(total) as u128 * rows as u128
                / total as u128) as u64;
            p(done - reported);
            reported = done;
        }
    }
    let scale = 1.0 / total as f64;
    for (px, s) in film.pixels.iter_mut().zip(&sums) {
        *px += Color::new(
            (s[0] * scale) as f32,
            (s[1] * scale) as f32,
            (s[2] * scale) as f32,
        );
    }
    counters
}
