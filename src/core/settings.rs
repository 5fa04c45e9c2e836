//! Render settings shared by every integrator and every transport, with
//! the limits that keep memory and recursion bounded.

use crate::core::window::{PathMap, RenderWindow};

/// Settings shared by every integrator.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels, at least 1.
    pub width: u32,
    /// Image height in pixels, at least 1.
    pub height: u32,
    /// Samples per pixel, at least 1. One sample goes through the pixel
    /// centre; more are jittered uniformly over the pixel (box filter).
    pub spp: u32,
    /// Maximum number of bounces after the camera ray: specular ones under
    /// Whitted transport; any under path transport, where the last vertex
    /// still gathers direct light but scatters no further.
    pub max_depth: u32,
    /// Secondary rays whose throughput (largest channel) falls below this
    /// are not traced.
    pub min_contribution: f32,
    /// Seed of the sample keys.
    pub seed: u64,
    /// Light transport: Whitted (point lights, specular bounces) or path
    /// tracing (area lights, diffuse interreflection).
    pub transport: Transport,
    /// Shadow rays per area light at each path-traced hit (next-event
    /// estimation); more gives smoother soft shadows per sample.
    pub light_samples: u32,
    /// Path tracing: bounce from which Russian roulette may end paths
    /// (`None`: never; paths run to `max_depth`).
    pub rr_start_depth: Option<u32>,
    /// Path tracing: Russian roulette's weight. A path whose throughput
    /// (largest channel) is at least this is never ended by roulette; a
    /// lighter one goes on with probability `throughput / rr_weight` and
    /// is then weighed up to `rr_weight` (1: the classic rule, survival
    /// probability equal to the throughput). See [`DEFAULT_RR_WEIGHT`].
    pub rr_weight: f32,
    /// Path tracing: paths continued from the first surface a camera ray
    /// hits, each weighted `1 / split`, after that hit's one next-event
    /// estimate (1: no splitting). See [`MAX_SPLIT`].
    pub split: u32,
    /// The part of the image and of each pixel's samples to render
    /// (`None`: the whole image, all `spp` samples). A windowed render
    /// produces only the window's pixels, each the exact sum of the
    /// window's samples, which are the same samples the whole render takes
    /// (see [`crate::core::window`]).
    pub window: Option<RenderWindow>,
    /// How surfaces lit by lights are shaded: physically, or with Gooch's
    /// cool-to-warm tones for illustration.
    pub style: Style,
    /// Parameters of [`Style::Gooch`] (unused otherwise).
    pub gooch: GoochParams,
    /// Feature lines (silhouettes, creases, borders, material boundaries)
    /// drawn over the image; `None` draws none and runs no line stage.
    pub lines: Option<LineSettings>,
    /// Where the random numbers come from: Owen-scrambled Sobol points
    /// (stratified per pixel) or independent hashed numbers.
    pub sampler: crate::core::rng::SamplerKind,
    /// Radiosity's options (used by [`Transport::Radiosity`] only).
    pub radiosity: crate::core::radiosity::RadiositySettings,
    /// Photon mapping's parameters (used by [`Transport::Photon`] only).
    pub photon: crate::core::photon_settings::PhotonSettings,
    /// A panoramic camera instead of the perspective one (`None`): every
    /// direction around the eye, see [`Panorama`].
    pub panorama: Option<Panorama>,
    /// Path transport: light tracing of the caustics seen directly
    /// (`E D S+ L`), which it takes over from path tracing; see
    /// [`crate::transport::caustic`]. The recursive integrator only, on a
    /// pinhole perspective camera, without a render window.
    pub caustics: bool,
}

/// A panoramic camera projection: the image holds every direction around
/// the camera's eye, in the camera's frame (the forward direction is the
/// environment map's `+X`, the camera's up its `+Y`, its right `+Z`), so
/// that a panorama read back as an environment (turned to the camera's
/// heading) lights a scene as the rendered one looked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Panorama {
    /// Latitude-longitude (360 x 180 degrees), the environment map's layout:
    /// column `x` is `u = x / width`, row `y` is `v = y / height`.
    Equirect,
    /// Six square 90-degree faces side by side, `width = 6 height`, in
    /// the order `+X, -X, +Y, -Y, +Z, -Z` of the map frame (front, back,
    /// up, down, right, left); each face is the perspective view from the
    /// eye with `+Y` up (`-X` up for the `+Y` face, `+X` for `-Y`).
    Cubemap,
}

