//! Absorbing interiors (Beer-Lambert).
//!
//! A material may give its object's interior an absorption coefficient
//! `sigma_a` ([`Material::absorption`](crate::scene::material::Material::absorption),
//! per channel, in inverse scene units). Light that travels a distance `d`
//! inside the object is attenuated by `exp(-sigma_a d)`; nothing is
//! scattered inside (there is no in-scattering and no emission), so the
//! transmittance along a segment is exact and noise-free.
//!
//! # Which segments are attenuated
//! The interior is the side a surface's geometric normal points away from
//! (meshes and shapes of Prism have outward normals). A ray segment that
//! ends on the *back* face of a surface with absorption has travelled
//! inside that object, from where it entered (or was reflected inside) to
//! where it hits the wall again, and is attenuated along its whole length.
//! This is applied at the hit, the same way in every transport: Whitted
//! (recursive and wavefront), path (both integrators) and the camera paths
//! and photon paths of photon transport. The model therefore assumes:
//! * the object is closed and does not hold other objects (a segment
//!   inside the medium that ends on another object is not attenuated);
//! * the camera and the lights are outside it;
//! * shadow rays do not cross it (every surface blocks shadow rays).
//!
//! Scenes without absorbing materials never reach the exponential: the
//! test is a comparison against zero, and their images are unchanged bit
//! for bit.

use crate::core::math::Color;
use crate::core::optics::beer_lambert;
use crate::transport::interaction::Interaction;

/// The transmittance of the segment of length `distance` that ended at
/// `it`, when it ran through an absorbing interior: `Some(exp(-sigma_a
/// distance))` if the ray hit the back face of a surface with absorption,
/// `None` otherwise (the segment is not attenuated).
#[inline]
pub fn interior_transmittance(it: &Interaction, distance: f32) -> Option<Color> {
    let sigma = it.surface.absorption;
    if it.front_face || sigma == Color::ZERO {
        return None;
    }
    Some(beer_lambert(sigma, distance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::optics::{absorption_from_attenuation, check_absorption};

    /// `-ln(c)/d` gives back `c` after `d`, and twice the distance squares
    /// the transmittance.
    #[test]
    fn attenuation_colour_round_trips() {
        let c = Color::new(0.9, 0.5, 0.1);
        let sigma = absorption_from_attenuation(c, 2.0).unwrap();
        let t = beer_lambert(sigma, 2.0);
        assert!((t - c).abs().max_element() < 1e-6, "{t}");
        let t2 = beer_lambert(sigma, 4.0);
        assert!((t2 - c * c).abs().max_element() < 1e-6, "{t2}");
        let black = absorption_from_attenuation(Color::new(0.0, 1.0, 0.5), f32::INFINITY).unwrap();
        assert_eq!(black, Color::ZERO);
        let b = absorption_from_attenuation(Color::new(0.0, 1.0, 0.5), 1.0).unwrap();
        assert_eq!(beer_lambert(b, 1.0).x, 0.0);
        assert_eq!(beer_lambert(b, 0.0), Color::ONE);
        assert!(absorption_from_attenuation(Color::splat(f32::NAN), 1.0).is_err());
        assert!(absorption_from_attenuation(Color::splat(1.5), 1.0).is_err());
        assert!(absorption_from_attenuation(Color::ONE, -1.0).is_err());
        assert!(absorption_from_attenuation(Color::ONE, f32::NAN).is_err());
        assert!(check_absorption(Color::new(0.0, -1.0, 0.0)).is_err());
        assert!(check_absorption(Color::new(0.0, f32::NAN, 0.0)).is_err());
        assert!(check_absorption(Color::new(0.0, f32::INFINITY, 0.0)).is_ok());
    }
}
