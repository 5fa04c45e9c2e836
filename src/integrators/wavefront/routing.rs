//! Routing: which queue a ray, a hit or a shading result goes to next.
//!
//! Every decision of where work goes after a stage is made here and only
//! here, as pbrt-v4's `EnqueueWorkAfterMiss` and
//! `EnqueueWorkAfterIntersection` make them:
//!
//! * after the closest-hit test ([`RoutedChunk::route`]), a ray that
//!   missed goes to the escaped queue, a ray that hit goes to the hit queue
//!   of its material's class;
//! * after shading ([`ShadeOutput`]), emission goes to the path's
//!   radiance, shadow rays to the shadow queue, and reflection and
//!   refraction rays to the next bounce's ray queue, every chunk's
//!   reflections before every chunk's refractions.
//!
//! Stages route into per-chunk buffers (see
//! [`drain`](crate::integrators::wavefront::drain)); [`join_routed`] and
//! [`join_shade_outputs`] append them to the stage's output in chunk
//! order.

use crate::core::math::Color;
use crate::integrators::counters::RayCounts;
use crate::integrators::wavefront::queues::{
    EscapedQueue, HitItem, HitQueue, MediumQueue, QueueBytes, RayItem, RayQueue, ShadowItem,
    ShadowQueue, ShadowSegments,
};
use crate::scene::Hit;
use crate::scene::material::MaterialClass;
use crate::transport::interaction::{RayKind, ShadowQuery};

/// Where hits are routed: one hit queue per material class.
pub trait ClassHitQueues {
    /// The hit queue of `class`.
    fn queue_mut(&mut self, class: MaterialClass) -> &mut HitQueue;
}

/// One chunk's hit queues, one per material class, indexed by
/// `class as usize`.
#[derive(Clone, Debug, Default)]
struct ClassQueues([HitQueue; MaterialClass::ALL.len()]);

/// One chunk of rays routed after the closest-hit test.
#[derive(Clone, Debug, Default)]
pub struct RoutedChunk {
    escaped: EscapedQueue,
    hits: ClassQueues,
    media: MediumQueue,
}

impl RoutedChunk {
    /// Removes every routed ray, keeping the buffers.
    pub fn clear(&mut self) {
        self.escaped.clear();
        for q in &mut self.hits.0 {
            q.clear();
        }
        self.media.clear();
    }

    /// Routes ray `i` of `rays` after its closest-hit test: a miss to the
    /// escaped queue (with its direction and density when
    /// `environment`: only an environment reads them), a hit to the queue
    /// of its material's class (`classes` holds the class of each
    /// material).
    #[inline]
    pub fn route(
        &mut self,
        classes: &[MaterialClass],
        environment: bool,
        rays: &RayQueue,
        i: usize,
        found: Option<Hit>,
    ) {
        match found {
            None if environment => self.escaped.push_toward(
                rays.path[i],
                rays.throughput[i],
                rays.direction[i],
                rays.pdf[i],
            ),
            None => self.escaped.push(rays.path[i], rays.throughput[i]),
            Some(h) => {
                let class = classes[h.material as usize];
                self.hits.0[class as usize].push(HitItem::new(&h, &rays.get(i)));
            }
        }
    }

    /// Routes ray `i` of `rays` of a scene with media under path
    /// transport: every ray, hit or not, goes to the medium queue, to be
    /// followed through the media before anything else.
    #[inline]
    pub fn route_to_media(&mut self, rays: &RayQueue, i: usize, found: Option<Hit>) {
        self.media.push(rays.get(i), found);
    }

    /// Routes what a ray of a scene with media ended on after it was
    /// followed through the media: `hit` (with `hit.t` the whole segment's
    /// length) of a ray in direction `item.ray.direction` to the queue of
    /// its material's class, or an escape in that direction to the escaped
    /// queue (with direction and density when `environment`).
    #[inline]
    pub fn route_after_media(
        &mut self,
        classes: &[MaterialClass],
        environment: bool,
        item: &RayItem,
        hit: Option<Hit>,
    ) {
        match hit {
            None if environment => {
                self.escaped
                    .push_toward(item.path, item.throughput, item.ray.direction, item.pdf)
            }
            None => self.escaped.push(item.path, item.throughput),
            Some(h) => {
                let class = classes[h.material as usize];
                self.hits.0[class as usize].push(HitItem::new(&h, item));
            }
        }
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.escaped.bytes()
            + self.hits.0.iter().map(|q| q.bytes()).sum::<usize>()
            + self.media.bytes()
    }
}

