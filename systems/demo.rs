//! An animated demo scene, written the way a game would: ordinary
//! components and systems that move entities every tick, with Prism
//! rendering whatever they leave behind. Used by `examples/game_loop.rs`
//! and `benches/frame_loop.rs`.
//!
//! The scene: a ground plane, a vertical mirror, torus knots turning in
//! place, spheres orbiting them, optionally the objects of a glTF file
//! turning about their common centre, one fixed and one wandering point
//! light, and a camera.

use std::f32::consts::TAU;
use std::sync::Arc;

use bevy_ecs::prelude::*;
use glam::{Affine3A, Quat, Vec3};

use super::{MeshInstance, PrismSystems};
use crate::core::math::Color;
use crate::geometry::mesh::{BuildQuality, Mesh, NormalMode};
use crate::geometry::shapes::Shape;
use crate::geometry::transform::Transform;
use crate::io::desc::{Geometry, SceneDesc};
use crate::scene::camera::Camera;
use crate::scene::light::Light;
use crate::scene::material::Material;

/// Animation clock, in seconds of scene time.
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct AnimationTime(pub f32);

/// Circles the vertical axis through `centre`.
#[derive(Component, Clone, Copy, Debug)]
pub struct Orbit {
    /// Centre of the circle.
    pub centre: Vec3,
    /// Radius.
    pub radius: f32,
    /// Radians per second.
    pub speed: f32,
    /// Angle at time zero.
    pub phase: f32,
    /// Amplitude of a vertical bob.
    pub bob: f32,
}

/// Turns about the vertical axis through `pivot`, starting from `base`.
#[derive(Component, Clone, Copy, Debug)]
pub struct Spin {
    /// The transform at time zero.
    pub base: Transform,
    /// World-space point on the rotation axis.
    pub pivot: Vec3,
    /// Radians per second.
    pub speed: f32,
}

/// Sets the transforms of orbiting and spinning entities for the current
/// [`AnimationTime`]. Writes only the transforms it changes.
pub fn animate(
    time: Res<AnimationTime>,
    mut orbits: Query<(&Orbit, &mut Transform), Without<Spin>>,
    mut spins: Query<(&Spin, &mut Transform), Without<Orbit>>,
) {
    let t = time.0;
    for (o, mut tr) in &mut orbits {
        let a = o.phase + o.speed * t;
        let p = o.centre
            + Vec3::new(
                o.radius * a.cos(),
                o.bob * (2.0 * a).sin(),
                o.radius * a.sin(),
            );
        let mut new = *tr;
        new.0.translation = p.as_dvec3();
        if new != *tr {
            *tr = new;
        }
    }
    for (s, mut tr) in &mut spins {
        let r = Affine3A::from_translation(s.pivot)
            * Affine3A::from_rotation_y(s.speed * t)
            * Affine3A::from_translation(-s.pivot);
        *tr = Transform(r.as_daffine3() * s.base.0);
    }
}

/// Adds [`animate`] to `schedule`, before Prism's stages.
pub fn add_animation(world: &mut World, schedule: &mut Schedule) {
    world.init_resource::<AnimationTime>();
    schedule.add_systems(animate.before(PrismSystems::Extract));
}

/// What to put in the demo scene.
#[derive(Clone, Debug)]
pub struct DemoScene {
    /// Triangles per torus knot mesh (two meshes, each instanced twice).
    pub knot_triangles: u32,
    /// Orbiting spheres.
    pub spheres: u32,
    /// Objects (meshes and shapes) of a loaded scene, turned as one group;
    /// its lights and cameras are ignored.
    pub gltf: Option<SceneDesc>,
}

impl Default for DemoScene {
    fn default() -> Self {
        Self {
            knot_triangles: 25_000,
            spheres: 16,
            gltf: None,
        }
    }
}

fn knot(p: u32, q: u32, triangles: u32) -> Arc<Mesh> {
    let sides = 16;
    let segments = (triangles / (2 * sides)).max(8);
    let data = crate::geometry::procedural::torus_knot(p, q, 1.0, 0.28, segments, sides);
    Arc::new(
        Mesh::new("torus knot", data, NormalMode::Smooth, BuildQuality::Medium)
            .expect("procedural knots are valid"),
    )
}

fn colour(i: u32) -> Color {
    let h = i as f32 * 0.61803;
    Color::new(
        0.5 + 0.45 * (TAU * h).cos(),
        0.5 + 0.45 * (TAU * (h + 0.33)).cos(),
        0.5 + 0.45 * (TAU * (h + 0.67)).cos(),
    )
}

impl DemoScene {
    /// Total triangles over all instances (without the glTF objects).
    pub fn triangle_count(&self) -> u64 {
        let sides = 16;
        4 * 2 * sides as u64 * (self.knot_triangles / (2 * sides)).max(8) as u64
    }

