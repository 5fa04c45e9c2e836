//! The render-ready scene: instances in world space, a top-level BVH over
//! them, materials and lights. Built from ECS data by the systems module,
//! or directly from a [`crate::io::desc::SceneDesc`] in tests.

pub mod camera;
pub mod emitters;
pub mod features;
pub mod light;
pub mod material;

use std::sync::Arc;
use std::time::Instant;

use glam::{Vec2, Vec3A};
use obvhs::aabb::Aabb;

use crate::accel::build::{BuildQuality, MAX_COORDINATE, padded_aabb};
use crate::accel::packet::{self, ALL_LANES, LANES, LaneMask, Packet, for_each_lane};
use crate::accel::single::traverse_bvh;
use crate::accel::tlas::{Placement, Tlas, TlasCounters, TlasPolicy, TlasUpdate};
use crate::core::math::{Color, Ray};
use crate::geometry::mesh::Mesh;
use crate::geometry::shapes::Shape;
use crate::geometry::transform::{InstanceTransform, Transform};
use crate::scene::emitters::EmitterTable;
use crate::scene::light::WorldLight;
use crate::scene::material::Material;

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

/// The geometry of one instance.
#[derive(Clone, Debug)]
pub enum InstanceGeometry {
    /// An analytic shape, intersected in object space.
    Shape(Shape),
    /// A shared triangle mesh with its own BVH.
    Mesh(Arc<Mesh>),
}

/// One object placed in the world.
#[derive(Clone, Debug)]
pub struct Instance {
    /// Shape or mesh.
    pub geometry: InstanceGeometry,
    /// World/object matrices.
    pub transform: InstanceTransform,
    /// Index into [`RenderScene::materials`].
    pub material: u32,
}

impl Instance {
    /// Creates an instance; the transform must be valid.
    pub fn new(geometry: InstanceGeometry, transform: &Transform, material: u32) -> Self {
        Self {
            geometry,
            transform: InstanceTransform::new(transform),
            material,
        }
    }

    /// Where the top level puts this instance.
    pub fn placement(&self) -> Placement {
        match self.world_bounds() {
            Some(b) => Placement::Bounded(b),
            None => match &self.geometry {
                InstanceGeometry::Mesh(m) if m.triangle_count() == 0 => Placement::Nowhere,
                _ => Placement::Unbounded,
            },
        }
    }

    /// World-space bounds, `None` if unbounded (planes), empty, or too
    /// large for the BVH builder (beyond [`MAX_COORDINATE`]); such
    /// instances are tested one by one instead.
    pub fn world_bounds(&self) -> Option<Aabb> {
        let (lo, hi) = match &self.geometry {
            InstanceGeometry::Shape(s) => s.bounds()?,
            InstanceGeometry::Mesh(m) => m.bounds()?,
        };
        let m = &self.transform.to_world;
        let mut wlo = Vec3A::splat(f32::INFINITY);
        let mut whi = Vec3A::splat(f32::NEG_INFINITY);
        for i in 0..8 {
            let c = Vec3A::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let w = m.transform_point3a(c);
            wlo = wlo.min(w);
            whi = whi.max(w);
        }
        let fits = |v: Vec3A| v.is_finite() && v.abs().max_element() <= MAX_COORDINATE;
        (fits(wlo) && fits(whi)).then(|| padded_aabb(wlo, whi))
    }
}

/// A surface point found by a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// World-space position.
    pub point: Vec3A,
    /// Unit geometric normal in world space, as the geometry defines it
    /// (outward for closed shapes; not flipped towards the ray).
    pub geometric_normal: Vec3A,
    /// Unit shading normal in world space, on the same side as the
    /// geometric normal.
    pub shading_normal: Vec3A,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Instance index.
    pub instance: u32,
    /// Material index.
    pub material: u32,
}

/// What an object-space intersection found, before world-space
/// attributes are computed (done once, for the closest hit only).
#[derive(Clone, Copy, Debug)]
enum LocalHit {
    Shape {
        point: Vec3A,
        normal: Vec3A,
        uv: Vec2,
    },
    Mesh(crate::geometry::mesh::MeshHit),
}

impl LocalHit {
    #[inline]
    fn shape(h: &crate::geometry::shapes::ShapeHit) -> Self {
        LocalHit::Shape {
            point: h.point,
            normal: h.normal,
            uv: h.uv,
        }
    }
}

