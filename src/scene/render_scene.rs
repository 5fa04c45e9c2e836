//! [`RenderScene`]: instances, the top level over them, materials, lights
//! and area lights, ready for rendering.

use std::time::Instant;

use crate::accel::build::BuildQuality;
use crate::accel::tlas::{Placement, Tlas};
use crate::core::math::Color;
use crate::core::medium::Medium;
use crate::scene::emitters::EmitterTable;
use crate::scene::environment::Environment;
use crate::scene::instance::{Instance, InstanceGeometry};
use crate::scene::merged::MergedMeshes;
use glam::{DVec3, Vec2};

use crate::geometry::transform::Transform;
use crate::scene::light::{Light, WorldLight};
use crate::scene::material::{Material, SurfaceSample};

/// A scene ready for rendering: instances, top-level BVH, materials, lights.
#[derive(Debug)]
pub struct RenderScene {
    /// All instances; the top-level BVH indexes this array.
    pub(super) instances: Vec<Instance>,
    /// Materials referenced by instances.
    pub(super) materials: Vec<Material>,
    /// Each material evaluated once when it has no texture (its surface is
    /// then the same at every point), else `None`: see
    /// [`RenderScene::surface`]. Kept in step with `materials`.
    pub(super) surfaces: Vec<Option<SurfaceSample>>,
    /// The render origin: the world point (f64) that the kernels' frame is
    /// centred on. Instances, lights and cameras are made relative to it in
    /// f64 before they are rounded to f32.
    pub(super) origin: DVec3,
    /// Lights as placed in the world (f64), kept to re-resolve them when
    /// the origin moves.
    pub(super) light_sources: Vec<(Light, Transform)>,
    /// Lights in the render frame.
    pub(super) lights: Vec<WorldLight>,
    /// Radiance of escaped rays.
    pub(super) background: Color,
    /// Light from infinitely far away: when present, escaped rays bring
    /// back its radiance instead of `background`, and path transport
    /// samples it as a light.
    pub(super) environment: Option<Environment>,
    /// Emissive surfaces as area lights, for path tracing (rebuilt by
    /// [`RenderScene::commit`] when instances or materials change).
    pub(super) emitters: EmitterTable,
    /// Set by changes to instances or materials: the emitter table is
    /// rebuilt at the next commit.
    pub(super) emitters_stale: bool,
    /// Top-level BVH over bounded instances, the instance of each of its
    /// leaf slots, and the unbounded instances (infinite planes) tested one
    /// by one.
    pub(super) tlas: Tlas,
    /// Seconds spent building the top-level BVH (by [`RenderScene::new`],
    /// or by the last [`RenderScene::commit`] that changed it).
    pub(super) tlas_build_seconds: f64,
    /// True when some material has an alpha mode
    /// ([`Material::alpha`]): only then do intersection queries look at
    /// materials ([`has_cutouts`]; kept up to date by the material updates).
    pub(super) cutouts: bool,
    /// True when a material is dispersive ([`has_dispersion`]; kept up to
    /// date by the material updates): path transport is then spectral.
    pub(super) spectral: bool,
    /// True when a material's interior scatters
    /// ([`Material::has_scattering_interior`]; kept up to date by the
    /// material updates): with it, or with a fog, path transport runs the
    /// medium kernels (`transport::volume`).
    pub(super) scattering: bool,
    /// True when every medium lies behind boundaries that block shadow
    /// rays ([`media_behind_opaque_boundaries`]; kept up to date by the
    /// material updates).
    pub(super) opaque_media: bool,
    /// The medium that fills the space outside every object (a global
    /// fog), if any.
    pub(super) fog: Option<Medium>,
    /// The scene's mesh instances merged under one BVH, if
    /// [`RenderScene::set_mesh_merging`] asked for it and a commit could
    /// merge every bounded instance; they are then out of the top level.
    pub(super) merged: Option<MergedMeshes>,
    /// Merging is asked for ([`RenderScene::set_mesh_merging`]).
    pub(super) merge_requested: bool,
    /// Merging was asked for and the next commit should try it.
    pub(super) merge_pending: bool,
    /// BVH build preset, for the merged group.
    pub(super) quality: BuildQuality,
}

impl RenderScene {
    /// Builds the top-level BVH over `instances`, with the render origin at
    /// the world origin.
    pub fn new(
        instances: Vec<Instance>,
        materials: Vec<Material>,
        lights: Vec<(Light, Transform)>,
        background: Color,
        quality: BuildQuality,
    ) -> Self {
        Self::with_origin(
            DVec3::ZERO,
            instances,
            materials,
            lights,
            background,
            quality,
        )
    }

