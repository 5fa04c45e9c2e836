//! Viewing a radiosity [`Solution`]: rows in parallel, each sample's
//! camera ray traced through mirrors and glass (perfect specular
//! reflection and refraction, as Whitted transport does) to a diffuse or
//! emissive surface, whose radiosity is read from the solution (see
//! [`ViewMode`]).
//!
//! The solution is computed once per scene ([`crate::radiosity::solve`]);
//! rendering a view only reads it, so a moving camera costs one view pass
//! per frame. Random numbers (pixel jitter, gather directions) are keyed
//! by (seed, pixel, sample, dimension), as in the other integrators.

use rayon::prelude::*;

use super::{Progress, accumulate, camera_rays, film_sample};
use crate::core::math::{Color, Ray, max_component};
use crate::core::rng::Sampler;
use crate::core::sampling::cosine_hemisphere;
use crate::core::settings::RenderSettings;
use crate::image::film::{Film, PixelSum};
use crate::integrators::counters::RenderCounters;
use crate::radiosity::{Solution, ViewMode};
use crate::scene::RenderScene;
use crate::scene::camera::Camera;
use crate::transport::interaction::{Interaction, RayKind};
use crate::transport::whitted::scatter;

/// Dimensions of the sampler used per bounce: two for the pixel, then
/// two per gather ray.
const PIXEL_DIMENSIONS: u32 = 2;

/// Radiance along `ray` (in the scene's frame) under the radiosity
/// solution `sol`.
#[allow(clippy::too_many_arguments)]
pub fn trace(
    scene: &RenderScene,
    sol: &Solution,
    settings: &RenderSettings,
    ray: &Ray,
    depth: u32,
    throughput: Color,
    sampler: &mut Sampler,
    counters: &mut RenderCounters,
) -> Color {
    let Some(hit) = scene.intersect(ray, 0.0, f32::INFINITY) else {
        return scene.background();
    };
    let it = Interaction::new(scene, ray, &hit);
    let shift = sol.to_solution_frame(scene.origin());
    let mut radiance = Color::ZERO;
    if it.surface.diffuse.max_element() > 0.0 || it.surface.emission.max_element() > 0.0 {
        let view = settings.radiosity.view;
        let flat = view == ViewMode::Flat;
        // The same ray in the solution's mesh: the patch surface the scene
        // hit lies at (nearly) the same parameter.
        let local = Ray::new(ray.origin + shift, ray.direction);
        let found = sol
            .hit(&local, hit.t * 0.999, hit.t * 1.001 + 1e-6, flat)
            .or_else(|| sol.hit(&local, 0.0, f32::INFINITY, flat));
        if view == ViewMode::Gather {
            radiance += it.surface.emission;
            let k = settings.radiosity.gather_rays;
            let origin = it.offset(it.ng) + shift;
            let mut sum = Color::ZERO;
            for _ in 0..k {
                let u = glam::Vec2::new(sampler.next_f32(), sampler.next_f32());
                let d = cosine_hemisphere(it.ng, u);
                counters.rays.reflection += 1;
                sum += match sol.radiance(&Ray::new(origin, d), 0.0, f32::INFINITY, false) {
                    Some(l) => l,
                    None => scene.background(),
                };
            }
            radiance += it.surface.diffuse * sum / k as f32;
        } else {
            radiance += match found {
                Some(h) => h.radiosity * std::f32::consts::FRAC_1_PI,
                None => it.surface.emission,
            };
        }
    }
    if depth < settings.max_depth {
        for s in scatter(&it).into_iter().flatten() {
            let t = throughput * s.weight;
            if max_component(t) < settings.min_contribution {
                continue;
            }
            match s.kind {
                RayKind::Reflection => counters.rays.reflection += 1,
                RayKind::Refraction => counters.rays.refraction += 1,
                RayKind::Camera => counters.rays.camera += 1,
            }
            radiance += s.weight
                * trace(
                    scene,
                    sol,
                    settings,
                    &s.ray,
                    depth + 1,
                    t,
                    sampler,
                    counters,
                );
        }
    }
    radiance
}

/// Renders the whole image from the radiosity solution `sol` of `scene`.
pub fn render(
    scene: &RenderScene,
    sol: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<Progress<'_>>,
) -> (Film, RenderCounters) {
    let cam = camera_rays(scene, camera, settings);
    let (w, h) = (settings.width, settings.height);
    let mut film = Film::new(w, h);
    let counters = film
        .pixels
        .par_chunks_mut(w as usize)
        .enumerate()
        .with_max_len(1)
        .map(|(y, row)| {
            let y = y as u32;
            let mut counters = RenderCounters::default();
            for (x, px) in row.iter_mut().enumerate() {
                let x = x as u32;
                let mut sum = PixelSum::default();
                for s in 0..settings.spp {
                    let mut sampler =
                        Sampler::with_kind(settings.sampler, settings.seed, y * w + x, s);
                    let ray = cam.ray(film_sample(x, y, settings.spp, &mut sampler));
                    sampler.set_dimension(PIXEL_DIMENSIONS);
                    counters.rays.camera += 1;
                    let l = trace(
                        scene,
                        sol,
                        settings,
                        &ray,
                        0,
                        Color::ONE,
                        &mut sampler,
                        &mut counters,
                    );
                    accumulate(&mut sum, l, &mut counters);
                }
                *px = sum.mean();
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
    (film, counters)
}
