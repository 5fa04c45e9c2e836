//! Image-based rendering from a two-plane light field (Levoy and Hanrahan
//! 1996): new views made from captured images alone, without geometry.
//!
//! # Parametrisation
//! A [`Rig`] is a regular grid of pinhole cameras on the *camera plane*
//! (the `(u, v)` plane), all looking along its normal through a common
//! window of the *focal plane* (the `(s, t)` plane) a distance
//! [`Rig::focal_distance`] in front. Camera `(column, row)` sits at
//! `centre + a right + b up` with
//! `a = (column - (columns - 1) / 2) spacing` and
//! `b = ((rows - 1) / 2 - row) spacing` (row 0 is the top row, as in an
//! image). Each camera's image is an off-axis (lens-shifted, see
//! [`Camera::shift`]) view of the same focal window, so pixel `(x, y)` of
//! every image sees the same point of the focal plane: the images are the
//! light slab `L(u, v, s, t)` sampled on the grid of cameras by the grid of
//! pixels.
//!
//! # Synthesis
//! [`synth::synthesise`] follows each ray of a new view to the camera
//! plane (continuous grid coordinates `(u, v)`) and to the focal plane
//! (continuous pixel coordinates `(s, t)`) and interpolates the 16
//! neighbouring samples quadrilinearly. With a proxy plane (the
//! lumigraph's depth correction, Gortler et al. 1996) the ray's point on
//! the proxy is projected into each of the four neighbouring cameras
//! instead, so surfaces near the proxy depth stay sharp; a proxy at the
//! focal distance is plain quadrilinear interpolation.
//!
//! # Files
//! `prism lightfield capture` writes one OpenEXR image per camera and a
//! [`Manifest`] (`lightfield.json`) last, so a folder without a manifest
//! is an unfinished capture. [`LightField::load`] reads it back and checks
//! everything it relies on (see there).

pub mod synth;

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec2};
use serde::{Deserialize, Serialize};

use crate::core::error::{Error, Result};
use crate::core::settings::{LightFieldSettings, MAX_IMAGE_SIDE};
use crate::image::film::Film;
use crate::scene::camera::Camera;

/// The manifest's file name inside a light-field folder.
pub const MANIFEST: &str = "lightfield.json";
/// [`Manifest::format`] of the files Prism writes.
pub const FORMAT: &str = "prism-lightfield";
/// [`Manifest::version`] of the files this build writes and reads.
pub const VERSION: u32 = 1;
/// Most pixels all images of one light field may hold together (2^30,
/// 12 GiB of RGB floats): a manifest asking for more is refused before
/// anything is read.
pub const MAX_TOTAL_PIXELS: u64 = 1 << 30;

/// The geometry of a two-plane light field (see the module docs). World
/// coordinates, in f64.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    /// Centre of the camera plane: the middle of the grid of cameras.
    pub centre: DVec3,
    /// Unit direction of increasing columns (the cameras' right).
    pub right: DVec3,
    /// Unit direction of decreasing rows (the cameras' up).
    pub up: DVec3,
    /// Unit normal of both planes, from the camera plane towards the focal
    /// plane (every camera's viewing direction), `forward = up x right` as
    /// for a camera looking along it.
    pub forward: DVec3,
    /// Distance from the camera plane to the focal plane.
    pub focal_distance: f64,
    /// Cameras across (columns) and up (rows).
    pub grid: [u32; 2],
    /// Distance between neighbouring cameras.
    pub spacing: f64,
    /// Width and height of every image, pixels.
    pub resolution: [u32; 2],
    /// Vertical field of view of every camera, degrees: the focal window
    /// is `2 d tan(vfov / 2)` high at the focal distance `d`, and as wide
    /// as the images' aspect ratio makes it.
    pub vfov_degrees: f64,
}

