//! `KHR_lights_punctual` lights and cameras, placed by their node's world
//! transform.

use glam::{DAffine3, DVec3, Vec3};

use crate::geometry::transform::Transform;
use crate::io::desc::LightDesc;
use crate::scene::camera::{Camera, Projection};
use crate::scene::light::Light;

use super::materials::{check_color, check_factor};

pub(super) fn convert_light(
    light: &gltf::khr_lights_punctual::Light,
    node: &str,
    transform: Transform,
) -> Result<LightDesc, String> {
    use gltf::khr_lights_punctual::Kind;
    let label = match light.name() {
        Some(name) => format!("light {} ('{name}') at {node}", light.index()),
        None => format!("light {} at {node}", light.index()),
    };
    let color = Vec3::from(light.color());
    check_color(color, "colour", &label)?;
    let intensity = light.intensity();
    check_factor(intensity, "intensity", &label)?;
    let value = color * intensity;
    check_color(value, "colour times intensity", &label)?;
    let light_value = match light.kind() {
        Kind::Point => Light::Point { intensity: value },
        Kind::Directional => Light::Directional { illuminance: value },
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            if !(inner_cone_angle.is_finite() && outer_cone_angle.is_finite()) {
                return Err(format!("{label}: spot cone angles are not finite"));
            }
            Light::Spot {
                intensity: value,
                inner_angle: inner_cone_angle,
                outer_angle: outer_cone_angle,
            }
        }
    };
    Ok(LightDesc {
        name: light.name().map(str::to_string),
        transform,
        light: light_value,
    })
}

pub(super) fn convert_camera(
    camera: &gltf::Camera,
    node: &str,
    world: DAffine3,
) -> Result<Option<Camera>, String> {
    let label = match camera.name() {
        Some(name) => format!("camera {} ('{name}') at {node}", camera.index()),
        None => format!("camera {} at {node}", camera.index()),
    };
    let (yfov, projection) = match camera.projection() {
        gltf::camera::Projection::Perspective(p) => (p.yfov(), Projection::Perspective),
        gltf::camera::Projection::Orthographic(o) => {
            let half_height = o.ymag().abs();
            if !(half_height.is_finite() && half_height > 0.0) {
                return Err(format!(
                    "{label}: orthographic ymag {} is not a positive number",
                    o.ymag()
                ));
            }
            (1.0, Projection::Orthographic { half_height })
        }
    };
    if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(format!("{label}: yfov {yfov} is not in (0, pi) radians"));
    }
    let position = world.translation;
    let forward = world.matrix3.mul_vec3(DVec3::NEG_Z).normalize_or_zero();
    let up = world
        .matrix3
        .mul_vec3(DVec3::Y)
        .normalize_or_zero()
        .as_vec3();
    let result = Camera {
        look_from: position,
        look_at: position + forward,
        up,
        vfov_degrees: yfov.to_degrees(),
        shift: glam::Vec2::ZERO,
        projection,
        name: camera.name().map(str::to_string),
        ..Default::default()
    };
    result.validate().map_err(|e| format!("{label}: {e}"))?;
    Ok(Some(result))
}
