//! The top-level BVH over a scene's instances, kept up to date
//! incrementally.
//!
//! The source of truth is an obvhs [`Bvh2`] with one instance per leaf:
//! it is the only obvhs BVH that supports insertion, removal and moving of
//! leaves. Traversal uses a [`Bvh8`] collapsed from it after each batch of
//! changes (see `Tlas::commit`): collapsing is linear in the number of
//! instances, needs no sort, and gives the top level the same node layout
//! and traversals (single rays, packets, streams) as meshes.
//!
//! Every instance has a *key*: its primitive id in the [`Bvh2`]. Keys stay
//! put when instances are swap-removed, so a removal touches one leaf.
//!
//! Mesh BVHs are never touched here: an instance's box is its mesh's
//! object-space bounds transformed to world space.

use std::time::Instant;

use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::ploc::PlocBuilder;

use crate::accel::build::BuildQuality;
use crate::accel::bvh8::Bvh8;

const NONE: u32 = u32::MAX;

/// Deepest traversal tree accepted after incremental updates; deeper
/// trees are rebuilt (traversal handles any depth, but a tree this deep
/// has lost its quality).
const MAX_DEPTH: usize = 32;

/// How a moved instance's leaf is updated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MoveStrategy {
    /// Resize the leaf in place and refit its ancestors: cheapest, but the
    /// tree keeps its old shape, so boxes of objects that travel far
    /// overlap more and more.
    Refit,
    /// Detach the leaf and reinsert it where it now belongs (obvhs's
    /// greedy sibling search with tree rotations on the way up), which
    /// keeps the tree's quality as objects travel.
    #[default]
    Reinsert,
}

/// When the top level is updated incrementally and when it is rebuilt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TlasPolicy {
    /// How moved leaves are updated.
    pub moves: MoveStrategy,
    /// Rebuild from scratch when more leaves changed (inserted, removed
    /// or moved) since the last commit than this fraction of the bounded
    /// instances at the last commit. See `benches/frame_loop.rs` (group `tlas_update`) for the
    /// measurement behind the default.
    pub rebuild_fraction: f32,
    /// Scenes with at most this many bounded instances are always rebuilt:
    /// below it a rebuild costs about as much as a few leaf updates.
    pub rebuild_below: usize,
}

/// The default churn threshold: the fraction of instances changed per
/// commit above which a full rebuild is cheaper than updating leaves one
/// by one.
///
/// Measured with `cargo bench --bench frame_loop -- tlas_update` (1,000
/// instances, 2 cores): a commit costs about 100 us of conversion to the
/// traversal BVH plus 0.3 us per reinserted leaf (0.05 us per refitted
/// leaf), while a rebuild costs about 470 us whatever changed. Reinsertion
/// therefore stays cheaper up to about 1,200 moved leaves per 1,000
/// instances: leaf updates win whenever each instance changes at most
/// once, and only heavier churn (many insertions and removals on top of
/// moves) triggers a rebuild.
pub const DEFAULT_REBUILD_FRACTION: f32 = 1.0;

impl Default for TlasPolicy {
    fn default() -> Self {
        Self {
            moves: MoveStrategy::default(),
            rebuild_fraction: DEFAULT_REBUILD_FRACTION,
            rebuild_below: 0,
        }
    }
}

/// Work done on the top level since the scene was created (cumulative).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TlasCounters {
    /// Full builds of a non-empty top level (PLOC build of the [`Bvh2`]).
    pub rebuilds: u64,
    /// Leaves resized in place, ancestors refitted.
    pub refits: u64,
    /// Leaves detached and reinserted elsewhere.
    pub reinserts: u64,
    /// Leaves inserted.
    pub inserts: u64,
    /// Leaves removed.
    pub removes: u64,
    /// Conversions of the [`Bvh2`] to the traversal [`Bvh8`].
    pub conversions: u64,
}

/// What a top-level commit ([`crate::scene::RenderScene::commit`]) did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasUpdate {
    /// Nothing changed since the last commit.
    #[default]
    Unchanged,
    /// Leaves were updated and the traversal BVH converted again.
    Incremental,
    /// The top level was rebuilt from scratch.
    Rebuilt,
}