impl Panorama {
    /// Lower-case name, as on the command line and in scene files.
    pub fn name(self) -> &'static str {
        match self {
            Panorama::Equirect => "equirect",
            Panorama::Cubemap => "cubemap",
        }
    }
}

/// A two-plane light field's capture rig as a scene file or the command
/// line asks for it (`[lightfield]`); every field is optional and falls
/// back to [`LightFieldSettings::DEFAULT_GRID`] and friends. See
/// `crate::lightfield` for the parametrisation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LightFieldSettings {
    /// Cameras across (along the camera's right) and up.
    pub grid: Option<[u32; 2]>,
    /// Distance between neighbouring cameras, world units.
    pub spacing: Option<f64>,
    /// Width and height of every captured image, pixels.
    pub resolution: Option<[u32; 2]>,
    /// Distance from the camera plane to the focal plane, world units.
    pub focal_distance: Option<f64>,
}

impl LightFieldSettings {
    /// Cameras across and up when neither the scene nor the command line
    /// says.
    pub const DEFAULT_GRID: [u32; 2] = [8, 8];
    /// Image size when neither says.
    pub const DEFAULT_RESOLUTION: [u32; 2] = [128, 128];
    /// Largest number of cameras along one side of the grid.
    pub const MAX_GRID_SIDE: u32 = 256;

    /// These values, falling back to `under`'s field by field.
    pub fn or(self, under: LightFieldSettings) -> Self {
        Self {
            grid: self.grid.or(under.grid),
            spacing: self.spacing.or(under.spacing),
            resolution: self.resolution.or(under.resolution),
            focal_distance: self.focal_distance.or(under.focal_distance),
        }
    }

    /// Checks the values given; the error names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if let Some([n, m]) = self.grid
            && !((1..=Self::MAX_GRID_SIDE).contains(&n) && (1..=Self::MAX_GRID_SIDE).contains(&m))
        {
            return Err(format!(
                "the light-field grid must have 1 to {} cameras a side, got {n}x{m}",
                Self::MAX_GRID_SIDE
            ));
        }
        if let Some(s) = self.spacing
            && !(s.is_finite() && s > 0.0)
        {
            return Err(format!(
                "the light-field camera spacing must be finite and positive, got {s}"
            ));
        }
        if let Some([w, h]) = self.resolution
            && !((1..=MAX_IMAGE_SIDE).contains(&w) && (1..=MAX_IMAGE_SIDE).contains(&h))
        {
            return Err(format!(
                "the light-field image size must be 1 to {MAX_IMAGE_SIDE} pixels a side, got {w}x{h}"
            ));
        }
        if let Some(d) = self.focal_distance
            && !(d.is_finite() && d > 0.0)
        {
            return Err(format!(
                "the light-field focal distance must be finite and positive, got {d}"
            ));
        }
        Ok(())
    }
}

/// How surfaces with a diffuse or glossy lobe are shaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Style {
    /// The transport's physically based local lighting.
    #[default]
    Shaded,
    /// Gooch, Gooch, Shirley and Cohen (1998): cool-to-warm tones from the
    /// key light, white highlights, no shadows; mirrors and glass still
    /// reflect and refract (Whitted transport only).
    Gooch,
}

impl Style {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Style::Shaded => "shaded",
            Style::Gooch => "gooch",
        }
    }
}

/// Gooch shading's parameters: `k_cool = (0, 0, b) + alpha k_d`,
/// `k_warm = (y, y, 0) + beta k_d`, and the colour
/// `t k_warm + (1 - t) k_cool` with `t = (1 + n.l) / 2`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GoochParams {
    /// Blue of the cool tone (default 0.4).
    pub b: f32,
    /// Yellow of the warm tone (default 0.4).
    pub y: f32,
    /// Share of the base colour in the cool tone (default 0.2).
    pub alpha: f32,
    /// Share of the base colour in the warm tone (default 0.6).
    pub beta: f32,
}

