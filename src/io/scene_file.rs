//! The project's own scene format: TOML, read through serde.
//!
//! It says what glTF cannot: analytic shapes and quadrics, Phong-style
//! materials, procedural textures and render settings; it can include
//! glTF files. The schema is documented in the README ("Scene format");
//! unknown keys are errors, so typos do not pass silently. Relative file
//! paths are relative to the scene file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DQuat, DVec3, Vec3};
use serde::Deserialize;

use crate::core::error::{Error, Result};
use crate::core::math::Color;
use crate::core::medium::Medium;
use crate::core::optics;
use crate::core::spectrum::{Dispersion, LAMBDA_D, Sellmeier};
use crate::geometry::mesh::{BuildOptions, Mesh, MeshData, NormalMode};
use crate::geometry::shapes::Shape;
use crate::geometry::transform::Transform;
use crate::image::output::srgb_to_linear;
use crate::io::desc::{Geometry, LightDesc, ObjectDesc, SceneDesc, SettingsDesc};
use crate::scene::camera::Camera;
use crate::scene::environment::{Environment, EnvironmentSource};
use crate::scene::light::Light;
use crate::scene::material::{ImageTexture, Material, Texture, UvTransform};

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileScene {
    #[serde(default)]
    settings: FileSettings,
    camera: Option<FileCamera>,
    #[serde(default)]
    materials: BTreeMap<String, FileMaterial>,
    #[serde(default)]
    objects: Vec<FileObject>,
    #[serde(default)]
    lights: Vec<FileLight>,
    #[serde(default)]
    gltf: Vec<FileInclude>,
    environment: Option<FileEnvironment>,
    lightfield: Option<FileLightField>,
    medium: Option<FileMedium>,
}

/// `[medium]`: the global fog, by physical parameters (`absorption`,
/// `scattering`, `g`) or by the artist's (`albedo`, `mean_free_path`, `g`).
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileMedium {
    absorption: Option<FileColor>,
    scattering: Option<FileColor>,
    g: Option<f32>,
    albedo: Option<FileColor>,
    mean_free_path: Option<FileColor>,
}

/// `[lightfield]`: the capture rig of `prism lightfield capture`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileLightField {
    grid: Option<[u32; 2]>,
    spacing: Option<f64>,
    resolution: Option<[u32; 2]>,
    focal_distance: Option<f64>,
}

/// `[environment]`: an equirectangular map (`path`) or a uniform `color`,
/// scaled by `intensity` and turned by `rotation` degrees about +Y.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileEnvironment {
    path: Option<PathBuf>,
    color: Option<FileColor>,
    #[serde(default = "one")]
    intensity: f32,
    #[serde(default)]
    rotation: f32,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileSettings {
    width: Option<u32>,
    height: Option<u32>,
    spp: Option<u32>,
    max_depth: Option<u32>,
    min_contribution: Option<f32>,
    seed: Option<u64>,
    exposure: Option<f32>,
    background: Option<[f32; 3]>,
    transport: Option<FileTransport>,
    light_samples: Option<u32>,
    /// Russian roulette start depth; `false` turns it off.
    russian_roulette: Option<FileRoulette>,
    /// Russian roulette's weight, in (0, 1].
    rr_weight: Option<f32>,
    /// Paths continued from each camera ray's first hit (path tracing),
    /// 1 to 64.
    split: Option<u32>,
    /// Light tracing of directly seen caustics (path transport, recursive
    /// integrator).
    caustics: Option<bool>,
    /// Structure over mesh triangles: bvh, kdtree, grid or brute.
    accel: Option<crate::core::settings::Accel>,
    /// `"shaded"` or `"gooch"`.
    style: Option<FileStyle>,
    /// Gooch parameters (each optional).
    gooch: Option<FileGooch>,
    /// Feature lines; the table's presence turns them on.
    lines: Option<FileLines>,
    /// `"sobol"` or `"hash"`.
    sampler: Option<FileSampler>,
    /// Radiosity's options (`[settings.radiosity]`).
    radiosity: Option<crate::core::radiosity::RadiosityDesc>,
    /// `"perspective"`, `"equirect"` or `"cubemap"`.
    camera_projection: Option<FileProjection>,
    /// Photon mapping (each optional).
    photon: Option<FilePhoton>,
}

