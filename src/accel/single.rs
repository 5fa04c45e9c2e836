//! Single-ray traversal of a [`Bvh8`]: nearest child first, with entry
//! distances on the stack so that subtrees made stale by a closer hit are
//! dropped without being tested.

use std::mem::MaybeUninit;

use crate::accel::bvh8::{Bvh8, LEAF, WIDTH, leaf_count, leaf_index};
use crate::accel::node::NodeRay;
use crate::core::math::Ray;

/// Entries held in the traversal's own frame (2 KiB): enough for trees
/// of up to 36 levels; deeper ones (large or degenerate input, see the
/// deep-tree test in `geometry::mesh`) get a heap buffer of their own.
const FIXED: usize = 256;

/// Pending subtrees: `entry distance bits << 32 | child reference`, in a
/// buffer of a power-of-two length at least `7 * depth + 1` (a node
/// stacks at most seven children, and only the nodes on the path from the
/// root have entries waiting), so pushes and pops need no bounds check
/// and no test for a full buffer: the index is masked. A tree whose
/// `depth` understates its levels would wrap around and lose subtrees,
/// never read outside the buffer or an unwritten entry (every slot below
/// `len` was written when `len` last passed it).
///
/// The buffer is left uninitialised: zeroing it cost about 80
/// instructions per traversal, a tenth of all the instructions of a frame
/// of the frame-loop benchmark (callgrind), and only written entries are
/// read. The earlier stack (a fixed part with a spill `Vec`) kept its
/// length in memory and tested for the spill at every pop: about 15
/// instructions per ray on the anchors' bounce rays (callgrind).
pub(crate) struct Stack<'a> {
    buf: &'a mut [MaybeUninit<u64>],
    mask: usize,
    len: usize,
}

impl<'a> Stack<'a> {
    /// A stack over `buf`, whose length is a power of two.
    #[inline(always)]
    pub(crate) fn new(buf: &'a mut [MaybeUninit<u64>]) -> Self {
        assert!(buf.len().is_power_of_two());
        let mask = buf.len() - 1;
        Self { buf, mask, len: 0 }
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, v: u64) {
        // SAFETY: `len & mask` is below `buf.len()`, a power of two.
        #[allow(unsafe_code)]
        unsafe { self.buf.get_unchecked_mut(self.len & self.mask) }.write(v);
        self.len += 1;
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<u64> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: in bounds as in `push`; the slot was written when `len`
        // last went from this value up (it starts at 0 and moves by one).
        #[allow(unsafe_code)]
        Some(unsafe { self.buf.get_unchecked(self.len & self.mask).assume_init() })
    }
}

/// Entries a traversal of `bvh` can have pending at once (see [`Stack`]).
#[inline(always)]
fn stack_need(bvh: &Bvh8) -> usize {
    (WIDTH - 1) * bvh.depth + 1
}

/// A heap buffer for a stack of `need` entries (trees deeper than the
/// frame's buffer covers): out of line, so that the traversal loops
/// inlined into every query do not each carry the allocation.
#[cold]
#[inline(never)]
fn heap_buffer(need: usize) -> Vec<MaybeUninit<u64>> {
    vec![MaybeUninit::uninit(); need.next_power_of_two()]
}

/// `bits` of an `f32` as an unsigned integer that orders as the float
/// does (for everything but NaN, and `-0.0` just below `0.0`).
#[inline(always)]
fn sortable(bits: u32) -> u32 {
    bits ^ ((((bits as i32) >> 31) as u32) | 0x8000_0000)
}

/// A stack entry.
#[inline(always)]
pub(crate) fn entry(t: f32, child: u32) -> u64 {
    ((t.to_bits() as u64) << 32) | child as u64
}

/// The entry distance and child of a stack entry.
#[inline(always)]
pub(crate) fn unpack(e: u64) -> (f32, u32) {
    (f32::from_bits((e >> 32) as u32), e as u32)
}

/// Traverses `bvh` from node `start` with `ray` (prepared for `bvh`),
/// searching `(t_min, t_max)`.
///
/// `visit(leaf, t_max)` tests the primitives of leaf `leaf` (an index
/// into [`Bvh8::leaves`]) and returns the `t` of the nearest hit inside
/// `(t_min, t_max)`, which then shrinks `t_max`. With `any_hit` the
/// traversal ends at the first hit (shadow rays). Returns whether any
/// primitive was hit.
///
/// At each node the entered children are sorted by entry distance; the
/// nearest is visited next and the others are stacked with their
/// distances, so a popped entry farther than the closest hit found since
/// is dropped.
#[inline(always)]
pub fn traverse_from<const AVX: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    mut visit: impl FnMut(u32, f32) -> Option<f32>,
) -> bool {
    traverse_from_with::<AVX, false>(
        bvh,
        start,
        ray,
        t_min,
        t_max,
        any_hit,
        #[inline(always)]
        |leaf, _, t_max| visit(leaf, t_max),
        |_| {},
    )
}

