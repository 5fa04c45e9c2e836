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

/// Flag of a child reference naming a leaf; references without it index
/// [`Bvh8::nodes`]. A leaf's reference holds its index into
/// [`Bvh8::leaves`] in the low [`LEAF_BITS`] bits ([`leaf_index`]) and
/// its primitive count less one in the three bits above ([`leaf_count`]),
/// so that traversal knows the count without reading `leaves` (a load that
/// missed the first-level cache at a tenth of the leaf visits of the
/// anchors' bounce rays, `perf annotate`).
pub const LEAF: u32 = 1 << 31;

/// Bits of a leaf reference that index [`Bvh8::leaves`].
pub const LEAF_BITS: u32 = 28;

/// Most primitives a leaf can hold (the count is kept in three bits of
/// its reference).
pub const LEAF_LIMIT: u32 = 8;

/// The reference of leaf `index` holding `count` (1 to [`LEAF_LIMIT`])
/// primitives.
#[inline(always)]
pub fn leaf_ref(index: u32, count: u32) -> u32 {
    assert!(
        index < 1 << LEAF_BITS && (1..=LEAF_LIMIT).contains(&count),
        "leaf {index} of {count} primitives does not fit a reference"
    );
    LEAF | (count - 1) << LEAF_BITS | index
}

/// The index into [`Bvh8::leaves`] of leaf reference `r`.
#[inline(always)]
pub fn leaf_index(r: u32) -> u32 {
    r & ((1 << LEAF_BITS) - 1)
}

