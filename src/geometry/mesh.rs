//! Triangle meshes with their own bottom-level BVH, intersected with the
//! watertight triangle test of [`crate::geometry::triangle`].

use std::time::Instant;

use glam::{Vec2, Vec3, Vec3A, Vec4};
use obvhs::aabb::Aabb;
use rayon::prelude::*;

use crate::accel::build::padded_aabb;
/// Re-exported: a mesh is built with one of these presets.
pub use crate::accel::build::{BuildOptions, BuildQuality, MAX_COORDINATE};
use crate::accel::bvh8::Bvh8;
use crate::accel::grid::Grid;
use crate::accel::kdtree::KdTree;
use crate::accel::packet::{LANES, LaneMask, Packet, PacketOf, for_each_lane};
use crate::accel::packet16::{LANES16, Packet16};
use crate::accel::single::traverse_with;
use crate::accel::stream::Stream;
use crate::core::math::Ray;

/// Most triangles in a mesh BVH leaf: one block of eight, tested in one
/// 8-wide pass on the AVX2 path ([`WatertightRay::intersect8`]). Leaves
/// of eight rather than four halve the nodes (anchors 100k: 11,400 ->
/// 5,800, which then fit a 2 MB L2) and take about one node visit off
/// each ray, for the same number of leaf visits.
pub const LEAF_TRIANGLES: u32 = 8;

/// Re-exported: the structure a mesh is built with.
pub use crate::core::settings::Accel;
use crate::geometry::triangle::{LeafFrame, Shears16, Tri8};

/// A packet's leaf visit by at least this many lanes that share an origin
/// and permutation computes the leaf's [`LeafFrame`] once for them.
const FRAME_LANES: u32 = 2;

/// A leaf visit of a packet of 16 by at least this many lanes that share
/// a frame tests each triangle against all of them side by side
/// ([`WatertightRay::intersect8_lanes16`]); fewer lanes test the leaf's
/// eight triangles side by side one lane at a time
/// ([`WatertightRay::intersect8_framed`]). On the anchors' camera rays
/// (one thread, AVX-512) a threshold of 2 / 4 / 7 / 10 / 12 / 14 / 17 gave
/// 15.9 / 16.1 / 16.2 / 16.2 / 16.2 / 16.4 / 13.8 Mrays/s on 100k
/// triangles and 10.3 / 10.1 / 11.2 / 11.5 / 11.6 / 11.6 / 11.1 on 1M.
const SIDE_BY_SIDE_LANES: u32 = 12;
/// Re-exported: the triangle test meshes use.
pub use crate::geometry::triangle::WatertightRay;

/// How a mesh's shading normal is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NormalMode {
    /// The triangle's geometric normal everywhere.
    Flat,
    /// Vertex normals interpolated with barycentric coordinates (computed
    /// as area-weighted averages when the input has none).
    #[default]
    Smooth,
}

/// Raw mesh input, as read by a loader.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Optional vertex normals (same length as `positions`).
    pub normals: Option<Vec<Vec3>>,
    /// Optional texture coordinates (same length as `positions`).
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex index triples.
    pub indices: Vec<[u32; 3]>,
}

/// The structure of a [`Mesh`] other than its BVH.
#[derive(Debug)]
enum Structure {
    /// [`Mesh::bvh`] (empty otherwise).
    Bvh,
    Grid(Grid),
    KdTree(KdTree),
    Brute,
}

/// A triangle mesh in object space, with an acceleration structure over
/// its triangles ([`Accel`]: the BVH by default).
///
/// With the BVH, triangles are stored in BVH leaf order so traversal reads
/// them without an indirection (each leaf's in input order); otherwise in
/// input order. [`MeshHit::triangle`] indexes that order and
/// [`Mesh::input_triangle`] maps it back to the input.
///
/// **Closest hit, equal `t`.** Every structure and brute force return the
/// hit of smallest `t`; of several hits with the same `t` (a ray through a
/// shared edge or vertex of coplanar triangles, which the watertight test
/// gives to each of them), the one of lowest *input* triangle index. So
/// all structures report the same triangle, bit for bit.
#[derive(Debug)]
pub struct Mesh {
    /// Name for messages.
    pub name: String,
    positions: Vec<Vec3A>,
    normals: Option<Vec<Vec3A>>,
    uvs: Option<Vec<Vec2>>,
    /// Optional vertex tangents for normal maps: `xyz` the unit tangent
    /// (direction of increasing `u`), `w` = ±1 the handedness of the
    /// bitangent `w * cross(normal, tangent)` (glTF's `TANGENT`).
    tangents: Option<Vec<Vec4>>,
    /// Vertex indices, in BVH order.
    triangles: Vec<[u32; 3]>,
    /// Vertex positions per triangle, in BVH order.
    corners: Vec<[Vec3A; 3]>,
    bvh: Bvh8,
    /// The triangles of each BVH leaf side by side (leaf `i` holds
    /// triangles `bvh.leaves[i].first ..` in BVH order).
    blocks: Vec<Tri8>,
    bounds: (Vec3A, Vec3A),
    structure: Structure,
    /// Seconds spent building the acceleration structure.
    pub build_seconds: f64,
}

/// A ray-mesh intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshHit {
    /// Ray parameter.
    pub t: f32,
    /// Triangle index in BVH order.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub b1: f32,
    /// Barycentric weight of the third vertex.
    pub b2: f32,
}

/// Surface attributes at a mesh hit, in object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshSurface {
    /// Hit point in object space, interpolated from the triangle's
    /// vertices: correct to a few ulps of its own coordinates, whereas
    /// `ray.at(t)` carries the rounding of the ray's origin.
    pub point: Vec3A,
    /// Geometric normal (unnormalised, by winding order).
    pub geometric_normal: Vec3A,
    /// Shading normal (unnormalised; equals the geometric one for flat meshes).
    pub shading_normal: Vec3A,
    /// Texture coordinates (zero when the mesh has none).
    pub uv: Vec2,
    /// Interpolated tangent (`xyz`, unnormalised) and handedness (`w`),
    /// when the mesh has tangents ([`Mesh::with_tangents`]).
    pub tangent: Option<Vec4>,
}

impl Mesh {
    /// Validates `data` and builds the mesh and its BVH.
    ///
    /// Errors name the problem: non-finite positions, normals or uvs,
    /// attribute arrays of the wrong length, or indices out of range.
    /// Degenerate (zero-area) triangles are kept: they can never be hit.
    pub fn new(
        name: impl Into<String>,
        data: MeshData,
        mode: NormalMode,
        quality: BuildQuality,
    ) -> Result<Self, String> {
        Self::with_accel(name, data, mode, quality, Accel::Bvh)
    }

