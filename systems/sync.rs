//! Incremental scene updates through ECS change detection.
//!
//! The [`RenderScene`] in [`SceneAccel`] persists from frame to frame.
//! Each frame the systems of [`PrismSystems::Extract`](super::PrismSystems::Extract) apply only what
//! changed in the world, in this order:
//!
//! 1. [`sync_removed`]: objects despawned or stripped of their transform
//!    or geometry leave the scene;
//! 2. [`sync_added`]: new objects enter it;
//! 3. [`sync_transforms`]: moved objects update their top-level leaf (no
//!    mesh BVH is rebuilt; a mesh's BVH lives in its shared [`Mesh`]);
//! 4. [`sync_geometry_and_materials`]: changed shapes or meshes, changed
//!    materials (which touch no BVH) and lights;
//!
//! then [`commit_scene`] (in [`PrismSystems::Accelerate`](super::PrismSystems::Accelerate)) commits the
//! top level: leaf updates and a conversion, or a full rebuild above the
//! churn threshold (see [`crate::accel::tlas::TlasPolicy`]).
//!
//! An *object* is an entity with a [`Transform`] and a [`Shape`] or a
//! [`MeshInstance`] (the mesh wins when it has both), and optionally a
//! [`Material`] (white Lambertian when absent). Objects are rendered as
//! instance `i` with material `i` (one material per object).
//!
//! Removal events come from [`RemovedComponents`], which `bevy_ecs` keeps
//! for two calls of [`World::clear_trackers`]: call it once per frame, as
//! [`super::run_frame`] does.
//!
//! [`Mesh`]: crate::geometry::mesh::Mesh

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;

use super::components::MeshInstance;
use super::{ExtractedScene, Frame, RenderConfig, RenderOrigin, SceneAccel};
use crate::geometry::mesh::BuildQuality;
use crate::geometry::shapes::Shape;
use crate::geometry::transform::Transform;
use crate::scene::light::Light;
use crate::scene::material::Material;
use crate::scene::{Instance, InstanceGeometry, RenderScene};

pub use super::frame::SceneUpdateReport;

/// The link between entities and the persistent scene.
#[derive(Resource, Default)]
pub struct SceneSync {
    slot_of: HashMap<Entity, u32>,
    entity_of: Vec<Entity>,
    /// Objects whose transform is invalid: kept out of the scene, and the
    /// frame fails naming the first.
    invalid: BTreeSet<Entity>,
    /// Objects inserted this frame (later phases skip them).
    fresh: HashSet<Entity>,
    /// Objects that lost a geometry or material component this frame but
    /// are still objects.
    regeometry: HashSet<Entity>,
    rematerial: HashSet<Entity>,
    /// Every object must be (re)inserted: the scene was recreated.
    resync_all: bool,
    lights_dirty: bool,
    quality: Option<BuildQuality>,
    start: Option<Instant>,
    /// This frame's report so far.
    pub report: SceneUpdateReport,
}

impl SceneSync {
    /// The entity rendered as instance `index` of the scene.
    pub fn entity(&self, index: u32) -> Option<Entity> {
        self.entity_of.get(index as usize).copied()
    }

    /// The instance index of `entity`, if it is in the scene.
    pub fn instance(&self, entity: Entity) -> Option<u32> {
        self.slot_of.get(&entity).copied()
    }
}

type ObjectData<'a> = (
    Entity,
    &'a Transform,
    Option<&'a Shape>,
    Option<&'a MeshInstance>,
    Option<&'a Material>,
);

type ObjectFilter = Or<(With<Shape>, With<MeshInstance>)>;

fn geometry(shape: Option<&Shape>, mesh: Option<&MeshInstance>) -> Option<InstanceGeometry> {
    match (mesh, shape) {
        (Some(m), _) => Some(InstanceGeometry::Mesh(m.0.clone())),
        (None, Some(s)) => Some(InstanceGeometry::Shape(s.clone())),
        (None, None) => None,
    }
}

fn scene_mut(accel: &mut SceneAccel) -> &mut RenderScene {
    Arc::get_mut(accel.scene.as_mut().expect("prepared by prepare_sync"))
        .expect("prepared by prepare_sync")
}

fn insert_object(scene: &mut RenderScene, sync: &mut SceneSync, o: ObjectData<'_>) {
    let (e, t, shape, mesh, material) = o;
    let Some(g) = geometry(shape, mesh) else {
        return;
    };
    if sync.slot_of.contains_key(&e) {
        return;
    }
    if !t.is_valid() {
        sync.invalid.insert(e);
        return;
    }
    sync.invalid.remove(&e);
    let m = scene.push_material(material.cloned().unwrap_or_default());
    let i = scene.push_instance(Instance::new(g, t, m));
    debug_assert_eq!(i, m);
    sync.slot_of.insert(e, i);
    sync.entity_of.push(e);
    sync.fresh.insert(e);
    sync.report.added += 1;
}

