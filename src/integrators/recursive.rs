//! The recursive tracer: depth-first. Whitted transport traces the camera
//! rays of sixteen neighbouring pixels and their shadow rays as packets
//! (`trace_camera_packet`) and recurses into each specular ray one at a
//! time; path transport follows one ray per bounce in a loop.

use rayon::prelude::*;

use super::{Progress, accumulate, camera_ray, camera_rays};
use crate::accel::packet::{LaneMask, for_each_lane};
use crate::core::math::{Color, Ray, RayCone, max_component};
use crate::core::rng::Sampler;
use crate::core::settings::{RenderSettings, Style, Transport};
use crate::image::film::{Film, PixelAccumulator, PixelSum};
use crate::integrators::counters::RenderCounters;
use crate::scene::camera::{Camera, CameraRays};
use crate::scene::query::COHERENT_LANES;
use crate::scene::{Hit, RenderScene};
use crate::transport::caustic::{self, ChainState};
use crate::transport::gooch::gooch_shade;
use crate::transport::interaction::{Interaction, RayKind};
use crate::transport::medium::interior_transmittance;
use crate::transport::path::{self, LobeChoice};
use crate::transport::volume::{self, SegmentEnd};
use crate::transport::whitted::{direct_light, scatter};

/// Radiance arriving along `ray`, whose ray cone is `cone` (texture level
/// of detail); `depth` is the number of bounces so far
/// and `throughput` the weight this radiance will be multiplied by on its
/// way to the camera (used for the contribution threshold).
pub fn trace(
    scene: &RenderScene,
    settings: &RenderSettings,
    ray: &Ray,
    cone: RayCone,
    depth: u32,
    throughput: Color,
    counters: &mut RenderCounters,
) -> Color {
    let Some(hit) = scene.intersect(ray, 0.0, f32::INFINITY) else {
        return escaped(scene, ray);
    };
    let it = Interaction::with_cone(scene, ray, &hit, cone);
    let interior = segment_transmittance(scene, ray, &hit, &it);
    let throughput = interior.map_or(throughput, |tr| throughput * tr);
    let mut radiance = it.surface.emission;
    if unshadowed_light(scene, settings, &it, &mut radiance) {
        for light in scene.lights() {
            if let Some(q) = direct_light(&it, light) {
                counters.rays.shadow += 1;
                if !scene.occluded(&q.ray, 0.0, q.t_max) {
                    radiance += q.radiance;
                }
            }
        }
    }
    add_specular(
        scene,
        settings,
        &it,
        throughput,
        depth,
        &mut radiance,
        counters,
    );
    interior.map_or(radiance, |tr| radiance * tr)
}

// The steps of Whitted shading at a hit, shared by `trace` (one ray) and
// `trace_camera_packet` (camera rays whose shadow rays are traced as
// packets): each adds the same terms in the same order either way, so the
// two give the same bits. They take the interaction by reference (moving
// it costs a `memcpy` call).

/// Radiance of a ray that found nothing.
#[inline(always)]
fn escaped(scene: &RenderScene, ray: &Ray) -> Color {
    let l = scene.escaped_radiance(ray.direction);
    match scene.fog() {
        Some(fog) => l * fog.transmittance(f32::INFINITY),
        None => l,
    }
}

/// Transmittance of the segment of `ray` that reached `hit`: through an
/// absorbing interior (or, in a scene with media, through any medium:
/// Beer-Lambert by its extinction), carried to everything seen at its
/// end.
#[inline(always)]
fn segment_transmittance(
    scene: &RenderScene,
    ray: &Ray,
    hit: &Hit,
    it: &Interaction,
) -> Option<Color> {
    let distance = hit.t * ray.direction.length();
    if scene.has_media() {
        volume::whitted_transmittance(scene, Some(hit), ray.direction, distance)
    } else {
        interior_transmittance(it, distance)
    }
}

