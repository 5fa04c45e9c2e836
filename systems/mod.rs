//! The ECS side of Prism: resources, system sets and the systems that turn
//! a `bevy_ecs` world into an image by calling the kernels.
//!
//! A scene is a world of entities carrying the components
//! [`Transform`](crate::geometry::transform::Transform), [`Shape`](crate::geometry::shapes::Shape)
//! or [`MeshInstance`],
//! [`Material`](crate::scene::material::Material), [`Light`](crate::scene::light::Light)
//! and [`Camera`](crate::scene::camera::Camera). Each frame runs three stages, declared once in
//! [`add_render_systems`]:
//!
//! 1. [`PrismSystems::Extract`]: apply what changed in the world since the
//!    last frame to the persistent scene, through change detection (see
//!    [`sync`]), and read the camera;
//! 2. [`PrismSystems::Accelerate`]: update the top-level BVH
//!    ([`sync::commit_scene`]);
//! 3. [`PrismSystems::Render`]: trace the image into [`Frame`], with
//!    [`render_recursive`] or, stage by stage, with the wavefront systems
//!    of [`wavefront`] (driven by [`wavefront::render_wavefront`]), or,
//!    under radiosity transport, from the solution kept between frames
//!    ([`radiosity::render_radiosity`]), then,
//!    only when the settings ask for them, the feature lines
//!    ([`lines::render_feature_lines`]).
//!
//! Games add these stages to their own schedule with [`PrismPlugin`]; see
//! its example. With [`ProgressiveRendering`] on, frames of an unchanged
//! scene accumulate samples.
//!
//! This module is compiled as part of the `prism` crate (one crate keeps
//! the build short and the binary simple); the kernels in `src/` never
//! refer to it.

pub mod components;
pub mod demo;
pub mod frame;
pub mod lightfield;
pub mod lines;
pub mod radiosity;
pub mod render;
pub mod renderer;
pub mod sync;
pub mod wavefront;

pub use components::MeshInstance;
pub use frame::{
    AccumulationState, ExtractedScene, Frame, ProgressFn, ProgressiveRendering, RenderConfig,
    RenderOrigin, SceneAccel,
};
pub use render::{frame_preconditions, integrator_is, render_recursive};
pub use renderer::Renderer;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;

use crate::core::settings::RenderSettings;
use crate::integrators::IntegratorKind;
use crate::io::desc::{Geometry, SceneDesc};

/// The stages of a frame, run in this order.
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum PrismSystems {
    /// Read entities into render-ready instances, materials and lights.
    Extract,
    /// Build the acceleration structure over the extracted instances.
    Accelerate,
    /// Trace rays and fill the frame.
    Render,
}

/// The schedule Prism's systems run in when used standalone.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct RenderFrame;

/// Adds Prism's stages to `schedule` in order.
pub fn add_render_systems(schedule: &mut Schedule) {
    schedule.configure_sets(
        (
            PrismSystems::Extract,
            PrismSystems::Accelerate,
            PrismSystems::Render,
        )
            .chain(),
    );
    schedule.add_systems((
        (
            sync::prepare_sync,
            sync::sync_removed,
            sync::sync_added,
            sync::sync_transforms,
            sync::sync_geometry_and_materials,
            sync::extract_camera,
        )
            .chain()
            .in_set(PrismSystems::Extract),
        sync::commit_scene.in_set(PrismSystems::Accelerate),
        render_recursive
            .run_if(integrator_is(IntegratorKind::Recursive))
            .run_if(not(radiosity::transport_is_radiosity))
            .in_set(PrismSystems::Render),
        wavefront::render_wavefront
            .run_if(integrator_is(IntegratorKind::Wavefront))
            .run_if(not(radiosity::transport_is_radiosity))
            .in_set(PrismSystems::Render),
        radiosity::render_radiosity
            .run_if(radiosity::transport_is_radiosity)
            .in_set(PrismSystems::Render),
        lines::render_feature_lines
            .run_if(lines::lines_requested)
            .after(render_recursive)
            .after(wavefront::render_wavefront)
            .after(radiosity::render_radiosity)
            .in_set(PrismSystems::Render),
    ));
}

/// Inserts Prism's resources into `world` (keeping any already there) and
/// returns a schedule with its systems, ready to run once per frame.
pub fn setup(world: &mut World) -> Schedule {
    world.init_resource::<RenderConfig>();
    world.init_resource::<ExtractedScene>();
    world.init_resource::<SceneAccel>();
    world.init_resource::<Frame>();
    world.init_resource::<sync::SceneSync>();
    world.init_resource::<ProgressiveRendering>();
    world.init_resource::<AccumulationState>();
    world.init_resource::<radiosity::RadiosityState>();
    wavefront::add_wavefront_schedules(world);
    let mut schedule = Schedule::new(RenderFrame);
    add_render_systems(&mut schedule);
    schedule
}

/// Runs one frame of `schedule` and then [`World::clear_trackers`], which
/// `bevy_ecs` needs once per frame so that removal events (used by the
/// incremental scene update) do not pile up.
pub fn run_frame(world: &mut World, schedule: &mut Schedule) {
    schedule.run(world);
    world.clear_trackers();
}

