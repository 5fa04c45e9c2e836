//! The stage kernels: each drains one queue and fills others.
//!
//! Plain functions over the queues of
//! [`queues`](crate::integrators::wavefront::queues); the ECS systems in
//! `systems/wavefront.rs` call them. The parallel stages drain their queue
//! with [`drain`](crate::integrators::wavefront::drain) and leave where
//! each result goes to [`routing`](crate::integrators::wavefront::routing).

use rayon::prelude::*;

use crate::accel::packet::{LANES, LaneMask};
use crate::core::math::{Color, Ray, RayCone, max_component, one_octant};
use crate::core::rng::{KeptSlot, SET_LANES, Sampler, SamplerSeed, SetRequest, sobol_sets};
use crate::core::settings::{RenderSettings, Style, Transport};
use crate::core::window::PathMap;
use crate::image::film::PixelAccumulator;
use crate::integrators::counters::{RayCounts, RenderCounters};
use crate::integrators::wavefront::CHUNK;
use crate::integrators::wavefront::drain::drain_queue;
use crate::integrators::wavefront::queues::{
    ClosestHits, EscapedQueue, HitItem, HitQueue, RayItem, RayQueue, ShadowSegments,
};
use crate::integrators::wavefront::routing::{
    ClassHitQueues, ShadeOutput, ShadeTargets, join_shade_outputs, route_rays,
};
use crate::integrators::{accumulate, camera_ray_paired};
use crate::scene::Hit;
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::scene::light::WorldLight;
use crate::scene::material::MaterialClass;
use crate::scene::polygons::{BATCH_LANES, PolygonBatch};
use crate::scene::query::COHERENT_LANES;
use crate::scene::triangles::TriangleBatch;
use crate::transport::gooch::gooch_shade;
use crate::transport::interaction::Interaction;
use crate::transport::medium::interior_transmittance;
use crate::transport::path::{self, LobeChoice};
use crate::transport::volume::{self, SegmentEnd};
use crate::transport::whitted::{
    HitLanes, LIGHT_LANES, LightLanes, direct_light, direct_point_lights, scatter,
};

/// Stage: one camera ray per path of the batch `[first, first + count)`,
/// made in parallel chunks. Path `p` goes where `paths` says (sample
/// `p % spp` of pixel `p / spp` for a whole image), with the same film
/// position and sample keys as the recursive tracer.
///
/// A path-traced frame that splits ([`RenderSettings::split`] `k > 1`)
/// gives each path `1 + k` slots ([`RenderSettings::path_slots`]): its
/// camera ray's at `p (1 + k)`, then its parts' at `p (1 + k) + 1 + j`,
/// whose sampler seeds are [`SamplerSeed::split`]`(j, k)`.
#[allow(clippy::too_many_arguments)]
pub fn generate_camera_rays(
    camera: &CameraRays,
    settings: &RenderSettings,
    paths: &PathMap,
    first: u64,
    count: usize,
    out: &mut RayQueue,
    seeds: &mut Vec<SamplerSeed>,
    kept: &mut Vec<KeptSlot>,
    rays: &mut RayCounts,
) {
    let seed = |k: &crate::core::window::PathKey| {
        SamplerSeed::new(
            settings.sampler,
            settings.seed,
            k.pixel(settings.width),
            k.sample,
        )
    };
    // Each chunk walks its consecutive paths' keys (`PathMap::paths_from`)
    // instead of dividing each path index out.
    let keys = |start: usize| paths.paths_from(first + start as u64);
    let slots = settings.path_slots();
    // Path transport draws numbers at every bounce: each path's sampler
    // keys are hashed once here, for the shading stages to start from.
    if settings.transport != Transport::Path {
        seeds.clear();
        kept.clear();
    } else {
        // Every path of the batch starts with no kept set (a slot holds
        // the previous batch's path of the same index until cleared).
        kept.resize_with(count * slots, KeptSlot::default);
        kept.par_iter()
            .with_min_len(CHUNK)
            .for_each(KeptSlot::clear);
        seeds.resize(count * slots, SamplerSeed::default());
        seeds
            .par_chunks_mut(CHUNK * slots)
            .zip(kept.par_chunks(CHUNK * slots))
            .enumerate()
            .with_max_len(1)
            .for_each(|(c, (s, kept))| {
                for (s, k) in s.chunks_mut(slots).zip(keys(c * CHUNK)) {
                    let camera = seed(&k);
                    s[0] = camera;
                    for (j, part) in s[1..].iter_mut().enumerate() {
                        *part = camera.split(j as u32, settings.split);
                    }
                }
                if slots > 1 {
                    prime_part_directions(s, kept, slots);
                }
            });
    }
    let seeds: &[SamplerSeed] = seeds;
    // The film position's Sobol set (set 0, which the lens shares) of the
    // chunk's paths, drawn sixteen side by side before the rays are made,
    // as the shading stages draw theirs (`PrimedSets`); none for one
    // sample per pixel (the pixel centre). Path transport keeps each
    // path's seed for the later bounces; the other transports make the
    // chunk's seeds here for the camera rays alone (each ray drew its
    // set by itself before: 3% of a Whitted render of
    // `assets/bench/diffuse_only.toml`, one thread).
    let chunk_seeds = |range: std::ops::Range<usize>| -> Vec<SamplerSeed> {
        if seeds.len() >= range.end * slots {
            range.map(|local| seeds[local * slots]).collect()
        } else {
            keys(range.start)
                .take(range.len())
                .map(|k| seed(&k))
                .collect()
        }
    };
    let film_sets = |chunk: &[SamplerSeed]| {
        let mut sets = Vec::new();
        if settings.spp > 1 {
            let requests: Option<Vec<SetRequest>> =
                chunk.iter().map(|s| s.sobol_request(0)).collect();
            if let Some(requests) = requests {
                sets.resize(requests.len(), [0.0; 4]);
                sobol_sets(&requests, &mut sets);
            }
        }
        sets
    };
    // A pinhole's one ray per pixel (through the pixel's centre) draws
    // no number: its rays are made without seeds. Hashing each path's
    // keys took this stage from 14 to 20 ms on
    // `assets/bench/camera_only.toml` (1M rays, one thread).
    let draws = settings.spp > 1 || camera.has_lens();
    let unused = SamplerSeed::default().sampler();
    out.fill_chunks(count, |range| {
        let chunk = if draws {
            chunk_seeds(range.clone())
        } else {
            Vec::new()
        };
        let sets = film_sets(&chunk);
        let start = range.start;
        keys(range.start).zip(range).map(move |(k, local)| {
            let mut sampler = if draws {
                chunk[local - start].sampler()
            } else {
                unused
            };
            if let Some(&set) = sets.get(local - start) {
                sampler.prime((0, set));
            }
            RayItem {
                ray: camera_ray_paired(camera, k.x, k.y, settings.spp, &mut sampler),
                throughput: Color::ONE,
                path: (local * slots) as u32,
                depth: 0,
                pdf: 0.0,
                cone: camera.cone(),
            }
        })
    });
    rays.camera += count as u64;
}

