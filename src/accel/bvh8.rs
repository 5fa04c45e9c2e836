//! Prism's own 8-wide BVH: the tree obvhs builds (a [`Bvh2`]), collapsed
//! into nodes of eight float child boxes stored as structure of arrays,
//! with leaves of a few primitives.
//!
//! obvhs stays the builder (PLOC, reinsertion, SAH leaf collapse); the
//! layout is Prism's so that one node test reads six rows of eight floats
//! (no dequantisation, no per-node margin) and leaves can hold their
//! primitives side by side for one SIMD test (see
//! [`crate::geometry::triangle::Tri8`]).

use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use rayon::prelude::*;

/// Children per node.
pub const WIDTH: usize = 8;

/// A child slot holding nothing.
pub const EMPTY: u32 = u32::MAX;

/// Flag of a child reference naming a leaf (the low bits index
/// [`Bvh8::leaves`]); references without it index [`Bvh8::nodes`].
pub const LEAF: u32 = 1 << 31;

/// One node: eight child boxes as rows of floats, and the children.
///
/// `planes[a][c]` is the lower bound of child `c` on axis `a` and
/// `planes[3 + a][c]` its upper bound. Empty slots have the box
/// `(+inf, -inf)`, which no ray enters, so the node test needs no mask.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Node8 {
    // Rows are 32 bytes at 32-byte offsets: one aligned AVX load each.
    /// Lower x, y, z then upper x, y, z bounds of the eight children.
    pub planes: [[f32; WIDTH]; 6],
    /// Child references: [`EMPTY`], a node index, or [`LEAF`] | leaf index.
    pub child: [u32; WIDTH],
}

impl Node8 {
    const BLANK: Node8 = Node8 {
        planes: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [EMPTY; WIDTH],
    };

    fn set(&mut self, c: usize, b: &Aabb, child: u32) {
        for a in 0..3 {
            self.planes[a][c] = b.min[a];
            self.planes[3 + a][c] = b.max[a];
        }
        self.child[c] = child;
    }

    /// Largest finite coordinate magnitude of the child boxes.
    fn magnitude(&self) -> f32 {
        let mut mag = 0.0f32;
        for row in &self.planes {
            for &v in row {
                if v.is_finite() {
                    mag = mag.max(v.abs());
                }
            }
        }
        mag
    }

    /// The box of child `c` (empty slots give an inverted box).
    pub fn child_box(&self, c: usize) -> (Vec3A, Vec3A) {
        let p = |a: usize| self.planes[a][c];
        (Vec3A::new(p(0), p(1), p(2)), Vec3A::new(p(3), p(4), p(5)))
    }
}

/// A leaf: a range of [`Bvh8::prims`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Leaf {
    /// First slot in [`Bvh8::prims`].
    pub first: u32,
    /// Number of primitives (1 ..= the build's leaf size).
    pub count: u32,
}

/// An 8-wide BVH over boxes.
#[derive(Clone, Debug, Default)]
pub struct Bvh8 {
    /// Nodes; the root is node 0 (none when the tree is empty).
    pub nodes: Vec<Node8>,
    /// Leaves, in depth-first order.
    pub leaves: Vec<Leaf>,
    /// Primitive indices (positions in the boxes the tree was built
    /// over), leaf after leaf.
    pub prims: Vec<u32>,
    /// Largest coordinate magnitude of any box: the node test's margin is
    /// taken relative to it once per ray ([`crate::accel::node`]).
    pub magnitude: f32,
    /// Levels of nodes (0 when empty).
    pub depth: usize,
}

/// A small leaf size for trees over arbitrary boxes (the collapse tests
/// use it); mesh BVHs choose their own (`LEAF_TRIANGLES` in the mesh
/// module).
pub const MAX_LEAF: u32 = 4;