#[derive(Deserialize, Clone, Copy, Default)]
#[serde(deny_unknown_fields)]
struct FilePhoton {
    photons: Option<u32>,
    radius: Option<f32>,
    alpha: Option<f32>,
    iterations: Option<u32>,
    gather_rays: Option<u32>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum FileProjection {
    Perspective,
    Equirect,
    Cubemap,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum FileSampler {
    Sobol,
    Hash,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum FileStyle {
    Shaded,
    Gooch,
}

#[derive(Deserialize, Clone, Copy, Default)]
#[serde(deny_unknown_fields)]
struct FileGooch {
    b: Option<f32>,
    y: Option<f32>,
    alpha: Option<f32>,
    beta: Option<f32>,
}

#[derive(Deserialize, Clone, Copy, Default)]
#[serde(deny_unknown_fields)]
struct FileLines {
    width: Option<f32>,
    color: Option<[f32; 3]>,
    crease_angle: Option<f32>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum FileTransport {
    Whitted,
    Path,
    Radiosity,
    Photon,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum FileRoulette {
    Enabled(bool),
    StartDepth(u32),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileCamera {
    look_from: [f64; 3],
    look_at: [f64; 3],
    #[serde(default = "default_up")]
    up: [f32; 3],
    #[serde(default = "default_vfov")]
    vfov: f32,
    /// Lens shift `[right, up]` in image heights.
    #[serde(default)]
    shift: [f32; 2],
    /// Thin lens: aperture radius in scene units (0: pinhole).
    aperture_radius: Option<f32>,
    /// Thin lens: f-number (see `Camera::set_f_number`).
    f_number: Option<f32>,
    /// Thin lens: distance of the plane in focus (default: to `look_at`).
    focus_distance: Option<f32>,
    /// Orthographic projection: half the height of the view, in scene units.
    ortho_half_height: Option<f32>,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_vfov() -> f32 {
    40.0
}

/// A colour given as one number (grey) or as `[r, g, b]`.
#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum FileColor {
    Grey(f32),
    Rgb([f32; 3]),
}

impl FileColor {
    fn get(self) -> Color {
        match self {
            FileColor::Grey(g) => Color::splat(g),
            FileColor::Rgb(c) => Color::from(c),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "lowercase")]
enum FileTexture {
    Checker {
        #[serde(default = "one")]
        scale: f32,
        even: FileColor,
        odd: FileColor,
    },
    Image {
        path: PathBuf,
    },
}

fn one() -> f32 {
    1.0
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileMaterial {
    color: Option<FileColor>,
    texture: Option<FileTexture>,
    diffuse: Option<f32>,
    specular: Option<FileColor>,
    shininess: Option<f32>,
    mirror: Option<FileColor>,
    transmission: Option<f32>,
    ior: Option<f32>,
    emission: Option<FileColor>,
    /// Absorption coefficient of the interior (sigma_a, per unit length).
    absorption: Option<FileColor>,
    /// Colour left after `attenuation_distance` inside (the artist's form).
    attenuation_color: Option<FileColor>,
    attenuation_distance: Option<f32>,
    /// Dispersion by Sellmeier's equation: a preset name or coefficients.
    sellmeier: Option<FileSellmeier>,
    /// Dispersion by an Abbe number (Cauchy's law through `ior`).
    abbe: Option<f32>,
    /// Scattering coefficient of the interior (sigma_s, per unit length).
    scattering: Option<FileColor>,
    /// Henyey-Greenstein asymmetry of the interior's scattering.
    g: Option<f32>,
    /// Single-scattering albedo of the interior (the artist's form, with
    /// `mean_free_path`).
    albedo: Option<FileColor>,
    /// Mean free path inside (per channel, scene units).
    mean_free_path: Option<FileColor>,
    /// Subsurface scattering: the colour a large slab of the material
    /// shows (see the README's "Subsurface scattering"), with
    /// `subsurface_radius`.
    subsurface_color: Option<FileColor>,
    /// Subsurface scattering: the mean free path per channel.
    subsurface_radius: Option<FileColor>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum FileSellmeierCoefficients {
    Coefficients { b: [f64; 3], c: [f64; 3] },
}

#[derive(Deserialize, Clone)]
#[serde(untagged)]
enum FileSellmeier {
    Preset(String),
    Custom(FileSellmeierCoefficients),
}

#[derive(Deserialize)]
#[serde(untagged)]
enum MaterialRef {
    Named(String),
    Inline(Box<FileMaterial>),
}

#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum FileShape {
    Sphere {
        radius: f32,
    },
    Plane,
    Disk {
        radius: f32,
    },
    Polygon {
        vertices: Vec<[f32; 3]>,
    },
    Cylinder {
        radius: f32,
        y_min: f32,
        y_max: f32,
    },
    Cone {
        radius: f32,
        height: f32,
    },
    Ellipsoid {
        radii: [f32; 3],
    },
    Paraboloid {
        radius: f32,
        height: f32,
    },
    Hyperboloid {
        waist_radius: f32,
        top_radius: f32,
        half_height: f32,
    },
    Mesh {
        positions: Vec<[f32; 3]>,
        indices: Vec<[u32; 3]>,
        #[serde(default)]
        smooth: bool,
    },
    #[serde(rename = "torus_knot")]
    TorusKnot {
        #[serde(default = "knot_p")]
        p: u32,
        #[serde(default = "knot_q")]
        q: u32,
        radius: f32,
        tube: f32,
        segments: u32,
        sides: u32,
        #[serde(default = "yes")]
        smooth: bool,
    },
}

/// Largest `settings.max_depth` a scene file may ask for.
const MAX_DEPTH_SETTING: u32 = 1024;

/// Most vertices a `torus_knot` may have (about 8 million triangles).
const MAX_KNOT_VERTICES: u64 = 4_000_000;

fn knot_p() -> u32 {
    2
}
fn knot_q() -> u32 {
    3
}
fn yes() -> bool {
    true
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FilePlacement {
    translate: Option<[f64; 3]>,
    /// Degrees about X, then Y, then Z.
    rotate: Option<[f64; 3]>,
    scale: Option<FileColor>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileObject {
    name: Option<String>,
    shape: FileShape,
    material: Option<MaterialRef>,
    #[serde(flatten)]
    placement: FilePlacement,
}

#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum FileLight {
    Point {
        position: [f64; 3],
        #[serde(default = "white")]
        color: FileColor,
        intensity: f32,
    },
    Directional {
        direction: [f64; 3],
        #[serde(default = "white")]
        color: FileColor,
        illuminance: f32,
    },
    Spot {
        position: [f64; 3],
        direction: [f64; 3],
        #[serde(default = "white")]
        color: FileColor,
        intensity: f32,
        #[serde(default)]
        inner_angle: f32,
        #[serde(default = "default_outer")]
        outer_angle: f32,
    },
}

fn white() -> FileColor {
    FileColor::Grey(1.0)
}
fn default_outer() -> f32 {
    45.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileInclude {
    path: PathBuf,
    #[serde(flatten)]
    placement: FilePlacement,
}

/// Loads a TOML scene file (see the README for the schema).
pub fn load_scene_file(path: &Path, quality: impl Into<BuildOptions>) -> Result<SceneDesc> {
    let bytes = crate::io::read_regular_file(path)
        .map_err(|e| Error::load(path, format!("cannot read scene file: {e}")))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| Error::load(path, "cannot read scene file: it is not valid UTF-8"))?;
    parse_scene_file(&text, path, quality)
}

/// Parses the text of a TOML scene file. `path` names the file in messages
/// and its folder is where relative paths (textures, included glTF files)
/// are looked up; it is not read itself. This is the entry point of the
/// scene-format fuzz target (`fuzz/`).
///
/// Meshes (and included glTF files) are built with `quality`'s structure,
/// else the file's `[settings] accel`, else the BVH.
pub fn parse_scene_file(
    text: &str,
    path: &Path,
    quality: impl Into<BuildOptions>,
) -> Result<SceneDesc> {
    let file: FileScene =
        toml::from_str(text).map_err(|e| Error::load(path, format!("invalid scene file: {e}")))?;
    let mut quality = quality.into();
    quality.accel = Some(quality.accel.or(file.settings.accel).unwrap_or_default());
    let base = path.parent().unwrap_or(Path::new("."));
    let ctx = Ctx {
        path,
        base,
        quality,
    };
    ctx.build(file)
}

struct Ctx<'a> {
    path: &'a Path,
    base: &'a Path,
    quality: BuildOptions,
}

/// A finite point or vector of the file, in double precision (world
/// positions keep every digit the file gives).
fn finite3d(what: &str, v: [f64; 3]) -> std::result::Result<DVec3, String> {
    let v = DVec3::from(v);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what} must be finite, got {v}"))
    }
}

fn finite3(what: &str, v: [f32; 3]) -> std::result::Result<Vec3, String> {
    let v = Vec3::from(v);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what} must be finite, got {v}"))
    }
}

fn non_negative(what: &str, c: Color) -> std::result::Result<Color, String> {
    if c.is_finite() && c.min_element() >= 0.0 {
        Ok(c)
    } else {
        Err(format!("{what} must be finite and non-negative, got {c}"))
    }
}

/// The material's dispersion (`sellmeier` or `abbe`, not both) and its
/// index at the d line: `ior` if given, else the Sellmeier index at
/// 587.56 nm.
fn dispersion(m: &FileMaterial) -> std::result::Result<(Option<Dispersion>, Option<f32>), String> {
    match (&m.sellmeier, m.abbe) {
        (None, None) => Ok((None, m.ior)),
        (Some(_), Some(_)) => Err("give either sellmeier or abbe, not both".to_string()),
        (None, Some(v)) => {
            let n_d = m.ior.unwrap_or(Material::default().ior);
            Ok((Some(Dispersion::from_abbe(n_d, v)?), m.ior))
        }
        (Some(s), None) => {
            let s = match s {
                FileSellmeier::Preset(name) => Sellmeier::PRESETS
                    .iter()
                    .find(|(n, _)| n.eq_ignore_ascii_case(name))
                    .map(|(_, s)| *s)
                    .ok_or_else(|| {
                        let names: Vec<&str> = Sellmeier::PRESETS.iter().map(|p| p.0).collect();
                        format!(
                            "unknown Sellmeier glass '{name}' (known: {})",
                            names.join(", ")
                        )
                    })?,
                FileSellmeier::Custom(FileSellmeierCoefficients::Coefficients { b, c }) => {
                    Sellmeier { b: *b, c: *c }.check()?
                }
            };
            let n_d = s.ior_f64(LAMBDA_D) as f32;
            Ok((Some(Dispersion::Sellmeier(s)), Some(m.ior.unwrap_or(n_d))))
        }
    }
}

/// The interior's absorption coefficient: `absorption` (sigma_a) or
/// `attenuation_color` with `attenuation_distance`, not both.
fn absorption(m: &FileMaterial) -> std::result::Result<Color, String> {
    match (m.absorption, m.attenuation_color, m.attenuation_distance) {
        (None, None, None) => Ok(Color::ZERO),
        (Some(a), None, None) => optics::check_absorption(a.get()),
        (None, Some(c), Some(d)) => optics::absorption_from_attenuation(c.get(), d),
        (None, _, _) => Err(
            "attenuation_color and attenuation_distance must be given together".to_string(),
        ),
        (Some(_), _, _) => Err(
            "give either absorption (sigma_a) or attenuation_color with attenuation_distance, not both"
                .to_string(),
        ),
    }
}

/// A medium from its physical parameters (`absorption`, `scattering`,
/// `g`) or its artist's parameters (`albedo` with `mean_free_path`, and
/// `g`); `absorbing` is the absorption already read (a material may give
/// it as an attenuation colour).
fn medium_parameters(
    absorbing: Option<Color>,
    scattering: Option<FileColor>,
    g: Option<f32>,
    albedo: Option<FileColor>,
    mean_free_path: Option<FileColor>,
) -> std::result::Result<Medium, String> {
    let g = g.unwrap_or(0.0);
    match (albedo, mean_free_path) {
        (None, None) => {
            let sigma_a = absorbing.unwrap_or(Color::ZERO);
            let sigma_s = scattering.map_or(Color::ZERO, |s| s.get());
            // An infinite absorption (a black interior) is allowed; the
            // scattering coefficient and g are checked like a medium's.
            Medium::checked(Color::ZERO, sigma_s, g)?;
            Ok(Medium {
                sigma_a,
                sigma_s,
                g,
            })
        }
        (Some(a), Some(l)) => {
            if absorbing.is_some_and(|a| a != Color::ZERO) || scattering.is_some() {
                return Err(
                    "give either absorption/scattering or albedo with mean_free_path, not both"
                        .into(),
                );
            }
            Medium::from_albedo(a.get(), l.get(), g)
        }
        _ => Err("albedo and mean_free_path must be given together".into()),
    }
}

fn unit_interval(what: &str, v: f32) -> std::result::Result<f32, String> {
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{what} must be in [0, 1], got {v}"))
    }
}

impl Ctx<'_> {
    fn err(&self, msg: impl Into<String>) -> Error {
        Error::load(self.path, msg.into())
    }

    fn build(&self, file: FileScene) -> Result<SceneDesc> {
        let mut scene = SceneDesc {
            settings: self.settings(&file.settings)?,
            ..Default::default()
        };
        if let Some(l) = &file.lightfield {
            let l = crate::core::settings::LightFieldSettings {
                grid: l.grid,
                spacing: l.spacing,
                resolution: l.resolution,
                focal_distance: l.focal_distance,
            };
            l.validate()
                .map_err(|m| self.err(format!("lightfield: {m}")))?;
            scene.settings.lightfield = Some(l);
        }
        if let Some(bg) = file.settings.background {
            scene.background =
                non_negative("settings.background", Color::from(bg)).map_err(|m| self.err(m))?;
        }
        if let Some(env) = &file.environment {
            scene.environment = Some(self.environment(env)?);
        }
        if let Some(m) = &file.medium {
            let sigma_a = m
                .absorption
                .map(|a| optics::check_absorption(a.get()))
                .transpose()
                .map_err(|e| self.err(format!("medium: {e}")))?;
            let fog = medium_parameters(sigma_a, m.scattering, m.g, m.albedo, m.mean_free_path)
                .and_then(|f| Medium::checked(f.sigma_a, f.sigma_s, f.g))
                .map_err(|e| self.err(format!("medium: {e}")))?;
            scene.fog = (!fog.is_clear()).then_some(fog);
        }
        if let Some(c) = &file.camera {
            scene.cameras.push(self.camera(c).map_err(|m| self.err(m))?);
        }
        let mut materials = BTreeMap::new();
        for (name, m) in &file.materials {
            let mat = self
                .material(m)
                .map_err(|msg| self.err(format!("materials.{name}: {msg}")))?;
            materials.insert(name.clone(), mat);
        }
        for (i, o) in file.objects.iter().enumerate() {
            let label = match &o.name {
                Some(n) => format!("objects[{i}] ({n})"),
                None => format!("objects[{i}]"),
            };
            let obj = self
                .object(o, &materials)
                .map_err(|msg| self.err(format!("{label}: {msg}")))?;
            scene.objects.push(obj);
        }
        for (i, l) in file.lights.iter().enumerate() {
            let light = self
                .light(l)
                .map_err(|msg| self.err(format!("lights[{i}]: {msg}")))?;
            scene.lights.push(light);
        }
        for (i, inc) in file.gltf.iter().enumerate() {
            let place = self
                .placement(&inc.placement)
                .map_err(|msg| self.err(format!("gltf[{i}]: {msg}")))?;
            let mut sub = crate::io::gltf::load_gltf(&self.base.join(&inc.path), self.quality)
                .map_err(|e| self.err(format!("gltf[{i}]: {e}")))?;
            for o in &mut sub.objects {
                o.transform = Transform(place.0 * o.transform.0);
            }
            for l in &mut sub.lights {
                l.transform = Transform(place.0 * l.transform.0);
            }
            for c in &mut sub.cameras {
                c.look_from = place.0.transform_point3(c.look_from);
                c.look_at = place.0.transform_point3(c.look_at);
                c.up = place.0.transform_vector3(c.up.as_dvec3()).as_vec3();
            }
            scene.append(sub);
        }
        Ok(scene)
    }

    fn settings(&self, s: &FileSettings) -> Result<SettingsDesc> {
        if let Some(m) = s.min_contribution
            && !(m >= 0.0 && m.is_finite())
        {
            return Err(self.err(format!(
                "settings.min_contribution must be finite and non-negative, got {m}"
            )));
        }
        if let Some(w) = s.rr_weight
            && !(w > 0.0 && w <= 1.0)
        {
            return Err(self.err(format!("settings.rr_weight must be in (0, 1], got {w}")));
        }
        if let Some(k) = s.split
            && !(1..=crate::core::settings::MAX_SPLIT).contains(&k)
        {
            return Err(self.err(format!(
                "settings.split must be between 1 and {}, got {k}",
                crate::core::settings::MAX_SPLIT
            )));
        }
        if let Some(d) = s.max_depth {
            // The recursive integrator recurses once per bounce: between two
            // facing perfect mirrors a depth of 20000 overflowed its stack
            // (an abort, not an error).
            if d > MAX_DEPTH_SETTING {
                return Err(self.err(format!(
                    "settings.max_depth must be at most {MAX_DEPTH_SETTING}, got {d}"
                )));
            }
        }
        if let Some(e) = s.exposure
            && !e.is_finite()
        {
            return Err(self.err(format!("settings.exposure must be finite, got {e}")));
        }
        let gooch = s.gooch.map(|g| {
            let d = crate::core::settings::GoochParams::default();
            crate::core::settings::GoochParams {
                b: g.b.unwrap_or(d.b),
                y: g.y.unwrap_or(d.y),
                alpha: g.alpha.unwrap_or(d.alpha),
                beta: g.beta.unwrap_or(d.beta),
            }
        });
        if let Some(g) = &gooch {
            g.validate()
                .map_err(|e| self.err(format!("settings.gooch: {e}")))?;
        }
        let lines = s.lines.map(|l| {
            let d = crate::core::settings::LineSettings::default();
            crate::core::settings::LineSettings {
                width: l.width.unwrap_or(d.width),
                color: l.color.unwrap_or(d.color),
                crease_degrees: l.crease_angle.unwrap_or(d.crease_degrees),
            }
        });
        if let Some(l) = &lines {
            l.validate()
                .map_err(|e| self.err(format!("settings.lines: {e}")))?;
        }
        let photon = s.photon.unwrap_or_default();
        let photon = crate::core::photon_settings::PhotonOverrides {
            photons: photon.photons,
            radius: photon.radius,
            alpha: photon.alpha,
            iterations: photon.iterations,
            gather_rays: photon.gather_rays,
        };
        photon
            .resolve()
            .validate()
            .map_err(|e| self.err(format!("settings.photon: {e}")))?;
        Ok(SettingsDesc {
            photon,
            caustics: s.caustics,
            width: s.width,
            height: s.height,
            spp: s.spp,
            max_depth: s.max_depth,
            min_contribution: s.min_contribution,
            seed: s.seed,
            exposure: s.exposure,
            transport: s.transport.map(|t| match t {
                FileTransport::Whitted => crate::core::settings::Transport::Whitted,
                FileTransport::Path => crate::core::settings::Transport::Path,
                FileTransport::Radiosity => crate::core::settings::Transport::Radiosity,
                FileTransport::Photon => crate::core::settings::Transport::Photon,
            }),
            light_samples: s.light_samples,
            rr_start_depth: s.russian_roulette.map(|r| match r {
                FileRoulette::Enabled(true) => Some(crate::core::settings::DEFAULT_RR_START_DEPTH),
                FileRoulette::Enabled(false) => None,
                FileRoulette::StartDepth(d) => Some(d),
            }),
            rr_weight: s.rr_weight,
            split: s.split,
            accel: s.accel,
            style: s.style.map(|t| match t {
                FileStyle::Shaded => crate::core::settings::Style::Shaded,
                FileStyle::Gooch => crate::core::settings::Style::Gooch,
            }),
            gooch,
            lines,
            sampler: s.sampler.map(|k| match k {
                FileSampler::Sobol => crate::core::rng::SamplerKind::Sobol,
                FileSampler::Hash => crate::core::rng::SamplerKind::Hash,
            }),
            radiosity: s.radiosity.unwrap_or_default(),
            panorama: s.camera_projection.map(|p| match p {
                FileProjection::Perspective => None,
                FileProjection::Equirect => Some(crate::core::settings::Panorama::Equirect),
                FileProjection::Cubemap => Some(crate::core::settings::Panorama::Cubemap),
            }),
            lightfield: None,
        })
    }

    fn camera(&self, c: &FileCamera) -> std::result::Result<Camera, String> {
        let cam = Camera {
            look_from: finite3d("camera.look_from", c.look_from)?,
            look_at: finite3d("camera.look_at", c.look_at)?,
            up: finite3("camera.up", c.up)?,
            vfov_degrees: c.vfov,
            shift: glam::Vec2::from(c.shift),
            name: None,
            focus_distance: c.focus_distance.unwrap_or(0.0),
            ..Default::default()
        };
        let mut cam = cam;
        match (c.aperture_radius, c.f_number) {
            (Some(_), Some(_)) => {
                return Err("camera: give aperture_radius or f_number, not both".into());
            }
            (Some(r), None) => cam.lens_radius = r,
            (None, Some(n)) => {
                if !(n.is_finite() && n > 0.0) {
                    return Err(format!("camera.f_number must be positive, got {n}"));
                }
                cam.set_f_number(n);
            }
            (None, None) => {}
        }
        if let Some(h) = c.ortho_half_height {
            cam.projection = crate::scene::camera::Projection::Orthographic { half_height: h };
        }
        cam.validate()?;
        Ok(cam)
    }

    fn texture(&self, t: &FileTexture) -> std::result::Result<Texture, String> {
        match t {
            FileTexture::Checker { scale, even, odd } => {
                if !(scale.is_finite() && *scale > 0.0) {
                    return Err(format!("checker scale must be positive, got {scale}"));
                }
                Ok(Texture::Checker {
                    scale: *scale,
                    even: non_negative("checker even colour", even.get())?,
                    odd: non_negative("checker odd colour", odd.get())?,
                })
            }
            FileTexture::Image { path } => {
                let full = self.base.join(path);
                let bytes = crate::io::read_regular_file(&full)
                    .map_err(|e| format!("cannot read texture {}: {e}", full.display()))?;
                let img = image::ImageReader::new(std::io::Cursor::new(bytes))
                    .with_guessed_format()
                    .map_err(|e| format!("cannot read texture {}: {e}", full.display()))?
                    .decode()
                    .map_err(|e| format!("cannot read texture {}: {e}", full.display()))?
                    .to_rgb32f();
                let (width, height) = img.dimensions();
                let texels = img
                    .pixels()
                    .map(|p| Color::new(p[0], p[1], p[2]).map(srgb_to_linear))
                    .collect();
                Ok(Texture::Image {
                    image: Arc::new(ImageTexture::new(width, height, texels)),
                    transform: UvTransform::default(),
                    sampler: Default::default(),
                })
            }
        }
    }

    fn environment(&self, e: &FileEnvironment) -> Result<Environment> {
        if !(e.intensity.is_finite() && e.intensity >= 0.0) {
            return Err(self.err(format!(
                "environment.intensity must be finite and non-negative, got {}",
                e.intensity
            )));
        }
        if !e.rotation.is_finite() {
            return Err(self.err(format!(
                "environment.rotation must be finite, got {}",
                e.rotation
            )));
        }
        let source = match (&e.path, e.color) {
            (Some(path), None) => EnvironmentSource::Map(
                crate::io::environment::load_environment_map(&self.base.join(path))?,
            ),
            (None, Some(c)) => EnvironmentSource::Uniform(
                non_negative("environment.color", c.get()).map_err(|m| self.err(m))?,
            ),
            _ => {
                return Err(self.err(
                    "[environment] needs exactly one of `path` (an .hdr or .exr map) and `color`",
                ));
            }
        };
        Ok(Environment::new(
            source,
            e.intensity,
            e.rotation.to_radians(),
        ))
    }

    fn material(&self, m: &FileMaterial) -> std::result::Result<Material, String> {
        let d = Material::default();
        let color = |c: Option<FileColor>, default: Color, what: &str| match c {
            Some(c) => non_negative(what, c.get()),
            None => Ok(default),
        };
        let shininess = m.shininess.unwrap_or(d.shininess);
        if !(shininess.is_finite() && shininess >= 1.0) {
            return Err(format!("shininess must be at least 1, got {shininess}"));
        }
        let (dispersion, ior) = dispersion(m)?;
        let ior = ior.unwrap_or(d.ior);
        let sigma_a = absorption(m)?;
        let (interior, subsurface) = match (m.subsurface_color, m.subsurface_radius) {
            (None, None) => (
                medium_parameters(Some(sigma_a), m.scattering, m.g, m.albedo, m.mean_free_path)?,
                false,
            ),
            (Some(c), Some(r)) => {
                if sigma_a != Color::ZERO
                    || m.scattering.is_some()
                    || m.albedo.is_some()
                    || m.mean_free_path.is_some()
                    || m.g.is_some()
                {
                    return Err("subsurface_color and subsurface_radius define the interior: give no absorption, attenuation, scattering, g, albedo or mean_free_path with them".into());
                }
                (Medium::subsurface(c.get(), r.get())?, true)
            }
            _ => {
                return Err("subsurface_color and subsurface_radius must be given together".into());
            }
        };
        // A subsurface material's surface is a diffuse-transmission
        // boundary under path transport (`transport::volume::diffuse_crossing`)
        // and an index-matched one under Whitted transport: it refracts
        // nothing, so an index of refraction would mean nothing.
        if subsurface && (m.ior.is_some() || dispersion.is_some()) {
            return Err("a subsurface material has a diffuse boundary that does not refract: give no ior or dispersion with subsurface_color".into());
        }
        if subsurface
            && (m.color.is_some()
                || m.texture.is_some()
                || m.diffuse.is_some()
                || m.specular.is_some()
                || m.mirror.is_some()
                || m.transmission.is_some())
        {
            return Err("a subsurface material's surface is its diffuse boundary: give no color, texture, diffuse, specular, mirror or transmission with subsurface_color".into());
        }
        let d = if subsurface {
            Material {
                base_color: Color::ONE,
                diffuse: 0.0,
                transmission: 1.0,
                ior: 1.0,
                subsurface: true,
                ..d
            }
        } else {
            d
        };
        let ior = if subsurface { 1.0 } else { ior };
        if !(ior.is_finite() && ior > 0.0) {
            return Err(format!("ior must be a positive finite number, got {ior}"));
        }
        Ok(Material {
            base_color: color(m.color, d.base_color, "color")?,
            base_color_texture: m.texture.as_ref().map(|t| self.texture(t)).transpose()?,
            diffuse: unit_interval("diffuse", m.diffuse.unwrap_or(d.diffuse))?,
            specular: color(m.specular, d.specular, "specular")?,
            shininess,
            mirror: color(m.mirror, d.mirror, "mirror")?,
            transmission: unit_interval("transmission", m.transmission.unwrap_or(d.transmission))?,
            ior,
            emission: color(m.emission, d.emission, "emission")?,
            absorption: interior.sigma_a,
            scattering: interior.sigma_s,
            phase_g: interior.g,
            dispersion,
            ..d
        })
    }

    fn placement(&self, p: &FilePlacement) -> std::result::Result<Transform, String> {
        let t = finite3d("translate", p.translate.unwrap_or([0.0; 3]))?;
        let r = finite3d("rotate", p.rotate.unwrap_or([0.0; 3]))?;
        let s = match p.scale {
            Some(s) => s.get(),
            None => Vec3::ONE,
        };
        if !s.is_finite() || s.min_element().abs() == 0.0 || s.abs().min_element() < 1e-30 {
            return Err(format!("scale must be finite and non-zero, got {s}"));
        }
        let q = DQuat::from_rotation_z(r.z.to_radians())
            * DQuat::from_rotation_y(r.y.to_radians())
            * DQuat::from_rotation_x(r.x.to_radians());
        let xf = Transform::from_trs(t, q, s.as_dvec3());
        if !xf.is_valid() {
            return Err("transform is not invertible".into());
        }
        Ok(xf)
    }

    fn object(
        &self,
        o: &FileObject,
        materials: &BTreeMap<String, Material>,
    ) -> std::result::Result<ObjectDesc, String> {
        let material = match &o.material {
            None => Material::default(),
            Some(MaterialRef::Named(n)) => materials
                .get(n)
                .cloned()
                .ok_or_else(|| format!("unknown material '{n}'"))?,
            Some(MaterialRef::Inline(m)) => self.material(m)?,
        };
        let shape = match &o.shape {
            FileShape::Sphere { radius } => Shape::Sphere { radius: *radius },
            FileShape::Plane => Shape::Plane,
            FileShape::Disk { radius } => Shape::Disk { radius: *radius },
            FileShape::Polygon { vertices } => Shape::Polygon {
                vertices: vertices.iter().map(|v| Vec3::from(*v)).collect(),
            },
            FileShape::Cylinder {
                radius,
                y_min,
                y_max,
            } => Shape::Cylinder {
                radius: *radius,
                y_min: *y_min,
                y_max: *y_max,
            },
            FileShape::Cone { radius, height } => Shape::Cone {
                radius: *radius,
                height: *height,
            },
            FileShape::Ellipsoid { radii } => Shape::Ellipsoid {
                radii: Vec3::from(*radii),
            },
            FileShape::Paraboloid { radius, height } => Shape::Paraboloid {
                radius: *radius,
                height: *height,
            },
            FileShape::Hyperboloid {
                waist_radius,
                top_radius,
                half_height,
            } => Shape::Hyperboloid {
                waist_radius: *waist_radius,
                top_radius: *top_radius,
                half_height: *half_height,
            },
            FileShape::Mesh { .. } | FileShape::TorusKnot { .. } => {
                let (data, smooth) = match &o.shape {
                    FileShape::Mesh {
                        positions,
                        indices,
                        smooth,
                    } => (
                        MeshData {
                            positions: positions.iter().map(|p| Vec3::from(*p)).collect(),
                            indices: indices.clone(),
                            ..Default::default()
                        },
                        smooth,
                    ),
                    FileShape::TorusKnot {
                        p,
                        q,
                        radius,
                        tube,
                        segments,
                        sides,
                        smooth,
                    } => {
                        if !(radius.is_finite() && *radius > 0.0 && tube.is_finite() && *tube > 0.0)
                        {
                            return Err("torus_knot radius and tube must be positive".into());
                        }
                        if !(3..=100_000).contains(segments) || !(3..=1000).contains(sides) {
                            return Err(format!(
                                "torus_knot needs 3..=100000 segments and 3..=1000 sides, got {segments} and {sides}"
                            ));
                        }
                        // Each side allows its maximum, but not both: 1e8
                        // vertices and 2e8 triangles would need tens of GB
                        // and minutes of BVH build for a few bytes of input.
                        if *segments as u64 * *sides as u64 > MAX_KNOT_VERTICES {
                            return Err(format!(
                                "torus_knot with {segments} segments x {sides} sides has more than {MAX_KNOT_VERTICES} vertices"
                            ));
                        }
                        (
                            crate::geometry::procedural::torus_knot(
                                *p, *q, *radius, *tube, *segments, *sides,
                            ),
                            smooth,
                        )
                    }
                    _ => unreachable!("matched above"),
                };
                let mode = if *smooth {
                    NormalMode::Smooth
                } else {
                    NormalMode::Flat
                };
                if material.has_scattering_interior() && !crate::geometry::mesh::is_closed(&data) {
                    return Err(
                        "holds a scattering medium but its mesh is not closed (every edge must join exactly two triangles)"
                            .into(),
                    );
                }
                let name = o.name.clone().unwrap_or_else(|| "mesh".into());
                let mesh = Mesh::with_accel(
                    name,
                    data,
                    mode,
                    self.quality.quality,
                    self.quality.accel.unwrap_or_default(),
                )?;
                return Ok(ObjectDesc {
                    name: o.name.clone(),
                    transform: self.placement(&o.placement)?,
                    geometry: Geometry::Mesh(Arc::new(mesh)),
                    material,
                });
            }
        };
        shape.validate()?;
        if material.has_scattering_interior()
            && !matches!(shape, Shape::Sphere { .. } | Shape::Ellipsoid { .. })
        {
            return Err(format!(
                "holds a scattering medium but a {} is not closed (only spheres, ellipsoids and closed meshes can hold one)",
                shape.kind_name()
            ));
        }
        Ok(ObjectDesc {
            name: o.name.clone(),
            transform: self.placement(&o.placement)?,
            geometry: Geometry::Shape(shape),
            material,
        })
    }

    fn light(&self, l: &FileLight) -> std::result::Result<LightDesc, String> {
        let intensity = |c: FileColor, i: f32, what: &str| {
            if !(i.is_finite() && i >= 0.0) {
                return Err(format!("{what} must be finite and non-negative, got {i}"));
            }
            non_negative("color", c.get()).map(|c| c * i)
        };
        let aim = |pos: DVec3, dir: [f64; 3]| -> std::result::Result<Transform, String> {
            let d = finite3d("direction", dir)?;
            if d.length_squared() == 0.0 {
                return Err("direction must not be zero".into());
            }
            let d = d.normalize();
            // Local -Z onto d.
            let q = DQuat::from_rotation_arc(DVec3::NEG_Z, d);
            Ok(Transform::from_trs(pos, q, DVec3::ONE))
        };
        let (transform, light) = match l {
            FileLight::Point {
                position,
                color,
                intensity: i,
            } => (
                Transform::from_translation(finite3d("position", *position)?),
                Light::Point {
                    intensity: intensity(*color, *i, "intensity")?,
                },
            ),
            FileLight::Directional {
                direction,
                color,
                illuminance,
            } => (
                aim(DVec3::ZERO, *direction)?,
                Light::Directional {
                    illuminance: intensity(*color, *illuminance, "illuminance")?,
                },
            ),
            FileLight::Spot {
                position,
                direction,
                color,
                intensity: i,
                inner_angle,
                outer_angle,
            } => {
                if !(inner_angle.is_finite()
                    && outer_angle.is_finite()
                    && *inner_angle >= 0.0
                    && inner_angle <= outer_angle
                    && *outer_angle <= 90.0)
                {
                    return Err(format!(
                        "spot angles need 0 <= inner_angle <= outer_angle <= 90 degrees, got {inner_angle} and {outer_angle}"
                    ));
                }
                (
                    aim(finite3d("position", *position)?, *direction)?,
                    Light::Spot {
                        intensity: intensity(*color, *i, "intensity")?,
                        inner_angle: inner_angle.to_radians(),
                        outer_angle: outer_angle.to_radians(),
                    },
                )
            }
        };
        Ok(LightDesc {
            name: None,
            transform,
            light,
        })
    }
}
