//! A kd-tree over triangles: the axis-aligned binary space partition,
//! built with the surface area heuristic over "perfect" split candidates
//! (Wald and Havran 2006) and traversed front to back with a stack.
//!
//! **Split candidates** are the faces of each triangle's bound *clipped
//! to the node*: the triangle is clipped to the node's box
//! (Sutherland-Hodgman, [`crate::core::clip::clip_polygon_box`]) and the
//! bound of what remains, kept inside both the node's box and the
//! triangle's own box, gives its candidate planes and decides its side.
//!
//! **Cost** of splitting a node of area `A` at a plane with `N_L`
//! triangles on the left (area `A_L`) and `N_R` on the right:
//! `lambda (K_T + K_I (A_L/A N_L + A_R/A N_R))`, with `K_T` =
//! [`TRAVERSAL_COST`], `K_I` = [`INTERSECTION_COST`] and `lambda` =
//! [`EMPTY_FACTOR`] when one side is empty (the empty-space bonus), else 1.
//! A node becomes a leaf when no plane costs less than `K_I N` or at
//! depth [`max_depth`] (`8 + 1.3 log2 N`). A triangle goes left if its
//! clipped bound starts below the plane, right if it ends above it, both
//! if it lies in the plane; straddlers are clipped again for each child.
//! Ties between planes of equal cost go to the lowest axis, then the
//! lowest position.
//!
//! **Build in O(N log N).** Each axis keeps its events (bound starts,
//! ends and planar triangles) sorted; one sweep per axis finds the best
//! plane, the events of triangles that stay on one side are split into
//! the children in order, and only the straddlers' new events are sorted
//! and merged in. [`KdTree::build_naive`] finds the same planes by
//! counting triangles at every candidate (O(N^2) per node): the tests
//! compare the two trees.
//!
//! **Traversal** is in double precision from the f32 ray. Each child is
//! entered over the parameter interval where the ray is within the node
//! test's margin ([`crate::accel::node::margin`]) of its half-space, so a
//! hit the watertight test accepts just outside a triangle, or on a
//! splitting plane, is never lost; the near child is visited first and
//! the far one waits on the stack with its entry distance, dropped once a
//! closer hit is known. Triangles in several leaves are tested once per
//! ray ([`crate::accel::mailbox`]).

use glam::{DVec3, Vec3A};

use crate::accel::mailbox::with_mailbox;
use crate::accel::node::margin;
use crate::core::clip::clip_polygon_box;
use crate::core::math::Ray;

/// `K_T`: cost of one traversal step (Wald and Havran's 15).
pub const TRAVERSAL_COST: f64 = 15.0;
/// `K_I`: cost of one triangle test (Wald and Havran's 20).
pub const INTERSECTION_COST: f64 = 20.0;
/// `lambda` for a split with an empty side: cutting off empty space is
/// favoured by 20%.
pub const EMPTY_FACTOR: f64 = 0.8;

/// Deepest level of a tree over `n` triangles: `8 + 1.3 log2 n`, rounded
/// (pbrt's rule).
pub fn max_depth(n: usize) -> u32 {
    (8.0 + 1.3 * (n.max(1) as f64).log2()).round() as u32
}

const LEAF: u8 = 3;

/// A node: an interior node splits on `axis` at `split`, its left child
/// is the next node and its right child node `index`; a leaf (`axis` 3)
/// holds `count` triangles from `index` in [`KdTree::prims`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KdNode {
    /// Splitting plane's coordinate (interior nodes).
    pub split: f64,
    /// 0, 1, 2 for x, y, z; 3 for a leaf.
    pub axis: u8,
    /// Right child (interior) or first slot in `prims` (leaf).
    pub index: u32,
    /// Triangles in a leaf.
    pub count: u32,
}

impl KdNode {
    /// True for a leaf.
    pub fn is_leaf(&self) -> bool {
        self.axis == LEAF
    }
}

/// A kd-tree; see the module documentation.
#[derive(Clone, Debug, Default)]
pub struct KdTree {
    /// Nodes in depth-first order; the root is node 0.
    pub nodes: Vec<KdNode>,
    /// Triangle indices of the leaves, each leaf's in increasing order.
    pub prims: Vec<u32>,
    /// Bounds of the root.
    pub lo: DVec3,
    /// Bounds of the root.
    pub hi: DVec3,
    /// Deepest leaf.
    pub depth: u32,
    count: usize,
    magnitude: f32,
}