    /// [`Mesh::new`] with the structure `accel` instead of the BVH
    /// (`quality` applies to the BVH only). No other structure is built.
    pub fn with_accel(
        name: impl Into<String>,
        data: MeshData,
        mode: NormalMode,
        quality: BuildQuality,
        accel: Accel,
    ) -> Result<Self, String> {
        let mut phases = crate::accel::bvh8::Phases::start();
        let name = name.into();
        let n = data.positions.len();
        if let Some(i) = data.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a non-finite position"));
        }
        if let Some(i) = data
            .positions
            .iter()
            .position(|p| p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(format!(
                "vertex {i} lies farther than {MAX_COORDINATE:e} from the origin"
            ));
        }
        if let Some(normals) = &data.normals {
            if normals.len() != n {
                return Err(format!("{} normals for {} vertices", normals.len(), n));
            }
            if let Some(i) = normals.iter().position(|p| !p.is_finite()) {
                return Err(format!("vertex {i} has a non-finite normal"));
            }
        }
        if let Some(uvs) = &data.uvs {
            if uvs.len() != n {
                return Err(format!(
                    "{} texture coordinates for {} vertices",
                    uvs.len(),
                    n
                ));
            }
            if let Some(i) = uvs.iter().position(|p| !p.is_finite()) {
                return Err(format!("vertex {i} has non-finite texture coordinates"));
            }
        }
        if let Some((i, t)) = data
            .indices
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= n))
        {
            return Err(format!(
                "triangle {i} uses vertex index {} but there are only {n} vertices",
                t.iter().max().unwrap()
            ));
        }
        let positions: Vec<Vec3A> = data.positions.iter().map(|&p| p.into()).collect();
        let normals = match mode {
            NormalMode::Flat => None,
            NormalMode::Smooth => Some(match data.normals {
                Some(ns) => ns
                    .into_iter()
                    .map(|n| Vec3A::from(n).normalize_or_zero())
                    .collect(),
                None => vertex_normals(&positions, &data.indices),
            }),
        };

        phases.lap("validate");
        let start = Instant::now();
        let bvh = if accel == Accel::Bvh {
            // The per-triangle passes run on the worker threads, like the build.
            let boxes: Vec<Aabb> = data
                .indices
                .par_iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| positions[i as usize]);
                    padded_aabb(a.min(b).min(c), a.max(b).max(c))
                })
                .collect();
            phases.lap("boxes");
            // Each leaf's triangles come in input order: of equal-t hits in
            // one leaf block the first lane, hence the lowest input index,
            // wins.
            let bvh = Bvh8::build(&boxes, quality.mesh_params(), LEAF_TRIANGLES);
            phases.lap("bvh8");
            MESH_BVH_BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            bvh
        } else {
            Bvh8 {
                prims: (0..data.indices.len() as u32).collect(),
                ..Bvh8::default()
            }
        };
        let triangles: Vec<[u32; 3]> = bvh
            .prims
            .par_iter()
            .map(|&i| data.indices[i as usize])
            .collect();
        let corners: Vec<[Vec3A; 3]> = triangles
            .par_iter()
            .map(|t| t.map(|i| positions[i as usize]))
            .collect();
        // One block per leaf: its triangles side by side.
        // (An indexed collect: one allocation, filled by the workers.)
        let blocks: Vec<Tri8> = bvh
            .leaves
            .par_iter()
            .map(|l| {
                let (first, count) = (l.first as usize, l.count as usize);
                Tri8::new(&corners[first..first + count], l.first)
            })
            .collect();
        phases.lap("triangles, corners, blocks");
        let structure = match accel {
            Accel::Bvh => Structure::Bvh,
            Accel::Grid => Structure::Grid(Grid::build(
                &corners
                    .iter()
                    .map(|[a, b, c]| (a.min(*b).min(*c), a.max(*b).max(*c)))
                    .collect::<Vec<_>>(),
            )),
            Accel::Kdtree => Structure::KdTree(KdTree::build(&corners)),
            Accel::Brute => Structure::Brute,
        };
        let build_seconds = start.elapsed().as_secs_f64();
        phases.lap("structure");
        let mut lo = Vec3A::splat(f32::INFINITY);
        let mut hi = Vec3A::splat(f32::NEG_INFINITY);
        for t in &triangles {
            for &i in t {
                lo = lo.min(positions[i as usize]);
                hi = hi.max(positions[i as usize]);
            }
        }
        Ok(Self {
            name,
            positions,
            normals,
            uvs: data.uvs,
            tangents: None,
            triangles,
            corners,
            bvh,
            blocks,
            bounds: (lo, hi),
            structure,
            build_seconds,
        })
        .inspect(|_| phases.lap("bounds"))
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Object-space bounds, or `None` for a mesh without triangles.
    pub fn bounds(&self) -> Option<(Vec3A, Vec3A)> {
        (!self.triangles.is_empty()).then_some(self.bounds)
    }

    /// Vertex positions of triangle `i` (BVH order).
    pub fn triangle(&self, i: usize) -> [Vec3A; 3] {
        self.corners[i]
    }

    /// The triangles as the leaf tests read them, one [`Tri8`] block per
    /// BVH leaf (every triangle in exactly one), when the mesh has a BVH.
    #[inline]
    pub(crate) fn leaf_blocks(&self) -> Option<&[Tri8]> {
        matches!(self.structure, Structure::Bvh).then_some(&self.blocks[..])
    }

    /// True when the BVH is one leaf (at most eight triangles, as the
    /// quads and panels of simple scenes are). Single rays then test its
    /// triangles at once instead of traversing: the traversal would only
    /// add the test of the leaf's box, which is conservative (padded, see
    /// `padded_aabb`), so it never rejects a ray that hits a triangle and
    /// the hits are the same bit for bit. Skipping it saves the
    /// traversal's setup, about a third of the cost of a visit to such a
    /// mesh instance (callgrind, glTF Cornell box: 19 instances of two
    /// triangles). Packets of rays that share no origin do the same, lane
    /// by lane.
    #[inline(always)]
    pub fn single_leaf(&self) -> bool {
        self.bvh.leaves.len() == 1
    }

    /// The nearest hit in leaf `leaf` inside `(t_min, t_max)`.
    #[inline(always)]
    fn leaf_hit<const AVX: bool>(
        &self,
        wt: &WatertightRay,
        leaf: u32,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        // The count from the small leaf array (`block.count`, which sits
        // at the block's end): known before the block arrives.
        let count = self.bvh.leaves[leaf as usize].count;
        self.leaf_hit_of::<AVX>(wt, leaf, count, t_min, t_max)
    }

    /// [`Self::leaf_hit`] of a leaf of `count` triangles (from its
    /// reference: see [`crate::accel::bvh8::leaf_count`]).
    #[inline(always)]
    fn leaf_hit_of<const AVX: bool>(
        &self,
        wt: &WatertightRay,
        leaf: u32,
        count: u32,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        let block = &self.blocks[leaf as usize];
        let (lane, t, b1, b2) = wt.intersect8::<AVX>(block, count, t_min, t_max)?;
        Some(MeshHit {
            t,
            triangle: block.first + lane,
            b1,
            b2,
        })
    }

    /// [`Self::leaf_hit`] with a [`LeafFrame`] of the leaf made by a ray
    /// that [`WatertightRay::shares_frame`] with `wt`: the same hit.
    #[inline(always)]
    fn leaf_hit_framed<const AVX: bool>(
        &self,
        wt: &WatertightRay,
        frame: &LeafFrame,
        leaf: u32,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        let block = &self.blocks[leaf as usize];
        let (lane, t, b1, b2) =
            wt.intersect8_framed::<AVX>(frame, block, block.count, t_min, t_max)?;
        Some(MeshHit {
            t,
            triangle: block.first + lane,
            b1,
            b2,
        })
    }

    /// The [`LeafFrame`] of leaf `leaf` for rays sharing `wt`'s origin and
    /// permutation.
    #[inline(always)]
    fn leaf_frame<const AVX: bool>(&self, wt: &WatertightRay, leaf: u32) -> LeafFrame {
        let block = &self.blocks[leaf as usize];
        wt.frame8::<AVX>(block, block.count)
    }

    /// The lanes of `lanes` whose rays share a [`LeafFrame`] with the
    /// lowest one (`lanes` non-empty), and that lane.
    #[inline(always)]
    fn frame_lanes(wt: &[WatertightRay; LANES], lanes: LaneMask) -> (LaneMask, usize) {
        let lead = lanes.trailing_zeros() as usize;
        // Rays from scattered points (bounces) fail on the second lane:
        // one comparison per packet.
        let second = lanes & (lanes - 1);
        if second == 0 || !wt[second.trailing_zeros() as usize].shares_frame(&wt[lead]) {
            return (1 << lead, lead);
        }
        let mut shared = 0;
        for_each_lane(
            lanes,
            #[inline(always)]
            |l| shared |= (wt[l].shares_frame(&wt[lead]) as LaneMask) << l,
        );
        (shared, lead)
    }

    /// Starts loading what [`Mesh::surface`] reads first for `triangle`
    /// (its vertex indices and corners), called when a leaf test finds a
    /// nearer hit: the traversal goes on for a while before the closest
    /// hit's surface is evaluated, and for incoherent rays on large meshes
    /// those two loads were most of `surface`'s time (`perf annotate` on
    /// `assets/bench/glass_mirror.toml`: 65% of its samples on them).
    #[inline(always)]
    fn prefetch_surface(&self, triangle: u32) {
        let i = triangle as usize;
        if let (Some(t), Some(c)) = (self.triangles.get(i), self.corners.get(i)) {
            // Either may straddle two cache lines: its first and last
            // elements name both.
            crate::accel::single::prefetch_bytes(&t[0], 1);
            crate::accel::single::prefetch_bytes(&t[2], 1);
            crate::accel::single::prefetch_bytes(&c[0], 1);
            crate::accel::single::prefetch_bytes(&c[2], 1);
        }
    }

    /// Starts loading the triangle block of leaf `leaf`.
    #[inline(always)]
    fn prefetch_leaf(&self, leaf: u32) {
        crate::accel::single::prefetch_bytes(
            &self.blocks[leaf as usize],
            std::mem::size_of::<Tri8>(),
        );
    }

    /// The structure the mesh was built with.
    pub fn accel(&self) -> Accel {
        match self.structure {
            Structure::Bvh => Accel::Bvh,
            Structure::Grid(_) => Accel::Grid,
            Structure::KdTree(_) => Accel::Kdtree,
            Structure::Brute => Accel::Brute,
        }
    }

    /// The grid, when built with [`Accel::Grid`].
    pub fn grid(&self) -> Option<&Grid> {
        match &self.structure {
            Structure::Grid(g) => Some(g),
            _ => None,
        }
    }

    /// The kd-tree, when built with [`Accel::Kdtree`].
    pub fn kdtree(&self) -> Option<&KdTree> {
        match &self.structure {
            Structure::KdTree(k) => Some(k),
            _ => None,
        }
    }

    /// The BVH (empty unless built with [`Accel::Bvh`]).
    pub fn bvh(&self) -> &Bvh8 {
        &self.bvh
    }

    /// Bytes of the acceleration structure: nodes, leaves and triangle
    /// blocks for the BVH, cells or nodes and triangle lists for the
    /// others (the triangles themselves not counted).
    pub fn accel_bytes(&self) -> usize {
        use std::mem::size_of;
        match &self.structure {
            Structure::Bvh => {
                self.bvh.nodes.len() * size_of::<crate::accel::bvh8::Node8>()
                    + self.bvh.leaves.len() * size_of::<crate::accel::bvh8::Leaf>()
                    + self.bvh.prims.len() * 4
                    + self.blocks.len() * size_of::<Tri8>()
            }
            Structure::Grid(g) => g.bytes(),
            Structure::KdTree(k) => k.bytes(),
            Structure::Brute => 0,
        }
    }

    /// True if a hit on triangle `tri` at `t` replaces `best`: nearer, or
    /// as near with a lower input index.
    #[inline(always)]
    fn wins(&self, t: f32, tri: u32, best: &Option<MeshHit>) -> bool {
        match best {
            None => true,
            Some(b) => {
                t < b.t
                    || (t == b.t
                        && self.bvh.prims[tri as usize] < self.bvh.prims[b.triangle as usize])
            }
        }
    }

    /// The upper end of the search for a triangle that may still replace
    /// `best` when the search is bounded by `t_max`: one ulp more once a
    /// hit is known, so that an equal `t` is found and can win on index.
    #[inline(always)]
    fn reach(t_max: f32, best: &Option<MeshHit>) -> f32 {
        if best.is_some() {
            t_max.next_up()
        } else {
            t_max
        }
    }

    /// Triangle `i` (stored order) if it replaces `best`.
    #[inline(always)]
    fn test_one(
        &self,
        wt: &WatertightRay,
        i: u32,
        t_min: f32,
        t_max: f32,
        best: &mut Option<MeshHit>,
    ) -> Option<f32> {
        let [p0, p1, p2] = self.corners[i as usize];
        let (t, b1, b2) = wt.intersect(p0, p1, p2, t_min, Self::reach(t_max, best))?;
        if !self.wins(t, i, best) {
            return None;
        }
        *best = Some(MeshHit {
            t,
            triangle: i,
            b1,
            b2,
        });
        Some(t)
    }

    crate::simd_outlined! {
        /// [`Mesh::intersect_kernel`] out of line, for rays traced one by
        /// one inside a larger query.
        pub(crate) fn intersect_outlined(&self, ray: &Ray, t_min: f32, t_max: f32)
            -> Option<MeshHit> => Mesh, intersect_kernel
    }

    crate::simd_outlined! {
        /// [`Mesh::intersect_for_surface_kernel`] out of line.
        pub(crate) fn intersect_for_surface_outlined(&self, ray: &Ray, t_min: f32, t_max: f32)
            -> Option<MeshHit> => Mesh, intersect_for_surface_kernel
    }

    crate::simd_outlined! {
        /// [`Mesh::occluded_kernel`] out of line.
        pub(crate) fn occluded_outlined(&self, ray: &Ray, t_min: f32, t_max: f32)
            -> bool => Mesh, occluded_kernel
    }

    /// [`Mesh::occluded_kernel`] for one lane of a packet query: a mesh of
    /// one leaf tests it inline, any other goes out of line
    /// ([`Mesh::occluded_outlined`]).
    #[inline(always)]
    pub(crate) fn occluded_lane<const AVX: bool>(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        if matches!(self.structure, Structure::Bvh) && self.single_leaf() {
            self.leaf_hit::<AVX>(&WatertightRay::new(ray), 0, t_min, t_max)
                .is_some()
        } else {
            self.occluded_outlined::<AVX>(ray, t_min, t_max)
        }
    }

    /// Closest hit with `t` in `(t_min, t_max)`.
    #[inline(always)]
    pub(crate) fn intersect_kernel<const AVX: bool>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        self.intersect_kernel_with::<AVX, false>(ray, t_min, t_max)
    }

    /// [`Mesh::intersect_kernel`] for a caller that evaluates the hit's
    /// [`Mesh::surface`] next (the scene's closest-hit queries): each
    /// nearer hit found starts loading what the surface reads
    /// ([`Mesh::prefetch_surface`]). Queries that only want the hit (the
    /// ray-file benchmark) do without: on the 100k-triangle workload the
    /// prefetches cost 4% of the bounce rays' throughput, while in a render
    /// they took 5% off `glass_mirror`'s time.
    #[inline(always)]
    pub(crate) fn intersect_for_surface_kernel<const AVX: bool>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        self.intersect_kernel_with::<AVX, true>(ray, t_min, t_max)
    }

    #[inline(always)]
    fn intersect_kernel_with<const AVX: bool, const SURFACE: bool>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<MeshHit> {
        let wt = WatertightRay::new(ray);
        let mut best: Option<MeshHit> = None;
        match &self.structure {
            Structure::Bvh if self.single_leaf() => {
                return self.leaf_hit::<AVX>(&wt, 0, t_min, t_max);
            }
            Structure::Bvh => {
                traverse_with::<AVX>(
                    &self.bvh,
                    ray,
                    t_min,
                    t_max,
                    false,
                    #[inline(always)]
                    |leaf, count, t_max| {
                        let hit = self.leaf_hit_of::<AVX>(
                            &wt,
                            leaf,
                            count,
                            t_min,
                            Self::reach(t_max, &best),
                        )?;
                        if !self.wins(hit.t, hit.triangle, &best) {
                            return None;
                        }
                        if SURFACE {
                            self.prefetch_surface(hit.triangle);
                        }
                        best = Some(hit);
                        Some(hit.t)
                    },
                    |leaf| self.prefetch_leaf(leaf),
                );
            }
            Structure::Grid(g) => {
                g.traverse(ray, t_min, t_max, false, |i, t_max| {
                    self.test_one(&wt, i, t_min, t_max, &mut best)
                });
            }
            Structure::KdTree(k) => {
                k.traverse(ray, t_min, t_max, false, |i, t_max| {
                    self.test_one(&wt, i, t_min, t_max, &mut best)
                });
            }
            Structure::Brute => return self.intersect_brute_force(ray, t_min, t_max),
        }
        best
    }

    /// Closest hits for the lanes of `packet` in `lanes` (rays in object
    /// space), by packet traversal: `best[l]` is replaced when lane `l`
    /// finds a nearer hit than `packet.t_max[l]`, which is shrunk to it.
    #[inline(always)]
    pub(crate) fn intersect_packet_kernel<const AVX: bool>(
        &self,
        packet: &mut Packet,
        lanes: LaneMask,
        best: &mut [Option<MeshHit>; LANES],
    ) {
        if !matches!(self.structure, Structure::Bvh) {
            for_each_lane(
                lanes,
                #[inline(always)]
                |l| {
                    if let Some(h) = self.intersect_outlined::<AVX>(
                        &packet.rays[l],
                        packet.t_min[l],
                        packet.t_max[l],
                    ) {
                        packet.t_max[l] = h.t;
                        best[l] = Some(h);
                    }
                },
            );
            return;
        }
        let wt = watertight_lanes(packet);
        let lanes = lanes & packet.valid;
        if lanes == 0 {
            return;
        }
        // Lanes that share one origin and permutation (a pinhole's camera
        // rays) test a leaf from one frame of it.
        let (shared, lead) = Self::frame_lanes(&wt, lanes);
        if self.single_leaf() && shared.count_ones() < FRAME_LANES {
            self.leaf_lanes::<AVX, LANES>(&wt, packet, lanes, 0, best);
            return;
        }
        crate::accel::packet::traverse::<AVX, true>(
            &self.bvh,
            packet,
            lanes,
            #[inline(always)]
            |p, hit, leaf| {
                let framed = hit & shared;
                let hit = if framed.count_ones() >= FRAME_LANES {
                    let frame = self.leaf_frame::<AVX>(&wt[lead], leaf);
                    for_each_lane(
                        framed,
                        #[inline(always)]
                        |l| {
                            let reach = Self::reach(p.t_max[l], &best[l]);
                            if let Some(h) =
                                self.leaf_hit_framed::<AVX>(&wt[l], &frame, leaf, p.t_min[l], reach)
                                && self.wins(h.t, h.triangle, &best[l])
                            {
                                p.t_max[l] = h.t;
                                best[l] = Some(h);
                            }
                        },
                    );
                    hit & !framed
                } else {
                    hit
                };
                self.leaf_lanes::<AVX, _>(&wt, p, hit, leaf, best);
                0
            },
        );
    }

    /// [`Self::intersect_packet_kernel`] for packets of 16
    /// ([`crate::accel::packet16`]). Lanes that share an origin and
    /// permutation with the packet's first (a pinhole's camera rays) test
    /// a leaf together, triangle by triangle across the lanes
    /// ([`WatertightRay::intersect8_lanes16`]); the others lane by lane.
    /// Either way each lane gets the hit [`Self::intersect`] gives it.
    #[inline(always)]
    pub(crate) fn intersect_packet16_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        packet: &mut Packet16,
        lanes: LaneMask,
        best: &mut [Option<MeshHit>; LANES16],
    ) {
        let lanes = lanes & packet.valid;
        if !matches!(self.structure, Structure::Bvh) {
            for_each_lane(
                lanes,
                #[inline(always)]
                |l| {
                    if let Some(h) = self.intersect_outlined::<AVX>(
                        &packet.rays[l],
                        packet.t_min[l],
                        packet.t_max[l],
                    ) {
                        packet.t_max[l] = h.t;
                        best[l] = Some(h);
                    }
                },
            );
            return;
        }
        if lanes == 0 {
            return;
        }
        let wt = watertight_lanes(packet);
        let lead = lanes.trailing_zeros() as usize;
        let mut shared = 0;
        for (l, w) in wt.iter().enumerate() {
            shared |= (w.shares_frame(&wt[lead]) as LaneMask) << l;
        }
        let shared = shared & lanes;
        if self.single_leaf() && shared.count_ones() < FRAME_LANES {
            self.leaf_lanes::<AVX, LANES16>(&wt, packet, lanes, 0, best);
            return;
        }
        let shears = Shears16::new(&wt);
        crate::accel::packet16::traverse16::<AVX, AVX512>(
            &self.bvh,
            packet,
            lanes,
            #[inline(always)]
            |p, hit, leaf| {
                let framed = hit & shared;
                let hit = if framed.count_ones() >= FRAME_LANES {
                    let block = &self.blocks[leaf as usize];
                    let count = block.count;
                    let frame = wt[lead].frame8::<AVX>(block, count);
                    // Each lane searches up to its reach (one ulp past a
                    // known hit, so an equal `t` can win on index), then
                    // its leaf hit must win against what it had.
                    let mut reach = p.t_max;
                    for_each_lane(
                        framed,
                        #[inline(always)]
                        |l| reach[l] = Self::reach(p.t_max[l], &best[l]),
                    );
                    if framed.count_ones() < SIDE_BY_SIDE_LANES {
                        for_each_lane(
                            framed,
                            #[inline(always)]
                            |l| {
                                if let Some(h) = self.leaf_hit_framed::<AVX>(
                                    &wt[l], &frame, leaf, p.t_min[l], reach[l],
                                ) && self.wins(h.t, h.triangle, &best[l])
                                {
                                    p.t_max[l] = h.t;
                                    best[l] = Some(h);
                                }
                            },
                        );
                        self.leaf_lanes::<AVX, _>(&wt, p, hit & !framed, leaf, best);
                        return 0;
                    }
                    let mut out = [(0, 0.0, 0.0, 0.0); LANES16];
                    let found = WatertightRay::intersect8_lanes16::<AVX512>(
                        &wt, &shears, &frame, block, count, framed, &p.t_min, &mut reach, &mut out,
                    );
                    for_each_lane(
                        found,
                        #[inline(always)]
                        |l| {
                            let (lane, t, b1, b2) = out[l];
                            let h = MeshHit {
                                t,
                                triangle: block.first + lane,
                                b1,
                                b2,
                            };
                            if self.wins(h.t, h.triangle, &best[l]) {
                                p.t_max[l] = h.t;
                                best[l] = Some(h);
                            }
                        },
                    );
                    hit & !framed
                } else {
                    hit
                };
                self.leaf_lanes::<AVX, _>(&wt, p, hit, leaf, best);
                0
            },
        );
    }

    /// Leaf `leaf` tested by each lane of `packet` in `lanes` alone (the
    /// single-ray leaf test): a lane's hit replaces `best[l]` and shrinks
    /// its `t_max` when it wins. The packet kernels use it for lanes that
    /// share no leaf frame, and for a mesh whose BVH is one leaf (leaf 0)
    /// when no lanes do: those skip the packet traversal's set-up (the
    /// lanes' node rays, the root's test) as [`Mesh::intersect`] does,
    /// since the leaf's padded box could not reject a hit. On
    /// `assets/prism.toml` (an eight-triangle prism) that took the
    /// wavefront's time to 0.8x.
    #[inline(always)]
    fn leaf_lanes<const AVX: bool, const N: usize>(
        &self,
        wt: &[WatertightRay; N],
        packet: &mut PacketOf<N>,
        lanes: LaneMask,
        leaf: u32,
        best: &mut [Option<MeshHit>; N],
    ) {
        for_each_lane(
            lanes,
            #[inline(always)]
            |l| {
                let reach = Self::reach(packet.t_max[l], &best[l]);
                if let Some(h) = self.leaf_hit::<AVX>(&wt[l], leaf, packet.t_min[l], reach)
                    && self.wins(h.t, h.triangle, &best[l])
                {
                    packet.t_max[l] = h.t;
                    best[l] = Some(h);
                }
            },
        );
    }

    /// The lanes of `packet` in `lanes` blocked within their intervals,
    /// each traced alone (structures other than the BVH).
    #[inline(always)]
    fn occluded_lane_by_lane<const AVX: bool, const N: usize>(
        &self,
        packet: &PacketOf<N>,
        lanes: LaneMask,
    ) -> LaneMask {
        let mut blocked = 0;
        for_each_lane(
            lanes,
            #[inline(always)]
            |l| {
                if self.occluded_outlined::<AVX>(&packet.rays[l], packet.t_min[l], packet.t_max[l])
                {
                    blocked |= 1 << l;
                }
            },
        );
        blocked
    }

    /// The lanes in `lanes` that hit a triangle of leaf `leaf` within
    /// their intervals in `p`, each tested with the single-ray leaf test.
    #[inline(always)]
    fn leaf_blocked_lanes<const AVX: bool, const N: usize>(
        &self,
        wt: &[WatertightRay; N],
        p: &PacketOf<N>,
        lanes: LaneMask,
        leaf: u32,
    ) -> LaneMask {
        let mut blocked = 0;
        for_each_lane(
            lanes,
            #[inline(always)]
            |l| {
                if self
                    .leaf_hit::<AVX>(&wt[l], leaf, p.t_min[l], p.t_max[l])
                    .is_some()
                {
                    blocked |= 1 << l;
                }
            },
        );
        blocked
    }

    /// The lanes of `packet` in `lanes` that hit any triangle within their
    /// intervals; each lane stops at its first blocker.
    #[inline(always)]
    pub(crate) fn occluded_packet_kernel<const AVX: bool>(
        &self,
        packet: &mut Packet,
        lanes: LaneMask,
    ) -> LaneMask {
        if !matches!(self.structure, Structure::Bvh) {
            return self.occluded_lane_by_lane::<AVX, _>(packet, lanes);
        }
        let wt = watertight_lanes(packet);
        let lanes = lanes & packet.valid;
        if lanes == 0 {
            return 0;
        }
        let (shared, lead) = Self::frame_lanes(&wt, lanes);
        let mut blocked = 0;
        crate::accel::packet::traverse::<AVX, false>(
            &self.bvh,
            packet,
            lanes,
            #[inline(always)]
            |p, hit, leaf| {
                let mut now = 0;
                let framed = hit & shared;
                let rest = if framed.count_ones() >= FRAME_LANES {
                    let frame = self.leaf_frame::<AVX>(&wt[lead], leaf);
                    for_each_lane(
                        framed,
                        #[inline(always)]
                        |l| {
                            if self
                                .leaf_hit_framed::<AVX>(
                                    &wt[l], &frame, leaf, p.t_min[l], p.t_max[l],
                                )
                                .is_some()
                            {
                                now |= 1 << l;
                            }
                        },
                    );
                    hit & !framed
                } else {
                    hit
                };
                now |= self.leaf_blocked_lanes::<AVX, _>(&wt, p, rest, leaf);
                blocked |= now;
                now
            },
        );
        blocked
    }

    /// [`Self::occluded_packet_kernel`] for packets of 16
    /// ([`crate::accel::packet16`]): the lanes of `packet` in `lanes` that
    /// hit any triangle within their intervals, each lane's leaves tested
    /// with the single-ray kernel (shadow rays from different points share
    /// no frame).
    #[inline(always)]
    pub(crate) fn occluded_packet16_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        packet: &mut Packet16,
        lanes: LaneMask,
    ) -> LaneMask {
        let lanes = lanes & packet.valid;
        if !matches!(self.structure, Structure::Bvh) {
            return self.occluded_lane_by_lane::<AVX, _>(packet, lanes);
        }
        if lanes == 0 {
            return 0;
        }
        let wt = watertight_lanes(packet);
        let mut blocked = 0;
        crate::accel::packet16::traverse16::<AVX, AVX512>(
            &self.bvh,
            packet,
            lanes,
            #[inline(always)]
            |p, hit, leaf| {
                let now = self.leaf_blocked_lanes::<AVX, _>(&wt, p, hit, leaf);
                blocked |= now;
                now
            },
        );
        blocked
    }

    /// Closest hits of every ray of `stream` (object space), by stream
    /// traversal ([`crate::accel::stream`]): `best[i]` is ray `i`'s nearest hit
    /// inside its interval, as [`Mesh::intersect`] finds it. `wt` is a
    /// reusable buffer.
    #[inline(always)]
    pub(crate) fn intersect_stream_kernel<const AVX: bool>(
        &self,
        stream: &mut Stream,
        wt: &mut Vec<WatertightRay>,
        best: &mut Vec<Option<MeshHit>>,
    ) {
        wt.clear();
        best.clear();
        best.resize(stream.len(), None);
        if !matches!(self.structure, Structure::Bvh) {
            for (r, b) in best.iter_mut().enumerate() {
                *b = self.intersect_outlined::<AVX>(
                    &stream.rays[r],
                    stream.t_min[r],
                    stream.t_max[r],
                );
            }
            return;
        }
        wt.extend(stream.rays.iter().map(WatertightRay::new));
        crate::accel::stream::traverse::<AVX>(
            &self.bvh,
            stream,
            #[inline(always)]
            |leaf, ids, s| {
                for &r in ids {
                    let r = r as usize;
                    let reach = Self::reach(s.t_max[r], &best[r]);
                    if let Some(h) = self.leaf_hit::<AVX>(&wt[r], leaf, s.t_min[r], reach)
                        && self.wins(h.t, h.triangle, &best[r])
                    {
                        s.t_max[r] = h.t;
                        best[r] = Some(h);
                    }
                }
            },
        );
    }

    crate::simd_entry! {
        /// Closest hit with `t` in `(t_min, t_max)`.
        pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<MeshHit>
            => Mesh, intersect_kernel
    }

    crate::simd_entry! {
        /// True if any triangle is hit with `t` in `(t_min, t_max)`; stops at
        /// the first one found.
        pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool
            => Mesh, occluded_kernel
    }

    crate::simd_entry! {
        /// Closest hits for the lanes of `packet` in `lanes` (rays in object
        /// space), by packet traversal: `best[l]` is replaced when lane `l`
        /// finds a nearer hit than `packet.t_max[l]`, which is shrunk to it.
        pub fn intersect_packet(
            &self,
            packet: &mut Packet,
            lanes: LaneMask,
            best: &mut [Option<MeshHit>; LANES],
        ) -> () => Mesh, intersect_packet_kernel
    }

    crate::simd_entry_wide! {
        /// Closest hits for the lanes of a packet of 16 (rays in object
        /// space), by packet traversal ([`crate::accel::packet16`]): as
        /// [`Self::intersect_packet`], `best[l]` is replaced when lane `l`
        /// finds a nearer hit than `packet.t_max[l]`, which is shrunk to
        /// it. Each lane gets the hit [`Self::intersect`] gives it, bit
        /// for bit, on every SIMD path.
        pub fn intersect_packet16(
            &self,
            packet: &mut Packet16,
            lanes: LaneMask,
            best: &mut [Option<MeshHit>; LANES16],
        ) -> () => Mesh, intersect_packet16_kernel
    }

    crate::simd_entry! {
        /// The lanes of `packet` in `lanes` that hit any triangle within their
        /// intervals; each lane stops at its first blocker.
        pub fn occluded_packet(&self, packet: &mut Packet, lanes: LaneMask) -> LaneMask
            => Mesh, occluded_packet_kernel
    }

    crate::simd_entry! {
        /// Closest hits of every ray of `stream` (object space), by stream
        /// traversal ([`crate::accel::stream`]): `best[i]` is ray `i`'s nearest
        /// hit inside its interval, as [`Mesh::intersect`] finds it. `wt` is a
        /// reusable buffer.
        pub fn intersect_stream(
            &self,
            stream: &mut Stream,
            wt: &mut Vec<WatertightRay>,
            best: &mut Vec<Option<MeshHit>>,
        ) -> () => Mesh, intersect_stream_kernel
    }

    /// The vertex indices of every triangle in input order: with
    /// [`Mesh::positions`], the mesh's input again (to rebuild it with
    /// another structure).
    pub fn input_indices(&self) -> Vec<[u32; 3]> {
        let mut out = vec![[0; 3]; self.triangles.len()];
        for (i, t) in self.triangles.iter().enumerate() {
            out[self.bvh.prims[i] as usize] = *t;
        }
        out
    }

    /// [`Mesh::input_indices`] with the positions, as loader input.
    pub fn input_data(&self) -> MeshData {
        MeshData {
            positions: self.positions.iter().map(|&p| p.into()).collect(),
            indices: self.input_indices(),
            ..MeshData::default()
        }
    }

    /// The position of triangle `i` (BVH order) in the input's indices.
    pub fn input_triangle(&self, i: usize) -> u32 {
        self.bvh.prims[i]
    }

    /// Closest hit by testing every triangle (equal `t` to the lowest
    /// input index): the reference for the structures' tests.
    pub fn intersect_brute_force(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<MeshHit> {
        let wt = WatertightRay::new(ray);
        let mut best = None;
        let mut bound = t_max;
        for i in 0..self.corners.len() as u32 {
            if let Some(t) = self.test_one(&wt, i, t_min, bound, &mut best) {
                bound = t;
            }
        }
        best
    }

    /// True if any triangle is hit with `t` in `(t_min, t_max)`; stops at
    /// the first one found.
    #[inline(always)]
    pub(crate) fn occluded_kernel<const AVX: bool>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> bool {
        let wt = WatertightRay::new(ray);
        let tri = |i: u32, t_max: f32| {
            let [p0, p1, p2] = self.corners[i as usize];
            wt.intersect(p0, p1, p2, t_min, t_max).map(|h| h.0)
        };
        match &self.structure {
            Structure::Bvh if self.single_leaf() => {
                self.leaf_hit::<AVX>(&wt, 0, t_min, t_max).is_some()
            }
            Structure::Bvh => traverse_with::<AVX>(
                &self.bvh,
                ray,
                t_min,
                t_max,
                true,
                #[inline(always)]
                |leaf, count, t_max| {
                    self.leaf_hit_of::<AVX>(&wt, leaf, count, t_min, t_max)
                        .map(|h| h.t)
                },
                |leaf| self.prefetch_leaf(leaf),
            ),
            Structure::Grid(g) => g.traverse(ray, t_min, t_max, true, tri),
            Structure::KdTree(k) => k.traverse(ray, t_min, t_max, true, tri),
            Structure::Brute => (0..self.corners.len() as u32).any(|i| tri(i, t_max).is_some()),
        }
    }

    /// The unnormalised object-space normal `(p1 - p0) x (p2 - p0)` of
    /// triangle `triangle` (BVH order): [`MeshSurface::geometric_normal`].
    #[inline(always)]
    pub fn geometric_normal(&self, triangle: u32) -> Vec3A {
        let [p0, p1, p2] = self.corners[triangle as usize];
        (p1 - p0).cross(p2 - p0)
    }

    /// Normals and texture coordinates at a hit.
    pub fn surface(&self, hit: &MeshHit) -> MeshSurface {
        let [i0, i1, i2] = self.triangles[hit.triangle as usize].map(|i| i as usize);
        let [p0, p1, p2] = self.corners[hit.triangle as usize];
        let b0 = 1.0 - hit.b1 - hit.b2;
        let geometric_normal = self.geometric_normal(hit.triangle);
        let shading_normal = match &self.normals {
            Some(ns) => {
                let n = ns[i0] * b0 + ns[i1] * hit.b1 + ns[i2] * hit.b2;
                if n.length_squared() > 0.0 {
                    n
                } else {
                    geometric_normal
                }
            }
            None => geometric_normal,
        };
        let uv = match &self.uvs {
            Some(uvs) => uvs[i0] * b0 + uvs[i1] * hit.b1 + uvs[i2] * hit.b2,
            None => Vec2::ZERO,
        };
        let tangent = self.tangents.as_ref().map(|ts| {
            let t = ts[i0] * b0 + ts[i1] * hit.b1 + ts[i2] * hit.b2;
            t.truncate().extend(ts[i0].w)
        });
        MeshSurface {
            point: p0 + (p1 - p0) * hit.b1 + (p2 - p0) * hit.b2,
            geometric_normal,
            shading_normal,
            uv,
            tangent,
        }
    }

    /// The derivatives `(dP/du, dP/dv)` of the surface point with respect
    /// to the texture coordinates over `triangle` (object space; texture
    /// level of detail), or `None` without texture coordinates or for a
    /// triangle whose texture coordinates are degenerate.
    pub fn uv_tangents(&self, triangle: u32) -> Option<(Vec3A, Vec3A)> {
        let uvs = self.uvs.as_ref()?;
        let [i0, i1, i2] = self.triangles[triangle as usize].map(|i| i as usize);
        let [p0, p1, p2] = self.corners[triangle as usize];
        let (e1, e2) = (p1 - p0, p2 - p0);
        let (d1, d2) = (uvs[i1] - uvs[i0], uvs[i2] - uvs[i0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        Some(((e1 * d2.y - e2 * d1.y) * inv, (e2 * d1.x - e1 * d2.x) * inv))
    }

    /// Adds vertex tangents for normal mapping: `given` (glTF `TANGENT`,
    /// one per vertex, checked: finite, `w` = ±1) or, when `None`, tangents
    /// generated from the texture coordinates: per triangle the direction
    /// of increasing `u` and the handedness of increasing `v`
    /// (`w = 1` when `cross(normal, tangent)` points towards decreasing
    /// `v`, glTF's "+Y up" normal maps with `v` growing downwards), summed
    /// over the triangles of each vertex weighted by their area, then made
    /// orthogonal to the vertex normal (Gram-Schmidt). This follows the
    /// construction MikkTSpace refines; it agrees with it on meshes whose
    /// texture mapping is smooth across triangles. A mesh without texture
    /// coordinates gets no tangents (normal maps cannot apply).
    pub fn with_tangents(mut self, given: Option<Vec<Vec4>>) -> Result<Self, String> {
        let n = self.positions.len();
        if let Some(ts) = given {
            if ts.len() != n {
                return Err(format!("{} tangents for {n} vertices", ts.len()));
            }
            if let Some(i) = ts.iter().position(|t| !t.is_finite()) {
                return Err(format!("vertex {i} has a non-finite tangent"));
            }
            self.tangents = Some(
                ts.into_iter()
                    .map(|t| {
                        let w = if t.w < 0.0 { -1.0 } else { 1.0 };
                        t.truncate().normalize_or_zero().extend(w)
                    })
                    .collect(),
            );
            return Ok(self);
        }
        let Some(uvs) = &self.uvs else {
            return Ok(self);
        };
        let mut tan = vec![Vec3A::ZERO; n];
        let mut bit = vec![Vec3A::ZERO; n];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| i as usize);
            let (e1, e2) = (
                self.positions[b] - self.positions[a],
                self.positions[c] - self.positions[a],
            );
            let (d1, d2) = (uvs[b] - uvs[a], uvs[c] - uvs[a]);
            let det = d1.x * d2.y - d2.x * d1.y;
            if det == 0.0 || !det.is_finite() {
                continue;
            }
            // dP/du and dP/dv times det; weighting by |det| (the uv area)
            // over the uv area's own scale leaves an area weight.
            let area = e1.cross(e2).length();
            let r = area / det.abs() * det.signum();
            let dpdu = (e1 * d2.y - e2 * d1.y) * r;
            let dpdv = (e2 * d1.x - e1 * d2.x) * r;
            for i in [a, b, c] {
                tan[i] += dpdu;
                bit[i] += dpdv;
            }
        }
        let normals = self
            .normals
            .clone()
            .unwrap_or_else(|| vertex_normals(&self.positions, &self.triangles));
        self.tangents = Some(
            (0..n)
                .map(|i| {
                    let nrm = normals[i];
                    let t = (tan[i] - nrm * nrm.dot(tan[i])).normalize_or_zero();
                    let w = if nrm.cross(t).dot(bit[i]) > 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    Vec3::from(t).extend(w)
                })
                .collect(),
        );
        Ok(self)
    }

    /// Positions of all vertices (object space).
    pub fn positions(&self) -> &[Vec3A] {
        &self.positions
    }

    /// Vertex indices of every triangle, in BVH order.
    pub fn triangle_indices(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}

/// Area-weighted vertex normals.
fn vertex_normals(positions: &[Vec3A], indices: &[[u32; 3]]) -> Vec<Vec3A> {
    let mut normals = vec![Vec3A::ZERO; positions.len()];
    for t in indices {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            normals[i as usize] += n;
        }
    }
    normals.iter().map(|n| n.normalize_or_zero()).collect()
}

