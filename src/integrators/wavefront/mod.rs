//! Wavefront kernels: each stage drains one queue and fills others.
//!
//! These are plain functions over the queues in [`crate::integrators::wavefront::queues`]; the ECS
//! systems in `systems/wavefront.rs` call them, and the order of the
//! stages is declared there, once. Every stage
//! splits its queue into fixed-size chunks processed in parallel and joins
//! the chunks' output in chunk order, so queue contents, and therefore
//! images, do not depend on the number of threads.
//!
//! The math is the recursive tracer's: [`scene::RenderScene::intersect`],
//! [`shading::Interaction`], [`shading::direct_light`] and
//! [`shading::scatter`]. Only the control flow differs.
//!
//! [`scene::RenderScene::intersect`]: crate::scene::RenderScene::intersect
//! [`shading::Interaction`]: crate::transport::interaction::Interaction
//! [`shading::direct_light`]: crate::transport::interaction::direct_light
//! [`shading::scatter`]: crate::transport::interaction::scatter

pub mod queues;

use rayon::prelude::*;

use crate::accel::packet::LANES;
use crate::core::math::Ray;
use crate::core::math::{Color, max_component};
use crate::core::rng::Sampler;
use crate::core::settings::{RenderSettings, Transport};
use crate::image::film::PixelAccumulator;
use crate::integrators::wavefront::queues::{
    EscapedQueue, HitItem, HitQueue, QueueBytes, RayItem, RayQueue, ShadowItem, ShadowQueue,
    ShadowSegments,
};
use crate::integrators::{accumulate, film_sample};
use crate::scene::camera::CameraRays;
use crate::scene::material::MaterialClass;
use crate::scene::{Hit, InstanceGeometry, RenderScene, StreamScratch};
use crate::transport::path::{self, LobeChoice};

/// Per-chunk routing buffers of [`intersect_closest`], kept between calls.
pub type RoutingScratch = Vec<(EscapedQueue, ClassQueues, StreamBuffers)>;

use crate::integrators::counters::{RayCounts, RenderCounters};
use crate::transport::interaction::{Interaction, RayKind, ShadowQuery, direct_light, scatter};

/// One chunk's buffers for tracing its rays as streams.
#[derive(Debug, Default)]
pub struct StreamBuffers {
    rays: Vec<Ray>,
    hits: Vec<Option<Hit>>,
    scratch: StreamScratch,
}

impl StreamBuffers {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.rays.capacity() * std::mem::size_of::<Ray>()
            + self.hits.capacity() * std::mem::size_of::<Option<Hit>>()
            + self.scratch.bytes()
    }
}

/// Items per parallel work chunk: large enough to amortise scheduling,
/// small enough to balance two to a few dozen threads.
pub const CHUNK: usize = 1024;

/// Default number of paths (pixel samples) per batch. Render time hardly
/// depends on it between 2048 and 65536 on the benchmark scenes (measured
/// with `prism render --batch-paths`), but queue memory grows with it: with
/// 48 lights a batch of 65536 paths held 466 MB of queues, 8192 hold 58 MB.
pub const DEFAULT_BATCH_PATHS: usize = 1 << 13;

/// Wall time spent in each stage, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageSeconds {
    /// Generating camera rays.
    pub generate_camera_rays: f64,
    /// Closest-hit traversal and routing of rays to queues.
    pub intersect_closest: f64,
    /// Adding the background for escaped rays.
    pub handle_escaped_rays: f64,
    /// Shading, all material classes.
    pub shade: f64,
    /// Tracing shadow rays.
    pub trace_shadow_rays: f64,
    /// Adding finished paths to the film.
    pub update_film: f64,
}

impl StageSeconds {
    /// Sum of all stages.
    pub fn total(&self) -> f64 {
        self.generate_camera_rays
            + self.intersect_closest
            + self.handle_escaped_rays
            + self.shade
            + self.trace_shadow_rays
            + self.update_film
    }
}

/// Hit queues, one per material class.
#[derive(Clone, Debug, Default)]
pub struct ClassQueues {
    /// One queue per [`MaterialClass`], indexed by `class as usize`.
    pub queues: [HitQueue; 5],
}

impl ClassQueues {
    /// The queue of `class`.
    pub fn get(&self, class: MaterialClass) -> &HitQueue {
        &self.queues[class as usize]
    }

