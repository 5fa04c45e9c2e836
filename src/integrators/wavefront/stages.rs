//! The stage kernels: each drains one queue and fills others.
//!
//! Plain functions over the queues of
//! [`queues`](crate::integrators::wavefront::queues); the ECS systems in
//! `systems/wavefront.rs` call them. The parallel stages drain their queue
//! with [`drain`](crate::integrators::wavefront::drain) and leave where
//! each result goes to [`routing`](crate::integrators::wavefront::routing).

use rayon::prelude::*;

use crate::accel::packet::LANES;
use crate::core::math::{Color, Ray, max_component};
use crate::core::rng::Sampler;
use crate::core::settings::{RenderSettings, Style, Transport};
use crate::core::window::PathMap;
use crate::image::film::PixelAccumulator;
use crate::integrators::counters::{RayCounts, RenderCounters};
use crate::integrators::wavefront::CHUNK;
use crate::integrators::wavefront::drain::{chunk_ranges, drain_chunks, drain_queue};
use crate::integrators::wavefront::queues::{
    ClosestHits, EscapedQueue, HitItem, HitQueue, RayItem, RayQueue, ShadowSegments,
};
use crate::integrators::wavefront::routing::{
    ClassHitQueues, ShadeOutput, ShadeTargets, join_shade_outputs, route_rays,
};
use crate::integrators::{accumulate, camera_ray};
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::scene::material::MaterialClass;
use crate::transport::gooch::gooch_shade;
use crate::transport::interaction::Interaction;
use crate::transport::medium::interior_transmittance;
use crate::transport::path::{self, LobeChoice};
use crate::transport::whitted::{direct_light, scatter};

/// Stage: one camera ray per path of the batch `[first, first + count)`,
/// made in parallel chunks. Path `p` goes where `paths` says (sample
/// `p % spp` of pixel `p / spp` for a whole image), with the same film
/// position and sample keys as the recursive tracer.
pub fn generate_camera_rays(
    camera: &CameraRays,
    settings: &RenderSettings,
    paths: &PathMap,
    first: u64,
    count: usize,
    out: &mut RayQueue,
    rays: &mut RayCounts,
) {
    out.fill_with(count, |local| {
        let k = paths.path(first + local as u64);
        let mut sampler = Sampler::with_kind(
            settings.sampler,
            settings.seed,
            k.pixel(settings.width),
            k.sample,
        );
        RayItem {
            ray: camera_ray(camera, k.x, k.y, settings.spp, &mut sampler),
            throughput: Color::ONE,
            path: local as u32,
            depth: 0,
            pdf: 0.0,
            cone: camera.cone(),
        }
    });
    rays.camera += count as u64;
}

/// Stage: closest hit for every ray of `rays`, written in place into
/// `found` (chunks traced in parallel), then each ray routed by index to
/// `escaped` or to the hit queue of the material's class.
pub fn intersect_closest(
    scene: &RenderScene,
    classes: &[MaterialClass],
    rays: &RayQueue,
    found: &mut ClosestHits,
    escaped: &mut EscapedQueue,
    hits: &mut impl ClassHitQueues,
) {
    // Eight neighbouring rays pointing into one octant go through the top
    // level and the meshes as one packet: coherent rays (camera rays,
    // mirror bounces) share the nodes, and a packet whose lanes diverge is
    // finished ray by ray (`crate::accel::packet`); rays pointing apart
    // are traced one at a time. Measured faster than mesh streams for
    // camera and for secondary rays since meshes have their own 8-wide
    // layout (README, "Measurement notes").
    let n = rays.len();
    found.0.clear();
    found.0.resize(n, None);
    found
        .0
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, out)| {
            for (k, lanes) in out.chunks_mut(LANES).enumerate() {
                let i = c * CHUNK + k * LANES;
                let m = lanes.len();
                let packet: [Ray; LANES] = std::array::from_fn(|l| rays.ray(i + l.min(m - 1)));
                if one_octant(&packet[..m]) {
                    scene.intersect_packet_with(&packet[..m], lanes, true);
                } else {
                    for (f, r) in lanes.iter_mut().zip(&packet[..m]) {
                        *f = scene.intersect(r, 0.0, f32::INFINITY);
                    }
                }
            }
        });
    route_rays(classes, &found.0, escaped, hits);
}