/// Adds the light that needs no shadow ray (the Gooch tone) to
/// `radiance`; returns whether the point takes the lights' shadow rays.
#[inline(always)]
fn unshadowed_light(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    radiance: &mut Color,
) -> bool {
    if !it.is_lit_by_lights() {
        return false;
    }
    if settings.style == Style::Gooch {
        *radiance += gooch_shade(&settings.gooch, scene.lights(), it);
        return false;
    }
    true
}

/// Adds the specular rays leaving `it` (traced recursively while `depth`
/// allows) to `radiance`.
#[inline(always)]
fn add_specular(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    throughput: Color,
    depth: u32,
    radiance: &mut Color,
    counters: &mut RenderCounters,
) {
    if depth >= settings.max_depth {
        return;
    }
    for s in scatter(it).into_iter().flatten() {
        let t = throughput * s.weight;
        if max_component(t) < settings.min_contribution {
            continue;
        }
        match s.kind {
            RayKind::Reflection => counters.rays.reflection += 1,
            RayKind::Refraction => counters.rays.refraction += 1,
            RayKind::Camera => counters.rays.camera += 1,
        }
        *radiance += s.weight * trace(scene, settings, &s.ray, it.cone, depth + 1, t, counters);
    }
}

/// [`trace`] of up to [`COHERENT_LANES`] camera rays (cone `cone`, depth
/// 0) into `out`: the same radiance on each, bit for bit. The camera rays
/// go through the scene together ([`RenderScene::intersect_coherent`]: one
/// packet of 16 on the AVX-512 path, packets of 8 elsewhere), and so do
/// the shadow rays of their hits towards each light in turn
/// ([`RenderScene::occluded_coherent`]; neighbouring pixels' shadow rays
/// to one light share most of the nodes they visit); packets whose rays
/// point into different octants are traced ray by ray, and specular rays
/// one at a time.
///
/// On the frame-loop benchmark's scene (`benches/frame_loop.rs`) this
/// takes 2.5% fewer instructions per frame than pixel by pixel
/// (callgrind), half from each kind of packet: most of a ray's work there
/// is per ray (the unbounded ground plane, the instance transforms, the
/// shapes and leaves tested lane by lane), not node tests.
fn trace_camera_packet(
    scene: &RenderScene,
    settings: &RenderSettings,
    rays: &[Ray],
    cone: RayCone,
    counters: &mut RenderCounters,
    out: &mut [Color],
) {
    let n = rays.len();
    let mut its: [Option<Interaction>; COHERENT_LANES] = [None; COHERENT_LANES];
    let mut interior: [Option<Color>; COHERENT_LANES] = [None; COHERENT_LANES];
    let mut throughput = [Color::ONE; COHERENT_LANES];
    let mut shadowed: LaneMask = 0;
    let mut hits = [None; COHERENT_LANES];
    scene.intersect_coherent(rays, &mut hits[..n]);
    for l in 0..n {
        let ray = &rays[l];
        let Some(hit) = &hits[l] else {
            out[l] = escaped(scene, ray);
            continue;
        };
        let it = Interaction::set_with_cone(&mut its[l], scene, ray, hit, cone);
        // Written only when there is one: storing the `None` tag and
        // reloading the whole option stalled store forwarding (3% of the
        // frame-loop benchmark's frame).
        if let Some(tr) = segment_transmittance(scene, ray, hit, it) {
            interior[l] = Some(tr);
            throughput[l] *= tr;
        }
        out[l] = it.surface.emission;
        if unshadowed_light(scene, settings, it, &mut out[l]) {
            shadowed |= 1 << l;
        }
    }
    if shadowed != 0 {
        for light in scene.lights() {
            // The lanes with a shadow ray towards this light, packed.
            let mut lane = [0usize; COHERENT_LANES];
            let mut shadow_rays = [Ray::new(glam::Vec3A::ZERO, glam::Vec3A::X); COHERENT_LANES];
            let mut t_max = [0.0f32; COHERENT_LANES];
            let mut radiance = [Color::ZERO; COHERENT_LANES];
            let mut k = 0;
            for_each_lane(shadowed, |l| {
                let it = its[l].as_ref().expect("shadowed lanes have a hit");
                if let Some(q) = direct_light(it, light) {
                    counters.rays.shadow += 1;
                    shadow_rays[k] = q.ray;
                    t_max[k] = q.t_max;
                    radiance[k] = q.radiance;
                    lane[k] = l;
                    k += 1;
                }
            });
            if k == 0 {
                continue;
            }
            let blocked = scene.occluded_coherent(&shadow_rays[..k], &t_max[..k]);
            for j in 0..k {
                if blocked & (1 << j) == 0 {
                    out[lane[j]] += radiance[j];
                }
            }
        }
    }
    for l in 0..n {
        if let Some(it) = &its[l] {
            add_specular(scene, settings, it, throughput[l], 0, &mut out[l], counters);
            if let Some(tr) = interior[l] {
                out[l] *= tr;
            }
        }
    }
}