/// The first numbers a split path's parts draw, drawn side by side
/// ([`sobol_sets`]) into their kept slots: each part's BSDF direction set
/// of bounce 0 ([`path::direction_set`]), which the shading stage then
/// finds there instead of drawing it part by part. `seeds` and `kept`:
/// whole paths of `slots` slots each.
fn prime_part_directions(seeds: &[SamplerSeed], kept: &[KeptSlot], slots: usize) {
    let set = path::direction_set(0);
    let parts: Vec<usize> = (0..seeds.len()).filter(|i| i % slots != 0).collect();
    for chunk in parts.chunks(SET_LANES) {
        let requests: Option<Vec<SetRequest>> =
            chunk.iter().map(|&i| seeds[i].sobol_request(set)).collect();
        // The hash sampler has no sets to draw (nor has a part past the
        // Sobol sequence's end: its chunk draws its own).
        let Some(requests) = requests else {
            continue;
        };
        let mut numbers = [[0.0f32; 4]; SET_LANES];
        sobol_sets(&requests, &mut numbers[..requests.len()]);
        for (&i, &v) in chunk.iter().zip(&numbers) {
            kept[i].store((set, v));
        }
    }
}

/// Part of the camera-ray stage in spectral mode (path transport of a
/// scene with a dispersive material): each path's wavelength, drawn once
/// per batch from its sampler seed (`seeds`, as
/// [`generate_camera_rays`] made them) and read by the shading stages
/// and [`update_film`]; empty otherwise.
pub fn path_wavelengths(
    scene: &RenderScene,
    settings: &RenderSettings,
    seeds: &[SamplerSeed],
    out: &mut Vec<f32>,
) {
    if !(scene.is_spectral() && settings.transport == Transport::Path) {
        out.clear();
        return;
    }
    // A split path's parts take its camera path's wavelength.
    let slots = settings.path_slots();
    out.resize(seeds.len(), 0.0);
    out.par_chunks_mut(CHUNK * slots)
        .zip(seeds.par_chunks(CHUNK * slots))
        .with_max_len(1)
        .for_each(|(out, seeds)| {
            for (w, seed) in out.chunks_mut(slots).zip(seeds.chunks(slots)) {
                let lambda = path::path_wavelength(scene, settings, &mut seed[0].sampler());
                w.fill(lambda.unwrap_or(0.0));
            }
        });
}

/// Stage: closest hit for every ray of `rays`, written in place into
/// `found` (chunks traced in parallel), then each ray routed by index to
/// `escaped` or to the hit queue of the material's class.
///
/// Without `route` (a scene with media under path transport) the rays
/// are left unrouted, to be followed through the media by
/// [`sample_media`] first, which routes them.
pub fn intersect_closest(
    scene: &RenderScene,
    classes: &[MaterialClass],
    rays: &RayQueue,
    found: &mut ClosestHits,
    escaped: &mut EscapedQueue,
    hits: &mut impl ClassHitQueues,
    route: bool,
) {
    // Eight neighbouring rays pointing into one octant go through the top
    // level and the meshes as one packet: coherent rays (camera rays,
    // mirror bounces) share the nodes, and a packet whose lanes diverge is
    // finished ray by ray (`crate::accel::packet`); rays pointing apart
    // are traced one at a time. Measured faster than mesh streams for
    // camera and for secondary rays since meshes have their own 8-wide
    // layout (README, "Measurement notes").
    // Every slot is written below: keep what the last bounce left in the
    // slots (resizing fills only new ones) instead of clearing them first.
    //
    // A scene of a few polygons skips the top level: sixteen rays at a
    // time meet every polygon (`PolygonBatch`), the same hits. A scene of
    // one small merged mesh skips its BVH: the chunk's rays, sorted by
    // axis permutation, meet every triangle sixteen at a time
    // (`TriangleBatch`), the same hits (`assets/gltf/cornell.gltf` path
    // traced: 0.83-0.86x the wavefront's time, camera rays included).
    //
    // Camera rays (the first bounce: every ray at depth 0) go sixteen at a
    // time (`RenderScene::intersect_coherent`: one packet of 16 on the
    // AVX-512 path, packets of 8 elsewhere); later bounces, less coherent,
    // eight at a time.
    let n = rays.len();
    found.0.resize(n, None);
    let batch = PolygonBatch::new(scene);
    let camera = batch.is_none() && rays.depth.iter().all(|&d| d == 0);
    let width = if batch.is_some() {
        BATCH_LANES
    } else if camera {
        COHERENT_LANES
    } else {
        LANES
    };
    let triangles = TriangleBatch::new(scene);
    found
        .0
        .par_chunks_mut(CHUNK)
        .enumerate()
        .with_max_len(1)
        .for_each(|(c, out)| {
            if let Some(t) = &triangles {
                let chunk: Vec<Ray> = (0..out.len()).map(|k| rays.ray(c * CHUNK + k)).collect();
                t.intersect(&chunk, out);
                return;
            }
            for (k, lanes) in out.chunks_mut(width).enumerate() {
                let i = c * CHUNK + k * width;
                let m = lanes.len();
                let packet: [Ray; COHERENT_LANES] =
                    std::array::from_fn(|l| rays.ray(i + l.min(m - 1)));
                if let Some(b) = &batch {
                    b.intersect(scene, &packet[..m], lanes);
                } else if camera {
                    scene.intersect_coherent(&packet[..m], lanes);
                } else if one_octant(&packet[..m]) {
                    scene.intersect_packet_with(&packet[..m], lanes, true);
                } else {
                    for (f, r) in lanes.iter_mut().zip(&packet[..m]) {
                        *f = scene.intersect(r, 0.0, f32::INFINITY);
                    }
                }
            }
        });
    if route {
        route_rays(classes, &found.0, escaped, hits);
    }
}

