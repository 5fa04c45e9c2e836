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

use crate::accel::packet::LaneMask;
use crate::core::math::{Color, Ray};
use crate::integrators::counters::RayCounts;
use crate::integrators::wavefront::queues::{
    EscapedQueue, HitItem, HitQueue, LitQueue, QueueBytes, RayItem, RayQueue, ShadowItem,
    ShadowQueue, ShadowSegments,
};
use crate::scene::Hit;
use crate::scene::material::MaterialClass;
use crate::scene::query::COHERENT_LANES;
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
    /// Shadow rays of the group of hits being shaded, until
    /// [`ShadeOutput::trace_shadows`] or
    /// [`ShadeOutput::trace_shadows_through`] traces them.
    shadows: ShadowQueue,
    /// Where each hit's shadow rays end in `shadows`, for the group of
    /// hits being shaded.
    hit_ends: Vec<u32>,
    /// Radiance brought back by the shadow rays traced so far.
    lit: LitQueue,
    /// Scratch of [`ShadeOutput::trace_shadows`]: the order rays are
    /// traced in, and which are unblocked.
    order: Vec<u32>,
    visible: Vec<bool>,
    reflections: RayQueue,
    refractions: RayQueue,
    counts: RayCounts,
}

impl ShadeOutput {
    /// Removes everything, keeping the buffers.
    pub fn clear(&mut self) {
        self.emitted.clear();
        self.shadows.clear();
        self.hit_ends.clear();
        self.lit.clear();
        self.reflections.clear();
        self.refractions.clear();
        self.counts = RayCounts::default();
    }

    /// Marks the end of one hit's shadow rays in the group of hits whose
    /// rays [`ShadeOutput::trace_shadows`] traces next.
    #[inline]
    pub fn end_hit(&mut self) {
        self.hit_ends.push(self.shadows.len() as u32);
    }

    /// Traces the shadow rays of the group of hits shaded since the last
    /// call (each hit closed by [`ShadeOutput::end_hit`]) and keeps the
    /// radiance of the unblocked ones, in queue order, for the shadow
    /// stage to add. The rays are traced in groups of up to `width` (at
    /// most [`COHERENT_LANES`]) taken across the hits: every hit's first ray, then every hit's
    /// second ray, and so on, so that a group holds the rays of
    /// neighbouring hits towards one light (the first light that can
    /// light them, the second...), which point alike; `occluded` returns
    /// the mask of the blocked rays of a group.
    pub fn trace_shadows(&mut self, width: usize, occluded: impl Fn(&[Ray], &[f32]) -> LaneMask) {
        let width = width.clamp(1, COHERENT_LANES);
        let n = self.shadows.len();
        if n == 0 {
            self.hit_ends.clear();
            return;
        }
        self.order.clear();
        for slot in 0.. {
            let before = self.order.len();
            let mut start = 0;
            for &end in &self.hit_ends {
                if start + slot < end {
                    self.order.push(start + slot);
                }
                start = end;
            }
            if self.order.len() == before {
                break;
            }
        }
        debug_assert_eq!(self.order.len(), n);
        self.visible.clear();
        self.visible.resize(n, false);
        let q = &self.shadows;
        for group in self.order.chunks(width) {
            let m = group.len();
            let rays: [Ray; COHERENT_LANES] =
                std::array::from_fn(|l| q.ray(group[l.min(m - 1)] as usize));
            let t_max: [f32; COHERENT_LANES] =
                std::array::from_fn(|l| q.t_max[group[l.min(m - 1)] as usize]);
            let blocked = occluded(&rays[..m], &t_max[..m]);
            for (l, &j) in group.iter().enumerate() {
                self.visible[j as usize] = blocked & (1 << l) == 0;
            }
        }
        for (j, &v) in self.visible.iter().enumerate() {
            if v {
                self.lit.push(q.path[j], q.radiance[j]);
            }
        }
        self.shadows.clear();
        self.hit_ends.clear();
    }

    /// Traces the shadow rays of the group of hits shaded since the last
    /// call all at once: `occluded(rays, t_max, blocked)` sets
    /// `blocked[j]` for each ray `j` of the group, in queue order (for
    /// [`crate::scene::triangles::TriangleBatch`], which sorts them
    /// itself). The radiance of the unblocked rays is kept as
    /// [`ShadeOutput::trace_shadows`] keeps it.
    pub fn trace_shadows_all(&mut self, occluded: impl Fn(&[Ray], &[f32], &mut [bool])) {
        let n = self.shadows.len();
        if n > 0 {
            let q = &self.shadows;
            let rays: Vec<Ray> = (0..n).map(|j| q.ray(j)).collect();
            self.visible.clear();
            self.visible.resize(n, false);
            occluded(&rays, &q.t_max[..n], &mut self.visible);
            for (j, &blocked) in self.visible.iter().enumerate() {
                if !blocked {
                    self.lit.push(q.path[j], q.radiance[j]);
                }
            }
        }
        self.shadows.clear();
        self.hit_ends.clear();
    }

    /// Traces the shadow rays pushed since the last call one at a time,
    /// in order, through the media they cross: `transmittance` gives each
    /// ray's, and the radiance of the rays that bring any back is kept for
    /// the shadow stage to add.
    pub fn trace_shadows_through(&mut self, transmittance: impl Fn(&Ray, f32) -> Color) {
        let lit = &mut self.lit;
        light_through(&self.shadows, transmittance, |path, l| lit.push(path, l));
        self.shadows.clear();
        self.hit_ends.clear();
    }