/// Radiance along a camera ray by path tracing: a loop, one vertex per
/// bounce, with next-event estimation at every vertex and multiple
/// importance sampling of emission found by scattered rays. `cone` is the
/// camera ray's cone (texture level of detail).
pub fn trace_path(
    scene: &RenderScene,
    settings: &RenderSettings,
    camera_ray: &Ray,
    cone: RayCone,
    sampler: &mut Sampler,
    counters: &mut RenderCounters,
) -> Color {
    trace_path_with(scene, settings, camera_ray, cone, sampler, false, counters)
}

/// [`trace_path`], leaving to light tracing the caustics it takes when
/// `caustics` (see [`crate::transport::caustic`]; the caller checks
/// [`caustic::applicable`] and adds light tracing's splats).
pub fn trace_path_with(
    scene: &RenderScene,
    settings: &RenderSettings,
    camera_ray: &Ray,
    cone: RayCone,
    sampler: &mut Sampler,
    caustics: bool,
    counters: &mut RenderCounters,
) -> Color {
    let lambda = path::path_wavelength(scene, settings, sampler);
    let caustics = caustics && lambda.is_none();
    let l = if scene.has_media() {
        trace_path_in::<true>(
            scene, settings, camera_ray, cone, sampler, lambda, false, counters,
        )
    } else if caustics {
        trace_path_in::<false>(
            scene, settings, camera_ray, cone, sampler, lambda, true, counters,
        )
    } else {
        trace_path_at(scene, settings, camera_ray, cone, sampler, lambda, counters)
    };
    path::weigh_wavelength(l, lambda)
}

/// [`trace_path`] at wavelength `lambda` (spectral mode) or in RGB
/// (`None`), without the film weight of the wavelength: through media
/// when the scene has them, else without a look at media.
fn trace_path_at(
    scene: &RenderScene,
    settings: &RenderSettings,
    camera_ray: &Ray,
    cone: RayCone,
    sampler: &mut Sampler,
    lambda: Option<f32>,
    counters: &mut RenderCounters,
) -> Color {
    if scene.has_media() {
        trace_path_in::<true>(
            scene, settings, camera_ray, cone, sampler, lambda, false, counters,
        )
    } else {
        trace_path_in::<false>(
            scene, settings, camera_ray, cone, sampler, lambda, false, counters,
        )
    }
}

/// The path loop; `MEDIA` follows each segment through the scene's media
/// ([`volume::propagate`]) and gives shadow rays their transmittance.
/// With `caustics` (never with `MEDIA`) the paths light tracing takes are
/// skipped ([`ChainState`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn trace_path_in<const MEDIA: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    camera_ray: &Ray,
    cone: RayCone,
    sampler: &mut Sampler,
    lambda: Option<f32>,
    caustics: bool,
    counters: &mut RenderCounters,
) -> Color {
    let start = PathStart {
        ray: *camera_ray,
        cone,
        throughput: Color::ONE,
        prev_pdf: 0.0,
        depth: 0,
        chain: ChainState::default(),
    };
    path_from::<MEDIA>(
        scene,
        settings,
        start,
        settings.split,
        sampler,
        lambda,
        caustics,
        counters,
    )
}