    /// Bytes allocated by all five queues.
    pub fn bytes(&self) -> usize {
        self.queues.iter().map(|q| q.bytes()).sum()
    }
}

/// Where each batch starts and how many paths it has.
pub fn batch_ranges(
    settings: &RenderSettings,
    batch_paths: usize,
) -> impl Iterator<Item = (u64, usize)> {
    let total = settings.width as u64 * settings.height as u64 * settings.spp as u64;
    let step = batch_paths.max(1) as u64;
    (0..total.div_ceil(step)).map(move |b| {
        let first = b * step;
        (first, (total - first).min(step) as usize)
    })
}

/// Stage: one camera ray per path of the batch `[first, first + count)`.
/// Path `p` is sample `p % spp` of pixel `p / spp`, with the same film
/// position and sample keys as the recursive tracer.
pub fn generate_camera_rays(
    camera: &CameraRays,
    settings: &RenderSettings,
    first: u64,
    count: usize,
    out: &mut RayQueue,
    rays: &mut RayCounts,
) {
    out.clear();
    let spp = settings.spp as u64;
    let width = settings.width as u64;
    for local in 0..count {
        let p = first + local as u64;
        let pixel = p / spp;
        let sample = (p % spp) as u32;
        let (x, y) = ((pixel % width) as u32, (pixel / width) as u32);
        let mut sampler = Sampler::new(settings.seed, pixel as u32, sample);
        let ray = camera.ray(film_sample(x, y, settings.spp, &mut sampler));
        out.push(RayItem {
            ray,
            throughput: Color::ONE,
            path: local as u32,
            depth: 0,
            pdf: 0.0,
        });
    }
    rays.camera += count as u64;
}

/// One reusable output buffer per [`CHUNK`] of `items` work items: grows
/// `buffers` when needed and returns the ones this call uses.
fn chunk_buffers<T: Default>(buffers: &mut Vec<T>, items: usize) -> &mut [T] {
    let chunks = items.div_ceil(CHUNK);
    if buffers.len() < chunks {
        buffers.resize_with(chunks, Default::default);
    }
    &mut buffers[..chunks]
}

/// Stage: closest hit for every ray of `rays`; misses go to `escaped`,
/// hits to the queue of their material's class. Chunks are traced and
/// routed in parallel into `scratch` queues, then appended in chunk order.
pub fn intersect_closest(
    scene: &RenderScene,
    classes: &[MaterialClass],
    rays: &RayQueue,
    scratch: &mut RoutingScratch,
    escaped: &mut EscapedQueue,
    hits: &mut ClassQueues,
) {
    let chunks = rays.len().div_ceil(CHUNK);
    // Streams pay only where there is a mesh to traverse.
    let use_streams = scene
        .instances
        .iter()
        .any(|i| matches!(i.geometry, InstanceGeometry::Mesh(_)));
    chunk_buffers(scratch, rays.len())
        .par_iter_mut()
        .enumerate()
        .for_each(|(c, (esc, local, streams))| {
            esc.clear();
            for q in &mut local.queues {
                q.clear();
            }
            let end = ((c + 1) * CHUNK).min(rays.len());
            let mut route = |i: usize, found: Option<Hit>| match found {
                None => esc.push(rays.path[i], rays.throughput[i]),
                Some(h) => {
                    let class = classes[h.material as usize];
                    local.queues[class as usize].push(HitItem::new(&h, &rays.get(i)));
                }
            };
            if use_streams {
                // The top level in packets of eight, then every mesh with
                // one stream per direction octant for the whole chunk
                // (see `crate::accel::stream`): measured faster than packets of
                // eight for camera rays as well as for secondary rays,
                // which share a mesh's upper nodes even where packets of
                // eight share nothing.
                let StreamBuffers {
                    rays: r,
                    hits,
                    scratch,
                } = streams;
                r.clear();
                r.extend((c * CHUNK..end).map(|i| rays.ray(i)));
                hits.clear();
                hits.resize(r.len(), None);
                scene.intersect_stream(r, hits, scratch);
                for (k, h) in hits.iter().enumerate() {
                    route(c * CHUNK + k, *h);
                }
                return;
            }
            let mut found = [None; LANES];
            for i in c * CHUNK..end {
                let lane = (i - c * CHUNK) % LANES;
                if lane == 0 {
                    // No mesh: eight neighbouring rays go through the top
                    // level as one packet.
                    let n = (end - i).min(LANES);
                    let packet: [Ray; LANES] = std::array::from_fn(|l| rays.ray(i + l.min(n - 1)));
                    scene.intersect_packet_with(&packet[..n], &mut found, true);
                }
                route(i, found[lane]);
            }
        });
    for (esc, local, _) in &scratch[..chunks] {
        escaped.append(esc);
        for (q, l) in hits.queues.iter_mut().zip(&local.queues) {
            q.append(l);
        }
    }
}