fn remove_object(scene: &mut RenderScene, sync: &mut SceneSync, e: Entity) {
    let Some(slot) = sync.slot_of.remove(&e) else {
        return;
    };
    scene.swap_remove_instance(slot);
    scene.swap_remove_material(slot);
    sync.entity_of.swap_remove(slot as usize);
    if let Some(&moved) = sync.entity_of.get(slot as usize) {
        sync.slot_of.insert(moved, slot);
    }
    sync.fresh.remove(&e);
    sync.report.removed += 1;
}

/// Starts a frame's update: makes sure the scene exists and is not shared
/// (the wavefront's per-frame state, which holds it, is dropped; it is
/// rebuilt every frame), otherwise starts a fresh scene.
pub fn prepare_sync(world: &mut World) {
    let start = Instant::now();
    world.remove_resource::<super::wavefront::WavefrontFrame>();
    let (background, environment, fog, quality) = {
        let c = world.resource::<RenderConfig>();
        (c.background, c.environment.clone(), c.fog, c.bvh_quality)
    };
    let same_quality = world.resource::<SceneSync>().quality == Some(quality);
    let mut accel = world.resource_mut::<SceneAccel>();
    let usable = same_quality
        && accel
            .scene
            .as_mut()
            .is_some_and(|s| Arc::get_mut(s).is_some());
    if !usable {
        accel.scene = Some(Arc::new(
            RenderScene::new(Vec::new(), Vec::new(), Vec::new(), background, quality)
                .with_environment(environment),
        ));
        if let Some(s) = accel.scene.as_mut().and_then(Arc::get_mut) {
            s.set_fog(fog);
        }
    } else if let Some(s) = accel.scene.as_mut().and_then(Arc::get_mut) {
        if s.background() != background {
            s.set_background(background);
        }
        if s.environment() != environment.as_ref() {
            s.set_environment(environment);
        }
        if s.fog() != fog.as_ref() {
            s.set_fog(fog);
        }
    }
    let rebased = choose_origin(world, !usable);
    let mut sync = world.resource_mut::<SceneSync>();
    sync.report = SceneUpdateReport::default();
    sync.report.rebased = rebased;
    sync.fresh.clear();
    sync.regeometry.clear();
    sync.rematerial.clear();
    sync.start = Some(start);
    if !usable {
        sync.slot_of.clear();
        sync.entity_of.clear();
        sync.invalid.clear();
        sync.resync_all = true;
        sync.lights_dirty = true;
        sync.quality = Some(quality);
        sync.report.reset = true;
    }
}

/// Moves the scene's render origin as [`RenderOrigin`] asks (the default
/// follows the active camera); returns whether it moved. On a fresh scene
/// a following origin starts exactly at the camera.
fn choose_origin(world: &mut World, fresh: bool) -> bool {
    let mode = world
        .get_resource::<RenderOrigin>()
        .copied()
        .unwrap_or_default();
    let chosen = world.resource::<RenderConfig>().camera;
    let camera = {
        let mut q = world.query::<(Entity, &crate::scene::camera::Camera)>();
        match chosen {
            Some(e) => q.get(world, e).ok().map(|(_, c)| c.look_from),
            None => q.iter(world).min_by_key(|c| c.0).map(|(_, c)| c.look_from),
        }
    };
    let mut accel = world.resource_mut::<SceneAccel>();
    let scene = scene_mut(&mut accel);
    let current = scene.origin();
    let target = match mode {
        RenderOrigin::Fixed(o) => o,
        RenderOrigin::FollowCamera { recenter_distance } => match camera {
            Some(c) if c.is_finite() && (fresh || (c - current).length() > recenter_distance) => c,
            _ => current,
        },
    };
    target.is_finite() && scene.set_origin(target)
}