/// Where the path loop starts: a camera ray, or the continuation of one
/// part of a split path ([`RenderSettings::split`]), with the state the
/// loop carries from vertex to vertex.
#[derive(Clone, Copy, Debug)]
struct PathStart {
    ray: Ray,
    cone: RayCone,
    throughput: Color,
    /// Density of the direction of `ray` (0: camera ray or specular lobe).
    prev_pdf: f32,
    /// Bounces before `ray`.
    depth: u32,
    chain: ChainState,
}

/// One part of a split path: [`path_from`] without splitting, out of line
/// (the loop calls it from inside itself).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn split_part<const MEDIA: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    start: PathStart,
    sampler: &mut Sampler,
    lambda: Option<f32>,
    caustics: bool,
    counters: &mut RenderCounters,
) -> Color {
    path_from::<MEDIA>(
        scene, settings, start, 1, sampler, lambda, caustics, counters,
    )
}

/// The path loop from `start`. With `split > 1`, the first vertex (a
/// surface at depth 0) continues `split` paths instead of one, after its
/// next-event estimate: part `j` draws from [`Sampler::split`]`(j,
/// split)`, from the lobe choice of that vertex on, and their radiance,
/// summed in order, counts `1 / split`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn path_from<const MEDIA: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    start: PathStart,
    split: u32,
    sampler: &mut Sampler,
    lambda: Option<f32>,
    caustics: bool,
    counters: &mut RenderCounters,
) -> Color {
    let caustics = caustics && !MEDIA;
    let PathStart {
        mut ray,
        mut cone,
        mut throughput,
        mut prev_pdf,
        mut depth,
        mut chain,
    } = start;
    let mut radiance = Color::ZERO;
    // Surfaces' shadow rays cross media only where some can be seen
    // through (`RenderScene::shadows_are_binary`).
    let through_media = MEDIA && !scene.shadows_are_binary();
    loop {
        let found = scene.intersect(&ray, 0.0, f32::INFINITY);
        let (hit, distance) = if MEDIA {
            let seg = volume::propagate(scene, &ray, found, depth, throughput, sampler);
            counters.rays.refraction += seg.rays.0;
            counters.rays.shadow += seg.rays.1;
            radiance += throughput * seg.radiance;
            throughput *= seg.weight;
            match seg.end {
                SegmentEnd::Surface { hit, ray: at } => {
                    ray = at;
                    (hit, hit.t)
                }
                SegmentEnd::Escaped(d) => {
                    radiance += throughput * path::escaped(scene, settings, d, prev_pdf);
                    return radiance;
                }
                SegmentEnd::Lost => return radiance,
                SegmentEnd::Scattered(v) => {
                    volume::medium_next_event(scene, settings, &v, sampler, depth, |q| {
                        counters.rays.shadow += 1;
                        let tr = volume::shadow_transmittance(scene, &q.ray, q.t_max);
                        radiance += throughput * q.radiance * tr;
                    });
                    let Some(c) =
                        volume::continue_in_medium(settings, &v, depth, throughput, sampler)
                    else {
                        return radiance;
                    };
                    counters.rays.reflection += 1;
                    throughput = throughput * c.sample.weight * c.scale;
                    ray = c.sample.ray;
                    cone = RayCone::NONE;
                    prev_pdf = c.sample.pdf;
                    depth += 1;
                    continue;
                }
            }
        } else {
            let Some(hit) = found else {
                radiance += throughput * path::escaped(scene, settings, ray.direction, prev_pdf);
                return radiance;
            };
            (hit, hit.t * ray.direction.length())
        };
        let mut it = Interaction::with_cone(scene, &ray, &hit, cone);
        path::at_wavelength(&mut it, lambda);
        if !MEDIA && let Some(tr) = interior_transmittance(&it, distance) {
            throughput *= tr;
        }
        if caustics {
            chain.enter(&it.surface, depth);
        }
        if !(caustics && chain.skip_emission()) {
            radiance +=
                throughput * path::emitted(scene, settings, &it, hit.instance, prev_pdf, distance);
        }
        // Subsurface materials have scattering interiors: only scenes with
        // media have them.
        let crossing = if MEDIA {
            volume::diffuse_crossing(scene, &hit, &mut it)
        } else {
            None
        };
        let lobes = LobeChoice::new(&it);
        if crossing != Some(volume::Crossing::Into) {
            let area = !(caustics && chain.skip_area_lights(depth, settings));
            path::next_event_with(scene, settings, &it, &lobes, sampler, depth, area, |q| {
                counters.rays.shadow += 1;
                if through_media {
                    let tr = volume::shadow_transmittance(scene, &q.ray, q.t_max);
                    radiance += throughput * q.radiance * tr;
                } else if !scene.occluded(&q.ray, 0.0, q.t_max) {
                    radiance += throughput * q.radiance;
                }
            });
        }
        if split > 1 && depth == 0 {
            let mut parts = Color::ZERO;
            for j in 0..split {
                let mut part = sampler.split(j, split);
                let Some(c) =
                    path::continue_path(settings, &it, &lobes, depth, throughput, &mut part)
                else {
                    continue;
                };
                let mut chain = chain;
                if caustics {
                    chain.leave(&it.surface, depth, c.sample.pdf);
                }
                count_ray(c.sample.kind, counters);
                let start = PathStart {
                    ray: if MEDIA {
                        volume::start_walk(crossing, &it, c.sample.ray)
                    } else {
                        c.sample.ray
                    },
                    cone: c.cone(&it),
                    throughput: throughput * c.sample.weight * c.scale,
                    prev_pdf: c.sample.pdf,
                    depth: depth + 1,
                    chain,
                };
                parts += split_part::<MEDIA>(
                    scene, settings, start, &mut part, lambda, caustics, counters,
                );
            }
            return radiance + parts * (1.0 / split as f32);
        }
        let Some(c) = path::continue_path(settings, &it, &lobes, depth, throughput, sampler) else {
            return radiance;
        };
        if caustics {
            chain.leave(&it.surface, depth, c.sample.pdf);
        }
        count_ray(c.sample.kind, counters);
        throughput = throughput * c.sample.weight * c.scale;
        ray = if MEDIA {
            volume::start_walk(crossing, &it, c.sample.ray)
        } else {
            c.sample.ray
        };
        cone = c.cone(&it);
        prev_pdf = c.sample.pdf;
        depth += 1;
    }
}

