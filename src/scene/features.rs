//! What a scene contains, analysed once per frame, so that the renderer
//! runs only the stages the scene needs: shading kernels for the material
//! classes present, shadow rays only when something can be lit, area-light
//! sampling only when there are emitters.

use serde::Serialize;

use crate::core::settings::Transport;
use crate::scene::instance::InstanceGeometry;
use crate::scene::light::WorldLight;
use crate::scene::material::MaterialClass;
use crate::scene::render_scene::RenderScene;

/// A summary of a scene's features.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SceneFeatures {
    /// Which material classes occur, indexed by `MaterialClass as usize`.
    #[serde(skip)]
    pub classes: [bool; 5],
    /// Names of the material classes that occur.
    pub material_classes: Vec<&'static str>,
    /// Point lights.
    pub point_lights: usize,
    /// Spot lights.
    pub spot_lights: usize,
    /// Directional lights.
    pub directional_lights: usize,
    /// Emissive primitives sampled as area lights by path transport.
    pub area_light_primitives: usize,
    /// Kinds of analytic shape, sorted by name.
    pub shapes: Vec<&'static str>,
    /// Mesh instances (each has a triangle BVH; a scene without meshes
    /// builds none).
    pub mesh_instances: usize,
    /// Whether any material reads a texture.
    pub textures: bool,
    /// Whether the scene has an environment (escaped rays look it up;
    /// path transport samples it as a light).
    pub environment: bool,
}

/// What a material class does: the one table that stage gating, the
/// shading kernels and the scene summary read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClassTraits {
    /// Lower-case name (stage names are `shade_<name>`).
    pub name: &'static str,
    /// Evaluates lights: a diffuse or glossy lobe, so shadow rays (and,
    /// under path transport, next-event estimation and diffuse bounces).
    pub lit: bool,
    /// Spawns specular reflection or refraction rays.
    pub scatters: bool,
}

/// [`ClassTraits`] of every class, indexed by `MaterialClass as usize`.
pub const CLASS_TRAITS: [ClassTraits; 5] = [
    ClassTraits {
        name: "emissive",
        lit: false,
        scatters: false,
    },
    ClassTraits {
        name: "diffuse",
        lit: true,
        scatters: false,
    },
    ClassTraits {
        name: "mirror",
        lit: false,
        scatters: true,
    },
    ClassTraits {
        name: "glass",
        lit: false,
        scatters: true,
    },
    ClassTraits {
        name: "general",
        lit: true,
        scatters: true,
    },
];

impl MaterialClass {
    /// This class's row of [`CLASS_TRAITS`].
    pub fn traits(self) -> ClassTraits {
        CLASS_TRAITS[self as usize]
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        self.traits().name
    }

    /// Does this class evaluate the lights (shadow rays)?
    pub fn is_lit(self) -> bool {
        self.traits().lit
    }

    /// Can this class spawn reflection or refraction rays?
    pub fn scatters(self) -> bool {
        self.traits().scatters
    }
}

impl SceneFeatures {
    /// Analyses `scene`: classes of the materials that instances use,
    /// lights by kind, shapes, meshes and textures.
    pub fn of(scene: &RenderScene) -> Self {
        let mut f = SceneFeatures::default();
        let mut shapes = std::collections::BTreeSet::new();
        for inst in &scene.instances {
            if let Some(m) = scene.materials.get(inst.material as usize) {
                f.classes[m.class() as usize] = true;
                f.textures |= m.base_color_texture.is_some()
                    || m.emission_texture.is_some()
                    || m.metallic_roughness
                        .as_ref()
                        .is_some_and(|mr| mr.texture.is_some());
            }
            match &inst.geometry {
                InstanceGeometry::Shape(s) => {
                    shapes.insert(s.kind_name());
                }
                InstanceGeometry::Mesh(_) => f.mesh_instances += 1,
            }
        }
        f.material_classes = MaterialClass::ALL
            .into_iter()
            .filter(|c| f.classes[*c as usize])
            .map(MaterialClass::name)
            .collect();
        for l in &scene.lights {
            match l {
                WorldLight::Point { .. } => f.point_lights += 1,
                WorldLight::Spot { .. } => f.spot_lights += 1,
                WorldLight::Directional { .. } => f.directional_lights += 1,
            }
        }
        f.area_light_primitives = scene.emitters.len();
        f.environment = scene.environment.is_some();
        f.shapes = shapes.into_iter().collect();
        f
    }

    /// True when a material of `class` occurs.
    pub fn has(&self, class: MaterialClass) -> bool {
        self.classes[class as usize]
    }

    /// True when shading can push shadow rays under `transport`: some
    /// material evaluates lights and some light exists (area lights count
    /// and the environment only for path transport).
    pub fn needs_shadow_rays(&self, transport: Transport) -> bool {
        let lit = MaterialClass::ALL
            .into_iter()
            .any(|c| c.is_lit() && self.has(c));
        let punctual = self.point_lights + self.spot_lights + self.directional_lights > 0;
        let area =
            transport == Transport::Path && (self.area_light_primitives > 0 || self.environment);
        lit && (punctual || area)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_class_table_is_in_class_order() {
        let names: Vec<_> = MaterialClass::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(names, ["emissive", "diffuse", "mirror", "glass", "general"]);
        assert!(MaterialClass::General.is_lit() && MaterialClass::General.scatters());
        assert!(!MaterialClass::Emissive.is_lit() && !MaterialClass::Emissive.scatters());
    }
}
