//! Materials: glTF metallic-roughness materials and their KHR material
//! extensions (emissive strength, transmission, ior, specular) mapped
//! onto [`Material`], with the checks of colours and factors.

use glam::Vec3;

use crate::core::math::Color;
use crate::core::optics;
use crate::core::spectrum::Dispersion;
use crate::scene::material::{Alpha, AlphaMode, Material, NormalMap};

use super::textures::{normal_texture, texture};
use super::{Ctx, State};

fn material_label(m: &gltf::Material) -> String {
    match (m.index(), m.name()) {
        (Some(i), Some(name)) => format!("material {i} ('{name}')"),
        (Some(i), None) => format!("material {i}"),
        (None, _) => "default material".to_string(),
    }
}

/// Checks a colour factor: finite and non-negative.
pub(super) fn check_color(c: Vec3, what: &str, owner: &str) -> Result<(), String> {
    if !c.is_finite() {
        return Err(format!("{owner}: {what} is not finite"));
    }
    if c.min_element() < 0.0 {
        return Err(format!("{owner}: {what} is negative"));
    }
    Ok(())
}

/// Checks a scalar factor: finite and non-negative.
pub(super) fn check_factor(v: f32, what: &str, owner: &str) -> Result<(), String> {
    if !v.is_finite() {
        return Err(format!("{owner}: {what} is not finite"));
    }
    if v < 0.0 {
        return Err(format!("{owner}: {what} is negative ({v})"));
    }
    Ok(())
}

/// The material of a primitive, converted once per glTF material.
pub(super) fn material(ctx: &Ctx, st: &mut State, m: &gltf::Material) -> Result<Material, String> {
    if let Some(cached) = st.materials.get(&m.index()) {
        return Ok(cached.clone());
    }
    let converted = convert_material(ctx, st, m)?;
    st.materials.insert(m.index(), converted.clone());
    Ok(converted)
}

fn convert_material(ctx: &Ctx, st: &mut State, m: &gltf::Material) -> Result<Material, String> {
    let label = material_label(m);
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, alpha_factor] = pbr.base_color_factor();
    let base = Vec3::new(r, g, b);
    check_color(base, "base colour factor", &label)?;
    let metallic = pbr.metallic_factor();
    check_factor(metallic, "metallic factor", &label)?;
    let roughness = pbr.roughness_factor();
    check_factor(roughness, "roughness factor", &label)?;
    let (specular_factor, specular_color) = match m.specular() {
        Some(s) => (s.specular_factor(), Vec3::from(s.specular_color_factor())),
        None => (1.0, Vec3::ONE),
    };
    check_factor(specular_factor, "specular factor", &label)?;
    check_color(specular_color, "specular colour factor", &label)?;
    let transmission = m.transmission().map_or(0.0, |t| t.transmission_factor());
    check_factor(transmission, "transmission factor", &label)?;
    let ior = m.ior().unwrap_or(1.5);
    if !(ior.is_finite() && ior > 0.0) {
        return Err(format!(
            "{label}: index of refraction {ior} is not a positive number"
        ));
    }
    let strength = m.emissive_strength().unwrap_or(1.0);
    check_factor(strength, "emissive strength", &label)?;
    let emissive = Vec3::from(m.emissive_factor());
    check_color(emissive, "emissive factor", &label)?;
    let emission = emissive * strength;
    check_color(emission, "emission (factor times strength)", &label)?;

    // F0 of a dielectric from its index of refraction (0.04 for 1.5), as
    // the glTF specification derives it, scaled by KHR_materials_specular.
    let f0_ior = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let dielectric_f0: Color = f0_ior * specular_factor * specular_color;
    let mut material = Material::from_metallic_roughness(
        base,
        metallic,
        roughness,
        dielectric_f0,
        transmission,
        ior,
    );
    material.emission = emission;
    if let Some(v) = m.extension_value("KHR_materials_dispersion") {
        let factor = v.get("dispersion").map_or(Some(0.0), |d| d.as_f64());
        let factor = factor.map(|f| f as f32).unwrap_or(f32::NAN);
        check_factor(factor, "KHR_materials_dispersion: dispersion", &label)?;
        // The extension's factor is 20 / V (V the Abbe number); 0 means
        // no dispersion.
        if factor > 0.0 {
            material.dispersion = Some(
                Dispersion::from_abbe(ior, 20.0 / factor)
                    .map_err(|e| format!("{label}: KHR_materials_dispersion: {e}"))?,
            );
        }
    }
    if let Some(v) = m.volume() {
        material.absorption = volume_absorption(&v).map_err(|e| format!("{label}: {e}"))?;
    }
    if let Some(mr) = material.metallic_roughness.as_mut() {
        mr.specular_factor = specular_factor;
    }
    if let Some(info) = pbr.base_color_texture() {
        material.base_color_texture = Some(texture(
            ctx,
            st,
            &info,
            true,
            "base colour texture",
            &label,
        )?);
    }
    if let Some(info) = pbr.metallic_roughness_texture() {
        let t = texture(ctx, st, &info, false, "metallic-roughness texture", &label)?;
        if let Some(mr) = material.metallic_roughness.as_mut() {
            mr.texture = Some(t);
        }
    }
    let alpha_mode = match m.alpha_mode() {
        gltf::material::AlphaMode::Opaque => None,
        gltf::material::AlphaMode::Mask => {
            let cutoff = m.alpha_cutoff().unwrap_or(0.5);
            check_factor(cutoff, "alpha cutoff", &label)?;
            Some(AlphaMode::Mask { cutoff })
        }
        gltf::material::AlphaMode::Blend => Some(AlphaMode::Blend),
    };
    if let Some(mode) = alpha_mode {
        check_factor(alpha_factor, "base colour alpha", &label)?;
        material.alpha = Some(Alpha {
            mode,
            factor: alpha_factor.min(1.0),
            // The base colour texture's alpha channel (itself, if any).
            texture: material.base_color_texture.clone(),
        });
    }
    if let Some(info) = m.normal_texture() {
        let scale = info.scale();
        if !scale.is_finite() {
            return Err(format!("{label}: normal texture scale is not finite"));
        }
        let tex = normal_texture(ctx, st, &info, &label)?;
        material.normal_map = Some(NormalMap {
            texture: tex,
            scale,
        });
    }
    // The emissive texture only scales the emissive factor: skip decoding
    // it when the factor is zero.
    if let Some(info) = m.emissive_texture()
        && emission != Vec3::ZERO
    {
        material.emission_texture =
            Some(texture(ctx, st, &info, true, "emissive texture", &label)?);
    }
    Ok(material)
}

/// The absorption coefficient of a `KHR_materials_volume` interior:
/// `-ln(attenuationColor) / attenuationDistance` per channel (Beer-Lambert,
/// see [`crate::transport::medium`]). A thin-walled surface
/// (`thicknessFactor` 0) bounds no volume and absorbs nothing; otherwise
/// the distance a ray really travels inside replaces `thicknessFactor`,
/// which the specification offers as an estimate for renderers that
/// cannot trace it.
fn volume_absorption(v: &gltf::material::Volume) -> Result<Color, String> {
    let thickness = v.thickness_factor();
    if !(thickness >= 0.0 && thickness.is_finite()) {
        return Err(format!(
            "KHR_materials_volume: thicknessFactor must be a non-negative number, got {thickness}"
        ));
    }
    let color = Color::from(v.attenuation_color());
    let sigma = optics::absorption_from_attenuation(color, v.attenuation_distance())
        .map_err(|e| format!("KHR_materials_volume: {e}"))?;
    Ok(if thickness == 0.0 { Color::ZERO } else { sigma })
}