/// Counts a continuation ray by its kind.
#[inline(always)]
fn count_ray(kind: RayKind, counters: &mut RenderCounters) {
    match kind {
        RayKind::Reflection => counters.rays.reflection += 1,
        RayKind::Refraction => counters.rays.refraction += 1,
        RayKind::Camera => counters.rays.camera += 1,
    }
}

/// Radiance of sample `s` of the `spp` samples of pixel `(x, y)`: its
/// camera ray, traced with the settings' transport. Its random numbers
/// are keyed by (seed, pixel, sample). Always inlined into the row loop:
/// as a call it costs about 50 instructions per sample on the cheapest
/// scenes (callgrind), which is 3-4% of a Whitted camera ray.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn pixel_sample(
    scene: &RenderScene,
    settings: &RenderSettings,
    cam: &CameraRays,
    (x, y): (u32, u32),
    (s, spp): (u32, u32),
    caustics: bool,
    counters: &mut RenderCounters,
) -> Color {
    let pixel = y * settings.width + x;
    let mut sampler = Sampler::with_kind(settings.sampler, settings.seed, pixel, s);
    let ray = camera_ray(cam, x, y, spp, &mut sampler);
    counters.rays.camera += 1;
    match settings.transport {
        Transport::Whitted => trace(scene, settings, &ray, cam.cone(), 0, Color::ONE, counters),
        // A lone sample has no photon maps: photon transport renders through
        // `integrators::photon`; here it falls back to path tracing.
        Transport::Path | Transport::Photon => trace_path_with(
            scene,
            settings,
            &ray,
            cam.cone(),
            &mut sampler,
            caustics,
            counters,
        ),
        // Radiosity frames need their solution and are rendered by
        // `integrators::radiosity`; without one, surfaces show as Whitted
        // transport sees them.
        Transport::Radiosity => trace(scene, settings, &ray, cam.cone(), 0, Color::ONE, counters),
    }
}