/// Whether all `rays` point into one octant: the packets worth tracing
/// together (others are traced one at a time, which costs them less).
fn one_octant(rays: &[Ray]) -> bool {
    let octant = |r: &Ray| {
        let d = r.direction;
        (d.x.is_sign_negative() as u8)
            | (d.y.is_sign_negative() as u8) << 1
            | (d.z.is_sign_negative() as u8) << 2
    };
    let first = octant(&rays[0]);
    rays.iter().all(|r| octant(r) == first)
}

/// Stage: escaped rays bring back the background, or the environment
/// (weighted against its next-event samples under path transport, as
/// [`path::escaped`] weighs it).
pub fn handle_escaped_rays(
    scene: &RenderScene,
    settings: &RenderSettings,
    rays: &RayQueue,
    escaped: &EscapedQueue,
    radiance: &mut [Color],
) {
    if scene.environment().is_none() {
        let background = scene.background();
        for &i in &escaped.ray {
            let i = i as usize;
            radiance[rays.path[i] as usize] += rays.throughput[i] * background;
        }
        return;
    }
    for &i in &escaped.ray {
        let i = i as usize;
        let l = path::escaped(scene, settings, rays.direction[i], rays.pdf[i]);
        radiance[rays.path[i] as usize] += rays.throughput[i] * l;
    }
}

/// Per-chunk buffers of the shading stages.
pub type ShadeScratch = Vec<ShadeOutput>;

/// What a shading stage reads: the bounce's rays, their closest hits and
/// the hit queue of the class it shades (indices into both).
#[derive(Clone, Copy)]
pub struct ShadeInput<'a> {
    /// Rays of the bounce.
    pub rays: &'a RayQueue,
    /// Their closest hits.
    pub found: &'a ClosestHits,
    /// The rays whose hits this stage shades.
    pub hits: &'a HitQueue,
}

/// Runs `kernel` on every hit of `input.hits` with its interaction, in
/// parallel chunks each writing its own [`ShadeOutput`], then joins the
/// outputs in chunk order.
fn shade_hits(
    scene: &RenderScene,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
    kernel: impl Fn(&HitItem, &Interaction, &mut ShadeOutput) + Sync,
) {
    let ShadeInput { rays, found, hits } = input;
    let outputs = drain_queue(hits.len(), scratch, |range, out| {
        out.clear();
        for &i in &hits.ray[range] {
            let i = i as usize;
            let Some(hit) = &found.0[i] else {
                debug_assert!(false, "ray {i} is queued for shading without a hit");
                continue;
            };
            let mut h = HitItem::new(hit, &rays.get(i));
            let it =
                Interaction::with_cone(scene, &Ray::new(h.point, h.direction), &h.hit(), h.cone);
            // A segment that ran through an absorbing interior carries its
            // transmittance to everything seen at its end.
            if let Some(tr) = interior_transmittance(&it, h.distance) {
                h.throughput *= tr;
            }
            kernel(&h, &it, out);
        }
    });
    join_shade_outputs(outputs, to);
}

