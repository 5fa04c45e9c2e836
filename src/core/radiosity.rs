//! Radiosity's options (see [`crate::radiosity`] for the method): kept
//! here, beside the other render settings, so that settings and scene
//! files can name them.

use serde::Serialize;

/// How form factors are estimated.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Estimator {
    /// Analytic point-to-polygon form factors at points of the sending
    /// patch, times ray-cast visibility.
    #[default]
    Raycast,
    /// Hemicubes at patch centroids, pixels resolved by ray casting.
    Hemicube,
}

impl Estimator {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Raycast => "raycast",
            Estimator::Hemicube => "hemicube",
        }
    }
}

/// Which solver finds the radiosities.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// Shoot from the patch with the most unshot power.
    #[default]
    Progressive,
    /// Gauss-Seidel sweeps.
    GaussSeidel,
}

impl Solver {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Progressive => "progressive",
            Solver::GaussSeidel => "gauss-seidel",
        }
    }
}

/// How view rays turn the solution into radiance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ViewMode {
    /// Radiosity interpolated from the patch's corner values (Gouraud).
    #[default]
    Gouraud,
    /// Each patch's own radiosity (flat, shows the patches).
    Flat,
    /// A final gather: at the first diffuse surface, cosine-distributed
    /// rays read the Gouraud radiosity where they land
    /// (`L = L_e + rho mean(B/pi)`), which hides the patches.
    Gather,
}

impl ViewMode {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            ViewMode::Gouraud => "gouraud",
            ViewMode::Flat => "flat",
            ViewMode::Gather => "gather",
        }
    }
}

/// Largest number of patches accepted by default: the form factor matrix
/// grows with its square.
pub const DEFAULT_MAX_PATCHES: u32 = 8192;

/// Radiosity's options.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RadiositySettings {
    /// Patch size in scene units: elements are split until their area is
    /// at most half its square (the halves of a square of this side).
    /// `None`: an eighth of the scene's largest extent.
    pub patch_size: Option<f32>,
    /// Form factor estimator.
    pub estimator: Estimator,
    /// Ray-cast quadrature level: `4^level` points per patch and as many
    /// visibility rays per pair (0 to 3, default 1).
    pub raycast_level: u32,
    /// Hemicube pixels across the top face (even, 4 to 1024, default 64).
    pub hemicube_resolution: u32,
    /// Solver.
    pub solver: Solver,
    /// Residual to reach, relative to the largest radiosity (default 1e-4).
    pub tolerance: f32,
    /// Most iterations (shots or sweeps) per solve.
    pub max_iterations: u32,
    /// Rounds of adaptive subdivision after the first solve (default 2).
    pub refine_levels: u32,
    /// A patch is split when its radiosity differs from one of its
    /// corners' Gouraud values by more than this times the mean
    /// radiosity (luminance; default 0.25).
    pub refine_threshold: f32,
    /// Most patches (default [`DEFAULT_MAX_PATCHES`]).
    pub max_patches: u32,
    /// How view rays read the solution.
    pub view: ViewMode,
    /// Gather rays per sample with [`ViewMode::Gather`] (default 16).
    pub gather_rays: u32,
}

impl Default for RadiositySettings {
    fn default() -> Self {
        Self {
            patch_size: None,
            estimator: Estimator::Raycast,
            raycast_level: 1,
            hemicube_resolution: 64,
            solver: Solver::Progressive,
            tolerance: 1e-4,
            max_iterations: 1_000_000,
            refine_levels: 2,
            refine_threshold: 0.25,
            max_patches: DEFAULT_MAX_PATCHES,
            view: ViewMode::Gouraud,
            gather_rays: 16,
        }
    }
}