/// Phase 1: objects that were despawned or lost their transform or
/// geometry leave the scene.
#[allow(clippy::too_many_arguments)]
pub fn sync_removed(
    mut sync: ResMut<SceneSync>,
    mut accel: ResMut<SceneAccel>,
    mut removed_transforms: RemovedComponents<Transform>,
    mut removed_shapes: RemovedComponents<Shape>,
    mut removed_meshes: RemovedComponents<MeshInstance>,
    mut removed_materials: RemovedComponents<Material>,
    mut removed_lights: RemovedComponents<Light>,
    objects: Query<ObjectData, ObjectFilter>,
) {
    let sync = &mut *sync;
    let scene = scene_mut(&mut accel);
    let mut gone: Vec<Entity> = removed_transforms.read().collect();
    if !gone.is_empty() || !removed_lights.is_empty() {
        // A light may have lost its transform or itself.
        sync.lights_dirty = true;
    }
    removed_lights.clear();
    let lost_geometry: Vec<Entity> = removed_shapes.read().chain(removed_meshes.read()).collect();
    gone.extend(&lost_geometry);
    gone.sort();
    gone.dedup();
    for e in gone {
        if objects.contains(e) {
            if lost_geometry.contains(&e) {
                sync.regeometry.insert(e);
            }
        } else {
            sync.invalid.remove(&e);
            remove_object(scene, sync, e);
        }
    }
    for e in removed_materials.read() {
        if sync.slot_of.contains_key(&e) {
            sync.rematerial.insert(e);
        }
    }
}

/// Phase 2: new objects enter the scene (every object after a reset), in
/// entity order.
#[allow(clippy::type_complexity)]
pub fn sync_added(
    mut sync: ResMut<SceneSync>,
    mut accel: ResMut<SceneAccel>,
    added: Query<
        ObjectData,
        (
            ObjectFilter,
            Or<(Added<Transform>, Added<Shape>, Added<MeshInstance>)>,
        ),
    >,
    all: Query<ObjectData, ObjectFilter>,
) {
    let sync = &mut *sync;
    let scene = scene_mut(&mut accel);
    let mut new: Vec<ObjectData> = if sync.resync_all {
        all.iter().collect()
    } else {
        added.iter().collect()
    };
    sync.resync_all = false;
    new.sort_by_key(|o| o.0);
    for o in new {
        insert_object(scene, sync, o);
    }
}

/// Phase 3: moved objects update their top-level leaf; objects whose
/// transform became invalid leave the scene, and valid again re-enter it.
pub fn sync_transforms(
    mut sync: ResMut<SceneSync>,
    mut accel: ResMut<SceneAccel>,
    moved: Query<ObjectData, (ObjectFilter, Changed<Transform>)>,
    lights: Query<(), (With<Light>, Changed<Transform>)>,
) {
    let sync = &mut *sync;
    let scene = scene_mut(&mut accel);
    if !lights.is_empty() {
        sync.lights_dirty = true;
    }
    let mut moved: Vec<ObjectData> = moved.iter().collect();
    moved.sort_by_key(|o| o.0);
    for o in moved {
        let (e, t, ..) = o;
        if sync.fresh.contains(&e) {
            continue;
        }
        match sync.slot_of.get(&e).copied() {
            Some(slot) if t.is_valid() => {
                scene.set_instance_transform(slot, t);
                sync.report.moved += 1;
            }
            Some(_) => {
                remove_object(scene, sync, e);
                sync.invalid.insert(e);
            }
            None => insert_object(scene, sync, o),
        }
    }
}

/// Phase 4: changed shapes and meshes, changed materials (no BVH is
/// touched) and lights.
#[allow(clippy::type_complexity)]
pub fn sync_geometry_and_materials(
    mut sync: ResMut<SceneSync>,
    mut accel: ResMut<SceneAccel>,
    changed: Query<
        (
            Entity,
            Option<Ref<Shape>>,
            Option<Ref<MeshInstance>>,
            Option<Ref<Material>>,
        ),
        Or<(Changed<Shape>, Changed<MeshInstance>, Changed<Material>)>,
    >,
    objects: Query<ObjectData, ObjectFilter>,
    changed_lights: Query<(), Changed<Light>>,
    lights: Query<(Entity, &Light, Option<&Transform>)>,
) {
    let sync = &mut *sync;
    let scene = scene_mut(&mut accel);
    let mut regeometry: Vec<Entity> = sync.regeometry.drain().collect();
    let mut rematerial: Vec<Entity> = sync.rematerial.drain().collect();
    for (e, shape, mesh, material) in &changed {
        if shape.is_some_and(|s| s.is_changed()) || mesh.is_some_and(|m| m.is_changed()) {
            regeometry.push(e);
        }
        if material.is_some_and(|m| m.is_changed()) {
            rematerial.push(e);
        }
    }
    regeometry.sort();
    regeometry.dedup();
    rematerial.sort();
    rematerial.dedup();
    for e in regeometry {
        if sync.fresh.contains(&e) {
            continue;
        }
        let (Some(slot), Ok((_, _, shape, mesh, _))) = (sync.slot_of.get(&e), objects.get(e))
        else {
            continue;
        };
        if let Some(g) = geometry(shape, mesh) {
            scene.set_instance_geometry(*slot, g);
            sync.report.regeometry += 1;
        }
    }
    for e in rematerial {
        if sync.fresh.contains(&e) {
            continue;
        }
        let (Some(slot), Ok((.., material))) = (sync.slot_of.get(&e), objects.get(e)) else {
            continue;
        };
        scene.set_material(*slot, material.cloned().unwrap_or_default());
        sync.report.rematerial += 1;
    }
    if sync.lights_dirty || !changed_lights.is_empty() {
        let mut ls: Vec<_> = lights.iter().collect();
        ls.sort_by_key(|l| l.0);
        scene.set_lights(
            ls.into_iter()
                .map(|(_, l, t)| (*l, t.copied().unwrap_or_default()))
                .collect(),
        );
        sync.lights_dirty = false;
        sync.report.lights_changed = true;
    }
}

