//! Components that exist only for the ECS side. The kernel types that
//! entities carry directly ([`Transform`](crate::geometry::transform::Transform),
//! [`Shape`](crate::geometry::shapes::Shape), [`Material`](crate::scene::material::Material),
//! [`Light`](crate::scene::light::Light), [`Camera`](crate::scene::camera::Camera))
//! derive `Component` where they are defined.

use std::sync::Arc;

use bevy_ecs::component::Component;

use crate::geometry::mesh::Mesh;

/// The entity is an instance of this shared mesh (its BVH is built once
/// and shared by every instance).
#[derive(Component, Clone, Debug)]
pub struct MeshInstance(pub Arc<Mesh>);
