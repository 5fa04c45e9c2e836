//! Instances (a shape or a shared mesh placed in the world with a
//! material) and the hits that rays find on them.

use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3A};
use obvhs::aabb::Aabb;

use crate::accel::build::{MAX_COORDINATE, padded_aabb};
use crate::accel::tlas::Placement;
use crate::core::math::Ray;
use crate::geometry::mesh::Mesh;
use crate::geometry::shapes::Shape;
use crate::geometry::transform::{InstanceTransform, Transform};

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
    /// The placement in world coordinates, in double precision.
    pub world: Transform,
    /// Object/render-frame matrices: `world` relative to the scene's
    /// render origin, in single precision (see
    /// [`RenderScene::origin`](crate::scene::RenderScene::origin)).
    pub transform: InstanceTransform,
    /// Index into [`RenderScene::materials`](crate::scene::RenderScene::materials).
    pub material: u32,
}

impl Instance {
    /// Creates an instance; the transform must be valid. Its render-frame
    /// matrices are relative to the world origin until a scene rebases
    /// them ([`Instance::rebase`]; [`RenderScene`](crate::scene::RenderScene)
    /// does when the instance is added).
    pub fn new(geometry: InstanceGeometry, transform: &Transform, material: u32) -> Self {
        Self {
            geometry,
            world: *transform,
            transform: InstanceTransform::placed(transform, DVec3::ZERO),
            material,
        }
    }

    /// Recomputes the render-frame matrices relative to `origin`.
    pub fn rebase(&mut self, origin: DVec3) {
        self.transform = InstanceTransform::placed(&self.world, origin);
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
    /// Position in the scene's render frame: the world point minus
    /// [`RenderScene::origin`](crate::scene::RenderScene::origin).
    pub point: Vec3A,
    /// Unit geometric normal in world space, as the geometry defines it
    /// (outward for closed shapes; not flipped towards the ray).
    pub geometric_normal: Vec3A,
    /// Unit shading normal in world space, on the same side as the
    /// geometric normal.
    pub shading_normal: Vec3A,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Texture coordinates per unit of world length at the hit: the square
    /// root of the texture area per world area of the surface (texture
    /// level of detail), or 0 where it is not derived or not needed (an
    /// untextured material; then lookups read the full-resolution texture).
    pub uv_density: f32,
    /// Instance index.
    pub instance: u32,
    /// Material index.
    pub material: u32,
}

/// What an object-space intersection found, before world-space
/// attributes are computed (done once, for the closest hit only).
#[derive(Clone, Copy, Debug)]
pub(crate) enum LocalHit {
    Shape {
        point: Vec3A,
        normal: Vec3A,
        uv: Vec2,
    },
    Mesh(crate::geometry::mesh::MeshHit),
}

impl LocalHit {
    #[inline]
    pub(crate) fn shape(h: &crate::geometry::shapes::ShapeHit) -> Self {
        LocalHit::Shape {
            point: h.point,
            normal: h.normal,
            uv: h.uv,
        }
    }
}

/// Converts an instance ray to object space.
#[inline]
pub(crate) fn to_object(inst: &Instance, ray: &Ray) -> Ray {
    let m = &inst.transform.to_object;
    Ray::new(
        m.transform_point3a(ray.origin),
        m.transform_vector3a(ray.direction),
    )
}