/// The primitive count of leaf reference `r` (1 to [`LEAF_LIMIT`]).
#[inline(always)]
pub fn leaf_count(r: u32) -> u32 {
    ((r >> LEAF_BITS) & (LEAF_LIMIT - 1)) + 1
}

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
    /// Child references: [`EMPTY`], a node index, or a leaf's reference
    /// ([`leaf_ref`]).
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

    /// Collapses `bvh2` (built over `boxes`) into 8-wide nodes, choosing
    /// the collapse of least cost under the surface area heuristic
    /// (`Plan`): which binary subtrees of at most `max_leaf` primitives
    /// become one leaf (its primitives in increasing order), and which
    /// binary descendants, up to eight, become the children of each node.
    /// Binary leaves of more than `max_leaf` primitives are split into
    /// leaves of `max_leaf` under nodes of their own (boxed by `boxes`,
    /// the boxes the tree was built over, or by the binary leaf's box when
    /// `boxes` is empty). `max_leaf` is taken between 1 and [`LEAF_LIMIT`].
    ///
    /// Large trees are collapsed subtree by subtree on the worker threads
    /// and put together in the order of the serial collapse, so the
    /// result does not depend on the number of threads.
    pub fn from_bvh2(bvh2: &Bvh2, boxes: &[Aabb], max_leaf: u32) -> Self {
        Self::collapse(bvh2, boxes, max_leaf, bvh2.nodes.len() >= PARALLEL_NODES)
    }

    /// [`Self::from_bvh2`], by subtree on the worker threads or not.
    fn collapse(bvh2: &Bvh2, boxes: &[Aabb], max_leaf: u32, parallel: bool) -> Self {
        let max_leaf = max_leaf.clamp(1, LEAF_LIMIT);
        let mut out = Self::default();
        if bvh2.nodes.is_empty() {
            return out;
        }
        let (plan, _) = Plan::new(bvh2, max_leaf, parallel);
        let c = Collapse {
            bvh2,
            plan: &plan,
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
            self.nodes[slot as usize].set(c, b, leaf_ref(leaf, count));
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
    plan: &'a Plan,
    boxes: &'a [Aabb],
    max_leaf: u32,
}

impl Collapse<'_> {
    fn count(&self, i: u32) -> u32 {
        self.plan.count(i)
    }

    /// A child that becomes a leaf: a binary leaf, or a small subtree
    /// the plan keeps whole.
    fn leafish(&self, i: u32) -> bool {
        self.plan.leaf(i)
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
            // The plan's roots below `b`: the subtrees that become its
            // children, left to right.
            let mut kids = [0u32; WIDTH];
            let mut n = 0;
            let k = self.plan.split8(b);
            self.plan
                .expand(bvh2, node.first_index, k, &mut kids, &mut n);
            self.plan
                .expand(bvh2, node.first_index + 1, WIDTH - k, &mut kids, &mut n);
            for (c, &kid) in kids[..n].iter().enumerate() {
                let kn = &bvh2.nodes[kid as usize];
                if self.leafish(kid) {
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

/// Cost of testing a node's children, per unit of its surface area, in
/// the collapse's cost model ([`Plan`]).
const NODE_COST: f32 = 1.0;

/// Cost of testing a leaf's primitives (one block of up to eight
/// triangles side by side), per unit of its surface area. Measured with
/// the anchors' 100k mesh: a leaf as dear as a node gave the fewest node
/// and leaf tests per bounce ray; 1.2 and 1.5 times it, fewer leaves of
/// more triangles and slightly more work (README, "Traversal kernel").
const LEAF_COST: f32 = 1.0;

/// Bits of [`Plan::how`]: the subtree is kept as one leaf.
const HOW_LEAF: u32 = 1;

/// The least-cost collapse of a binary tree into 8-wide nodes, by
/// dynamic programming over its subtrees (after Ylitie, Karras and Laine,
/// "Efficient incoherent ray traversal on GPUs through compressed wide
/// BVHs", 2017). The cost of a tree is the surface area heuristic's:
/// each node's area times [`NODE_COST`] plus each leaf's area times
/// [`LEAF_COST`] (a split binary leaf as a node and its leaves). For every
/// binary subtree `n` and `i` in 1..=7, `C(n, i)` is the least cost of
/// representing it as at most `i` roots side by side: `C(n, 1)` keeps it
/// whole, as one leaf (at most `max_leaf` primitives) or as one node whose
/// eight children are the best eight roots of its two halves; `C(n, i)`
/// takes the better of that and splitting the `i` roots between the
/// halves. The greedy collapse it replaces (opening the child of largest
/// area times square root of count) did 2-4% more node and leaf tests per
/// bounce ray on the anchors' meshes.
///
/// Every entry depends only on the subtree below it, so the plan, and the
/// tree made from it, do not depend on the number of threads.
struct Plan {
    /// Primitives below each binary node.
    counts: Vec<AtomicU32>,
    /// Per node: [`HOW_LEAF`]; in bits `4 (i - 1)..4 i` for `i` = 2..=7,
    /// the roots the first half takes in `C(n, i)` (0: the subtree is
    /// one root); in bits 28..32 those it takes under `n` as a node. (The
    /// costs themselves are needed only by the parent, and are handed up
    /// on the way, not stored.)
    how: Vec<AtomicU32>,
}

/// `C(n, i)` for `i` = 1..=7 of a planned subtree and its primitive count.
type Costs = (u32, [f32; 7]);

impl Plan {
    /// The plan of `bvh2` and the least cost of the whole tree.
    fn new(bvh2: &Bvh2, max_leaf: u32, parallel: bool) -> (Self, f32) {
        let n = bvh2.nodes.len();
        let zeros = |k: usize| -> Vec<AtomicU32> {
            if parallel {
                (0..k).into_par_iter().map(|_| AtomicU32::new(0)).collect()
            } else {
                (0..k).map(|_| AtomicU32::new(0)).collect()
            }
        };
        let plan = Plan {
            counts: zeros(n),
            how: zeros(n),
        };
        if n == 0 {
            return (plan, 0.0);
        }
        if !parallel {
            let (_, cost) = plan.below(bvh2, 0, max_leaf);
            return (plan, cost[0]);
        }
        // The top levels split between threads, each subtree below
        // planned serially.
        fn split(plan: &Plan, bvh2: &Bvh2, i: u32, depth: u32, max_leaf: u32) -> Costs {
            let n = &bvh2.nodes[i as usize];
            if depth == 0 || n.is_leaf() {
                return plan.below(bvh2, i, max_leaf);
            }
            let (l, r) = rayon::join(
                || split(plan, bvh2, n.first_index, depth - 1, max_leaf),
                || split(plan, bvh2, n.first_index + 1, depth - 1, max_leaf),
            );
            plan.fill(bvh2, i, max_leaf, Some((&l, &r)))
        }
        let (_, cost) = split(&plan, bvh2, 0, 6, max_leaf);
        (plan, cost[0])
    }

    fn count(&self, i: u32) -> u32 {
        self.counts[i as usize].load(Ordering::Relaxed)
    }

    fn how(&self, n: u32) -> u32 {
        self.how[n as usize].load(Ordering::Relaxed)
    }

    /// Whether binary subtree `n` becomes one leaf when it is a root.
    fn leaf(&self, n: u32) -> bool {
        self.how(n) & HOW_LEAF != 0
    }

    /// The roots the first half of `n` takes when `n` becomes a node (1..=7).
    fn split8(&self, n: u32) -> usize {
        (self.how(n) >> 28) as usize
    }

    /// Appends to `out[*len..]` the roots of binary subtree `x` taken as at
    /// most `m` roots (`m` in 1..=7), left to right.
    fn expand(&self, bvh2: &Bvh2, x: u32, m: usize, out: &mut [u32; WIDTH], len: &mut usize) {
        let k = if m >= 2 {
            (self.how(x) >> (4 * (m - 1)) & 15) as usize
        } else {
            0
        };
        if k == 0 {
            out[*len] = x;
            *len += 1;
            return;
        }
        let first = bvh2.nodes[x as usize].first_index;
        self.expand(bvh2, first, k, out, len);
        self.expand(bvh2, first + 1, m - k, out, len);
    }

    /// Plans every node below binary node `root`, children first, and
    /// returns the root's costs.
    fn below(&self, bvh2: &Bvh2, root: u32, max_leaf: u32) -> Costs {
        // Post-order without recursion: (node, children done); each
        // planned node leaves its costs on `done`, where its parent finds
        // its first half's on top (the second half was planned first).
        let mut stack = vec![(root, false)];
        let mut done: Vec<Costs> = Vec::new();
        while let Some((i, children_done)) = stack.pop() {
            let n = &bvh2.nodes[i as usize];
            if n.is_leaf() {
                done.push(self.fill(bvh2, i, max_leaf, None));
            } else if !children_done {
                stack.push((i, true));
                stack.push((n.first_index, false));
                stack.push((n.first_index + 1, false));
            } else {
                let l = done.pop().expect("first half planned");
                let r = done.pop().expect("second half planned");
                done.push(self.fill(bvh2, i, max_leaf, Some((&l, &r))));
            }
        }
        done.pop().expect("the root planned")
    }

    /// Plans binary node `i` from its halves' costs (`None` for a binary
    /// leaf) and returns its own.
    fn fill(&self, bvh2: &Bvh2, i: u32, max_leaf: u32, halves: Option<(&Costs, &Costs)>) -> Costs {
        let n = &bvh2.nodes[i as usize];
        let area = n.aabb.half_area();
        let Some(((cl, l), (cr, r))) = halves else {
            let count = n.prim_count;
            self.counts[i as usize].store(count, Ordering::Relaxed);
            let c = if count <= max_leaf {
                area * LEAF_COST
            } else {
                area * (NODE_COST + count.div_ceil(max_leaf) as f32 * LEAF_COST)
            };
            self.how[i as usize].store(HOW_LEAF, Ordering::Relaxed);
            return (count, [c; 7]);
        };
        let count = cl + cr;
        self.counts[i as usize].store(count, Ordering::Relaxed);
        // Both halves as `j` roots in all, `j` in 2..=8; the first takes
        // `split[j]`.
        let mut both = [f32::INFINITY; WIDTH + 1];
        let mut split = [0u32; WIDTH + 1];
        for j in 2..=WIDTH {
            for k in 1..j {
                let c = l[k - 1] + r[j - k - 1];
                if c < both[j] {
                    both[j] = c;
                    split[j] = k as u32;
                }
            }
        }
        let node = area * NODE_COST + both[WIDTH];
        let leaf = if count <= max_leaf {
            area * LEAF_COST
        } else {
            f32::INFINITY
        };
        let mut how = split[WIDTH] << 28;
        let whole = if leaf <= node {
            how |= HOW_LEAF;
            leaf
        } else {
            node
        };
        let mut costs = [whole; 7];
        for j in 2..=7 {
            if both[j] < whole {
                costs[j - 1] = both[j];
                how |= split[j] << (4 * (j - 1));
            }
        }
        self.how[i as usize].store(how, Ordering::Relaxed);
        (count, costs)
    }
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

    /// obvhs's binary tree over `boxes`, one primitive per leaf.
    fn binary_tree(boxes: &[Aabb]) -> Bvh2 {
        obvhs::bvh2::builder::build_bvh2(
            boxes,
            obvhs::BvhBuildParams {
                max_prims_per_leaf: 1,
                ..obvhs::BvhBuildParams::medium_build()
            },
            &mut Default::default(),
        )
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
                        let leaf = bvh.leaves[leaf_index(r) as usize];
                        assert_eq!(leaf_count(r), leaf.count);
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
        let bvh2 = binary_tree(&boxes);
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

    /// The tree the collapse makes costs what its plan says: the surface
    /// area heuristic summed over the 8-wide tree's nodes and leaves (each
    /// child box is its binary node's) equals the plan's least cost of the
    /// root, so the tree is the one the dynamic programme chose.
    #[test]
    fn collapse_costs_what_its_plan_says() {
        let boxes = random_boxes(2000, 3);
        let bvh2 = binary_tree(&boxes);
        let half_area = |lo: Vec3A, hi: Vec3A| {
            let d = hi - lo;
            d.x * d.y + d.y * d.z + d.z * d.x
        };
        for max_leaf in [1, 4, 8] {
            let bvh = Bvh8::collapse(&bvh2, &boxes, max_leaf, false);
            let mut sum = bvh2.nodes[0].aabb.half_area() as f64 * NODE_COST as f64;
            let mut leaves = 0;
            for node in &bvh.nodes {
                for c in 0..WIDTH {
                    if node.child[c] == EMPTY {
                        continue;
                    }
                    let (lo, hi) = node.child_box(c);
                    let cost = if node.child[c] & LEAF != 0 {
                        leaves += 1;
                        LEAF_COST
                    } else {
                        NODE_COST
                    };
                    sum += half_area(lo, hi) as f64 * cost as f64;
                }
            }
            assert_eq!(leaves, bvh.leaves.len());
            let planned = Plan::new(&bvh2, max_leaf, false).1 as f64;
            assert!(
                (sum - planned).abs() <= 1e-4 * planned,
                "max_leaf {max_leaf}: tree {sum}, plan {planned}"
            );
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