impl Bvh8 {
    /// Builds over `boxes` with obvhs's preset `params`: a binary tree
    /// with one primitive per leaf, collapsed into 8-wide nodes whose
    /// leaves gather subtrees of at most `max_leaf` primitives (see
    /// [`Self::from_bvh2`]).
    pub fn build(boxes: &[Aabb], params: obvhs::BvhBuildParams, max_leaf: u32) -> Self {
        if boxes.is_empty() {
            return Self::default();
        }
        let mut phases = Phases::start();
        // obvhs's `build_bvh2` with leaves of one primitive (the collapse
        // gathers small subtrees), step by step so that the phases can be
        // timed: PLOC, then one reinsertion pass (obvhs's leaf collapse
        // does nothing with leaves of one primitive, so its second
        // reinsertion pass would only repeat the first). No pre-splits.
        let mut bvh2 = obvhs::ploc::PlocBuilder::with_capacity(boxes.len()).build(
            params.ploc_search_distance,
            boxes,
            (0..boxes.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        phases.lap("ploc");
        obvhs::bvh2::reinsertion::ReinsertionOptimizer::default().run(
            &mut bvh2,
            params.reinsertion_batch_ratio,
            None,
        );
        phases.lap("reinsertion");
        let out = Self::from_bvh2(&bvh2, boxes, max_leaf);
        phases.lap("collapse");
        out
    }

    /// Collapses `bvh2` (built over `boxes`) into 8-wide nodes: each node
    /// takes the two children of a binary node and keeps opening the
    /// inner child of largest surface area times square root of its
    /// primitive count until it has eight. A binary
    /// subtree of at most `max_leaf` primitives becomes one leaf, its
    /// primitives in increasing order; binary
    /// leaves of more than `max_leaf` primitives are split into leaves of
    /// `max_leaf` under nodes of their own (boxed by `boxes`, the boxes
    /// the tree was built over, or by the binary leaf's box when `boxes`
    /// is empty).
    ///
    /// Large trees are collapsed subtree by subtree on the worker threads
    /// and put together in the order of the serial collapse, so the
    /// result does not depend on the number of threads.
    pub fn from_bvh2(bvh2: &Bvh2, boxes: &[Aabb], max_leaf: u32) -> Self {
        Self::collapse(bvh2, boxes, max_leaf, bvh2.nodes.len() >= PARALLEL_NODES)
    }

    /// [`Self::from_bvh2`], by subtree on the worker threads or not.
    fn collapse(bvh2: &Bvh2, boxes: &[Aabb], max_leaf: u32, parallel: bool) -> Self {
        let max_leaf = max_leaf.max(1);
        let mut out = Self::default();
        if bvh2.nodes.is_empty() {
            return out;
        }
        let counts = subtree_counts(bvh2, parallel);
        let c = Collapse {
            bvh2,
            counts: &counts,
            boxes,
            max_leaf,
        };
        out.nodes.push(Node8::BLANK);
        if c.leafish(0) {
            let mut prims = Vec::new();
            gather(bvh2, 0, &mut prims);
            out.place_leaf(0, 0, &bvh2.nodes[0].aabb, &prims, boxes, max_leaf, 1);
        } else if !parallel {
            c.run(&mut out, (0, 0, 1), 0, |_, _| {});
        } else {
            // Subtrees of at most `split` primitives are collapsed apart;
            // the threshold depends on the tree only.
            let split = (c.count(0) / SUBTREES).max(max_leaf + 1);
            // The serial collapse reaches them in this order.
            let mut apart = Vec::new();
            let mut scratch = Self {
                nodes: vec![Node8::BLANK],
                ..Self::default()
            };
            c.run(&mut scratch, (0, 0, 1), split, |_, item| apart.push(item));
            let parts: Vec<Self> = apart
                .par_iter()
                .map(|&(b, _, level)| {
                    // Room for the whole part up front: grown by doubling,
                    // the node array was copied and page-faulted again at
                    // every step (a quarter of a 1M-triangle build's page
                    // faults). Capacity never written costs no memory, and
                    // a tree whose leaves hold several primitives has far
                    // fewer nodes than one per four primitives (more only
                    // grows the vector as before).
                    let n = c.count(b) as usize;
                    let mut part = Self {
                        nodes: Vec::with_capacity(n / 4 + 8),
                        leaves: Vec::with_capacity(n / 2 + 8),
                        prims: Vec::with_capacity(n),
                        ..Self::default()
                    };
                    part.nodes.push(Node8::BLANK);
                    c.run(&mut part, (b, 0, level), 0, |_, _| {});
                    part
                })
                .collect();
            let sum = |f: fn(&Self) -> usize| parts.iter().map(f).sum::<usize>();
            out.nodes.reserve(2 * apart.len() + sum(|p| p.nodes.len()));
            out.leaves
                .reserve(2 * apart.len() + sum(|p| p.leaves.len()));
            out.prims.reserve(bvh2.primitive_indices.len());
            let mut next = parts.into_iter();
            c.run(&mut out, (0, 0, 1), split, |out, (_, slot, _)| {
                out.append(slot, next.next().expect("one part per subtree"))
            });
        }
        out.magnitude = if parallel {
            out.nodes
                .par_iter()
                .map(Node8::magnitude)
                .reduce(|| 0.0, f32::max)
        } else {
            out.nodes.iter().map(Node8::magnitude).fold(0.0, f32::max)
        };
        out
    }

    /// Puts `part`, the collapse of a subtree whose root is node `slot`,
    /// behind what is already here.
    fn append(&mut self, slot: u32, part: Self) {
        // Part node `k` >= 1 becomes node `node_base + k`.
        let node_base = self.nodes.len() as u32 - 1;
        let leaf_base = self.leaves.len() as u32;
        let prim_base = self.prims.len() as u32;
        let shift = |mut n: Node8| {
            for r in &mut n.child {
                if *r == EMPTY {
                } else if *r & LEAF != 0 {
                    *r += leaf_base;
                } else {
                    *r += node_base;
                }
            }
            n
        };
        self.nodes[slot as usize] = shift(part.nodes[0]);
        self.nodes.extend(part.nodes[1..].iter().map(|&n| shift(n)));
        self.leaves.extend(part.leaves.iter().map(|l| Leaf {
            first: l.first + prim_base,
            count: l.count,
        }));
        self.prims.extend_from_slice(&part.prims);
        self.depth = self.depth.max(part.depth);
    }

    /// Puts the primitives `prims` into child `c` of node `slot` as one
    /// leaf, or, when there are more than `max_leaf`, as leaves of
    /// `max_leaf` under a node of their own.
    #[allow(clippy::too_many_arguments)]
    fn place_leaf(
        &mut self,
        slot: u32,
        c: usize,
        b: &Aabb,
        prims: &[u32],
        boxes: &[Aabb],
        max_leaf: u32,
        level: usize,
    ) {
        let count = prims.len() as u32;
        if count <= max_leaf {
            let leaf = self.leaves.len() as u32;
            self.leaves.push(Leaf {
                first: self.prims.len() as u32,
                count,
            });
            let at = self.prims.len();
            self.prims.extend_from_slice(prims);
            self.prims[at..].sort_unstable();
            self.nodes[slot as usize].set(c, b, LEAF | leaf);
            self.depth = self.depth.max(level);
            return;
        }
        // Too many for one leaf (degenerate input: obvhs's collapse keeps
        // to the limit): chunks of `max_leaf` under a node of their own,
        // eight chunks per node, recursively.
        let index = self.nodes.len() as u32;
        self.nodes.push(Node8::BLANK);
        self.nodes[slot as usize].set(c, b, index);
        let per_child = count.div_ceil(WIDTH as u32).max(max_leaf);
        let per_child = (per_child.div_ceil(max_leaf) * max_leaf) as usize;
        for (k, chunk) in prims.chunks(per_child).enumerate() {
            // Without the primitives' boxes, the whole leaf's box (larger,
            // still conservative).
            let mut bb = if boxes.is_empty() { *b } else { Aabb::empty() };
            for &p in chunk {
                if let Some(pb) = boxes.get(p as usize) {
                    bb = bb.union(pb);
                }
            }
            self.place_leaf(index, k, &bb, chunk, boxes, max_leaf, level + 1);
        }
    }
}

/// Wall-clock phase timer printing to stderr when `PRISM_BUILD_PHASES`
/// is set (build profiling).
pub(crate) struct Phases(Option<std::time::Instant>);

impl Phases {
    pub(crate) fn start() -> Self {
        static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        let on = *ON.get_or_init(|| std::env::var_os("PRISM_BUILD_PHASES").is_some());
        Self(on.then(std::time::Instant::now))
    }

    pub(crate) fn lap(&mut self, name: &str) {
        if let Some(t) = &mut self.0 {
            let now = std::time::Instant::now();
            eprintln!("phase {name}: {:.2} ms", (now - *t).as_secs_f64() * 1e3);
            *t = now;
        }
    }
}

/// Trees of at least this many binary nodes are collapsed on the worker
/// threads.
const PARALLEL_NODES: usize = 1 << 15;

/// About how many subtrees a parallel collapse cuts the tree into.
const SUBTREES: u32 = 64;

/// What the collapse reads.
struct Collapse<'a> {
    bvh2: &'a Bvh2,
    counts: &'a [AtomicU32],
    boxes: &'a [Aabb],
    max_leaf: u32,
}

impl Collapse<'_> {
    fn count(&self, i: u32) -> u32 {
        self.counts[i as usize].load(Ordering::Relaxed)
    }