/// The top-level acceleration structure of a [`crate::scene::RenderScene`].
pub struct Tlas {
    bvh2: Bvh2,
    /// Traversal BVH; its `prims` are keys.
    pub(crate) bvh: Bvh8,
    /// Instance index per traversal leaf slot (position in `bvh.prims`).
    pub(crate) leaf_instances: Vec<u32>,
    /// Instances without bounds (infinite planes, huge objects), tested
    /// one by one.
    pub(crate) unbounded: Vec<u32>,
    key_instance: Vec<u32>,
    instance_key: Vec<u32>,
    free_keys: Vec<u32>,
    quality: BuildQuality,
    /// The policy in use.
    pub policy: TlasPolicy,
    /// Leaves changed since the last commit.
    changes: usize,
    /// Bounded instances at the last commit: churn is measured against it
    /// (so a scene filled from empty is built, not grown leaf by leaf).
    committed_count: usize,
    /// The Bvh2 changed since the last conversion.
    stale: bool,
    /// Churn passed the threshold: leaf updates are skipped and the next
    /// commit rebuilds.
    rebuild_pending: bool,
    counters: TlasCounters,
    /// Seconds spent by the last commit (or build).
    pub last_seconds: f64,
}

impl std::fmt::Debug for Tlas {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tlas")
            .field("bvh2_nodes", &self.bvh2.nodes.len())
            .field("bvh8_nodes", &self.bvh.nodes.len())
            .field("leaves", &self.leaf_instances.len())
            .field("unbounded", &self.unbounded)
            .field("policy", &self.policy)
            .field("counters", &self.counters)
            .finish()
    }
}

/// Where an instance belongs in the top level: what the top level needs
/// to know of it, computed by the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Placement {
    /// In the BVH, with this world-space box.
    Bounded(Aabb),
    /// Tested by every ray (infinite planes, huge objects).
    Unbounded,
    /// Never hit (a mesh without triangles).
    Nowhere,
}

impl Tlas {
    /// Builds the top level over `count` instances, instance `i` placed
    /// as `placement(i)`.
    pub fn build(
        count: usize,
        placement: impl Fn(usize) -> Placement,
        quality: BuildQuality,
    ) -> Self {
        let mut tlas = Self {
            bvh2: Bvh2::default(),
            bvh: Bvh8::default(),
            leaf_instances: Vec::new(),
            unbounded: Vec::new(),
            key_instance: Vec::new(),
            instance_key: Vec::new(),
            free_keys: Vec::new(),
            quality,
            policy: TlasPolicy::default(),
            changes: 0,
            committed_count: 0,
            stale: false,
            rebuild_pending: false,
            counters: TlasCounters::default(),
            last_seconds: 0.0,
        };
        let start = Instant::now();
        tlas.rebuild(count, placement);
        tlas.last_seconds = start.elapsed().as_secs_f64();
        tlas
    }

    /// Cumulative work counters.
    pub fn counters(&self) -> TlasCounters {
        self.counters
    }

    /// Number of bounded instances in the BVH.
    pub fn bounded_count(&self) -> usize {
        self.key_instance.len() - self.free_keys.len()
    }

