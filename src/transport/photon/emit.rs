//! Where photons start: every light of the scene, chosen in proportion to
//! its power, with the photon's power in Prism's units.
//!
//! Powers (per channel, `I` in cd, `E` in lx, `L` the emitted radiance):
//! - point light: `4 pi I`, directions uniform over the sphere;
//! - spot light: `2 pi I ((1 - cos_inner) + (cos_inner - cos_outer) / 3)`,
//!   the integral of its smooth falloff `t^2`, directions uniform over the
//!   outer cone;
//! - directional light: `E pi R^2` through a disk of radius `R` (the
//!   bounding sphere of the scene's bounded objects) facing the light,
//!   points uniform on the disk; unbounded objects (planes) outside that
//!   sphere receive no photons from it;
//! - emissive surfaces (the path tracer's area lights, [`EmitterTable`]):
//!   `2 pi L A` (two-sided, as shading sees them), a point drawn from the
//!   table, a side by a fair coin, a cosine-distributed direction.
//!
//! A photon's power is its light's power sample divided by the probability
//! of the light and of the sample, so that the expected sum over `N`
//! photons is the scene's emitted power; each photon then carries `1/N` of
//! it (the caller divides).
//!
//! [`EmitterTable`]: crate::scene::emitters::EmitterTable

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, Ray, luminance, orthonormal_basis};
use crate::core::optics::offset_origin_relative;
use crate::core::rng::Sampler;
use crate::core::sampling::{concentric_disk, cosine_hemisphere, uniform_sphere};
use crate::scene::RenderScene;
use crate::scene::light::WorldLight;

/// One source of photons.
#[derive(Clone, Copy, Debug)]
enum Source {
    /// A punctual light (index into the scene's lights).
    Light(u32),
    /// All emissive surfaces, sampled through the emitter table.
    Emitters,
}

/// The scene's photon sources with their selection probabilities.
#[derive(Clone, Debug)]
pub struct PhotonSources {
    sources: Vec<Source>,
    /// Selection probability of each source.
    prob: Vec<f32>,
    /// Cumulative probabilities; the last is exactly 1.
    cdf: Vec<f32>,
    /// Bounding sphere of the bounded objects (for directional lights).
    centre: Vec3A,
    radius: f32,
}

/// A photon leaving a light.
#[derive(Clone, Copy, Debug)]
pub struct EmittedPhoton {
    /// Its first ray (origin offset from any surface it starts on).
    pub ray: Ray,
    /// Power: the light's power sample over the probability of this
    /// photon (not yet divided by the photon count).
    pub power: Color,
}

/// Power (per channel) of a punctual light in a scene whose bounded
/// objects fit in a sphere of radius `radius`.
pub fn light_power(light: &WorldLight, radius: f32) -> Color {
    match *light {
        WorldLight::Point { intensity, .. } => intensity * (4.0 * PI),
        WorldLight::Spot {
            intensity,
            cos_inner,
            cos_outer,
            ..
        } => {
            let (ci, co) = (cos_inner.max(cos_outer), cos_outer);
            intensity * (2.0 * PI * ((1.0 - ci) + (ci - co) / 3.0))
        }
        WorldLight::Directional { illuminance, .. } => illuminance * (PI * radius * radius),
    }
}

