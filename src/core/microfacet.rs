//! The glTF 2.0 metallic-roughness BRDF (the specification's appendix B)
//! for path transport: a Trowbridge-Reitz (GGX) distribution of normals
//! with `alpha = roughness^2`, the height-correlated Smith
//! masking-shadowing term, Schlick's Fresnel approximation, and the mix of
//! a dielectric (a Lambertian base under a specular layer weighted by
//! `KHR_materials_specular`) with a metal (the specular layer tinted by
//! the base colour). Directions are drawn from the distribution of visible
//! normals (Heitz 2018, "Sampling the GGX Distribution of Visible
//! Normals").
//!
//! All functions work in a local frame given by the unit shading normal
//! `n`: `cos` values are dot products with it.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, max_component, orthonormal_basis};
use crate::core::optics::reflect;

/// Smallest `alpha` kept: a lobe that narrow (roughness below about
/// 0.032) is narrower than any pixel, so a surface whose `alpha` is at
/// this bound is rendered with a perfectly smooth specular layer
/// ([`GltfBrdf::is_smooth`]): Fresnel-weighted reflection about the
/// shading normal, a Dirac lobe that next-event estimation skips.
pub const MIN_ALPHA: f32 = 1e-3;

/// The microfacet lobes of a glTF metallic-roughness surface at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfBrdf {
    /// GGX `alpha = roughness^2`, at least [`MIN_ALPHA`].
    pub alpha: f32,
    /// Weight of the metal: `metallic`.
    pub metallic: f32,
    /// F0 of the metal: the base colour.
    pub metal_f0: Color,
    /// Weight of the dielectric's specular layer: `(1 - metallic) (1 -
    /// transmission)` (transmission's own reflection is the smooth glass
    /// lobe's).
    pub dielectric_weight: f32,
    /// Weighted F0 of the dielectric: `specular * min(F0(ior) *
    /// specularColor, 1)`.
    pub dielectric_f0: Color,
    /// Weighted F90 of the dielectric: `KHR_materials_specular`'s factor.
    pub dielectric_f90: f32,
    /// Lambertian albedo under the layer: `base (1 - metallic) (1 -
    /// transmission)`.
    pub diffuse: Color,
}

/// Schlick's `(1 - cos)^5`.
#[inline]
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// The GGX distribution of normals `D(h) = a^2 / (pi (cos^2 (a^2 - 1) + 1)^2)`
/// at `cos_h = n.h`, with `sin2_h = |n x h|^2` passed separately: the
/// denominator is evaluated as `sin^2 + a^2 cos^2`, which keeps its
/// precision for narrow lobes near their peak (where `1 - cos^2` would
/// cancel).
#[inline]
pub fn ggx_d(alpha: f32, cos_h: f32, sin2_h: f32) -> f32 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = sin2_h + a2 * cos_h * cos_h;
    if t > 0.0 { a2 / (PI * t * t) } else { 0.0 }
}

/// Smith's `Lambda` for GGX at `cos = n.w`, written as the square root
/// that the masking terms share: `sqrt(alpha^2 + (1 - alpha^2) cos^2)`.
#[inline]
fn smith_root(alpha: f32, cos: f32) -> f32 {
    let a2 = alpha * alpha;
    (a2 + (1.0 - a2) * cos * cos).max(0.0).sqrt()
}

/// Smith's masking `G1(w) = 2 cos / (cos + sqrt(alpha^2 + (1-alpha^2) cos^2))`.
#[inline]
pub fn smith_g1(alpha: f32, cos: f32) -> f32 {
    if cos <= 0.0 {
        return 0.0;
    }
    2.0 * cos / (cos + smith_root(alpha, cos))
}

/// The height-correlated visibility term `V = G2 / (4 cos_i cos_o)`:
/// `0.5 / (cos_i sqrt(a^2 + (1-a^2) cos_o^2) + cos_o sqrt(a^2 + (1-a^2) cos_i^2))`.
#[inline]
pub fn visibility(alpha: f32, cos_i: f32, cos_o: f32) -> f32 {
    let d = cos_i * smith_root(alpha, cos_o) + cos_o * smith_root(alpha, cos_i);
    if d > 0.0 { 0.5 / d } else { 0.0 }
}