/// Stage: escaped rays bring back the background.
pub fn handle_escaped_rays(escaped: &EscapedQueue, background: Color, radiance: &mut [Color]) {
    for (&path, &t) in escaped.path.iter().zip(&escaped.throughput) {
        radiance[path as usize] += t * background;
    }
}

/// What one chunk of a shading stage produced; kept between calls so
/// shading allocates nothing once the buffers have grown.
#[derive(Default, Debug)]
pub struct ShadeOutput {
    emitted: Vec<(u32, Color)>,
    shadows: ShadowQueue,
    reflections: RayQueue,
    refractions: RayQueue,
    counts: RayCounts,
}

impl ShadeOutput {
    fn clear(&mut self) {
        self.emitted.clear();
        self.shadows.clear();
        self.reflections.clear();
        self.refractions.clear();
        self.counts = RayCounts::default();
    }

    /// Bytes allocated for reflection and refraction rays.
    pub fn secondary_bytes(&self) -> usize {
        self.reflections.bytes() + self.refractions.bytes()
    }

    /// Bytes allocated for refraction rays.
    pub fn refraction_bytes(&self) -> usize {
        self.refractions.bytes()
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.emitted.capacity() * std::mem::size_of::<(u32, Color)>()
            + self.shadows.bytes()
            + self.reflections.bytes()
            + self.refractions.bytes()
    }
}

impl ShadeOutput {
    /// Queues the shadow ray of `q` for hit `h` and counts it.
    #[inline]
    fn push_shadow(&mut self, h: &HitItem, q: ShadowQuery) {
        self.counts.shadow += 1;
        self.shadows.push(ShadowItem {
            ray: q.ray,
            t_max: q.t_max,
            radiance: h.throughput * q.radiance,
            path: h.path,
        });
    }

    /// Queues a reflection or refraction ray and counts it.
    #[inline]
    fn push_secondary(&mut self, kind: RayKind, item: RayItem) {
        if kind == RayKind::Refraction {
            self.counts.refraction += 1;
            self.refractions.push(item);
        } else {
            self.counts.reflection += 1;
            self.reflections.push(item);
        }
    }
}

/// Per-chunk buffers of the shading stages.
pub type ShadeScratch = Vec<ShadeOutput>;

/// The queues a shading stage adds to: path radiance, shadow rays, next
/// rays and ray counts.
type ShadeTargets<'a> = (
    &'a mut [Color],
    &'a mut ShadowSegments,
    &'a mut RayQueue,
    &'a mut RayCounts,
);

/// Runs `kernel` on every hit of `hits` with its interaction, in parallel
/// chunks of [`CHUNK`] hits each writing its own [`ShadeOutput`], then joins
/// the outputs in chunk order.
fn shade_hits(
    scene: &RenderScene,
    hits: &HitQueue,
    scratch: &mut ShadeScratch,
    (radiance, shadows, next, rays): ShadeTargets<'_>,
    kernel: impl Fn(&HitItem, &Interaction, &mut ShadeOutput) + Sync,
) {
    let chunks = hits.len().div_ceil(CHUNK);
    chunk_buffers(scratch, hits.len())
        .par_iter_mut()
        .enumerate()
        .for_each(|(c, out)| {
            out.clear();
            let end = ((c + 1) * CHUNK).min(hits.len());
            for i in c * CHUNK..end {
                let h = hits.get(i);
                let it = Interaction::new(scene, &Ray::new(h.point, h.direction), &h.hit());
                kernel(&h, &it, out);
            }
        });
    merge_shade_outputs(&mut scratch[..chunks], radiance, shadows, next, rays);
}

/// Joins the shading chunks' output in chunk order: emission into the
/// paths' radiance, shadow segments handed over, then every chunk's
/// reflection rays before every chunk's refraction rays (so neighbouring
/// rays of the next bounce are alike).
fn merge_shade_outputs(
    outputs: &mut [ShadeOutput],
    radiance: &mut [Color],
    shadows: &mut ShadowSegments,
    next: &mut RayQueue,
    rays: &mut RayCounts,
) {
    for out in outputs.iter_mut() {
        for &(path, l) in &out.emitted {
            radiance[path as usize] += l;
        }
        shadows.take(&mut out.shadows);
        next.append(&out.reflections);
        rays.add(&out.counts);
    }
    for out in outputs.iter() {
        next.append(&out.refractions);
    }
}