    /// Builds the top-level BVH over `instances` in the frame centred on
    /// `origin` (see [`RenderScene::origin`]).
    pub fn with_origin(
        origin: DVec3,
        mut instances: Vec<Instance>,
        materials: Vec<Material>,
        light_sources: Vec<(Light, Transform)>,
        background: Color,
        quality: BuildQuality,
    ) -> Self {
        let start = Instant::now();
        for inst in &mut instances {
            inst.rebase(origin);
        }
        let lights = resolve_lights(&light_sources, origin);
        let tlas = Tlas::build(instances.len(), |i| instances[i].placement(), quality);
        let emitters = EmitterTable::build(&instances, &materials);
        Self {
            surfaces: materials.iter().map(constant_surface).collect(),
            cutouts: has_cutouts(&materials),
            spectral: has_dispersion(&materials),
            scattering: has_scattering(&materials),
            opaque_media: media_behind_opaque_boundaries(&materials),
            fog: None,
            instances,
            materials,
            origin,
            light_sources,
            lights,
            background,
            environment: None,
            emitters,
            emitters_stale: false,
            tlas,
            tlas_build_seconds: start.elapsed().as_secs_f64(),
            merged: None,
            merge_requested: false,
            merge_pending: false,
            quality,
        }
    }

    /// Asks the next [`RenderScene::commit`] to merge the scene's mesh
    /// instances under one BVH (`true`; done only when every bounded
    /// instance is a mesh with a BVH used by no other instance and not
    /// cut out by an alpha material), or undoes a merge (`false`). A merged group is an acceleration structure only:
    /// hits report the instances and triangles they always did, computed
    /// in the render frame instead of object space (the last bits of `t`
    /// and of the barycentrics may differ). It is undone by the first
    /// change that touches a member (a move, new geometry, removal, an
    /// alpha material, a new render origin) and not redone after, so it
    /// suits scenes that stand still; see `scene::merged`. Asking again
    /// while it is asked for does nothing (a frame loop may ask every
    /// frame).
    pub fn set_mesh_merging(&mut self, merge: bool) {
        if merge == self.merge_requested {
            return;
        }
        self.merge_requested = merge;
        self.merge_pending = merge;
        if !merge {
            self.dissolve_merged();
        }
    }

    /// Number of instances in the merged group (0 without one).
    pub fn merged_instances(&self) -> usize {
        self.merged.as_ref().map_or(0, |m| m.member_count())
    }

    /// Bytes of the merged group's BVH, triangles and triangle owners (0
    /// without one).
    pub fn merged_bytes(&self) -> usize {
        self.merged.as_ref().map_or(0, |m| m.bytes())
    }

    /// Builds the merged group if merging is pending (at most once per
    /// request) and takes its members out of the top level.
    pub(super) fn merge_if_pending(&mut self) {
        if !self.merge_pending || self.merged.is_some() {
            return;
        }
        self.merge_pending = false;
        let materials = &self.materials;
        let cutouts = self.cutouts;
        let cut_out = |inst: &Instance| {
            cutouts
                && materials
                    .get(inst.material as usize)
                    .is_none_or(|m| m.alpha.is_some())
        };
        self.merged = MergedMeshes::build(&self.instances, cut_out, self.quality);
        if let Some(m) = &self.merged {
            for i in m.members() {
                self.tlas.updated(i, Placement::Nowhere);
            }
        }
    }

    /// Undoes the merged group: its members go back into the top level
    /// (at the next commit).
    pub(super) fn dissolve_merged(&mut self) {
        if let Some(m) = self.merged.take() {
            for i in m.members() {
                self.tlas.updated(i, self.instances[i as usize].placement());
            }
        }
    }

