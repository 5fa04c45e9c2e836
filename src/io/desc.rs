//! A loaded scene before it is spawned into an ECS world.
//!
//! Loaders ([`crate::io`]) produce a [`SceneDesc`]; the systems module
//! spawns it as entities. Keeping this plain struct between the two lets
//! loaders stay free of any ECS code and lets tests inspect what was loaded.

use std::sync::Arc;

use crate::core::math::Color;
use crate::geometry::mesh::Mesh;
use crate::geometry::shapes::Shape;
use crate::geometry::transform::Transform;
use crate::scene::camera::Camera;
use crate::scene::light::Light;
use crate::scene::material::Material;

/// What an object's surface is made of.
#[derive(Clone, Debug)]
pub enum Geometry {
    /// An analytic shape.
    Shape(Shape),
    /// A triangle mesh, shared between instances.
    Mesh(Arc<Mesh>),
}

/// One renderable object.
#[derive(Clone, Debug)]
pub struct ObjectDesc {
    /// Optional name, for messages.
    pub name: Option<String>,
    /// Object-to-world transform.
    pub transform: Transform,
    /// Shape or mesh.
    pub geometry: Geometry,
    /// Surface material.
    pub material: Material,
}

/// One light with its placement.
#[derive(Clone, Debug)]
pub struct LightDesc {
    /// Optional name.
    pub name: Option<String>,
    /// Placement: origin is the position, local `-Z` the direction.
    pub transform: Transform,
    /// The light.
    pub light: Light,
}

/// Render settings a scene file may suggest; the command line overrides them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SettingsDesc {
    /// Image width in pixels.
    pub width: Option<u32>,
    /// Image height in pixels.
    pub height: Option<u32>,
    /// Samples per pixel.
    pub spp: Option<u32>,
    /// Maximum recursion depth.
    pub max_depth: Option<u32>,
    /// Contribution threshold for terminating rays.
    pub min_contribution: Option<f32>,
    /// Random seed.
    pub seed: Option<u64>,
    /// Exposure in stops for PNG output.
    pub exposure: Option<f32>,
    /// Light transport.
    pub transport: Option<crate::core::settings::Transport>,
    /// Shadow rays per area light per path-traced hit.
    pub light_samples: Option<u32>,
    /// Russian roulette start depth; `Some(None)` turns it off.
    pub rr_start_depth: Option<Option<u32>>,
    /// Structure over mesh triangles asked for by the file (applied when
    /// it was loaded; kept for reporting).
    pub accel: Option<crate::core::settings::Accel>,
    /// Shading style.
    pub style: Option<crate::core::settings::Style>,
    /// Gooch parameters.
    pub gooch: Option<crate::core::settings::GoochParams>,
    /// Feature lines to draw.
    pub lines: Option<crate::core::settings::LineSettings>,
    /// Random numbers.
    pub sampler: Option<crate::core::rng::SamplerKind>,
    /// Camera projection: `Some(None)` is the perspective camera,
    /// `Some(Some(p))` a panorama.
    pub panorama: Option<Option<crate::core::settings::Panorama>>,
    /// The light-field capture rig (`[lightfield]`), for `prism lightfield
    /// capture`; not part of [`SettingsDesc::resolve`].
    pub lightfield: Option<crate::core::settings::LightFieldSettings>,
}

impl SettingsDesc {
    /// Render settings from these values, falling back to `under` (the
    /// scene's own settings, say) and then to the defaults.
    pub fn resolve(&self, under: &SettingsDesc) -> crate::core::settings::RenderSettings {
        let d = crate::core::settings::RenderSettings::default();
        crate::core::settings::RenderSettings {
            width: self.width.or(under.width).unwrap_or(d.width),
            height: self.height.or(under.height).unwrap_or(d.height),
            spp: self.spp.or(under.spp).unwrap_or(d.spp),
            max_depth: self.max_depth.or(under.max_depth).unwrap_or(d.max_depth),
            min_contribution: self
                .min_contribution
                .or(under.min_contribution)
                .unwrap_or(d.min_contribution),
            seed: self.seed.or(under.seed).unwrap_or(d.seed),
            transport: self.transport.or(under.transport).unwrap_or(d.transport),
            light_samples: self
                .light_samples
                .or(under.light_samples)
                .unwrap_or(d.light_samples),
            rr_start_depth: self
                .rr_start_depth
                .or(under.rr_start_depth)
                .unwrap_or(d.rr_start_depth),
            window: None,
            style: self.style.or(under.style).unwrap_or(d.style),
            gooch: self.gooch.or(under.gooch).unwrap_or(d.gooch),
            lines: self.lines.or(under.lines),
            sampler: self.sampler.or(under.sampler).unwrap_or(d.sampler),
            panorama: self.panorama.or(under.panorama).unwrap_or(d.panorama),
        }
    }
}

/// A whole scene as loaded from files.
#[derive(Clone, Debug, Default)]
pub struct SceneDesc {
    /// Renderable objects.
    pub objects: Vec<ObjectDesc>,
    /// Lights.
    pub lights: Vec<LightDesc>,
    /// Cameras, in file order (the project's own camera first, then those
    /// of included glTF files).
    pub cameras: Vec<Camera>,
    /// Radiance of rays that escape the scene.
    pub background: Color,
    /// Light from infinitely far away (replaces `background` when
    /// present).
    pub environment: Option<crate::scene::environment::Environment>,
    /// Suggested settings.
    pub settings: SettingsDesc,
}

impl SceneDesc {
    /// Appends another scene's objects, lights and cameras (used when a
    /// scene file includes a glTF file).
    pub fn append(&mut self, other: SceneDesc) {
        self.objects.extend(other.objects);
        self.lights.extend(other.lights);
        self.cameras.extend(other.cameras);
    }
}
