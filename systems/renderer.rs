//! [`Renderer`]: a world, Prism's schedule and a loaded scene in one
//! value, so that "world, resources, schedule, spawn, configure, run" is
//! written once.

use bevy_ecs::prelude::*;

use super::frame::{Frame, RenderConfig, SceneAccel};
use super::{run_frame, setup, spawn_scene};
use crate::io::desc::SceneDesc;
use crate::scene::RenderScene;

/// A `bevy_ecs` world that renders: Prism's resources and frame schedule,
/// the scene's entities, and the camera entities in file order.
///
/// ```no_run
/// use prism::geometry::mesh::BuildQuality;
/// use prism::systems::{RenderConfig, Renderer};
/// let desc = prism::io::load("assets/whitted.toml".as_ref(), BuildQuality::Medium)?;
/// let mut renderer = Renderer::with_scene(desc, RenderConfig::default(), 0)?;
/// let frame = renderer.render()?;
/// assert_eq!(frame.film.expect("rendered").width, 640);
/// # Ok::<(), prism::Error>(())
/// ```
pub struct Renderer {
    world: World,
    schedule: Schedule,
    cameras: Vec<Entity>,
}

impl Default for Renderer {
    fn default() -> Self {
        Self::new()
    }
}

impl Renderer {
    /// An empty world with Prism's resources and schedule.
    pub fn new() -> Self {
        let mut world = World::new();
        let schedule = setup(&mut world);
        Self {
            world,
            schedule,
            cameras: Vec::new(),
        }
    }

    /// Spawns `desc` into a new world and configures it with `config`,
    /// the scene's background and environment and its camera number `camera` (file order).
    pub fn with_scene(
        desc: SceneDesc,
        mut config: RenderConfig,
        camera: usize,
    ) -> crate::Result<Self> {
        let mut r = Self::new();
        config.background = desc.background;
        config.environment = desc.environment.clone();
        config.fog = desc.fog;
        r.cameras = spawn_scene(&mut r.world, desc);
        config.camera = Some(*r.cameras.get(camera).ok_or_else(|| {
            crate::Error::Invalid(format!(
                "camera {camera} requested but the scene has {} camera(s)",
                r.cameras.len()
            ))
        })?);
        r.world.insert_resource(config);
        Ok(r)
    }

    /// The camera entities of the scene, in file order.
    pub fn cameras(&self) -> &[Entity] {
        &self.cameras
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, to spawn, move or despawn entities between frames.
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// The render configuration, to change between frames.
    pub fn config_mut(&mut self) -> Mut<'_, RenderConfig> {
        self.world.resource_mut::<RenderConfig>()
    }

    /// Inserts (or replaces) a resource, such as
    /// [`BatchSize`](super::wavefront::BatchSize).
    pub fn insert_resource<R: Resource>(&mut self, resource: R) -> &mut Self {
        self.world.insert_resource(resource);
        self
    }

    /// Runs one frame and returns it, leaving it in the world.
    pub fn run(&mut self) -> &Frame {
        run_frame(&mut self.world, &mut self.schedule);
        self.world.resource::<Frame>()
    }

    /// Runs one frame and takes it out of the world; a frame that failed
    /// is an error carrying its reason.
    pub fn render(&mut self) -> crate::Result<Frame> {
        run_frame(&mut self.world, &mut self.schedule);
        let frame = std::mem::take(&mut *self.world.resource_mut::<Frame>());
        match &frame.error {
            Some(e) => Err(crate::Error::Invalid(e.clone())),
            None => Ok(frame),
        }
    }

    /// The render-ready scene as last built, if a frame has run.
    pub fn scene(&self) -> Option<std::sync::Arc<RenderScene>> {
        self.world.resource::<SceneAccel>().scene.clone()
    }
}
