//! Closest hits and occlusion of sixteen rays at once against every
//! polygon of a scene made of a few polygons (the Cornell box: 19
//! polygons under a top level of a few nodes), for the wavefront, which
//! has the rays of a whole bounce at hand.
//!
//! Every ray meets every polygon, the rays side by side (one SIMD lane
//! each), instead of each ray walking the top-level BVH and testing the
//! polygons of the leaves it reaches one at a time. The plane and edge
//! tests are the float operations of [`Shape::intersect`] in the same
//! order, lane by lane, so each polygon's `t` is bit for bit the one the
//! per-ray query computes, and the hit of the nearest polygon is built by
//! the same function ([`polygon_hit`]). The per-ray query keeps the first
//! polygon it meets among equally near ones, in the order of its
//! traversal; a ray whose nearest `t` belongs to two polygons is
//! therefore handed to it ([`RenderScene::intersect`]), and so is a ray
//! whose nearest hit is not finite (the query skips such hits and goes
//! on). The answers are the per-ray query's in every case.

use std::ops::Range;

use glam::Vec3A;

use crate::accel::packet::LaneMask;
use crate::core::math::Ray;
use crate::geometry::shapes::{Shape, polygon_hit, polygon_normal, polygon_uv_axes};
use crate::scene::instance::{Hit, InstanceGeometry, LocalHit, to_object};
use crate::scene::render_scene::RenderScene;

/// Rays tested side by side: one AVX-512 register of `f32` per
/// coordinate (two AVX2 ones, four SSE ones on the other paths). Sixteen
/// instead of eight took the path-traced `cornell.toml`'s wavefront to
/// 0.88x of its time on the AVX-512 path, 0.90x on AVX2 and 0.92x
/// portable (320x240, 16 spp, 2 threads; README, "Integrators").
pub const BATCH_LANES: usize = 16;

/// Scenes of at most this many instances, all polygons, are tested in
/// batches. Every ray pays for every polygon, so beyond a few dozen the
/// top-level BVH, which skips most of them, costs less.
pub const MAX_POLYGONS: usize = 32;

/// One polygon: what its plane and edge tests and its hit read.
#[derive(Clone, Debug)]
struct Polygon {
    /// Its instance in the scene.
    instance: u32,
    /// Newell normal (object space).
    n: Vec3A,
    /// First vertex.
    v0: Vec3A,
    /// Texture axes ([`polygon_uv_axes`]).
    axes: (Vec3A, Vec3A),
    /// Its edges in [`PolygonBatch::edges`].
    edges: Range<usize>,
}

/// Polygons whose instances share one world-to-object transform (bit for
/// bit), so that each ray is taken to their object space once.
#[derive(Clone, Debug)]
struct Group {
    /// An instance of the group, whose transform the group uses.
    instance: u32,
    /// Its polygons in [`PolygonBatch::polygons`].
    polygons: Range<usize>,
}

/// Every polygon of a scene of polygons, laid out for the batched tests.
#[derive(Clone, Debug)]
pub struct PolygonBatch {
    groups: Vec<Group>,
    polygons: Vec<Polygon>,
    /// Per edge: its first vertex `a` and `b - a`.
    edges: Vec<(Vec3A, Vec3A)>,
}

/// The lanes of one coordinate.
type Lanes = [f32; BATCH_LANES];

/// The rays in object space, one coordinate array each.
struct RayLanes {
    o: [Lanes; 3],
    d: [Lanes; 3],
}

impl RayLanes {
    /// The rays taken to the object space of `inst`'s transform, lane by
    /// lane as [`to_object`] does it; lanes past `rays.len()` repeat the
    /// last ray.
    #[inline(always)]
    fn new(scene: &RenderScene, instance: u32, rays: &[Ray]) -> Self {
        let inst = &scene.instances()[instance as usize];
        let mut r = RayLanes {
            o: [[0.0; BATCH_LANES]; 3],
            d: [[0.0; BATCH_LANES]; 3],
        };
        for l in 0..BATCH_LANES {
            let local = to_object(inst, &rays[l.min(rays.len() - 1)]);
            for a in 0..3 {
                r.o[a][l] = local.origin[a];
                r.d[a][l] = local.direction[a];
            }
        }
        r
    }
}

