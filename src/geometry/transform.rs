//! Object-to-world transforms.

use bevy_ecs::component::Component;
use glam::{Affine3A, Mat3A, Quat, Vec3, Vec3A};

/// An entity's object-to-world transform.
///
/// Stored as a full affine matrix rather than translation/rotation/scale so
/// that flattened glTF hierarchies (which may shear under non-uniform
/// scale) are represented exactly.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Transform(pub Affine3A);

impl Default for Transform {
    fn default() -> Self {
        Self(Affine3A::IDENTITY)
    }
}

impl Transform {
    /// Scale, then rotate, then translate.
    pub fn from_trs(translation: Vec3, rotation: Quat, scale: Vec3) -> Self {
        Self(Affine3A::from_scale_rotation_translation(
            scale,
            rotation,
            translation,
        ))
    }

    /// A pure translation.
    pub fn from_translation(t: Vec3) -> Self {
        Self(Affine3A::from_translation(t))
    }

    /// True when every matrix entry is finite and the linear part is invertible.
    pub fn is_valid(&self) -> bool {
        let det = self.0.matrix3.determinant();
        self.0.is_finite() && det.is_finite() && det.abs() > 1e-30
    }
}

/// Precomputed matrices an instance needs to move rays and normals between
/// world and object space.
#[derive(Clone, Copy, Debug)]
pub struct InstanceTransform {
    /// Object to world.
    pub to_world: Affine3A,
    /// World to object.
    pub to_object: Affine3A,
    /// Inverse transpose of the linear part: maps object-space normals to
    /// world space.
    pub normal_to_world: Mat3A,
}

impl InstanceTransform {
    /// Precomputes inverse and normal matrix. The caller guarantees
    /// [`Transform::is_valid`].
    pub fn new(t: &Transform) -> Self {
        let to_object = t.0.inverse();
        Self {
            to_world: t.0,
            to_object,
            normal_to_world: to_object.matrix3.transpose(),
        }
    }

    /// Object-space normal to a unit world-space normal.
    #[inline]
    pub fn normal(&self, n: Vec3A) -> Vec3A {
        (self.normal_to_world * n).normalize_or_zero()
    }
}