    /// A child that becomes a leaf: a binary leaf, or a small subtree.
    fn leafish(&self, i: u32) -> bool {
        self.count(i) <= self.max_leaf
    }

    /// The collapse from `start` = (binary node, node slot in `out`,
    /// level), depth first. Pending inner children with at most `split`
    /// primitives are handed to `apart(out, item)` instead of being
    /// collapsed.
    fn run(
        &self,
        out: &mut Bvh8,
        start: (u32, u32, usize),
        split: u32,
        mut apart: impl FnMut(&mut Bvh8, (u32, u32, usize)),
    ) {
        let bvh2 = self.bvh2;
        let mut prims = Vec::new();
        let mut work = vec![start];
        while let Some((b, slot, level)) = work.pop() {
            if b != start.0 && self.count(b) <= split {
                apart(out, (b, slot, level));
                continue;
            }
            out.depth = out.depth.max(level);
            let node = &bvh2.nodes[b as usize];
            // (binary node, becomes a leaf, half area)
            let kid = |i: u32| {
                let leaf = self.leafish(i);
                // Opening priority: surface area times the square root of
                // the primitive count. Area alone (the usual greedy rule)
                // leaves many nodes of two small children at the bottom;
                // weighing in the count opens large subtrees first and
                // lowers the tree (anchors 100k: 9.7 -> 9.3 nodes per
                // bounce ray, ~5% faster; area x count and count alone
                // measured between the two).
                let area = if leaf {
                    f32::NEG_INFINITY
                } else {
                    bvh2.nodes[i as usize].aabb.half_area() * (self.count(i) as f32).sqrt()
                };
                (i, leaf, area)
            };
            let mut kids = [(0u32, false, 0.0f32); WIDTH];
            kids[0] = kid(node.first_index);
            kids[1] = kid(node.first_index + 1);
            let mut n = 2;
            while n < WIDTH {
                let mut best = None;
                let mut best_area = f32::NEG_INFINITY;
                for (k, &(_, leaf, area)) in kids[..n].iter().enumerate() {
                    if !leaf && area > best_area {
                        best_area = area;
                        best = Some(k);
                    }
                }
                let Some(k) = best else { break };
                let first = bvh2.nodes[kids[k].0 as usize].first_index;
                kids[k] = kid(first);
                kids[n] = kid(first + 1);
                n += 1;
            }
            for (c, &(kid, leaf, _)) in kids[..n].iter().enumerate() {
                let kn = &bvh2.nodes[kid as usize];
                if leaf {
                    prims.clear();
                    gather(bvh2, kid, &mut prims);
                    out.place_leaf(
                        slot,
                        c,
                        &kn.aabb,
                        &prims,
                        self.boxes,
                        self.max_leaf,
                        level + 1,
                    );
                } else {
                    let index = out.nodes.len() as u32;
                    out.nodes.push(Node8::BLANK);
                    out.nodes[slot as usize].set(c, &kn.aabb, index);
                    work.push((kid, index, level + 1));
                }
            }
        }
    }
}

