//! The ECS side of Prism: resources, system sets and the systems that turn
//! a `bevy_ecs` world into an image by calling the kernels.
//!
//! A scene is a world of entities carrying the components
//! [`Transform`], [`Shape`] or [`MeshInstance`], [`Material`], [`Light`]
//! and [`Camera`]. Each frame runs three stages, declared once in
//! [`add_render_systems`]:
//!
//! 1. [`PrismSystems::Extract`]: gather instances, materials and lights
//!    from the world ([`extract_scene`]);
//! 2. [`PrismSystems::Accelerate`]: build the top-level BVH
//!    ([`build_acceleration`]);
//! 3. [`PrismSystems::Render`]: trace the image into [`Frame`], with
//!    [`render_recursive`] or, stage by stage, with the wavefront systems
//!    of [`wavefront`] (driven by [`wavefront::render_wavefront`]).
//!
//! This module is compiled as part of the `prism` crate (one crate keeps
//! the build short and the binary simple); the kernels in `src/` never
//! refer to it.

pub mod wavefront;

use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;

use crate::camera::Camera;
use crate::desc::{Geometry, SceneDesc};
use crate::film::Film;
use crate::integrator::wavefront::WavefrontReport;
use crate::integrator::{self, IntegratorKind, RenderSettings};
use crate::light::{Light, WorldLight};
use crate::material::Material;
use crate::math::Color;
use crate::mesh::{BuildQuality, MeshInstance};
use crate::scene::{Instance, InstanceGeometry, RenderScene};
use crate::shapes::Shape;
use crate::stats::RenderCounters;
use crate::transform::Transform;

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

/// Called with the number of image rows finished.
pub type ProgressFn = Arc<dyn Fn(u64) + Send + Sync>;

/// How frames are rendered.
#[derive(Resource, Clone)]
pub struct RenderConfig {
    /// Image size, samples, depth, threshold, seed.
    pub settings: RenderSettings,
    /// Integrator.
    pub integrator: IntegratorKind,
    /// Which camera entity to render from; the first camera (lowest
    /// entity id) when `None`.
    pub camera: Option<Entity>,
    /// BVH build preset for the top level.
    pub bvh_quality: BuildQuality,
    /// Radiance of escaped rays.
    pub background: Color,
    /// Optional progress callback.
    pub progress: Option<ProgressFn>,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            settings: RenderSettings::default(),
            integrator: IntegratorKind::default(),
            camera: None,
            bvh_quality: BuildQuality::default(),
            background: Color::ZERO,
            progress: None,
        }
    }
}

/// Instances, materials and lights read from the world this frame.
#[derive(Resource, Default)]
pub struct ExtractedScene {
    instances: Vec<Instance>,
    materials: Vec<Material>,
    lights: Vec<WorldLight>,
    camera: Option<Camera>,
    error: Option<String>,
}

/// The render-ready scene with its BVH.
#[derive(Resource, Default)]
pub struct SceneAccel {
    /// The scene, once built.
    pub scene: Option<Arc<RenderScene>>,
    /// Seconds spent building the top-level BVH this frame.
    pub build_seconds: f64,
}

/// The finished frame.
#[derive(Resource, Default)]
pub struct Frame {
    /// The image, or `None` if the frame failed.
    pub film: Option<Film>,
    /// Why the frame failed.
    pub error: Option<String>,
    /// Rays traced and non-finite samples caught.
    pub counters: RenderCounters,
    /// Seconds spent tracing.
    pub render_seconds: f64,
    /// Stage times and queue memory, for wavefront frames.
    pub wavefront: Option<WavefrontReport>,
}

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
        extract_scene.in_set(PrismSystems::Extract),
        build_acceleration.in_set(PrismSystems::Accelerate),
        render_recursive
            .run_if(integrator_is(IntegratorKind::Recursive))
            .in_set(PrismSystems::Render),
        wavefront::render_wavefront
            .run_if(integrator_is(IntegratorKind::Wavefront))
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
    wavefront::add_wavefront_schedules(world);
    let mut schedule = Schedule::new(RenderFrame);
    add_render_systems(&mut schedule);
    schedule
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

