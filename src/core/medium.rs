//! Homogeneous participating media: coefficients, the Henyey-Greenstein
//! phase function, and the conversions from the scene format's parameters.
//!
//! A medium has an absorption coefficient `sigma_a`, a scattering
//! coefficient `sigma_s` (both per RGB channel, in inverse scene units)
//! and a Henyey-Greenstein asymmetry `g` in `(-1, 1)`. Its extinction is
//! `sigma_t = sigma_a + sigma_s` and its single-scattering albedo
//! `sigma_s / sigma_t`. The kernels that move light through media are in
//! `transport::volume`.
//!
//! # Artist parameters
//! A medium may instead be given by a single-scattering `albedo` (per
//! channel, in `[0, 1]`) and a `mean_free_path` `l` (per channel, positive;
//! the mean distance between interactions): `sigma_t = 1 / l`,
//! `sigma_s = albedo sigma_t`, `sigma_a = (1 - albedo) sigma_t`.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use crate::core::math::{Color, orthonormal_basis};
use crate::core::optics::beer_lambert;

/// A homogeneous medium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Medium {
    /// Absorption coefficient per channel (inverse scene units).
    pub sigma_a: Color,
    /// Scattering coefficient per channel (inverse scene units).
    pub sigma_s: Color,
    /// Henyey-Greenstein asymmetry: 0 isotropic, towards 1 forward,
    /// towards -1 backward scattering.
    pub g: f32,
}

impl Medium {
    /// A medium that only absorbs (Beer-Lambert), with coefficient `sigma_a`.
    pub const fn absorbing(sigma_a: Color) -> Self {
        Self {
            sigma_a,
            sigma_s: Color::ZERO,
            g: 0.0,
        }
    }

    /// Extinction `sigma_a + sigma_s`.
    #[inline]
    pub fn sigma_t(&self) -> Color {
        self.sigma_a + self.sigma_s
    }

    /// True when the medium scatters light in some channel.
    #[inline]
    pub fn scatters(&self) -> bool {
        self.sigma_s.max_element() > 0.0
    }

    /// True when the medium changes light at all.
    #[inline]
    pub fn is_clear(&self) -> bool {
        self.sigma_a.max_element() <= 0.0 && self.sigma_s.max_element() <= 0.0
    }

    /// Transmittance `exp(-sigma_t d)` over a distance `d` (which may be
    /// infinite: then zero in every channel that attenuates, one in the
    /// others).
    #[inline]
    pub fn transmittance(&self, distance: f32) -> Color {
        beer_lambert(self.sigma_t(), distance)
    }

    /// The medium of the physical parameters, checked: coefficients finite
    /// and non-negative, `|g| < 1`. The error is to be prefixed by the
    /// owner's name.
    pub fn checked(sigma_a: Color, sigma_s: Color, g: f32) -> Result<Self, String> {
        let bad = |c: Color| !(c.min_element() >= 0.0) || !c.is_finite();
        if bad(sigma_a) {
            return Err(format!(
                "absorption coefficient (sigma_a) must be finite and non-negative in every channel, got [{}, {}, {}]",
                sigma_a.x, sigma_a.y, sigma_a.z
            ));
        }
        if bad(sigma_s) {
            return Err(format!(
                "scattering coefficient (sigma_s) must be finite and non-negative in every channel, got [{}, {}, {}]",
                sigma_s.x, sigma_s.y, sigma_s.z
            ));
        }
        if !(g.abs() < 1.0) {
            return Err(format!(
                "phase asymmetry g must lie strictly between -1 and 1, got {g}"
            ));
        }
        Ok(Self {
            sigma_a,
            sigma_s,
            g,
        })
    }

    /// The medium of the artist's parameters (see the module notes):
    /// single-scattering `albedo` in `[0, 1]` and `mean_free_path` positive
    /// and finite, per channel.
    pub fn from_albedo(albedo: Color, mean_free_path: Color, g: f32) -> Result<Self, String> {
        if !(albedo.min_element() >= 0.0 && albedo.max_element() <= 1.0) {
            return Err(format!(
                "albedo must lie in [0, 1] per channel, got [{}, {}, {}]",
                albedo.x, albedo.y, albedo.z
            ));
        }
        let l = mean_free_path;
        if !(l.min_element() > 0.0) || !l.is_finite() {
            return Err(format!(
                "mean free path must be positive and finite per channel, got [{}, {}, {}]",
                l.x, l.y, l.z
            ));
        }
        let sigma_t = Color::ONE / l;
        Self::checked((Color::ONE - albedo) * sigma_t, albedo * sigma_t, g)
    }
}

