//! Radiosity: view-independent diffuse interreflection, solved once over
//! patches and then looked up by view rays.
//!
//! 1. [`patches`]: the scene's polygons and mesh triangles are cut into
//!    patches of about [`RadiositySettings::patch_size`];
//! 2. [`form_factor`]: the form factors between patches, by ray-cast
//!    visibility with the analytic point-to-polygon term, or by hemicubes;
//! 3. [`solver`]: progressive refinement or Gauss-Seidel to a stated
//!    residual;
//! 4. adaptive subdivision: patches where the radiosity changes fast are
//!    split and steps 2-3 run again, [`RadiositySettings::refine_levels`]
//!    times;
//! 5. the view ([`Solution::radiance`]): a ray finds its patch and the
//!    radiosity is interpolated from the patch's corners (Gouraud), or
//!    gathered one bounce further (see [`ViewMode`]).
//!
//! What the solution models: diffuse reflection (the material's diffuse
//! albedo, [`SurfaceSample::diffuse`](crate::scene::material::SurfaceSample::diffuse))
//! and emission (two-sided, as the path tracer has it). Mirrors and glass
//! are traced through by the view rays (perfect specular reflection and
//! refraction, as Whitted transport does) until they reach a diffuse
//! surface, whose radiosity they read; inside the solve they reflect
//! nothing (light that reaches a diffuse surface only through a mirror or
//! glass is missing: caustics are photon mapping's). Blinn-Phong
//! highlights are left out. Punctual lights (point, spot, directional)
//! and analytic shapes other than polygons are refused with an error: the
//! solution transports light between patches only.
//!
//! Everything is deterministic: form factor rows are pure functions of the
//! patches, computed in parallel but collected in order; the solvers run
//! in a fixed order; so the solution is the same bit for bit whatever the
//! thread count.

pub mod form_factor;
pub mod patches;
pub mod solver;

use std::time::Instant;

use glam::{DVec3, Vec2, Vec3, Vec3A};
use serde::Serialize;

pub use crate::core::radiosity::{
    DEFAULT_MAX_PATCHES, Estimator, RadiosityDesc, RadiositySettings, Solver, ViewMode,
};
pub use form_factor::{FormFactorMethod, FormFactors};
pub use patches::Patches;
pub use solver::{SolveReport, System};

use crate::core::math::{Color, Ray};
use crate::geometry::mesh::{BuildQuality, Mesh, MeshData, MeshHit, NormalMode};
use crate::geometry::shapes::Shape;
use crate::scene::RenderScene;
use crate::scene::instance::InstanceGeometry;

/// The form factor method `settings` choose.
pub fn method(settings: &RadiositySettings) -> FormFactorMethod {
    match settings.estimator {
        Estimator::Raycast => FormFactorMethod::Raycast {
            level: settings.raycast_level,
        },
        Estimator::Hemicube => FormFactorMethod::Hemicube {
            resolution: settings.hemicube_resolution,
        },
    }
}

/// What a radiosity solve did, for `--stats`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RadiosityStats {
    /// Patches of the final solution.
    pub patches: usize,
    /// Base triangles (polygon fan triangles and mesh triangles).
    pub base_triangles: usize,
    /// Patch size used.
    pub patch_size: f32,
    /// Solves run (1 + rounds of adaptive subdivision that split patches).
    pub passes: u32,
    /// Patches split by adaptive subdivision.
    pub refined: usize,
    /// Stored form factors of the final pass.
    pub form_factors: usize,
    /// Bytes of the final form factor matrix.
    pub form_factor_bytes: usize,
    /// Largest memory of the solution's structures at any pass (form
    /// factors, patches, radiosities, the patch mesh), in bytes.
    pub peak_bytes: usize,
    /// Iterations of the final solve (shots or sweeps).
    pub iterations: u64,
    /// Residual of the final solve, relative to the largest radiosity.
    pub residual: f64,
    /// True when the final solve reached the tolerance.
    pub converged: bool,
    /// Seconds computing form factors (all passes).
    pub form_factor_seconds: f64,
    /// Seconds in the solver (all passes).
    pub solve_seconds: f64,
    /// Seconds of the whole solve.
    pub total_seconds: f64,
}

/// A solved scene: patches, their radiosities and corner values, and the
/// mesh of base triangles that view rays look patches up in.
#[derive(Debug)]
pub struct Solution {
    /// The patches.
    pub patches: Patches,
    /// Radiosity (exitance, W m^-2 in the renderer's units) of each patch.
    pub radiosity: Vec<Color>,
    /// Gouraud values at each patch's corners.
    pub corners: Vec<[Color; 3]>,
    /// The base triangles as one mesh, in the render frame of `origin`.
    pub mesh: Mesh,
    /// The render origin the solution's positions are relative to.
    pub origin: DVec3,
    /// What the solve did.
    pub stats: RadiosityStats,
}

/// Reported while solving: `(rows done, rows in this pass)` of the form
/// factor matrix.
pub type SolveProgress<'a> = &'a (dyn Fn(u64, u64) + Sync);

