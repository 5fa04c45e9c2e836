//! Intersection queries of a [`RenderScene`]: closest hit and occlusion
//! for single rays, packets of eight (and of sixteen, for closest hits of
//! coherent rays), and streams, and the brute-force reference.

use glam::Vec3A;

use crate::accel::packet::{LANES, LaneMask, Packet, PacketOf, for_each_lane};
use crate::accel::packet16::{LANES16, Packet16, PacketTraversal};
use crate::accel::single::traverse_bvh;
use crate::core::math::{Ray, one_octant, one_origin};
use crate::geometry::mesh::{Mesh, MeshHit};
use crate::scene::instance::{Hit, Instance, InstanceGeometry, LocalHit, to_object};
use crate::scene::merged::MERGED;
use crate::scene::render_scene::RenderScene;

/// `ray` in the space of instance `index`: its object space, or the
/// render frame itself for the merged group (whose corners are there;
/// never transformed, so that every query sees the same ray, signed
/// zeros included).
#[inline(always)]
fn local_ray(index: u32, inst: &Instance, ray: &Ray) -> Ray {
    if index == MERGED {
        *ray
    } else {
        to_object(inst, ray)
    }
}

/// Rays per call of [`RenderScene::intersect_coherent`]: one packet of
/// 16 on the AVX-512 path, two packets of 8 elsewhere.
pub const COHERENT_LANES: usize = LANES16;

/// Bits of a deferred stream key that hold the ray's index.
const RAY_BITS: u64 = 0xffff_ffff;

/// Buffers of [`RenderScene::intersect_stream`], kept between calls so
/// that tracing allocates nothing once they have grown.
#[derive(Debug, Default)]
pub struct StreamScratch {
    best: Vec<Option<(f32, u32, LocalHit)>>,
    /// (instance << 35 | octant << 32 | ray) of rays reaching a mesh.
    deferred: Vec<u64>,
    stream: crate::accel::stream::Stream,
    wt: Vec<crate::geometry::mesh::WatertightRay>,
    mesh_hits: Vec<Option<crate::geometry::mesh::MeshHit>>,
}

impl StreamScratch {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.best.capacity() * size_of::<Option<(f32, u32, LocalHit)>>()
            + self.deferred.capacity() * size_of::<u64>()
            + self.stream.bytes()
            + self.wt.capacity() * size_of::<crate::geometry::mesh::WatertightRay>()
            + self.mesh_hits.capacity() * size_of::<Option<crate::geometry::mesh::MeshHit>>()
    }
}