/// A scene ready for rendering: instances, top-level BVH, materials, lights.
#[derive(Debug)]
pub struct RenderScene {
    /// All instances; the top-level BVH indexes this array.
    pub instances: Vec<Instance>,
    /// Materials referenced by instances.
    pub materials: Vec<Material>,
    /// Lights in world space.
    pub lights: Vec<WorldLight>,
    /// Radiance of escaped rays.
    pub background: Color,
    /// Emissive surfaces as area lights, for path tracing (rebuilt by
    /// [`RenderScene::commit`] when instances or materials change).
    pub emitters: EmitterTable,
    /// Set by changes to instances or materials: the emitter table is
    /// rebuilt at the next commit.
    emitters_stale: bool,
    /// Top-level BVH over bounded instances, the instance of each of its
    /// leaf slots, and the unbounded instances (infinite planes) tested one
    /// by one.
    tlas: Tlas,
    /// Seconds spent building the top-level BVH (by [`RenderScene::new`],
    /// or by the last [`RenderScene::commit`] that changed it).
    pub tlas_build_seconds: f64,
}

/// Converts an instance ray to object space.
#[inline]
fn to_object(inst: &Instance, ray: &Ray) -> Ray {
    let m = &inst.transform.to_object;
    Ray::new(
        m.transform_point3a(ray.origin),
        m.transform_vector3a(ray.direction),
    )
}

impl RenderScene {
    /// Builds the top-level BVH over `instances`.
    pub fn new(
        instances: Vec<Instance>,
        materials: Vec<Material>,
        lights: Vec<WorldLight>,
        background: Color,
        quality: BuildQuality,
    ) -> Self {
        let start = Instant::now();
        let tlas = Tlas::build(instances.len(), |i| instances[i].placement(), quality);
        let emitters = EmitterTable::build(&instances, &materials);
        Self {
            instances,
            materials,
            lights,
            background,
            emitters,
            emitters_stale: false,
            tlas,
            tlas_build_seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// Total triangles over all instances (instanced meshes count once per
    /// instance).
    pub fn triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| match &i.geometry {
                InstanceGeometry::Mesh(m) => m.triangle_count(),
                InstanceGeometry::Shape(_) => 0,
            })
            .sum()
    }

    #[inline]
    fn intersect_instance(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, LocalHit)> {
        self.intersect_instance_with(index, ray, t_min, t_max, false)
    }

    /// Closest hit on one instance; meshes by their BVH, or by testing
    /// every triangle when `brute_force` is set.
    #[inline]
    fn intersect_instance_with(
        &self,
        index: u32,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        brute_force: bool,
    ) -> Option<(f32, LocalHit)> {
        let inst = &self.instances[index as usize];
        let local = to_object(inst, ray);
        match &inst.geometry {
            InstanceGeometry::Shape(s) => s
                .intersect(&local, t_min, t_max)
                .map(|h| (h.t, LocalHit::shape(&h))),
            InstanceGeometry::Mesh(m) => if brute_force {
                m.intersect_brute_force(&local, t_min, t_max)
            } else {
                m.intersect(&local, t_min, t_max)
            }
            .map(|h| (h.t, LocalHit::Mesh(h))),
        }
    }

    #[inline]
    fn occludes_instance(&self, index: u32, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        let inst = &self.instances[index as usize];
        let local = to_object(inst, ray);
        match &inst.geometry {
            InstanceGeometry::Shape(s) => s.intersect(&local, t_min, t_max).is_some(),
            InstanceGeometry::Mesh(m) => m.occluded(&local, t_min, t_max),
        }
    }

