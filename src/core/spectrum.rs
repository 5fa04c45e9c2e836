//! Wavelengths: indices of refraction that depend on them (dispersion) and
//! the conversion of one sampled wavelength back to linear sRGB.
//!
//! # Spectral path transport
//! A scene with a dispersive material is path traced with one wavelength
//! per path ([`sample_wavelength`]), drawn uniformly in
//! [[`LAMBDA_MIN`], [`LAMBDA_MAX`]] nm. Reflectances and emission stay
//! RGB, channel by channel: the path's RGB radiance is multiplied at the
//! film by the RGB response of its wavelength, `w(lambda) =
//! M xyz(lambda) / N`, where `xyz` are the CIE 1931 2-degree colour
//! matching functions (the analytic multi-lobe Gaussian fit of Wyman,
//! Sloan and Shirley 2013, written out in [`cie_xyz`]), `M` the XYZ to
//! linear sRGB matrix and `N` the per-channel mean of `M xyz` over the
//! range, so that `E[w] = (1, 1, 1)`: an equal-energy spectrum is white.
//! Anything that does not depend on wavelength therefore renders, in
//! expectation, exactly the RGB image; only a dispersive interface (whose
//! index is [`Dispersion::ior`] at the path's wavelength) separates the
//! colours. Pure spectral colours lie outside the sRGB gamut, so single
//! samples can have a negative channel; pixel means of ordinary scenes
//! converge to the RGB image.

use std::sync::OnceLock;

use crate::core::math::Color;

/// Shortest wavelength sampled (nm).
pub const LAMBDA_MIN: f32 = 380.0;
/// Longest wavelength sampled (nm).
pub const LAMBDA_MAX: f32 = 780.0;

/// Sellmeier coefficients: `n^2(lambda) = 1 + sum_i B_i lambda^2 /
/// (lambda^2 - C_i)` with `lambda` in micrometres and `C_i` in
/// micrometres squared.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sellmeier {
    /// `B1, B2, B3`.
    pub b: [f64; 3],
    /// `C1, C2, C3` (um^2).
    pub c: [f64; 3],
}

impl Sellmeier {
    /// Schott N-BK7 (borosilicate crown), from Schott's data sheet.
    pub const N_BK7: Sellmeier = Sellmeier {
        b: [1.039_612_12, 0.231_792_344, 1.010_469_45],
        c: [0.006_000_698_67, 0.020_017_914_4, 103.560_653],
    };
    /// Fused silica (Malitson 1965).
    pub const FUSED_SILICA: Sellmeier = Sellmeier {
        b: [0.696_166_3, 0.407_942_6, 0.897_479_4],
        c: [0.004_679_148_26, 0.013_512_063_1, 97.934_002_5],
    };
    /// Schott N-SF11 (dense flint), from Schott's data sheet.
    pub const N_SF11: Sellmeier = Sellmeier {
        b: [1.737_596_95, 0.313_747_346, 1.898_781_01],
        c: [0.013_188_707, 0.062_306_814_2, 155.236_29],
    };

    /// The named presets, by the names the scene format accepts.
    pub const PRESETS: [(&'static str, Sellmeier); 3] = [
        ("N-BK7", Sellmeier::N_BK7),
        ("fused-silica", Sellmeier::FUSED_SILICA),
        ("N-SF11", Sellmeier::N_SF11),
    ];

    /// The index at `lambda_nm` nanometres, in f64.
    pub fn ior_f64(&self, lambda_nm: f64) -> f64 {
        let l2 = (lambda_nm * 1e-3).powi(2);
        let n2 = 1.0
            + (0..3)
                .map(|i| self.b[i] * l2 / (l2 - self.c[i]))
                .sum::<f64>();
        n2.sqrt()
    }

    /// Checks the coefficients: finite, and a real index above 1 over the
    /// sampled range. The error is to be prefixed by the owner's name.
    pub fn check(&self) -> Result<Self, String> {
        let finite = self.b.iter().chain(&self.c).all(|v| v.is_finite());
        let ok = finite
            && (0..=40).all(|i| {
                let n = self.ior_f64(LAMBDA_MIN as f64 + 10.0 * i as f64);
                n.is_finite() && n >= 1.0
            });
        if !ok {
            return Err(format!(
                "Sellmeier coefficients B = {:?}, C = {:?} do not give a real index of at least 1 over {LAMBDA_MIN}-{LAMBDA_MAX} nm",
                self.b, self.c
            ));
        }
        Ok(*self)
    }
}

/// Fraunhofer d line (helium, nm): where `n_d` is given.
pub const LAMBDA_D: f64 = 587.56;
/// Fraunhofer F line (hydrogen, nm).
pub const LAMBDA_F: f64 = 486.13;
/// Fraunhofer C line (hydrogen, nm).
pub const LAMBDA_C: f64 = 656.27;

/// How a material's index of refraction depends on wavelength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dispersion {
    /// Sellmeier's equation.
    Sellmeier(Sellmeier),
    /// Cauchy's `n = a + b / lambda^2` (lambda in nm) fitted to an index
    /// `n_d` at the d line and an Abbe number `V = (n_d - 1) / (n_F -
    /// n_C)`, as `KHR_materials_dispersion` defines it.
    Cauchy {
        /// `a`.
        a: f64,
        /// `b` (nm^2).
        b: f64,
    },
}