static MESH_BVH_BUILDS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The watertight-test form of each lane's ray of `packet`
/// ([`WatertightRay::lanes`]).
#[inline(always)]
fn watertight_lanes<const N: usize>(packet: &PacketOf<N>) -> [WatertightRay; N] {
    WatertightRay::lanes(&packet.rays)
}

/// Number of mesh BVHs built by this process so far (one per successful
/// [`Mesh::new`]). Scene updates never build one: tests compare this
/// counter before and after.
pub fn mesh_bvh_builds() -> u64 {
    MESH_BVH_BUILDS.load(std::sync::atomic::Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::packet::ALL_LANES as ALL;

    /// Small triangles at geometrically growing distances along a line,
    /// from 1e-30 up: each triangle's nearest neighbour is the next
    /// smaller one, and the smallest share one Morton cell, so the builder
    /// chains them (150 triangles give a binary tree 58 levels deep, 15
    /// levels of 8-wide nodes where a balanced tree would need 3).
    fn deep_soup(n: u32) -> MeshData {
        let mut data = MeshData::default();
        for i in 0..n {
            let x = 1.5f32.powi(i as i32) * 1e-30;
            let s = 0.02 * x;
            let k = data.positions.len() as u32;
            data.positions.push(Vec3::new(x - s, -s, 0.0));
            data.positions.push(Vec3::new(x + s, -s, 0.0));
            data.positions.push(Vec3::new(x, s, 0.0));
            data.indices.push([k, k + 1, k + 2]);
        }
        data
    }

    /// Degenerate, chain-like trees, which only degenerate input produces:
    /// every traversal must find what brute force finds. This tree never
    /// has more than a few subtrees pending; the stack's spilling past its
    /// fixed part, which a deep tree with branching needs, is tested in
    /// `accel::single` directly.
    #[test]
    fn deep_trees_are_traversed_completely() {
        let mesh = Mesh::new(
            "soup",
            deep_soup(150),
            NormalMode::Flat,
            BuildQuality::Medium,
        )
        .unwrap();
        let depth = mesh.bvh.depth;
        assert!(
            depth > 12,
            "the soup must be deeper than 12 levels, got {depth}"
        );
        let mut rays = Vec::new();
        let mut s = 7u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        for i in 0..300 {
            // Straight down onto triangle i / 2, near its centre, or beside it.
            let x = 1.5f32.powi(i / 2) * 1e-30;
            let dx = (next() - 0.5) * 0.05 * x;
            let dy = (next() - 0.5) * 0.05 * x;
            let o = Vec3A::new(x + dx, dy, x);
            rays.push(Ray::new(o, Vec3A::new(0.0, 0.0, -1.0)));
        }
        let mut hits = 0;
        let mut stream = Stream::default();
        for r in &rays {
            stream.push(*r, 0.0, f32::INFINITY);
        }
        let (mut wt, mut best) = (Vec::new(), Vec::new());
        mesh.intersect_stream(&mut stream, &mut wt, &mut best);
        for (k, chunk) in rays.chunks(LANES).enumerate() {
            let mut packet = Packet::new(
                chunk,
                &vec![0.0; chunk.len()],
                &vec![f32::INFINITY; chunk.len()],
            );
            let mut packed = [None; LANES];
            let lanes = packet.valid;
            mesh.intersect_packet(&mut packet, lanes, &mut packed);
            for (l, r) in chunk.iter().enumerate() {
                let want = mesh.intersect_brute_force(r, 0.0, f32::INFINITY);
                hits += want.is_some() as u32;
                let t = |h: Option<MeshHit>| h.map(|h| h.t);
                assert_eq!(
                    t(mesh.intersect(r, 0.0, f32::INFINITY)),
                    t(want),
                    "single ray {}",
                    k * LANES + l
                );
                assert_eq!(t(packed[l]), t(want), "packet ray {}", k * LANES + l);
                assert_eq!(
                    t(best[k * LANES + l]),
                    t(want),
                    "stream ray {}",
                    k * LANES + l
                );
                assert_eq!(mesh.occluded(r, 0.0, f32::INFINITY), want.is_some());
            }
        }
        for (k, chunk) in rays.chunks(LANES16).enumerate() {
            let n = chunk.len();
            let mut packet = Packet16::new(chunk, &vec![0.0; n], &vec![f32::INFINITY; n]);
            let mut packed = [None; LANES16];
            let lanes = packet.valid;
            mesh.intersect_packet16(&mut packet, lanes, &mut packed);
            for (l, r) in chunk.iter().enumerate() {
                let want = mesh.intersect_brute_force(r, 0.0, f32::INFINITY);
                assert_eq!(
                    packed[l].map(|h| h.t),
                    want.map(|h| h.t),
                    "packet16 ray {}",
                    k * LANES16 + l
                );
            }
        }
        assert!(hits > 50, "only {hits} of the rays hit the soup");
    }

    /// Packets of rays from one point (where leaves are tested from a
    /// shared [`LeafFrame`]) find what single rays find, bit for bit: the
    /// same triangle, `t` and barycentrics, and the same blocked lanes.
    /// A closed bumpy sphere (shared edges and vertices everywhere) seen
    /// from points around it, rays aimed at its vertices, edge midpoints
    /// and inside its triangles, fanned around the diagonal between two
    /// axes so that lanes of one packet have different permutations; some
    /// packets have a lane from another origin, some finite intervals.
    /// Packets of 16 ([`Mesh::intersect_packet16`], lane-major leaf tests),
    /// full and partial, are checked on every SIMD path this CPU has.
    #[test]
    fn camera_packets_give_single_ray_hits_bit_for_bit() {
        use crate::core::simd::{self, Isa};
        let isas: Vec<Isa> = [Isa::Portable, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .filter(|&i| simd::supported(i))
            .collect();
        // Lanes of packets of 16 whose hit differs from the single ray's,
        // per path.
        let mut wrong16 = vec![0u32; isas.len()];
        let mut s = 21u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let (rings, segments) = (24u32, 48u32);
        let mut data = MeshData::default();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = std::f32::consts::TAU * j as f32 / segments as f32;
                let r = 1.0 + 0.05 * next();
                data.positions.push(
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.cos(),
                        theta.sin() * phi.sin(),
                    ) * r,
                );
            }
        }
        let at = |i: u32, j: u32| i * segments + j % segments;
        for i in 0..rings {
            for j in 0..segments {
                let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
                data.indices.push([a, c, b]);
                data.indices.push([b, c, d]);
            }
        }
        let mesh = Mesh::new("bumpy", data, NormalMode::Flat, BuildQuality::Medium).unwrap();
        let bits = |h: Option<MeshHit>| {
            h.map(|h| (h.t.to_bits(), h.triangle, h.b1.to_bits(), h.b2.to_bits()))
        };
        let (mut hits, mut mixed) = (0, 0);
        for k in 0..1500u32 {
            // The eye: along the diagonal between axis `a` and the next.
            let a = (k % 3) as usize;
            let mut axis = Vec3A::ZERO;
            axis[a] = 1.0;
            axis[(a + 1) % 3] = if k % 2 == 0 { 1.0 } else { -1.0 };
            let eye = axis * (1.5 + 2.0 * next()) + Vec3A::new(next(), next(), next()) * 0.1;
            // Half the time a triangle where the view straight at the
            // centre meets the surface (lanes straddle the diagonal), else
            // any triangle.
            let near = if (k / 2) % 2 == 0 {
                axis.normalize() + Vec3A::new(next(), next(), next()) * 0.1
            } else {
                Vec3A::new(next(), next(), next()) * 2.0 - 1.0
            };
            let pick = (0..mesh.triangle_count())
                .min_by(|&i, &j| {
                    let d = |i: usize| (mesh.triangle(i)[0] - near).length_squared();
                    d(i).total_cmp(&d(j))
                })
                .unwrap();
            let tri = mesh.triangle(pick);
            let rays16: Vec<Ray> = (0..LANES16)
                .map(|l| {
                    let target = match (k as usize + l) % 3 {
                        0 => tri[l % 3],
                        1 => (tri[l % 3] + tri[(l + 1) % 3]) * 0.5,
                        _ => {
                            tri[0]
                                + (tri[1] - tri[0]) * next() * 0.5
                                + (tri[2] - tri[0]) * next() * 0.5
                        }
                    };
                    // A little off the target, so the fan spreads.
                    let target =
                        target + Vec3A::new(next(), next(), next()) * 0.02 * (k % 4) as f32;
                    let o = if k % 7 == 0 && l == 5 {
                        eye + Vec3A::Y * 1e-3
                    } else {
                        eye
                    };
                    Ray::new(o, target - o)
                })
                .collect();
            let rays = &rays16[..LANES];
            let perms: Vec<_> = rays
                .iter()
                .map(|r| WatertightRay::new(r).permutation())
                .collect();
            mixed += perms.iter().any(|p| *p != perms[0]) as u32;
            let t_max16: Vec<f32> = (0..LANES16)
                .map(|_| {
                    if k % 3 == 0 {
                        0.5 + 3.0 * next()
                    } else {
                        f32::INFINITY
                    }
                })
                .collect();
            let t_max = &t_max16[..LANES];
            let mut packet = Packet::new(rays, &[0.0; LANES], t_max);
            let mut packed = [None; LANES];
            mesh.intersect_packet(&mut packet, ALL, &mut packed);
            let mut packet = Packet::new(rays, &[0.0; LANES], t_max);
            let blocked = mesh.occluded_packet(&mut packet, ALL);
            // Every fifth packet of 16 is partial (3 to 15 rays, the rest
            // padding), as at the image's edges.
            let m16 = if k % 5 == 4 {
                3 + k as usize % 13
            } else {
                LANES16
            };
            for (i, &isa) in isas.iter().enumerate() {
                assert!(simd::force(isa));
                let mut packet =
                    Packet16::new(&rays16[..m16], &[0.0; LANES16][..m16], &t_max16[..m16]);
                let mut packed = [None; LANES16];
                mesh.intersect_packet16(
                    &mut packet,
                    crate::accel::packet16::ALL_LANES16,
                    &mut packed,
                );
                simd::force(simd::detected());
                for (l, r) in rays16.iter().enumerate().take(m16) {
                    let want = mesh.intersect(r, 0.0, t_max16[l]);
                    wrong16[i] += (bits(packed[l]) != bits(want)) as u32;
                }
            }
            for (l, r) in rays.iter().enumerate() {
                let want = mesh.intersect(r, 0.0, t_max[l]);
                hits += want.is_some() as u32;
                assert_eq!(bits(packed[l]), bits(want), "packet {k} lane {l}");
                assert_eq!(
                    (blocked >> l) & 1 == 1,
                    want.is_some(),
                    "shadow packet {k} lane {l}"
                );
            }
        }
        assert!(
            hits > 8000 && mixed > 200,
            "{hits} hits, {mixed} packets of mixed permutations"
        );
        assert!(
            wrong16.iter().all(|&w| w == 0),
            "lanes of packets of 16 with another hit than the single ray's, on {isas:?}: {wrong16:?}"
        );
    }
}

