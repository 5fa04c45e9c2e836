//! Routing: which queue a ray, a hit or a shading result goes to next.
//!
//! Every decision of where work goes after a stage is made here and only
//! here, as pbrt-v4's `EnqueueWorkAfterMiss` and
//! `EnqueueWorkAfterIntersection` make them:
//!
//! * after the closest-hit test ([`route_rays`]), a ray that missed goes
//!   to the escaped queue, a ray that hit goes to the hit queue of its
//!   material's class; both queues hold the ray's index only;
//! * after shading ([`ShadeOutput`]), emission goes to the path's
//!   radiance, shadow rays to the shadow queue, and reflection and
//!   refraction rays to the next bounce's ray queue, every chunk's
//!   reflections before every chunk's refractions.
//!
//! Shading stages route into per-chunk buffers (see
//! [`drain`](crate::integrators::wavefront::drain)); [`join_shade_outputs`]
//! appends them to the stage's output in chunk order.

use crate::core::math::Color;
use crate::integrators::counters::RayCounts;
use crate::integrators::wavefront::queues::{
    EscapedQueue, HitItem, HitQueue, QueueBytes, RayItem, RayQueue, ShadowItem, ShadowQueue,
    ShadowSegments,
};
use crate::scene::Hit;
use crate::scene::material::MaterialClass;
use crate::transport::interaction::{RayKind, ShadowQuery};

/// Where hits are routed: one hit queue per material class.
pub trait ClassHitQueues {
    /// The hit queue of `class`.
    fn queue_mut(&mut self, class: MaterialClass) -> &mut HitQueue;

    /// Every class's hit queue, indexed by `class as usize`.
    fn all_mut(&mut self) -> [&mut HitQueue; MaterialClass::ALL.len()];
}

/// Routes every ray of the bounce after its closest-hit test, in ray
/// order: ray `i`, whose closest hit is `found[i]`, goes to `escaped` on
/// a miss, else to the hit queue of its material's class (`classes`
/// holds the class of each material). Each queue receives ascending ray
/// indices.
pub fn route_rays(
    classes: &[MaterialClass],
    found: &[Option<Hit>],
    escaped: &mut EscapedQueue,
    hits: &mut impl ClassHitQueues,
) {
    let queues = hits.all_mut();
    for (i, f) in found.iter().enumerate() {
        match f {
            None => escaped.push(i as u32),
            Some(h) => queues[classes[h.material as usize] as usize].push(i as u32),
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
pub fn join_shade_outputs(outputs: &mut [ShadeOutput], to: ShadeTargets<'_>) {
    for out in outputs.iter_mut() {
        for &(path, l) in &out.emitted {
            to.radiance[path as usize] += l;
        }
        to.shadows.take(&mut out.shadows);
        to.next.append(&out.reflections);
        to.rays.add(&out.counts);
    }
    for out in outputs.iter() {
        to.next.append(&out.refractions);
    }
}