impl Rig {
    /// The rig of `camera` (the grid centred on its eye, in the plane of
    /// its right and up, looking along its view direction, its field of
    /// view framing the focal window) with the grid, spacing, resolution
    /// and focal distance of `settings`; the focal distance defaults to
    /// the distance from the camera's eye to the point it looks at, the
    /// spacing to a sixteenth of the focal distance. The camera's
    /// [`shift`](Camera::shift), lens and projection are not used: the
    /// rig's cameras are pinholes.
    pub fn from_camera(camera: &Camera, settings: &LightFieldSettings) -> Result<Self> {
        camera.validate().map_err(Error::Invalid)?;
        settings.validate().map_err(Error::Invalid)?;
        let forward = (camera.look_at - camera.look_from).normalize();
        let right = forward.cross(camera.up.as_dvec3()).normalize();
        let up = right.cross(forward);
        let focal_distance = settings
            .focal_distance
            .unwrap_or_else(|| (camera.look_at - camera.look_from).length());
        let rig = Self {
            centre: camera.look_from,
            right,
            up,
            forward,
            focal_distance,
            grid: settings.grid.unwrap_or(LightFieldSettings::DEFAULT_GRID),
            spacing: settings.spacing.unwrap_or(focal_distance / 16.0),
            resolution: settings
                .resolution
                .unwrap_or(LightFieldSettings::DEFAULT_RESOLUTION),
            vfov_degrees: camera.vfov_degrees as f64,
        };
        rig.validate().map_err(Error::Invalid)?;
        Ok(rig)
    }

    /// Checks that the rig is usable: finite values, unit and mutually
    /// orthogonal axes (to 1e-6) with `forward = up x right`, a grid of
    /// 1 to 256 cameras a side, images of 1 to 32768 pixels a side, a
    /// positive spacing and focal distance, a field of view in (0, 180).
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (name, v) in [
            ("centre", self.centre),
            ("right", self.right),
            ("up", self.up),
            ("forward", self.forward),
        ] {
            if !v.is_finite() {
                return Err(format!("the rig's {name} is not finite: {v}"));
            }
        }
        let unit = |v: DVec3| (v.length() - 1.0).abs() < 1e-6;
        if !(unit(self.right) && unit(self.up) && unit(self.forward))
            || self.right.dot(self.up).abs() > 1e-6
            || (self.up.cross(self.right) - self.forward).length() > 1e-6
        {
            return Err(format!(
                "the rig's right {}, up {} and forward {} are not an orthonormal frame with forward = up x right",
                self.right, self.up, self.forward
            ));
        }
        LightFieldSettings {
            grid: Some(self.grid),
            spacing: Some(self.spacing),
            resolution: Some(self.resolution),
            focal_distance: Some(self.focal_distance),
        }
        .validate()?;
        if !(self.vfov_degrees > 0.0 && self.vfov_degrees < 180.0) {
            return Err(format!(
                "the rig's field of view must be in (0, 180) degrees, got {}",
                self.vfov_degrees
            ));
        }
        let [w, h] = self.resolution;
        debug_assert!(w <= MAX_IMAGE_SIDE && h <= MAX_IMAGE_SIDE);
        let total = self.camera_count() as u64 * w as u64 * h as u64;
        if total > MAX_TOTAL_PIXELS {
            return Err(format!(
                "the light field would hold {total} pixels ({}x{} cameras of {w}x{h}); at most {MAX_TOTAL_PIXELS}",
                self.grid[0], self.grid[1]
            ));
        }
        Ok(())
    }

    /// Number of cameras.
    pub fn camera_count(&self) -> usize {
        self.grid[0] as usize * self.grid[1] as usize
    }

    /// Offset of camera `(column, row)` from the centre along `right` and
    /// `up`.
    pub fn offset(&self, column: u32, row: u32) -> (f64, f64) {
        let a = (column as f64 - (self.grid[0] as f64 - 1.0) * 0.5) * self.spacing;
        let b = ((self.grid[1] as f64 - 1.0) * 0.5 - row as f64) * self.spacing;
        (a, b)
    }

    /// Height of the image plane at unit distance, `2 tan(vfov / 2)`.
    pub fn unit_height(&self) -> f64 {
        2.0 * (self.vfov_degrees.to_radians() * 0.5).tan()
    }

    /// Width and height of the focal window (world units).
    pub fn window_size(&self) -> (f64, f64) {
        let h = self.unit_height() * self.focal_distance;
        let [rw, rh] = self.resolution;
        (h * rw as f64 / rh as f64, h)
    }

    /// The camera of grid position `(column, row)`: on the camera plane,
    /// looking along `forward` with `up` up, shifted so that its image is
    /// the focal window.
    pub fn camera(&self, column: u32, row: u32) -> Camera {
        let (a, b) = self.offset(column, row);
        Camera {
            name: Some(format!("lightfield camera column {column} row {row}")),
            ..self.camera_at(a, b)
        }
    }

    /// A camera like the grid's at any point of the camera plane, `a`
    /// along `right` and `b` along `up` from the centre: its image is the
    /// focal window seen from there.
    pub fn camera_at(&self, a: f64, b: f64) -> Camera {
        let eye = self.centre + self.right * a + self.up * b;
        let scale = self.focal_distance * self.unit_height();
        Camera {
            look_from: eye,
            look_at: eye + self.forward,
            up: self.up.as_vec3(),
            vfov_degrees: self.vfov_degrees as f32,
            shift: Vec2::new((-a / scale) as f32, (-b / scale) as f32),
            ..Default::default()
        }
    }

    /// Half the extent of the grid along `right` and `up`: camera centres
    /// lie within `[-x, x] x [-y, y]` of the centre.
    pub fn half_aperture(&self) -> (f64, f64) {
        (
            (self.grid[0] as f64 - 1.0) * 0.5 * self.spacing,
            (self.grid[1] as f64 - 1.0) * 0.5 * self.spacing,
        )
    }

    /// World point `p` in the rig frame: along `right`, `up` and `forward`
    /// from the centre.
    pub fn to_rig(&self, p: DVec3) -> DVec3 {
        let q = p - self.centre;
        DVec3::new(q.dot(self.right), q.dot(self.up), q.dot(self.forward))
    }

    /// World direction `d` in the rig frame.
    pub fn direction_to_rig(&self, d: DVec3) -> DVec3 {
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }
}

