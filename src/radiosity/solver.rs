//! Solving the radiosity system `B_i = E_i + rho_i sum_j F_ij B_j` (per
//! colour channel) for the patch radiosities `B`.
//!
//! * **Progressive refinement** (Cohen, Chen, Wallace and Greenberg 1988):
//!   every patch keeps its unshot radiosity; the patch with the most
//!   unshot power (`A_i` times the sum of its unshot radiosity's
//!   channels, lowest index on ties) shoots it to every patch it sees, using
//!   reciprocity (`F_ji = A_i F_ij / A_j`) to read its own row.
//! * **Gauss-Seidel**: sweeps over the patches in index order, each
//!   gathering from the newest values.
//!
//! Both run in a fixed order on one thread, so they are deterministic,
//! and both stop at the same measure: the residual
//! `max_i |E_i + rho_i sum_j F_ij B_j - B_i| / max_i B_i` (largest
//! channel) below the tolerance. Progressive refinement checks it after
//! every `N` shots (one check costs as much as `N` shots).

use glam::DVec3;
use serde::Serialize;

pub use crate::core::radiosity::Solver;

use super::form_factor::FormFactors;
use crate::core::math::{Color, max_component};

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SolveReport {
    /// Shots (progressive refinement) or sweeps (Gauss-Seidel).
    pub iterations: u64,
    /// The final residual, relative to the largest radiosity.
    pub residual: f64,
    /// True when the residual reached the tolerance.
    pub converged: bool,
}

/// The system to solve: form factors, reflectances, emitted exitances
/// and patch areas.
pub struct System<'a> {
    /// Form factors.
    pub ff: &'a FormFactors,
    /// Diffuse reflectance of each patch.
    pub rho: &'a [Color],
    /// Emitted exitance of each patch.
    pub e: &'a [Color],
    /// Area of each patch.
    pub area: &'a [f32],
}

