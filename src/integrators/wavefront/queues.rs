//! Structure-of-arrays work queues for the wavefront integrator.
//!
//! A queue holds one `Vec` per field of its item; it only knows how to
//! push, read back and clear. Which queue an item goes to is decided by the
//! integrator's stages, never here. Pushes assert (in debug builds) that no
//! NaN or infinity enters a queue.

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use crate::core::math::{Color, Ray, RayCone};
use crate::integrators::wavefront::CHUNK;
use crate::scene::Hit;

/// Memory held by a queue's buffers, in bytes (capacity, not length).
pub trait QueueBytes {
    /// Bytes allocated.
    fn bytes(&self) -> usize;
}

fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

/// The field-by-field methods every structure-of-arrays queue has: length
/// (of the field `$len`), `clear`, `append`, [`QueueBytes`] and
/// [`Segment`], over the
/// listed fields, which must be all of the queue's `Vec`s.
macro_rules! soa_queue {
    ($queue:ident, $what:literal, $len:ident, [$($field:ident),+ $(,)?]) => {
        impl $queue {
            #[doc = concat!("Number of ", $what, ".")]
            pub fn len(&self) -> usize {
                self.$len.len()
            }

            #[doc = concat!("True when no ", $what, " are queued.")]
            pub fn is_empty(&self) -> bool {
                self.$len.is_empty()
            }

            #[doc = concat!("Removes all ", $what, ", keeping the allocation.")]
            pub fn clear(&mut self) {
                $(self.$field.clear();)+
            }

            #[doc = concat!("Appends all ", $what, " of `other`, in order.")]
            pub fn append(&mut self, other: &$queue) {
                $(self.$field.extend_from_slice(&other.$field);)+
            }
        }

        impl QueueBytes for $queue {
            fn bytes(&self) -> usize {
                0 $(+ vec_bytes(&self.$field))+
            }
        }

        impl Segment for $queue {
            fn is_empty(&self) -> bool {
                $queue::is_empty(self)
            }

            fn clear(&mut self) {
                $queue::clear(self)
            }

            fn len(&self) -> usize {
                $queue::len(self)
            }
        }
    };
}

/// A ray waiting to be traced, with the path it belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayItem {
    /// The ray (origin already offset from the surface it leaves).
    pub ray: Ray,
    /// Weight of the radiance it brings back, relative to the pixel sample.
    pub throughput: Color,
    /// Index of the path (pixel sample) within the batch.
    pub path: u32,
    /// Bounces so far (0 for camera rays).
    pub depth: u32,
    /// Path tracing: density with which the direction was drawn (zero for
    /// camera rays and specular lobes, and unused by Whitted transport).
    pub pdf: f32,
    /// The ray's cone at its origin (texture level of detail).
    pub cone: RayCone,
}

/// Rays to trace, by field.
#[derive(Clone, Debug, Default)]
pub struct RayQueue {
    /// Origins.
    pub origin: Vec<Vec3A>,
    /// Directions (unit).
    pub direction: Vec<Vec3A>,
    /// Path throughputs.
    pub throughput: Vec<Color>,
    /// Path indices within the batch.
    pub path: Vec<u32>,
    /// Bounce depths.
    pub depth: Vec<u32>,
    /// Direction densities (path tracing).
    pub pdf: Vec<f32>,
    /// Ray cones at the origins.
    pub cone: Vec<RayCone>,
}

impl RayQueue {
    /// Appends a ray.
    #[inline(always)]
    pub fn push(&mut self, item: RayItem) {
        debug_assert!(
            item.ray.origin.is_finite() && item.ray.direction.is_finite(),
            "non-finite ray pushed: {item:?}"
        );
        debug_assert!(
            item.throughput.is_finite(),
            "non-finite throughput: {item:?}"
        );
        self.origin.push(item.ray.origin);
        self.direction.push(item.ray.direction);
        self.throughput.push(item.throughput);
        self.path.push(item.path);
        self.depth.push(item.depth);
        self.pdf.push(item.pdf);
        self.cone.push(item.cone);
    }

    /// The ray at `i`.
    #[inline]
    pub fn ray(&self, i: usize) -> Ray {
        Ray::new(self.origin[i], self.direction[i])
    }

    /// The item at `i`.
    #[inline]
    pub fn get(&self, i: usize) -> RayItem {
        RayItem {
            ray: self.ray(i),
            throughput: self.throughput[i],
            path: self.path[i],
            depth: self.depth[i],
            pdf: self.pdf[i],
            cone: self.cone[i],
        }
    }
}

