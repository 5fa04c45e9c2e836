//! Gooch shading for technical illustration (Gooch, Gooch, Shirley and
//! Cohen 1998): surfaces are toned from cool (facing away from the key
//! light) to warm (facing it), so shape reads without dark shadows, with
//! white highlights. No shadow rays are traced; mirrors and glass still
//! reflect and refract through [`whitted::scatter`](crate::transport::whitted::scatter).

use glam::Vec3A;

use crate::core::math::Color;
use crate::core::settings::GoochParams;
use crate::scene::light::WorldLight;
use crate::transport::interaction::Interaction;

/// The Gooch colour of a surface of base colour `kd` whose normal makes
/// `n_dot_l` with the key light: `t k_warm + (1 - t) k_cool` with
/// `t = (1 + n.l) / 2`, `k_cool = (0, 0, b) + alpha kd` and
/// `k_warm = (y, y, 0) + beta kd`.
#[inline]
pub fn gooch_tone(g: &GoochParams, kd: Color, n_dot_l: f32) -> Color {
    let t = 0.5 * (1.0 + n_dot_l.clamp(-1.0, 1.0));
    let cool = Color::new(0.0, 0.0, g.b) + kd * g.alpha;
    let warm = Color::new(g.y, g.y, 0.0) + kd * g.beta;
    warm * t + cool * (1.0 - t)
}

/// Unit direction from `p` towards the key light: the scene's first light
/// (file order), whatever its reach or cone; a headlight (towards the
/// viewer, `wo`) when the scene has no light.
#[inline]
pub fn key_light_direction(lights: &[WorldLight], p: Vec3A, wo: Vec3A) -> Vec3A {
    let towards = match lights.first() {
        Some(WorldLight::Directional { direction, .. }) => -*direction,
        Some(WorldLight::Point { position, .. }) | Some(WorldLight::Spot { position, .. }) => {
            *position - p
        }
        None => wo,
    };
    let l = towards.normalize_or_zero();
    if l == Vec3A::ZERO { wo } else { l }
}

/// Radiance of a lit surface under the Gooch style: the Gooch tone of its
/// base colour, weighted by its diffuse lobe, plus a white Blinn-Phong
/// highlight `max(ks) (n.h)^s` for surfaces with a highlight lobe. Emission
/// and specular rays are the caller's, as for any shading.
#[inline]
pub fn gooch_shade(g: &GoochParams, lights: &[WorldLight], it: &Interaction) -> Color {
    let s = &it.surface;
    let l = key_light_direction(lights, it.point, it.wo);
    let n_dot_l = it.ns.dot(l);
    let mut c = Color::ZERO;
    if s.diffuse_weight > 0.0 {
        c += gooch_tone(g, s.base, n_dot_l) * s.diffuse_weight;
    }
    let ks = s.specular.max_element();
    if ks > 0.0 && n_dot_l > 0.0 {
        let h = (it.wo + l).normalize_or_zero();
        let cos_h = it.ns.dot(h).max(0.0);
        c += Color::splat(ks * cos_h.powf(s.shininess));
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_issue_s_three_tones() {
        let g = GoochParams::default();
        let kd = Color::new(0.8, 0.2, 0.2);
        for (ndl, want) in [
            (-1.0, Color::new(0.16, 0.04, 0.44)),
            (0.0, Color::new(0.52, 0.28, 0.28)),
            (1.0, Color::new(0.88, 0.52, 0.12)),
        ] {
            let c = gooch_tone(&g, kd, ndl);
            assert!(
                (c - want).abs().max_element() < 1e-6,
                "{ndl}: {c} vs {want}"
            );
        }
    }
}