impl PolygonBatch {
    /// The batch of `scene`'s polygons, or `None` when the scene is not
    /// made of polygons alone, has more than [`MAX_POLYGONS`] instances,
    /// none, or a material with an alpha mode (cut-outs are searched
    /// beyond).
    pub fn new(scene: &RenderScene) -> Option<Self> {
        let instances = scene.instances();
        if instances.is_empty() || instances.len() > MAX_POLYGONS {
            return None;
        }
        let materials = scene.materials();
        // Checked before anything is allocated: other scenes pay one pass
        // over at most `MAX_POLYGONS` instances per stage.
        let eligible = instances.iter().all(|inst| {
            matches!(
                inst.geometry,
                InstanceGeometry::Shape(Shape::Polygon { .. })
            ) && materials[inst.material as usize].alpha.is_none()
        });
        if !eligible {
            return None;
        }
        let order: Vec<u32> = (0..instances.len() as u32).collect();
        // Group by transform, bit for bit (a translation by -0 and one by
        // +0 round some origins differently), keeping the scene's order
        // within each group.
        let bits = |i: u32| {
            instances[i as usize]
                .transform
                .to_object
                .to_cols_array()
                .map(f32::to_bits)
        };
        let mut batch = PolygonBatch {
            groups: Vec::new(),
            polygons: Vec::with_capacity(order.len()),
            edges: Vec::new(),
        };
        let mut left = order;
        while let Some(&first) = left.first() {
            let key = bits(first);
            let start = batch.polygons.len();
            left.retain(|&i| {
                if bits(i) != key {
                    return true;
                }
                let InstanceGeometry::Shape(Shape::Polygon { vertices }) =
                    &instances[i as usize].geometry
                else {
                    unreachable!("only polygons are batched")
                };
                let e0 = batch.edges.len();
                for (k, a) in vertices.iter().enumerate() {
                    let a = Vec3A::from(*a);
                    let b = Vec3A::from(vertices[(k + 1) % vertices.len()]);
                    batch.edges.push((a, b - a));
                }
                let n = Vec3A::from(polygon_normal(vertices));
                batch.polygons.push(Polygon {
                    instance: i,
                    n,
                    v0: Vec3A::from(vertices[0]),
                    axes: polygon_uv_axes(n),
                    edges: e0..batch.edges.len(),
                });
                false
            });
            // Largest first: the nearest hit found early rejects the
            // planes of farther polygons before their edges are tested.
            // (The order changes no answer: ties go to the per-ray query.)
            batch.polygons[start..]
                .sort_by(|a, b| b.n.length_squared().total_cmp(&a.n.length_squared()));
            batch.groups.push(Group {
                instance: first,
                polygons: start..batch.polygons.len(),
            });
        }
        Some(batch)
    }

    crate::simd_entry_wide! {
        /// Closest hits of up to [`BATCH_LANES`] rays (each searched in
        /// `(0, inf)`) into `out`: the hits [`RenderScene::intersect`]
        /// gives, bit for bit.
        pub fn intersect(
            &self,
            scene: &RenderScene,
            rays: &[Ray],
            out: &mut [Option<Hit>],
        ) -> () => PolygonBatch, intersect_kernel
    }

    crate::simd_entry_wide! {
        /// For up to [`BATCH_LANES`] segments `(0, t_max[l])` along `rays`, the
        /// mask of those blocked: the answers of [`RenderScene::occluded`].
        pub fn occluded(
            &self,
            scene: &RenderScene,
            rays: &[Ray],
            t_max: &[f32],
        ) -> LaneMask => PolygonBatch, occluded_kernel
    }

    /// For every lane, whether polygon `p`'s plane and edge tests accept
    /// the ray with `t` inside `(0, limit)` (`(0, limit]` with
    /// `inclusive`), as [`Shape::intersect`] decides it (1 for yes), the
    /// `t` and the point; `None` when no lane is accepted. Straight-line
    /// code over the lanes (no `&&`), which the compiler vectorises.
    #[inline(always)]
    fn test(
        &self,
        p: &Polygon,
        r: &RayLanes,
        limit: &Lanes,
        inclusive: bool,
    ) -> Option<([u32; BATCH_LANES], Lanes, [Lanes; 3])> {
        let [nx, ny, nz] = p.n.to_array();
        let [vx, vy, vz] = p.v0.to_array();
        let (o, d) = (&r.o, &r.d);
        let mut t = [0.0f32; BATCH_LANES];
        let mut ok = [0u32; BATCH_LANES];
        for l in 0..BATCH_LANES {
            // n.dot(d), n.dot(v0 - o): glam's order, (x + y) + z.
            let denom = nx * d[0][l] + ny * d[1][l] + nz * d[2][l];
            let num = nx * (vx - o[0][l]) + ny * (vy - o[1][l]) + nz * (vz - o[2][l]);
            let tl = num / denom;
            t[l] = tl;
            // `Shape::intersect` first rejects a zero or non-finite
            // `denom`; the quotient is then infinite, zero or NaN, never
            // inside (0, inf), so the range test alone decides alike
            // (and, unlike the class test the compiler makes of
            // `denom != 0 && denom.is_finite()`, it vectorises). Inclusive
            // of `limit`, the bound `f32::MAX` keeps `t < inf`.
            let inside = if inclusive {
                tl <= limit[l].min(f32::MAX)
            } else {
                tl < limit[l]
            };
            ok[l] = ((tl > 0.0) & inside) as u32;
        }
        if ok.iter().fold(0, |a, &k| a | k) == 0 {
            return None;
        }
        let mut pt = [[0.0f32; BATCH_LANES]; 3];
        for a in 0..3 {
            for l in 0..BATCH_LANES {
                pt[a][l] = o[a][l] + d[a][l] * t[l];
            }
        }
        for &(a, e) in &self.edges[p.edges.clone()] {
            let [ax, ay, az] = a.to_array();
            let [ex, ey, ez] = e.to_array();
            for l in 0..BATCH_LANES {
                // `cross_rounded(b - a, p - a).dot(n)`, as the per-ray
                // test computes it.
                let (wx, wy, wz) = (pt[0][l] - ax, pt[1][l] - ay, pt[2][l] - az);
                let cx = ey * wz - ez * wy;
                let cy = ez * wx - ex * wz;
                let cz = ex * wy - ey * wx;
                let s = cx * nx + cy * ny + cz * nz;
                ok[l] &= (!(s < 0.0)) as u32;
            }
            if ok.iter().fold(0, |a, &k| a | k) == 0 {
                return None;
            }
        }
        Some((ok, t, pt))
    }

