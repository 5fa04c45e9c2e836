//! Materials of the Whitted model and the textures they read.
//!
//! One [`Material`] describes every surface, whether it came from the
//! project's scene format (Phong-style parameters) or from glTF
//! (metallic-roughness, mapped as documented on [`Material::from_metallic_roughness`]).
//!
//! At a hit the material is evaluated into a [`SurfaceSample`]: textures
//! are looked up once and the shading kernels see plain colours.

use std::sync::Arc;

use bevy_ecs::component::Component;
use glam::{Vec2, Vec3};

use crate::core::math::Color;
use crate::core::microfacet::{GltfBrdf, MIN_ALPHA};

/// An RGB(A) image texture in linear space, sampled bilinearly with
/// repeat wrapping.
#[derive(Debug)]
pub struct ImageTexture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major linear RGB texels.
    pub texels: Vec<Vec3>,
}

impl ImageTexture {
    /// Bilinear lookup with repeat wrapping; `uv` (0,0) is the top-left corner.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        if self.width == 0 || self.height == 0 {
            return Vec3::ONE;
        }
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !x.is_finite() || !y.is_finite() {
            return self.texels[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let h = self.height as i64;
        let at = |xi: i64, yi: i64| {
            let xi = xi.rem_euclid(w) as usize;
            let yi = yi.rem_euclid(h) as usize;
            self.texels[yi * self.width as usize + xi]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = at(x0, y0).lerp(at(x0 + 1, y0), fx);
        let bottom = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }
}

/// An affine transform of texture coordinates (`KHR_texture_transform`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Offset added after scale and rotation.
    pub offset: Vec2,
    /// Counter-clockwise rotation in radians.
    pub rotation: f32,
    /// Scale applied first.
    pub scale: Vec2,
}

impl Default for UvTransform {
    fn default() -> Self {
        Self {
            offset: Vec2::ZERO,
            rotation: 0.0,
            scale: Vec2::ONE,
        }
    }
}

impl UvTransform {
    /// Applies scale, rotation, then offset (the order of the glTF extension).
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let s = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        Vec2::new(cos * s.x + sin * s.y, -sin * s.x + cos * s.y) + self.offset
    }
}

/// A colour source: an image or a procedural pattern.
#[derive(Clone, Debug)]
pub enum Texture {
    /// An image, shared between materials.
    Image {
        /// The texels.
        image: Arc<ImageTexture>,
        /// Transform of the texture coordinates before lookup.
        transform: UvTransform,
    },
    /// A checkerboard of squares `1/scale` wide in texture space.
    Checker {
        /// Squares per unit of texture coordinate.
        scale: f32,
        /// Colour of squares where `floor(u*s)+floor(v*s)` is even.
        even: Color,
        /// Colour of the other squares.
        odd: Color,
    },
}

impl Texture {
    /// Colour at texture coordinate `uv`.
    pub fn sample(&self, uv: Vec2) -> Color {
        match self {
            Texture::Image { image, transform } => image.sample(transform.apply(uv)),
            Texture::Checker { scale, even, odd } => {
                let p = (uv * *scale).floor();
                if (p.x as i64 + p.y as i64).rem_euclid(2) == 0 {
                    *even
                } else {
                    *odd
                }
            }
        }
    }
}

/// A surface description for the Whitted model, in physical units.
///
/// Radiance leaving a surface lit by a light of irradiance `E` from
/// direction `l`, seen from `v`:
///
/// `Lo = emission + [diffuse * base/pi + specular * (s+8)/(8 pi) * (n.h)^s] * E * (n.l)`
/// `   + mirror * Li(reflected) + transmission * [F Li(reflected) + (1-F) base * Li(refracted)]`
///
/// The Blinn-Phong lobe is normalised so that `specular` is its directional
/// albedo at normal incidence (approximately); `mirror` and the dielectric
/// term are perfectly specular and carry no highlight.
#[derive(Component, Clone, Debug)]
pub struct Material {
    /// Base (albedo) colour, linear.
    pub base_color: Color,
    /// Optional texture multiplied into `base_color`.
    pub base_color_texture: Option<Texture>,
    /// Weight of the Lambertian lobe (`kd`), in `[0, 1]`.
    pub diffuse: f32,
    /// Colour of the Blinn-Phong highlight (`ks`).
    pub specular: Color,
    /// Blinn-Phong exponent (`s`), at least 1.
    pub shininess: f32,
    /// Perfect-mirror reflectance per channel.
    pub mirror: Color,
    /// Weight of the smooth dielectric lobe, in `[0, 1]`.
    pub transmission: f32,
    /// Index of refraction of the inside, relative to the outside medium.
    pub ior: f32,
    /// Emitted radiance (W sr^-1 m^-2 in the renderer's units).
    pub emission: Color,
    /// Optional texture multiplied into `emission`.
    pub emission_texture: Option<Texture>,
    /// glTF metallic-roughness texture (roughness in G, metallic in B);
    /// when present the surface is re-derived per hit, see
    /// [`Material::from_metallic_roughness`].
    pub metallic_roughness: Option<MetallicRoughness>,
}