    /// Spawns the scene into `world`; returns the camera entity. The
    /// wandering light carries an [`Orbit`].
    pub fn spawn(self, world: &mut World) -> Entity {
        // Ground and mirror.
        world.spawn((
            Transform::default(),
            Shape::Plane,
            Material {
                base_color: Color::splat(0.6),
                ..Default::default()
            },
        ));
        world.spawn((
            Transform::from(
                Affine3A::from_translation(Vec3::new(0.0, 2.6, -7.0))
                    * Affine3A::from_rotation_x(TAU / 4.0),
            ),
            Shape::Disk { radius: 5.0 },
            Material {
                base_color: Color::splat(0.05),
                diffuse: 0.1,
                mirror: Color::splat(0.85),
                ..Default::default()
            },
        ));
        // Knots turning in place.
        let meshes = [
            knot(2, 3, self.knot_triangles),
            knot(3, 5, self.knot_triangles),
        ];
        let spots = [
            Vec3::new(-4.5, 1.4, -1.5),
            Vec3::new(4.5, 1.4, -1.5),
            Vec3::new(-2.0, 1.4, 2.5),
            Vec3::new(2.0, 1.4, 2.5),
        ];
        for (i, &p) in spots.iter().enumerate() {
            let base = Transform::from(Affine3A::from_rotation_translation(
                Quat::from_rotation_x(0.4 * i as f32),
                p,
            ));
            world.spawn((
                base,
                MeshInstance(meshes[i % 2].clone()),
                Material {
                    base_color: colour(i as u32 + 7),
                    specular: Color::splat(0.3),
                    shininess: 40.0,
                    ..Default::default()
                },
                Spin {
                    base,
                    pivot: p,
                    speed: 0.6 + 0.2 * i as f32,
                },
            ));
        }
        // Orbiting spheres.
        for i in 0..self.spheres {
            let mirror = i % 5 == 0;
            world.spawn((
                Transform::default(),
                Shape::Sphere {
                    radius: 0.3 + 0.1 * (i % 3) as f32,
                },
                Material {
                    base_color: colour(i),
                    mirror: Color::splat(if mirror { 0.7 } else { 0.0 }),
                    diffuse: if mirror { 0.3 } else { 1.0 },
                    specular: Color::splat(0.2),
                    shininess: 60.0,
                    ..Default::default()
                },
                Orbit {
                    centre: Vec3::new(0.0, 0.9, 0.0),
                    radius: 3.0 + 3.5 * (i as f32 / self.spheres.max(1) as f32),
                    speed: 0.5 + 0.05 * i as f32,
                    phase: i as f32 * 2.4,
                    bob: 0.4,
                },
            ));
        }
        // A loaded scene's mesh objects, scaled to about 2.5 units and
        // turning; flat ones (floors) are left out.
        if let Some(desc) = self.gltf {
            let bounds = |o: &crate::io::desc::ObjectDesc| {
                let Geometry::Mesh(m) = &o.geometry else {
                    return None;
                };
                let (a, b) = m.bounds()?;
                let mut lo = Vec3::splat(f32::INFINITY);
                let mut hi = Vec3::splat(f32::NEG_INFINITY);
                for i in 0..8 {
                    let c = Vec3::new(
                        if i & 1 == 0 { a.x } else { b.x },
                        if i & 2 == 0 { a.y } else { b.y },
                        if i & 4 == 0 { a.z } else { b.z },
                    );
                    let w = o.transform.0.transform_point3(c.as_dvec3()).as_vec3();
                    lo = lo.min(w);
                    hi = hi.max(w);
                }
                let e = hi - lo;
                (e.min_element() > 0.01 * e.max_element()).then_some((lo, hi))
            };
            let kept: Vec<_> = desc
                .objects
                .into_iter()
                .filter_map(|o| bounds(&o).map(|b| (o, b)))
                .collect();
            let lo = kept.iter().fold(Vec3::INFINITY, |l, (_, b)| l.min(b.0));
            let hi = kept.iter().fold(Vec3::NEG_INFINITY, |h, (_, b)| h.max(b.1));
            let size = (hi - lo).max_element();
            if size.is_finite() && size > 0.0 {
                let pivot = Vec3::new(0.0, 0.0, 0.0);
                let fit = Affine3A::from_scale(Vec3::splat(2.5 / size))
                    * Affine3A::from_translation(Vec3::new(
                        -(lo.x + hi.x) * 0.5,
                        -lo.y,
                        -(lo.z + hi.z) * 0.5,
                    ));
                for (o, _) in kept {
                    let base = Transform(fit.as_daffine3() * o.transform.0);
                    if !base.is_valid() {
                        continue;
                    }
                    let mut e = world.spawn((
                        base,
                        o.material,
                        Spin {
                            base,
                            pivot,
                            speed: -0.8,
                        },
                    ));
                    if let Geometry::Mesh(m) = o.geometry {
                        e.insert(MeshInstance(m));
                    }
                }
            }
        }
        // One fixed light and one wandering above the scene.
        world.spawn((
            Transform::from_translation(glam::DVec3::new(-6.0, 9.0, 8.0)),
            Light::Point {
                intensity: Color::splat(250.0),
            },
        ));
        world.spawn((
            Transform::default(),
            Light::Point {
                intensity: Color::new(160.0, 130.0, 90.0),
            },
            Orbit {
                centre: Vec3::new(0.0, 6.0, 0.0),
                radius: 5.0,
                speed: 0.7,
                phase: 0.0,
                bob: 1.0,
            },
        ));
        world
            .spawn(Camera {
                look_from: glam::DVec3::new(0.0, 5.5, 14.0),
                look_at: glam::DVec3::new(0.0, 1.2, 0.0),
                up: Vec3::Y,
                vfov_degrees: 45.0,
                shift: glam::Vec2::ZERO,
                name: None,
                ..Default::default()
            })
            .id()
    }
}