/// Stage: shades every hit of one material class. Emission goes straight
/// to the path's radiance; lit classes push one shadow ray per light that
/// can contribute; scattering classes push reflection and refraction rays
/// above the contribution threshold, up to the maximum depth.
///
/// `LIT` and `SCATTER` select the lobes the class has, so each class's
/// kernel runs only the code it needs. Within a chunk, reflection rays go
/// before refraction rays, so that neighbouring rays of the next bounce
/// are alike.
#[allow(clippy::too_many_arguments)]
pub fn shade<const LIT: bool, const SCATTER: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    hits: &HitQueue,
    scratch: &mut ShadeScratch,
    radiance: &mut [Color],
    shadows: &mut ShadowSegments,
    next: &mut RayQueue,
    rays: &mut RayCounts,
) {
    let outputs = (radiance, shadows, next, rays);
    shade_hits(scene, hits, scratch, outputs, |h, it, out| {
        if it.surface.emission != Color::ZERO {
            out.emitted
                .push((h.path, h.throughput * it.surface.emission));
        }
        if LIT && it.is_lit_by_lights() {
            for light in &scene.lights {
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
                };
                out.push_secondary(s.kind, item);
            }
        }
    });
}

/// Shades the hits of `class` with the kernel for that class and the
/// settings' transport; `first` is the batch's first path.
#[allow(clippy::too_many_arguments)]
pub fn shade_class(
    class: MaterialClass,
    scene: &RenderScene,
    settings: &RenderSettings,
    first: u64,
    hits: &HitQueue,
    scratch: &mut ShadeScratch,
    radiance: &mut [Color],
    shadows: &mut ShadowSegments,
    next: &mut RayQueue,
    rays: &mut RayCounts,
) {
    if settings.transport == Transport::Path {
        // Every lit class also scatters diffusely under path transport.
        let f = match class {
            MaterialClass::Emissive => shade_path::<false, false>,
            MaterialClass::Diffuse | MaterialClass::General => shade_path::<true, true>,
            MaterialClass::Mirror | MaterialClass::Glass => shade_path::<false, true>,
        };
        return f(
            scene, settings, first, hits, scratch, radiance, shadows, next, rays,
        );
    }
    let f = match class {
        MaterialClass::Emissive => shade::<false, false>,
        MaterialClass::Diffuse => shade::<true, false>,
        MaterialClass::Mirror | MaterialClass::Glass => shade::<false, true>,
        MaterialClass::General => shade::<true, true>,
    };
    f(
        scene, settings, hits, scratch, radiance, shadows, next, rays,
    )
}

/// Stage, path transport: shades every hit of one material class. Each
/// hit adds its MIS-weighted emission, pushes next-event shadow rays
/// (`NEE`: the class has a lobe lights can reach) and at most one
/// continuation ray (`SCATTER`), chosen as the recursive tracer chooses it
/// from the same sample numbers.
#[allow(clippy::too_many_arguments)]
pub fn shade_path<const NEE: bool, const SCATTER: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    first: u64,
    hits: &HitQueue,
    scratch: &mut ShadeScratch,
    radiance: &mut [Color],
    shadows: &mut ShadowSegments,
    next: &mut RayQueue,
    rays: &mut RayCounts,
) {
    let spp = settings.spp as u64;
    let outputs = (radiance, shadows, next, rays);
    shade_hits(scene, hits, scratch, outputs, |h, it, out| {
        let e = path::emitted(scene, settings, it, h.instance, h.pdf, h.distance);
        if e != Color::ZERO {
            out.emitted.push((h.path, h.throughput * e));
        }
        if !NEE && !SCATTER {
            return;
        }
        let p = first + h.path as u64;
        let mut sampler = Sampler::new(settings.seed, (p / spp) as u32, (p % spp) as u32);
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
            };
            out.push_secondary(cont.sample.kind, item);
        }
    });
}

/// Reusable buffers of [`trace_shadow_rays`].
#[derive(Clone, Debug, Default)]
pub struct ShadowScratch {
    visible: Vec<bool>,
}