impl Dispersion {
    /// Cauchy's law through `n_d` with Abbe number `abbe` (> 0). The error
    /// is to be prefixed by the owner's name.
    pub fn from_abbe(n_d: f32, abbe: f32) -> Result<Self, String> {
        if !(abbe > 0.0 && abbe.is_finite()) {
            return Err(format!("Abbe number must be positive, got {abbe}"));
        }
        let n_d = n_d as f64;
        let b = (n_d - 1.0) / (abbe as f64 * (LAMBDA_F.powi(-2) - LAMBDA_C.powi(-2)));
        Ok(Dispersion::Cauchy {
            a: n_d - b / (LAMBDA_D * LAMBDA_D),
            b,
        })
    }

    /// The index at `lambda_nm` nanometres.
    #[inline]
    pub fn ior(&self, lambda_nm: f32) -> f32 {
        match self {
            Dispersion::Sellmeier(s) => s.ior_f64(lambda_nm as f64) as f32,
            Dispersion::Cauchy { a, b } => (a + b / (lambda_nm as f64).powi(2)) as f32,
        }
    }
}

/// One lobe of the Wyman-Sloan-Shirley fit: a Gaussian of peak 1 at `mu`
/// with width `s1` below it and `s2` above.
#[inline]
fn lobe(lambda: f64, mu: f64, s1: f64, s2: f64) -> f64 {
    let t = (lambda - mu) / if lambda < mu { s1 } else { s2 };
    (-0.5 * t * t).exp()
}