/// The exact sum of the window's samples of pixel `(x, y)`.
#[inline(always)]
fn pixel_sum(
    scene: &RenderScene,
    settings: &RenderSettings,
    cam: &CameraRays,
    (x, y): (u32, u32),
    samples: std::ops::Range<u32>,
    caustics: bool,
    counters: &mut RenderCounters,
) -> PixelSum {
    let mut sum = PixelSum::default();
    for s in samples {
        let l = pixel_sample(
            scene,
            settings,
            cam,
            (x, y),
            (s, settings.spp),
            caustics,
            counters,
        );
        accumulate(&mut sum, l, counters);
    }
    sum
}

/// The exact sums of the window's samples of the `n` (at most
/// [`COHERENT_LANES`])
/// pixels from `(x, y)` along a row, under Whitted transport: each sample
/// index is traced for all of them as one packet
/// ([`trace_camera_packet`]). The same sums as [`pixel_sum`] per pixel.
#[inline(always)]
fn camera_packet_sums(
    scene: &RenderScene,
    settings: &RenderSettings,
    cam: &CameraRays,
    (x, y): (u32, u32),
    n: usize,
    samples: std::ops::Range<u32>,
    counters: &mut RenderCounters,
) -> [PixelSum; COHERENT_LANES] {
    let mut sums: [PixelSum; COHERENT_LANES] = Default::default();
    let spp = settings.spp;
    // Without jitter or lens the camera ray uses no random numbers.
    let fixed = spp == 1 && !cam.has_lens();
    let row = if fixed {
        cam.pixel_centre_row::<COHERENT_LANES>(x, y, n)
    } else {
        None
    };
    for s in samples {
        let rays: [Ray; COHERENT_LANES] = row.unwrap_or_else(|| {
            std::array::from_fn(|l| {
                let x = x + l.min(n - 1) as u32;
                if fixed {
                    cam.ray(glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5))
                } else {
                    let pixel = y * settings.width + x;
                    let mut sampler = Sampler::with_kind(settings.sampler, settings.seed, pixel, s);
                    camera_ray(cam, x, y, spp, &mut sampler)
                }
            })
        });
        counters.rays.camera += n as u64;
        let mut radiance = [Color::ZERO; COHERENT_LANES];
        trace_camera_packet(
            scene,
            settings,
            &rays[..n],
            cam.cone(),
            counters,
            &mut radiance[..n],
        );
        for (sum, l) in sums.iter_mut().zip(&radiance[..n]) {
            accumulate(sum, *l, counters);
        }
    }
    sums
}