/// A triangle's bound at a node.
#[derive(Clone, Copy, Debug)]
struct Item {
    tri: u32,
    lo: DVec3,
    hi: DVec3,
}

/// Kinds of events, in sweep order at one position.
const END: u8 = 0;
const PLANAR: u8 = 1;
const START: u8 = 2;

#[derive(Clone, Copy, Debug)]
struct Event {
    pos: f64,
    kind: u8,
    tri: u32,
}

fn event_order(a: &Event, b: &Event) -> std::cmp::Ordering {
    a.pos
        .total_cmp(&b.pos)
        .then(a.kind.cmp(&b.kind))
        .then(a.tri.cmp(&b.tri))
}

fn area(lo: DVec3, hi: DVec3) -> f64 {
    let e = (hi - lo).max(DVec3::ZERO);
    2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
}

/// The SAH cost of splitting `(lo, hi)` on `axis` at `p`.
fn split_cost(lo: DVec3, hi: DVec3, axis: usize, p: f64, nl: usize, nr: usize) -> f64 {
    let total = area(lo, hi);
    let mut lhi = hi;
    lhi[axis] = p;
    let mut rlo = lo;
    rlo[axis] = p;
    let (pl, pr) = (area(lo, lhi) / total, area(rlo, hi) / total);
    let lambda = if nl == 0 || nr == 0 {
        EMPTY_FACTOR
    } else {
        1.0
    };
    lambda * (TRAVERSAL_COST + INTERSECTION_COST * (pl * nl as f64 + pr * nr as f64))
}

/// The bound of triangle `tri` clipped to the box `(lo, hi)`, inside both
/// that box and the triangle's own bound; `None` if nothing is left.
pub fn clipped_bound(tri: &[DVec3; 3], lo: DVec3, hi: DVec3) -> Option<(DVec3, DVec3)> {
    let poly = clip_polygon_box(tri, lo, hi);
    if poly.is_empty() {
        return None;
    }
    let (mut a, mut b) = (poly[0], poly[0]);
    for p in &poly[1..] {
        a = a.min(*p);
        b = b.max(*p);
    }
    let tlo = tri[0].min(tri[1]).min(tri[2]);
    let thi = tri[0].max(tri[1]).max(tri[2]);
    let a = a.max(lo).max(tlo);
    let b = b.min(hi).min(thi);
    a.cmple(b).all().then_some((a, b))
}

/// A split: `(cost, axis, position)`.
type Split = (f64, usize, f64);

fn better(a: Split, b: Option<Split>) -> bool {
    match b {
        None => true,
        Some(b) => a.0 < b.0 || (a.0 == b.0 && (a.1 < b.1 || (a.1 == b.1 && a.2 < b.2))),
    }
}

/// Nodes of at least this many triangles, at depth below
/// [`PARALLEL_DEPTH`], build their two subtrees in parallel.
pub const PARALLEL_MIN: usize = 4096;

/// Depth down to which subtrees are built in parallel: up to 2^6 = 64
/// tasks, each with its own per-triangle scratch.
pub const PARALLEL_DEPTH: u32 = 6;

struct Builder<'a> {
    tris: &'a [[DVec3; 3]],
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
    max_depth: u32,
    depth: u32,
    /// Per triangle: 1 left, 2 right, 3 both (scratch of the partition).
    side: Vec<u8>,
    /// Smallest node whose subtrees are built in parallel.
    parallel_min: usize,
}

