//! Settings of photon-mapping transport (probabilistic progressive photon
//! mapping, Knaus and Zwicker 2011): photons per iteration, the first
//! gather radius and how it shrinks, the number of iterations, and final
//! gathering.

/// Default photons traced per iteration.
pub const DEFAULT_PHOTONS: u32 = 100_000;

/// Default number of iterations (photon pass plus camera pass each).
pub const DEFAULT_ITERATIONS: u32 = 16;

/// Default radius-reduction parameter: Hachisuka and Jensen's 2/3.
pub const DEFAULT_ALPHA: f32 = 2.0 / 3.0;

/// Largest number of photons per iteration accepted (the map of one
/// iteration holds at most `photons * (max_depth + 1)` photons of 32 bytes).
pub const MAX_PHOTONS: u32 = 1 << 26;

/// Largest number of iterations accepted.
pub const MAX_ITERATIONS: u32 = 1 << 20;

/// Largest number of final-gather rays per camera sample accepted.
pub const MAX_GATHER_RAYS: u32 = 4096;

/// Photon mapping's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotonSettings {
    /// Photons emitted per iteration, shared among the lights in
    /// proportion to their power; at least 1.
    pub photons: u32,
    /// Gather radius of the first iteration, in scene units; `None`: the
    /// scene's bounding-box diagonal divided by
    /// [`AUTO_RADIUS_DIVISOR`].
    pub radius: Option<f32>,
    /// Radius reduction: iteration `i + 1` gathers over
    /// `r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1)` (`i` counting iterations
    /// from 1); in `(0, 1)`.
    pub alpha: f32,
    /// Iterations: each traces its own photons and one round of camera
    /// samples (`spp` per pixel) and the image is their mean; at least 1.
    pub iterations: u32,
    /// Final-gather rays per camera sample: 0 visualises the photon maps
    /// directly at the first diffuse or glossy surface seen (through
    /// mirrors and glass); more computes direct light exactly, caustics
    /// from the caustic map, and indirect light from this many BSDF rays
    /// that read both maps where they land.
    pub gather_rays: u32,
}

/// The automatic first radius is the scene's bounding-box diagonal over
/// this.
pub const AUTO_RADIUS_DIVISOR: f32 = 200.0;

impl Default for PhotonSettings {
    fn default() -> Self {
        Self {
            photons: DEFAULT_PHOTONS,
            radius: None,
            alpha: DEFAULT_ALPHA,
            iterations: DEFAULT_ITERATIONS,
            gather_rays: 0,
        }
    }
}

impl PhotonSettings {
    /// Rejects unusable values with a message naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.photons == 0 || self.photons > MAX_PHOTONS {
            return Err(format!(
                "photons per iteration must be between 1 and {MAX_PHOTONS}, got {}",
                self.photons
            ));
        }
        if let Some(r) = self.radius
            && !(r > 0.0 && r.is_finite())
        {
            return Err(format!(
                "photon gather radius must be a finite number above 0, got {r}"
            ));
        }
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(format!(
                "photon radius alpha must be between 0 and 1 (exclusive), got {}",
                self.alpha
            ));
        }
        if self.iterations == 0 || self.iterations > MAX_ITERATIONS {
            return Err(format!(
                "photon iterations must be between 1 and {MAX_ITERATIONS}, got {}",
                self.iterations
            ));
        }
        if self.gather_rays > MAX_GATHER_RAYS {
            return Err(format!(
                "final-gather rays must be at most {MAX_GATHER_RAYS}, got {}",
                self.gather_rays
            ));
        }
        Ok(())
    }

    /// The squared gather radius of iteration `i` (from 0) given the first
    /// radius `r1`: `r1^2 prod_{k=1}^{i} (k + alpha) / (k + 1)`, computed in
    /// f64 (Knaus and Zwicker's sequence, whose variance and bias both
    /// vanish as iterations grow for `alpha` in `(0, 1)`).
    pub fn radius2_at(&self, r1: f32, i: u32) -> f32 {
        let mut r2 = r1 as f64 * r1 as f64;
        let a = self.alpha as f64;
        for k in 1..=i as u64 {
            r2 *= (k as f64 + a) / (k as f64 + 1.0);
        }
        r2 as f32
    }
}

/// Command-line or scene-file values for [`PhotonSettings`]; unset fields
/// fall back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhotonOverrides {
    /// Photons per iteration.
    pub photons: Option<u32>,
    /// First gather radius.
    pub radius: Option<f32>,
    /// Radius reduction.
    pub alpha: Option<f32>,
    /// Iterations.
    pub iterations: Option<u32>,
    /// Final-gather rays.
    pub gather_rays: Option<u32>,
}

impl PhotonOverrides {
    /// These values, then `under`'s.
    pub fn or(self, under: PhotonOverrides) -> PhotonOverrides {
        PhotonOverrides {
            photons: self.photons.or(under.photons),
            radius: self.radius.or(under.radius),
            alpha: self.alpha.or(under.alpha),
            iterations: self.iterations.or(under.iterations),
            gather_rays: self.gather_rays.or(under.gather_rays),
        }
    }

    /// The settings: these values, then the defaults.
    pub fn resolve(self) -> PhotonSettings {
        let d = PhotonSettings::default();
        PhotonSettings {
            photons: self.photons.unwrap_or(d.photons),
            radius: self.radius.or(d.radius),
            alpha: self.alpha.unwrap_or(d.alpha),
            iterations: self.iterations.unwrap_or(d.iterations),
            gather_rays: self.gather_rays.unwrap_or(d.gather_rays),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The product form equals the recurrence `r_{i+1}^2 = r_i^2 (i +
    /// alpha) / (i + 1)` (1-based), and the radius shrinks.
    #[test]
    fn radius_sequence_follows_the_recurrence() {
        let s = PhotonSettings::default();
        let mut r2 = 4.0f64;
        // r2 is r_{i+1}^2 in the 1-based recurrence, iteration i from 0.
        for i in 1..20u32 {
            r2 *= (i as f64 + s.alpha as f64) / (i as f64 + 1.0);
            let got = s.radius2_at(2.0, i) as f64;
            assert!((got - r2).abs() <= 1e-6 * r2, "{i}: {got} vs {r2}");
            assert!(got < s.radius2_at(2.0, i - 1) as f64);
        }
    }

    #[test]
    fn bad_values_are_refused() {
        for bad in [
            PhotonSettings {
                photons: 0,
                ..Default::default()
            },
            PhotonSettings {
                radius: Some(0.0),
                ..Default::default()
            },
            PhotonSettings {
                radius: Some(f32::NAN),
                ..Default::default()
            },
            PhotonSettings {
                alpha: 1.0,
                ..Default::default()
            },
            PhotonSettings {
                iterations: 0,
                ..Default::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        assert!(PhotonSettings::default().validate().is_ok());
    }
}