    /// The closest hit with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let mut best: Option<(f32, u32, LocalHit)> = None;
        let mut t_max = t_max;
        for &i in &self.tlas.unbounded {
            if let Some((t, h)) = self.intersect_instance(i, ray, t_min, t_max) {
                t_max = t;
                best = Some((t, i, h));
            }
        }
        if !self.tlas.leaf_instances.is_empty() {
            traverse_bvh(&self.tlas.cw, ray, t_min, t_max, false, |slot, t_max| {
                let inst = self.tlas.leaf_instances[slot];
                let (t, h) = self.intersect_instance(inst, ray, t_min, t_max)?;
                best = Some((t, inst, h));
                Some(t)
            });
        }
        let (t, index, local) = best?;
        Some(self.finish_hit(t, index, local))
    }

    /// True when anything blocks the ray between `t_min` and `t_max`; stops
    /// at the first blocker found.
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        if self
            .tlas
            .unbounded
            .iter()
            .any(|&i| self.occludes_instance(i, ray, t_min, t_max))
        {
            return true;
        }
        if self.tlas.leaf_instances.is_empty() {
            return false;
        }
        traverse_bvh(&self.tlas.cw, ray, t_min, t_max, true, |slot, t_max| {
            self.occludes_instance(self.tlas.leaf_instances[slot], ray, t_min, t_max)
                .then_some(t_min)
        })
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
    fn top_level_packet(
        &self,
        rays: &[Ray],
        best: &mut [Option<(f32, u32, LocalHit)>],
        mut mesh: impl FnMut(
            &mut Packet,
            LaneMask,
            u32,
            &Instance,
            &Mesh,
            &mut [Option<(f32, u32, LocalHit)>],
        ),
    ) {
        let n = rays.len().min(LANES);
        let mut t_max = [f32::INFINITY; LANES];
        for (l, ray) in rays[..n].iter().enumerate() {
            for &i in &self.tlas.unbounded {
                if let Some((t, h)) = self.intersect_instance(i, ray, 0.0, t_max[l]) {
                    t_max[l] = t;
                    best[l] = Some((t, i, h));
                }
            }
        }
        let mut packet = Packet::new(&rays[..n], &[0.0; LANES][..n], &t_max[..n]);
        packet::traverse(&self.tlas.cw, &mut packet, ALL_LANES, |p, lanes, slot| {
            let index = self.tlas.leaf_instances[slot];
            let inst = &self.instances[index as usize];
            match &inst.geometry {
                InstanceGeometry::Shape(s) => for_each_lane(lanes, |l| {
                    let local = to_object(inst, &p.rays[l]);
                    if let Some(h) = s.intersect(&local, p.t_min[l], p.t_max[l]) {
                        p.t_max[l] = h.t;
                        best[l] = Some((h.t, index, LocalHit::shape(&h)));
                    }
                }),
                InstanceGeometry::Mesh(m) => mesh(p, lanes, index, inst, m, best),
            }
            0
        });
    }

    /// [`RenderScene::intersect_packet`], with the top level traversed as a
    /// packet and each mesh either as a packet (`mesh_packets`) or one lane
    /// at a time, for rays too incoherent to share a mesh's nodes.
    pub fn intersect_packet_with(&self, rays: &[Ray], out: &mut [Option<Hit>], mesh_packets: bool) {
        let n = rays.len().min(LANES);
        let mut best: [Option<(f32, u32, LocalHit)>; LANES] = [None; LANES];
        self.top_level_packet(rays, &mut best, |p, lanes, index, inst, m, best| {
            let mut hits = [None; LANES];
            if mesh_packets {
                let mut local = Packet::new(&[], &[], &[]);
                for_each_lane(lanes, |l| {
                    local.set_lane(l, to_object(inst, &p.rays[l]), p.t_min[l], p.t_max[l])
                });
                m.intersect_packet(&mut local, lanes, &mut hits);
            } else {
                for_each_lane(lanes, |l| {
                    hits[l] = m.intersect(&to_object(inst, &p.rays[l]), p.t_min[l], p.t_max[l]);
                });
            }
            for_each_lane(lanes, |l| {
                if let Some(h) = hits[l] {
                    p.t_max[l] = h.t;
                    best[l] = Some((h.t, index, LocalHit::Mesh(h)));
                }
            });
        });
        for (l, o) in out[..n].iter_mut().enumerate() {
            *o = best[l].map(|(t, i, h)| self.finish_hit(t, i, h));
        }
    }

    /// Closest hits of all `rays` (each searched in `(0, inf)`), by
    /// streams: the top level is traversed in packets of eight
    /// consecutive rays, shapes are intersected there, and every ray that
    /// reaches a mesh instance joins that instance's stream for its
    /// direction octant; each stream then traverses the mesh's BVH at once
    /// ([`crate::accel::stream`]). The same hits as [`RenderScene::intersect`] on
    /// each ray. `scratch` keeps the buffers between calls.
    pub fn intersect_stream(
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
            self.top_level_packet(packet_rays, best, |p, lanes, index, inst, _, _| {
                for_each_lane(lanes, |l| {
                    let d = inst
                        .transform
                        .to_object
                        .transform_vector3a(p.rays[l].direction);
                    let octant =
                        (d.x < 0.0) as u64 | ((d.y < 0.0) as u64) << 1 | ((d.z < 0.0) as u64) << 2;
                    deferred.push((index as u64) << 35 | octant << 32 | (first + l) as u64);
                })
            });
        }
        // One stream per (instance, octant), in a fixed order.
        deferred.sort_unstable();
        let mut rest = &deferred[..];
        while let Some(&key) = rest.first() {
            let group = rest.partition_point(|&k| k >> 32 == key >> 32);
            let index = (key >> 35) as u32;
            let inst = &self.instances[index as usize];
            let InstanceGeometry::Mesh(mesh) = &inst.geometry else {
                unreachable!("only meshes are deferred")
            };
            stream.clear();
            for &k in &rest[..group] {
                let i = (k & RAY_BITS) as usize;
                let t_max = best[i].as_ref().map_or(f32::INFINITY, |b| b.0);
                stream.push(to_object(inst, &rays[i]), 0.0, t_max);
            }
            mesh.intersect_stream(stream, wt, mesh_hits);
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

    /// [`RenderScene::occluded_packet`], with meshes traversed as a packet
    /// (`mesh_packets`) or one lane at a time.
    pub fn occluded_packet_with(
        &self,
        rays: &[Ray],
        t_max: &[f32],
        mesh_packets: bool,
    ) -> LaneMask {
        let n = rays.len().min(LANES);
        let mut blocked: LaneMask = 0;
        for (l, ray) in rays[..n].iter().enumerate() {
            if self
                .tlas
                .unbounded
                .iter()
                .any(|&i| self.occludes_instance(i, ray, 0.0, t_max[l]))
            {
                blocked |= 1 << l;
            }
        }
        let mut packet = Packet::new(&rays[..n], &[0.0; LANES][..n], &t_max[..n]);
        let todo = ALL_LANES & !blocked;
        packet::traverse(&self.tlas.cw, &mut packet, todo, |p, lanes, slot| {
            let inst = &self.instances[self.tlas.leaf_instances[slot] as usize];
            let now = match &inst.geometry {
                InstanceGeometry::Shape(s) => {
                    let mut now = 0;
                    for_each_lane(lanes, |l| {
                        let local = to_object(inst, &p.rays[l]);
                        if s.intersect(&local, p.t_min[l], p.t_max[l]).is_some() {
                            now |= 1 << l;
                        }
                    });
                    now
                }
                InstanceGeometry::Mesh(m) if !mesh_packets => {
                    let mut now = 0;
                    for_each_lane(lanes, |l| {
                        let local = to_object(inst, &p.rays[l]);
                        if m.occluded(&local, p.t_min[l], p.t_max[l]) {
                            now |= 1 << l;
                        }
                    });
                    now
                }
                InstanceGeometry::Mesh(m) => {
                    let mut local = Packet::new(&[], &[], &[]);
                    for_each_lane(lanes, |l| {
                        local.set_lane(l, to_object(inst, &p.rays[l]), p.t_min[l], p.t_max[l])
                    });
                    m.occluded_packet(&mut local, lanes)
                }
            };
            blocked |= now;
            now
        });
        blocked & packet.valid
    }

    /// The closest hit found by testing every instance, and every triangle
    /// of every mesh, without any BVH: the reference that BVH traversal is
    /// tested against.
    pub fn intersect_brute_force(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let mut best: Option<(f32, u32, LocalHit)> = None;
        let mut t_max = t_max;
        for i in 0..self.instances.len() as u32 {
            if let Some((t, h)) = self.intersect_instance_with(i, ray, t_min, t_max, true) {
                t_max = t;
                best = Some((t, i, h));
            }
        }
        let (t, index, local) = best?;
        Some(self.finish_hit(t, index, local))
    }

    fn finish_hit(&self, t: f32, index: u32, local: LocalHit) -> Hit {
        let inst = &self.instances[index as usize];
        let xf = &inst.transform;
        // The point comes from the object-space surface point, correct to a
        // few ulps of its own coordinates; `ray.at(t)` would carry the
        // rounding of a possibly distant ray origin.
        let (point, gn, sn, uv) = match (local, &inst.geometry) {
            (LocalHit::Shape { point, normal, uv }, _) => {
                let n = xf.normal(normal);
                (xf.to_world.transform_point3a(point), n, n, uv)
            }
            (LocalHit::Mesh(h), InstanceGeometry::Mesh(m)) => {
                let s = m.surface(&h);
                let gn = xf.normal(s.geometric_normal);
                let mut sn = xf.normal(s.shading_normal);
                if sn.dot(gn) < 0.0 {
                    sn = -sn;
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
            instance: index,
            material: inst.material,
        }
    }
}

/// Incremental updates, for scenes that change from frame to frame.
///
/// Every change goes through these methods and becomes visible to
/// traversal at the next [`RenderScene::commit`], which is also the one
/// place where anything derived from instances and materials is brought up
/// to date. Between a change and the commit, intersection queries must not
/// be made. Mesh BVHs are never rebuilt: they live in the shared
/// [`Mesh`]es; only the top level over instances changes.
impl RenderScene {
    /// Appends an instance; returns its index. Its material index must be
    /// valid once the scene is committed.
    pub fn push_instance(&mut self, instance: Instance) -> u32 {
        self.emitters_stale = true;
        let index = self.instances.len() as u32;
        self.tlas.inserted(index, instance.placement());
        self.instances.push(instance);
        index
    }

    /// Removes instance `index` by moving the last instance into its place
    /// (so the last instance's index becomes `index`); returns the removed
    /// instance. Panics if `index` is out of range.
    pub fn swap_remove_instance(&mut self, index: u32) -> Instance {
        self.emitters_stale = true;
        let last = self.instances.len() as u32 - 1;
        assert!(index <= last, "instance {index} out of range");
        self.tlas.removing(index, last);
        self.instances.swap_remove(index as usize)
    }

    /// Moves instance `index`; `transform` must be valid
    /// ([`Transform::is_valid`]).
    pub fn set_instance_transform(&mut self, index: u32, transform: &Transform) {
        self.emitters_stale = true;
        let inst = &mut self.instances[index as usize];
        inst.transform = crate::geometry::transform::InstanceTransform::new(transform);
        self.tlas.updated(index, inst.placement());
    }

    /// Gives instance `index` another shape or mesh (the mesh's own BVH is
    /// reused as it is).
    pub fn set_instance_geometry(&mut self, index: u32, geometry: InstanceGeometry) {
        self.emitters_stale = true;
        let inst = &mut self.instances[index as usize];
        inst.geometry = geometry;
        self.tlas.updated(index, inst.placement());
    }

    /// Points instance `index` at material `material`.
    pub fn set_instance_material(&mut self, index: u32, material: u32) {
        self.emitters_stale = true;
        self.instances[index as usize].material = material;
    }

    /// Appends a material; returns its index.
    pub fn push_material(&mut self, material: Material) -> u32 {
        self.emitters_stale = true;
        self.materials.push(material);
        self.materials.len() as u32 - 1
    }

    /// Replaces material `index`. Touches no BVH.
    pub fn set_material(&mut self, index: u32, material: Material) {
        self.emitters_stale = true;
        self.materials[index as usize] = material;
    }

    /// Removes material `index` by moving the last material into its
    /// place; instances that used the last material are pointed at
    /// `index`. No instance may still use the removed material.
    pub fn swap_remove_material(&mut self, index: u32) -> Material {
        self.emitters_stale = true;
        let last = self.materials.len() as u32 - 1;
        assert!(index <= last, "material {index} out of range");
        if index != last {
            for inst in &mut self.instances {
                if inst.material == last {
                    inst.material = index;
                }
            }
        }
        self.materials.swap_remove(index as usize)
    }

    /// Replaces the lights.
    pub fn set_lights(&mut self, lights: Vec<WorldLight>) {
        self.lights = lights;
    }

    /// Sets the radiance of escaped rays.
    pub fn set_background(&mut self, background: Color) {
        self.background = background;
    }

    /// Makes the changes since the last commit visible: rebuilds the
    /// emitter table if instances or materials changed, updates the top
    /// level (leaf updates then a conversion, or a full rebuild above the
    /// churn threshold of [`TlasPolicy`]), and returns what was done to
    /// the top level.
    pub fn commit(&mut self) -> TlasUpdate {
        if self.emitters_stale {
            // Area lights follow moved, added, removed and re-materialed
            // instances; this is a table, not a BVH.
            self.emitters = EmitterTable::build(&self.instances, &self.materials);
            self.emitters_stale = false;
        }
        let instances = &self.instances;
        let update = self
            .tlas
            .commit(instances.len(), |i| instances[i].placement());
        if update != TlasUpdate::Unchanged {
            self.tlas_build_seconds = self.tlas.last_seconds;
        }
        update
    }

    /// Cumulative work done on the top level.
    pub fn tlas_counters(&self) -> TlasCounters {
        self.tlas.counters()
    }

    /// The policy deciding between leaf updates and rebuilds.
    pub fn tlas_policy(&self) -> TlasPolicy {
        self.tlas.policy
    }

    /// Changes the policy deciding between leaf updates and rebuilds.
    pub fn set_tlas_policy(&mut self, policy: TlasPolicy) {
        self.tlas.policy = policy;
    }
}