    #[inline(always)]
    fn intersect_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        scene: &RenderScene,
        rays: &[Ray],
        out: &mut [Option<Hit>],
    ) {
        let n = rays.len().min(BATCH_LANES);
        if n == 0 {
            return;
        }
        const NONE: u32 = u32::MAX;
        let mut best = [f32::INFINITY; BATCH_LANES];
        let mut which = [NONE; BATCH_LANES];
        let mut tie = [false; BATCH_LANES];
        for g in &self.groups {
            let r = RayLanes::new(scene, g.instance, &rays[..n]);
            for k in g.polygons.clone() {
                let p = &self.polygons[k];
                let Some((ok, t, _)) = self.test(p, &r, &best, true) else {
                    continue;
                };
                for l in 0..BATCH_LANES {
                    // Nearer: the new best; as near: a tie.
                    let nearer = (ok[l] != 0) & (t[l] < best[l]);
                    let same = (ok[l] != 0) & (t[l] == best[l]);
                    tie[l] = (tie[l] & !nearer) | same;
                    best[l] = if nearer { t[l] } else { best[l] };
                    which[l] = if nearer { k as u32 } else { which[l] };
                }
            }
        }
        for l in 0..n {
            let ray = &rays[l];
            out[l] = if which[l] == NONE {
                None
            } else if tie[l] {
                scene.intersect(ray, 0.0, f32::INFINITY)
            } else {
                let p = &self.polygons[which[l] as usize];
                let local = to_object(&scene.instances()[p.instance as usize], ray);
                let t = best[l];
                let hit = polygon_hit(t, local.at(t), p.n, p.v0, p.axes);
                if hit.is_finite() {
                    Some(scene.finish_hit(t, p.instance, LocalHit::shape(&hit)))
                } else {
                    scene.intersect(ray, 0.0, f32::INFINITY)
                }
            };
        }
    }

    #[inline(always)]
    fn occluded_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        scene: &RenderScene,
        rays: &[Ray],
        t_max: &[f32],
    ) -> LaneMask {
        let n = rays.len().min(BATCH_LANES);
        if n == 0 {
            return 0;
        }
        let all: LaneMask = (1 << n) - 1;
        let mut limit = [0.0f32; BATCH_LANES];
        for (l, t) in limit.iter_mut().enumerate() {
            *t = t_max[l.min(n - 1)];
        }
        let mut blocked: LaneMask = 0;
        for g in &self.groups {
            let r = RayLanes::new(scene, g.instance, &rays[..n]);
            for p in &self.polygons[g.polygons.clone()] {
                let Some((ok, t, pt)) = self.test(p, &r, &limit, false) else {
                    continue;
                };
                for l in 0..n {
                    if ok[l] != 0 && blocked & (1 << l) == 0 {
                        let at = Vec3A::new(pt[0][l], pt[1][l], pt[2][l]);
                        if polygon_hit(t[l], at, p.n, p.v0, p.axes).is_finite() {
                            blocked |= 1 << l;
                            // A blocked lane is done.
                            limit[l] = 0.0;
                        }
                    }
                }
                if blocked == all {
                    return blocked;
                }
            }
        }
        blocked
    }
}