/// How [`sample_media`] changed one ray: it now ends on `hit` (a surface)
/// or escapes (`None`), with `ray`, `throughput`, `depth`, `pdf` and
/// `cone` as the segment (or the unlit random walk that ended with it)
/// left them. Rays that scattered into the next bounce or were lost have
/// no update.
#[derive(Clone, Copy, Debug)]
struct SegmentUpdate {
    index: u32,
    ray: Ray,
    throughput: Color,
    depth: u32,
    pdf: f32,
    cone: RayCone,
    hit: Option<Hit>,
}

/// One chunk's buffers of [`sample_media`].
#[derive(Debug, Default)]
pub struct MediaChunk {
    updates: Vec<SegmentUpdate>,
    /// The chunk's rays that end on a surface or escape, in order: those
    /// of `updates` and those whose segment is plain (left as it is).
    routes: Vec<u32>,
    shaded: ShadeOutput,
    /// The chunk's rays that are not plain segments (their walks), and
    /// the first step's two Sobol sets of each walk that has them
    /// (`first_sets[2 k]`, `[2 k + 1]` for walk `owners[k]`).
    walks: Vec<u32>,
    owners: Vec<u32>,
    requests: Vec<SetRequest>,
    first_sets: Vec<[f32; 4]>,
}

impl std::borrow::Borrow<ShadeOutput> for MediaChunk {
    fn borrow(&self) -> &ShadeOutput {
        &self.shaded
    }
}

impl std::borrow::BorrowMut<ShadeOutput> for MediaChunk {
    fn borrow_mut(&mut self) -> &mut ShadeOutput {
        &mut self.shaded
    }
}

impl MediaChunk {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.updates.capacity() * std::mem::size_of::<SegmentUpdate>()
            + (self.routes.capacity() + self.walks.capacity() + self.owners.capacity())
                * std::mem::size_of::<u32>()
            + self.requests.capacity() * std::mem::size_of::<SetRequest>()
            + self.first_sets.capacity() * std::mem::size_of::<[f32; 4]>()
            + self.shaded.bytes()
    }
}

/// Per-chunk buffers of [`sample_media`], kept between calls.
pub type MediaScratch = Vec<MediaChunk>;

/// Where [`sample_media`] sends what it produces: the surfaces and
/// escapes at the segments' ends, and the light, shadow rays and next rays
/// of scattering events.
pub struct MediaTargets<'a> {
    /// Rays that left the scene.
    pub escaped: &'a mut EscapedQueue,
    /// Hits, by material class.
    pub hits: &'a mut dyn ClassHitQueues,
    /// Light, shadow rays, next rays and counts.
    pub shade: ShadeTargets<'a>,
}