/// [`traverse_from`] with `visit(leaf, count, t_max)` told the number of
/// primitives in the leaf (from its reference, without reading
/// [`Bvh8::leaves`]), and `prefetch_leaf(leaf)`, called for a leaf that
/// will be visited soon (it was entered beside a sibling), to start
/// loading what its visit reads. Nodes entered beside a sibling are
/// prefetched the same way. With `FUSED` the nodes are tested with
/// [`NodeRay::test_fused`]: only for queries whose hits do not depend on
/// the order in which leaves are visited.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn traverse_from_with<const AVX: bool, const FUSED: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    if bvh.nodes.is_empty() {
        return false;
    }
    // One buffer, chosen here, so that the loop below is compiled once
    // per `FMA` whichever buffer it gets (one loop per buffer made the
    // crate's release build four times longer).
    let need = stack_need(bvh);
    let mut fixed = [const { MaybeUninit::<u64>::uninit() }; FIXED];
    let mut heap;
    let buf: &mut [MaybeUninit<u64>] = if need <= FIXED {
        &mut fixed
    } else {
        heap = heap_buffer(need);
        &mut heap
    };
    let stack = Stack::new(buf);
    if FUSED && AVX && ray.fused {
        walk::<AVX, true>(
            bvh,
            stack,
            start,
            ray,
            t_min,
            t_max,
            any_hit,
            visit,
            prefetch_leaf,
        )
    } else {
        walk::<AVX, false>(
            bvh,
            stack,
            start,
            ray,
            t_min,
            t_max,
            any_hit,
            visit,
            prefetch_leaf,
        )
    }
}

/// [`traverse_from_with`]'s loop; with `FMA`, every node is tested in the
/// fused form ([`NodeRay::test_fma_known`]: the ray allows it).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn walk<const AVX: bool, const FMA: bool>(
    bvh: &Bvh8,
    mut stack: Stack<'_>,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    mut t_max: f32,
    any_hit: bool,
    mut visit: impl FnMut(u32, u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    let prefetch = |r: u32| {
        if r & LEAF == 0 {
            prefetch_bytes(
                &bvh.nodes[r as usize],
                std::mem::size_of::<crate::accel::bvh8::Node8>(),
            );
        } else {
            prefetch_leaf(leaf_index(r));
        }
    };
    let mut any = false;
    let mut cur = start;
    loop {
        if cur & LEAF == 0 {
            let node = &bvh.nodes[cur as usize];
            let (mask, enter) = if FMA {
                ray.test_fma_known::<AVX>(node, t_min, t_max)
            } else {
                ray.test::<AVX>(node, t_min, t_max)
            };
            if mask != 0 {
                let first = mask.trailing_zeros() as usize;
                let rest = mask & (mask - 1);
                if rest == 0 {
                    cur = node.child[first & (WIDTH - 1)];
                    continue;
                }
                let second = rest.trailing_zeros() as usize;
                if rest & (rest - 1) == 0 {
                    // Two children: the farther one waits.
                    let (a, b) = (
                        (enter[first & (WIDTH - 1)], node.child[first & (WIDTH - 1)]),
                        (
                            enter[second & (WIDTH - 1)],
                            node.child[second & (WIDTH - 1)],
                        ),
                    );
                    let (near, far) = if b.0 < a.0 { (b, a) } else { (a, b) };
                    if PREFETCH {
                        prefetch(far.1);
                        prefetch(near.1);
                    }
                    stack.push(entry(far.0, far.1));
                    cur = near.1;
                    continue;
                }
                // Three or more: sorted far to near by an insertion sort
                // of at most eight integer keys (the entry distance as an
                // integer of the same order, then the slot, so that equal
                // distances keep the slots' order), all but the nearest
                // stacked.
                let bits: [u32; WIDTH] = enter.map(f32::to_bits);
                let mut keys = [0u64; WIDTH];
                let mut n = 0;
                let mut m = mask;
                while m != 0 {
                    let c = m.trailing_zeros() as usize & (WIDTH - 1);
                    m &= m - 1;
                    if PREFETCH {
                        prefetch(node.child[c]);
                    }
                    let key = (sortable(bits[c]) as u64) << 32 | (WIDTH - 1 - c) as u64;
                    let mut j = n;
                    while j > 0 && keys[j - 1] < key {
                        keys[j] = keys[j - 1];
                        j -= 1;
                    }
                    keys[j] = key;
                    n += 1;
                }
                let slot = |k: u64| (WIDTH - 1) - (k as usize & (WIDTH - 1));
                for &k in &keys[..n - 1] {
                    let c = slot(k);
                    stack.push((bits[c] as u64) << 32 | node.child[c] as u64);
                }
                cur = node.child[slot(keys[(n - 1) & (WIDTH - 1)])];
                continue;
            }
        } else if let Some(t) = visit(leaf_index(cur), leaf_count(cur), t_max) {
            any = true;
            if any_hit {
                return true;
            }
            t_max = t_max.min(t);
        }
        // Next pending subtree that a hit has not made stale.
        loop {
            let Some(e) = stack.pop() else {
                return any;
            };
            let (t, c) = unpack(e);
            if t <= t_max {
                cur = c;
                break;
            }
        }
    }
}