impl Default for GoochParams {
    fn default() -> Self {
        Self {
            b: 0.4,
            y: 0.4,
            alpha: 0.2,
            beta: 0.6,
        }
    }
}

/// Blender Freestyle's default crease angle, in degrees: edges whose
/// faces' normals deviate by more than this are creases.
pub const DEFAULT_CREASE_DEGREES: f32 = 45.57;

/// Largest line width accepted, in pixels: the stencil grows with the
/// square of the width.
pub const MAX_LINE_WIDTH: f32 = 16.0;

/// Feature lines found by ray casting: what is drawn and how.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineSettings {
    /// Line width in pixels, in `(0, 16]` (default 1).
    pub width: f32,
    /// Line colour, in display (sRGB-encoded) values in `[0, 1]` for PNG
    /// output, linear for EXR (default black).
    pub color: [f32; 3],
    /// Crease threshold in degrees, in `[0, 180]`: a normal deviation of
    /// more than this between neighbouring samples of one object is a
    /// crease (default [`DEFAULT_CREASE_DEGREES`]; 180 turns creases off).
    pub crease_degrees: f32,
}

impl Default for LineSettings {
    fn default() -> Self {
        Self {
            width: 1.0,
            color: [0.0; 3],
            crease_degrees: DEFAULT_CREASE_DEGREES,
        }
    }
}

impl LineSettings {
    /// Rejects unusable line settings with a message naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.width > 0.0 && self.width <= MAX_LINE_WIDTH) {
            return Err(format!(
                "line width must be more than 0 and at most {MAX_LINE_WIDTH} pixels, got {}",
                self.width
            ));
        }
        if !(self.crease_degrees >= 0.0 && self.crease_degrees <= 180.0) {
            return Err(format!(
                "crease angle must be between 0 and 180 degrees, got {}",
                self.crease_degrees
            ));
        }
        if !self
            .color
            .iter()
            .all(|c| c.is_finite() && (0.0..=1.0).contains(c))
        {
            return Err(format!(
                "line colour channels must be in [0, 1], got {:?}",
                self.color
            ));
        }
        Ok(())
    }
}

impl GoochParams {
    /// Rejects non-finite or negative parameters.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("b", self.b),
            ("y", self.y),
            ("alpha", self.alpha),
            ("beta", self.beta),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "Gooch parameter {name} must be finite and non-negative, got {v}"
                ));
            }
        }
        Ok(())
    }
}

/// How light is transported: the model, orthogonal to the integrator that
/// executes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    /// Whitted: direct light from punctual lights, perfect mirror
    /// reflection and refraction; emissive surfaces glow but light nothing.
    #[default]
    Whitted,
    /// Unidirectional path tracing with next-event estimation and
    /// multiple importance sampling: emissive surfaces are area lights,
    /// diffuse surfaces scatter light onwards.
    Path,
    /// Radiosity: diffuse interreflection between patches, solved once
    /// per scene and looked up by view rays (see [`crate::radiosity`]).
    Radiosity,
    /// Progressive photon mapping: photons traced from the lights into a
    /// caustic and a global map each iteration, read by the camera side
    /// at diffuse and glossy surfaces (see [`crate::transport::photon`]).
    Photon,
}

impl Transport {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Transport::Whitted => "whitted",
            Transport::Path => "path",
            Transport::Radiosity => "radiosity",
            Transport::Photon => "photon",
        }
    }
}

/// The acceleration structure over each mesh's triangles. All four give
/// the same hits (the same watertight triangle test, the same closest-`t`
/// rule, equal `t` going to the lower input triangle index); they differ
/// in build time, memory and speed.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Accel {
    /// Prism's 8-wide BVH (built by obvhs), the default.
    #[default]
    Bvh,
    /// A kd-tree: SAH over exactly clipped triangle bounds.
    Kdtree,
    /// A uniform grid walked by a 3D DDA.
    Grid,
    /// No structure: every triangle is tested (the reference).
    Brute,
}