/// Stage (path transport in a scene with media): follows every ray of
/// the bounce through the media with [`volume::propagate`], as the
/// recursive tracer does, starting from its closest hit in `found`. A
/// segment that ends on a surface or escapes is written back in place
/// (its ray, weighted throughput and end) and routed by index to its
/// class's hit queue or to the escaped queue; a segment through no
/// medium to a surface it does not cross ([`volume::is_plain_segment`],
/// most segments of most scenes with media) is only routed, its ray left
/// with its old origin, which no later stage reads (shading starts from
/// the hit, escapes from the direction). A scattering event traces its
/// next-event shadow rays ([`volume::medium_next_event`]) and adds their
/// light at once, then the walk goes on here with its next ray
/// ([`volume::continue_in_medium`]), one ray at a time as the recursive
/// tracer follows it, until it reaches a surface, escapes or is lost: a
/// walk of many steps costs one bounce of the queues, not one per step
/// (it had been one pass through every stage and queue per step, most of
/// them over a handful of rays late in a batch; a dense lit ball took 358
/// bounces of one batch, now 4). Each path's terms are added in the order
/// of its vertices, as the recursive tracer adds them: the light scattered
/// in along each segment and the shadow rays' light of each event go into
/// the chunk's emission in step order, and the surface the walk ends on
/// is shaded by a later stage of the same bounce. `seeds` holds each
/// path's sampler seed ([`generate_camera_rays`]). The two Sobol sets of
/// every walk's first step (the medium's numbers and the continuation's)
/// are drawn for the whole chunk at once, sixteen side by side, as the
/// shading stages draw theirs: `assets/fog.toml` path traced in 0.97x the
/// wavefront's time, the same image. (Drawing every step's sets side by
/// side, the chunk's walks taking their steps in lockstep, cost more in
/// moving the walks' state than it saved: 1.01x.)
#[allow(clippy::too_many_arguments)]
pub fn sample_media(
    scene: &RenderScene,
    settings: &RenderSettings,
    seeds: &[SamplerSeed],
    classes: &[MaterialClass],
    rays: &mut RayQueue,
    found: &mut ClosestHits,
    scratch: &mut MediaScratch,
    to: MediaTargets<'_>,
) {
    let rays_in: &RayQueue = rays;
    let found_in: &ClosestHits = found;
    let chunks = drain_queue(rays_in.len(), scratch, |range, chunk| {
        let MediaChunk {
            updates,
            routes,
            shaded,
            walks,
            owners,
            requests,
            first_sets,
        } = chunk;
        updates.clear();
        routes.clear();
        shaded.clear();
        walks.clear();
        owners.clear();
        requests.clear();
        // A segment through no medium to a surface it does not cross (or
        // out of the scene) stays as it is: only routed, with no sampler
        // made, no copy of the ray and its hit. The others start a walk.
        // Each walk's first step draws two Sobol sets, the medium's and
        // the continuation's, when its first part runs through a
        // scattering medium: requested here for all the chunk's walks and
        // drawn sixteen side by side ([`sobol_sets`]), as the shading
        // stages draw theirs. Later steps, one walk at a time, draw their
        // own.
        for i in range.clone() {
            let (hit, dir) = (found_in.0[i].as_ref(), rays_in.direction[i]);
            let medium = volume::segment_medium(scene, hit, dir);
            if volume::is_plain_segment_in(scene, medium.as_ref(), hit, dir) {
                continue;
            }
            let k = walks.len() as u32;
            walks.push(i as u32);
            if !medium.is_some_and(|m| m.scatters()) {
                continue;
            }
            let (path, depth) = (rays_in.path[i], rays_in.depth[i]);
            let seed = &seeds[path as usize];
            let medium_set = seed.sobol_request(volume::medium_dimension(depth, 0) / 4);
            let next_set = seed.sobol_request(volume::continue_dimension(settings, depth) / 4);
            if let (Some(m), Some(n)) = (medium_set, next_set) {
                requests.extend([m, n]);
                owners.push(k);
            }
        }
        first_sets.resize(requests.len(), [0.0; 4]);
        sobol_sets(requests, &mut first_sets[..requests.len()]);
        let mut walk = 0usize;
        let mut owner = 0usize;
        for i in range {
            if walks.get(walk) != Some(&(i as u32)) {
                routes.push(i as u32);
                continue;
            }
            // The first step's sets, when this walk has them.
            let mut primed = None;
            if owners.get(owner) == Some(&(walk as u32)) {
                primed = Some((first_sets[2 * owner], first_sets[2 * owner + 1]));
                owner += 1;
            }
            walk += 1;
            let mut item = rays_in.get(i);
            let mut sampler = seeds[item.path as usize].sampler();
            let mut found = found_in.0[i];
            // One segment per pass; passes after the first follow an unlit
            // random walk (see above).
            loop {
                if let Some((medium, _)) = primed {
                    sampler.prime((volume::medium_dimension(item.depth, 0) / 4, medium));
                }
                let seg = volume::propagate(
                    scene,
                    &item.ray,
                    found,
                    item.depth,
                    item.throughput,
                    &mut sampler,
                );
                shaded.count_rays(seg.rays.0, seg.rays.1);
                if seg.radiance != Color::ZERO {
                    shaded.emit(item.path, item.throughput * seg.radiance);
                }
                let throughput = item.throughput * seg.weight;
                let update = |ray, hit| SegmentUpdate {
                    index: i as u32,
                    ray,
                    throughput,
                    depth: item.depth,
                    pdf: item.pdf,
                    cone: item.cone,
                    hit,
                };
                match seg.end {
                    SegmentEnd::Surface { hit, ray } => {
                        updates.push(update(ray, Some(hit)));
                        routes.push(i as u32);
                    }
                    SegmentEnd::Escaped(d) => {
                        updates.push(update(Ray::new(item.ray.origin, d), None));
                        routes.push(i as u32);
                    }
                    SegmentEnd::Lost => {}
                    SegmentEnd::Scattered(v) => {
                        volume::medium_next_event(
                            scene,
                            settings,
                            &v,
                            &mut sampler,
                            item.depth,
                            |q| shaded.push_shadow_from(item.path, throughput, q),
                        );
                        // The event's shadow rays are traced here and
                        // their light added at once, before the walk goes
                        // on: the path's terms in the order of its
                        // vertices, as the recursive tracer adds them.
                        shaded.trace_shadows_through_now(|r, t_max| {
                            volume::shadow_transmittance(scene, r, t_max)
                        });
                        if let Some((_, next)) = primed.take() {
                            let set = volume::continue_dimension(settings, item.depth) / 4;
                            sampler.prime((set, next));
                        }
                        if let Some(c) = volume::continue_in_medium(
                            settings,
                            &v,
                            item.depth,
                            throughput,
                            &mut sampler,
                        ) {
                            // The walk goes on here, one step at a time
                            // as the recursive tracer follows it.
                            shaded.count_secondary(c.sample.kind);
                            item = RayItem {
                                ray: c.sample.ray,
                                throughput: throughput * c.sample.weight * c.scale,
                                path: item.path,
                                depth: item.depth + 1,
                                pdf: c.sample.pdf,
                                cone: RayCone::NONE,
                            };
                            found = scene.intersect(&item.ray, 0.0, f32::INFINITY);
                            continue;
                        }
                    }
                }
                break;
            }
        }
    });
    let MediaTargets {
        escaped,
        hits,
        shade,
    } = to;
    for u in chunks.iter().flat_map(|c| &c.updates) {
        let i = u.index as usize;
        rays.origin[i] = u.ray.origin;
        rays.direction[i] = u.ray.direction;
        rays.throughput[i] = u.throughput;
        rays.depth[i] = u.depth;
        rays.pdf[i] = u.pdf;
        rays.cone[i] = u.cone;
        found.0[i] = u.hit;
    }
    // Chunks in order, routes in ray order: every queue receives
    // ascending indices, as `route_rays` gives them.
    let queues = hits.all_mut();
    for &i in chunks.iter().flat_map(|c| &c.routes) {
        match &found.0[i as usize] {
            None => escaped.push(i),
            Some(h) => queues[classes[h.material as usize] as usize].push(i),
        }
    }
    join_shade_outputs(chunks, shade);
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
    // Under Whitted transport a fog attenuates escaped rays by its
    // transmittance to infinity (path transport weighs them in
    // `sample_media`).
    if settings.transport != Transport::Path
        && let Some(fog) = scene.fog()
    {
        let tr = fog.transmittance(f32::INFINITY);
        for &i in &escaped.ray {
            let i = i as usize;
            let l = scene.escaped_radiance(rays.direction[i]);
            radiance[rays.path[i] as usize] += rays.throughput[i] * (l * tr);
        }
        return;
    }
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
    /// Sampler seed of each path of the batch (path transport; empty
    /// under the other transports, which draw no numbers in shading).
    pub seeds: &'a [SamplerSeed],
    /// Wavelength of each path of the batch in spectral mode
    /// ([`path_wavelengths`]); empty otherwise.
    pub wavelengths: &'a [f32],
    /// Each path's kept Sobol set, handed from one bounce's shading to the
    /// next (path transport; empty otherwise).
    pub kept: &'a [KeptSlot],
}

/// The interaction of the hit item `h` (built where it is kept: returned
/// in a pair with the item, as before, it cost two copies of its 300
/// bytes per hit, 2.7% of a path-traced `cornell.toml`).
#[inline(always)]
fn interaction(scene: &RenderScene, h: &HitItem) -> Interaction {
    Interaction::with_cone_at(scene, h.direction, &h.hit(), h.cone, h.distance)
}

/// Attenuates `h`'s throughput by what its segment crossed.
#[inline(always)]
fn attenuate(scene: &RenderScene, settings: &RenderSettings, h: &mut HitItem, it: &Interaction) {
    // A segment that ran through an absorbing interior carries its
    // transmittance to everything seen at its end. In a scene with media,
    // path transport has weighed the segment in `sample_media`, and
    // Whitted transport attenuates it by its medium's extinction.
    let tr = if scene.has_media() {
        whitted_media_transmittance(scene, settings, h)
    } else {
        interior_transmittance(it, h.distance)
    };
    if let Some(tr) = tr {
        h.throughput *= tr;
    }
}

/// True when surfaces' shadow rays are followed through media with their
/// transmittance: path transport in a scene with media, unless those
/// media cannot attenuate a shadow ray
/// ([`RenderScene::shadows_are_binary`]).
#[inline]
fn shadows_through_media(scene: &RenderScene, settings: &RenderSettings) -> bool {
    scene.has_media() && settings.transport == Transport::Path && !scene.shadows_are_binary()
}