/// Renders the settings' window with the recursive tracer, rows in
/// parallel, into one value per window pixel (row-major over the window's
/// columns and rows) made by `f` from the pixel's exact sum.
fn render_rows<T: Send>(
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<Progress<'_>>,
    out: &mut [T],
    f: impl Fn(PixelSum) -> T + Sync,
) -> RenderCounters {
    let cam = camera_rays(scene, camera, settings);
    let map = settings.path_map();
    let window = settings.window();
    let x0 = map.first_column();
    // Whitted transport traces runs of sixteen pixels of a row as packets
    // (`trace_camera_packet`); the pixels' sums are the same bits.
    let packets = matches!(
        settings.transport,
        Transport::Whitted | Transport::Radiosity
    );
    let caustics = caustic::applicable(scene, settings, &cam);
    out.par_chunks_mut(map.columns() as usize)
        .zip(map.rows().par_iter())
        .with_max_len(1)
        .map(|(row, &y)| {
            let mut counters = RenderCounters::default();
            if packets {
                for (c, run) in row.chunks_mut(COHERENT_LANES).enumerate() {
                    let x = x0 + (c * COHERENT_LANES) as u32;
                    let sums = camera_packet_sums(
                        scene,
                        settings,
                        &cam,
                        (x, y),
                        run.len(),
                        window.samples.clone(),
                        &mut counters,
                    );
                    for (px, sum) in run.iter_mut().zip(sums) {
                        *px = f(sum);
                    }
                }
                if let Some(p) = progress {
                    p(1);
                }
                return counters;
            }
            for (i, px) in row.iter_mut().enumerate() {
                let x = x0 + i as u32;
                let sum = pixel_sum(
                    scene,
                    settings,
                    &cam,
                    (x, y),
                    window.samples.clone(),
                    caustics,
                    &mut counters,
                );
                *px = f(sum);
            }
            if let Some(p) = progress {
                p(1);
            }
            counters
        })
        .reduce(RenderCounters::default, |mut a, b| {
            a.add(&b);
            a
        })
}

/// Renders every pixel of the settings' window with the recursive tracer,
/// rows in parallel: the whole image when the settings have no window,
/// else a film of the window's pixels (its columns by its rows, in order).
pub fn render(
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<Progress<'_>>,
) -> (Film, RenderCounters) {
    let window = settings.window();
    let mut film = Film::new(
        window.columns.end - window.columns.start,
        window.row_count(),
    );
    let mut counters = render_rows(scene, camera, settings, progress, &mut film.pixels, |s| {
        s.mean()
    });
    let cam = camera_rays(scene, camera, settings);
    if caustic::applicable(scene, settings, &cam) {
        let c = super::caustics::add_splats(scene, settings, &cam, &mut film, progress);
        counters.add(&c);
    } else if let Some(p) = progress {
        // Asked for, but nothing to trace (no mirror or glass, say): the
        // pass, if any, is done.
        let rows = caustic::light_pass_rows(settings);
        if rows > 0 {
            p(rows);
        }
    }
    (film, counters)
}