/// One captured image in the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageEntry {
    /// Grid column (0 at the left).
    pub column: u32,
    /// Grid row (0 at the top).
    pub row: u32,
    /// File name inside the light-field folder (an OpenEXR image).
    pub file: String,
}

/// How the images were rendered (for the record and for `prism lightfield
/// compare`, which renders the reference the same way).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureInfo {
    /// The scene file, as given on the command line.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Maximum path depth.
    pub max_depth: u32,
    /// `whitted` or `path`.
    pub transport: String,
    /// Random seed.
    pub seed: u64,
    /// Seconds to render all images (excluding loading and writing).
    pub render_seconds: f64,
    /// Seconds spent building acceleration structures: the meshes' BVHs
    /// when the scene was loaded and the top level at the first view.
    pub bvh_seconds: f64,
    /// Top-level rebuilds after the first view (0: the BVH was reused for
    /// every view).
    pub bvh_rebuilds: u32,
    /// Prism's version.
    pub prism_version: String,
}

/// The manifest of a light-field folder (`lightfield.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The parametrisation.
    pub rig: Rig,
    /// One entry per camera, in row-major order.
    pub images: Vec<ImageEntry>,
    /// How the images were made.
    pub capture: CaptureInfo,
}

impl Manifest {
    /// The manifest of `rig` with Prism's own image names
    /// ([`Manifest::image_name`]).
    pub fn new(rig: Rig, capture: CaptureInfo) -> Self {
        let images = (0..rig.grid[1])
            .flat_map(|row| {
                (0..rig.grid[0]).map(move |column| ImageEntry {
                    column,
                    row,
                    file: Self::image_name(column, row),
                })
            })
            .collect();
        Self {
            format: FORMAT.into(),
            version: VERSION,
            rig,
            images,
            capture,
        }
    }

    /// `view_r{row}_c{column}.exr`, three digits each.
    pub fn image_name(column: u32, row: u32) -> String {
        format!("view_r{row:03}_c{column:03}.exr")
    }

    /// The manifest as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("the manifest is plain data")
    }

    /// Reads `dir/lightfield.json` and checks it: the format and version,
    /// the rig ([`Rig::validate`]), and one image per camera, each a plain
    /// file name (no folders), listed once.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(MANIFEST);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Error::load(
                    &path,
                    if dir.is_dir() {
                        "no light-field manifest here: `prism lightfield capture` writes it \
                         last, so the capture into this folder did not finish (or the folder \
                         is not a light field)"
                            .to_string()
                    } else {
                        format!("{} is not a folder", dir.display())
                    },
                ));
            }
            Err(e) => return Err(Error::load(&path, e.to_string())),
        };
        let m: Manifest = serde_json::from_str(&text)
            .map_err(|e| Error::load(&path, format!("not a light-field manifest: {e}")))?;
        m.check().map_err(|e| Error::load(&path, e))?;
        Ok(m)
    }

    /// The checks of [`Manifest::read`] on a parsed manifest.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.format != FORMAT {
            return Err(format!("format is {:?}, expected {FORMAT:?}", self.format));
        }
        if self.version != VERSION {
            return Err(format!(
                "version {} is not supported (this build reads version {VERSION})",
                self.version
            ));
        }
        self.rig.validate()?;
        let [cols, rows] = self.rig.grid;
        if self.images.len() != self.rig.camera_count() {
            return Err(format!(
                "the grid is {cols}x{rows} cameras but {} images are listed",
                self.images.len()
            ));
        }
        let mut seen = vec![false; self.rig.camera_count()];
        for e in &self.images {
            if e.column >= cols || e.row >= rows {
                return Err(format!(
                    "image {:?} is at column {}, row {}: outside the {cols}x{rows} grid",
                    e.file, e.column, e.row
                ));
            }
            let i = (e.row * cols + e.column) as usize;
            if std::mem::replace(&mut seen[i], true) {
                return Err(format!(
                    "column {}, row {} is listed twice",
                    e.column, e.row
                ));
            }
            let p = Path::new(&e.file);
            if e.file.is_empty()
                || p.components().count() != 1
                || !matches!(p.components().next(), Some(std::path::Component::Normal(_)))
            {
                return Err(format!(
                    "image name {:?} must be a plain file name inside the folder",
                    e.file
                ));
            }
        }
        Ok(())
    }
}

