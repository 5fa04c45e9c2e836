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
    /// Russian roulette's weight.
    pub rr_weight: Option<f32>,
    /// Paths continued from each camera ray's first hit (path tracing).
    pub split: Option<u32>,
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
    /// Radiosity's options (each optional).
    pub radiosity: crate::core::radiosity::RadiosityDesc,
    /// Camera projection: `Some(None)` is the perspective camera,
    /// `Some(Some(p))` a panorama.
    pub panorama: Option<Option<crate::core::settings::Panorama>>,
    /// The light-field capture rig (`[lightfield]`), for `prism lightfield
    /// capture`; not part of [`SettingsDesc::resolve`].
    pub lightfield: Option<crate::core::settings::LightFieldSettings>,
    /// Photon mapping's parameters, each optional.
    pub photon: crate::core::photon_settings::PhotonOverrides,
    /// Light tracing of directly seen caustics.
    pub caustics: Option<bool>,
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
            rr_weight: self.rr_weight.or(under.rr_weight).unwrap_or(d.rr_weight),
            split: self.split.or(under.split).unwrap_or(d.split),
            window: None,
            style: self.style.or(under.style).unwrap_or(d.style),
            gooch: self.gooch.or(under.gooch).unwrap_or(d.gooch),
            lines: self.lines.or(under.lines),
            sampler: self.sampler.or(under.sampler).unwrap_or(d.sampler),
            radiosity: self.radiosity.resolve(&under.radiosity),
            panorama: self.panorama.or(under.panorama).unwrap_or(d.panorama),
            photon: self.photon.or(under.photon).resolve(),
            caustics: self.caustics.or(under.caustics).unwrap_or(d.caustics),
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
    /// The medium filling the space outside every object (a global fog).
    pub fog: Option<crate::core::medium::Medium>,
    /// Suggested settings.
    pub settings: SettingsDesc,
}

impl SceneDesc {
    /// The world-space box around every bounded object (analytic shapes
    /// and meshes through their transforms; infinite planes are left out),
    /// or `None` when there is no bounded object.
    pub fn world_bounds(&self) -> Option<(glam::DVec3, glam::DVec3)> {
        use glam::DVec3;
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for o in &self.objects {
            let b = match &o.geometry {
                Geometry::Shape(s) => s.bounds(),
                Geometry::Mesh(m) => m.bounds(),
            };
            let Some((a, b)) = b else { continue };
            for i in 0..8 {
                let c = glam::Vec3A::select(
                    glam::BVec3A::new(i & 1 != 0, i & 2 != 0, i & 4 != 0),
                    b,
                    a,
                );
                let w = o.transform.0.transform_point3(c.as_dvec3());
                if w.is_finite() {
                    lo = lo.min(w);
                    hi = hi.max(w);
                }
            }
        }
        (lo.cmple(hi).all()).then_some((lo, hi))
    }

    /// True when the scene is lit under `transport`: it has a punctual
    /// light; or, under path, photon and radiosity transport (where
    /// emissive surfaces are area lights, emit photons or are the
    /// solution's sources), an emissive surface; or, under
    /// path transport (the only one that samples it as a light), an
    /// environment.
    pub fn is_lit(&self, transport: crate::core::settings::Transport) -> bool {
        use crate::core::settings::Transport;
        let emissive = || {
            self.objects
                .iter()
                .any(|o| o.material.emission.max_element() > 0.0)
        };
        !self.lights.is_empty()
            || (matches!(
                transport,
                Transport::Path | Transport::Photon | Transport::Radiosity
            ) && emissive())
            || (transport == Transport::Path && self.environment.is_some())
    }

    /// Gives a scene without a camera one, the way glTF viewers show a
    /// bare model: [`frame_bounds`](crate::scene::camera::frame_bounds) of
    /// [`SceneDesc::world_bounds`] (a unit box at the origin when nothing is
    /// bounded) for an image of aspect ratio `aspect`. Returns a notice for
    /// standard error when it added one.
    pub fn ensure_camera(&mut self, aspect: f64) -> Option<String> {
        if !self.cameras.is_empty() {
            return None;
        }
        let (lo, hi) = self
            .world_bounds()
            .unwrap_or((glam::DVec3::splat(-0.5), glam::DVec3::splat(0.5)));
        self.cameras
            .push(crate::scene::camera::frame_bounds(lo, hi, aspect));
        Some(format!(
            "the scene has no camera; framing its bounds from +Z ({} degree vertical field of view)",
            crate::scene::camera::AUTO_VFOV_DEGREES
        ))
    }

