//! Punctual lights in glTF's photometric units.

use bevy_ecs::component::Component;
use glam::{DVec3, Vec3A};

use crate::core::math::Color;
use crate::geometry::transform::Transform;

/// A light source, placed by the entity's [`Transform`]: point and spot
/// lights sit at the transform's origin, directional and spot lights shine
/// along its local `-Z` axis (the glTF convention).
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Emits `intensity` candela (per channel) in every direction.
    Point {
        /// Luminous intensity, cd.
        intensity: Color,
    },
    /// Parallel light delivering `illuminance` lux on a surface facing it.
    Directional {
        /// Illuminance, lx.
        illuminance: Color,
    },
    /// A point light restricted to a cone with a smooth edge.
    Spot {
        /// Luminous intensity on the axis, cd.
        intensity: Color,
        /// Half-angle (radians) inside which the intensity is full.
        inner_angle: f32,
        /// Half-angle (radians) outside which there is no light.
        outer_angle: f32,
    },
}

/// A light resolved into world space, ready for shading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WorldLight {
    /// Point light at `position`.
    Point {
        /// World position.
        position: Vec3A,
        /// Intensity, cd.
        intensity: Color,
    },
    /// Directional light travelling along `direction` (unit).
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3A,
        /// Illuminance, lx.
        illuminance: Color,
    },
    /// Spot light.
    Spot {
        /// World position.
        position: Vec3A,
        /// Unit axis the light shines along.
        direction: Vec3A,
        /// Intensity on the axis, cd.
        intensity: Color,
        /// Cosine of the inner half-angle.
        cos_inner: f32,
        /// Cosine of the outer half-angle.
        cos_outer: f32,
    },
}

/// What a light delivers at a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from the point towards the light.
    pub wi: Vec3A,
    /// Distance to the light (infinite for directional lights).
    pub distance: f32,
    /// Irradiance on a surface facing the light (lux), before the cosine.
    pub irradiance: Color,
}

impl WorldLight {
    /// Resolves a light component with its transform, in the frame
    /// centred on `origin` (the scene's render origin; the subtraction is
    /// done in f64).
    pub fn new(light: &Light, transform: &Transform, origin: DVec3) -> Self {
        let position = (transform.0.translation - origin).as_vec3a();
        let axis = transform
            .0
            .matrix3
            .mul_vec3(DVec3::NEG_Z)
            .normalize_or(DVec3::NEG_Z)
            .as_vec3a();
        match *light {
            Light::Point { intensity } => WorldLight::Point {
                position,
                intensity,
            },
            Light::Directional { illuminance } => WorldLight::Directional {
                direction: axis,
                illuminance,
            },
            Light::Spot {
                intensity,
                inner_angle,
                outer_angle,
            } => {
                let outer = outer_angle.clamp(0.0, std::f32::consts::FRAC_PI_2);
                let inner = inner_angle.clamp(0.0, outer);
                WorldLight::Spot {
                    position,
                    direction: axis,
                    intensity,
                    cos_inner: inner.cos(),
                    cos_outer: outer.cos(),
                }
            }
        }
    }

    /// Light arriving at `p`, or `None` when the point is outside the
    /// light's reach (behind a spot's cone, or exactly at a point light).
    #[inline]
    pub fn illuminate(&self, p: Vec3A) -> Option<LightSample> {
        match *self {
            WorldLight::Directional {
                direction,
                illuminance,
            } => Some(LightSample {
                wi: -direction,
                distance: f32::INFINITY,
                irradiance: illuminance,
            }),
            WorldLight::Point {
                position,
                intensity,
            } => {
                let d = position - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) || !dist2.is_finite() {
                    return None;
                }
                let dist = dist2.sqrt();
                Some(LightSample {
                    wi: d / dist,
                    distance: dist,
                    irradiance: intensity / dist2,
                })
            }
            WorldLight::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let d = position - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) || !dist2.is_finite() {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos = (-wi).dot(direction);
                if cos <= cos_outer {
                    return None;
                }
                // Smooth falloff recommended by KHR_lights_punctual.
                let t = if cos_inner > cos_outer {
                    ((cos - cos_outer) / (cos_inner - cos_outer)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                Some(LightSample {
                    wi,
                    distance: dist,
                    irradiance: intensity * (t * t) / dist2,
                })
            }
        }
    }
}