/// Like [`render`], but keeps each window pixel's exact sum and sample
/// count (for sample-range shards, which are merged by adding sums).
pub fn render_sums(
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<Progress<'_>>,
) -> (PixelAccumulator, RenderCounters) {
    let window = settings.window();
    let mut sums = PixelAccumulator::new(
        window.columns.end - window.columns.start,
        window.row_count(),
    );
    let counters = render_rows(scene, camera, settings, progress, sums.pixels_mut(), |s| s);
    (sums, counters)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{DVec3, Vec3};

    use super::*;
    use crate::accel::build::BuildQuality;
    use crate::geometry::mesh::{Mesh, NormalMode};
    use crate::geometry::shapes::Shape;
    use crate::geometry::transform::Transform;
    use crate::scene::instance::{Instance, InstanceGeometry};
    use crate::scene::light::Light;
    use crate::scene::material::Material;

    /// A ground plane, a torus-knot mesh, a mirror ball, a glass ball, a
    /// mirror disk and three point lights (three terms, so that the order
    /// in which they are added shows in the bits): every kind of ray of
    /// Whitted transport, and shadow rays blocked by shapes and by
    /// triangles.
    fn scene() -> RenderScene {
        let knot = crate::geometry::procedural::torus_knot(2, 3, 1.0, 0.3, 64, 8);
        let knot =
            Arc::new(Mesh::new("knot", knot, NormalMode::Smooth, BuildQuality::Medium).unwrap());
        let at = |x: f64, y: f64, z: f64| Transform::from_translation(DVec3::new(x, y, z));
        let instances = vec![
            Instance::new(
                InstanceGeometry::Shape(Shape::Plane),
                &Transform::default(),
                0,
            ),
            Instance::new(InstanceGeometry::Mesh(knot), &at(0.0, 1.2, 0.0), 1),
            Instance::new(
                InstanceGeometry::Shape(Shape::Sphere { radius: 0.6 }),
                &at(-2.0, 0.6, 0.5),
                2,
            ),
            Instance::new(
                InstanceGeometry::Shape(Shape::Sphere { radius: 0.5 }),
                &at(1.8, 0.5, 1.0),
                3,
            ),
            Instance::new(
                InstanceGeometry::Shape(Shape::Disk { radius: 3.0 }),
                &Transform::from(
                    glam::Affine3A::from_translation(Vec3::new(0.0, 2.0, -3.0))
                        * glam::Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2),
                ),
                2,
            ),
        ];
        let materials = vec![
            Material {
                base_color: Vec3::splat(0.6),
                ..Default::default()
            },
            Material {
                base_color: Vec3::new(0.8, 0.3, 0.2),
                specular: Vec3::splat(0.3),
                shininess: 40.0,
                ..Default::default()
            },
            Material {
                base_color: Vec3::splat(0.05),
                diffuse: 0.1,
                mirror: Vec3::splat(0.85),
                ..Default::default()
            },
            Material {
                base_color: Vec3::ONE,
                diffuse: 0.0,
                transmission: 1.0,
                ior: 1.5,
                ..Default::default()
            },
        ];
        let lights = vec![
            (
                Light::Point {
                    intensity: Vec3::splat(60.0),
                },
                at(-3.0, 5.0, 4.0),
            ),
            (
                Light::Point {
                    intensity: Vec3::new(30.0, 25.0, 20.0),
                },
                at(2.0, 4.0, -1.0),
            ),
            (
                Light::Point {
                    intensity: Vec3::new(7.0, 9.0, 11.0),
                },
                at(0.5, 6.0, 3.0),
            ),
        ];
        RenderScene::new(
            instances,
            materials,
            lights,
            Vec3::splat(0.1),
            BuildQuality::Medium,
        )
    }

    /// Under Whitted transport `render` traces runs of eight pixels as
    /// packets (camera rays, then each light's shadow rays); every pixel
    /// must be the bits that tracing it alone gives (`pixel_sum`, which
    /// calls `trace` ray by ray), and the ray counts the same: at one and
    /// at three samples per pixel, through a lens, with a width that is
    /// not a multiple of eight and a view whose middle packets point into
    /// two octants.
    #[test]
    fn camera_packets_give_the_bits_of_pixel_by_pixel_tracing() {
        let scene = scene();
        for (spp, lens_radius) in [(1, 0.0), (3, 0.0), (1, 0.05)] {
            let camera = Camera {
                look_from: DVec3::new(0.0, 3.0, 8.0),
                look_at: DVec3::new(0.0, 1.0, 0.0),
                vfov_degrees: 50.0,
                lens_radius,
                ..Default::default()
            };
            let settings = RenderSettings {
                width: 45,
                height: 30,
                spp,
                max_depth: 3,
                transport: Transport::Whitted,
                ..Default::default()
            };
            let (film, counters) = render(&scene, &camera, &settings, None);
            let cam = camera_rays(&scene, &camera, &settings);
            let mut alone = RenderCounters::default();
            for y in 0..settings.height {
                for x in 0..settings.width {
                    let sum = pixel_sum(&scene, &settings, &cam, (x, y), 0..spp, false, &mut alone);
                    let (p, q) = (film.pixels[(y * settings.width + x) as usize], sum.mean());
                    assert_eq!(
                        p.to_array().map(f32::to_bits),
                        q.to_array().map(f32::to_bits),
                        "spp {spp}, lens {lens_radius}: pixel ({x}, {y}): {p} vs {q}"
                    );
                }
            }
            assert_eq!(counters, alone, "spp {spp}, lens {lens_radius}");
            assert!(
                counters.rays.shadow > 0
                    && counters.rays.reflection > 0
                    && counters.rays.refraction > 0,
                "{counters:?}"
            );
        }
    }
}