/// Primitives below every binary node (on the worker threads when
/// `parallel`, by subtree).
fn subtree_counts(bvh2: &Bvh2, parallel: bool) -> Vec<AtomicU32> {
    let n = bvh2.nodes.len();
    if !parallel {
        let counts: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
        counts_below(bvh2, 0, &counts);
        return counts;
    }
    let counts: Vec<AtomicU32> = (0..n).into_par_iter().map(|_| AtomicU32::new(0)).collect();
    // The top levels split between threads, each subtree below counted
    // serially.
    fn split(bvh2: &Bvh2, i: u32, depth: u32, counts: &[AtomicU32]) -> u32 {
        let n = &bvh2.nodes[i as usize];
        if depth == 0 || n.is_leaf() {
            return counts_below(bvh2, i, counts);
        }
        let (a, b) = rayon::join(
            || split(bvh2, n.first_index, depth - 1, counts),
            || split(bvh2, n.first_index + 1, depth - 1, counts),
        );
        counts[i as usize].store(a + b, Ordering::Relaxed);
        a + b
    }
    split(bvh2, 0, 6, &counts);
    counts
}

/// Fills `counts` below binary node `root` and returns its count.
fn counts_below(bvh2: &Bvh2, root: u32, counts: &[AtomicU32]) -> u32 {
    let get = |i: u32| counts[i as usize].load(Ordering::Relaxed);
    // Post-order without recursion: (node, children done).
    let mut stack = vec![(root, false)];
    while let Some((i, done)) = stack.pop() {
        let n = &bvh2.nodes[i as usize];
        let c = if n.is_leaf() {
            n.prim_count
        } else if done {
            get(n.first_index) + get(n.first_index + 1)
        } else {
            stack.push((i, true));
            stack.push((n.first_index, false));
            stack.push((n.first_index + 1, false));
            continue;
        };
        counts[i as usize].store(c, Ordering::Relaxed);
    }
    get(root)
}