impl Accel {
    /// Every structure, the default first.
    pub const ALL: [Accel; 4] = [Accel::Bvh, Accel::Kdtree, Accel::Grid, Accel::Brute];

    /// Lower-case name, as on the command line and in scene files.
    pub fn name(self) -> &'static str {
        match self {
            Accel::Bvh => "bvh",
            Accel::Kdtree => "kdtree",
            Accel::Grid => "grid",
            Accel::Brute => "brute",
        }
    }
}

/// Default bounce from which Russian roulette may end a path: the first
/// bounces carry most of the image and are always traced. 5, as Mitsuba
/// 3's `rr_depth`: path tracing `assets/gltf/cornell.gltf` at 320x240, 64
/// spp and 16 bounces, it traces 25% more rays than 3 did for 31% less
/// relMSE and 16% less mean relative error against a 4096-spp reference,
/// 1.15x and 1.14x the efficiency (1 / (error measure x rays), the mean
/// relative error squared); on `assets/gltf/spheres.gltf` 6% more rays,
/// 1.10x and 1.05x.
pub const DEFAULT_RR_START_DEPTH: u32 = 5;

/// Default weight of Russian roulette ([`RenderSettings::rr_weight`]):
/// paths whose throughput is a quarter or more are never ended. The
/// classic rule (weight 1, as Mitsuba 3's) ends about 83% of the paths of
/// the Cornell box at bounce 5 (throughput about 0.7^5), and the
/// survivors' weight of 6 costs more variance than their bounces cost
/// time. `assets/gltf/cornell.gltf` at 320x240, 256 spp, 16 bounces,
/// against a 16384-spp reference, 3 alternating runs: weight 1 gave mean
/// relative error 0.0165 in 8.67 s, weight 0.25 0.0148 in 9.63 s, 0.90x
/// the time at equal error (weights 0.5 to 0.17 all within 3% of that);
/// on `assets/gltf/spheres.gltf` 0.94x to 0.97x (examples/measure/LOG.md,
/// "Russian roulette's weight").
pub const DEFAULT_RR_WEIGHT: f32 = 0.25;

/// Largest number of light samples per area light accepted.
pub const MAX_LIGHT_SAMPLES: u32 = 1024;

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            spp: 1,
            max_depth: 8,
            min_contribution: 1e-3,
            seed: 0,
            transport: Transport::Whitted,
            light_samples: 1,
            rr_start_depth: Some(DEFAULT_RR_START_DEPTH),
            rr_weight: DEFAULT_RR_WEIGHT,
            split: 1,
            window: None,
            style: Style::Shaded,
            gooch: GoochParams::default(),
            lines: None,
            sampler: crate::core::rng::SamplerKind::default(),
            radiosity: Default::default(),
            panorama: None,
            photon: Default::default(),
            caustics: false,
        }
    }
}

impl RenderSettings {
    /// Path slots per camera sample in the wavefront's batch arrays: the
    /// camera path, then one per part when a path-traced frame splits
    /// ([`RenderSettings::split`]); 1 otherwise.
    pub fn path_slots(&self) -> usize {
        if self.transport == Transport::Path && self.split > 1 {
            1 + self.split as usize
        } else {
            1
        }
    }
}

/// Most paths [`RenderSettings::split`] continues from a camera ray's
/// first hit.
pub const MAX_SPLIT: u32 = 64;

/// Largest image side accepted, to keep memory bounded.
pub const MAX_IMAGE_SIDE: u32 = 1 << 15;

/// Largest number of pixels accepted (2^26, e.g. 8192 x 8192): the film
/// alone takes 12 bytes per pixel.
pub const MAX_PIXELS: u64 = 1 << 26;

/// Largest number of samples per pixel accepted.
pub const MAX_SPP: u32 = 1 << 20;

/// Largest maximum depth accepted: the recursive tracer uses one stack
/// frame per bounce, and two facing mirrors reach any depth asked for.
pub const MAX_DEPTH_LIMIT: u32 = 1024;