impl Builder<'_> {
    fn leaf(&mut self, items: &[Item], depth: u32) {
        let first = self.prims.len() as u32;
        let mut ids: Vec<u32> = items.iter().map(|i| i.tri).collect();
        ids.sort_unstable();
        self.prims.extend_from_slice(&ids);
        self.nodes.push(KdNode {
            split: 0.0,
            axis: LEAF,
            index: first,
            count: ids.len() as u32,
        });
        self.depth = self.depth.max(depth);
    }

    /// Whether a node of `n` triangles should split at `best`.
    fn worth(
        &self,
        lo: DVec3,
        hi: DVec3,
        n: usize,
        depth: u32,
        best: Option<Split>,
    ) -> Option<Split> {
        if n == 0 || depth >= self.max_depth || area(lo, hi) <= 0.0 {
            return None;
        }
        best.filter(|b| b.0 < INTERSECTION_COST * n as f64)
    }

    /// Sides of the items for a split at `p` on `axis`, and the children's
    /// items: one-sided triangles keep their bounds, the others are
    /// clipped again to each child (and dropped where nothing is left).
    fn partition(
        &mut self,
        items: &[Item],
        lo: DVec3,
        hi: DVec3,
        axis: usize,
        p: f64,
    ) -> (Vec<Item>, Vec<Item>, Vec<Item>, Vec<Item>) {
        let mut lhi = hi;
        lhi[axis] = p;
        let mut rlo = lo;
        rlo[axis] = p;
        let (mut left, mut right, mut new_left, mut new_right) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for it in items {
            let planar = it.lo[axis] == p && it.hi[axis] == p;
            let l = it.lo[axis] < p || planar;
            let r = it.hi[axis] > p || planar;
            let s = l as u8 | (r as u8) << 1;
            self.side[it.tri as usize] = s;
            match s {
                1 => left.push(*it),
                2 => right.push(*it),
                _ => {
                    let t = &self.tris[it.tri as usize];
                    if let Some((a, b)) = clipped_bound(t, lo, lhi) {
                        new_left.push(Item {
                            tri: it.tri,
                            lo: a,
                            hi: b,
                        });
                    }
                    if let Some((a, b)) = clipped_bound(t, rlo, hi) {
                        new_right.push(Item {
                            tri: it.tri,
                            lo: a,
                            hi: b,
                        });
                    }
                }
            }
        }
        (left, right, new_left, new_right)
    }

    /// The O(N log N) build of a node with `items` and their sorted
    /// `events` per axis.
    fn build(
        &mut self,
        items: Vec<Item>,
        events: [Vec<Event>; 3],
        lo: DVec3,
        hi: DVec3,
        depth: u32,
    ) {
        let n = items.len();
        let mut best: Option<Split> = None;
        for (axis, ev) in events.iter().enumerate() {
            let (mut below, mut ended) = (0usize, 0usize);
            let mut i = 0;
            while i < ev.len() {
                let p = ev[i].pos;
                let (mut starts, mut ends, mut planar) = (0, 0, 0);
                while i < ev.len() && ev[i].pos == p {
                    match ev[i].kind {
                        END => ends += 1,
                        PLANAR => planar += 1,
                        _ => starts += 1,
                    }
                    i += 1;
                }
                if lo[axis] < p && p < hi[axis] {
                    let (nl, nr) = (below + planar, n - ended - ends);
                    let c = (split_cost(lo, hi, axis, p, nl, nr), axis, p);
                    if better(c, best) {
                        best = Some(c);
                    }
                }
                below += starts + planar;
                ended += ends + planar;
            }
        }
        let Some((_, axis, p)) = self.worth(lo, hi, n, depth, best) else {
            self.leaf(&items, depth);
            return;
        };
        let (left, right, new_left, new_right) = self.partition(&items, lo, hi, axis, p);
        drop(items);
        let mut lev: [Vec<Event>; 3] = Default::default();
        let mut rev: [Vec<Event>; 3] = Default::default();
        for (a, ev) in events.into_iter().enumerate() {
            let (mut l, mut r): (Vec<Event>, Vec<Event>) = (Vec::new(), Vec::new());
            for e in ev {
                match self.side[e.tri as usize] {
                    1 => l.push(e),
                    2 => r.push(e),
                    _ => {}
                }
            }
            lev[a] = merge(l, events_of(&new_left, a));
            rev[a] = merge(r, events_of(&new_right, a));
        }
        let (mut litems, mut ritems) = (left, right);
        litems.extend(new_left);
        ritems.extend(new_right);
        let (me, lhi, rlo) = self.push_split(lo, hi, axis, p);
        if n >= self.parallel_min && depth < PARALLEL_DEPTH {
            // The right subtree in a builder of its own, spliced in after
            // the left one: the same nodes, in the same order, as the
            // sequential build.
            let mut right = Builder {
                tris: self.tris,
                nodes: Vec::new(),
                prims: Vec::new(),
                max_depth: self.max_depth,
                depth: 0,
                side: vec![0; self.tris.len()],
                parallel_min: self.parallel_min,
            };
            rayon::join(
                || self.build(litems, lev, lo, lhi, depth + 1),
                || right.build(ritems, rev, rlo, hi, depth + 1),
            );
            self.splice(me, right);
        } else {
            self.build(litems, lev, lo, lhi, depth + 1);
            self.nodes[me].index = self.nodes.len() as u32;
            self.build(ritems, rev, rlo, hi, depth + 1);
        }
    }

    /// Appends the subtree `right` built on its own as the right child of
    /// node `me`, renumbering its node and triangle references.
    fn splice(&mut self, me: usize, right: Builder) {
        let (base, first) = (self.nodes.len() as u32, self.prims.len() as u32);
        self.nodes[me].index = base;
        self.nodes.extend(right.nodes.into_iter().map(|mut n| {
            n.index += if n.is_leaf() { first } else { base };
            n
        }));
        self.prims.extend(right.prims);
        self.depth = self.depth.max(right.depth);
    }

    /// Pushes an inner node splitting `lo..hi` at `p` on `axis` (its right
    /// child's index is filled in once the left subtree is built); returns
    /// the node's index and the upper corner of the left child's box and
    /// the lower corner of the right child's.
    fn push_split(&mut self, lo: DVec3, hi: DVec3, axis: usize, p: f64) -> (usize, DVec3, DVec3) {
        let mut lhi = hi;
        lhi[axis] = p;
        let mut rlo = lo;
        rlo[axis] = p;
        let me = self.nodes.len();
        self.nodes.push(KdNode {
            split: p,
            axis: axis as u8,
            index: 0,
            count: 0,
        });
        (me, lhi, rlo)
    }

    /// The naive build: every candidate plane evaluated by counting.
    fn build_naive(&mut self, items: Vec<Item>, lo: DVec3, hi: DVec3, depth: u32) {
        let n = items.len();
        let mut best: Option<Split> = None;
        for axis in 0..3 {
            let mut cands: Vec<f64> = items
                .iter()
                .flat_map(|i| [i.lo[axis], i.hi[axis]])
                .collect();
            cands.sort_by(f64::total_cmp);
            cands.dedup();
            for &p in &cands {
                if !(lo[axis] < p && p < hi[axis]) {
                    continue;
                }
                let planar = items
                    .iter()
                    .filter(|i| i.lo[axis] == p && i.hi[axis] == p)
                    .count();
                let nl = items.iter().filter(|i| i.lo[axis] < p).count() + planar;
                let nr = items.iter().filter(|i| i.hi[axis] > p).count() + planar;
                let c = (split_cost(lo, hi, axis, p, nl, nr), axis, p);
                if better(c, best) {
                    best = Some(c);
                }
            }
        }
        let Some((_, axis, p)) = self.worth(lo, hi, n, depth, best) else {
            self.leaf(&items, depth);
            return;
        };
        let (mut left, mut right, new_left, new_right) = self.partition(&items, lo, hi, axis, p);
        left.extend(new_left);
        right.extend(new_right);
        let (me, lhi, rlo) = self.push_split(lo, hi, axis, p);
        self.build_naive(left, lo, lhi, depth + 1);
        self.nodes[me].index = self.nodes.len() as u32;
        self.build_naive(right, rlo, hi, depth + 1);
    }
}

