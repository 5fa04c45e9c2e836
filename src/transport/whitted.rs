//! Whitted transport: direct light from punctual lights through shadow
//! rays, and the perfectly specular reflection and refraction rays.

use glam::Vec3A;

use crate::core::math::{Color, Ray};
use crate::core::optics::{fresnel_dielectric, reflect, refract};
use crate::scene::light::{LightSample, WorldLight};
use crate::transport::interaction::{Interaction, RayKind, Secondary, ShadowQuery, brdf_cos};

/// Sets up the shadow ray for one light, or `None` when the light cannot
/// contribute (below the horizon, outside a spot cone, zero BRDF).
#[inline]
pub fn direct_light(it: &Interaction, light: &WorldLight) -> Option<ShadowQuery> {
    direct_light_with(it, light, |wi| brdf_cos(&it.surface, it.ns, it.wo, wi))
}

/// [`direct_light`] with another BRDF: `brdf_cos(wi)` is the BRDF times
/// the cosine for the direction `wi` towards the light. Always inlined:
/// as a call (with the BRDF as a closure) it cost Whitted scenes of many
/// lights 3% more instructions (callgrind, `many_lights`).
#[inline(always)]
pub fn direct_light_with(
    it: &Interaction,
    light: &WorldLight,
    brdf_cos: impl Fn(Vec3A) -> Color,
) -> Option<ShadowQuery> {
    let LightSample {
        wi,
        distance,
        irradiance,
    } = light.illuminate(it.point)?;
    if it.ng.dot(wi) <= 0.0 {
        return None;
    }
    let radiance = brdf_cos(wi) * irradiance;
    if !(radiance.max_element() > 0.0) {
        return None;
    }
    let origin = it.offset(it.ng);
    let t_max = if distance.is_finite() {
        // Distance from the offset origin, shortened by a relative margin
        // so the light's own position is never counted as a blocker.
        (it.point + wi * distance - origin).length() * (1.0 - 1e-5)
    } else {
        f32::INFINITY
    };
    Some(ShadowQuery {
        ray: Ray::new(origin, wi),
        t_max,
        radiance,
    })
}

/// The perfectly specular rays leaving a hit: at most one reflection
/// (mirror plus the dielectric's Fresnel part, which share a direction)
/// and one refraction.
#[inline]
pub fn scatter(it: &Interaction) -> [Option<Secondary>; 2] {
    let s = &it.surface;
    let d = -it.wo;
    let mut reflect_w = s.mirror;
    let mut refraction = None;
    if s.transmission > 0.0 {
        // Relative index: outside -> inside when entering the front face.
        let eta = if it.front_face { 1.0 / s.ior } else { s.ior };
        let cos_i = it.ns.dot(it.wo).max(0.0);
        let f = fresnel_dielectric(cos_i, eta);
        reflect_w += Color::splat(s.transmission * f);
        if f < 1.0
            && let Some(t) = refract(d, it.ns, eta)
        {
            // The refracted ray must leave on the far side of the true surface.
            if t.dot(it.ng) < 0.0 {
                refraction = Some(Secondary {
                    ray: Ray::new(it.offset(-it.ng), t),
                    weight: s.transmission_tint * (s.transmission * (1.0 - f)),
                    kind: RayKind::Refraction,
                });
            }
        }
    }
    let reflection = (reflect_w.max_element() > 0.0).then(|| {
        let mut r = reflect(d, it.ns);
        if r.dot(it.ng) <= 0.0 {
            // A shading normal can reflect below the surface; fall back to
            // the geometric normal.
            r = reflect(d, it.ng);
        }
        Secondary {
            ray: Ray::new(it.offset(it.ng), r),
            weight: reflect_w,
            kind: RayKind::Reflection,
        }
    });
    [reflection, refraction]
}