/// Traces the shadow rays a shading chunk pushed since the last call
/// (see [`shade_hits`]).
#[inline(always)]
fn trace_chunk_shadows(
    scene: &RenderScene,
    through_media: bool,
    batch: Option<&PolygonBatch>,
    triangles: Option<&TriangleBatch>,
    out: &mut ShadeOutput,
) {
    if through_media {
        out.trace_shadows_through(|r, t_max| volume::shadow_transmittance(scene, r, t_max));
    } else if let Some(t) = triangles {
        out.trace_shadows_all(|rays, t_max, blocked| t.occluded(rays, t_max, blocked));
    } else {
        let width = if batch.is_some() {
            BATCH_LANES
        } else {
            shadow_group_width()
        };
        out.trace_shadows(width, |rays, t_max| {
            occluded_group(scene, batch, rays, t_max)
        });
    }
}

/// Hits whose shadow rays a shading chunk traces together (see
/// [`ShadeOutput::trace_shadows`]): enough for full packets of rays of
/// neighbouring hits towards each light, few enough that the group's rays
/// stay in the core's cache (48 lights: 1,536 rays, 80 kB).
pub const SHADOW_GROUP: usize = 4 * LANES;

/// Hits whose shadow rays a shading chunk traces together in a scene of
/// one small merged mesh ([`TriangleBatch`]), which sorts them by axis
/// permutation into groups of 16 side by side: with [`SHADOW_GROUP`] hits
/// the groups were a third full and the shadow rays took 1.8x the time of
/// the per-ray queries; 4 to 64 times as many measured alike
/// (`assets/gltf/cornell.gltf`, 320x240, 32 spp).
pub const BATCH_SHADOW_GROUP: usize = 16 * SHADOW_GROUP;

/// No set: [`Primed`] entries and [`shade_hits`]'s `primes` use it for
/// a set not drawn.
const NO_SET: u32 = u32::MAX;

/// The Sobol sets drawn for one hit before its kernel runs ([`PrimedSets`]):
/// `(set, numbers)` of the first light sample's set and of the BSDF
/// direction's kept set, `NO_SET` where none was drawn.
type Primed = [(u32, [f32; 4]); 2];

/// The Sobol sets that a group of hits will draw, drawn for all of them
/// at once ([`sobol_sets`]: sixteen side by side), before their kernels
/// run, which then find them in their samplers' caches
/// ([`Sampler::prime`](crate::core::rng::Sampler::prime),
/// [`Sampler::restore_kept`](crate::core::rng::Sampler::restore_kept)).
/// The numbers are the ones the kernels would draw, bit for bit: only
/// where they are computed changes.
#[derive(Clone, Debug, Default)]
struct PrimedSets {
    /// Per hit of the group.
    primed: Vec<Primed>,
}

impl PrimedSets {
    /// Draws the sets `primes(depth)` of every ray of `group` whose path
    /// has a Sobol sampler (none under the hash sampler or without
    /// seeds), except a direction set the path's kept slot holds already.
    #[inline]
    fn draw(
        &mut self,
        group: &[u32],
        rays: &RayQueue,
        seeds: &[SamplerSeed],
        kept: &[KeptSlot],
        primes: &impl Fn(u32) -> [u32; 2],
    ) {
        self.primed.clear();
        if seeds.is_empty() {
            self.primed.resize(group.len(), [(NO_SET, [0.0; 4]); 2]);
            return;
        }
        const N: usize = SET_LANES;
        for chunk in group.chunks(N) {
            // Up to two requests per hit, in order; `to[k]`: the hit and
            // slot of request `k`.
            let mut requests = [SetRequest::default(); 2 * N];
            let mut to = [(0u8, 0u8); 2 * N];
            let mut sets = [[NO_SET; 2]; N];
            let mut n = 0;
            for (j, &i) in chunk.iter().enumerate() {
                let path = rays.path[i as usize] as usize;
                sets[j] = primes(rays.depth[i as usize]);
                for (slot, &set) in sets[j].iter().enumerate() {
                    if set == NO_SET
                        || (slot == 1 && kept.get(path).is_some_and(|k| k.set() == set))
                    {
                        continue;
                    }
                    if let Some(r) = seeds[path].sobol_request(set) {
                        requests[n] = r;
                        to[n] = (j as u8, slot as u8);
                        n += 1;
                    }
                }
            }
            let mut numbers = [[0.0f32; 4]; 2 * N];
            sobol_sets(&requests[..n], &mut numbers[..n]);
            let first = self.primed.len();
            self.primed
                .resize(first + chunk.len(), [(NO_SET, [0.0; 4]); 2]);
            for (&(j, slot), &v) in to[..n].iter().zip(&numbers[..n]) {
                let (j, slot) = (j as usize, slot as usize);
                self.primed[first + j][slot] = (sets[j][slot], v);
            }
        }
    }

    /// The sets drawn for hit `j` of the group.
    #[inline(always)]
    fn of(&self, j: usize) -> &Primed {
        &self.primed[j]
    }
}

