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

    /// Adds rays traced inside a stage: `crossings` boundary crossings
    /// (counted as refraction rays) and `shadows` shadow rays (of point
    /// lights in media).
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

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3A};

    use super::*;

    /// Hit queues indexed by class, as the ECS side keeps them.
    #[derive(Default)]
    struct Queues([HitQueue; MaterialClass::ALL.len()]);

    impl ClassHitQueues for Queues {
        fn queue_mut(&mut self, class: MaterialClass) -> &mut HitQueue {
            &mut self.0[class as usize]
        }

        fn all_mut(&mut self) -> [&mut HitQueue; MaterialClass::ALL.len()] {
            self.0.each_mut()
        }
    }

    fn hit(material: u32) -> Hit {
        Hit {
            t: 1.0,
            point: Vec3A::ZERO,
            geometric_normal: Vec3A::Y,
            shading_normal: Vec3A::Y,
            uv: Vec2::ZERO,
            uv_density: 0.0,
            instance: 0,
            material,
        }
    }

    /// Every ray goes to exactly one queue: misses to the escaped queue,
    /// hits to their material's class, each queue in ascending ray order
    /// (the order shading then reads them in, which keeps the next
    /// bounce's ray order, and so the image, what it was with copied hits).
    #[test]
    fn every_ray_is_routed_once_by_class_in_ray_order() {
        let classes = [
            MaterialClass::Diffuse,
            MaterialClass::Glass,
            MaterialClass::Diffuse,
        ];
        let found: Vec<Option<Hit>> = (0..1000u32)
            .map(|i| (i % 7 != 3).then(|| hit(i % 3)))
            .collect();
        let mut escaped = EscapedQueue::default();
        let mut queues = Queues::default();
        route_rays(&classes, &found, &mut escaped, &mut queues);
        let mut seen = vec![0u32; found.len()];
        for &i in &escaped.ray {
            assert!(found[i as usize].is_none());
            seen[i as usize] += 1;
        }
        for class in MaterialClass::ALL {
            let q = &queues.0[class as usize];
            assert!(q.ray.windows(2).all(|w| w[0] < w[1]), "{class:?}");
            for &i in &q.ray {
                let m = found[i as usize].expect("a hit").material;
                assert_eq!(classes[m as usize], class);
                seen[i as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        assert_eq!(escaped.len(), (0..1000).filter(|i| i % 7 == 3).count());
        assert!(queues.0[MaterialClass::Mirror as usize].is_empty());
        assert!(!queues.0[MaterialClass::Glass as usize].is_empty());
    }
}