/// Adds Prism to a game's own world and schedule: resources, the
/// wavefront's schedules, and the three stages (after which the finished
/// image is in the [`Frame`] resource).
///
/// Entities the game spawns with [`Transform`](crate::geometry::transform::Transform)
/// and a [`Shape`](crate::geometry::shapes::Shape) or [`MeshInstance`] (optionally
/// a [`Material`](crate::scene::material::Material)), lights
/// ([`Light`](crate::scene::light::Light), placed by their transform) and a
/// [`Camera`](crate::scene::camera::Camera) are rendered; each frame only what changed is updated.
/// Order your game systems `.before(PrismSystems::Extract)` so a frame
/// shows this tick's state, and call [`World::clear_trackers`] after each
/// run (or use [`run_frame`]).
///
/// ```
/// use bevy_ecs::prelude::*;
/// use glam::Vec3;
/// use prism::scene::camera::Camera;
/// use prism::core::settings::RenderSettings;
/// use prism::scene::light::Light;
/// use prism::scene::material::Material;
/// use prism::geometry::shapes::Shape;
/// use prism::systems::{Frame, PrismPlugin, PrismSystems, run_frame};
/// use prism::geometry::transform::Transform;
///
/// #[derive(Component)]
/// struct Spin;
///
/// fn spin(mut q: Query<&mut Transform, With<Spin>>) {
///     for mut t in &mut q {
///         t.0.translation.x += 0.1;
///     }
/// }
///
/// let mut world = World::new();
/// let mut schedule = Schedule::default();
/// schedule.add_systems(spin.before(PrismSystems::Extract));
/// PrismPlugin::new()
///     .settings(RenderSettings { width: 32, height: 24, max_depth: 2, ..Default::default() })
///     .progressive(true)
///     .build(&mut world, &mut schedule);
///
/// world.spawn((
///     Transform::default(), // world positions are f64 (`glam::DVec3`)
///     Shape::Sphere { radius: 1.0 },
///     Material::default(),
///     Spin,
/// ));
/// world.spawn((
///     Transform::from_translation(glam::DVec3::new(0.0, 4.0, 4.0)),
///     Light::Point { intensity: Vec3::splat(50.0) },
/// ));
/// world.spawn(Camera::default()); // at z = 5, looking at the origin
///
/// run_frame(&mut world, &mut schedule); // the first frame adds everything
/// assert_eq!(world.resource::<Frame>().update.added, 1);
/// for _ in 0..2 {
///     run_frame(&mut world, &mut schedule);
///     let frame = world.resource::<Frame>();
///     assert!(frame.error.is_none());
///     assert_eq!((frame.update.added, frame.update.moved), (0, 1)); // only the move
/// }
/// let film = world.resource::<Frame>().film.as_ref().expect("rendered");
/// assert_eq!((film.width, film.height), (32, 24));
/// ```
#[derive(Clone, Default)]
pub struct PrismPlugin {
    config: RenderConfig,
    progressive: bool,
}

impl PrismPlugin {
    /// Default settings: the recursive integrator, Whitted transport,
    /// 640x480, one sample per pixel.
    pub fn new() -> Self {
        Self::default()
    }

    /// Image size, samples, depth, seed, transport.
    pub fn settings(mut self, settings: RenderSettings) -> Self {
        self.config.settings = settings;
        self
    }

    /// The whole render configuration.
    pub fn config(mut self, config: RenderConfig) -> Self {
        self.config = config;
        self
    }

    /// Accumulate samples over frames while nothing changes.
    pub fn progressive(mut self, enabled: bool) -> Self {
        self.progressive = enabled;
        self
    }

    /// Inserts the resources into `world` (replacing any [`RenderConfig`]
    /// and [`ProgressiveRendering`]) and adds Prism's stages to
    /// `schedule`.
    pub fn build(self, world: &mut World, schedule: &mut Schedule) {
        world.insert_resource(self.config);
        world.insert_resource(ProgressiveRendering {
            enabled: self.progressive,
        });
        world.init_resource::<ExtractedScene>();
        world.init_resource::<SceneAccel>();
        world.init_resource::<Frame>();
        world.init_resource::<sync::SceneSync>();
        world.init_resource::<AccumulationState>();
        world.init_resource::<radiosity::RadiosityState>();
        wavefront::add_wavefront_schedules(world);
        add_render_systems(schedule);
    }
}

/// Spawns a loaded scene's objects, lights and cameras; returns the camera
/// entities in file order.
pub fn spawn_scene(world: &mut World, desc: SceneDesc) -> Vec<Entity> {
    for o in desc.objects {
        let mut e = world.spawn((o.transform, o.material));
        match o.geometry {
            Geometry::Shape(s) => e.insert(s),
            Geometry::Mesh(m) => e.insert(MeshInstance(m)),
        };
    }
    for l in desc.lights {
        world.spawn((l.transform, l.light));
    }
    desc.cameras
        .into_iter()
        .map(|c| world.spawn(c).id())
        .collect()
}

/// Renders a loaded scene in a fresh world: spawns it, runs one frame and
/// returns the frame. `camera` indexes the scene's cameras in file order.
/// The same as [`Renderer::with_scene`] followed by [`Renderer::render`].
///
/// ```no_run
/// use prism::geometry::mesh::BuildQuality;
/// use prism::systems;
/// let desc = prism::io::load("assets/whitted.toml".as_ref(), BuildQuality::Medium)?;
/// let frame = systems::render_scene_desc(desc, systems::RenderConfig::default(), 0)?;
/// let film = frame.film.expect("rendered");
/// assert_eq!(film.width, 640);
/// # Ok::<(), prism::Error>(())
/// ```
pub fn render_scene_desc(
    desc: SceneDesc,
    config: RenderConfig,
    camera: usize,
) -> crate::Result<Frame> {
    Renderer::with_scene(desc, config, camera)?.render()
}
