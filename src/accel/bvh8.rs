//! Prism's own 8-wide BVH: the tree obvhs builds (a [`Bvh2`]), collapsed
//! into nodes of eight float child boxes stored as structure of arrays,
//! with leaves of a few primitives.
//!
//! obvhs stays the builder (PLOC, reinsertion, SAH leaf collapse); the
//! layout is Prism's so that one node test reads six rows of eight floats
//! (no dequantisation, no per-node margin) and leaves can hold their
//! primitives side by side for one SIMD test (see
//! [`crate::geometry::triangle::Tri4`]).

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;

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
    pub fn build(boxes: &[Aabb], mut params: obvhs::BvhBuildParams, max_leaf: u32) -> Self {
        if boxes.is_empty() {
            return Self::default();
        }
        params.pre_split = false;
        // Leaves of one primitive: the collapse gathers small subtrees.
        params.max_prims_per_leaf = 1;
        // With leaves of one primitive obvhs's leaf collapse does nothing,
        // so its second reinsertion pass would only repeat the first.
        params.post_collapse_reinsertion_batch_ratio_multiplier = 0.0;
        let bvh2 = obvhs::bvh2::builder::build_bvh2(boxes, params, &mut Default::default());
        Self::from_bvh2(&bvh2, boxes, max_leaf)
    }

    /// Collapses `bvh2` (built over `boxes`) into 8-wide nodes: each node
    /// takes the two children of a binary node and keeps opening the
    /// inner child of largest surface area times square root of its
    /// primitive count until it has eight. A binary
    /// subtree of at most `max_leaf` primitives becomes one leaf; binary
    /// leaves of more than `max_leaf` primitives are split into leaves of
    /// `max_leaf` under nodes of their own (boxed by `boxes`, the boxes
    /// the tree was built over, or by the binary leaf's box when `boxes`
    /// is empty).
    pub fn from_bvh2(bvh2: &Bvh2, boxes: &[Aabb], max_leaf: u32) -> Self {
        let max_leaf = max_leaf.max(1);
        let mut out = Self::default();
        if bvh2.nodes.is_empty() {
            return out;
        }
        // A child that becomes a leaf: a binary leaf, or a small subtree.
        let counts = subtree_counts(bvh2);
        let leafish = |i: u32| counts[i as usize] <= max_leaf;
        let mut prims = Vec::new();
        out.nodes.push(Node8::BLANK);
        // (binary node, node slot, level)
        let mut work: Vec<(u32, u32, usize)> = Vec::new();
        if leafish(0) {
            gather(bvh2, 0, &mut prims);
            out.place_leaf(0, 0, &bvh2.nodes[0].aabb, &prims, boxes, max_leaf, 1);
        } else {
            work.push((0, 0, 1));
        }
        while let Some((b, slot, level)) = work.pop() {
            out.depth = out.depth.max(level);
            let node = &bvh2.nodes[b as usize];
            // (binary node, becomes a leaf, half area)
            let kid = |i: u32| {
                let leaf = leafish(i);
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
                    bvh2.nodes[i as usize].aabb.half_area() * (counts[i as usize] as f32).sqrt()
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
                    out.place_leaf(slot, c, &kn.aabb, &prims, boxes, max_leaf, level + 1);
                } else {
                    let index = out.nodes.len() as u32;
                    out.nodes.push(Node8::BLANK);
                    out.nodes[slot as usize].set(c, &kn.aabb, index);
                    work.push((kid, index, level + 1));
                }
            }
        }
        let mut mag = 0.0f32;
        for n in &out.nodes {
            for row in &n.planes {
                for &v in row {
                    if v.is_finite() {
                        mag = mag.max(v.abs());
                    }
                }
            }
        }
        out.magnitude = mag;
        out
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
            self.prims.extend_from_slice(prims);
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

/// Primitives below every binary node.
fn subtree_counts(bvh2: &Bvh2) -> Vec<u32> {
    let mut counts = vec![0u32; bvh2.nodes.len()];
    // Post-order without recursion: (node, children done).
    let mut stack = vec![(0u32, false)];
    while let Some((i, done)) = stack.pop() {
        let n = &bvh2.nodes[i as usize];
        if n.is_leaf() {
            counts[i as usize] = n.prim_count;
        } else if done {
            counts[i as usize] =
                counts[n.first_index as usize] + counts[n.first_index as usize + 1];
        } else {
            stack.push((i, true));
            stack.push((n.first_index, false));
            stack.push((n.first_index + 1, false));
        }
    }
    counts
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