/// Appends the primitives below binary node `i`, left to right.
fn gather(bvh2: &Bvh2, i: u32, out: &mut Vec<u32>) {
    let n = &bvh2.nodes[i as usize];
    if n.is_leaf() {
        let f = n.first_index as usize;
        out.extend_from_slice(&bvh2.primitive_indices[f..f + n.prim_count as usize]);
    } else {
        // Only called on subtrees of at most a leaf's size: shallow.
        gather(bvh2, n.first_index, out);
        gather(bvh2, n.first_index + 1, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_boxes(n: usize, seed: u64) -> Vec<Aabb> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        (0..n)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next()) * 10.0;
                let h = Vec3A::new(next().abs(), next().abs(), next().abs()) * 0.5 + 0.01;
                Aabb::new(c - h, c + h)
            })
            .collect()
    }

    /// Every primitive sits in exactly one leaf, every child box contains
    /// what is below it, and leaves keep to the size limit.
    #[test]
    fn collapse_keeps_every_primitive_inside_its_boxes() {
        for n in [1usize, 2, 7, 9, 100, 1000] {
            let boxes = random_boxes(n, n as u64);
            let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), MAX_LEAF);
            let mut seen = vec![0u32; n];
            fn walk(bvh: &Bvh8, node: u32, lo: Vec3A, hi: Vec3A, boxes: &[Aabb], seen: &mut [u32]) {
                let nd = &bvh.nodes[node as usize];
                for c in 0..WIDTH {
                    let r = nd.child[c];
                    if r == EMPTY {
                        continue;
                    }
                    let (clo, chi) = nd.child_box(c);
                    assert!(clo.cmpge(lo).all() && chi.cmple(hi).all());
                    if r & LEAF != 0 {
                        let leaf = bvh.leaves[(r & !LEAF) as usize];
                        assert!(leaf.count >= 1 && leaf.count <= MAX_LEAF);
                        for s in leaf.first..leaf.first + leaf.count {
                            let p = bvh.prims[s as usize] as usize;
                            seen[p] += 1;
                            let b = &boxes[p];
                            assert!(b.min.cmpge(clo).all() && b.max.cmple(chi).all());
                        }
                    } else {
                        walk(bvh, r, clo, chi, boxes, seen);
                    }
                }
            }
            walk(
                &bvh,
                0,
                Vec3A::splat(f32::NEG_INFINITY),
                Vec3A::splat(f32::INFINITY),
                &boxes,
                &mut seen,
            );
            assert!(seen.iter().all(|&s| s == 1), "n = {n}");
            assert!(bvh.depth >= 1);
        }
    }

    /// The collapse by subtree on the worker threads gives the serial
    /// collapse's tree, node for node, for any number of threads.
    #[test]
    fn parallel_collapse_is_the_serial_collapse() {
        let boxes = random_boxes(3000, 11);
        let bvh2 = obvhs::bvh2::builder::build_bvh2(
            &boxes,
            obvhs::BvhBuildParams {
                max_prims_per_leaf: 1,
                ..obvhs::BvhBuildParams::medium_build()
            },
            &mut Default::default(),
        );
        let key = |b: &Bvh8| {
            let nodes: Vec<_> = b
                .nodes
                .iter()
                .map(|n| (n.child, n.planes.map(|r| r.map(f32::to_bits))))
                .collect();
            (
                nodes,
                b.leaves.clone(),
                b.prims.clone(),
                b.depth,
                b.magnitude,
            )
        };
        for max_leaf in [1, 4, 8] {
            let serial = Bvh8::collapse(&bvh2, &boxes, max_leaf, false);
            assert!(serial.nodes.len() > 100);
            for threads in [1, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let parallel = pool.install(|| Bvh8::collapse(&bvh2, &boxes, max_leaf, true));
                assert!(key(&parallel) == key(&serial), "max_leaf {max_leaf}");
            }
        }
    }

    /// A binary leaf over the limit is split into leaves within it.
    #[test]
    fn oversized_leaves_are_split() {
        let boxes = random_boxes(37, 5);
        let bvh2 = obvhs::bvh2::builder::build_bvh2(
            &boxes,
            obvhs::BvhBuildParams {
                max_prims_per_leaf: 64,
                collapse_traversal_cost: 1000.0,
                ..obvhs::BvhBuildParams::medium_build()
            },
            &mut Default::default(),
        );
        let bvh = Bvh8::from_bvh2(&bvh2, &boxes, 4);
        assert_eq!(bvh.prims.len(), 37);
        assert!(bvh.leaves.iter().all(|l| l.count <= 4));
    }
}