    /// Gives a scene that is not lit under `transport`
    /// ([`SceneDesc::is_lit`]) the default lighting: under path transport
    /// a uniform white environment of radiance 1 ([`default_environment`]:
    /// light from every direction, as glTF viewers show a bare model),
    /// under the other transports (which do not light surfaces with an
    /// environment) the key light of [`default_lights`] for `camera`.
    /// Returns a notice for standard error when it added either.
    pub fn ensure_light(
        &mut self,
        camera: &Camera,
        transport: crate::core::settings::Transport,
    ) -> Option<String> {
        if self.is_lit(transport) {
            return None;
        }
        if transport == crate::core::settings::Transport::Path {
            let (environment, what) = default_environment();
            self.environment = Some(environment);
            return Some(format!("the scene has no light; adding {what}"));
        }
        let (lights, what) = default_lights(camera);
        self.lights.extend(lights);
        Some(format!("the scene has no light; adding {what}"))
    }

    /// Appends another scene's objects, lights and cameras (used when a
    /// scene file includes a glTF file).
    pub fn append(&mut self, other: SceneDesc) {
        self.objects.extend(other.objects);
        self.lights.extend(other.lights);
        self.cameras.extend(other.cameras);
    }
}

/// The environment an unlit scene gets under path transport
/// ([`SceneDesc::ensure_light`]): uniform white of radiance 1 (a white
/// Lambertian surface under it, unshadowed, has radiance 1), and a few
/// words saying what it is.
pub fn default_environment() -> (crate::scene::environment::Environment, String) {
    (
        crate::scene::environment::Environment::uniform(Color::ONE),
        "a uniform white environment of radiance 1".to_string(),
    )
}

/// Illuminance of the default key light, lux: a white Lambertian surface
/// facing it has radiance `E / pi`, about 1.
pub const DEFAULT_KEY_LUX: f32 = std::f32::consts::PI;

/// The lights an unlit scene gets under Whitted, photon and radiosity
/// transport ([`SceneDesc::ensure_light`]), and a few words saying what
/// they are: one directional "key" light of
/// [`DEFAULT_KEY_LUX`] lux, white, shining from behind the camera's left
/// shoulder (from the eye's side, rotated 30 degrees up and 30 degrees to
/// the left of the viewing direction) so that faces turned towards the
/// camera are lit and shapes read by their shading.
///
/// With [`default_environment`], the one place that decides the default
/// lighting.
pub fn default_lights(camera: &Camera) -> (Vec<LightDesc>, String) {
    use glam::{DMat3, DVec3};
    let forward = (camera.look_at - camera.look_from).normalize_or(DVec3::NEG_Z);
    let up_hint = camera.up.as_dvec3();
    let right = forward.cross(up_hint).normalize_or(DVec3::X);
    let up = right.cross(forward);
    let angle = 30f64.to_radians();
    // Travel direction: the viewing direction turned down and to the right,
    // so the light comes from above and from the left.
    let direction = (forward * angle.cos() * angle.cos() - up * angle.sin()
        + right * angle.cos() * angle.sin())
    .normalize();
    // A transform whose local -Z is `direction`.
    let z = -direction;
    let x = up.cross(z).normalize_or(DVec3::X);
    let y = z.cross(x);
    let rotation = glam::DQuat::from_mat3(&DMat3::from_cols(x, y, z));
    let light = LightDesc {
        name: Some("default key light".into()),
        transform: Transform::from_trs(DVec3::ZERO, rotation, DVec3::ONE),
        light: Light::Directional {
            illuminance: Color::splat(DEFAULT_KEY_LUX),
        },
    };
    (
        vec![light],
        format!(
            "a white directional key light of {DEFAULT_KEY_LUX:.2} lux from above the camera's left shoulder"
        ),
    )
}