/// Sorted events of `items` on `axis`.
fn events_of(items: &[Item], axis: usize) -> Vec<Event> {
    let mut ev = Vec::with_capacity(items.len() * 2);
    for it in items {
        if it.lo[axis] == it.hi[axis] {
            ev.push(Event {
                pos: it.lo[axis],
                kind: PLANAR,
                tri: it.tri,
            });
        } else {
            ev.push(Event {
                pos: it.lo[axis],
                kind: START,
                tri: it.tri,
            });
            ev.push(Event {
                pos: it.hi[axis],
                kind: END,
                tri: it.tri,
            });
        }
    }
    ev.sort_unstable_by(event_order);
    ev
}

/// Merges two sorted event lists.
fn merge(a: Vec<Event>, b: Vec<Event>) -> Vec<Event> {
    if b.is_empty() {
        return a;
    }
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if event_order(&a[i], &b[j]).is_le() {
            out.push(a[i]);
            i += 1;
        } else {
            out.push(b[j]);
            j += 1;
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

impl KdTree {
    fn start(triangles: &[[Vec3A; 3]]) -> (Vec<[DVec3; 3]>, Vec<Item>, DVec3, DVec3, f32) {
        let tris: Vec<[DVec3; 3]> = triangles.iter().map(|t| t.map(|p| p.as_dvec3())).collect();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut magnitude = 0.0f32;
        let items: Vec<Item> = tris
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let a = t[0].min(t[1]).min(t[2]);
                let b = t[0].max(t[1]).max(t[2]);
                lo = lo.min(a);
                hi = hi.max(b);
                Item {
                    tri: i as u32,
                    lo: a,
                    hi: b,
                }
            })
            .collect();
        for t in triangles {
            for p in t {
                magnitude = magnitude.max(p.abs().max_element());
            }
        }
        (tris, items, lo, hi, magnitude)
    }

    fn finish(b: Builder, lo: DVec3, hi: DVec3, magnitude: f32) -> Self {
        Self {
            count: b.tris.len(),
            nodes: b.nodes,
            prims: b.prims,
            lo,
            hi,
            depth: b.depth,
            magnitude,
        }
    }

    /// Builds over `triangles` (index = triangle number) in O(N log N).
    /// The two subtrees of large nodes near the root ([`PARALLEL_MIN`]
    /// triangles, depth below [`PARALLEL_DEPTH`]) are built in parallel on
    /// rayon's threads; the tree is the same whatever the thread count.
    pub fn build(triangles: &[[Vec3A; 3]]) -> Self {
        Self::build_with_max_depth(triangles, max_depth(triangles.len()))
    }

    /// [`Self::build`] with another depth limit than [`max_depth`].
    pub fn build_with_max_depth(triangles: &[[Vec3A; 3]], limit: u32) -> Self {
        Self::build_with(triangles, limit, PARALLEL_MIN)
    }

    /// The build with subtrees of nodes of `parallel_min` triangles or more
    /// built in parallel (`usize::MAX`: none).
    fn build_with(triangles: &[[Vec3A; 3]], limit: u32, parallel_min: usize) -> Self {
        if triangles.is_empty() {
            return Self::default();
        }
        let (tris, items, lo, hi, magnitude) = Self::start(triangles);
        let events = std::array::from_fn(|a| events_of(&items, a));
        let mut b = Builder {
            tris: &tris,
            nodes: Vec::new(),
            prims: Vec::new(),
            max_depth: limit,
            depth: 0,
            side: vec![0; tris.len()],
            parallel_min,
        };
        b.build(items, events, lo, hi, 0);
        Self::finish(b, lo, hi, magnitude)
    }

    /// The same tree as [`Self::build`], found by counting the triangles
    /// on each side of every candidate (O(N^2) per node): the reference
    /// the tests compare the fast build with.
    pub fn build_naive(triangles: &[[Vec3A; 3]]) -> Self {
        if triangles.is_empty() {
            return Self::default();
        }
        let (tris, items, lo, hi, magnitude) = Self::start(triangles);
        let mut b = Builder {
            tris: &tris,
            nodes: Vec::new(),
            prims: Vec::new(),
            max_depth: max_depth(tris.len()),
            depth: 0,
            side: vec![0; tris.len()],
            parallel_min: usize::MAX,
        };
        b.build_naive(items, lo, hi, 0);
        Self::finish(b, lo, hi, magnitude)
    }

    /// Bytes of the node and triangle arrays.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<KdNode>()
            + self.prims.len() * 4
            + std::mem::size_of::<Self>()
    }

    /// Calls `f(node, lo, hi, depth)` for every node with its box, parents
    /// first.
    pub fn for_each_node(&self, mut f: impl FnMut(&KdNode, DVec3, DVec3, u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = vec![(0usize, self.lo, self.hi, 0u32)];
        while let Some((i, lo, hi, depth)) = stack.pop() {
            let n = &self.nodes[i];
            f(n, lo, hi, depth);
            if !n.is_leaf() {
                let a = n.axis as usize;
                let mut lhi = hi;
                lhi[a] = n.split;
                let mut rlo = lo;
                rlo[a] = n.split;
                stack.push((n.index as usize, rlo, hi, depth + 1));
                stack.push((i + 1, lo, lhi, depth + 1));
            }
        }
    }

    /// Visits the leaves `ray` may reach within `[t_min, t_max]`, near to
    /// far. `visit(prim, t_max)` tests triangle `prim` (each at most once
    /// per ray) and returns the `t` of a hit it accepts, which becomes the
    /// new `t_max`; subtrees entered beyond it are dropped. With `any_hit`
    /// the traversal ends at the first hit. Returns whether any triangle
    /// was hit.
    pub fn traverse(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        any_hit: bool,
        mut visit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let o = ray.origin.as_dvec3();
        let d = ray.direction.as_dvec3();
        let pad = margin(ray.origin.abs().max_element(), self.magnitude) as f64;
        let slack = |t: f64| t + 8.0 * f32::EPSILON as f64 * t.abs();
        let (mut t0, mut t1) = (-slack(-(t_min as f64)), slack(t_max as f64));
        for a in 0..3 {
            let (lo, hi) = (self.lo[a] - pad, self.hi[a] + pad);
            if d[a] == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return false;
                }
            } else {
                let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if !(t0 <= t1) {
            return false;
        }
        let mut best = t_max;
        let mut any = false;
        with_mailbox(self.count, |mb| {
            let mut stack: Vec<(u32, f64, f64)> = Vec::with_capacity(64);
            let mut cur = Some((0u32, t0, t1));
            loop {
                let (mut n, mut ta, mut tb) = match cur.take().or_else(|| stack.pop()) {
                    Some(e) => e,
                    None => return,
                };
                if any && ta > slack(best as f64) {
                    continue;
                }
                loop {
                    let node = &self.nodes[n as usize];
                    if node.is_leaf() {
                        let first = node.index as usize;
                        for &p in &self.prims[first..first + node.count as usize] {
                            if !mb.first_visit(p) {
                                continue;
                            }
                            if let Some(t) = visit(p, best) {
                                best = t;
                                any = true;
                                if any_hit {
                                    return;
                                }
                            }
                        }
                        break;
                    }
                    let a = node.axis as usize;
                    let (p, left, right) = (node.split, n + 1, node.index);
                    if d[a] == 0.0 {
                        let l = o[a] <= p + pad;
                        let r = o[a] >= p - pad;
                        n = match (l, r) {
                            (true, true) => {
                                let (near, far) = if o[a] < p {
                                    (left, right)
                                } else {
                                    (right, left)
                                };
                                stack.push((far, ta, tb));
                                near
                            }
                            (true, false) => left,
                            _ => right,
                        };
                        continue;
                    }
                    let below = (p - pad - o[a]) / d[a];
                    let above = (p + pad - o[a]) / d[a];
                    // Near child first: left when moving up the axis.
                    let (near, near_end, far, far_start) = if d[a] > 0.0 {
                        (left, above, right, below)
                    } else {
                        (right, below, left, above)
                    };
                    let near_tb = tb.min(near_end);
                    let far_ta = ta.max(far_start);
                    match (ta <= near_tb, far_ta <= tb) {
                        (true, true) => {
                            stack.push((far, far_ta, tb));
                            n = near;
                            tb = near_tb;
                        }
                        (true, false) => {
                            n = near;
                            tb = near_tb;
                        }
                        (false, true) => {
                            n = far;
                            ta = far_ta;
                        }
                        (false, false) => break,
                    }
                }
            }
        });
        any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn soup(n: usize, seed: u64, spread: f32, size: f32) -> Vec<[Vec3A; 3]> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|i| {
                let c = Vec3A::new(next(), next(), next()) * spread;
                let mut t = [0; 3].map(|_| c + (Vec3A::new(next(), next(), next()) - 0.5) * size);
                if i % 7 == 0 {
                    // Axis-aligned (planar) triangles.
                    for p in &mut t {
                        p.y = c.y;
                    }
                }
                if i % 11 == 0 {
                    // Repeated coordinates: equal events.
                    t[0].x = 0.5 * spread;
                    t[1].x = 0.5 * spread;
                }
                t
            })
            .collect()
    }

    /// Every clipped bound lies inside the node box and the triangle's
    /// own box, and contains every point of the triangle inside the node.
    #[test]
    fn clipped_bounds_lie_inside_node_and_triangle() {
        let tris = soup(400, 3, 1.0, 0.8);
        let mut s = 5u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut clipped = 0;
        for t in &tris {
            let t = t.map(|p| p.as_dvec3());
            for _ in 0..20 {
                let a = DVec3::new(next(), next(), next()) * 1.2 - 0.1;
                let b = a + DVec3::new(next(), next(), next()) * 0.5;
                let tlo = t[0].min(t[1]).min(t[2]);
                let thi = t[0].max(t[1]).max(t[2]);
                let got = clipped_bound(&t, a, b);
                // Points of the triangle inside the box must be in the bound.
                let mut inside_pts = 0;
                for i in 0..=20 {
                    for j in 0..=(20 - i) {
                        let (u, v) = (i as f64 / 20.0, j as f64 / 20.0);
                        let q = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                        if q.cmpge(a).all() && q.cmple(b).all() {
                            inside_pts += 1;
                            let (lo, hi) = got.expect("a point inside but no bound");
                            let tol = 1e-12;
                            assert!(q.cmpge(lo - tol).all() && q.cmple(hi + tol).all());
                        }
                    }
                }
                if let Some((lo, hi)) = got {
                    clipped += (inside_pts > 0) as u32;
                    assert!(
                        lo.cmpge(a).all() && hi.cmple(b).all(),
                        "outside the node box"
                    );
                    assert!(
                        lo.cmpge(tlo).all() && hi.cmple(thi).all(),
                        "outside the triangle's box"
                    );
                    assert!(lo.cmple(hi).all());
                }
            }
        }
        assert!(clipped > 200, "only {clipped} clips kept anything");
    }

    /// Subtrees built in parallel and spliced give the sequential tree:
    /// the same nodes (child and leaf references renumbered), leaves and
    /// depth, on one thread or two, forking at every node of 16 or more
    /// triangles down to PARALLEL_DEPTH.
    #[test]
    fn parallel_build_equals_sequential_build() {
        for (seed, n) in [(6, 300), (7, 3000)] {
            let tris = soup(n, seed, 1.0, 0.1);
            let limit = max_depth(n);
            let sequential = KdTree::build_with(&tris, limit, usize::MAX);
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let parallel = pool.install(|| KdTree::build_with(&tris, limit, 16));
                assert_eq!(
                    parallel.nodes, sequential.nodes,
                    "seed {seed}, {threads} threads"
                );
                assert_eq!(parallel.prims, sequential.prims);
                assert_eq!(parallel.depth, sequential.depth);
            }
            assert!(sequential.depth > PARALLEL_DEPTH, "{}", sequential.depth);
        }
        // The default threshold on a small input is the sequential build.
        let tris = soup(300, 6, 1.0, 0.1);
        assert_eq!(KdTree::build(&tris).nodes, KdTree::build_naive(&tris).nodes);
    }

    /// The sweep build gives the tree of the counting build: same nodes,
    /// planes and leaves.
    #[test]
    fn fast_build_equals_naive_build() {
        for (seed, n) in [(1, 1), (2, 7), (3, 60), (4, 200), (5, 300)] {
            let tris = soup(n, seed, 1.0, 0.3);
            let fast = KdTree::build(&tris);
            let naive = KdTree::build_naive(&tris);
            assert_eq!(fast.nodes, naive.nodes, "seed {seed}, {n} triangles");
            assert_eq!(fast.prims, naive.prims);
            if n >= 60 {
                assert!(
                    fast.nodes.len() > 10,
                    "{n} triangles gave {} nodes",
                    fast.nodes.len()
                );
            }
        }
    }

    /// No leaf is deeper than the limit: 8 + 1.3 log2 N by default, and a
    /// smaller limit that binds (the unlimited tree is deeper) is met
    /// exactly.
    #[test]
    fn depth_limit_holds() {
        let tris = soup(600, 9, 1.0, 0.05);
        let deepest = |t: &KdTree| {
            let mut d = 0;
            t.for_each_node(|_, _, _, k| d = d.max(k));
            assert_eq!(d, t.depth);
            d
        };
        let tree = KdTree::build(&tris);
        let limit = max_depth(tris.len());
        assert_eq!(limit, 20);
        let full = deepest(&tree);
        assert!(full <= limit, "depth {full} over the limit {limit}");
        assert!(full > 6, "the tree should be deeper than 6, got {full}");
        let short = KdTree::build_with_max_depth(&tris, 6);
        assert_eq!(deepest(&short), 6);
    }
}