impl RayQueue {
    /// Replaces the queue's rays with `item(0)`, ..., `item(count - 1)`,
    /// made in parallel chunks of [`CHUNK`] rays, each written in place.
    pub fn fill_with(&mut self, count: usize, item: impl Fn(usize) -> RayItem + Sync) {
        self.fill_chunks(count, |range| range.map(&item));
    }

    /// Replaces the queue's rays with `count` rays made in parallel chunks
    /// of [`CHUNK`] rays, each written in place: `items(range)` gives the
    /// rays of the indices `range` in order (at least `range.len()` of
    /// them).
    pub fn fill_chunks<I: Iterator<Item = RayItem>>(
        &mut self,
        count: usize,
        items: impl Fn(std::ops::Range<usize>) -> I + Sync,
    ) {
        // The rays are written into the fields' spare capacity, which then
        // becomes their contents: resizing first filled every slot of all
        // seven fields at each batch (the queue is cleared between
        // batches), a quarter of the camera-ray stage's instructions
        // (callgrind, `assets/bench/camera_only.toml`).
        self.clear();
        self.origin.reserve(count);
        self.direction.reserve(count);
        self.throughput.reserve(count);
        self.path.reserve(count);
        self.depth.reserve(count);
        self.pdf.reserve(count);
        self.cone.reserve(count);
        (
            self.origin.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.direction.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.throughput.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.path.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.depth.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.pdf.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
            self.cone.spare_capacity_mut()[..count].par_chunks_mut(CHUNK),
        )
            .into_par_iter()
            .enumerate()
            .with_max_len(1)
            .for_each(
                |(c, (origin, direction, throughput, path, depth, pdf, cone))| {
                    let start = c * CHUNK;
                    let mut items = items(start..start + origin.len());
                    for k in 0..origin.len() {
                        let it = items.next().expect("a ray per index");
                        debug_assert!(
                            it.ray.origin.is_finite() && it.ray.direction.is_finite(),
                            "non-finite ray: {it:?}"
                        );
                        origin[k].write(it.ray.origin);
                        direction[k].write(it.ray.direction);
                        throughput[k].write(it.throughput);
                        path[k].write(it.path);
                        depth[k].write(it.depth);
                        pdf[k].write(it.pdf);
                        cone[k].write(it.cone);
                    }
                },
            );
        // SAFETY: the loop above wrote slots `0..count` of every field
        // (each chunk every index of its range; a chunk that could not
        // panicked, and then this is not reached), and the capacity holds
        // `count` (reserved above).
        #[allow(unsafe_code)]
        unsafe {
            self.origin.set_len(count);
            self.direction.set_len(count);
            self.throughput.set_len(count);
            self.path.set_len(count);
            self.depth.set_len(count);
            self.pdf.set_len(count);
            self.cone.set_len(count);
        }
    }
}

soa_queue!(
    RayQueue,
    "rays",
    path,
    [origin, direction, throughput, path, depth, pdf, cone]
);

/// A surface hit as a shading stage sees it: the hit found by a ray of
/// the current bounce, with that ray's path state. Built on the fly from
/// the ray queue and the closest hits ([`HitItem::new`]); the hit queues
/// themselves hold only ray indices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitItem {
    /// Direction of the ray that found the hit.
    pub direction: Vec3A,
    /// World-space hit point.
    pub point: Vec3A,
    /// Unit geometric normal (as the geometry defines it).
    pub geometric_normal: Vec3A,
    /// Unit shading normal.
    pub shading_normal: Vec3A,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Material index.
    pub material: u32,
    /// Path throughput.
    pub throughput: Color,
    /// Path index.
    pub path: u32,
    /// Bounce depth of the ray that hit.
    pub depth: u32,
    /// Instance hit.
    pub instance: u32,
    /// Length of the ray segment to the hit.
    pub distance: f32,
    /// Density of the ray's direction (path tracing; see [`RayItem::pdf`]).
    pub pdf: f32,
    /// Texture coordinates per world length ([`Hit::uv_density`]).
    pub uv_density: f32,
    /// The cone of the ray that hit, at its origin.
    pub cone: RayCone,
}

impl HitItem {
    /// The shading view of `hit`, found by `ray` (whose direction is unit).
    #[inline]
    pub fn new(hit: &Hit, ray: &RayItem) -> Self {
        Self {
            direction: ray.ray.direction,
            point: hit.point,
            geometric_normal: hit.geometric_normal,
            shading_normal: hit.shading_normal,
            uv: hit.uv,
            material: hit.material,
            throughput: ray.throughput,
            path: ray.path,
            depth: ray.depth,
            instance: hit.instance,
            distance: hit.t * ray.ray.direction.length(),
            pdf: ray.pdf,
            uv_density: hit.uv_density,
            cone: ray.cone,
        }
    }