impl ShadowScratch {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.visible.capacity()
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
    let visible = &mut scratch.visible;
    visible.clear();
    visible.resize(shadows.len(), false);
    // Work items of at most CHUNK rays, each within one segment, paired
    // with their slice of the visibility flags (in queue order).
    let mut work: Vec<(&ShadowQueue, usize, &mut [bool])> = Vec::new();
    let mut rest: &mut [bool] = visible;
    for seg in shadows.segments() {
        let mut start = 0;
        while start < seg.len() {
            let n = (seg.len() - start).min(CHUNK);
            let (head, tail) = rest.split_at_mut(n);
            work.push((seg, start, head));
            rest = tail;
            start += n;
        }
    }
    work.par_iter_mut().for_each(|(seg, start, out)| {
        for (k, lanes) in out.chunks_mut(LANES).enumerate() {
            let j = *start + k * LANES;
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
    let mut flags = visible.iter();
    for seg in shadows.segments() {
        for (&path, l) in seg.path.iter().zip(&seg.radiance) {
            if *flags.next().expect("one flag per ray") {
                radiance[path as usize] += *l;
            }
        }
    }
}

/// Stage: adds each finished path of the batch to its pixel, in path
/// order (so samples are summed in the same order as the recursive
/// tracer sums them), dropping and counting non-finite samples.
pub fn update_film(
    radiance: &[Color],
    first: u64,
    spp: u32,
    sums: &mut PixelAccumulator,
    counters: &mut RenderCounters,
) {
    let pixels = sums.pixels_mut();
    for (local, &l) in radiance.iter().enumerate() {
        let pixel = ((first + local as u64) / spp as u64) as usize;
        accumulate(&mut pixels[pixel], l, counters);
    }
}

/// How many times each stage system ran during a frame: stages a scene
/// does not need never run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct StageRuns {
    /// Camera ray generation (once per batch).
    pub generate_camera_rays: u32,
    /// Closest-hit traversal (once per bounce).
    pub intersect_closest: u32,
    /// Escaped-ray handling.
    pub handle_escaped_rays: u32,
    /// Shading of emissive-only materials.
    pub shade_emissive: u32,
    /// Shading of diffuse/glossy materials.
    pub shade_diffuse: u32,
    /// Shading of mirrors (the reflection stage).
    pub shade_mirror: u32,
    /// Shading of glass (the refraction stage).
    pub shade_glass: u32,
    /// Shading of materials with several lobes.
    pub shade_general: u32,
    /// Shadow-ray tracing.
    pub trace_shadow_rays: u32,
    /// Film update (once per batch).
    pub update_film: u32,
}

impl StageRuns {
    /// The shading counter of `class`.
    pub fn shade_mut(&mut self, class: MaterialClass) -> &mut u32 {
        match class {
            MaterialClass::Emissive => &mut self.shade_emissive,
            MaterialClass::Diffuse => &mut self.shade_diffuse,
            MaterialClass::Mirror => &mut self.shade_mirror,
            MaterialClass::Glass => &mut self.shade_glass,
            MaterialClass::General => &mut self.shade_general,
        }
    }

    /// Names of the stages that ran at least once, in stage order.
    pub fn names_run(&self) -> Vec<&'static str> {
        [
            ("generate_camera_rays", self.generate_camera_rays),
            ("intersect_closest", self.intersect_closest),
            ("handle_escaped_rays", self.handle_escaped_rays),
            ("shade_emissive", self.shade_emissive),
            ("shade_diffuse", self.shade_diffuse),
            ("shade_mirror", self.shade_mirror),
            ("shade_glass", self.shade_glass),
            ("shade_general", self.shade_general),
            ("trace_shadow_rays", self.trace_shadow_rays),
            ("update_film", self.update_film),
        ]
        .into_iter()
        .filter(|(_, n)| *n > 0)
        .map(|(name, _)| name)
        .collect()
    }
}

/// Everything the wavefront reports beyond the image.
#[derive(Clone, Copy, Debug, Default)]
pub struct WavefrontReport {
    /// Runs of each stage system.
    pub runs: StageRuns,
    /// Rays and dropped samples.
    pub counters: RenderCounters,
    /// Time per stage.
    pub stages: StageSeconds,
    /// Largest total of bytes held by all queues at once.
    pub peak_queue_bytes: usize,
    /// Number of batches.
    pub batches: usize,
}