/// Appends routed chunks to the escaped queue and the hit queues, in
/// chunk order.
pub fn join_routed<'a>(
    chunks: impl IntoIterator<Item = &'a RoutedChunk>,
    escaped: &mut EscapedQueue,
    hits: &mut impl ClassHitQueues,
    media: &mut MediumQueue,
) {
    for chunk in chunks {
        escaped.append(&chunk.escaped);
        for class in MaterialClass::ALL {
            hits.queue_mut(class).append(&chunk.hits.0[class as usize]);
        }
        if !chunk.media.is_empty() {
            media.append(&chunk.media);
        }
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
    /// Removes everything, keeping the buffers.
    pub fn clear(&mut self) {
        self.emitted.clear();
        self.shadows.clear();
        self.reflections.clear();
        self.refractions.clear();
        self.counts = RayCounts::default();
    }

    /// Adds `radiance` to path `path`.
    #[inline]
    pub fn emit(&mut self, path: u32, radiance: Color) {
        self.emitted.push((path, radiance));
    }

    /// Queues the shadow ray of `q` for hit `h` and counts it.
    #[inline]
    pub fn push_shadow(&mut self, h: &HitItem, q: ShadowQuery) {
        self.counts.shadow += 1;
        self.shadows.push(ShadowItem {
            ray: q.ray,
            t_max: q.t_max,
            radiance: h.throughput * q.radiance,
            path: h.path,
        });
    }

    /// Queues the shadow ray of `q` for path `path` reached with
    /// `throughput` (a scattering event in a medium) and counts it.
    #[inline]
    pub fn push_shadow_from(&mut self, path: u32, throughput: Color, q: ShadowQuery) {
        self.counts.shadow += 1;
        self.shadows.push(ShadowItem {
            ray: q.ray,
            t_max: q.t_max,
            radiance: throughput * q.radiance,
            path,
        });
    }

    /// Adds `n` rays traced inside a stage (boundary crossings, as
    /// refraction rays; shadow rays of point lights in media).
    #[inline]
    pub fn count_rays(&mut self, crossings: u64, shadows: u64) {
        self.counts.refraction += crossings;
        self.counts.shadow += shadows;
    }

    /// Queues a reflection or refraction ray for the next bounce and
    /// counts it.
    #[inline]
    pub fn push_secondary(&mut self, kind: RayKind, item: RayItem) {
        if kind == RayKind::Refraction {
            self.counts.refraction += 1;
            self.refractions.push(item);
        } else {
            self.counts.reflection += 1;
            self.reflections.push(item);
        }
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

/// Where a shading stage's output goes: path radiance, shadow rays, the
/// next bounce's rays and ray counts.
pub struct ShadeTargets<'a> {
    /// Radiance gathered by each path of the batch.
    pub radiance: &'a mut [Color],
    /// Shadow rays of this bounce.
    pub shadows: &'a mut ShadowSegments,
    /// Rays of the next bounce.
    pub next: &'a mut RayQueue,
    /// Rays counted by kind.
    pub rays: &'a mut RayCounts,
}

/// Joins the shading chunks' output in chunk order: emission into the
/// paths' radiance, shadow segments handed over, then every chunk's
/// reflection rays before every chunk's refraction rays (so neighbouring
/// rays of the next bounce are alike).
pub fn join_shade_outputs<T: std::borrow::BorrowMut<ShadeOutput>>(
    outputs: &mut [T],
    to: ShadeTargets<'_>,
) {
    for out in outputs.iter_mut() {
        let out = out.borrow_mut();
        for &(path, l) in &out.emitted {
            to.radiance[path as usize] += l;
        }
        to.shadows.take(&mut out.shadows);
        to.next.append(&out.reflections);
        to.rays.add(&out.counts);
    }
    for out in outputs.iter() {
        to.next.append(&out.borrow().refractions);
    }
}
