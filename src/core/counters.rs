//! Counters an integrator fills while rendering: rays by kind and dropped
//! samples. (`prism render --stats` reports them; its JSON types belong to
//! the command-line program.)

use serde::Serialize;

/// Rays traced, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RayCounts {
    /// Primary rays.
    pub camera: u64,
    /// Shadow rays (one per light per shaded hit that can see the light's side).
    pub shadow: u64,
    /// Mirror and Fresnel reflection rays.
    pub reflection: u64,
    /// Refraction rays.
    pub refraction: u64,
}

impl RayCounts {
    /// All rays.
    pub fn total(&self) -> u64 {
        self.camera + self.shadow + self.reflection + self.refraction
    }

    /// Component-wise sum.
    pub fn add(&mut self, o: &RayCounts) {
        self.camera += o.camera;
        self.shadow += o.shadow;
        self.reflection += o.reflection;
        self.refraction += o.refraction;
    }
}

/// Counters an integrator fills while rendering.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderCounters {
    /// Rays by kind.
    pub rays: RayCounts,
    /// Samples whose radiance was NaN or infinite (dropped from the image).
    pub nonfinite_samples: u64,
}

impl RenderCounters {
    /// Component-wise sum.
    pub fn add(&mut self, o: &RenderCounters) {
        self.rays.add(&o.rays);
        self.nonfinite_samples += o.nonfinite_samples;
    }
}
