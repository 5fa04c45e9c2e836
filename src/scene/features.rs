//! What a scene contains, analysed once per frame, so that the renderer
//! runs only the stages the scene needs: shading kernels for the material
//! classes present, shadow rays only when something can be lit, area-light
//! sampling only when there are emitters.

use serde::Serialize;

use crate::core::settings::Transport;
use crate::scene::light::WorldLight;
use crate::scene::material::MaterialClass;
use crate::scene::{InstanceGeometry, RenderScene};

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
}

/// Lower-case name of a material class.
pub fn class_name(c: MaterialClass) -> &'static str {
    match c {
        MaterialClass::Emissive => "emissive",
        MaterialClass::Diffuse => "diffuse",
        MaterialClass::Mirror => "mirror",
        MaterialClass::Glass => "glass",
        MaterialClass::General => "general",
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
            .map(class_name)
            .collect();
        for l in &scene.lights {
            match l {
                WorldLight::Point { .. } => f.point_lights += 1,
                WorldLight::Spot { .. } => f.spot_lights += 1,
                WorldLight::Directional { .. } => f.directional_lights += 1,
            }
        }
        f.area_light_primitives = scene.emitters.len();
        f.shapes = shapes.into_iter().collect();
        f
    }

    /// True when a material of `class` occurs.
    pub fn has(&self, class: MaterialClass) -> bool {
        self.classes[class as usize]
    }

    /// True when shading can push shadow rays under `transport`: some
    /// material evaluates lights and some light exists (area lights count
    /// only for path transport).
    pub fn needs_shadow_rays(&self, transport: Transport) -> bool {
        let lit = self.has(MaterialClass::Diffuse) || self.has(MaterialClass::General);
        let punctual = self.point_lights + self.spot_lights + self.directional_lights > 0;
        let area = transport == Transport::Path && self.area_light_primitives > 0;
        lit && (punctual || area)
    }
}