/// The base triangles of `scene` (fan triangles of polygons, mesh
/// triangles), their grouping (one group per polygon, one per mesh
/// triangle), and per triangle its diffuse reflectance and exitance.
/// Refuses scenes the solution cannot hold.
#[allow(clippy::type_complexity)]
pub fn base_triangles(
    scene: &RenderScene,
) -> Result<(Vec<patches::BaseTriangle>, Vec<u32>, Vec<(Color, Color)>), String> {
    if !scene.lights().is_empty() {
        return Err(format!(
            "radiosity transports light between surfaces: the scene's {} punctual light(s) \
             (point, spot, directional) cannot be part of the solution; light it with emissive \
             polygons or meshes, or use --transport path",
            scene.lights().len()
        ));
    }
    let mut bases = Vec::new();
    let mut group = Vec::new();
    let mut shading = Vec::new();
    let mut groups = 0u32;
    for (i, inst) in scene.instances().iter().enumerate() {
        let material = &scene.materials()[inst.material as usize];
        let m = &inst.transform.to_world;
        let mut push = |corners: [Vec3A; 3], uv: Vec2, g: u32| {
            let [a, b, c] = corners.map(|p| m.transform_point3a(p));
            let n = (b - a).cross(c - a);
            if !(n.length() > 0.0 && n.is_finite()) {
                return Ok(());
            }
            let s = material.sample(uv);
            if s.diffuse.max_element() >= 1.0 {
                return Err(format!(
                    "radiosity needs diffuse reflectance below 1 (the system diverges otherwise); \
                     object {i} has {:?}",
                    s.diffuse.to_array()
                ));
            }
            bases.push(patches::BaseTriangle {
                corners: [a, b, c],
                normal: n.normalize(),
                instance: i as u32,
                material: inst.material,
                surfaces: [None, None],
            });
            group.push(g);
            shading.push((
                s.diffuse.max(Vec3::ZERO),
                s.emission.max(Vec3::ZERO) * std::f32::consts::PI,
            ));
            Ok(())
        };
        match &inst.geometry {
            InstanceGeometry::Shape(Shape::Polygon { vertices }) => {
                let v0 = Vec3A::from(vertices[0]);
                for k in 1..vertices.len() - 1 {
                    push(
                        [v0, Vec3A::from(vertices[k]), Vec3A::from(vertices[k + 1])],
                        Vec2::ZERO,
                        groups,
                    )?;
                }
                groups += 1;
            }
            InstanceGeometry::Mesh(mesh) => {
                for t in 0..mesh.triangle_count() {
                    let uv = mesh
                        .surface(&MeshHit {
                            t: 0.0,
                            triangle: t as u32,
                            b1: 1.0 / 3.0,
                            b2: 1.0 / 3.0,
                        })
                        .uv;
                    push(mesh.triangle(t), uv, groups)?;
                    groups += 1;
                }
            }
            InstanceGeometry::Shape(s) => {
                return Err(format!(
                    "radiosity patches are made from polygons and meshes; object {i} is a {} \
                     (model it as a mesh, or use --transport path)",
                    s.kind_name()
                ));
            }
        }
    }
    if bases.is_empty() {
        return Err("radiosity needs at least one polygon or mesh triangle".into());
    }
    Ok((bases, group, shading))
}