/// Commits the frame's changes to the top-level BVH and publishes the
/// report in [`Frame::update`].
pub fn commit_scene(
    config: Res<RenderConfig>,
    mut sync: ResMut<SceneSync>,
    mut accel: ResMut<SceneAccel>,
    mut frame: ResMut<Frame>,
) {
    let start = Instant::now();
    let sync_seconds = sync.start.take().map_or(0.0, |s| (start - s).as_secs_f64());
    let scene = scene_mut(&mut accel);
    scene.set_mesh_merging(config.merge_meshes);
    let update = scene.commit();
    let counters = scene.tlas_counters();
    let origin = scene.origin();
    let accel_seconds = start.elapsed().as_secs_f64();
    accel.build_seconds = accel_seconds;
    let report = &mut sync.report;
    report.tlas = update;
    report.origin = origin;
    report.tlas_counters = counters;
    report.mesh_bvh_builds = crate::geometry::mesh::mesh_bvh_builds();
    report.sync_seconds = sync_seconds;
    report.accel_seconds = accel_seconds;
    frame.update = *report;
}

/// Reads the camera, and fails the frame while an object's transform is
/// invalid.
pub fn extract_camera(
    config: Res<RenderConfig>,
    sync: Res<SceneSync>,
    cameras: Query<(Entity, &crate::scene::camera::Camera)>,
    mut out: ResMut<ExtractedScene>,
) {
    out.error = sync
        .invalid
        .first()
        .map(|e| format!("entity {e}: transform is not finite and invertible"));
    out.camera = match config.camera {
        Some(e) => cameras.get(e).ok().map(|(_, c)| c.clone()),
        None => cameras.iter().min_by_key(|c| c.0).map(|(_, c)| c.clone()),
    };
}

/// Builds the scene the incremental systems should have produced, from
/// scratch: every object of `world` in entity order (instance `i` uses
/// material `i`), the lights, and a freshly built top level. Returns the
/// scene and the entity of each instance, or the message of an invalid
/// transform. The scene is expressed relative to `origin` (pass the
/// incremental scene's [`RenderScene::origin`] to compare the two). Used to
/// check incremental updates.
pub fn scene_from_scratch(
    world: &mut World,
    origin: glam::DVec3,
    background: crate::core::math::Color,
    quality: BuildQuality,
) -> Result<(RenderScene, Vec<Entity>), String> {
    let mut q = world.query_filtered::<ObjectData, ObjectFilter>();
    let mut objects: Vec<ObjectData> = q.iter(world).collect();
    objects.sort_by_key(|o| o.0);
    let mut instances = Vec::new();
    let mut materials = Vec::new();
    let mut entities = Vec::new();
    for (e, t, shape, mesh, material) in objects {
        if !t.is_valid() {
            return Err(format!(
                "entity {e}: transform is not finite and invertible"
            ));
        }
        let g = geometry(shape, mesh).expect("filtered");
        instances.push(Instance::new(g, t, materials.len() as u32));
        materials.push(material.cloned().unwrap_or_default());
        entities.push(e);
    }
    let mut lq = world.query::<(Entity, &Light, Option<&Transform>)>();
    let mut ls: Vec<_> = lq.iter(world).collect();
    ls.sort_by_key(|l| l.0);
    let lights = ls
        .into_iter()
        .map(|(_, l, t)| (*l, t.copied().unwrap_or_default()))
        .collect();
    Ok((
        RenderScene::with_origin(origin, instances, materials, lights, background, quality),
        entities,
    ))
}