/// The glTF parameters kept for per-hit evaluation of a textured
/// metallic-roughness material.
#[derive(Clone, Debug)]
pub struct MetallicRoughness {
    /// Metallic factor.
    pub metallic: f32,
    /// Roughness factor.
    pub roughness: f32,
    /// Texture with roughness in G and metallic in B (linear).
    pub texture: Option<Texture>,
    /// Dielectric F0 (0.04 scaled by `KHR_materials_specular`).
    pub dielectric_f0: Color,
    /// `KHR_materials_specular`'s factor (1 without the extension): the
    /// dielectric's F90 in path transport's microfacet BRDF, by which
    /// `dielectric_f0` is already scaled.
    pub specular_factor: f32,
}

impl Default for Material {
    /// A white Lambertian surface.
    fn default() -> Self {
        Self {
            base_color: Color::splat(0.8),
            base_color_texture: None,
            diffuse: 1.0,
            specular: Color::ZERO,
            shininess: 1.0,
            mirror: Color::ZERO,
            transmission: 0.0,
            ior: 1.5,
            emission: Color::ZERO,
            emission_texture: None,
            metallic_roughness: None,
        }
    }
}

/// Which shading kernel a material needs: the wavefront integrator sorts
/// hits into one queue per class so that each kernel handles one kind of
/// surface without branching on it. What each class does (is it lit, does
/// it scatter) is the one table in [`crate::scene::features`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MaterialClass {
    /// Only emission (or nothing): no lights, no secondary rays.
    Emissive,
    /// Lambert and/or Blinn-Phong lobes lit by the lights, no secondary rays.
    Diffuse,
    /// A perfect mirror only.
    Mirror,
    /// A smooth dielectric only.
    Glass,
    /// Any combination of the above (glTF materials are always here).
    General,
}

impl MaterialClass {
    /// Every class, in the order the wavefront shades them.
    pub const ALL: [MaterialClass; 5] = [
        MaterialClass::Emissive,
        MaterialClass::Diffuse,
        MaterialClass::Mirror,
        MaterialClass::Glass,
        MaterialClass::General,
    ];
}

/// A material evaluated at one surface point: what the shading kernels read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// Lambertian albedo (already multiplied by the diffuse weight).
    pub diffuse: Color,
    /// Blinn-Phong highlight colour.
    pub specular: Color,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Mirror reflectance.
    pub mirror: Color,
    /// Dielectric weight.
    pub transmission: f32,
    /// Tint applied to refracted light.
    pub transmission_tint: Color,
    /// Relative index of refraction.
    pub ior: f32,
    /// Emitted radiance.
    pub emission: Color,
    /// Base colour with its texture (what Gooch shading tones).
    pub base: Color,
    /// Weight of the diffuse lobe: `diffuse` is `base` times this.
    pub diffuse_weight: f32,
    /// The glTF metallic-roughness BRDF, which path transport uses in
    /// place of the Whitted lobes `diffuse`, `specular` and `mirror`
    /// (Whitted transport keeps those). `None` for the project's own
    /// materials and for glTF surfaces without a specular layer (metallic
    /// 0 and `KHR_materials_specular` 0, or full transmission): those are
    /// exactly Lambertian.
    pub gltf: Option<GltfBrdf>,
}

/// The Whitted lobes that a glTF metallic-roughness surface maps to.
struct MrLobes {
    diffuse: Color,
    specular: Color,
    shininess: f32,
    mirror: Color,
}

/// Roughness below which a glTF surface is treated as a perfect mirror
/// with no highlight (its highlight would be narrower than a pixel).
const MIRROR_ROUGHNESS: f32 = 0.02;

fn map_metallic_roughness(
    base: Color,
    metallic: f32,
    roughness: f32,
    dielectric_f0: Color,
    transmission: f32,
) -> MrLobes {
    let metallic = metallic.clamp(0.0, 1.0);
    let roughness = roughness.clamp(0.0, 1.0);
    let f0 = dielectric_f0.lerp(base, metallic);
    let diffuse = base * (1.0 - metallic) * (1.0 - transmission);
    // The specular lobe is split between a perfect mirror (sharp part) and a
    // Blinn-Phong highlight (blurred part); smoothness decides the split.
    let smooth = (1.0 - roughness) * (1.0 - roughness);
    let (mirror_w, highlight_w) = if roughness < MIRROR_ROUGHNESS {
        (1.0, 0.0)
    } else {
        (smooth, 1.0 - smooth)
    };
    // Beckmann-to-Phong exponent for alpha = roughness^2.
    let alpha = (roughness * roughness).max(1e-4);
    let shininess = (2.0 / (alpha * alpha) - 2.0).clamp(1.0, 1.0e4);
    // The dielectric lobe already carries its own Fresnel reflection.
    let spec_scale = 1.0 - transmission * (1.0 - metallic);
    MrLobes {
        diffuse,
        specular: f0 * highlight_w * spec_scale,
        shininess,
        mirror: f0 * mirror_w * spec_scale,
    }
}