/// Writes into `order` the indices of `rays` grouped by direction octant
/// (the signs of the direction's components, `-0.0` counted negative),
/// keeping their order inside each octant: a counting sort in two passes.
///
/// Tracing incoherent rays one at a time in this order instead of as
/// given keeps the traversal's branches (which child is nearer, which
/// slab plane is entered first) the same from one ray to the next while
/// neighbouring rays still start close together; hits do not change, only
/// the order in which rays are traced. Measured in `prism bench rays`
/// (mode `binned`, see the README).
pub fn octant_order(rays: &[Ray], order: &mut Vec<u32>) {
    let octant = |r: &Ray| {
        let d = r.direction;
        (d.x.is_sign_negative() as usize)
            | ((d.y.is_sign_negative() as usize) << 1)
            | ((d.z.is_sign_negative() as usize) << 2)
    };
    let mut start = [0u32; 9];
    for r in rays {
        start[octant(r) + 1] += 1;
    }
    for o in 1..9 {
        start[o] += start[o - 1];
    }
    order.clear();
    order.resize(rays.len(), 0);
    for (i, r) in rays.iter().enumerate() {
        let o = octant(r);
        order[start[o] as usize] = i as u32;
        start[o] += 1;
    }
}

/// Whether traversal prefetches the children it enters beside a sibling
/// (the farther ones wait on the stack, so their loads overlap the work on
/// the nearer ones). Measured on the anchors' 100k mesh, one thread, rays
/// per CPU second: bounce rays +15% (single) and +11% (packets of 8),
/// camera rays unchanged.
const PREFETCH: bool = true;

/// Starts loading the `bytes` bytes at `p` into the cache (nothing on
/// targets without a prefetch instruction).
#[inline(always)]
pub fn prefetch_bytes<T>(p: &T, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = (p as *const T).cast::<i8>();
        let mut off = 0;
        while off < bytes {
            // SAFETY: a prefetch never faults nor changes memory; SSE is
            // part of the x86-64 baseline.
            #[allow(unsafe_code)]
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(off));
            }
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, bytes);
}

/// [`traverse_from`] from the root, preparing `ray` for `bvh`.
#[inline(always)]
pub fn traverse<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, f32) -> Option<f32>,
) -> bool {
    let node_ray = NodeRay::new(ray, bvh);
    traverse_from::<AVX>(bvh, 0, &node_ray, t_min, t_max, any_hit, visit)
}

/// [`traverse`] with [`traverse_from_with`]'s leaf count and prefetch, and nodes
/// tested with [`NodeRay::test_fused`]: for mesh BVHs, whose closest hit
/// does not depend on the order of the leaves (equal `t` goes to the
/// lowest triangle index) and whose any-hit answer does not either.
#[inline(always)]
pub fn traverse_with<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    let node_ray = NodeRay::new(ray, bvh);
    traverse_from_with::<AVX, true>(
        bvh,
        0,
        &node_ray,
        t_min,
        t_max,
        any_hit,
        visit,
        prefetch_leaf,
    )
}