impl RenderScene {
    #[inline(always)]
    fn intersect_instance<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, LocalHit)> {
        self.intersect_instance_with::<AVX>(index, ray, t_min, t_max, false)
    }

    crate::simd_outlined! {
        /// [`RenderScene::intersect_instance`] out of line: for the rare
        /// instances of the paths below (cut-outs, unbounded instances
        /// that are not plain shapes).
        fn intersect_instance_outlined(&self, index: u32, ray: &Ray, t_min: f32, t_max: f32)
            -> Option<(f32, LocalHit)> => RenderScene, intersect_instance
    }

    crate::simd_outlined! {
        /// [`RenderScene::occludes_instance`] out of line.
        fn occludes_instance_outlined(&self, index: u32, ray: &Ray, t_min: f32, t_max: f32)
            -> bool => RenderScene, occludes_instance
    }

    /// [`RenderScene::intersect_instance`] for the unbounded instances
    /// (planes): a shape without cut-outs is tested inline, anything
    /// else out of line.
    #[inline(always)]
    fn intersect_unbounded<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, LocalHit)> {
        let inst = &self.instances[index as usize];
        match &inst.geometry {
            InstanceGeometry::Shape(s) if !self.has_alpha(inst) => s
                .intersect(&to_object(inst, ray), t_min, t_max)
                .map(|h| (h.t, LocalHit::shape(&h))),
            _ => self.intersect_instance_outlined::<AVX>(index, ray, t_min, t_max),
        }
    }

    /// [`RenderScene::occludes_instance`] for the unbounded instances, as
    /// [`RenderScene::intersect_unbounded`].
    #[inline(always)]
    fn occludes_unbounded<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> bool {
        let inst = &self.instances[index as usize];
        match &inst.geometry {
            InstanceGeometry::Shape(s) if !self.has_alpha(inst) => {
                s.occludes(&to_object(inst, ray), t_min, t_max)
            }
            _ => self.occludes_instance_outlined::<AVX>(index, ray, t_min, t_max),
        }
    }

    /// Closest hit on one instance; meshes by their BVH, or by testing
    /// every triangle when `brute_force` is set. Hits where the instance's
    /// material is cut away ([`Material::alpha`](crate::scene::material::Material::alpha))
    /// are skipped: the search goes on beyond them.
    #[inline(always)]
    fn intersect_instance_with<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        brute_force: bool,
    ) -> Option<(f32, LocalHit)> {
        let inst = &self.instances[index as usize];
        if self.has_alpha(inst) {
            return self.intersect_cut_out::<AVX>(index, ray, t_min, t_max, brute_force);
        }
        closest_in_geometry::<AVX>(inst, &to_object(inst, ray), t_min, t_max, brute_force)
    }

    /// The `t` of [`RenderScene::intersect_instance`]'s hit, without
    /// building the hit where that is cheaper (planes and disks).
    #[inline(always)]
    fn instance_t<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<f32> {
        let inst = &self.instances[index as usize];
        match &inst.geometry {
            InstanceGeometry::Shape(s) if !self.has_alpha(inst) => {
                s.intersect_t(&to_object(inst, ray), t_min, t_max)
            }
            _ => self
                .intersect_instance_outlined::<AVX>(index, ray, t_min, t_max)
                .map(|(t, _)| t),
        }
    }

    /// [`RenderScene::intersect_instance_with`] for an instance whose
    /// material has an alpha mode: the closest hit that is not cut away,
    /// found by searching again beyond each cut-away hit (each raises
    /// `t_min` strictly, so this ends). Kept out of line: scenes without
    /// alpha never call it.
    #[cold]
    #[inline(never)]
    fn intersect_cut_out<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        brute_force: bool,
    ) -> Option<(f32, LocalHit)> {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            #[target_feature(enable = "avx2,fma")]
            fn fast(
                this: &RenderScene,
                index: u32,
                ray: &Ray,
                t_min: f32,
                t_max: f32,
                brute_force: bool,
            ) -> Option<(f32, LocalHit)> {
                this.cut_out_loop::<true>(index, ray, t_min, t_max, brute_force)
            }
            // SAFETY: `AVX` is set only by the AVX2 entry points, which run
            // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
            #[allow(unsafe_code)]
            return unsafe { fast(self, index, ray, t_min, t_max, brute_force) };
        }
        self.cut_out_loop::<false>(index, ray, t_min, t_max, brute_force)
    }

    /// The body of [`Self::intersect_cut_out`], inlined into its code path.
    #[inline(always)]
    fn cut_out_loop<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        brute_force: bool,
    ) -> Option<(f32, LocalHit)> {
        let inst = &self.instances[index as usize];
        let local = to_object(inst, ray);
        let mut t_min = t_min;
        loop {
            let (t, h) = closest_in_geometry::<AVX>(inst, &local, t_min, t_max, brute_force)?;
            if !self.cut_away(inst, ray, t, &h) {
                return Some((t, h));
            }
            t_min = t;
        }
    }

    /// True when the scene has cut-outs and `inst`'s material is one.
    #[inline(always)]
    fn has_alpha(&self, inst: &Instance) -> bool {
        self.cutouts && self.materials[inst.material as usize].alpha.is_some()
    }

    /// True when the hit `h` at `t` of `ray` on `inst` falls where its
    /// material's alpha removes the surface (a MASK cut-out, or a BLEND
    /// surface the ray passes through: decided by a hash of the ray, the
    /// hit's `t` and the instance, so the same ray always gets the same
    /// answer).
    #[inline(never)]
    fn cut_away(&self, inst: &Instance, ray: &Ray, t: f32, h: &LocalHit) -> bool {
        let Some(alpha) = &self.materials[inst.material as usize].alpha else {
            return false;
        };
        let uv = match (h, &inst.geometry) {
            (LocalHit::Shape { uv, .. }, _) => *uv,
            (LocalHit::Mesh(mh), InstanceGeometry::Mesh(m)) => m.surface(mh).uv,
            (LocalHit::Mesh(_), InstanceGeometry::Shape(_)) => return false,
        };
        alpha.passes(uv, ray_hash(ray, t))
    }

    #[inline(always)]
    fn occludes_instance<const AVX: bool>(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> bool {
        let inst = &self.instances[index as usize];
        if self.has_alpha(inst) {
            return self
                .intersect_instance_outlined::<AVX>(index, ray, t_min, t_max)
                .is_some();
        }
        let local = to_object(inst, ray);
        match &inst.geometry {
            InstanceGeometry::Shape(s) => s.occludes(&local, t_min, t_max),
            InstanceGeometry::Mesh(m) => m.occluded_kernel::<AVX>(&local, t_min, t_max),
        }
    }

    crate::simd_entry! {
        /// The closest hit with `t` in `(t_min, t_max)`.
        pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit>
            => RenderScene, intersect_kernel
    }

    crate::simd_entry! {
        /// True when anything blocks the ray between `t_min` and `t_max`;
        /// stops at the first blocker found.
        pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool
            => RenderScene, occluded_kernel
    }

    crate::simd_entry! {
        /// [`RenderScene::intersect_packet`], with the top level traversed as
        /// a packet and each mesh either as a packet (`mesh_packets`) or one
        /// lane at a time, for rays too incoherent to share a mesh's nodes.
        pub fn intersect_packet_with(
            &self,
            rays: &[Ray],
            out: &mut [Option<Hit>],
            mesh_packets: bool,
        ) -> () => RenderScene, intersect_packet_kernel
    }

    crate::simd_entry_wide! {
        /// Closest hits of up to [`LANES16`] rays at once (each searched in
        /// `(0, inf)`), by packet traversal of the top-level BVH and of
        /// mesh BVHs in packets of 16 ([`crate::accel::packet16`]): the
        /// same hits as [`RenderScene::intersect`] on each ray, bit for bit,
        /// on every SIMD path. Fastest on the AVX-512 path
        /// ([`crate::core::simd::Isa::Avx512`]); elsewhere
        /// [`RenderScene::intersect_coherent`] takes packets of 8.
        pub fn intersect_packet16(&self, rays: &[Ray], out: &mut [Option<Hit>]) -> ()
            => RenderScene, intersect_packet16_kernel
    }

    crate::simd_entry_wide! {
        /// For up to [`LANES16`] segments `(0, t_max[l])` along `rays`, the
        /// mask of those blocked by anything, by packet traversal in
        /// packets of 16 ([`crate::accel::packet16`]): the answers of
        /// [`RenderScene::occluded`] on each, on every SIMD path.
        pub fn occluded_packet16(&self, rays: &[Ray], t_max: &[f32]) -> LaneMask
            => RenderScene, occluded_packet16_kernel
    }

    crate::simd_entry! {
        /// Closest hits of all `rays` (each searched in `(0, inf)`), by
        /// streams: the top level is traversed in packets of eight
        /// consecutive rays, shapes are intersected there, and every ray that
        /// reaches a mesh instance joins that instance's stream for its
        /// direction octant; each stream then traverses the mesh's BVH at
        /// once ([`crate::accel::stream`]). The same hits as
        /// [`RenderScene::intersect`] on each ray. `scratch` keeps the
        /// buffers between calls.
        pub fn intersect_stream(
            &self,
            rays: &[Ray],
            out: &mut [Option<Hit>],
            scratch: &mut StreamScratch,
        ) -> () => RenderScene, intersect_stream_kernel
    }

    crate::simd_entry! {
        /// [`RenderScene::occluded_packet`], with meshes traversed as a
        /// packet (`mesh_packets`) or one lane at a time.
        pub fn occluded_packet_with(
            &self,
            rays: &[Ray],
            t_max: &[f32],
            mesh_packets: bool,
        ) -> LaneMask => RenderScene, occluded_packet_kernel
    }

    #[inline(always)]
    fn intersect_kernel<const AVX: bool>(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let mut best: Option<(f32, u32, LocalHit)> = None;
        let mut t_max = t_max;
        for &i in &self.tlas.unbounded {
            if let Some((t, h)) = self.intersect_unbounded::<AVX>(i, ray, t_min, t_max) {
                t_max = t;
                best = Some((t, i, h));
            }
        }
        if let Some(g) = &self.merged
            && let Some(h) = g.mesh().intersect_kernel::<AVX>(ray, t_min, t_max)
        {
            t_max = h.t;
            best = Some((h.t, MERGED, LocalHit::Mesh(h)));
        }
        if !self.tlas.leaf_instances.is_empty() {
            traverse_bvh::<AVX>(
                &self.tlas.bvh,
                ray,
                t_min,
                t_max,
                false,
                #[inline(always)]
                |slot, t_max| {
                    let inst = self.tlas.leaf_instances[slot];
                    let (t, h) = self.intersect_instance::<AVX>(inst, ray, t_min, t_max)?;
                    best = Some((t, inst, h));
                    Some(t)
                },
            );
        }
        let (t, index, local) = best?;
        Some(self.finish_hit(t, index, local))
    }

    #[inline(always)]
    fn occluded_kernel<const AVX: bool>(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        // A plain loop, not `Iterator::any` with a closure: a closure left
        // out of line is compiled without the AVX2 entry point's features
        // and calls every intrinsic of the inlined shape and mesh tests as a
        // function (`objdump -d` showed 239 such calls in each).
        for &i in &self.tlas.unbounded {
            if self.occludes_unbounded::<AVX>(i, ray, t_min, t_max) {
                return true;
            }
        }
        if let Some(g) = &self.merged
            && g.mesh().occluded_kernel::<AVX>(ray, t_min, t_max)
        {
            return true;
        }
        if self.tlas.leaf_instances.is_empty() {
            return false;
        }
        traverse_bvh::<AVX>(
            &self.tlas.bvh,
            ray,
            t_min,
            t_max,
            true,
            #[inline(always)]
            |slot, t_max| {
                self.occludes_instance::<AVX>(self.tlas.leaf_instances[slot], ray, t_min, t_max)
                    .then_some(t_min)
            },
        )
    }

    /// Closest hits of up to [`LANES`] rays at once (each searched in
    /// `(0, inf)`), by packet traversal of the top-level BVH and of mesh
    /// BVHs: the same hits as [`RenderScene::intersect`] on each ray.
    pub fn intersect_packet(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        self.intersect_packet_with(rays, out, true)
    }

    /// Closest hits of up to [`LANES`] rays (each searched in `(0, inf)`)
    /// on the unbounded instances and, by packet traversal of the top
    /// level, on the shapes, into `best`. The lanes of `p` that reach mesh
    /// instance `index` go to `mesh(p, lanes, index, instance, mesh, best)`,
    /// which may record hits in `best` and shrink `p.t_max`.
    ///
    /// Written once for packets of `N` lanes: 8 ([`packet::traverse`]) or
    /// 16 ([`crate::accel::packet16::traverse16`], whose AVX-512 child test
    /// `AVX512` selects).
    #[inline(always)]
    fn top_level_packet<const N: usize, const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        best: &mut [Option<(f32, u32, LocalHit)>],
        mut mesh: impl FnMut(
            &mut PacketOf<N>,
            LaneMask,
            u32,
            &Instance,
            &Mesh,
            &mut [Option<(f32, u32, LocalHit)>],
        ),
    ) -> [(u32, f32); N]
    where
        PacketOf<N>: PacketTraversal,
    {
        let n = rays.len().min(N);
        let mut t_max = [f32::INFINITY; N];
        // Each lane's nearest unbounded instance and the interval end it
        // was found in: its hit is built at the end, by the same search
        // again, and only where nothing nearer was found. (Building it
        // here and moving it through `best` stalled on store forwarding:
        // 5% of the frame-loop benchmark, whose every ray meets the
        // ground plane.)
        let mut unbounded = [(u32::MAX, 0.0f32); N];
        for (l, ray) in rays[..n].iter().enumerate() {
            for &i in &self.tlas.unbounded {
                if let Some(t) = self.instance_t::<AVX>(i, ray, 0.0, t_max[l]) {
                    unbounded[l] = (i, t_max[l]);
                    t_max[l] = t;
                }
            }
        }
        let mut packet = PacketOf::<N>::new(&rays[..n], &[0.0; N][..n], &t_max[..n]);
        if let Some(g) = &self.merged {
            let all = packet.valid;
            mesh(&mut packet, all, MERGED, &g.instance, g.mesh(), best);
        }
        let bvh = &self.tlas.bvh;
        let all = packet.valid;
        packet.traverse_bvh::<AVX, AVX512>(
            bvh,
            all,
            #[inline(always)]
            |p, lanes, leaf| {
                let lf = bvh.leaves[leaf as usize];
                for slot in lf.first..lf.first + lf.count {
                    let index = self.tlas.leaf_instances[slot as usize];
                    let inst = &self.instances[index as usize];
                    if self.has_alpha(inst) {
                        for_each_lane(
                            lanes,
                            #[inline(always)]
                            |l| {
                                let ray = &p.rays[l];
                                if let Some((t, h)) = self.intersect_instance_outlined::<AVX>(
                                    index, ray, p.t_min[l], p.t_max[l],
                                ) {
                                    p.t_max[l] = t;
                                    best[l] = Some((t, index, h));
                                }
                            },
                        );
                        continue;
                    }
                    match &inst.geometry {
                        InstanceGeometry::Shape(s) => for_each_lane(
                            lanes,
                            #[inline(always)]
                            |l| {
                                let local = to_object(inst, &p.rays[l]);
                                if let Some(h) = s.intersect(&local, p.t_min[l], p.t_max[l]) {
                                    p.t_max[l] = h.t;
                                    best[l] = Some((h.t, index, LocalHit::shape(&h)));
                                }
                            },
                        ),
                        InstanceGeometry::Mesh(m) => mesh(p, lanes, index, inst, m, best),
                    }
                }
                0
            },
        );
        unbounded
    }

    /// The hit on unbounded instance `u.0` (`u32::MAX`: none) that
    /// [`Self::top_level_packet`] found for `ray` within `u.1`: the same
    /// search again.
    #[inline(always)]
    fn unbounded_hit<const AVX: bool>(
        &self,
        ray: &Ray,
        u: (u32, f32),
    ) -> Option<(f32, u32, LocalHit)> {
        let (i, reach) = u;
        if i == u32::MAX {
            return None;
        }
        self.intersect_unbounded::<AVX>(i, ray, 0.0, reach)
            .map(|(t, h)| (t, i, h))
    }

    #[inline(always)]
    fn intersect_packet_kernel<const AVX: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
        mesh_packets: bool,
    ) {
        self.intersect_packet_of::<LANES, AVX, false>(
            rays,
            out,
            #[inline(always)]
            |p, lanes, index, inst, m, hits| {
                if mesh_packets {
                    let mut local = Packet::new(&[], &[], &[]);
                    for_each_lane(
                        lanes,
                        #[inline(always)]
                        |l| {
                            local.set_lane(
                                l,
                                local_ray(index, inst, &p.rays[l]),
                                p.t_min[l],
                                p.t_max[l],
                            )
                        },
                    );
                    m.intersect_packet_kernel::<AVX>(&mut local, lanes, hits);
                } else {
                    for_each_lane(
                        lanes,
                        #[inline(always)]
                        |l| {
                            hits[l] = m.intersect_for_surface_outlined::<AVX>(
                                &local_ray(index, inst, &p.rays[l]),
                                p.t_min[l],
                                p.t_max[l],
                            );
                        },
                    );
                }
            },
        );
    }

    /// [`Self::intersect_packet_kernel`] for packets of 16: the top level
    /// and every mesh traversed as one 16-lane packet
    /// ([`crate::accel::packet16`]).
    #[inline(always)]
    fn intersect_packet16_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
    ) {
        self.intersect_packet_of::<LANES16, AVX, AVX512>(
            rays,
            out,
            #[inline(always)]
            |p, lanes, index, inst, m, hits| {
                let mut local = Packet16::new(&[], &[], &[]);
                for_each_lane(
                    lanes,
                    #[inline(always)]
                    |l| {
                        local.set_lane(
                            l,
                            local_ray(index, inst, &p.rays[l]),
                            p.t_min[l],
                            p.t_max[l],
                        )
                    },
                );
                m.intersect_packet16_kernel::<AVX, AVX512>(&mut local, lanes, hits);
            },
        );
    }

    /// The closest-hit query of packets of `N` lanes (8 or 16, as
    /// [`Self::top_level_packet`]): `mesh_hits(packet, lanes, instance,
    /// mesh, hits)` finds the object-space hits of the lanes that reach a
    /// mesh instance, which then shrink the lanes' intervals; the
    /// nearest hits are finished into `out`.
    #[inline(always)]
    fn intersect_packet_of<const N: usize, const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
        mut mesh_hits: impl FnMut(
            &PacketOf<N>,
            LaneMask,
            u32,
            &Instance,
            &Mesh,
            &mut [Option<MeshHit>; N],
        ),
    ) where
        PacketOf<N>: PacketTraversal,
    {
        let n = rays.len().min(N);
        let mut best: [Option<(f32, u32, LocalHit)>; N] = [None; N];
        let unbounded = self.top_level_packet::<N, AVX, AVX512>(
            rays,
            &mut best,
            #[inline(always)]
            |p, lanes, index, inst, m, best| {
                let mut hits = [None; N];
                mesh_hits(p, lanes, index, inst, m, &mut hits);
                for_each_lane(
                    lanes,
                    #[inline(always)]
                    |l| {
                        if let Some(h) = hits[l] {
                            p.t_max[l] = h.t;
                            best[l] = Some((h.t, index, LocalHit::Mesh(h)));
                        }
                    },
                );
            },
        );
        // A lane without a hit above has its unbounded instance's, if any
        // (every hit recorded is nearer). The hits are built in place
        // (`finish_hit_inline`): returned from a call, each was copied out
        // of a temporary; inlined, the frame-loop benchmark ran 0.91-1.03x
        // the time over ten alternating pairs (median 0.97x).
        for (l, o) in out[..n].iter_mut().enumerate() {
            *o = match best[l] {
                Some((t, i, h)) => Some(self.finish_hit_inline(t, i, h)),
                None => self
                    .unbounded_hit::<AVX>(&rays[l], unbounded[l])
                    .map(|(t, i, h)| self.finish_hit_inline(t, i, h)),
            };
        }
    }

    /// Closest hits of up to [`COHERENT_LANES`] neighbouring rays (camera
    /// rays of a run of pixels; each searched in `(0, inf)`), traced the
    /// fastest way this CPU has: one packet of 16 on the AVX-512 path or
    /// when the rays share their origin
    /// ([`RenderScene::intersect_packet16`]), packets of 8 otherwise
    /// ([`RenderScene::intersect_packet`]); rays pointing into different
    /// octants go eight at a time, and a group of eight that is still
    /// mixed goes ray by ray. Every way gives each ray the hit
    /// [`RenderScene::intersect`] gives it.
    pub fn intersect_coherent(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let rays = &rays[..rays.len().min(COHERENT_LANES)];
        // Rays from one point take packets of 16 on every path: their inner
        // nodes are tested as one frustum (`accel::packet16`), which on
        // the anchors' camera rays (100k triangles, one thread) ran at
        // 12.7 against 10.7 Mrays/s for packets of 8 on the AVX2 path and
        // 9.1 against 7.6 on the portable one.
        if one_octant(rays)
            && (crate::core::simd::use_avx512() || (rays.len() > LANES && one_origin(rays)))
        {
            self.intersect_packet16(rays, out);
            return;
        }
        for (rays, out) in rays.chunks(LANES).zip(out.chunks_mut(LANES)) {
            if one_octant(rays) {
                self.intersect_packet(rays, out);
            } else {
                for (o, r) in out.iter_mut().zip(rays) {
                    *o = self.intersect(r, 0.0, f32::INFINITY);
                }
            }
        }
    }

    /// For up to [`COHERENT_LANES`] neighbouring segments `(0, t_max[l])`
    /// along `rays` (shadow rays of neighbouring pixels towards one
    /// light), the mask of those blocked, traced as
    /// [`RenderScene::intersect_coherent`] traces rays: one packet of 16
    /// on the AVX-512 path, packets of 8 otherwise, a group still mixed
    /// (or of one ray) ray by ray. The answers of [`RenderScene::occluded`].
    pub fn occluded_coherent(&self, rays: &[Ray], t_max: &[f32]) -> LaneMask {
        let n = rays.len().min(COHERENT_LANES);
        let (rays, t_max) = (&rays[..n], &t_max[..n]);
        if crate::core::simd::use_avx512() && n > LANES && one_octant(rays) {
            return self.occluded_packet16(rays, t_max);
        }
        let mut blocked: LaneMask = 0;
        for (c, (rays, t_max)) in rays.chunks(LANES).zip(t_max.chunks(LANES)).enumerate() {
            let b = if rays.len() > 1 && one_octant(rays) {
                self.occluded_packet(rays, t_max)
            } else {
                let mut b = 0;
                for (j, (r, &t)) in rays.iter().zip(t_max).enumerate() {
                    if self.occluded(r, 0.0, t) {
                        b |= 1 << j;
                    }
                }
                b
            };
            blocked |= b << (c * LANES);
        }
        blocked
    }

    #[inline(always)]
    fn intersect_stream_kernel<const AVX: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
        scratch: &mut StreamScratch,
    ) {
        let n = rays.len();
        debug_assert!(
            n <= RAY_BITS as usize,
            "ray indices are 32-bit in stream keys"
        );
        let StreamScratch {
            best,
            deferred,
            stream,
            wt,
            mesh_hits,
        } = scratch;
        best.clear();
        best.resize(n, None);
        deferred.clear();
        for (p, packet_rays) in rays.chunks(LANES).enumerate() {
            let first = p * LANES;
            let best = &mut best[first..first + packet_rays.len()];
            let unbounded = self.top_level_packet::<LANES, AVX, false>(
                packet_rays,
                best,
                |p, lanes, index, inst, _, _| {
                    for_each_lane(
                        lanes,
                        #[inline(always)]
                        |l| {
                            let d = local_ray(index, inst, &p.rays[l]).direction;
                            let octant = (d.x < 0.0) as u64
                                | ((d.y < 0.0) as u64) << 1
                                | ((d.z < 0.0) as u64) << 2;
                            deferred.push((index as u64) << 35 | octant << 32 | (first + l) as u64);
                        },
                    )
                },
            );
            // The streams below start from the nearest of the unbounded
            // instances' and the shapes' hits.
            for (l, ray) in packet_rays.iter().enumerate() {
                if best[l].is_none() {
                    best[l] = self.unbounded_hit::<AVX>(ray, unbounded[l]);
                }
            }
        }
        // One stream per (instance, octant), in a fixed order.
        deferred.sort_unstable();
        let mut rest = &deferred[..];
        while let Some(&key) = rest.first() {
            let group = rest.partition_point(|&k| k >> 32 == key >> 32);
            let index = (key >> 35) as u32;
            let inst = match &self.merged {
                Some(g) if index == MERGED => &g.instance,
                _ => &self.instances[index as usize],
            };
            let InstanceGeometry::Mesh(mesh) = &inst.geometry else {
                unreachable!("only meshes are deferred")
            };
            stream.clear();
            for &k in &rest[..group] {
                let i = (k & RAY_BITS) as usize;
                let t_max = best[i].as_ref().map_or(f32::INFINITY, |b| b.0);
                stream.push(local_ray(index, inst, &rays[i]), 0.0, t_max);
            }
            mesh.intersect_stream_kernel::<AVX>(stream, wt, mesh_hits);
            for (&k, h) in rest[..group].iter().zip(mesh_hits.iter()) {
                if let Some(h) = h {
                    best[(k & RAY_BITS) as usize] = Some((h.t, index, LocalHit::Mesh(*h)));
                }
            }
            rest = &rest[group..];
        }
        for (o, b) in out[..n].iter_mut().zip(best.iter()) {
            *o = b.map(|(t, i, h)| self.finish_hit(t, i, h));
        }
    }

    /// For up to [`LANES`] segments `(0, t_max[l])` along `rays`, the mask
    /// of those blocked by anything: the same answers as
    /// [`RenderScene::occluded`] on each.
    pub fn occluded_packet(&self, rays: &[Ray], t_max: &[f32]) -> LaneMask {
        self.occluded_packet_with(rays, t_max, true)
    }

    #[inline(always)]
    fn occluded_packet_kernel<const AVX: bool>(
        &self,
        rays: &[Ray],
        t_max: &[f32],
        mesh_packets: bool,
    ) -> LaneMask {
        self.occluded_packet_of::<LANES, AVX, false>(
            rays,
            t_max,
            mesh_packets,
            #[inline(always)]
            |m, p, lanes| m.occluded_packet_kernel::<AVX>(p, lanes),
        )
    }

    #[inline(always)]
    fn occluded_packet16_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        t_max: &[f32],
    ) -> LaneMask {
        self.occluded_packet_of::<LANES16, AVX, AVX512>(
            rays,
            t_max,
            true,
            #[inline(always)]
            |m, p, lanes| m.occluded_packet16_kernel::<AVX, AVX512>(p, lanes),
        )
    }

    /// The occlusion query of packets of `N` lanes (8 or 16, as
    /// [`Self::top_level_packet`]); the lanes of a packet that reach a
    /// mesh go through it as one packet, `mesh_packet(mesh, packet,
    /// lanes)` (when `mesh_packets`), or one lane at a time.
    #[inline(always)]
    fn occluded_packet_of<const N: usize, const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        t_max: &[f32],
        mesh_packets: bool,
        mut mesh_packet: impl FnMut(&Mesh, &mut PacketOf<N>, LaneMask) -> LaneMask,
    ) -> LaneMask
    where
        PacketOf<N>: PacketTraversal,
    {
        let n = rays.len().min(N);
        let mut blocked: LaneMask = 0;
        // Plain loops, as in `occluded_kernel` (no out-of-line closure).
        for (l, ray) in rays[..n].iter().enumerate() {
            for &i in &self.tlas.unbounded {
                if self.occludes_unbounded::<AVX>(i, ray, 0.0, t_max[l]) {
                    blocked |= 1 << l;
                    break;
                }
            }
        }
        let mut packet = PacketOf::<N>::new(&rays[..n], &[0.0; N][..n], &t_max[..n]);
        if let Some(g) = &self.merged {
            let lanes = packet.valid & !blocked;
            let m = g.mesh();
            if lanes != 0 && (!mesh_packets || m.single_leaf()) {
                for_each_lane(
                    lanes,
                    #[inline(always)]
                    |l| {
                        if m.occluded_lane::<AVX>(&rays[l], 0.0, t_max[l]) {
                            blocked |= 1 << l;
                        }
                    },
                );
            } else if lanes != 0 {
                // The group is in the render frame: the packet as it is.
                let mut local = packet;
                blocked |= mesh_packet(m, &mut local, lanes);
            }
        }
        let todo = packet.valid & !blocked;
        let bvh = &self.tlas.bvh;
        packet.traverse_bvh::<AVX, AVX512>(
            bvh,
            todo,
            #[inline(always)]
            |p, lanes, leaf| {
                let lf = bvh.leaves[leaf as usize];
                let mut lanes = lanes;
                let mut found = 0;
                for slot in lf.first..lf.first + lf.count {
                    if lanes == 0 {
                        break;
                    }
                    let index = self.tlas.leaf_instances[slot as usize];
                    let inst = &self.instances[index as usize];
                    let now = match &inst.geometry {
                        _ if self.has_alpha(inst) => {
                            let mut now = 0;
                            for_each_lane(
                                lanes,
                                #[inline(always)]
                                |l| {
                                    if self.occludes_instance_outlined::<AVX>(
                                        index, &p.rays[l], p.t_min[l], p.t_max[l],
                                    ) {
                                        now |= 1 << l;
                                    }
                                },
                            );
                            now
                        }
                        InstanceGeometry::Shape(s) => {
                            let mut now = 0;
                            for_each_lane(
                                lanes,
                                #[inline(always)]
                                |l| {
                                    let local = to_object(inst, &p.rays[l]);
                                    if s.occludes(&local, p.t_min[l], p.t_max[l]) {
                                        now |= 1 << l;
                                    }
                                },
                            );
                            now
                        }
                        // A mesh of one leaf goes lane by lane, as for
                        // closest hits.
                        InstanceGeometry::Mesh(m) if !mesh_packets || m.single_leaf() => {
                            let mut now = 0;
                            for_each_lane(
                                lanes,
                                #[inline(always)]
                                |l| {
                                    let local = to_object(inst, &p.rays[l]);
                                    if m.occluded_lane::<AVX>(&local, p.t_min[l], p.t_max[l]) {
                                        now |= 1 << l;
                                    }
                                },
                            );
                            now
                        }
                        InstanceGeometry::Mesh(m) => {
                            let mut local = PacketOf::<N>::new(&[], &[], &[]);
                            for_each_lane(
                                lanes,
                                #[inline(always)]
                                |l| {
                                    local.set_lane(
                                        l,
                                        to_object(inst, &p.rays[l]),
                                        p.t_min[l],
                                        p.t_max[l],
                                    )
                                },
                            );
                            mesh_packet(m, &mut local, lanes)
                        }
                    };
                    found |= now;
                    lanes &= !now;
                }
                blocked |= found;
                found
            },
        );
        blocked & packet.valid
    }

    /// The closest hit found by testing every instance, and every triangle
    /// of every mesh, without any BVH: the reference that BVH traversal is
    /// tested against.
    pub fn intersect_brute_force(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let mut best: Option<(f32, u32, LocalHit)> = None;
        let mut t_max = t_max;
        if let Some(g) = &self.merged
            && let Some(h) = g.mesh().intersect_brute_force(ray, t_min, t_max)
        {
            t_max = h.t;
            best = Some((h.t, MERGED, LocalHit::Mesh(h)));
        }
        for i in 0..self.instances.len() as u32 {
            if self.merged.as_ref().is_some_and(|g| g.is_member(i)) {
                continue;
            }
            if let Some((t, h)) = self.intersect_instance_with::<false>(i, ray, t_min, t_max, true)
            {
                t_max = t;
                best = Some((t, i, h));
            }
        }
        let (t, index, local) = best?;
        Some(self.finish_hit(t, index, local))
    }

    pub(super) fn finish_hit(&self, t: f32, index: u32, local: LocalHit) -> Hit {
        self.finish_hit_inline(t, index, local)
    }

    /// [`Self::finish_hit`] inlined into its caller, which can then build
    /// the hit where it keeps it (the wavefront's hit slots) instead of
    /// copying it out of a returned value.
    #[inline(always)]
    pub(super) fn finish_hit_inline(&self, t: f32, index: u32, local: LocalHit) -> Hit {
        // A hit on the merged group becomes one on the instance it merged.
        // (With its world geometric normal, which the group keeps.)
        let (index, local, merged_gn) = match (&self.merged, local) {
            (Some(g), LocalHit::Mesh(h)) if index == MERGED => {
                let (instance, triangle) = g.owner(h.triangle);
                (
                    instance,
                    LocalHit::Mesh(MeshHit { triangle, ..h }),
                    Some(g.normal(h.triangle)),
                )
            }
            _ => (index, local, None),
        };
        let inst = &self.instances[index as usize];
        let xf = &inst.transform;
        // The point comes from the object-space surface point, correct to a
        // few ulps of its own coordinates; `ray.at(t)` would carry the
        // rounding of a possibly distant ray origin.
        // Texture coordinates per length only matter to textured materials.
        let lod = self.materials[inst.material as usize].has_textures();
        let mut tangents = None;
        let (point, gn, sn, uv) = match (local, &inst.geometry) {
            (LocalHit::Shape { point, normal, uv }, InstanceGeometry::Shape(shape)) if lod => {
                tangents = shape.uv_tangents(point, normal);
                let n = xf.normal(normal);
                (xf.to_world.transform_point3a(point), n, n, uv)
            }
            (LocalHit::Shape { point, normal, uv }, _) => {
                let n = xf.normal(normal);
                (xf.to_world.transform_point3a(point), n, n, uv)
            }
            (LocalHit::Mesh(h), InstanceGeometry::Mesh(m)) => {
                if lod {
                    tangents = m.uv_tangents(h.triangle);
                }
                let s = m.surface(&h);
                let gn = merged_gn.unwrap_or_else(|| xf.normal(s.geometric_normal));
                let mut sn = xf.normal(s.shading_normal);
                if sn.dot(gn) < 0.0 {
                    sn = -sn;
                }
                if let (Some(map), Some(tangent)) = (
                    &self.materials[inst.material as usize].normal_map,
                    s.tangent,
                ) {
                    sn = normal_mapped(map, &s, tangent, xf, sn, gn);
                }
                (xf.to_world.transform_point3a(s.point), gn, sn, s.uv)
            }
            (LocalHit::Mesh(_), InstanceGeometry::Shape(_)) => {
                unreachable!("hit kind matches geometry")
            }
        };
        Hit {
            t,
            point,
            geometric_normal: gn,
            shading_normal: sn,
            uv,
            uv_density: tangents.map_or(0.0, |(du, dv)| uv_density(xf, du, dv)),
            instance: index,
            material: inst.material,
        }
    }
}

