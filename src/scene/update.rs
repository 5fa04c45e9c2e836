//! The incremental-update API of a [`RenderScene`].

use crate::accel::tlas::{TlasCounters, TlasPolicy, TlasUpdate};
use crate::core::math::Color;
use crate::geometry::transform::Transform;
use crate::scene::emitters::EmitterTable;
use crate::scene::instance::{Instance, InstanceGeometry};
use crate::scene::light::Light;
use crate::scene::material::Material;
use crate::scene::render_scene::{
    RenderScene, constant_surface, has_cutouts, has_dispersion, has_scattering,
    media_behind_opaque_boundaries, resolve_lights,
};
use glam::DVec3;

/// Incremental updates, for scenes that change from frame to frame.
///
/// Every change goes through these methods and becomes visible to
/// traversal at the next [`RenderScene::commit`], which is also the one
/// place where anything derived from instances and materials is brought up
/// to date. Between a change and the commit, intersection queries must not
/// be made. Mesh BVHs are never rebuilt: they live in the shared
/// [`Mesh`](crate::geometry::mesh::Mesh)es; only the top level over instances changes.
impl RenderScene {
    /// Appends an instance; returns its index. Its material index must be
    /// valid once the scene is committed.
    pub fn push_instance(&mut self, mut instance: Instance) -> u32 {
        self.emitters_stale = true;
        instance.rebase(self.origin);
        let index = self.instances.len() as u32;
        self.tlas.inserted(index, instance.placement());
        self.instances.push(instance);
        if let Some(m) = &mut self.merged {
            m.pushed();
        }
        index
    }

    /// Removes instance `index` by moving the last instance into its place
    /// (so the last instance's index becomes `index`); returns the removed
    /// instance. Panics if `index` is out of range.
    pub fn swap_remove_instance(&mut self, index: u32) -> Instance {
        assert!(
            (index as usize) < self.instances.len(),
            "instance {index} out of range ({} instances)",
            self.instances.len()
        );
        self.emitters_stale = true;
        let last = self.instances.len() as u32 - 1;
        if self
            .merged
            .as_ref()
            .is_some_and(|m| m.is_member(index) || m.is_member(last))
        {
            self.dissolve_merged();
        }
        if let Some(m) = &mut self.merged {
            m.swap_removed(index);
        }
        self.tlas.removing(index, last);
        self.instances.swap_remove(index as usize)
    }

    /// Moves instance `index`; `transform` must be valid
    /// ([`Transform::is_valid`]).
    pub fn set_instance_transform(&mut self, index: u32, transform: &Transform) {
        self.emitters_stale = true;
        self.dissolve_if_member(index);
        let inst = &mut self.instances[index as usize];
        inst.world = *transform;
        inst.rebase(self.origin);
        self.tlas.updated(index, inst.placement());
    }

    /// Gives instance `index` another shape or mesh (the mesh's own BVH is
    /// reused as it is).
    pub fn set_instance_geometry(&mut self, index: u32, geometry: InstanceGeometry) {
        self.emitters_stale = true;
        self.dissolve_if_member(index);
        let inst = &mut self.instances[index as usize];
        inst.geometry = geometry;
        self.tlas.updated(index, inst.placement());
    }

    /// Points instance `index` at material `material`.
    pub fn set_instance_material(&mut self, index: u32, material: u32) {
        self.emitters_stale = true;
        // A merged instance may not be cut away by its material.
        if self
            .materials
            .get(material as usize)
            .is_none_or(|m| m.alpha.is_some())
        {
            self.dissolve_if_member(index);
        }
        self.instances[index as usize].material = material;
    }

    /// Appends a material; returns its index.
    pub fn push_material(&mut self, material: Material) -> u32 {
        self.emitters_stale = true;
        self.cutouts |= material.alpha.is_some();
        self.spectral |= material.dispersion.is_some();
        self.scattering |= material.has_scattering_interior();
        self.opaque_media &= media_behind_opaque_boundaries(std::slice::from_ref(&material));
        self.surfaces.push(constant_surface(&material));
        self.materials.push(material);
        self.materials.len() as u32 - 1
    }