/// The CIE 1931 2-degree colour matching functions at `lambda` nm, by the
/// multi-lobe fit of Wyman, Sloan and Shirley ("Simple Analytic
/// Approximations to the CIE XYZ Color Matching Functions", JCGT 2013).
pub fn cie_xyz(lambda: f64) -> [f64; 3] {
    let x = 1.056 * lobe(lambda, 599.8, 37.9, 31.0) + 0.362 * lobe(lambda, 442.0, 16.0, 26.7)
        - 0.065 * lobe(lambda, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(lambda, 568.8, 46.9, 40.5) + 0.286 * lobe(lambda, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(lambda, 437.0, 11.8, 36.0) + 0.681 * lobe(lambda, 459.0, 26.0, 13.8);
    [x, y, z]
}

/// Linear sRGB (D65) of CIE XYZ.
fn xyz_to_srgb([x, y, z]: [f64; 3]) -> [f64; 3] {
    [
        3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z,
        -0.969_266_0 * x + 1.876_010_8 * y + 0.041_556_0 * z,
        0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z,
    ]
}

/// Per-channel mean of `M xyz(lambda)` over the sampled range (midpoint
/// rule, 0.01 nm steps, f64): the normalisation that makes an
/// equal-energy spectrum white.
fn channel_means() -> &'static [f64; 3] {
    static MEANS: OnceLock<[f64; 3]> = OnceLock::new();
    MEANS.get_or_init(|| {
        let n = 40_000;
        let (lo, hi) = (LAMBDA_MIN as f64, LAMBDA_MAX as f64);
        let step = (hi - lo) / n as f64;
        let mut sum = [0.0f64; 3];
        for i in 0..n {
            let rgb = xyz_to_srgb(cie_xyz(lo + (i as f64 + 0.5) * step));
            for c in 0..3 {
                sum[c] += rgb[c];
            }
        }
        sum.map(|s| s / n as f64)
    })
}

/// The RGB weight of wavelength `lambda` nm drawn uniformly in the
/// sampled range: `M xyz(lambda) / N` (see the module documentation);
/// its mean over the range is `(1, 1, 1)`.
pub fn wavelength_weight(lambda: f32) -> Color {
    let rgb = xyz_to_srgb(cie_xyz(lambda as f64));
    let n = channel_means();
    Color::new(
        (rgb[0] / n[0]) as f32,
        (rgb[1] / n[1]) as f32,
        (rgb[2] / n[2]) as f32,
    )
}

/// The wavelength (nm) of uniform number `u` in `[0, 1)`.
#[inline]
pub fn sample_wavelength(u: f32) -> f32 {
    LAMBDA_MIN + (LAMBDA_MAX - LAMBDA_MIN) * u
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Schott's catalogue indices of N-BK7 at the F, d and C lines.
    #[test]
    fn bk7_sellmeier_matches_the_catalogue() {
        let s = Sellmeier::N_BK7;
        for (lambda, n) in [
            (LAMBDA_F, 1.522_376),
            (LAMBDA_D, 1.516_800),
            (LAMBDA_C, 1.514_322),
        ] {
            let got = s.ior_f64(lambda);
            assert!((got - n).abs() < 1e-6, "{lambda} nm: {got} vs {n}");
        }
        assert!(s.check().is_ok());
        assert!(
            Sellmeier {
                b: [f64::NAN; 3],
                c: [0.0; 3]
            }
            .check()
            .is_err()
        );
        assert!(
            Sellmeier {
                b: [-2.0, 0.0, 0.0],
                c: [0.0; 3]
            }
            .check()
            .is_err()
        );
    }

    /// A 60-degree N-BK7 prism at minimum deviation, one ray per Fraunhofer
    /// line, traced through both faces with Prism's own [`refract`]
    /// (f32): the ray leaves deviated by `2 asin(n sin 30) - 60` for the
    /// catalogue indices, 39.1381, 38.6467 and 38.4291 degrees, within
    /// 1e-4 degrees (the catalogue's 1e-6 rounding of n moves the
    /// deviation by up to 0.8e-4 degrees; f32 tracing by about 1e-5).
    #[test]
    fn bk7_prism_at_minimum_deviation_splits_the_lines() {
        use crate::core::optics::refract;
        use glam::Vec3A;
        let half = 30f64.to_radians();
        // Apex up; outward normals of the left and right faces.
        let n1 = Vec3A::new(-half.cos() as f32, half.sin() as f32, 0.0);
        let n2 = Vec3A::new(half.cos() as f32, half.sin() as f32, 0.0);
        let d = Dispersion::Sellmeier(Sellmeier::N_BK7);
        for (lambda, deviation) in [
            (LAMBDA_F, 39.1381),
            (LAMBDA_D, 38.6467),
            (LAMBDA_C, 38.4291),
        ] {
            let n = Sellmeier::N_BK7.ior_f64(lambda);
            // At minimum deviation the ray inside runs parallel to the
            // base: it meets the first face at asin(n sin 30) from its
            // inward normal, turned from it towards the apex side.
            let incidence = (n * half.sin()).asin();
            let angle = -half + incidence;
            let d_in = Vec3A::new(angle.cos() as f32, angle.sin() as f32, 0.0);
            let ior = d.ior(lambda as f32);
            let inside = refract(d_in, n1, 1.0 / ior).unwrap();
            let out = refract(inside, -n2, ior).unwrap();
            let cos = (d_in.dot(out) as f64 / (out.length() as f64)).clamp(-1.0, 1.0);
            let got = cos.acos().to_degrees();
            assert!(
                (got - deviation).abs() < 1e-4,
                "{lambda} nm: {got} degrees, expected {deviation}"
            );
            // Minimum deviation is symmetric: the ray inside is horizontal.
            assert!(inside.y.abs() < 1e-6, "{inside}");
        }
    }

    /// Cauchy through `n_d` with Abbe number `V` gives back `n_d` and `V`.
    #[test]
    fn abbe_number_round_trips() {
        let d = Dispersion::from_abbe(1.5168, 64.17).unwrap();
        let n = |l: f64| d.ior(l as f32) as f64;
        assert!((n(LAMBDA_D) - 1.5168).abs() < 1e-6);
        let v = (n(LAMBDA_D) - 1.0) / (n(LAMBDA_F) - n(LAMBDA_C));
        assert!((v - 64.17).abs() < 0.05, "{v}");
        assert!(Dispersion::from_abbe(1.5, 0.0).is_err());
        assert!(Dispersion::from_abbe(1.5, f32::NAN).is_err());
    }

    /// The fit's luminance peak (555 nm region) and the weights' mean of 1:
    /// a midpoint sum over 4000 wavelengths (0.1 nm) within 1e-4 of 1.
    #[test]
    fn wavelength_weights_average_to_white() {
        let y = |l: f64| cie_xyz(l)[1];
        assert!(y(555.0) > 0.99 && y(555.0) < 1.01, "{}", y(555.0));
        let n = 4000;
        let mut sum = Color::ZERO;
        for i in 0..n {
            sum += wavelength_weight(sample_wavelength((i as f32 + 0.5) / n as f32));
        }
        let mean = sum / n as f32;
        assert!((mean - Color::ONE).abs().max_element() < 1e-4, "{mean}");
        // Red at 650 nm, green at 530 nm, blue at 450 nm dominate.
        let w = wavelength_weight;
        assert!(w(650.0).x > w(650.0).y.max(w(650.0).z));
        assert!(w(530.0).y > w(530.0).x.max(w(530.0).z));
        assert!(w(450.0).z > w(450.0).x.max(w(450.0).y));
    }
}