/// Stage, Whitted transport: shades every hit of one material class.
/// Emission goes straight to the path's radiance; lit classes push one
/// shadow ray per light that can contribute; scattering classes push
/// reflection and refraction rays above the contribution threshold, up to
/// the maximum depth.
///
/// `LIT` and `SCATTER` select the lobes the class has, so each class's
/// kernel runs only the code it needs. Within a chunk, reflection rays go
/// before refraction rays, so that neighbouring rays of the next bounce
/// are alike.
pub fn shade<const LIT: bool, const SCATTER: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    shade_hits(scene, input, scratch, to, |h, it, out| {
        if it.surface.emission != Color::ZERO {
            out.emit(h.path, h.throughput * it.surface.emission);
        }
        if LIT && it.is_lit_by_lights() && settings.style == Style::Gooch {
            out.emit(
                h.path,
                h.throughput * gooch_shade(&settings.gooch, scene.lights(), it),
            );
        } else if LIT && it.is_lit_by_lights() {
            for light in scene.lights() {
                if let Some(q) = direct_light(it, light) {
                    out.push_shadow(h, q);
                }
            }
        }
        if SCATTER && h.depth < settings.max_depth {
            for s in scatter(it).into_iter().flatten() {
                let t = h.throughput * s.weight;
                if max_component(t) < settings.min_contribution {
                    continue;
                }
                let item = RayItem {
                    ray: s.ray,
                    throughput: t,
                    path: h.path,
                    depth: h.depth + 1,
                    pdf: 0.0,
                    cone: it.cone,
                };
                out.push_secondary(s.kind, item);
            }
        }
    });
}

/// Stage, path transport: shades every hit of one material class. Each
/// hit adds its MIS-weighted emission, pushes next-event shadow rays
/// (`NEE`: the class has a lobe lights can reach) and at most one
/// continuation ray (`SCATTER`), chosen as the recursive tracer chooses it
/// from the same sample numbers. `first` is the batch's first path.
pub fn shade_path<const NEE: bool, const SCATTER: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    paths: &PathMap,
    first: u64,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    shade_hits(scene, input, scratch, to, |h, it, out| {
        let e = path::emitted(scene, settings, it, h.instance, h.pdf, h.distance);
        if e != Color::ZERO {
            out.emit(h.path, h.throughput * e);
        }
        if !NEE && !SCATTER {
            return;
        }
        let (pixel, sample) = paths.sampler_keys(first + h.path as u64);
        let mut sampler = Sampler::with_kind(settings.sampler, settings.seed, pixel, sample);
        let lambda = path::path_wavelength(scene, settings, &mut sampler);
        let spectral;
        let it = if lambda.is_some() {
            let mut at = *it;
            path::at_wavelength(&mut at, lambda);
            spectral = at;
            &spectral
        } else {
            it
        };
        let lobes = LobeChoice::new(it);
        if NEE {
            path::next_event(scene, settings, it, &lobes, &mut sampler, h.depth, |q| {
                out.push_shadow(h, q)
            });
        }
        if SCATTER
            && let Some(cont) =
                path::continue_path(settings, it, &lobes, h.depth, h.throughput, &mut sampler)
        {
            let item = RayItem {
                ray: cont.sample.ray,
                throughput: h.throughput * cont.sample.weight * cont.scale,
                path: h.path,
                depth: h.depth + 1,
                pdf: cont.sample.pdf,
                cone: cont.cone(it),
            };
            out.push_secondary(cont.sample.kind, item);
        }
    });
}

/// Stage: shades the hits of `class` with the kernel for the lobes the
/// class has ([`MaterialClass::is_lit`], [`MaterialClass::scatters`]) and
/// the settings' transport; `first` is the batch's first path.
#[allow(clippy::too_many_arguments)]
pub fn shade_class(
    class: MaterialClass,
    scene: &RenderScene,
    settings: &RenderSettings,
    paths: &PathMap,
    first: u64,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    let lobes = (class.is_lit(), class.scatters());
    if settings.transport == Transport::Path {
        let f = match lobes {
            (false, false) => shade_path::<false, false>,
            (false, true) => shade_path::<false, true>,
            // Every lit class also scatters diffusely under path transport.
            (true, _) => shade_path::<true, true>,
        };
        return f(scene, settings, paths, first, input, scratch, to);
    }
    let f = match lobes {
        (false, false) => shade::<false, false>,
        (false, true) => shade::<false, true>,
        (true, false) => shade::<true, false>,
        (true, true) => shade::<true, true>,
    };
    f(scene, settings, input, scratch, to)
}