/// Stage 1: reads shapes, meshes, materials, lights and the camera.
///
/// Entities are visited in entity order so the result does not depend on
/// archetype layout. Entities with an invalid transform make the frame
/// fail with a message.
#[allow(clippy::type_complexity)]
pub fn extract_scene(
    config: Res<RenderConfig>,
    shapes: Query<(Entity, &Transform, &Shape, Option<&Material>)>,
    meshes: Query<(Entity, &Transform, &MeshInstance, Option<&Material>)>,
    lights: Query<(Entity, &Light, Option<&Transform>)>,
    cameras: Query<(Entity, &Camera)>,
    mut out: ResMut<ExtractedScene>,
) {
    let out = &mut *out;
    out.instances.clear();
    out.materials.clear();
    out.lights.clear();
    out.error = None;
    let mut objects: Vec<(Entity, &Transform, InstanceGeometry, Option<&Material>)> = shapes
        .iter()
        .map(|(e, t, s, m)| (e, t, InstanceGeometry::Shape(s.clone()), m))
        .chain(
            meshes
                .iter()
                .map(|(e, t, mi, m)| (e, t, InstanceGeometry::Mesh(mi.0.clone()), m)),
        )
        .collect();
    objects.sort_by_key(|o| o.0);
    for (e, t, g, m) in objects {
        if !t.is_valid() {
            out.error = Some(format!(
                "entity {e}: transform is not finite and invertible"
            ));
            return;
        }
        let id = out.materials.len() as u32;
        out.materials.push(m.cloned().unwrap_or_default());
        out.instances.push(Instance::new(g, t, id));
    }
    let mut ls: Vec<_> = lights.iter().collect();
    ls.sort_by_key(|l| l.0);
    out.lights = ls
        .into_iter()
        .map(|(_, l, t)| WorldLight::new(l, t.unwrap_or(&Transform::default())))
        .collect();
    out.camera = match config.camera {
        Some(e) => cameras.get(e).ok().map(|(_, c)| c.clone()),
        None => cameras.iter().min_by_key(|c| c.0).map(|(_, c)| c.clone()),
    };
}

/// Stage 2: builds the top-level BVH over the extracted instances.
pub fn build_acceleration(
    config: Res<RenderConfig>,
    mut extracted: ResMut<ExtractedScene>,
    mut accel: ResMut<SceneAccel>,
) {
    let start = Instant::now();
    let ex = &mut *extracted;
    let scene = RenderScene::new(
        std::mem::take(&mut ex.instances),
        std::mem::take(&mut ex.materials),
        std::mem::take(&mut ex.lights),
        config.background,
        config.bvh_quality,
    );
    accel.scene = Some(Arc::new(scene));
    accel.build_seconds = start.elapsed().as_secs_f64();
}

/// Run condition: the configured integrator is `kind`.
pub fn integrator_is(kind: IntegratorKind) -> impl Fn(Res<RenderConfig>) -> bool + Clone {
    move |config: Res<RenderConfig>| config.integrator == kind
}

/// Checks what every integrator needs before it can trace: a valid
/// camera, valid settings and a built scene. On failure it records the
/// reason in [`Frame`] and returns `None`.
pub fn frame_preconditions(world: &mut World) -> Option<(Arc<RenderScene>, Camera)> {
    *world.resource_mut::<Frame>() = Frame::default();
    let extracted = world.resource::<ExtractedScene>();
    let result = (|| {
        if let Some(e) = &extracted.error {
            return Err(e.clone());
        }
        let camera = extracted
            .camera
            .clone()
            .ok_or_else(|| "the scene has no camera".to_string())?;
        camera.validate()?;
        world.resource::<RenderConfig>().settings.validate()?;
        let scene = world
            .resource::<SceneAccel>()
            .scene
            .clone()
            .ok_or_else(|| "no acceleration structure was built".to_string())?;
        Ok((scene, camera))
    })();
    match result {
        Ok(v) => Some(v),
        Err(e) => {
            world.resource_mut::<Frame>().error = Some(e);
            None
        }
    }
}

/// Stage 3, recursive integrator: renders every pixel depth-first.
pub fn render_recursive(world: &mut World) {
    let Some((scene, camera)) = frame_preconditions(world) else {
        return;
    };
    let config = world.resource::<RenderConfig>().clone();
    let start = Instant::now();
    let progress = config
        .progress
        .as_deref()
        .map(|p| p as integrator::Progress<'_>);
    let (film, counters) =
        integrator::recursive::render(&scene, &camera, &config.settings, progress);
    let mut frame = world.resource_mut::<Frame>();
    frame.render_seconds = start.elapsed().as_secs_f64();
    frame.film = Some(film);
    frame.counters = counters;
}

/// Renders a loaded scene in a fresh world: spawns it, runs one frame and
/// returns the frame. `camera` indexes the scene's cameras in file order.
///
/// ```no_run
/// use prism::{loader, mesh::BuildQuality, systems};
/// let desc = loader::load("assets/whitted.toml".as_ref(), BuildQuality::Medium)?;
/// let frame = systems::render_scene_desc(desc, systems::RenderConfig::default(), 0)?;
/// let film = frame.film.expect("rendered");
/// assert_eq!(film.width, 640);
/// # Ok::<(), prism::Error>(())
/// ```
pub fn render_scene_desc(
    desc: SceneDesc,
    mut config: RenderConfig,
    camera: usize,
) -> crate::Result<Frame> {
    let mut world = World::new();
    let mut schedule = setup(&mut world);
    config.background = desc.background;
    let cameras = spawn_scene(&mut world, desc);
    config.camera = Some(*cameras.get(camera).ok_or_else(|| {
        crate::Error::Invalid(format!(
            "camera {camera} requested but the scene has {} camera(s)",
            cameras.len()
        ))
    })?);
    world.insert_resource(config);
    schedule.run(&mut world);
    let frame = world.remove_resource::<Frame>().unwrap_or_default();
    match &frame.error {
        Some(e) => Err(crate::Error::Invalid(e.clone())),
        None => Ok(frame),
    }
}