/// The mesh of `bases`, in order (its input triangle `i` is base `i`).
pub fn base_mesh(bases: &[patches::BaseTriangle]) -> Result<Mesh, String> {
    let data = MeshData {
        positions: bases
            .iter()
            .flat_map(|b| b.corners.map(Vec3::from))
            .collect(),
        indices: (0..bases.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect(),
        ..Default::default()
    };
    Mesh::new(
        "radiosity patches",
        data,
        NormalMode::Flat,
        BuildQuality::Medium,
    )
}

/// Solves the radiosity of `scene`: patches, form factors, solve, and
/// `settings.refine_levels` rounds of adaptive subdivision.
pub fn solve(
    scene: &RenderScene,
    settings: &RadiositySettings,
    progress: Option<SolveProgress<'_>>,
) -> Result<Solution, String> {
    settings.validate()?;
    let (bases, group, shading) = base_triangles(scene)?;
    solve_triangles(bases, &group, &shading, scene.origin(), settings, progress)
}

/// [`solve`] for base triangles given directly (their `surfaces` are
/// filled in): `group[i]` is triangle `i`'s group (triangles of one group
/// are split to the same depth), `shading[i]` its diffuse reflectance and
/// emitted exitance; `origin` is recorded as the solution's frame.
pub fn solve_triangles(
    bases: Vec<patches::BaseTriangle>,
    group: &[u32],
    shading: &[(Color, Color)],
    origin: DVec3,
    settings: &RadiositySettings,
    progress: Option<SolveProgress<'_>>,
) -> Result<Solution, String> {
    settings.validate()?;
    let start = Instant::now();
    if bases.is_empty() {
        return Err("radiosity needs at least one polygon or mesh triangle".into());
    }
    let mut lo = Vec3A::splat(f32::INFINITY);
    let mut hi = Vec3A::splat(f32::NEG_INFINITY);
    for b in &bases {
        for c in b.corners {
            lo = lo.min(c);
            hi = hi.max(c);
        }
    }
    let patch_size = settings
        .patch_size
        .unwrap_or_else(|| (hi - lo).max_element() / 8.0);
    if !(patch_size.is_finite() && patch_size > 0.0) {
        return Err(format!(
            "radiosity patch size must be positive, got {patch_size}"
        ));
    }
    let mesh = base_mesh(&bases)?;
    let max_patches = settings.max_patches as usize;
    let base_count = bases.len();
    let mut patches = Patches::build(bases, group, patch_size, (lo, hi), shading, max_patches)?;
    let mut stats = RadiosityStats {
        base_triangles: base_count,
        patch_size,
        ..Default::default()
    };
    loop {
        let n = patches.len() as u64;
        let done = std::sync::atomic::AtomicU64::new(0);
        let tick = |k: u64| {
            let d = done.fetch_add(k, std::sync::atomic::Ordering::Relaxed) + k;
            if let Some(p) = progress {
                p(d, n);
            }
        };
        let t0 = Instant::now();
        let ff = form_factor::compute(&patches, &mesh, method(settings), &tick);
        stats.form_factor_seconds += t0.elapsed().as_secs_f64();
        let rho: Vec<Color> = (0..patches.len()).map(|p| patches.reflectance(p)).collect();
        let e: Vec<Color> = (0..patches.len()).map(|p| patches.exitance(p)).collect();
        let system = System {
            ff: &ff,
            rho: &rho,
            e: &e,
            area: &patches.area,
        };
        let t1 = Instant::now();
        let tol = settings.tolerance as f64;
        let max_it = settings.max_iterations as u64;
        let (b, report) = match settings.solver {
            Solver::Progressive => system.progressive(tol, max_it),
            Solver::GaussSeidel => system.gauss_seidel(tol, max_it),
        };
        stats.solve_seconds += t1.elapsed().as_secs_f64();
        stats.passes += 1;
        stats.iterations = report.iterations;
        stats.residual = report.residual;
        stats.converged = report.converged;
        stats.form_factors = ff.entries();
        stats.form_factor_bytes = ff.bytes();
        let patch_bytes = patches.elements.len() * std::mem::size_of::<patches::Element>()
            + patches.len() * (4 + 4 + 4 + 2 * 12 + 3 * 12);
        stats.peak_bytes = stats
            .peak_bytes
            .max(ff.bytes() + patch_bytes + mesh.accel_bytes());
        if stats.passes > settings.refine_levels
            || patches.refine(&b, settings.refine_threshold, max_patches) == 0
        {
            stats.patches = patches.len();
            stats.total_seconds = start.elapsed().as_secs_f64();
            let corners = patches.corner_values(&b);
            return Ok(Solution {
                patches,
                radiosity: b,
                corners,
                mesh,
                origin,
                stats,
            });
        }
        stats.refined += (patches.len() - n as usize) / 3;
    }
}

/// A view ray's first surface in a [`Solution`].
#[derive(Clone, Copy, Debug)]
pub struct SolutionHit {
    /// Ray parameter.
    pub t: f32,
    /// Patch.
    pub patch: u32,
    /// Radiosity there, interpolated as the view mode asks (Gouraud or
    /// flat).
    pub radiosity: Color,
}

impl Solution {
    /// The first patch along `ray` (in the solution's frame) with `t` in
    /// `(t_min, t_max)`, and its radiosity there: interpolated from the
    /// corners, or the patch's own with `flat`.
    pub fn hit(&self, ray: &Ray, t_min: f32, t_max: f32, flat: bool) -> Option<SolutionHit> {
        let (p, u, v, t) = form_factor::patch_hit(&self.patches, &self.mesh, ray, t_min, t_max)?;
        let radiosity = if flat {
            self.radiosity[p as usize]
        } else {
            let [c0, c1, c2] = self.corners[p as usize];
            c0 * (1.0 - u - v) + c1 * u + c2 * v
        };
        Some(SolutionHit {
            t,
            patch: p,
            radiosity,
        })
    }

    /// Radiance leaving the first patch along `ray`: its radiosity over
    /// pi (Lambertian), or `None` when the ray leaves the scene.
    pub fn radiance(&self, ray: &Ray, t_min: f32, t_max: f32, flat: bool) -> Option<Color> {
        self.hit(ray, t_min, t_max, flat)
            .map(|h| h.radiosity * std::f32::consts::FRAC_1_PI)
    }

    /// Shifts a point of a render frame centred on `origin` into the
    /// solution's frame.
    pub fn to_solution_frame(&self, origin: DVec3) -> Vec3A {
        (origin - self.origin).as_vec3a()
    }
}
