//! Reflection, refraction and Fresnel: the optics of the Whitted model.

use glam::Vec3A;

use crate::core::math::Color;

/// Mirror reflection of incident direction `d` (pointing towards the
/// surface) about unit normal `n`.
#[inline]
pub fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of the unit incident direction `d` (pointing towards the
/// surface) through a surface with unit normal `n` facing the incident
/// side, with `eta = n_incident / n_transmitted`.
///
/// Snell's law `n1 sin(theta1) = n2 sin(theta2)`; returns `None` under total
/// internal reflection (`sin(theta2) > 1`).
#[inline]
pub fn refract(d: Vec3A, n: Vec3A, eta: f32) -> Option<Vec3A> {
    let cos_i = (-d.dot(n)).clamp(-1.0, 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((eta * d + (eta * cos_i - cos_t) * n).normalize())
}

/// Unpolarised Fresnel reflectance of a smooth dielectric boundary for
/// light arriving at `cos_i` (cosine to the normal, on the incident side)
/// with `eta = n_incident / n_transmitted`. Returns 1 under total internal
/// reflection. At normal incidence this is `((n1-n2)/(n1+n2))^2`.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    // With n_i = eta * n_t: r_s = (eta cos_i - cos_t)/(eta cos_i + cos_t),
    // r_p = (cos_i - eta cos_t)/(cos_i + eta cos_t).
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r = 0.5 * (rs * rs + rp * rp);
    if r.is_finite() {
        r.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Critical angle (radians) for light going from index `n1` into a less
/// dense medium `n2 < n1`; `None` when there is no total internal reflection.
pub fn critical_angle(n1: f32, n2: f32) -> Option<f32> {
    (n2 < n1).then(|| (n2 / n1).asin())
}

/// Moves a new ray's origin `p` off the surface with geometric normal `n`
/// (unit), to the side of `n` (pass `-n` for the other side), by a few
/// units in the last place of `p`'s own coordinates.
///
/// The offset is scale-independent: it moves each coordinate by a fixed
/// number of ulps (integer arithmetic on the float's bits), and by a small
/// absolute amount only very near the origin where ulps vanish. This is the
/// approach of Wachter and Binder, "A Fast and Robust Method for Avoiding
/// Self-Intersection" (Ray Tracing Gems, 2019).
#[inline]
pub fn offset_origin(p: Vec3A, n: Vec3A) -> Vec3A {
    const NEAR_ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let step = |p: f32, n: f32| -> f32 {
        let offset = (INT_SCALE * n) as i32;
        let bits = p.to_bits() as i32;
        let moved = f32::from_bits(if p < 0.0 {
            bits.wrapping_sub(offset)
        } else {
            bits.wrapping_add(offset)
        } as u32);
        if p.abs() < NEAR_ORIGIN {
            p + FLOAT_SCALE * n
        } else {
            moved
        }
    };
    Vec3A::new(step(p.x, n.x), step(p.y, n.y), step(p.z, n.z))
}

/// Moves a new ray's origin `p` off the surface with geometric normal `n`
/// (unit), to the side of `n` (pass `-n` for the other side), by
/// [`OFFSET_ULPS`] units in the last place of the *largest* coordinate of
/// `p`, without any scene-scale constant.
///
/// This is the offset for hit points computed from the object-space
/// surface point ([`crate::geometry::shapes::ShapeHit::point`],
/// [`crate::geometry::mesh::MeshSurface::point`], then the instance transform),
/// which are correct to a few ulps of their own largest coordinate: every
/// coordinate's error is then bounded by that ulp, and a move of several of
/// them along the normal clears the surface at any scale.
///
/// [`offset_origin`] (Wachter and Binder) moves each coordinate by 256 of
/// its *own* ulps, and by a fixed 2^-16 below 1/32. With hit points
/// computed as `ray.at(t)`, whose error grows with the distance of the
/// ray's origin, its fixed offset is what keeps unit-sized scenes free of
/// acne, but it is too large for a scene scaled by 1e-4 (contact shadows
/// vanish) and too small for one scaled by 1e4 (acne on a floor at
/// `y = 0`), and 256 ulps of 1e5 is 2 units, which skips small occluders
/// in a translated scene (`tests/render/robustness.rs`, scale invariance). Do not
/// use this function with `ray.at(t)` points: their error is not bounded
/// by the point's own ulps (seen: acne on a cone 10 units from the camera).
#[inline]
pub fn offset_origin_relative(p: Vec3A, n: Vec3A) -> Vec3A {
    offset_origin_scaled(p, n, 0.0)
}

/// [`offset_origin_relative`] for a point whose error is bounded by the
/// ulps of `scale` when that is larger than the point's own largest
/// coordinate: a point computed as `M p + t` near the render frame's
/// origin from an object point and a translation of magnitude 1000 (the
/// top of a ground sphere of radius 1000 centred 1000 below the origin)
/// carries rounding errors of ulps of 1000, not of its own small
/// coordinates ([`Interaction::offset_scale`](crate::transport::interaction::Interaction::offset_scale)).
#[inline]
pub fn offset_origin_scaled(p: Vec3A, n: Vec3A, scale: f32) -> Vec3A {
    // At least one ulp of the largest coordinate (also for denormals and
    // the exact origin, where the error is zero anyway).
    let magnitude = p.abs().max_element().max(scale).max(f32::MIN_POSITIVE);
    let q = p + n * (OFFSET_ULPS * f32::EPSILON * magnitude);
    if q.is_finite() { q } else { p }
}

/// Size of the [`offset_origin_relative`] move, in ulps of the point's
/// largest coordinate. A hit point from an object-space surface point
/// carries about 3 roundings of the instance transform (and of the
/// barycentric or projection step before it); 16 covers that with a
/// margin, and along the normal's largest component (at least 1/sqrt(3)
/// of it) the move is still 9 ulps, so the point always moves.
pub const OFFSET_ULPS: f32 = 16.0;

/// `exp(-sigma d)` per channel; zero where `sigma d` is infinite, so no
/// NaN can come out of an infinite coefficient.
#[inline]
pub fn beer_lambert(sigma: Color, distance: f32) -> Color {
    let tau = sigma * distance.max(0.0);
    // A grey medium (a fog, most absorbing glass) has one optical depth
    // in every channel: one exponential gives the same three values.
    if tau.x == tau.y && tau.y == tau.z {
        return Color::splat(transmit(tau.x));
    }
    Color::new(transmit(tau.x), transmit(tau.y), transmit(tau.z))
}

#[inline]
fn transmit(tau: f32) -> f32 {
    if tau > 0.0 { (-tau).exp() } else { 1.0 }
}

/// The absorption coefficient that leaves `color` of the light after
/// `distance` (the artist's parameters, as glTF's `KHR_materials_volume`
/// gives them: `attenuationColor` and `attenuationDistance`):
/// `sigma_a = -ln(color) / distance` per channel. A channel of colour 1 or
/// an infinite distance absorbs nothing; a channel of colour 0 absorbs
/// everything (an infinite coefficient). Errors (to be prefixed by the
/// owner's name) for a colour outside `[0, 1]` or NaN and for a distance
/// that is not positive.
pub fn absorption_from_attenuation(color: Color, distance: f32) -> Result<Color, String> {
    if !(color.min_element() >= 0.0 && color.max_element() <= 1.0) {
        return Err(format!(
            "attenuation colour must lie in [0, 1] per channel, got [{}, {}, {}]",
            color.x, color.y, color.z
        ));
    }
    if !(distance > 0.0) {
        return Err(format!(
            "attenuation distance must be positive, got {distance}"
        ));
    }
    if distance == f32::INFINITY {
        return Ok(Color::ZERO);
    }
    let sigma = |c: f32| {
        if c >= 1.0 {
            0.0
        } else if c <= 0.0 {
            f32::INFINITY
        } else {
            -c.ln() / distance
        }
    };
    Ok(Color::new(sigma(color.x), sigma(color.y), sigma(color.z)))
}

/// Checks an absorption coefficient: every channel non-negative and not
/// NaN (infinity is allowed: the interior is black). The error is to be
/// prefixed by the owner's name.
pub fn check_absorption(sigma: Color) -> Result<Color, String> {
    if !(sigma.min_element() >= 0.0) || sigma.is_nan() {
        return Err(format!(
            "absorption coefficient (sigma_a) must be non-negative in every channel, got [{}, {}, {}]",
            sigma.x, sigma.y, sigma.z
        ));
    }
    Ok(sigma)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey medium's one exponential gives, bit for bit, the three that
    /// each channel's own optical depth gives, also at zero, infinite and
    /// NaN depths; a coloured medium still gets its own per channel.
    #[test]
    fn grey_transmittance_is_each_channels_own() {
        let per_channel = |s: Color, d: f32| {
            (s * d.max(0.0))
                .to_array()
                .map(|t| if t > 0.0 { (-t).exp() } else { 1.0 })
        };
        let sigmas = [0.0, 1e-30, 0.07, 0.5, 1.0, 3.7, 1e3, f32::INFINITY];
        let distances = [
            -1.0,
            0.0,
            1e-20,
            0.3,
            1.0,
            7.25,
            1e5,
            f32::INFINITY,
            f32::NAN,
        ];
        for &s in &sigmas {
            for &d in &distances {
                let grey = beer_lambert(Color::splat(s), d).to_array();
                let own = per_channel(Color::splat(s), d);
                assert_eq!(
                    grey.map(f32::to_bits),
                    own.map(f32::to_bits),
                    "sigma {s} d {d}"
                );
                let coloured = Color::new(s, 0.25, 2.0);
                let c = beer_lambert(coloured, d).to_array();
                let own = per_channel(coloured, d);
                assert_eq!(
                    c.map(f32::to_bits),
                    own.map(f32::to_bits),
                    "sigma {s} d {d}"
                );
            }
        }
    }

    fn unit(theta: f32) -> Vec3A {
        // A direction travelling downwards onto the plane y = 0 at angle
        // theta from the normal +Y.
        Vec3A::new(theta.sin(), -theta.cos(), 0.0)
    }

    #[test]
    fn snell_law_holds() {
        let n = Vec3A::Y;
        for &(n1, n2) in &[(1.0f32, 1.5f32), (1.0, 1.333), (1.5, 1.0), (2.4, 1.2)] {
            for i in 0..40 {
                let theta_i = i as f32 / 40.0 * 1.5;
                let d = unit(theta_i);
                match refract(d, n, n1 / n2) {
                    Some(t) => {
                        assert!((t.length() - 1.0).abs() < 1e-5);
                        let sin_t = (t.x * t.x + t.z * t.z).sqrt();
                        // n1 sin(i) = n2 sin(t), error of a few f32 ulps of 1.
                        assert!(
                            (n1 * theta_i.sin() - n2 * sin_t).abs() < 1e-5,
                            "{n1} {n2} {theta_i}"
                        );
                        assert!(t.y < 0.0, "refracted ray continues through");
                        assert!(t.x >= 0.0, "stays in the plane of incidence");
                    }
                    None => {
                        assert!(n1 > n2);
                        assert!(n1 / n2 * theta_i.sin() >= 1.0 - 1e-6);
                    }
                }
            }
        }
    }

    #[test]
    fn total_internal_reflection_starts_at_the_critical_angle() {
        let (n1, n2) = (1.5f32, 1.0f32);
        let crit = critical_angle(n1, n2).unwrap();
        assert!((crit - (1.0f32 / 1.5).asin()).abs() < 1e-7);
        // 41.81 degrees for glass to air.
        assert!((crit.to_degrees() - 41.8103).abs() < 1e-3);
        let n = Vec3A::Y;
        assert!(refract(unit(crit - 1e-3), n, n1 / n2).is_some());
        assert!(refract(unit(crit + 1e-3), n, n1 / n2).is_none());
        assert_eq!(fresnel_dielectric((crit + 1e-3).cos(), n1 / n2), 1.0);
        assert!(fresnel_dielectric((crit - 1e-2).cos(), n1 / n2) < 1.0);
        assert!(critical_angle(1.0, 1.5).is_none());
    }

    #[test]
    fn fresnel_at_normal_incidence() {
        for &(n1, n2) in &[
            (1.0f32, 1.5f32),
            (1.5, 1.0),
            (1.0, 2.4),
            (1.0, 1.0),
            (1.33, 1.5),
        ] {
            let expect = ((n1 - n2) / (n1 + n2)).powi(2);
            let got = fresnel_dielectric(1.0, n1 / n2);
            assert!((got - expect).abs() < 1e-6, "{n1}->{n2}: {got} vs {expect}");
        }
        // Glass: 4 %.
        assert!((fresnel_dielectric(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
    }

    #[test]
    fn fresnel_grazing_and_monotone_from_outside() {
        let eta = 1.0 / 1.5;
        let mut prev = 0.0;
        for i in 0..=100 {
            let cos = 1.0 - i as f32 / 100.0;
            let f = fresnel_dielectric(cos, eta);
            assert!((0.0..=1.0).contains(&f));
            assert!(f >= prev - 1e-6, "Fresnel grows towards grazing");
            prev = f;
        }
        assert!((fresnel_dielectric(0.0, eta) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn reflection_preserves_angle() {
        let d = unit(0.7);
        let r = reflect(d, Vec3A::Y);
        assert!((r.y - 0.7f32.cos()).abs() < 1e-6);
        assert!((r.x - 0.7f32.sin()).abs() < 1e-6);
    }

    #[test]
    fn offset_moves_to_the_requested_side_at_every_scale() {
        let n = Vec3A::new(0.3, 0.9, -0.3).normalize();
        for &s in &[1e-6f32, 1e-3, 0.5, 1.0, 1e3, 1e6, 1e9] {
            for &p in &[Vec3A::splat(s), Vec3A::splat(-s), Vec3A::new(s, -s, 0.0)] {
                let q = offset_origin(p, n);
                assert!((q - p).dot(n) > 0.0, "offset at scale {s}");
                let back = offset_origin(p, -n);
                assert!((back - p).dot(n) < 0.0);
                // Never more than a few hundred ulps (or 2^-16 near 0).
                let tol = (p.abs().max_element() * 512.0 * f32::EPSILON).max(1.0 / 32768.0);
                assert!((q - p).abs().max_element() <= tol);
            }
        }
    }
}