/// [`traverse`] with a visitor per primitive: `visit(slot, t_max)` tests
/// the primitive at `bvh.prims[slot]` (leaves' primitives in order).
#[inline(always)]
pub fn traverse_bvh<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    mut visit: impl FnMut(usize, f32) -> Option<f32>,
) -> bool {
    traverse::<AVX>(
        bvh,
        ray,
        t_min,
        t_max,
        any_hit,
        #[inline(always)]
        |leaf, mut t_max| {
            let l = bvh.leaves[leaf as usize];
            let mut best = None;
            for slot in l.first..l.first + l.count {
                if let Some(t) = visit(slot as usize, t_max) {
                    if any_hit {
                        return Some(t);
                    }
                    t_max = t_max.min(t);
                    best = Some(t_max);
                }
            }
            best
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// The octant order is a stable sort of the rays by the signs of
    /// their direction components (checked against the standard library's
    /// stable sort), `-0.0` counted as negative.
    #[test]
    fn octant_order_is_a_stable_sort_by_direction_signs() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let comp = |v: u64| match v % 5 {
            0 => 0.0,
            1 => -0.0,
            2 => 1.5,
            3 => -2.0,
            _ => f32::MIN_POSITIVE,
        };
        let rays: Vec<Ray> = (0..1000)
            .map(|_| {
                let d = Vec3A::new(comp(next()), comp(next()), comp(next()));
                Ray::new(Vec3A::ZERO, d)
            })
            .collect();
        let key = |r: &Ray| {
            let d = r.direction;
            (d.x.to_bits() >> 31) | ((d.y.to_bits() >> 31) << 1) | ((d.z.to_bits() >> 31) << 2)
        };
        let mut expect: Vec<u32> = (0..rays.len() as u32).collect();
        expect.sort_by_key(|&i| key(&rays[i as usize]));
        let mut order = vec![7; 3];
        octant_order(&rays, &mut order);
        assert_eq!(order, expect);
        octant_order(&[], &mut order);
        assert!(order.is_empty());
    }

    /// The stack gives back every entry, last in first out, up to its
    /// capacity; past it, it wraps around (keeping the latest entries)
    /// instead of reading or writing outside its buffer.
    #[test]
    fn stack_keeps_every_entry_up_to_its_capacity() {
        let mut buf = [MaybeUninit::uninit(); 256];
        let mut s = Stack::new(&mut buf);
        for i in 0..256u32 {
            s.push(entry(i as f32, i));
        }
        for i in (0..256u32).rev() {
            assert_eq!(unpack(s.pop().unwrap()), (i as f32, i));
        }
        assert!(s.pop().is_none());
        // Interleaved pushes and pops.
        for i in 0..70u32 {
            s.push(entry(0.0, i));
        }
        assert_eq!(unpack(s.pop().unwrap()).1, 69);
        s.push(entry(0.0, 1000));
        assert_eq!(unpack(s.pop().unwrap()).1, 1000);
        for i in (0..69u32).rev() {
            assert_eq!(unpack(s.pop().unwrap()).1, i);
        }
        assert!(s.pop().is_none());
        // Past the capacity: the last eight of twelve come back, then the
        // wrapped slots again, never anything unwritten.
        let mut buf = [MaybeUninit::uninit(); 8];
        let mut s = Stack::new(&mut buf);
        for i in 0..12u32 {
            s.push(entry(0.0, i));
        }
        let got: Vec<u32> = std::iter::from_fn(|| s.pop())
            .map(|e| unpack(e).1)
            .collect();
        assert_eq!(got, [11, 10, 9, 8, 7, 6, 5, 4, 11, 10, 9, 8]);
    }

    /// A stack is as large as the tree needs: seven entries per level.
    #[test]
    fn stack_buffer_covers_the_depth() {
        for depth in [0, 1, 36, 37, 100] {
            let bvh = Bvh8 {
                depth,
                ..Bvh8::default()
            };
            let need = stack_need(&bvh);
            let cap = if need <= FIXED {
                FIXED
            } else {
                heap_buffer(need).len()
            };
            assert!(cap > 7 * depth && cap.is_power_of_two(), "{depth}: {cap}");
        }
    }

    /// The integer keys of the three-or-more sort order as the floats do.
    #[test]
    fn sortable_keys_order_as_floats() {
        let v = [
            f32::NEG_INFINITY,
            -3.5,
            -1.0e-30,
            -0.0,
            0.0,
            1.0e-40,
            0.25,
            7.0,
            f32::MAX,
            f32::INFINITY,
        ];
        for w in v.windows(2) {
            assert!(
                sortable(w[0].to_bits()) < sortable(w[1].to_bits()),
                "{} {}",
                w[0],
                w[1]
            );
        }
    }
}