/// A visible normal for the view direction `wo` (local frame, `z` the
/// normal, `wo.z > 0`), from two uniform numbers: Heitz's method, which
/// stretches the view to the `alpha = 1` configuration, samples the
/// projected hemisphere seen from it, and unstretches the normal.
#[inline]
pub fn sample_visible_normal(alpha: f32, wo: Vec3A, u: Vec2) -> Vec3A {
    let v = Vec3A::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2 > 0.0 {
        Vec3A::new(-v.y, v.x, 0.0) / len2.sqrt()
    } else {
        Vec3A::X
    };
    let t2 = v.cross(t1);
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let (sin_p, cos_p) = phi.sin_cos();
    let p1 = r * cos_p;
    let p2_disk = r * sin_p;
    // Warp the lower half disk so it covers what the view sees of the
    // hemisphere.
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2_disk;
    let p3 = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nh = t1 * p1 + t2 * p2 + v * p3;
    Vec3A::new(alpha * nh.x, alpha * nh.y, nh.z.max(0.0)).normalize()
}

impl GltfBrdf {
    /// True when the specular layers are absent: no metal and a
    /// dielectric layer whose Fresnel is zero at every angle
    /// (`KHR_materials_specular` factor 0), so the BRDF is the Lambertian
    /// base alone. [`GltfBrdf::eval_cos`] and [`GltfBrdf::lobe_weights`]
    /// then skip the microfacet terms, which would be multiplied by zero:
    /// the results are the same bits.
    #[inline]
    pub fn is_lambertian(&self) -> bool {
        self.metallic == 0.0 && self.dielectric_f90 == 0.0 && self.dielectric_f0 == Color::ZERO
    }

    /// True when the specular layers are perfectly smooth (`alpha` at
    /// [`MIN_ALPHA`], roughness below about 0.032): they reflect about the
    /// shading normal only, with the weight [`GltfBrdf::smooth_reflectance`],
    /// and [`GltfBrdf::eval_cos`] holds only the Lambertian base. As a
    /// microfacet lobe that narrow they sent next-event estimation's
    /// shadow rays where the lobe is almost zero and drew their directions
    /// by visible normals, for the same image.
    #[inline]
    pub fn is_smooth(&self) -> bool {
        self.alpha <= MIN_ALPHA
    }

    /// Reflectance of the smooth specular layers seen from `cos_o` (their
    /// Fresnel terms, metal and dielectric weighted): the weight of the
    /// perfect reflection of a smooth surface ([`GltfBrdf::is_smooth`]).
    #[inline]
    pub fn smooth_reflectance(&self, cos_o: f32) -> Color {
        let cos_o = cos_o.max(0.0);
        self.metal_fresnel(cos_o) * self.metallic
            + self.dielectric_fresnel(cos_o) * self.dielectric_weight
    }

    /// Dielectric Fresnel at `cos`, weighted by `KHR_materials_specular`.
    #[inline]
    fn dielectric_fresnel(&self, cos: f32) -> Color {
        let w = schlick_weight(cos);
        self.dielectric_f0 + (Color::splat(self.dielectric_f90) - self.dielectric_f0) * w
    }

    /// Metal Fresnel at `cos`.
    #[inline]
    fn metal_fresnel(&self, cos: f32) -> Color {
        self.metal_f0 + (Color::ONE - self.metal_f0) * schlick_weight(cos)
    }