/// Runs `kernel` on every hit of `input.hits` with its interaction, in
/// parallel chunks each writing its own [`ShadeOutput`], then joins the
/// outputs in chunk order.
///
/// Each chunk traces the shadow rays its hits pushed itself,
/// [`SHADOW_GROUP`] hits at a time, while the rays are still in the
/// core's cache, and passes on only the radiance they bring back (see
/// [`trace_shadow_rays`]): queueing every ray for a stage of its own cost
/// the stores and loads of 52 bytes per ray, most of the work on scenes
/// of many lights. In a scene with media under path transport each ray is
/// followed through the media it crosses and carries its transmittance
/// ([`volume::shadow_transmittance`]).
///
/// Before a group's kernels run, the Sobol sets `primes(depth)` names for
/// each hit (the first light sample's and the BSDF direction's, `NO_SET`
/// for none) are drawn for the whole group at once and handed to the
/// kernel ([`PrimedSets`]): sixteen side by side cost less than one at a
/// time in each kernel (path-traced glTF Cornell box, one thread: 0.95x
/// the wavefront's time on the AVX-512 and AVX2 paths, 0.97x portable).
fn shade_hits(
    scene: &RenderScene,
    settings: &RenderSettings,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
    primes: impl Fn(u32) -> [u32; 2] + Sync,
    kernel: impl Fn(&HitItem, &mut Interaction, &mut ShadeOutput, &Primed) + Sync,
) {
    let ShadeInput {
        rays,
        found,
        hits,
        seeds,
        kept,
        ..
    } = input;
    let through_media = shadows_through_media(scene, settings);
    let batch = PolygonBatch::new(scene);
    let batch = batch.as_ref();
    let triangles = TriangleBatch::new(scene);
    let triangles = triangles.as_ref();
    let outputs = drain_queue(hits.len(), scratch, |range, out| {
        out.clear();
        let mut sets = PrimedSets::default();
        for group in hits.ray[range].chunks(if triangles.is_some() {
            BATCH_SHADOW_GROUP
        } else {
            SHADOW_GROUP
        }) {
            sets.draw(group, rays, seeds, kept, &primes);
            for (j, &i) in group.iter().enumerate() {
                let i = i as usize;
                let Some(hit) = &found.0[i] else {
                    debug_assert!(false, "ray {i} is queued for shading without a hit");
                    continue;
                };
                let mut h = HitItem::new(hit, &rays.get(i));
                let mut it = interaction(scene, &h);
                attenuate(scene, settings, &mut h, &it);
                kernel(&h, &mut it, out, sets.of(j));
                out.end_hit();
            }
            trace_chunk_shadows(scene, through_media, batch, triangles, out);
        }
    });
    join_shade_outputs(outputs, to);
}

/// The mask of the blocked rays among up to [`LANES`] shadow rays: against
/// every polygon at once in a scene of a few polygons (`batch`); else
/// through the top level as one packet when they point into one octant
/// (each lane then traverses meshes alone), else one at a time, which
/// costs rays pointing apart fewer instructions.
#[inline]
fn occluded_group(
    scene: &RenderScene,
    batch: Option<&PolygonBatch>,
    rays: &[Ray],
    t_max: &[f32],
) -> LaneMask {
    if let Some(b) = batch {
        // (The batch takes up to `BATCH_LANES` rays at a time.)
        let mut blocked = 0;
        for (c, (r, t)) in rays
            .chunks(BATCH_LANES)
            .zip(t_max.chunks(BATCH_LANES))
            .enumerate()
        {
            blocked |= b.occluded(scene, r, t) << (c * BATCH_LANES);
        }
        return blocked;
    }
    if rays.len() > LANES {
        // Groups of 16 (the AVX-512 path, `shadow_group_width`): one
        // packet of 16 where the rays share an octant.
        return scene.occluded_coherent(rays, t_max);
    }
    if rays.len() > 1 && one_octant(rays) {
        return scene.occluded_packet_with(rays, t_max, false);
    }
    let mut blocked = 0;
    for (l, (r, &t)) in rays.iter().zip(t_max).enumerate() {
        if scene.occluded(r, 0.0, t) {
            blocked |= 1 << l;
        }
    }
    blocked
}

/// Shadow rays per group traced together by [`occluded_group`]: 16 on
/// the AVX-512 path (one packet of 16, as the recursive integrator's
/// camera packets trace theirs), 8 elsewhere.
fn shadow_group_width() -> usize {
    if crate::core::simd::use_avx512() {
        COHERENT_LANES
    } else {
        LANES
    }
}

/// The attenuation of hit `h`'s segment in a scene with media: by its
/// medium's extinction under Whitted transport, none under path transport
/// (`sample_media` has weighed it). Out of line: scenes without media
/// never call it.
#[cold]
#[inline(never)]
fn whitted_media_transmittance(
    scene: &RenderScene,
    settings: &RenderSettings,
    h: &HitItem,
) -> Option<Color> {
    if settings.transport == Transport::Path {
        return None;
    }
    volume::whitted_transmittance(scene, Some(&h.hit()), h.direction, h.distance)
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
    if LIT && settings.style != Style::Gooch && point_lights(scene) >= LANES_MIN_POINT_LIGHTS {
        return shade_lit_in_lanes::<SCATTER>(scene, settings, input, scratch, to);
    }
    shade_hits(
        scene,
        settings,
        input,
        scratch,
        to,
        |_| [NO_SET; 2],
        |h, it, out, _| {
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
            if SCATTER {
                push_specular(settings, h, it, out);
            }
        },
    );
}

/// Point lights from which [`shade`] sets up shadow rays in lanes
/// (`shade_lit_in_lanes`): filling the lanes costs about what setting
/// up a few lights' rays one hit at a time does, and the Blinn-Phong
/// power stays one `powf` per lane. Measured on the 2-core AMD EPYC
/// (AVX2), wavefront, 2 threads, 8 spp, 5 alternating renders against the
/// per-hit kernel (`examples/measure/ab_wall.sh`): `many_lights` with its
/// first 2, 4, 8 and 16 point lights 1.067x, 1.005x, 0.980x and 0.947x
/// the time, all 48 at 4 spp 0.953x; `diffuse_only` (two point lights,
/// no highlight) 1.107x at 16 spp.
pub const LANES_MIN_POINT_LIGHTS: usize = 8;

/// The scene's point lights.
fn point_lights(scene: &RenderScene) -> usize {
    scene
        .lights()
        .iter()
        .filter(|l| matches!(l, WorldLight::Point { .. }))
        .count()
}