#[cfg(test)]
mod tangent_tests {
    use super::*;

    /// A unit quad in the XY plane facing +Z with `uv(corner)` mapping.
    fn quad(uv: impl Fn(Vec2) -> Vec2) -> Mesh {
        let corners = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ];
        let data = MeshData {
            positions: corners.iter().map(|c| c.extend(0.0)).collect(),
            normals: Some(vec![Vec3::Z; 4]),
            uvs: Some(corners.iter().map(|&c| uv(c)).collect()),
            indices: vec![[0, 1, 2], [0, 2, 3]],
        };
        Mesh::new("quad", data, NormalMode::Smooth, BuildQuality::Fastest).unwrap()
    }

    /// glTF's texture space has `v` growing downwards: with `u` along +X
    /// and `v` along -Y (an image laid on the quad upright) the tangent is
    /// +X and `w = 1` (bitangent `cross(Z, X) = +Y`, "up" in the image);
    /// mirrored `u` flips the tangent; `v` along +Y (an image upside down)
    /// flips the handedness.
    #[test]
    fn generated_tangents_follow_the_texture() {
        for (map, tangent, w) in [
            (
                Box::new(|c: Vec2| Vec2::new(c.x, 1.0 - c.y)) as Box<dyn Fn(Vec2) -> Vec2>,
                Vec3::X,
                1.0,
            ),
            (
                Box::new(|c: Vec2| Vec2::new(1.0 - c.x, 1.0 - c.y)),
                Vec3::NEG_X,
                -1.0,
            ),
            (Box::new(|c: Vec2| Vec2::new(c.x, c.y)), Vec3::X, -1.0),
            (Box::new(|c: Vec2| Vec2::new(c.y, c.x)), Vec3::Y, 1.0),
        ] {
            let mesh = quad(map).with_tangents(None).unwrap();
            let s = mesh.surface(&MeshHit {
                t: 1.0,
                triangle: 0,
                b1: 0.3,
                b2: 0.2,
            });
            let t = s.tangent.unwrap();
            assert!((t.truncate().normalize() - tangent).length() < 1e-6, "{t}");
            assert_eq!(t.w, w, "{t}");
        }
    }

    /// Tangents from the file are kept (normalised, `w` as its sign) and
    /// checked; a mesh without texture coordinates gets none.
    #[test]
    fn given_tangents_are_checked() {
        let mesh = quad(|c| c)
            .with_tangents(Some(vec![Vec4::new(0.0, 2.0, 0.0, -1.0); 4]))
            .unwrap();
        let s = mesh.surface(&MeshHit {
            t: 1.0,
            triangle: 1,
            b1: 0.5,
            b2: 0.25,
        });
        assert_eq!(s.tangent, Some(Vec4::new(0.0, 1.0, 0.0, -1.0)));
        let e = quad(|c| c)
            .with_tangents(Some(vec![Vec4::ONE; 3]))
            .unwrap_err();
        assert!(e.contains("3 tangents for 4 vertices"), "{e}");
        let e = quad(|c| c)
            .with_tangents(Some(vec![Vec4::NAN; 4]))
            .unwrap_err();
        assert!(e.contains("non-finite tangent"), "{e}");
        let mut data = quad(|c| c).input_data();
        data.uvs = None;
        let bare = Mesh::new("bare", data, NormalMode::Flat, BuildQuality::Fastest).unwrap();
        assert!(bare.with_tangents(None).unwrap().tangents.is_none());
    }
}

/// True when the triangles of `data` close a volume: after merging
/// vertices at the same position, every edge is shared by exactly two
/// triangles that run along it in opposite directions (a closed,
/// consistently oriented surface). Degenerate triangles are ignored;
/// out-of-range indices make the mesh not closed.
pub fn is_closed(data: &MeshData) -> bool {
    use std::collections::HashMap;
    let mut id: HashMap<[u32; 3], u32> = HashMap::new();
    let mut welded = Vec::with_capacity(data.positions.len());
    for p in &data.positions {
        let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let next = id.len() as u32;
        welded.push(*id.entry(key).or_insert(next));
    }
    // Directed edge -> count.
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    for t in &data.indices {
        let Some(v) = t
            .iter()
            .map(|&i| welded.get(i as usize).copied())
            .collect::<Option<Vec<u32>>>()
        else {
            return false;
        };
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        for k in 0..3 {
            *edges.entry((v[k], v[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    !edges.is_empty()
        && edges
            .iter()
            .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
}