/// Texture coordinates per unit of world length for the object-space
/// derivatives `du`, `dv` of the surface point with respect to the texture
/// coordinates: `1 / sqrt(|M du x M dv|)` with `M` the instance's linear
/// part (0 when that area is zero or not finite).
#[inline]
fn uv_density(xf: &crate::geometry::transform::InstanceTransform, du: Vec3A, dv: Vec3A) -> f32 {
    let area = (xf.to_world.matrix3 * du)
        .cross(xf.to_world.matrix3 * dv)
        .length();
    if area > 0.0 && area.is_finite() {
        area.sqrt().recip()
    } else {
        0.0
    }
}

/// The shading normal `sn` (world space, unit, on the side of `gn`)
/// perturbed by the normal map `map` at the mesh surface point `s`, whose
/// object-space tangent is `tangent`: the map's tangent-space normal in the
/// frame (tangent, bitangent, normal) with the bitangent
/// `tangent.w * cross(normal, tangent)` built in object space and both
/// carried to world space as vectors. A mapped normal that would face
/// away from the geometric side (or a degenerate frame) keeps `sn`. Out
/// of line: hits without normal maps only pay for the check.
#[cold]
#[inline(never)]
fn normal_mapped(
    map: &crate::scene::material::NormalMap,
    s: &crate::geometry::mesh::MeshSurface,
    tangent: glam::Vec4,
    xf: &crate::geometry::transform::InstanceTransform,
    sn: Vec3A,
    gn: Vec3A,
) -> Vec3A {
    let n_obj = s.shading_normal.normalize_or_zero();
    let t_obj = Vec3A::from(tangent.truncate());
    let t_obj = (t_obj - n_obj * n_obj.dot(t_obj)).normalize_or_zero();
    if t_obj == Vec3A::ZERO {
        return sn;
    }
    let b_obj = n_obj.cross(t_obj) * tangent.w;
    let t = xf.to_world.transform_vector3a(t_obj);
    let b = xf.to_world.transform_vector3a(b_obj);
    // The frame's normal as the mesh has it (`sn` may have been turned
    // to the geometric side; the mapped normal is turned with it).
    let n = xf.normal(s.shading_normal);
    let local = map.normal(s.uv);
    let mut mapped = (t * local.x + b * local.y + n * local.z).normalize_or_zero();
    if n.dot(sn) < 0.0 {
        mapped = -mapped;
    }
    if mapped.dot(gn) > 0.0 { mapped } else { sn }
}