    /// [`ShadeOutput::trace_shadows_through`], adding the radiance the
    /// rays bring back to their paths as emission, after what the chunk
    /// emitted so far, instead of keeping it for the shadow stage: for a
    /// stage that follows a path on past the vertex that made the rays
    /// (the media stage's walks), so that each path's terms keep the order
    /// of its vertices.
    pub fn trace_shadows_through_now(&mut self, transmittance: impl Fn(&Ray, f32) -> Color) {
        let emitted = &mut self.emitted;
        light_through(&self.shadows, transmittance, |path, l| {
            emitted.push((path, l))
        });
        self.shadows.clear();
        self.hit_ends.clear();
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
        self.count_secondary(kind);
        if kind == RayKind::Refraction {
            self.refractions.push(item);
        } else {
            self.reflections.push(item);
        }
    }

    /// Counts a reflection or refraction ray that the stage follows
    /// itself instead of queueing it (an unlit step of a random walk in
    /// a medium), as [`ShadeOutput::push_secondary`] counts a queued one.
    #[inline]
    pub fn count_secondary(&mut self, kind: RayKind) {
        if kind == RayKind::Refraction {
            self.counts.refraction += 1;
        } else {
            self.counts.reflection += 1;
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
            + self.lit.bytes()
            + (self.hit_ends.capacity() + self.order.capacity()) * std::mem::size_of::<u32>()
            + self.visible.capacity()
            + self.reflections.bytes()
            + self.refractions.bytes()
    }
}

/// Traces the shadow rays of `q` one at a time, in order, with
/// `transmittance`, and hands each one that brings light back to `sink`
/// (its path and radiance).
#[inline(always)]
fn light_through(
    q: &ShadowQueue,
    transmittance: impl Fn(&Ray, f32) -> Color,
    mut sink: impl FnMut(u32, Color),
) {
    for j in 0..q.len() {
        let t = transmittance(&q.ray(j), q.t_max[j]);
        if t != Color::ZERO {
            sink(q.path[j], q.radiance[j] * t);
        }
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
        debug_assert!(out.shadows.is_empty(), "shadow rays left untraced");
        to.shadows.take(&mut out.lit);
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

    /// A chunk that traces its own shadow rays traces every ray of the
    /// group exactly once, in groups of at most the width asked for (8 or
    /// 16) that take the
    /// hits' first rays, then their second rays, and so on, and passes on
    /// the radiance of the unblocked rays in queue order (hit by hit,
    /// each hit's rays in the order pushed), whatever order they were
    /// traced in: the order each path's radiance is summed in.
    #[test]
    fn shadow_rays_traced_by_slot_are_passed_on_in_queue_order() {
        use crate::accel::packet::LANES;
        use std::cell::RefCell;

        for width in [LANES, COHERENT_LANES] {
            // Hit h pushes counts[h] rays; ray k of hit h is keyed 100 h + k
            // (in its origin's x, its path and its radiance).
            let counts = [2usize, 0, 3, 1, 12, 2, 1, 1, 1, 3];
            let mut out = ShadeOutput::default();
            for (h, &n) in counts.iter().enumerate() {
                for k in 0..n {
                    let key = (100 * h + k) as u32;
                    let q = ShadowQuery {
                        ray: Ray::new(Vec3A::new(key as f32, 0.0, 0.0), Vec3A::Y),
                        t_max: 1.0,
                        radiance: Color::splat(key as f32),
                    };
                    out.push_shadow_from(key, Color::ONE, q);
                }
                out.end_hit();
            }
            let groups = RefCell::new(Vec::new());
            // Rays with an odd key are blocked.
            out.trace_shadows(width, |rays, t_max| {
                assert_eq!(rays.len(), t_max.len());
                let keys: Vec<u32> = rays.iter().map(|r| r.origin.x as u32).collect();
                let blocked = keys
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| *k % 2 == 1)
                    .fold(0, |m, (l, _)| m | 1 << l);
                groups.borrow_mut().push(keys);
                blocked
            });
            // By slot: every hit's first ray, then every hit's second ...
            let by_slot: Vec<u32> = (0..12)
                .flat_map(|k| {
                    counts
                        .iter()
                        .enumerate()
                        .filter(move |(_, n)| k < **n)
                        .map(move |(h, _)| (100 * h + k) as u32)
                })
                .collect();
            let groups = groups.into_inner();
            assert!(groups.iter().all(|g| !g.is_empty() && g.len() <= width));
            assert_eq!(groups.concat(), by_slot);
            assert_eq!(
                groups[0].len(),
                width,
                "the hits' first rays share a packet"
            );
            // Passed on: the even keys, in queue order.
            let in_queue_order: Vec<u32> = counts
                .iter()
                .enumerate()
                .flat_map(|(h, &n)| (0..n).map(move |k| (100 * h + k) as u32))
                .filter(|k| k % 2 == 0)
                .collect();
            assert_eq!(out.lit.path, in_queue_order);
            let radiance: Vec<u32> = out.lit.radiance.iter().map(|c| c.x as u32).collect();
            assert_eq!(radiance, in_queue_order);
            assert!(out.shadows.is_empty() && out.hit_ends.is_empty());
            // Handed over whole at the join, after the emission.
            let mut radiance = vec![Color::ZERO; 1300];
            let mut shadows = ShadowSegments::default();
            let mut next = RayQueue::default();
            let mut rays = RayCounts::default();
            join_shade_outputs(
                std::slice::from_mut(&mut out),
                ShadeTargets {
                    radiance: &mut radiance,
                    shadows: &mut shadows,
                    next: &mut next,
                    rays: &mut rays,
                },
            );
            assert_eq!(shadows.len(), in_queue_order.len());
            assert_eq!(rays.shadow, counts.iter().sum::<usize>() as u64);
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