    /// Replaces material `index`. Touches no BVH.
    pub fn set_material(&mut self, index: u32, material: Material) {
        self.emitters_stale = true;
        if material.alpha.is_some()
            && let Some(m) = &self.merged
            && m.members()
                .any(|i| self.instances[i as usize].material == index)
        {
            self.dissolve_merged();
        }
        self.surfaces[index as usize] = constant_surface(&material);
        self.materials[index as usize] = material;
        self.cutouts = has_cutouts(&self.materials);
        self.spectral = has_dispersion(&self.materials);
        self.scattering = has_scattering(&self.materials);
        self.opaque_media = media_behind_opaque_boundaries(&self.materials);
    }

    /// Removes material `index` by moving the last material into its
    /// place; instances that used the last material are pointed at
    /// `index`. No instance may still use the removed material.
    pub fn swap_remove_material(&mut self, index: u32) -> Material {
        assert!(
            (index as usize) < self.materials.len(),
            "material {index} out of range ({} materials)",
            self.materials.len()
        );
        self.emitters_stale = true;
        let last = self.materials.len() as u32 - 1;
        if index != last {
            for inst in &mut self.instances {
                if inst.material == last {
                    inst.material = index;
                }
            }
        }
        self.surfaces.swap_remove(index as usize);
        let removed = self.materials.swap_remove(index as usize);
        self.cutouts = has_cutouts(&self.materials);
        self.spectral = has_dispersion(&self.materials);
        self.scattering = has_scattering(&self.materials);
        self.opaque_media = media_behind_opaque_boundaries(&self.materials);
        removed
    }

    /// Replaces the lights (placed in world coordinates).
    pub fn set_lights(&mut self, lights: Vec<(Light, Transform)>) {
        self.lights = resolve_lights(&lights, self.origin);
        self.light_sources = lights;
    }

    /// Moves the render origin to `origin` (a world point, f64): every
    /// instance and light is re-expressed relative to it, and the top
    /// level is updated at the next commit. No mesh BVH is touched (they
    /// live in object space). Returns whether the origin changed.
    pub fn set_origin(&mut self, origin: DVec3) -> bool {
        if origin == self.origin {
            return false;
        }
        self.origin = origin;
        self.emitters_stale = true;
        // The merged corners are in the old frame.
        self.dissolve_merged();
        for (i, inst) in self.instances.iter_mut().enumerate() {
            inst.rebase(origin);
            self.tlas.updated(i as u32, inst.placement());
        }
        self.lights = resolve_lights(&self.light_sources, origin);
        true
    }

    /// Sets the radiance of escaped rays.
    pub fn set_background(&mut self, background: Color) {
        self.background = background;
    }

    /// Makes the changes since the last commit visible: rebuilds the
    /// emitter table if instances or materials changed, updates the top
    /// level (leaf updates then a conversion, or a full rebuild above the
    /// churn threshold of [`TlasPolicy`]), and returns what was done to
    /// the top level.
    pub fn commit(&mut self) -> TlasUpdate {
        if self.emitters_stale {
            // Area lights follow moved, added, removed and re-materialed
            // instances; this is a table, not a BVH.
            self.emitters = EmitterTable::build(&self.instances, &self.materials);
            self.emitters_stale = false;
        }
        self.merge_if_pending();
        let merged = &self.merged;
        let instances = &self.instances;
        let update = self.tlas.commit(instances.len(), |i| match merged {
            Some(m) if m.is_member(i as u32) => crate::accel::tlas::Placement::Nowhere,
            _ => instances[i].placement(),
        });
        if update != TlasUpdate::Unchanged {
            self.tlas_build_seconds = self.tlas.last_seconds;
        }
        update
    }

    /// Undoes the merged group if instance `index` is in it.
    fn dissolve_if_member(&mut self, index: u32) {
        if self.merged.as_ref().is_some_and(|m| m.is_member(index)) {
            self.dissolve_merged();
        }
    }

    /// Cumulative work done on the top level.
    pub fn tlas_counters(&self) -> TlasCounters {
        self.tlas.counters()
    }

    /// The policy deciding between leaf updates and rebuilds.
    pub fn tlas_policy(&self) -> TlasPolicy {
        self.tlas.policy
    }