/// Gauss-Legendre nodes and weights on `[0, 1]` (`N` points, by Newton's
/// method on the Legendre polynomial).
fn gauss_legendre_unit<const N: usize>() -> ([f64; N], [f64; N]) {
    let mut x = [0.0; N];
    let mut w = [0.0; N];
    for i in 0..N {
        // Initial guess (Tricomi), then Newton on P_N.
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (N as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0f64, z);
            for k in 2..=N {
                let k = k as f64;
                let p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            dp = N as f64 * (z * p1 - p0) / (z * z - 1.0);
            let dz = p1 / dp;
            z -= dz;
            if dz.abs() < 1e-15 {
                break;
            }
        }
        x[i] = 0.5 * (1.0 - z);
        w[i] = 1.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

/// Nodes of the H-function's quadrature (Gauss-Legendre on `[0, 1]`).
const H_NODES: usize = 48;

/// Chandrasekhar's H-function of isotropic scattering with
/// single-scattering albedo `omega` at the quadrature nodes, from its
/// integral equation in the form `1/H(mu) = sqrt(1 - omega) + (omega/2)
/// int_0^1 mu' H(mu') / (mu + mu') dmu'`, iterated on 48 Gauss-Legendre
/// nodes until it changes by less than 1e-13 or for 2000 rounds. The
/// iteration converges for `omega < 1` (slowly near 1: at 0.99 it stops at
/// the round limit, within about 1e-7) and not at `omega = 1`, which
/// callers never ask for (colours are below 1). Returns the nodes, their
/// weights and H at them.
fn h_at_nodes(omega: f64) -> ([f64; H_NODES], [f64; H_NODES], [f64; H_NODES]) {
    const N: usize = H_NODES;
    let (x, w) = gauss_legendre_unit::<N>();
    let root = (1.0 - omega).max(0.0).sqrt();
    let mut h = [1.0f64; N];
    let integral =
        |h: &[f64; N], mu: f64| -> f64 { (0..N).map(|j| w[j] * x[j] * h[j] / (mu + x[j])).sum() };
    for _ in 0..2000 {
        let mut next = [0.0; N];
        let mut change = 0.0f64;
        for i in 0..N {
            next[i] = 1.0 / (root + 0.5 * omega * integral(&h, x[i]));
            change = change.max((next[i] - h[i]).abs());
        }
        h = next;
        if change < 1e-13 {
            break;
        }
    }
    (x, w, h)
}

/// Chandrasekhar's H-function of isotropic scattering with
/// single-scattering albedo `omega` at direction cosine `mu`: the integral
/// equation solved on 48 Gauss-Legendre nodes of `[0, 1]`, then evaluated at `mu`
/// by the equation itself (Nystrom interpolation).
pub fn chandrasekhar_h(omega: f64, mu: f64) -> f64 {
    let (x, w, h) = h_at_nodes(omega);
    let root = (1.0 - omega).max(0.0).sqrt();
    let integral: f64 = (0..H_NODES).map(|j| w[j] * x[j] * h[j] / (mu + x[j])).sum();
    1.0 / (root + 0.5 * omega * integral)
}

/// The radiance that a semi-infinite, index-matched medium of isotropic
/// scattering and single-scattering albedo `omega` sends back along its
/// normal under a uniform sky of radiance 1: `1 - H(1) sqrt(1 - omega)`
/// (Chandrasekhar).
pub fn slab_normal_radiance(omega: f64) -> f64 {
    1.0 - chandrasekhar_h(omega, 1.0) * (1.0 - omega).max(0.0).sqrt()
}

/// The diffuse (bihemispherical) albedo of a semi-infinite medium of
/// isotropic scattering and single-scattering albedo `omega` behind an
/// index-matched boundary: the fraction of light entering it with
/// cosine-distributed directions that comes back out,
/// `1 - 2 sqrt(1 - omega) int_0^1 H(mu) mu dmu` (the plane albedo
/// `1 - H(mu) sqrt(1 - omega)` of a beam entering at cosine `mu`,
/// Chandrasekhar, averaged with the cosine weight `2 mu`). The integral
/// is the Gauss-Legendre sum over the H-function's own nodes.
pub fn slab_diffuse_albedo(omega: f64) -> f64 {
    let (x, w, h) = h_at_nodes(omega);
    let moment: f64 = (0..H_NODES).map(|j| w[j] * x[j] * h[j]).sum();
    1.0 - 2.0 * (1.0 - omega).max(0.0).sqrt() * moment
}

/// The single-scattering albedo whose semi-infinite slab has the diffuse
/// albedo `colour` (in `[0, 1)`): [`slab_diffuse_albedo`], which rises
/// monotonically from 0 to 1, inverted in the variable `s = sqrt(1 -
/// omega)`, in which it is nearly linear (`1 - c s` near `s = 0`, where
/// `omega` approaches 1 and each H-function solve is slowest), by the
/// Illinois variant of regula falsi: the root stays bracketed, and a side
/// that is kept twice in a row has its value halved, so the bracket
/// shrinks from both sides. It ends when the bracket is narrower than
/// 1e-13 in `s`, the value is zero, or after 60 steps. The ends need no
/// solve: `s = 0` (`omega = 1`) gives albedo 1 and `s = 1` gives 0.
///
/// Until stop 38 this was 40 halvings of `omega`, one H-function solve
/// each; the regula falsi takes 8 to 11 solves for most colours (at most
/// 27 of the 206 the unit test tries) and gives the same `f32` albedo on
/// all of them.
pub fn albedo_for_diffuse_albedo(colour: f64) -> f64 {
    if colour <= 0.0 {
        return 0.0;
    }
    // g(s) = albedo(1 - s^2) - colour, decreasing from 1 - colour to
    // -colour.
    let g = |s: f64| slab_diffuse_albedo(1.0 - s * s) - colour;
    let (mut lo, mut g_lo) = (0.0f64, 1.0 - colour);
    let (mut hi, mut g_hi) = (1.0f64, -colour);
    let mut kept = 0i32; // +1: `lo` kept in a row, -1: `hi`
    for _ in 0..60 {
        if hi - lo < 1e-13 {
            break;
        }
        let mut s = hi - g_hi * (hi - lo) / (g_hi - g_lo);
        if !(s > lo && s < hi) {
            s = 0.5 * (lo + hi);
        }
        let v = g(s);
        if v == 0.0 {
            return 1.0 - s * s;
        }
        if v > 0.0 {
            lo = s;
            g_lo = v;
            if kept == -1 {
                g_hi *= 0.5;
            }
            kept = -1;
        } else {
            hi = s;
            g_hi = v;
            if kept == 1 {
                g_lo *= 0.5;
            }
            kept = 1;
        }
    }
    let s = 0.5 * (lo + hi);
    1.0 - s * s
}

impl Medium {
    /// The subsurface medium of a surface colour and a scattering radius
    /// (per channel): isotropic scattering with mean free path `radius`
    /// and the single-scattering albedo whose semi-infinite slab has the
    /// diffuse albedo `colour` ([`albedo_for_diffuse_albedo`]). Behind
    /// the diffuse boundary of a subsurface material (light enters with
    /// cosine-distributed directions and leaves through a Lambertian
    /// transmission, see `transport::volume::diffuse_crossing`), a large
    /// flat slab of it is then a Lambertian reflector of albedo `colour`.
    pub fn subsurface(colour: Color, radius: Color) -> Result<Self, String> {
        if !(colour.min_element() >= 0.0 && colour.max_element() < 1.0) {
            return Err(format!(
                "subsurface colour must lie in [0, 1) per channel, got [{}, {}, {}]",
                colour.x, colour.y, colour.z
            ));
        }
        // The three channels' inversions (each up to 40 solves of the
        // H-function, about 40 ms) run on the worker threads: the same
        // numbers, sooner.
        let channels: Vec<f32> = [colour.x, colour.y, colour.z]
            .par_iter()
            .map(|&c| albedo_for_diffuse_albedo(c as f64) as f32)
            .collect();
        let albedo = Color::new(channels[0], channels[1], channels[2]);
        Self::from_albedo(albedo, radius, 0.0)
            .map_err(|e| e.replace("mean free path", "subsurface radius"))
    }
}

/// The Henyey-Greenstein phase function `(1 - g^2) / (4 pi (1 + g^2 - 2 g
/// cos)^(3/2))` at the cosine `cos` between the propagation directions
/// before and after scattering (it integrates to one over the sphere).
#[inline]
pub fn henyey_greenstein(cos: f32, g: f32) -> f32 {
    // |g| below 1e-3 is isotropic, as [`sample_henyey_greenstein`] draws it
    // (its inverse is unstable there): density and sampling stay one pair.
    let g = if g.abs() < 1e-3 { 0.0 } else { g };
    let denom = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
}

/// A direction drawn from the Henyey-Greenstein lobe around the
/// propagation direction `forward` (unit), by inverting its cumulative
/// distribution in the cosine (uniform for |g| < 1e-3); its density is
/// `henyey_greenstein(forward . wi, g)`.
#[inline]
pub fn sample_henyey_greenstein(forward: Vec3A, g: f32, u: Vec2) -> Vec3A {
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u.x
    } else {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let (t, b) = orthonormal_basis(forward);
    (t * (sin * phi.cos()) + b * (sin * phi.sin()) + forward * cos).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phase function integrates to one, and its mean cosine is g
    /// (midpoint rule over the cosine, 20000 steps: error far below 1e-3).
    #[test]
    fn henyey_greenstein_is_normalised_with_mean_cosine_g() {
        for g in [-0.9, -0.3, 0.0, 0.5, 0.95] {
            let n = 20_000;
            let (mut total, mut mean) = (0.0f64, 0.0f64);
            for i in 0..n {
                let c = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let p = henyey_greenstein(c as f32, g) as f64 * 2.0 * std::f64::consts::PI * 2.0
                    / n as f64;
                total += p;
                mean += p * c;
            }
            assert!((total - 1.0).abs() < 2e-3, "g {g}: integral {total}");
            assert!((mean - g as f64).abs() < 2e-3, "g {g}: mean cosine {mean}");
        }
    }

    /// Sampled directions have mean cosine g about the forward axis
    /// (200000 samples; the cosine's standard deviation is below 1, so the
    /// standard error is below 2.3e-3: 5 sigma is 0.012).
    #[test]
    fn sampling_has_mean_cosine_g() {
        let f = Vec3A::new(0.0, 0.6, 0.8);
        for g in [-0.7, 0.0, 0.4, 0.9] {
            let n = 200_000;
            let mut s = 0.0f64;
            for i in 0..n {
                let u = Vec2::new(
                    (i as f32 + 0.5) / n as f32,
                    ((i as u64 * 2654435769) % n as u64) as f32 / n as f32,
                );
                s += sample_henyey_greenstein(f, g, u).dot(f) as f64;
            }
            assert!(
                (s / n as f64 - g as f64).abs() < 0.012,
                "g {g}: {}",
                s / n as f64
            );
        }
    }

    /// The H-function against Chandrasekhar's tabulated results: the
    /// radiance of the semi-infinite slab seen along its normal, and the
    /// inversion back to the albedo.
    #[test]
    fn slab_radiance_matches_chandrasekhar_and_inverts() {
        for (omega, r) in [(0.8, 0.285255), (0.9, 0.414947), (0.99, 0.752721)] {
            let got = slab_normal_radiance(omega);
            assert!((got - r).abs() < 2e-6, "omega {omega}: {got} vs {r}");
        }
        for omega in [0.3, 0.8, 0.99] {
            let a = slab_diffuse_albedo(omega);
            let back = albedo_for_diffuse_albedo(a);
            assert!((back - omega).abs() < 1e-6, "{back} vs {omega}");
        }
        // No scattering: nothing comes back.
        assert!(slab_normal_radiance(0.0).abs() < 1e-12);
        let m = Medium::subsurface(Color::new(0.8, 0.5, 0.0), Color::splat(0.5)).unwrap();
        assert_eq!(m.sigma_t(), Color::splat(2.0));
        assert_eq!(m.sigma_s.z, 0.0);
        assert!(Medium::subsurface(Color::ONE, Color::ONE).is_err());
        assert!(Medium::subsurface(Color::splat(0.5), Color::ZERO).is_err());
    }

    /// The regula falsi in `sqrt(1 - omega)` gives the `f32` albedo the
    /// former 40 halvings of `omega` gave, on 200 colours across `(0,
    /// 1)` and the assets' subsurface colours, with far fewer H-function
    /// solves.
    #[test]
    fn albedo_inversion_matches_bisection() {
        let bisection = |colour: f64| {
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if slab_diffuse_albedo(mid) < colour {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        let mut colours: Vec<f64> = (0..200).map(|i| (i as f64 + 0.5) / 200.0).collect();
        colours.extend([0.86, 0.84, 0.80, 0.78, 0.52, 0.40].map(|c: f32| c as f64));
        let mut differ = 0;
        for c in colours {
            let new = albedo_for_diffuse_albedo(c);
            let old = bisection(c);
            assert!((new - old).abs() < 1e-9, "colour {c}: {new} vs {old}");
            differ += (new as f32 != old as f32) as u32;
        }
        assert_eq!(differ, 0);
    }

    /// The H-function's zeroth moment has the closed form `int_0^1 H dmu
    /// = (2 / omega) (1 - sqrt(1 - omega))` (Chandrasekhar): a check of
    /// the quadrature the diffuse albedo sums over.
    #[test]
    fn h_function_zeroth_moment_is_exact() {
        for omega in [0.2, 0.6, 0.9, 0.99] {
            let (_, w, h) = h_at_nodes(omega);
            let moment: f64 = (0..H_NODES).map(|j| w[j] * h[j]).sum();
            let exact = 2.0 / omega * (1.0 - (1.0 - omega).sqrt());
            assert!(
                (moment - exact).abs() < 1e-6,
                "omega {omega}: {moment} vs {exact}"
            );
        }
    }

    /// The diffuse albedo of the semi-infinite slab against a brute-force
    /// random walk: walks enter the half-space `z < 0` at the surface
    /// with cosine-distributed directions, fly exponential distances of
    /// mean 1, scatter isotropically with probability `omega` (else they
    /// are absorbed), and count when they cross `z = 0`. 100000 walks: the
    /// fraction's standard error is at most 1.6e-3; the test allows 4 of
    /// them (6.4e-3).
    #[test]
    fn slab_diffuse_albedo_matches_a_random_walk() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut uniform = move || {
            // splitmix64
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        for omega in [0.5, 0.9, 0.98] {
            let n = 100_000;
            let mut out = 0u32;
            for _ in 0..n {
                // Cosine-distributed entry: cos theta = sqrt(u), downwards.
                let mut mu = -uniform().sqrt();
                let mut z = 0.0f64;
                loop {
                    z += mu * -(1.0 - uniform()).ln();
                    if z >= 0.0 {
                        out += 1;
                        break;
                    }
                    if uniform() >= omega {
                        break;
                    }
                    mu = 1.0 - 2.0 * uniform();
                }
            }
            let got = out as f64 / n as f64;
            let expected = slab_diffuse_albedo(omega);
            assert!(
                (got - expected).abs() < 6.4e-3,
                "omega {omega}: walk {got} vs {expected}"
            );
        }
    }

    #[test]
    fn parameters_are_checked() {
        assert!(Medium::checked(Color::ONE, Color::ONE, 0.5).is_ok());
        assert!(Medium::checked(Color::new(-1.0, 0.0, 0.0), Color::ONE, 0.0).is_err());
        assert!(Medium::checked(Color::ONE, Color::splat(f32::NAN), 0.0).is_err());
        assert!(Medium::checked(Color::ONE, Color::ONE, 1.0).is_err());
        assert!(Medium::checked(Color::ONE, Color::ONE, f32::NAN).is_err());
        let m = Medium::from_albedo(Color::new(0.5, 0.8, 1.0), Color::splat(2.0), 0.0).unwrap();
        assert_eq!(m.sigma_t(), Color::splat(0.5));
        assert_eq!(m.sigma_s, Color::new(0.25, 0.4, 0.5));
        assert!(Medium::from_albedo(Color::splat(1.5), Color::ONE, 0.0).is_err());
        assert!(Medium::from_albedo(Color::ONE, Color::ZERO, 0.0).is_err());
    }
}