/// Reusable buffers of [`trace_shadow_rays`].
#[derive(Clone, Debug, Default)]
pub struct ShadowScratch {
    /// Each work chunk's segment and ray range, in queue order.
    work: Vec<(usize, std::ops::Range<usize>)>,
    /// Each work chunk's visibility flags.
    visible: Vec<Vec<bool>>,
}

impl ShadowScratch {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.work.capacity() * std::mem::size_of::<(usize, std::ops::Range<usize>)>()
            + self.visible.iter().map(|v| v.capacity()).sum::<usize>()
    }
}

/// Stage: traces every shadow ray, stopping at the first blocker, and adds
/// the radiance of the unblocked ones to their paths, in queue order.
///
/// Eight consecutive shadow rays (mostly one hit point's rays to eight
/// lights) go through the top level as a packet, and each lane traverses
/// meshes alone: whole packets, also with rays binned by light, were
/// measured slower than single rays, because the single-ray node test is
/// SIMD across a node's eight children already.
pub fn trace_shadow_rays(
    scene: &RenderScene,
    shadows: &ShadowSegments,
    scratch: &mut ShadowScratch,
    radiance: &mut [Color],
) {
    let ShadowScratch { work, visible } = scratch;
    // Work chunks of at most CHUNK rays, each within one segment.
    work.clear();
    for (s, seg) in shadows.segments().iter().enumerate() {
        work.extend(chunk_ranges(seg.len()).map(|range| (s, range)));
    }
    let work = &*work;
    let flags = drain_chunks(work.len(), visible, |c, flags| {
        let (s, range) = &work[c];
        let seg = &shadows.segments()[*s];
        flags.clear();
        flags.resize(range.len(), false);
        for (k, lanes) in flags.chunks_mut(LANES).enumerate() {
            let j = range.start + k * LANES;
            let rays: [Ray; LANES] = std::array::from_fn(|l| seg.ray(j + l.min(lanes.len() - 1)));
            let blocked = scene.occluded_packet_with(
                &rays[..lanes.len()],
                &seg.t_max[j..j + lanes.len()],
                false,
            );
            for (l, v) in lanes.iter_mut().enumerate() {
                *v = blocked & (1 << l) == 0;
            }
        }
    });
    for ((s, range), flags) in work.iter().zip(flags.iter()) {
        let seg = &shadows.segments()[*s];
        let rays = seg.path[range.clone()]
            .iter()
            .zip(&seg.radiance[range.clone()]);
        for ((&path, l), &visible) in rays.zip(flags) {
            if visible {
                radiance[path as usize] += *l;
            }
        }
    }
}

/// Stage: adds each finished path of the batch to its window pixel,
/// dropping and counting non-finite samples. The sums are exact, so the
/// order in which paths are added does not matter.
///
/// In spectral mode (path transport of a scene with a dispersive
/// material) each path's radiance is first weighted by its wavelength's
/// RGB response, the wavelength drawn again from the path's sampler keys
/// as the shading stages drew it.
pub fn update_film(
    scene: &RenderScene,
    settings: &RenderSettings,
    radiance: &[Color],
    paths: &PathMap,
    first: u64,
    sums: &mut PixelAccumulator,
    counters: &mut RenderCounters,
) {
    let pixels = sums.pixels_mut();
    let n = paths.samples() as u64;
    let spectral = scene.is_spectral() && settings.transport == Transport::Path;
    for (local, &l) in radiance.iter().enumerate() {
        let pixel = ((first + local as u64) / n) as usize;
        let l = if spectral {
            let (key, sample) = paths.sampler_keys(first + local as u64);
            let mut sampler = Sampler::with_kind(settings.sampler, settings.seed, key, sample);
            path::weigh_wavelength(l, path::path_wavelength(scene, settings, &mut sampler))
        } else {
            l
        };
        accumulate(&mut pixels[pixel], l, counters);
    }
}