    /// Changes the policy deciding between leaf updates and rebuilds.
    pub fn set_tlas_policy(&mut self, policy: TlasPolicy) {
        self.tlas.policy = policy;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::build::BuildQuality;

    fn empty() -> RenderScene {
        RenderScene::new(
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Color::ZERO,
            BuildQuality::Medium,
        )
    }

    // On an empty scene `len - 1` used to underflow (a debug-build
    // overflow panic, a wrap to u32::MAX in release) before the range
    // check could report the bad index.
    #[test]
    #[should_panic(expected = "instance 0 out of range (0 instances)")]
    fn removing_an_instance_from_an_empty_scene_names_the_index() {
        empty().swap_remove_instance(0);
    }

    /// What shading reads through [`RenderScene::surface`] follows every
    /// material update: an untextured material's surface (evaluated once)
    /// after a push, a replacement and a swap-removal, and a textured
    /// material's surface at each point.
    #[test]
    fn surfaces_follow_material_updates() {
        use crate::scene::material::{Material, Texture};
        use glam::Vec2;
        let plain = |r: f32| Material {
            base_color: Color::new(r, 0.5, 0.25),
            ..Default::default()
        };
        let checker = Material {
            base_color_texture: Some(Texture::Checker {
                scale: 2.0,
                even: Color::ONE,
                odd: Color::ZERO,
            }),
            ..Default::default()
        };
        let uvs = [Vec2::new(0.1, 0.1), Vec2::new(0.6, 0.1)];
        let check = |scene: &RenderScene, i: u32, m: &Material| {
            for uv in uvs {
                assert_eq!(
                    scene.surface(i, uv, 0.0),
                    m.sample(uv),
                    "material {i} at {uv}"
                );
            }
        };
        let mut scene = empty();
        let a = scene.push_material(plain(0.9));
        let b = scene.push_material(checker.clone());
        check(&scene, a, &plain(0.9));
        check(&scene, b, &checker);
        // The checker's squares differ: the surface really is read per point.
        assert_ne!(scene.surface(b, uvs[0], 0.0), scene.surface(b, uvs[1], 0.0));
        scene.set_material(a, plain(0.2));
        check(&scene, a, &plain(0.2));
        scene.set_material(b, plain(0.7));
        check(&scene, b, &plain(0.7));
        scene.set_material(a, checker.clone());
        check(&scene, a, &checker);
        scene.swap_remove_material(a);
        check(&scene, 0, &plain(0.7));
    }

    /// [`RenderScene::shadows_are_binary`] follows the materials and the
    /// fog: true for subsurface interiors alone, false once a shadow ray
    /// could be seen through a medium (an absorbing glass, an
    /// index-matched interface, a fog), and true again when that is gone.
    #[test]
    fn binary_shadows_follow_material_updates_and_fog() {
        use crate::core::medium::Medium;
        let diffuse = Material::default();
        let subsurface = Material {
            subsurface: true,
            absorption: Color::splat(0.1),
            scattering: Color::splat(2.0),
            ..Default::default()
        };
        let glass = |absorption: f32, ior: f32| Material {
            base_color: Color::ONE,
            diffuse: 0.0,
            transmission: 1.0,
            ior,
            absorption: Color::splat(absorption),
            ..Default::default()
        };
        assert!(glass(0.0, 1.0).is_interface());
        let mut scene = empty();
        assert!(scene.shadows_are_binary(), "empty scene");
        scene.push_material(diffuse.clone());
        let s = scene.push_material(subsurface.clone());
        assert!(scene.shadows_are_binary(), "subsurface interior");
        let g = scene.push_material(glass(0.5, 1.5));
        assert!(!scene.shadows_are_binary(), "absorbing glass pushed");
        scene.set_material(g, glass(0.0, 1.5));
        assert!(scene.shadows_are_binary(), "clear glass");
        scene.set_material(s, glass(0.0, 1.0));
        assert!(!scene.shadows_are_binary(), "interface");
        scene.swap_remove_material(s);
        assert!(scene.shadows_are_binary(), "interface removed");
        scene.set_fog(Some(Medium {
            sigma_a: Color::splat(0.1),
            sigma_s: Color::splat(0.1),
            g: 0.0,
        }));
        assert!(!scene.shadows_are_binary(), "fog");
        scene.set_fog(None);
        assert!(scene.shadows_are_binary(), "fog removed");
    }

    #[test]
    #[should_panic(expected = "material 0 out of range (0 materials)")]
    fn removing_a_material_from_an_empty_scene_names_the_index() {
        empty().swap_remove_material(0);
    }
}