impl RadiositySettings {
    /// Rejects unusable options with a message naming the option.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(s) = self.patch_size
            && !(s.is_finite() && s > 0.0)
        {
            return Err(format!(
                "radiosity patch size must be a positive finite length, got {s}"
            ));
        }
        if self.raycast_level > 3 {
            return Err(format!(
                "radiosity ray-cast level must be 0 to 3 (1 to 64 points per patch), got {}",
                self.raycast_level
            ));
        }
        let r = self.hemicube_resolution;
        if !(4..=1024).contains(&r) || r % 2 != 0 {
            return Err(format!(
                "hemicube resolution must be an even number from 4 to 1024, got {r}"
            ));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(format!(
                "radiosity tolerance must be between 0 and 1 (exclusive), got {}",
                self.tolerance
            ));
        }
        if !(self.refine_threshold.is_finite() && self.refine_threshold > 0.0) {
            return Err(format!(
                "radiosity refine threshold must be a positive finite number, got {}",
                self.refine_threshold
            ));
        }
        if self.refine_levels > 8 {
            return Err(format!(
                "radiosity refine levels must be at most 8, got {}",
                self.refine_levels
            ));
        }
        if self.max_patches == 0 || self.max_iterations == 0 {
            return Err("radiosity max patches and max iterations must be at least 1".into());
        }
        if self.gather_rays == 0 || self.gather_rays > 4096 {
            return Err(format!(
                "radiosity gather rays must be 1 to 4096, got {}",
                self.gather_rays
            ));
        }
        Ok(())
    }
}

/// Radiosity's options as a scene file's `[settings.radiosity]` table or
/// the command line give them: each optional, resolved over another
/// (the command line over the file) and then the defaults.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadiosityDesc {
    /// [`RadiositySettings::patch_size`].
    pub patch_size: Option<f32>,
    /// [`RadiositySettings::estimator`].
    pub estimator: Option<Estimator>,
    /// [`RadiositySettings::raycast_level`].
    pub raycast_level: Option<u32>,
    /// [`RadiositySettings::hemicube_resolution`].
    pub hemicube_resolution: Option<u32>,
    /// [`RadiositySettings::solver`].
    pub solver: Option<Solver>,
    /// [`RadiositySettings::tolerance`].
    pub tolerance: Option<f32>,
    /// [`RadiositySettings::max_iterations`].
    pub max_iterations: Option<u32>,
    /// [`RadiositySettings::refine_levels`].
    pub refine_levels: Option<u32>,
    /// [`RadiositySettings::refine_threshold`].
    pub refine_threshold: Option<f32>,
    /// [`RadiositySettings::max_patches`].
    pub max_patches: Option<u32>,
    /// [`RadiositySettings::view`].
    pub view: Option<ViewMode>,
    /// [`RadiositySettings::gather_rays`].
    pub gather_rays: Option<u32>,
}

impl RadiosityDesc {
    /// These options over `under`, then the defaults.
    pub fn resolve(&self, under: &RadiosityDesc) -> RadiositySettings {
        let d = RadiositySettings::default();
        RadiositySettings {
            patch_size: self.patch_size.or(under.patch_size).or(d.patch_size),
            estimator: self.estimator.or(under.estimator).unwrap_or(d.estimator),
            raycast_level: self
                .raycast_level
                .or(under.raycast_level)
                .unwrap_or(d.raycast_level),
            hemicube_resolution: self
                .hemicube_resolution
                .or(under.hemicube_resolution)
                .unwrap_or(d.hemicube_resolution),
            solver: self.solver.or(under.solver).unwrap_or(d.solver),
            tolerance: self.tolerance.or(under.tolerance).unwrap_or(d.tolerance),
            max_iterations: self
                .max_iterations
                .or(under.max_iterations)
                .unwrap_or(d.max_iterations),
            refine_levels: self
                .refine_levels
                .or(under.refine_levels)
                .unwrap_or(d.refine_levels),
            refine_threshold: self
                .refine_threshold
                .or(under.refine_threshold)
                .unwrap_or(d.refine_threshold),
            max_patches: self
                .max_patches
                .or(under.max_patches)
                .unwrap_or(d.max_patches),
            view: self.view.or(under.view).unwrap_or(d.view),
            gather_rays: self
                .gather_rays
                .or(under.gather_rays)
                .unwrap_or(d.gather_rays),
        }
    }
}