impl Material {
    /// Maps glTF metallic-roughness parameters onto the Whitted model:
    ///
    /// * `F0 = mix(dielectric_f0, base, metallic)` where `dielectric_f0` is
    ///   0.04 times the `KHR_materials_specular` factor and colour (so a
    ///   specular factor of 0 leaves a pure Lambertian surface);
    /// * diffuse albedo `base * (1 - metallic) * (1 - transmission)`;
    /// * the specular lobe of weight `F0` is split into a perfect mirror of
    ///   weight `F0 (1-r)^2` and a Blinn-Phong highlight of weight
    ///   `F0 (1 - (1-r)^2)` with exponent `2/r^4 - 2` (the usual
    ///   Beckmann-to-Phong match); below roughness 0.02 it is all mirror;
    /// * `transmission` (from `KHR_materials_transmission`) makes the
    ///   dielectric part a smooth glass of index `ior`, tinted by `base`.
    ///
    /// Metallic 1, roughness 0 therefore gives a perfect mirror tinted by
    /// the base colour.
    pub fn from_metallic_roughness(
        base: Color,
        metallic: f32,
        roughness: f32,
        dielectric_f0: Color,
        transmission: f32,
        ior: f32,
    ) -> Self {
        Self {
            base_color: base,
            transmission: transmission.clamp(0.0, 1.0),
            ior,
            metallic_roughness: Some(MetallicRoughness {
                metallic,
                roughness,
                texture: None,
                dielectric_f0,
                specular_factor: 1.0,
            }),
            ..Default::default()
        }
    }

    /// The shading kernel this material needs. A class never omits a lobe
    /// the material has, so shading by class gives exactly the radiance of
    /// shading every lobe.
    pub fn class(&self) -> MaterialClass {
        if self.metallic_roughness.is_some() {
            return MaterialClass::General;
        }
        let lit = (self.diffuse > 0.0 && self.base_color.max_element() > 0.0)
            || self.specular.max_element() > 0.0;
        let mirror = self.mirror.max_element() > 0.0;
        let glass = self.transmission > 0.0;
        match (lit, mirror, glass) {
            (false, false, false) => MaterialClass::Emissive,
            (true, false, false) => MaterialClass::Diffuse,
            (false, true, false) => MaterialClass::Mirror,
            (false, false, true) => MaterialClass::Glass,
            _ => MaterialClass::General,
        }
    }

    /// Evaluates the material at texture coordinate `uv`.
    pub fn sample(&self, uv: Vec2) -> SurfaceSample {
        let mut base = self.base_color;
        if let Some(t) = &self.base_color_texture {
            base *= t.sample(uv);
        }
        let mut emission = self.emission;
        if let Some(t) = &self.emission_texture {
            emission *= t.sample(uv);
        }
        if let Some(mr) = &self.metallic_roughness {
            let (mut metallic, mut roughness) = (mr.metallic, mr.roughness);
            if let Some(t) = &mr.texture {
                let texel = t.sample(uv);
                roughness *= texel.y;
                metallic *= texel.z;
            }
            let transmission = self.transmission;
            let lobes =
                map_metallic_roughness(base, metallic, roughness, mr.dielectric_f0, transmission);
            let gltf = gltf_brdf(base, metallic, roughness, mr, transmission);
            return SurfaceSample {
                diffuse: lobes.diffuse,
                specular: lobes.specular,
                shininess: lobes.shininess,
                mirror: lobes.mirror,
                transmission: transmission * (1.0 - metallic),
                transmission_tint: base,
                ior: self.ior,
                emission,
                base,
                diffuse_weight: (1.0 - metallic.clamp(0.0, 1.0)) * (1.0 - transmission),
                gltf,
            };
        }
        SurfaceSample {
            diffuse: base * self.diffuse,
            specular: self.specular,
            shininess: self.shininess,
            mirror: self.mirror,
            transmission: self.transmission,
            transmission_tint: base,
            ior: self.ior,
            emission,
            base,
            diffuse_weight: self.diffuse,
            gltf: None,
        }
    }
}

/// The glTF BRDF of a metallic-roughness surface at one point, or `None`
/// when it has no specular layer (then its path-traced BRDF is the
/// Lambertian `diffuse` lobe, exactly as before the microfacet model).
fn gltf_brdf(
    base: Color,
    metallic: f32,
    roughness: f32,
    mr: &MetallicRoughness,
    transmission: f32,
) -> Option<GltfBrdf> {
    let metallic = metallic.clamp(0.0, 1.0);
    let roughness = roughness.clamp(0.0, 1.0);
    let w = mr.specular_factor.max(0.0);
    let dielectric_weight = (1.0 - metallic) * (1.0 - transmission);
    if !(metallic > 0.0 || (dielectric_weight > 0.0 && w > 0.0)) {
        return None;
    }
    Some(GltfBrdf {
        alpha: (roughness * roughness).max(MIN_ALPHA),
        metallic,
        metal_f0: base,
        dielectric_weight,
        // `dielectric_f0` is `w * F0(ior) * colour`; the specification
        // clamps `F0(ior) * colour` to 1 before weighting.
        dielectric_f0: mr.dielectric_f0.min(Color::splat(w)),
        dielectric_f90: w,
        diffuse: base * dielectric_weight,
    })
}