impl PhotonSources {
    /// The lights and emitters of `scene`, weighted by power (luminance).
    pub fn new(scene: &RenderScene) -> Self {
        let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
        for inst in scene.instances() {
            if let Some(b) = inst.world_bounds() {
                lo = lo.min(b.min);
                hi = hi.max(b.max);
            }
        }
        let (centre, radius) = if lo.cmple(hi).all() {
            ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-6))
        } else {
            (Vec3A::ZERO, 0.0)
        };
        let mut sources = Vec::new();
        let mut power = Vec::new();
        for (i, l) in scene.lights().iter().enumerate() {
            let p = luminance(light_power(l, radius));
            if p > 0.0 && p.is_finite() {
                sources.push(Source::Light(i as u32));
                power.push(p as f64);
            }
        }
        let e = 2.0 * PI * scene.emitters().weighted_area();
        if !scene.emitters().is_empty() && e > 0.0 && e.is_finite() {
            sources.push(Source::Emitters);
            power.push(e as f64);
        }
        let total: f64 = power.iter().sum();
        let prob: Vec<f32> = power.iter().map(|p| (p / total) as f32).collect();
        let mut acc = 0.0;
        let mut cdf: Vec<f32> = power
            .iter()
            .map(|p| {
                acc += p;
                (acc / total) as f32
            })
            .collect();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Self {
            sources,
            prob,
            cdf,
            centre,
            radius,
        }
    }

    /// True when nothing in the scene emits photons.
    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// Centre and radius of the bounding sphere of the bounded objects
    /// (radius 0 when there are none).
    pub fn bounds(&self) -> (Vec3A, f32) {
        (self.centre, self.radius)
    }

    /// Emits one photon with the sampler's dimensions 0 to 7: set 0 chooses
    /// the source, its point and side; set 1 the direction.
    pub fn emit(&self, scene: &RenderScene, sampler: &mut Sampler) -> Option<EmittedPhoton> {
        sampler.set_dimension(0);
        let u_point = Vec2::new(sampler.next_f32(), sampler.next_f32());
        let u_source = sampler.next_f32();
        let u_side = sampler.next_f32();
        let u_dir = Vec2::new(sampler.next_f32(), sampler.next_f32());
        let k = self
            .cdf
            .partition_point(|&c| c <= u_source)
            .min(self.sources.len().checked_sub(1)?);
        let p_select = self.prob[k];
        if !(p_select > 0.0) {
            return None;
        }
        let photon = match self.sources[k] {
            Source::Light(i) => match scene.lights()[i as usize] {
                WorldLight::Point {
                    position,
                    intensity,
                } => EmittedPhoton {
                    ray: Ray::new(position, uniform_sphere(u_dir)),
                    power: intensity * (4.0 * PI),
                },
                WorldLight::Spot {
                    position,
                    direction,
                    intensity,
                    cos_inner,
                    cos_outer,
                } => {
                    // Uniform over the outer cone's solid angle.
                    let cos = 1.0 - u_dir.x * (1.0 - cos_outer);
                    let sin = (1.0 - cos * cos).max(0.0).sqrt();
                    let phi = 2.0 * PI * u_dir.y;
                    let (t, b) = orthonormal_basis(direction);
                    let d = t * (sin * phi.cos()) + b * (sin * phi.sin()) + direction * cos;
                    let f = if cos_inner > cos_outer {
                        ((cos - cos_outer) / (cos_inner - cos_outer)).clamp(0.0, 1.0)
                    } else {
                        1.0
                    };
                    EmittedPhoton {
                        ray: Ray::new(position, d.normalize()),
                        power: intensity * (f * f * 2.0 * PI * (1.0 - cos_outer)),
                    }
                }
                WorldLight::Directional {
                    direction,
                    illuminance,
                } => {
                    let (t, b) = orthonormal_basis(direction);
                    let d = concentric_disk(u_point) * self.radius;
                    let origin = self.centre + t * d.x + b * d.y - direction * (1.01 * self.radius);
                    EmittedPhoton {
                        ray: Ray::new(origin, direction),
                        power: illuminance * (PI * self.radius * self.radius),
                    }
                }
            },
            Source::Emitters => {
                let ls = scene.emitters().sample(
                    scene.instances(),
                    scene.materials(),
                    u_source_rescaled(u_source, &self.cdf, k),
                    u_point,
                )?;
                let n = if u_side < 0.5 { ls.normal } else { -ls.normal };
                // L cos / (pdf_area * 1/2 * cos / pi).
                EmittedPhoton {
                    ray: Ray::new(
                        offset_origin_relative(ls.point, n),
                        cosine_hemisphere(n, u_dir),
                    ),
                    power: ls.radiance * (2.0 * PI / ls.pdf_area),
                }
            }
        };
        let power = photon.power / p_select;
        (power.is_finite() && power.max_element() > 0.0)
            .then_some(EmittedPhoton { power, ..photon })
    }
}

/// The source number's position within source `k`'s interval, reused to
/// choose within the source (keeps the dimension count fixed).
fn u_source_rescaled(u: f32, cdf: &[f32], k: usize) -> f32 {
    let lo = if k == 0 { 0.0 } else { cdf[k - 1] };
    let w = cdf[k] - lo;
    if w > 0.0 {
        ((u - lo) / w).clamp(0.0, 1.0 - f32::EPSILON / 2.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spot light's power formula against a midpoint quadrature of
    /// the falloff over the sphere.
    #[test]
    fn spot_power_matches_quadrature() {
        let (ci, co) = (0.9f32, 0.6f32);
        let light = WorldLight::Spot {
            position: Vec3A::ZERO,
            direction: Vec3A::Z,
            intensity: Color::ONE,
            cos_inner: ci,
            cos_outer: co,
        };
        let n = 100_000;
        let mut sum = 0.0f64;
        for i in 0..n {
            let c = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
            let f = if c <= co as f64 {
                0.0
            } else if c >= ci as f64 {
                1.0
            } else {
                ((c - co as f64) / (ci - co) as f64).powi(2)
            };
            sum += f * 2.0 / n as f64;
        }
        let expected = 2.0 * std::f64::consts::PI * sum;
        let got = light_power(&light, 0.0).x as f64;
        assert!(
            (got - expected).abs() < 1e-4 * expected,
            "{got} vs {expected}"
        );
    }
}