/// Pushes the reflection and refraction rays of a Whitted hit above the
/// contribution threshold, up to the maximum depth.
#[inline(always)]
fn push_specular(settings: &RenderSettings, h: &HitItem, it: &Interaction, out: &mut ShadeOutput) {
    if h.depth >= settings.max_depth {
        return;
    }
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

/// [`shade`] of a lit class (not Gooch): the hits of each chunk are taken
/// [`LIGHT_LANES`] at a time, and each light's shadow rays for the lit
/// ones among them are set up side by side ([`direct_point_lights`] for
/// point lights, [`direct_light`] per hit for the others): the hits of a
/// wavefront queue are of one material class, so the lanes run the same
/// code. Each lane's query is [`direct_light`]'s bit for bit, and the
/// rays are pushed in the order of the per-hit kernel (hit by hit, light
/// by light), so the image is the recursive tracer's.
fn shade_lit_in_lanes<const SCATTER: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    let ShadeInput {
        rays, found, hits, ..
    } = input;
    let through_media = shadows_through_media(scene, settings);
    let batch = PolygonBatch::new(scene);
    let batch = batch.as_ref();
    let triangles = TriangleBatch::new(scene);
    let triangles = triangles.as_ref();
    let lights = scene.lights();
    let outputs = drain_queue(hits.len(), scratch, |range, out| {
        out.clear();
        let mut per_light = vec![LightLanes::default(); lights.len()];
        // Reused: lanes past `count` keep old values, which no one reads.
        let mut lanes = HitLanes::default();
        for group in hits.ray[range].chunks(SHADOW_GROUP) {
            for sub in group.chunks(LIGHT_LANES) {
                // Each hit's emission and specular rays go out at once (their
                // queues' order is the per-hit kernel's); the lit hits'
                // lanes are filled, with the queries of lights other than
                // point lights made hit by hit.
                lanes.count = 0;
                let mut lit_hit = [(0u32, Color::ZERO); LIGHT_LANES];
                let mut lit_at = [usize::MAX; LIGHT_LANES];
                for (k, &i) in sub.iter().enumerate() {
                    let i = i as usize;
                    let Some(hit) = &found.0[i] else {
                        debug_assert!(false, "ray {i} is queued for shading without a hit");
                        continue;
                    };
                    let mut h = HitItem::new(hit, &rays.get(i));
                    let it = interaction(scene, &h);
                    attenuate(scene, settings, &mut h, &it);
                    if it.surface.emission != Color::ZERO {
                        out.emit(h.path, h.throughput * it.surface.emission);
                    }
                    if it.is_lit_by_lights() {
                        let l = lanes.count;
                        lit_at[k] = l;
                        lit_hit[l] = (h.path, h.throughput);
                        lanes.push(&it);
                        set_up_other_lights(&it, l, lights, &mut per_light);
                    }
                    if SCATTER {
                        push_specular(settings, &h, &it, out);
                    }
                }
                if lanes.count > 0 {
                    set_up_point_lights(&lanes, lights, &mut per_light);
                }
                for &l in &lit_at[..sub.len()] {
                    if l != usize::MAX {
                        let (path, throughput) = lit_hit[l];
                        for ll in &per_light {
                            if ll.lit[l] {
                                out.push_shadow_from(path, throughput, ll.query(&lanes, l));
                            }
                        }
                    }
                    out.end_hit();
                }
            }
            trace_chunk_shadows(scene, through_media, batch, triangles, out);
        }
    });
    join_shade_outputs(outputs, to);
}

/// The shadow queries of lane `l` (interaction `it`) for the lights that
/// are not point lights, one by one with [`direct_light`].
#[inline]
fn set_up_other_lights(
    it: &Interaction,
    l: usize,
    lights: &[WorldLight],
    per_light: &mut [LightLanes],
) {
    for (light, out) in lights.iter().zip(per_light.iter_mut()) {
        if matches!(light, WorldLight::Point { .. }) {
            continue;
        }
        let q = direct_light(it, light);
        out.lit[l] = q.is_some();
        if let Some(q) = q {
            for a in 0..3 {
                out.wi[a][l] = q.ray.direction[a];
                out.radiance[a][l] = q.radiance[a];
            }
            out.t_max[l] = q.t_max;
        }
    }
}

/// The shadow queries of every point light for the lanes `lanes`, side
/// by side ([`direct_point_lights`]), into `per_light`.
#[inline]
fn set_up_point_lights(lanes: &HitLanes, lights: &[WorldLight], per_light: &mut [LightLanes]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        fn fast(lanes: &HitLanes, lights: &[WorldLight], out: &mut [LightLanes]) {
            point_lights_with::<true>(lanes, lights, out)
        }
        if crate::core::simd::use_avx2() {
            // SAFETY: `use_avx2` holds only on CPUs with AVX2 and FMA.
            #[allow(unsafe_code)]
            return unsafe { fast(lanes, lights, per_light) };
        }
    }
    point_lights_with::<false>(lanes, lights, per_light)
}

/// [`set_up_point_lights`]'s body, inlined into each of its code paths.
#[inline(always)]
fn point_lights_with<const AVX: bool>(
    lanes: &HitLanes,
    lights: &[WorldLight],
    per_light: &mut [LightLanes],
) {
    for (light, out) in lights.iter().zip(per_light.iter_mut()) {
        if let WorldLight::Point {
            position,
            intensity,
        } = *light
        {
            direct_point_lights::<AVX>(lanes, position, intensity, out);
        }
    }
}

/// Stage, path transport: shades every hit of one material class. Each
/// hit adds its MIS-weighted emission, pushes next-event shadow rays
/// (`NEE`: the class has a lobe lights can reach) and at most one
/// continuation ray (`SCATTER`), chosen as the recursive tracer chooses it
/// from the same sample numbers, drawn from the path's sampler seed
/// (`input.seeds`). `SSS`: the class may hold subsurface surfaces, whose diffuse boundary
/// ([`volume::diffuse_crossing`]) the kernel then handles (kernels of scenes
/// without subsurface materials carry none of that code).
pub fn shade_path<const NEE: bool, const SCATTER: bool, const SSS: bool>(
    scene: &RenderScene,
    settings: &RenderSettings,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    let (seeds, wavelengths, kept) = (input.seeds, input.wavelengths, input.kept);
    // The sets the kernel draws first, drawn for a group of hits at once:
    // the first light sample's (when there are lights to sample) and the
    // BSDF direction's (when the path may go on).
    let light = NEE && (scene.environment().is_some() || !scene.emitters().is_empty());
    let primes = |depth: u32| {
        [
            if light {
                path::bounce_dimension(settings, depth) / 4
            } else {
                NO_SET
            },
            // (A split path's parts draw their own first directions.)
            if SCATTER && depth < settings.max_depth && !(settings.split > 1 && depth == 0) {
                path::direction_set(depth)
            } else {
                NO_SET
            },
        ]
    };
    shade_hits(
        scene,
        settings,
        input,
        scratch,
        to,
        primes,
        |h, it, out, primed| {
            let e = path::emitted(scene, settings, it, h.instance, h.pdf, h.distance);
            if e != Color::ZERO {
                out.emit(h.path, h.throughput * e);
            }
            if !NEE && !SCATTER {
                return;
            }
            let mut sampler = seeds[h.path as usize].sampler();
            let slot = kept.get(h.path as usize);
            if let Some(k) = slot {
                sampler.restore_kept(k.load());
            }
            let [first, direction] = *primed;
            if direction.0 != NO_SET {
                sampler.restore_kept(direction);
            }
            if first.0 != NO_SET {
                sampler.prime(first);
            }
            let lambda = wavelengths.get(h.path as usize).copied();
            // The interaction is adjusted in place (a copy of it costs a
            // `memmove` per hit).
            let mut crossing = None;
            if SSS && scene.materials()[h.material as usize].subsurface {
                crossing = at_wavelength_and_boundary(scene, h, it, lambda);
            } else if lambda.is_some() {
                path::at_wavelength(it, lambda);
            }
            let it = &*it;
            let lobes = LobeChoice::new(it);
            if NEE && crossing != Some(volume::Crossing::Into) {
                path::next_event(scene, settings, it, &lobes, &mut sampler, h.depth, |q| {
                    out.push_shadow(h, q)
                });
            }
            if !SCATTER {
                return;
            }
            // The path's next ray, drawn with `sampler`, into path slot
            // `path` (whose kept Sobol set is `kept_slot`).
            let mut go_on = |path: u32, sampler: &mut Sampler, kept_slot: Option<&KeptSlot>| {
                let Some(cont) =
                    path::continue_path(settings, it, &lobes, h.depth, h.throughput, sampler)
                else {
                    return;
                };
                let item = RayItem {
                    ray: if SSS {
                        volume::start_walk(crossing, it, cont.sample.ray)
                    } else {
                        cont.sample.ray
                    },
                    throughput: h.throughput * cont.sample.weight * cont.scale,
                    path,
                    depth: h.depth + 1,
                    pdf: cont.sample.pdf,
                    cone: cont.cone(it),
                };
                out.push_secondary(cont.sample.kind, item);
                if let Some(k) = kept_slot {
                    k.store(sampler.kept());
                }
            };
            if settings.split > 1 && h.depth == 0 {
                // A split path: its parts' slots follow its own.
                for j in 0..settings.split {
                    let part_slot = h.path + 1 + j;
                    let mut part = seeds[part_slot as usize].sampler();
                    let part_kept = kept.get(part_slot as usize);
                    if let Some(k) = part_kept {
                        part.restore_kept(k.load());
                    }
                    go_on(part_slot, &mut part, part_kept);
                }
            } else {
                go_on(h.path, &mut sampler, slot);
            }
        },
    );
}