    /// The BRDF times `n.wi`, for unit `wo` and `wi` and shading normal
    /// `n`: zero unless both are above the surface. Of a smooth surface
    /// ([`GltfBrdf::is_smooth`]) only the Lambertian base under the layer:
    /// its Dirac reflection is not a density.
    pub fn eval_cos(&self, n: Vec3A, wo: Vec3A, wi: Vec3A) -> Color {
        let cos_i = n.dot(wi);
        let cos_o = n.dot(wo);
        if cos_i <= 0.0 || cos_o <= 0.0 {
            return Color::ZERO;
        }
        if self.is_lambertian() {
            return self.diffuse * (1.0 / PI) * cos_i;
        }
        let h = (wo + wi).normalize_or_zero();
        let cos_h = n.dot(h);
        let voh = wo.dot(h).max(0.0);
        let spec = if self.is_smooth() {
            0.0
        } else {
            ggx_d(self.alpha, cos_h, h.cross(n).length_squared())
                * visibility(self.alpha, cos_i, cos_o)
        };
        let fd = self.dielectric_fresnel(voh);
        let mut f =
            self.metal_fresnel(voh) * (self.metallic * spec) + fd * (self.dielectric_weight * spec);
        if self.diffuse != Color::ZERO {
            f += self.diffuse * ((1.0 - max_component(fd)).max(0.0) / PI);
        }
        f * cos_i
    }

    /// Density of [`GltfBrdf::sample_specular`] drawing `wi`:
    /// `G1(wo) D(h) / (4 n.wo)`.
    pub fn specular_pdf(&self, n: Vec3A, wo: Vec3A, wi: Vec3A) -> f32 {
        let cos_o = n.dot(wo);
        if cos_o <= 0.0 || n.dot(wi) <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize_or_zero();
        let cos_h = n.dot(h);
        if cos_h <= 0.0 || wo.dot(h) <= 0.0 {
            return 0.0;
        }
        smith_g1(self.alpha, cos_o) * ggx_d(self.alpha, cos_h, h.cross(n).length_squared())
            / (4.0 * cos_o)
    }

    /// A reflected direction about a visible normal drawn for `wo`;
    /// `None` when `wo` is below the surface or the reflection falls
    /// below it.
    pub fn sample_specular(&self, n: Vec3A, wo: Vec3A, u: Vec2) -> Option<Vec3A> {
        let (t, b) = orthonormal_basis(n);
        let local = Vec3A::new(wo.dot(t), wo.dot(b), wo.dot(n));
        if local.z <= 0.0 {
            return None;
        }
        let m = sample_visible_normal(self.alpha, local, u);
        let h = t * m.x + b * m.y + n * m.z;
        let wi = reflect(-wo, h);
        (n.dot(wi) > 0.0).then_some(wi)
    }