    /// The surface point as a [`Hit`] for shading (`t` is the distance
    /// along the unit direction).
    #[inline]
    pub fn hit(&self) -> Hit {
        Hit {
            t: self.distance,
            point: self.point,
            geometric_normal: self.geometric_normal,
            shading_normal: self.shading_normal,
            uv: self.uv,
            uv_density: self.uv_density,
            instance: self.instance,
            material: self.material,
        }
    }
}

/// The closest hit of every ray of the current bounce, indexed like the
/// ray queue (`None`: the ray left the scene). The closest-hit stage
/// writes it in place, chunk by chunk; the shading stages read it.
#[derive(Clone, Debug, Default)]
pub struct ClosestHits(pub Vec<Option<Hit>>);

impl QueueBytes for ClosestHits {
    fn bytes(&self) -> usize {
        vec_bytes(&self.0)
    }
}

/// A queue of rays of the current bounce by index: the rays whose hit is
/// on one material class (a hit queue), or the rays that escaped. Items
/// are 4 bytes; what a stage needs of a ray it reads from the ray queue
/// and [`ClosestHits`] at that index.
#[derive(Clone, Debug, Default)]
pub struct RayIndexQueue {
    /// Indices into the ray queue, ascending.
    pub ray: Vec<u32>,
}

impl RayIndexQueue {
    /// Appends ray `i`.
    #[inline]
    pub fn push(&mut self, i: u32) {
        self.ray.push(i);
    }
}

soa_queue!(RayIndexQueue, "rays", ray, [ray]);

/// Hits on one material class: indices of the rays that found them.
pub type HitQueue = RayIndexQueue;

/// Rays that left the scene: they bring back the background or the
/// environment.
pub type EscapedQueue = RayIndexQueue;

/// A shadow ray and what it adds to its path if nothing blocks it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowItem {
    /// The ray towards the light.
    pub ray: Ray,
    /// Far end of the segment (the light's distance, or infinity).
    pub t_max: f32,
    /// Radiance added to the path if visible, throughput included.
    pub radiance: Color,
    /// Path index.
    pub path: u32,
}

/// Shadow rays, by field.
#[derive(Clone, Debug, Default)]
pub struct ShadowQueue {
    /// Origins.
    pub origin: Vec<Vec3A>,
    /// Directions.
    pub direction: Vec<Vec3A>,
    /// Segment ends.
    pub t_max: Vec<f32>,
    /// Radiance if unoccluded.
    pub radiance: Vec<Color>,
    /// Path indices.
    pub path: Vec<u32>,
}

impl ShadowQueue {
    /// Appends a shadow ray.
    #[inline(always)]
    pub fn push(&mut self, item: ShadowItem) {
        debug_assert!(
            item.ray.origin.is_finite() && item.ray.direction.is_finite(),
            "non-finite shadow ray: {item:?}"
        );
        debug_assert!(!item.t_max.is_nan(), "NaN shadow extent: {item:?}");
        self.origin.push(item.ray.origin);
        self.direction.push(item.ray.direction);
        self.t_max.push(item.t_max);
        self.radiance.push(item.radiance);
        self.path.push(item.path);
    }

    /// The ray at `i`.
    #[inline]
    pub fn ray(&self, i: usize) -> Ray {
        Ray::new(self.origin[i], self.direction[i])
    }
}

soa_queue!(
    ShadowQueue,
    "shadow rays",
    path,
    [origin, direction, t_max, radiance, path]
);

/// Radiance that shadow rays brought back (unblocked, or through media
/// with their transmittance), for their paths: what a stage that traced
/// its own shadow rays hands on, in queue order, to be added after every
/// shading stage of the bounce (the order in which each path's terms are
/// summed).
#[derive(Clone, Debug, Default)]
pub struct LitQueue {
    /// Path indices.
    pub path: Vec<u32>,
    /// Radiance to add, throughput included.
    pub radiance: Vec<Color>,
}

impl LitQueue {
    /// Appends radiance `l` for path `path`.
    #[inline(always)]
    pub fn push(&mut self, path: u32, l: Color) {
        self.path.push(path);
        self.radiance.push(l);
    }
}

soa_queue!(LitQueue, "contributions", path, [path, radiance]);

/// A queue a shading chunk hands over whole ([`Segments::take`]).
pub trait Segment: Default + QueueBytes {
    /// True when nothing is queued.
    fn is_empty(&self) -> bool;
    /// Removes everything, keeping the allocation.
    fn clear(&mut self);
    /// Number of items.
    fn len(&self) -> usize;
}