impl RenderSettings {
    /// Rejects unusable settings with a message naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size must be at least 1x1, got {}x{}",
                self.width, self.height
            ));
        }
        if self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return Err(format!(
                "image size {}x{} exceeds the maximum side of {MAX_IMAGE_SIDE} pixels",
                self.width, self.height
            ));
        }
        if self.width as u64 * self.height as u64 > MAX_PIXELS {
            return Err(format!(
                "image size {}x{} exceeds the maximum of {MAX_PIXELS} pixels",
                self.width, self.height
            ));
        }
        if self.spp > MAX_SPP {
            return Err(format!(
                "samples per pixel {} exceeds the maximum of {MAX_SPP}",
                self.spp
            ));
        }
        if self.max_depth > MAX_DEPTH_LIMIT {
            return Err(format!(
                "max depth {} exceeds the limit of {MAX_DEPTH_LIMIT}",
                self.max_depth
            ));
        }
        if self.light_samples == 0 || self.light_samples > MAX_LIGHT_SAMPLES {
            return Err(format!(
                "light samples must be between 1 and {MAX_LIGHT_SAMPLES}, got {}",
                self.light_samples
            ));
        }
        if self.spp == 0 {
            return Err("samples per pixel must be at least 1".into());
        }
        if self.caustics && self.window.is_some() {
            return Err(
                "caustic light tracing splats onto the whole image: it takes no render window or shard"
                    .into(),
            );
        }
        if self.split == 0 || self.split > MAX_SPLIT {
            return Err(format!(
                "split must be between 1 and {MAX_SPLIT}, got {}",
                self.split
            ));
        }
        if !(self.rr_weight > 0.0 && self.rr_weight <= 1.0) {
            return Err(format!(
                "the Russian roulette weight must be in (0, 1], got {}",
                self.rr_weight
            ));
        }
        if !(self.min_contribution >= 0.0 && self.min_contribution.is_finite()) {
            return Err(format!(
                "min contribution must be a finite non-negative number, got {}",
                self.min_contribution
            ));
        }
        if let Some(w) = &self.window {
            w.validate(self.width, self.height, self.spp)?;
            if self.lines.is_some() {
                return Err(
                    "feature lines need the whole image: they do not combine with a render window"
                        .into(),
                );
            }
        }
        if self.style == Style::Gooch && self.transport != Transport::Whitted {
            return Err(
                "the Gooch style shades with Whitted transport (mirrors and glass included); \
                 it does not combine with path transport"
                    .into(),
            );
        }
        self.gooch.validate()?;
        if self.transport == Transport::Radiosity {
            self.radiosity.validate()?;
            if self.window.is_some() {
                return Err("radiosity renders whole images: it takes no render window".into());
            }
        }
        if let Some(p) = self.panorama {
            if p == Panorama::Cubemap && self.width != 6 * self.height {
                return Err(format!(
                    "a cube-map panorama is six square faces side by side: its width must be \
                     6 x its height, got {}x{}",
                    self.width, self.height
                ));
            }
            if self.lines.is_some() {
                return Err(format!(
                    "feature lines are drawn for the perspective camera; they do not combine \
                     with the {} panorama",
                    p.name()
                ));
            }
        }
        if self.transport == Transport::Photon {
            self.photon.validate()?;
            if self.spp as u64 * self.photon.iterations as u64 > MAX_SPP as u64 {
                return Err(format!(
                    "photon iterations times samples per pixel ({} x {}) exceeds the maximum of {MAX_SPP} samples per pixel",
                    self.photon.iterations, self.spp
                ));
            }
        }
        if let Some(l) = &self.lines {
            l.validate()?;
        }
        Ok(())
    }

    /// The window rendered: [`RenderSettings::window`], or the whole
    /// image with all its samples.
    pub fn window(&self) -> RenderWindow {
        self.window
            .clone()
            .unwrap_or_else(|| RenderWindow::full(self.width, self.height, self.spp))
    }

    /// Where each path of the window goes.
    pub fn path_map(&self) -> PathMap {
        PathMap::new(&self.window(), self.width)
    }
}