    /// Weights for choosing between the Lambertian base and the
    /// specular layers when sampling, from their reflectance seen from
    /// `cos_o`: `(diffuse, specular)` luminances.
    pub fn lobe_weights(&self, cos_o: f32) -> (f32, f32) {
        if self.is_lambertian() {
            return (crate::core::math::luminance(self.diffuse).max(0.0), 0.0);
        }
        let fd = self.dielectric_fresnel(cos_o.max(0.0));
        let spec = self.metal_fresnel(cos_o.max(0.0)) * self.metallic + fd * self.dielectric_weight;
        let diffuse = self.diffuse * (1.0 - max_component(fd)).max(0.0);
        (
            crate::core::math::luminance(diffuse).max(0.0),
            crate::core::math::luminance(spec).max(0.0),
        )
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    fn metal(alpha: f32) -> GltfBrdf {
        GltfBrdf {
            alpha,
            metallic: 1.0,
            metal_f0: Color::ONE,
            dielectric_weight: 0.0,
            dielectric_f0: Color::ZERO,
            dielectric_f90: 0.0,
            diffuse: Color::ZERO,
        }
    }

    fn dir(cos: f32) -> Vec3A {
        Vec3A::new((1.0 - cos * cos).max(0.0).sqrt(), 0.0, cos)
    }

    /// The directional albedo `int f cos dwi` of a lobe by a midpoint rule
    /// over `(cos theta, phi)` (the integrand is smooth for these alphas
    /// at this resolution).
    pub(crate) fn albedo_quadrature(b: &GltfBrdf, wo: Vec3A, n_theta: usize, n_phi: usize) -> f64 {
        let mut sum = 0.0f64;
        for i in 0..n_theta {
            // Fine near the horizon and at the peak alike: uniform in cos.
            let c = (i as f64 + 0.5) / n_theta as f64;
            let s = (1.0 - c * c).sqrt();
            for j in 0..n_phi {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n_phi as f64;
                let wi = Vec3A::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
                sum += b.eval_cos(Vec3A::Z, wo, wi).x as f64;
            }
        }
        sum * (1.0 / n_theta as f64) * (2.0 * std::f64::consts::PI / n_phi as f64)
    }

    /// The specular BRDF with F = 1 times the cosine, written out in f64
    /// from the specification's formulas, independently of the kernel:
    /// `D = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2)`, `V` height-correlated.
    fn reference_metal_cos(alpha: f64, wo: [f64; 3], wi: [f64; 3]) -> f64 {
        let (co, ci) = (wo[2], wi[2]);
        if co <= 0.0 || ci <= 0.0 {
            return 0.0;
        }
        let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
        let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let nh = h[2] / len;
        let a2 = alpha * alpha;
        let d = a2 / (std::f64::consts::PI * (nh * nh * (a2 - 1.0) + 1.0).powi(2));
        let v = 0.5
            / (ci * (co * co * (1.0 - a2) + a2).sqrt() + co * (ci * ci * (1.0 - a2) + a2).sqrt());
        d * v * ci
    }

    /// Rough metal with F0 = 1: importance-sampled directional albedo
    /// (each sample weighs `f cos / pdf`) equals the single-scattering
    /// energy integrated numerically from the specification's formulas,
    /// which is below 1 and falls with roughness and at grazing angles.
    #[test]
    fn metal_furnace_matches_the_integrated_albedo() {
        for (alpha, cos_o, n_theta) in [(0.25f32, 0.9f32, 2000), (0.5, 0.5, 1000), (1.0, 0.2, 800)]
        {
            let b = metal(alpha);
            let wo = dir(cos_o);
            let wo64 = [wo.x as f64, 0.0, wo.z as f64];
            let n_phi = 720;
            let mut reference = 0.0;
            for i in 0..n_theta {
                let c = (i as f64 + 0.5) / n_theta as f64;
                let s = (1.0 - c * c).sqrt();
                for j in 0..n_phi {
                    let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n_phi as f64;
                    let wi = [s * phi.cos(), s * phi.sin(), c];
                    reference += reference_metal_cos(alpha as f64, wo64, wi);
                }
            }
            reference *= 2.0 * std::f64::consts::PI / (n_theta * n_phi) as f64;
            // The kernel's own BRDF integrates to the same.
            let kernel = albedo_quadrature(&b, wo, n_theta, n_phi);
            assert!((kernel - reference).abs() < 1e-4, "{kernel} vs {reference}");
            let n = 100_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for k in 0..n {
                let mut s = Sampler::new(11, k, 0);
                let u = Vec2::new(s.next_f32(), s.next_f32());
                if let Some(wi) = b.sample_specular(Vec3A::Z, wo, u) {
                    let pdf = b.specular_pdf(Vec3A::Z, wo, wi);
                    let x = (b.eval_cos(Vec3A::Z, wo, wi).x / pdf) as f64;
                    sum += x;
                    sum2 += x * x;
                }
            }
            let mean = sum / n as f64;
            let err = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(
                (mean - reference).abs() < 5.0 * err + 2e-3,
                "alpha {alpha} cos {cos_o}: sampled {mean} +- {err}, integrated {reference}"
            );
            assert!(reference < 1.0 && reference > 0.5, "{reference}");
        }
    }

    /// Chi-square test of the visible-normal sampler against its density
    /// [`GltfBrdf::specular_pdf`], integrated over bins of
    /// `(cos theta, phi)` by a fine midpoint rule; directions below the
    /// horizon form their own bin.
    #[test]
    fn visible_normal_sampling_chi_square() {
        for (alpha, cos_o) in [
            (0.05f32, 0.8f32),
            (0.2, 0.95),
            (0.4, 0.3),
            (0.7, 0.6),
            (1.0, 0.1),
        ] {
            let b = metal(alpha);
            let wo = dir(cos_o);
            let (nc, np) = (16usize, 24usize);
            let bins = nc * np;
            let n = 100_000u32;
            let mut counts = vec![0.0f64; bins + 1];
            for k in 0..n {
                let mut s = Sampler::new(5, k, 0);
                let u = Vec2::new(s.next_f32(), s.next_f32());
                match b.sample_specular(Vec3A::Z, wo, u) {
                    Some(wi) => {
                        let c = ((wi.z * nc as f32) as usize).min(nc - 1);
                        let p = ((wi.y.atan2(wi.x) / (2.0 * PI) + 0.5) * np as f32) as usize;
                        counts[c * np + p.min(np - 1)] += 1.0;
                    }
                    None => counts[bins] += 1.0,
                }
            }
            let sub = 32;
            let mut expected = vec![0.0f64; bins + 1];
            let mut inside = 0.0;
            for c in 0..nc * sub {
                let z = (c as f64 + 0.5) / (nc * sub) as f64;
                let r = (1.0 - z * z).sqrt();
                for p in 0..np * sub {
                    let phi = -std::f64::consts::PI
                        + 2.0 * std::f64::consts::PI * (p as f64 + 0.5) / (np * sub) as f64;
                    let wi = Vec3A::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                    let dw = (1.0 / (nc * sub) as f64)
                        * (2.0 * std::f64::consts::PI / (np * sub) as f64);
                    let m = b.specular_pdf(Vec3A::Z, wo, wi) as f64 * dw;
                    expected[(c / sub) * np + p / sub] += m;
                    inside += m;
                }
            }
            expected[bins] = (1.0 - inside).max(0.0);
            let (mut chi2, mut dof) = (0.0, 0usize);
            let (mut po, mut pe) = (0.0, 0.0);
            for (o, e) in counts.iter().zip(&expected) {
                let e = e * n as f64;
                if e < 5.0 {
                    po += o;
                    pe += e;
                } else {
                    chi2 += (o - e) * (o - e) / e;
                    dof += 1;
                }
            }
            if pe >= 5.0 {
                chi2 += (po - pe) * (po - pe) / pe;
                dof += 1;
            } else {
                assert!(po < 20.0, "{po} samples where {pe} were expected");
            }
            let dof = (dof - 1) as f64;
            let z = ((chi2 / dof).cbrt() - (1.0 - 2.0 / (9.0 * dof))) / (2.0 / (9.0 * dof)).sqrt();
            assert!(
                z < 4.5,
                "alpha {alpha} cos {cos_o}: chi2 {chi2} with {dof} dof (z = {z})"
            );
        }
    }

    /// The dielectric with specular 0 is exactly Lambertian (albedo 1
    /// keeps all energy); with the default specular it reflects the
    /// Fresnel share specularly and passes the rest to the base, so albedo
    /// 1 loses at most what single scattering loses.
    #[test]
    fn dielectric_energy() {
        let lambert = GltfBrdf {
            alpha: 0.3,
            metallic: 0.0,
            metal_f0: Color::ONE,
            dielectric_weight: 1.0,
            dielectric_f0: Color::ZERO,
            dielectric_f90: 0.0,
            diffuse: Color::ONE,
        };
        let wo = dir(0.6);
        let wi = dir(0.3);
        assert_eq!(lambert.eval_cos(Vec3A::Z, wo, wi), Color::splat(0.3 / PI));
        let e = albedo_quadrature(&lambert, wo, 400, 360);
        assert!((e - 1.0).abs() < 1e-3, "{e}");
        let plastic = GltfBrdf {
            dielectric_f0: Color::splat(0.04),
            dielectric_f90: 1.0,
            ..lambert
        };
        let e = albedo_quadrature(&plastic, wo, 1000, 360);
        assert!(e < 1.0 && e > 0.95, "{e}");
    }
}