/// A queue kept as the per-chunk segments that filled it, in chunk
/// order: a shading chunk hands its whole buffer over
/// ([`Segments::take`]) instead of copying it into one long queue, and
/// gets an empty, already allocated buffer back. Readers go through the
/// segments in order, so results do not depend on the thread count.
#[derive(Clone, Debug)]
pub struct Segments<Q> {
    segments: Vec<Q>,
    used: usize,
}

impl<Q> Default for Segments<Q> {
    fn default() -> Self {
        Self {
            segments: Vec::new(),
            used: 0,
        }
    }
}

impl<Q: Segment> Segments<Q> {
    /// Appends the items of `q` as the next segment, leaving in `q` an
    /// empty buffer (one of this queue's spares) for reuse.
    pub fn take(&mut self, q: &mut Q) {
        if q.is_empty() {
            return;
        }
        if self.used == self.segments.len() {
            self.segments.push(Q::default());
        }
        std::mem::swap(&mut self.segments[self.used], q);
        self.used += 1;
    }

    /// The segments in order.
    pub fn segments(&self) -> &[Q] {
        &self.segments[..self.used]
    }

    /// Total number of items.
    pub fn len(&self) -> usize {
        self.segments().iter().map(|s| s.len()).sum()
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.used == 0
    }

    /// Removes every item, keeping the buffers.
    pub fn clear(&mut self) {
        for s in &mut self.segments[..self.used] {
            s.clear();
        }
        self.used = 0;
    }
}

impl<Q: QueueBytes> QueueBytes for Segments<Q> {
    fn bytes(&self) -> usize {
        self.segments.iter().map(|s| s.bytes()).sum()
    }
}

/// The radiance of a bounce's unblocked shadow rays, as the chunks that
/// traced them handed it over, in chunk order.
pub type ShadowSegments = Segments<LitQueue>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queues_round_trip_and_clear() {
        let mut q = RayQueue::default();
        let item = RayItem {
            ray: Ray::new(Vec3A::new(1.0, 2.0, 3.0), Vec3A::X),
            throughput: Color::new(0.5, 0.25, 1.0),
            path: 7,
            depth: 2,
            pdf: 0.25,
            cone: RayCone::NONE,
        };
        q.push(item);
        q.push(RayItem { path: 8, ..item });
        assert_eq!(q.len(), 2);
        assert_eq!(q.get(0), item);
        assert_eq!(q.get(1).path, 8);
        let bytes = q.bytes();
        assert!(bytes >= 2 * (16 + 16 + 12 + 4 + 4 + 4));
        q.clear();
        assert!(q.is_empty());
        assert_eq!(q.bytes(), bytes, "clearing keeps the allocation");
    }

    /// Rays made in parallel chunks land where sequential pushes put
    /// them, whatever the thread count.
    #[test]
    fn rays_filled_in_parallel_equal_rays_pushed_in_order() {
        let item = |i: usize| RayItem {
            ray: Ray::new(Vec3A::new(i as f32, 0.5, -1.0), Vec3A::Y),
            throughput: Color::new(1.0, 0.5, i as f32),
            path: i as u32,
            depth: (i % 5) as u32,
            pdf: 0.25 * i as f32,
            cone: RayCone::NONE,
        };
        let n = 3 * CHUNK + 5;
        let mut pushed = RayQueue::default();
        for i in 0..n {
            pushed.push(item(i));
        }
        for threads in [1, 2, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut filled = RayQueue::default();
            // A longer queue first: filling replaces it.
            filled.push(item(7));
            pool.install(|| filled.fill_with(n, item));
            assert_eq!(filled.len(), n);
            assert!((0..n).all(|i| filled.get(i) == pushed.get(i)), "{threads}");
        }
    }

    #[test]
    #[cfg(debug_assertions)]
    #[should_panic(expected = "non-finite")]
    fn nan_cannot_enter_a_ray_queue() {
        let mut q = RayQueue::default();
        q.push(RayItem {
            ray: Ray::new(Vec3A::new(f32::NAN, 0.0, 0.0), Vec3A::X),
            throughput: Color::ONE,
            path: 0,
            depth: 0,
            pdf: 0.0,
            cone: RayCone::NONE,
        });
    }

    #[test]
    #[cfg(debug_assertions)]
    #[should_panic(expected = "non-finite")]
    fn nan_cannot_enter_a_shadow_queue() {
        let mut q = ShadowQueue::default();
        q.push(ShadowItem {
            ray: Ray::new(Vec3A::ZERO, Vec3A::new(0.0, f32::INFINITY, 0.0)),
            t_max: 1.0,
            radiance: Color::ONE,
            path: 0,
        });
    }
}
