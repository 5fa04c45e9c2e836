//! `prism render`'s radiosity options (`--transport radiosity`).

use clap::ValueEnum;

use prism::radiosity::{Estimator, RadiosityDesc, Solver, ViewMode};

/// `--radiosity-estimator`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum EstimatorArg {
    /// Analytic point-to-polygon form factors times ray-cast visibility.
    Raycast,
    /// Hemicubes at patch centroids, pixels found by ray casting.
    Hemicube,
}

/// `--radiosity-solver`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum SolverArg {
    /// Progressive refinement: shoot from the patch with most unshot power.
    Progressive,
    /// Gauss-Seidel sweeps.
    GaussSeidel,
}

/// `--radiosity-view`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ViewArg {
    /// Radiosity interpolated from patch corners (Gouraud).
    Gouraud,
    /// Each patch's own radiosity (shows the patches).
    Flat,
    /// A final gather of the Gouraud solution, one bounce from the view.
    Gather,
}

/// Radiosity's options (each falls back to the scene's
/// `[settings.radiosity]`, then to the default).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct RadiosityFlags {
    /// Radiosity: patch size in scene units; patches are split until their
    /// area is at most half its square [default: an eighth of the scene's
    /// largest extent].
    #[arg(long, value_name = "LENGTH", allow_hyphen_values = true)]
    pub patch_size: Option<f32>,
    /// Radiosity: form factor estimator [default: raycast].
    #[arg(long, value_enum)]
    pub radiosity_estimator: Option<EstimatorArg>,
    /// Radiosity: ray-cast quadrature level, 0 to 3: 4^L points per patch
    /// and as many visibility rays per pair [default: 1].
    #[arg(long, value_name = "L")]
    pub raycast_level: Option<u32>,
    /// Radiosity: hemicube pixels across the top face (even, 4 to 1024)
    /// [default: 64].
    #[arg(long, value_name = "PIXELS")]
    pub hemicube_resolution: Option<u32>,
    /// Radiosity: solver [default: progressive].
    #[arg(long, value_enum)]
    pub radiosity_solver: Option<SolverArg>,
    /// Radiosity: residual to reach, relative to the largest radiosity
    /// [default: 1e-4].
    #[arg(long, value_name = "R")]
    pub radiosity_tolerance: Option<f32>,
    /// Radiosity: rounds of adaptive subdivision where radiosity changes
    /// fast (0 to 8) [default: 2].
    #[arg(long, value_name = "N")]
    pub refine_levels: Option<u32>,
    /// Radiosity: split a patch whose radiosity differs from a corner's
    /// Gouraud value by more than this times the mean radiosity
    /// [default: 0.25].
    #[arg(long, value_name = "T")]
    pub refine_threshold: Option<f32>,
    /// Radiosity: most patches [default: 8192].
    #[arg(long, value_name = "N")]
    pub max_patches: Option<u32>,
    /// Radiosity: how view rays read the solution [default: gouraud].
    #[arg(long, value_enum)]
    pub radiosity_view: Option<ViewArg>,
    /// Radiosity: final-gather rays per sample with --radiosity-view gather
    /// [default: 16].
    #[arg(long, value_name = "N")]
    pub gather_rays: Option<u32>,
}

impl RadiosityFlags {
    /// The options given.
    pub fn desc(&self) -> RadiosityDesc {
        RadiosityDesc {
            patch_size: self.patch_size,
            estimator: self.radiosity_estimator.map(|e| match e {
                EstimatorArg::Raycast => Estimator::Raycast,
                EstimatorArg::Hemicube => Estimator::Hemicube,
            }),
            raycast_level: self.raycast_level,
            hemicube_resolution: self.hemicube_resolution,
            solver: self.radiosity_solver.map(|s| match s {
                SolverArg::Progressive => Solver::Progressive,
                SolverArg::GaussSeidel => Solver::GaussSeidel,
            }),
            tolerance: self.radiosity_tolerance,
            max_iterations: None,
            refine_levels: self.refine_levels,
            refine_threshold: self.refine_threshold,
            max_patches: self.max_patches,
            view: self.radiosity_view.map(|v| match v {
                ViewArg::Gouraud => ViewMode::Gouraud,
                ViewArg::Flat => ViewMode::Flat,
                ViewArg::Gather => ViewMode::Gather,
            }),
            gather_rays: self.gather_rays,
        }
    }
}