/// A uniform number in `[0, 1)` that is a pure function of a ray and a
/// hit distance (stochastic transparency of BLEND surfaces): the same ray
/// meets the same surface the same way whatever the thread or integrator,
/// while the jittered camera rays and the shadow rays of different samples
/// decide independently.
#[inline]
fn ray_hash(ray: &Ray, t: f32) -> f32 {
    let mut h = 0x9e37_79b9_7f4a_7c15u64;
    for v in [
        ray.origin.x,
        ray.origin.y,
        ray.origin.z,
        ray.direction.x,
        ray.direction.y,
        ray.direction.z,
        t,
    ] {
        h = (h ^ v.to_bits() as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 29;
    }
    h = (h ^ (h >> 32)).wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^= h >> 31;
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// The closest hit in `(t_min, t_max)` of an instance's own geometry along
/// `local` (the ray in its object space), alpha ignored: the shape's test,
/// or the mesh's structure (or every triangle, `brute_force`).
#[inline(always)]
fn closest_in_geometry<const AVX: bool>(
    inst: &Instance,
    local: &Ray,
    t_min: f32,
    t_max: f32,
    brute_force: bool,
) -> Option<(f32, LocalHit)> {
    match &inst.geometry {
        InstanceGeometry::Shape(s) => s
            .intersect(local, t_min, t_max)
            .map(|h| (h.t, LocalHit::shape(&h))),
        InstanceGeometry::Mesh(m) => if brute_force {
            m.intersect_brute_force(local, t_min, t_max)
        } else {
            m.intersect_for_surface_kernel::<AVX>(local, t_min, t_max)
        }
        .map(|h| (h.t, LocalHit::Mesh(h))),
    }
}
