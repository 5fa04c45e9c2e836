//! Object-to-world transforms.
//!
//! Scene-level placements ([`Transform`]) are kept in double precision:
//! glTF node hierarchies, the TOML format's placements and the ECS
//! components compose in f64, so a scene placed 1e9 units from the world
//! origin loses nothing. The kernels work in single precision in a frame
//! centred on a *render origin* chosen in f64 (by default the camera):
//! [`Transform::relative_to`] subtracts that origin in f64 and only then
//! rounds to f32, so what the kernels see is as precise as the distance to
//! the render origin allows, whatever the distance to the world origin.

use bevy_ecs::component::Component;
use glam::{Affine3A, DAffine3, DQuat, DVec3, Mat3A, Quat, Vec3, Vec3A};

/// An entity's object-to-world transform, in double precision.
///
/// Stored as a full affine matrix rather than translation/rotation/scale so
/// that flattened glTF hierarchies (which may shear under non-uniform
/// scale) are represented exactly.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Transform(pub DAffine3);

impl Default for Transform {
    fn default() -> Self {
        Self(DAffine3::IDENTITY)
    }
}

impl From<Affine3A> for Transform {
    /// Widens a single-precision affine transform (exactly).
    fn from(a: Affine3A) -> Self {
        Self(a.as_daffine3())
    }
}

impl Transform {
    /// Scale, then rotate, then translate.
    pub fn from_trs(translation: DVec3, rotation: DQuat, scale: DVec3) -> Self {
        Self(DAffine3::from_scale_rotation_translation(
            scale,
            rotation,
            translation,
        ))
    }

    /// [`Transform::from_trs`] from single-precision parts (widened
    /// exactly; the composition is done in f64).
    pub fn from_trs_f32(translation: Vec3, rotation: Quat, scale: Vec3) -> Self {
        Self::from_trs(
            translation.as_dvec3(),
            rotation.as_dquat(),
            scale.as_dvec3(),
        )
    }

    /// A pure translation.
    pub fn from_translation(t: DVec3) -> Self {
        Self(DAffine3::from_translation(t))
    }

    /// True when every matrix entry is finite and the linear part is invertible.
    pub fn is_valid(&self) -> bool {
        let det = self.0.matrix3.determinant();
        self.0.is_finite() && det.is_finite() && det.abs() > 1e-30
    }

    /// The transform from object space to the frame centred on `origin`
    /// (world minus `origin`), rounded to single precision only after the
    /// subtraction.
    pub fn relative_to(&self, origin: DVec3) -> Affine3A {
        let mut a = self.0;
        a.translation -= origin;
        a.as_affine3a()
    }

    /// The world-space position of the object's origin.
    pub fn translation(&self) -> DVec3 {
        self.0.translation
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
    /// Precomputes inverse and normal matrix of `to_world` (object space to
    /// the render frame; see [`Transform::relative_to`]). The caller
    /// guarantees that it is invertible ([`Transform::is_valid`]).
    pub fn new(to_world: Affine3A) -> Self {
        let to_object = to_world.inverse();
        Self {
            to_world,
            to_object,
            normal_to_world: to_object.matrix3.transpose(),
        }
    }

    /// The matrices of `t` in the frame centred on `origin`: the
    /// subtraction and the inverse are computed in f64, then rounded.
    pub fn placed(t: &Transform, origin: DVec3) -> Self {
        let mut rel = t.0;
        rel.translation -= origin;
        let inv = rel.inverse();
        Self {
            to_world: rel.as_affine3a(),
            to_object: inv.as_affine3a(),
            normal_to_world: Mat3A::from(inv.matrix3.transpose().as_mat3()),
        }
    }

    /// Object-space normal to a unit world-space normal.
    #[inline]
    pub fn normal(&self, n: Vec3A) -> Vec3A {
        (self.normal_to_world * n).normalize_or_zero()
    }
}