/// Sets the interaction `it` of hit `h` to the path's wavelength `lambda`
/// and, on a subsurface surface, turns it into its diffuse boundary
/// ([`volume::diffuse_crossing`]), returning the crossing. Out of line:
/// most scenes need neither.
#[cold]
#[inline(never)]
fn at_wavelength_and_boundary(
    scene: &RenderScene,
    h: &HitItem,
    it: &mut Interaction,
    lambda: Option<f32>,
) -> Option<volume::Crossing> {
    path::at_wavelength(it, lambda);
    volume::diffuse_crossing(scene, &h.hit(), it)
}

/// Stage: shades the hits of `class` with the kernel for the lobes the
/// class has ([`MaterialClass::is_lit`], [`MaterialClass::scatters`]) and
/// the settings' transport.
pub fn shade_class(
    class: MaterialClass,
    scene: &RenderScene,
    settings: &RenderSettings,
    input: ShadeInput<'_>,
    scratch: &mut ShadeScratch,
    to: ShadeTargets<'_>,
) {
    let lobes = (class.is_lit(), class.scatters());
    if settings.transport == Transport::Path {
        // Subsurface materials are of the general class.
        let sss = class == MaterialClass::General && scene.materials().iter().any(|m| m.subsurface);
        let f = match (lobes, sss) {
            ((false, false), _) => shade_path::<false, false, false>,
            ((false, true), _) => shade_path::<false, true, false>,
            // Every lit class also scatters diffusely under path transport.
            ((true, _), false) => shade_path::<true, true, false>,
            ((true, _), true) => shade_path::<true, true, true>,
        };
        return f(scene, settings, input, scratch, to);
    }
    let f = match lobes {
        (false, false) => shade::<false, false>,
        (false, true) => shade::<false, true>,
        (true, false) => shade::<true, false>,
        (true, true) => shade::<true, true>,
    };
    f(scene, settings, input, scratch, to)
}

/// Stage: adds the radiance the bounce's shadow rays brought back to
/// their paths, in queue order (media first, then shading stage by
/// shading stage, chunk by chunk), after every shading stage has added
/// its emission: the order in which each path's terms are summed.
///
/// The rays themselves were traced by the stages that made them, chunk
/// by chunk, while they were still in the core's cache
/// ([`ShadeOutput::trace_shadows`]: groups of the rays of neighbouring
/// hits towards one light, through the top level as one packet when
/// they point into one octant; through media one at a time with their
/// transmittance, [`ShadeOutput::trace_shadows_through`]).
pub fn trace_shadow_rays(shadows: &ShadowSegments, radiance: &mut [Color]) {
    for seg in shadows.segments() {
        for (&path, l) in seg.path.iter().zip(&seg.radiance) {
            radiance[path as usize] += *l;
        }
    }
}

/// Stage: adds each finished path of the batch to its window pixel,
/// dropping and counting non-finite samples. The sums are exact, so the
/// order in which paths are added does not matter. `slots` path slots
/// make one sample ([`RenderSettings::path_slots`]): a split path's
/// radiance is its camera path's plus its parts' sum (in order) over
/// their number, as the recursive integrator adds them.
///
/// In spectral mode (path transport of a scene with a dispersive
/// material) each path's radiance is first weighted by its wavelength's
/// RGB response: `wavelengths` holds each path's (see
/// [`path_wavelengths`]; empty otherwise).
pub fn update_film(
    radiance: &[Color],
    wavelengths: &[f32],
    slots: usize,
    paths: &PathMap,
    first: u64,
    sums: &mut PixelAccumulator,
    counters: &mut RenderCounters,
) {
    let pixels = sums.pixels_mut();
    // Path `first + local` is a sample of window pixel `(first + local) /
    // n`: the batch's paths run through consecutive pixels, so the pixel
    // is stepped along instead of divided out per path (this stage holds
    // the lock on the frame's sums).
    let n = paths.samples() as u64;
    let mut pixel = (first / n) as usize;
    let mut left = n - first % n;
    for (local, slot) in radiance.chunks(slots).enumerate() {
        let mut l = slot[0];
        if slots > 1 {
            let mut parts = Color::ZERO;
            for &part in &slot[1..] {
                parts += part;
            }
            l += parts * (1.0 / (slots - 1) as f32);
        }
        let l = match wavelengths.get(local * slots) {
            Some(&w) => path::weigh_wavelength(l, Some(w)),
            None => l,
        };
        accumulate(&mut pixels[pixel], l, counters);
        left -= 1;
        if left == 0 {
            pixel += 1;
            left = n;
        }
    }
}