/// A light field in memory: its manifest and one image per camera.
#[derive(Clone, Debug)]
pub struct LightField {
    /// The manifest it was read with.
    pub manifest: Manifest,
    /// The images in row-major grid order (`row * columns + column`).
    pub images: Vec<Film>,
}

impl LightField {
    /// A light field from a manifest and its images in row-major grid
    /// order; checks the manifest, the image count, every image's size
    /// against the rig's resolution and that every value is finite.
    pub fn new(manifest: Manifest, images: Vec<Film>) -> Result<Self> {
        manifest.check().map_err(Error::Invalid)?;
        if images.len() != manifest.rig.camera_count() {
            return Err(Error::Invalid(format!(
                "{} images for a grid of {} cameras",
                images.len(),
                manifest.rig.camera_count()
            )));
        }
        for (i, film) in images.iter().enumerate() {
            let cols = manifest.rig.grid[0] as usize;
            let name = manifest
                .images
                .iter()
                .find(|e| (e.row as usize * cols + e.column as usize) == i)
                .map_or_else(|| format!("image {i}"), |e| e.file.clone());
            check_image(film, &name, manifest.rig.resolution)?;
        }
        Ok(Self { manifest, images })
    }

    /// Reads the light field in folder `dir`: the manifest
    /// ([`Manifest::read`]), then every image it lists, which must exist,
    /// be an OpenEXR image of the rig's resolution and hold only finite,
    /// non-negative values. Errors name the file and say what is wrong.
    pub fn load(dir: &Path) -> Result<Self> {
        let manifest = Manifest::read(dir)?;
        let cols = manifest.rig.grid[0] as usize;
        let mut slots: Vec<Option<Film>> = vec![None; manifest.rig.camera_count()];
        for e in &manifest.images {
            let path: PathBuf = dir.join(&e.file);
            if !path.is_file() {
                return Err(Error::load(
                    &path,
                    format!(
                        "the image of column {}, row {} listed in {MANIFEST} is missing",
                        e.column, e.row
                    ),
                ));
            }
            let film = crate::image::metrics::read_exr(&path)?;
            check_image(&film, &path.display().to_string(), manifest.rig.resolution)?;
            slots[e.row as usize * cols + e.column as usize] = Some(film);
        }
        let images = slots
            .into_iter()
            .map(|f| f.expect("Manifest::check saw every camera once"))
            .collect();
        Ok(Self { manifest, images })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.manifest.rig
    }

    /// The image of camera `(column, row)`.
    pub fn image(&self, column: u32, row: u32) -> &Film {
        &self.images[(row * self.rig().grid[0] + column) as usize]
    }
}

/// Checks one captured image against the rig's resolution.
fn check_image(film: &Film, name: &str, [w, h]: [u32; 2]) -> Result<()> {
    crate::image::metrics::check_film(film, name)?;
    if (film.width, film.height) != (w, h) {
        return Err(Error::Invalid(format!(
            "{name} is {}x{} but the light field's images are {w}x{h} (images of different sizes)",
            film.width, film.height
        )));
    }
    if let Some(i) = film.pixels.iter().position(|p| p.min_element() < 0.0) {
        return Err(Error::Invalid(format!(
            "{name} has a negative value at pixel ({}, {})",
            i % w as usize,
            i / w as usize
        )));
    }
    Ok(())
}