impl System<'_> {
    /// `sum_j F_ij B_j` in f64.
    #[inline]
    fn gather(&self, i: usize, b: &[Color]) -> [f64; 3] {
        let mut s = [0.0f64; 3];
        for (j, f) in self.ff.row(i) {
            let bj = b[j];
            s[0] += f as f64 * bj.x as f64;
            s[1] += f as f64 * bj.y as f64;
            s[2] += f as f64 * bj.z as f64;
        }
        s
    }

    /// The residual of `b`, relative to its largest channel.
    pub fn residual(&self, b: &[Color]) -> f64 {
        let mut worst = 0.0f64;
        let mut scale = 0.0f64;
        for i in 0..b.len() {
            let g = self.gather(i, b);
            let (rho, e) = (self.rho[i], self.e[i]);
            let r = [
                e.x as f64 + rho.x as f64 * g[0] - b[i].x as f64,
                e.y as f64 + rho.y as f64 * g[1] - b[i].y as f64,
                e.z as f64 + rho.z as f64 * g[2] - b[i].z as f64,
            ];
            worst = worst.max(r[0].abs().max(r[1].abs()).max(r[2].abs()));
            scale = scale.max(max_component(b[i]) as f64);
        }
        if scale > 0.0 { worst / scale } else { worst }
    }

    /// Gauss-Seidel sweeps until the residual is below `tolerance` or
    /// `max_sweeps` have run; starts from `B = E`.
    pub fn gauss_seidel(&self, tolerance: f64, max_sweeps: u64) -> (Vec<Color>, SolveReport) {
        let mut b: Vec<Color> = self.e.to_vec();
        let mut report = SolveReport::default();
        loop {
            report.residual = self.residual(&b);
            if report.residual < tolerance {
                report.converged = true;
                break;
            }
            if report.iterations >= max_sweeps {
                break;
            }
            for i in 0..b.len() {
                let g = self.gather(i, &b);
                let (rho, e) = (self.rho[i], self.e[i]);
                b[i] = Color::new(
                    (e.x as f64 + rho.x as f64 * g[0]) as f32,
                    (e.y as f64 + rho.y as f64 * g[1]) as f32,
                    (e.z as f64 + rho.z as f64 * g[2]) as f32,
                );
            }
            report.iterations += 1;
        }
        (b, report)
    }

    /// Progressive refinement until the residual is below `tolerance` or
    /// `max_shots` shots; starts with every patch's emission unshot.
    pub fn progressive(&self, tolerance: f64, max_shots: u64) -> (Vec<Color>, SolveReport) {
        let n = self.e.len();
        // Sums of many small shots: kept in f64.
        let mut b: Vec<DVec3> = self.e.iter().map(|c| c.as_dvec3()).collect();
        let mut unshot: Vec<DVec3> = b.clone();
        let out = |b: &[DVec3]| -> Vec<Color> { b.iter().map(|c| c.as_vec3()).collect() };
        let mut report = SolveReport::default();
        let check_every = n.max(1) as u64;
        loop {
            if report.iterations % check_every == 0 {
                report.residual = self.residual(&out(&b));
                if report.residual < tolerance {
                    report.converged = true;
                    break;
                }
            }
            if report.iterations >= max_shots {
                report.residual = self.residual(&out(&b));
                break;
            }
            // The patch with the most unshot power.
            let mut best = None;
            let mut most = 0.0f64;
            for i in 0..n {
                let u = unshot[i];
                let p = self.area[i] as f64 * (u.x + u.y + u.z);
                if p > most {
                    most = p;
                    best = Some(i);
                }
            }
            let Some(i) = best else {
                // Nothing left to shoot: the solution is exact.
                report.residual = self.residual(&out(&b));
                report.converged = report.residual < tolerance;
                break;
            };
            let shot = unshot[i];
            unshot[i] = DVec3::ZERO;
            let ai = self.area[i] as f64;
            for (j, f) in self.ff.row(i) {
                // F_ji = A_i F_ij / A_j.
                let d = self.rho[j].as_dvec3() * shot * (f as f64 * ai / self.area[j] as f64);
                b[j] += d;
                unshot[j] += d;
            }
            report.iterations += 1;
        }
        (out(&b), report)
    }

    /// Solves `(I - rho F) B = E` directly (Gaussian elimination with
    /// partial pivoting, in f64), per channel: the reference the
    /// iterative solvers are checked against. Cost `O(N^3)`: for small
    /// systems only.
    pub fn dense(&self) -> Vec<Color> {
        let n = self.e.len();
        let mut out = vec![Color::ZERO; n];
        for c in 0..3 {
            let mut m = vec![0.0f64; n * (n + 1)];
            for i in 0..n {
                let row = &mut m[i * (n + 1)..(i + 1) * (n + 1)];
                row[i] = 1.0;
                for (j, f) in self.ff.row(i) {
                    row[j] -= self.rho[i][c] as f64 * f as f64;
                }
                row[n] = self.e[i][c] as f64;
            }
            for k in 0..n {
                let p = (k..n)
                    .max_by(|&a, &b| {
                        m[a * (n + 1) + k]
                            .abs()
                            .total_cmp(&m[b * (n + 1) + k].abs())
                    })
                    .unwrap_or(k);
                if p != k {
                    for col in 0..=n {
                        m.swap(k * (n + 1) + col, p * (n + 1) + col);
                    }
                }
                let pivot = m[k * (n + 1) + k];
                for r in k + 1..n {
                    let factor = m[r * (n + 1) + k] / pivot;
                    if factor != 0.0 {
                        for col in k..=n {
                            m[r * (n + 1) + col] -= factor * m[k * (n + 1) + col];
                        }
                    }
                }
            }
            let mut x = vec![0.0f64; n];
            for k in (0..n).rev() {
                let mut s = m[k * (n + 1) + n];
                for col in k + 1..n {
                    s -= m[k * (n + 1) + col] * x[col];
                }
                x[k] = s / m[k * (n + 1) + k];
                out[k][c] = x[k] as f32;
            }
        }
        out
    }
}