    fn rebuild(&mut self, count: usize, placement: impl Fn(usize) -> Placement) {
        let mut boxes = Vec::with_capacity(count);
        self.key_instance.clear();
        self.instance_key.clear();
        self.instance_key.resize(count, NONE);
        self.free_keys.clear();
        self.unbounded.clear();
        for i in 0..count {
            match placement(i) {
                Placement::Bounded(b) => {
                    self.instance_key[i] = boxes.len() as u32;
                    self.key_instance.push(i as u32);
                    boxes.push(b);
                }
                Placement::Unbounded => self.unbounded.push(i as u32),
                Placement::Nowhere => {}
            }
        }
        let params = self.quality.params();
        self.bvh2 = PlocBuilder::with_capacity(boxes.len()).build(
            params.ploc_search_distance,
            &boxes,
            (0..boxes.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        ReinsertionOptimizer::default().run(&mut self.bvh2, params.reinsertion_batch_ratio, None);
        if !boxes.is_empty() {
            self.counters.rebuilds += 1;
        }
        self.rebuild_pending = false;
        self.convert();
    }

    fn convert(&mut self) {
        // Every Bvh2 leaf holds one instance (PLOC leaves, insertions), and
        // so does every traversal leaf: each instance's box is tested in
        // the node that holds it.
        self.bvh = Bvh8::from_bvh2(&self.bvh2, &[], 1);
        self.leaf_instances = self
            .bvh
            .prims
            .iter()
            .map(|&k| self.key_instance[k as usize])
            .collect();
        self.counters.conversions += 1;
        self.stale = false;
        self.changes = 0;
        self.committed_count = self.bounded_count();
    }

    /// Counts one changed leaf; past the churn threshold the remaining
    /// leaf updates are skipped and the next commit rebuilds.
    fn note_change(&mut self) {
        self.changes += 1;
        self.stale = true;
        let n = self.committed_count;
        if n <= self.policy.rebuild_below
            || self.changes as f32 > self.policy.rebuild_fraction * n as f32
        {
            self.rebuild_pending = true;
        }
    }

    fn insert_key(&mut self, index: u32, b: Aabb) {
        let key = self.free_keys.pop().unwrap_or_else(|| {
            self.key_instance.push(NONE);
            self.key_instance.len() as u32 - 1
        });
        self.key_instance[key as usize] = index;
        self.instance_key[index as usize] = key;
        self.note_change();
        if !self.rebuild_pending {
            self.bvh2.insert_primitive(b, key);
            self.counters.inserts += 1;
        }
    }

    fn remove_key(&mut self, index: u32) {
        let key = self.instance_key[index as usize];
        self.instance_key[index as usize] = NONE;
        self.key_instance[key as usize] = NONE;
        self.free_keys.push(key);
        self.note_change();
        if !self.rebuild_pending {
            self.bvh2.remove_primitive(key);
            self.counters.removes += 1;
        }
    }

    fn place(&mut self, index: u32, placement: Placement) {
        match placement {
            Placement::Bounded(b) => self.insert_key(index, b),
            Placement::Unbounded => self.unbounded.push(index),
            Placement::Nowhere => {}
        }
    }

    fn unplace(&mut self, index: u32) {
        if self.instance_key[index as usize] != NONE {
            self.remove_key(index);
        } else if let Some(p) = self.unbounded.iter().position(|&u| u == index) {
            self.unbounded.swap_remove(p);
        }
    }

    /// Instance `index` was just appended, placed as `placement`.
    pub fn inserted(&mut self, index: u32, placement: Placement) {
        debug_assert_eq!(index as usize, self.instance_key.len());
        self.instance_key.push(NONE);
        self.place(index, placement);
    }

    /// Instance `index` is about to be swap-removed (the last instance,
    /// at `last`, takes its index).
    pub fn removing(&mut self, index: u32, last: u32) {
        self.unplace(index);
        if index != last {
            let key = self.instance_key[last as usize];
            self.instance_key[index as usize] = key;
            if key != NONE {
                self.key_instance[key as usize] = index;
            }
            for u in &mut self.unbounded {
                if *u == last {
                    *u = index;
                }
            }
            // Leaf slots name instances: convert again even if nothing
            // else changed.
            self.stale = true;
        }
        self.instance_key.pop();
    }

    /// Instance `index` moved or changed geometry; it is now placed as
    /// `placement`.
    pub fn updated(&mut self, index: u32, placement: Placement) {
        let key = self.instance_key[index as usize];
        match (key != NONE, placement) {
            (true, Placement::Bounded(b)) => {
                self.note_change();
                if !self.rebuild_pending {
                    match self.policy.moves {
                        MoveStrategy::Refit => {
                            self.bvh2.init_primitives_to_nodes_if_uninit();
                            let node = self.bvh2.primitives_to_nodes[key as usize] as usize;
                            self.bvh2.resize_node(node, b);
                            self.counters.refits += 1;
                        }
                        MoveStrategy::Reinsert => {
                            self.bvh2.move_primitive(b, key);
                            self.counters.reinserts += 1;
                        }
                    }
                }
            }
            _ => {
                // Bounded <-> unbounded, or an unbounded shape changed.
                self.unplace(index);
                self.place(index, placement);
            }
        }
    }

    /// Applies the changes since the last commit: a rebuild when churn
    /// passed the threshold, otherwise a conversion of the updated
    /// [`Bvh2`]. Does nothing when nothing changed.
    /// `placement(i)` places each of the `count` instances, as for
    /// [`Tlas::build`].
    pub fn commit(&mut self, count: usize, placement: impl Fn(usize) -> Placement) -> TlasUpdate {
        let start = Instant::now();
        let update = if self.rebuild_pending {
            self.rebuild(count, placement);
            TlasUpdate::Rebuilt
        } else if self.stale {
            self.convert();
            if self.bvh.depth > MAX_DEPTH {
                self.rebuild(count, placement);
                TlasUpdate::Rebuilt
            } else {
                TlasUpdate::Incremental
            }
        } else {
            TlasUpdate::Unchanged
        };
        if update != TlasUpdate::Unchanged {
            self.last_seconds = start.elapsed().as_secs_f64();
        }
        update
    }
}