    /// The render origin: the world point, in f64, at the centre of the
    /// single-precision frame that instances, lights, hits and rays live
    /// in. A world point `p` is `p - origin` in that frame; cameras are
    /// made relative to it by [`CameraRays::relative_to`](crate::scene::camera::CameraRays::relative_to).
    pub fn origin(&self) -> DVec3 {
        self.origin
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

    /// All instances; the top-level BVH indexes this array.
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// True when a material is dispersive: path transport then traces one
    /// wavelength per path (see [`crate::core::spectrum`]).
    pub fn is_spectral(&self) -> bool {
        self.spectral
    }

    /// Material `material` evaluated at texture coordinate `uv` with a
    /// footprint `width_uv` wide ([`Material::sample_lod`]); for a material
    /// without textures, its one surface, evaluated when the material was
    /// set (the same value: an untextured surface does not depend on `uv`).
    /// Saves the metallic-roughness mapping at every hit (about 250
    /// instructions; callgrind, glTF Cornell box).
    #[inline]
    pub fn surface(&self, material: u32, uv: Vec2, width_uv: f32) -> SurfaceSample {
        match &self.surfaces[material as usize] {
            Some(s) => *s,
            None => self.materials[material as usize].sample_lod(uv, width_uv),
        }
    }

    /// The surface sample of an untextured material, the same everywhere
    /// on it ([`RenderScene::surface`] gives it), or `None`.
    #[inline]
    pub fn cached_surface(&self, material: u32) -> Option<&SurfaceSample> {
        self.surfaces[material as usize].as_ref()
    }

    /// Materials referenced by instances.
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// Lights in world space.
    pub fn lights(&self) -> &[WorldLight] {
        &self.lights
    }

    /// Radiance of escaped rays.
    pub fn background(&self) -> Color {
        self.background
    }

    /// The environment, if the scene has one.
    #[inline]
    pub fn environment(&self) -> Option<&Environment> {
        self.environment.as_ref()
    }

    /// Probability with which a next-event light sample of path transport
    /// picks the environment rather than the area lights: 0 without an
    /// environment, 1 without area lights, else one half.
    #[inline]
    pub fn environment_selection(&self) -> f32 {
        match (&self.environment, self.emitters.is_empty()) {
            (None, _) => 0.0,
            (Some(_), true) => 1.0,
            (Some(_), false) => 0.5,
        }
    }

    /// Radiance of a ray that leaves the scene in direction `d`, without
    /// multiple importance sampling (Whitted transport): the
    /// environment's, else the background.
    #[inline]
    pub fn escaped_radiance(&self, d: glam::Vec3A) -> Color {
        match &self.environment {
            Some(env) => env.radiance(d),
            None => self.background,
        }
    }

    /// The medium outside every object (global fog), if any.
    #[inline]
    pub fn fog(&self) -> Option<&Medium> {
        self.fog.as_ref()
    }

    /// Sets or removes the global fog.
    pub fn set_fog(&mut self, fog: Option<Medium>) {
        self.fog = fog;
    }

    /// True when light transport must follow rays through participating
    /// media: the scene has a fog or an object whose interior scatters.
    /// Scenes whose media only absorb inside objects take the exact
    /// Beer-Lambert path of `transport::medium` instead.
    #[inline]
    pub fn has_media(&self) -> bool {
        self.scattering || self.fog.is_some()
    }

    /// True when the shadow rays of surfaces are either blocked or reach
    /// their light unattenuated, so that path transport traces them as
    /// occlusion queries (any hit, in coherent groups) instead of
    /// following them through media
    /// ([`shadow_transmittance`](crate::transport::volume::shadow_transmittance),
    /// closest hits one by one), with the same result: no fog, no
    /// index-matched interface, and every medium the interior of a
    /// subsurface material. Lights are outside subsurface objects (the
    /// model of `transport::volume`), so a shadow ray that starts in one
    /// ends on its boundary, which blocks it, as every surface that is
    /// not an interface does; one that starts outside crosses no medium
    /// before its first surface.
    #[inline]
    pub fn shadows_are_binary(&self) -> bool {
        self.fog.is_none() && self.opaque_media
    }

    /// Sets or removes the environment.
    pub fn set_environment(&mut self, environment: Option<Environment>) {
        self.environment = environment;
    }

    /// This scene with `environment` set (see [`RenderScene::set_environment`]).
    pub fn with_environment(mut self, environment: Option<Environment>) -> Self {
        self.environment = environment;
        self
    }

    /// Emissive surfaces as area lights, for path tracing.
    pub fn emitters(&self) -> &EmitterTable {
        &self.emitters
    }

    /// Seconds spent building the top-level BVH (by [`RenderScene::new`],
    /// or by the last [`RenderScene::commit`] that changed it).
    pub fn tlas_build_seconds(&self) -> f64 {
        self.tlas_build_seconds
    }
}

/// Lights placed in the world, resolved in the frame centred on `origin`.
/// `material`'s surface when it is the same everywhere (no texture).
pub(super) fn constant_surface(material: &Material) -> Option<SurfaceSample> {
    (!material.has_textures()).then(|| material.sample(Vec2::ZERO))
}

/// True when any of `materials` has an alpha mode (cut-outs or
/// transparency), which intersection queries must then honour.
pub(super) fn has_cutouts(materials: &[Material]) -> bool {
    materials.iter().any(|m| m.alpha.is_some())
}

/// True when the interior of any of `materials` scatters.
pub(super) fn has_scattering(materials: &[Material]) -> bool {
    materials.iter().any(|m| m.has_scattering_interior())
}

/// True when no material of `materials` is an index-matched interface
/// ([`Material::is_interface`]) and every interior is a subsurface
/// material's (see [`RenderScene::shadows_are_binary`]).
pub(super) fn media_behind_opaque_boundaries(materials: &[Material]) -> bool {
    materials
        .iter()
        .all(|m| !m.is_interface() && (m.subsurface || m.interior().is_none()))
}

/// True when any of `materials` is dispersive.
pub(super) fn has_dispersion(materials: &[Material]) -> bool {
    materials.iter().any(|m| m.dispersion.is_some())
}

pub(super) fn resolve_lights(sources: &[(Light, Transform)], origin: DVec3) -> Vec<WorldLight> {
    sources
        .iter()
        .map(|(l, t)| WorldLight::new(l, t, origin))
        .collect()
}
