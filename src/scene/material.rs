//! Materials of the Whitted model and the textures they read.
//!
//! One [`Material`] describes every surface, whether it came from the
//! project's scene format (Phong-style parameters) or from glTF
//! (metallic-roughness, mapped as documented on [`Material::from_metallic_roughness`]).
//!
//! At a hit the material is evaluated into a [`SurfaceSample`]: textures
//! are looked up once and the shading kernels see plain colours.

use crate::core::medium::Medium;
use std::sync::Arc;

use bevy_ecs::component::Component;
use glam::{Vec2, Vec3};

use crate::core::math::Color;
use crate::core::microfacet::{GltfBrdf, MIN_ALPHA};
use crate::core::spectrum::Dispersion;

/// An RGB(A) image texture in linear space.
#[derive(Debug)]
pub struct ImageTexture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major linear RGB texels.
    pub texels: Vec<Vec3>,
    /// Row-major alpha (coverage) of each texel, or empty when the image
    /// has no alpha channel (opaque).
    pub alpha: Vec<f32>,
    /// The mipmap levels below the full-resolution image: level `k` (at
    /// index `k - 1`) halves level `k - 1` in each dimension (rounded
    /// down, at least 1) by averaging its 2x2 (or, for odd sizes, up to
    /// 3x3) blocks, down to 1x1.
    levels: Vec<MipLevel>,
}

/// One reduced-resolution copy of an [`ImageTexture`] (colour only).
#[derive(Debug)]
struct MipLevel {
    width: u32,
    height: u32,
    texels: Vec<Vec3>,
}

impl MipLevel {
    /// The next smaller level of the `width` x `height` `texels`: texel
    /// `(i, j)` averages source columns `[2i, 2i+1]` and rows
    /// `[2j, 2j+1]`, with the last column (row) of an odd size folded into
    /// the last texel, so every source texel counts and the mean of the
    /// image is kept up to rounding.
    fn halve(width: u32, height: u32, texels: &[Vec3]) -> MipLevel {
        let (w, h) = ((width / 2).max(1), (height / 2).max(1));
        let span = |i: u32, n: u32, m: u32| {
            let start = (2 * i).min(n - 1);
            let end = if i + 1 == m { n } else { (2 * i + 2).min(n) };
            start..end
        };
        let mut out = Vec::with_capacity((w * h) as usize);
        for j in 0..h {
            let rows = span(j, height, h);
            for i in 0..w {
                let cols = span(i, width, w);
                let mut sum = Vec3::ZERO;
                let mut n = 0.0;
                for y in rows.clone() {
                    for x in cols.clone() {
                        sum += texels[(y * width + x) as usize];
                        n += 1.0;
                    }
                }
                out.push(sum / n);
            }
        }
        MipLevel {
            width: w,
            height: h,
            texels: out,
        }
    }
}

/// The texel indices and fractions of a lookup at `uv` in a `width` x
/// `height` image with `sampler` (see [`ImageTexture::taps`]).
#[inline]
fn taps_in(
    width: u32,
    height: u32,
    uv: Vec2,
    sampler: TextureSampler,
) -> Option<([usize; 4], f32, f32)> {
    if width == 0 || height == 0 {
        return None;
    }
    let (w, h) = (width as i64, height as i64);
    let at = |xi: i64, yi: i64| {
        sampler.wrap_v.index(yi, h) * width as usize + sampler.wrap_u.index(xi, w)
    };
    if !sampler.linear {
        let x = uv.x * width as f32;
        let y = uv.y * height as f32;
        if !x.is_finite() || !y.is_finite() {
            return None;
        }
        let i = at(x.floor() as i64, y.floor() as i64);
        return Some(([i; 4], 0.0, 0.0));
    }
    let x = uv.x * width as f32 - 0.5;
    let y = uv.y * height as f32 - 0.5;
    if !x.is_finite() || !y.is_finite() {
        return None;
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    Some((
        [
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        ],
        fx,
        fy,
    ))
}

/// Bilinear (or nearest) lookup in `texels` of a `width` x `height` image.
#[inline]
fn bilinear(width: u32, height: u32, texels: &[Vec3], uv: Vec2, sampler: TextureSampler) -> Vec3 {
    let Some(([a, b, c, d], fx, fy)) = taps_in(width, height, uv, sampler) else {
        return texels.first().copied().unwrap_or(Vec3::ONE);
    };
    let top = texels[a].lerp(texels[b], fx);
    let bottom = texels[c].lerp(texels[d], fx);
    top.lerp(bottom, fy)
}

/// How texture coordinates outside `[0, 1]` are mapped (glTF sampler
/// `wrapS` / `wrapT`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// The image repeats (the default).
    #[default]
    Repeat,
    /// The image repeats, mirrored every other time.
    MirroredRepeat,
    /// Coordinates are clamped to the edge texels.
    ClampToEdge,
}

impl Wrap {
    /// The texel index for integer coordinate `i` of an axis of `n` texels.
    #[inline]
    fn index(self, i: i64, n: i64) -> usize {
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
            Wrap::ClampToEdge => i.clamp(0, n - 1),
        }) as usize
    }
}

/// How an image texture is read between texels (glTF sampler filters).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureSampler {
    /// Wrapping of `u`.
    pub wrap_u: Wrap,
    /// Wrapping of `v`.
    pub wrap_v: Wrap,
    /// Bilinear interpolation (true, the default) or the nearest texel.
    pub linear: bool,
}

impl Default for TextureSampler {
    fn default() -> Self {
        Self {
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
            linear: true,
        }
    }
}

impl ImageTexture {
    /// An opaque texture of `width` x `height` row-major texels, with its
    /// mipmaps.
    pub fn new(width: u32, height: u32, texels: Vec<Vec3>) -> Self {
        Self::with_alpha(width, height, texels, Vec::new())
    }

    /// A texture with an alpha channel (`alpha` empty: opaque), with its
    /// mipmaps (of the colour; alpha is read at full resolution).
    pub fn with_alpha(width: u32, height: u32, texels: Vec<Vec3>, alpha: Vec<f32>) -> Self {
        let mut levels: Vec<MipLevel> = Vec::new();
        if texels.len() == (width as usize) * (height as usize) {
            let (mut w, mut h) = (width, height);
            while w > 1 || h > 1 {
                let next = match levels.last() {
                    Some(l) => MipLevel::halve(w, h, &l.texels),
                    None => MipLevel::halve(w, h, &texels),
                };
                (w, h) = (next.width, next.height);
                levels.push(next);
            }
        }
        Self {
            width,
            height,
            texels,
            alpha,
            levels,
        }
    }

    /// Number of mipmap levels, the full-resolution image included.
    pub fn level_count(&self) -> usize {
        self.levels.len() + 1
    }

    /// The size of mipmap level `level` (0: full resolution), clamped to
    /// the last level.
    pub fn level_size(&self, level: usize) -> (u32, u32) {
        match level.min(self.levels.len()) {
            0 => (self.width, self.height),
            k => (self.levels[k - 1].width, self.levels[k - 1].height),
        }
    }

    /// The (fractional) mipmap level for a footprint `width_uv` wide in
    /// texture coordinates: `log2` of the footprint in texels of the
    /// full-resolution image, `log2(width_uv * sqrt(width * height))`
    /// (the ray-cone rule for an isotropic footprint). At most 0 (or not
    /// finite) reads the full-resolution image.
    #[inline]
    pub fn level_of(&self, width_uv: f32) -> f32 {
        let texels = width_uv * ((self.width as f32) * (self.height as f32)).sqrt();
        texels.log2()
    }

    /// Bilinear lookup with repeat wrapping; `uv` (0,0) is the top-left corner.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        self.sample_with(uv, TextureSampler::default())
    }

    /// The texels of a lookup at `uv` with `sampler`: the four texel
    /// indices of the bilinear footprint (top-left, top-right, bottom-left,
    /// bottom-right; all four the same texel for nearest filtering) and
    /// the fractions `(fx, fy)` between them; `None` when the image is
    /// empty or the texel coordinates are not finite.
    #[inline]
    fn taps(&self, uv: Vec2, sampler: TextureSampler) -> Option<([usize; 4], f32, f32)> {
        taps_in(self.width, self.height, uv, sampler)
    }

    /// Lookup with `sampler`'s wrapping and filter; `uv` (0,0) is the
    /// top-left corner. Non-finite coordinates read the first texel.
    pub fn sample_with(&self, uv: Vec2, sampler: TextureSampler) -> Vec3 {
        bilinear(self.width, self.height, &self.texels, uv, sampler)
    }

    /// Lookup at mipmap level `level` (fractional: the two levels around
    /// it are blended, trilinear filtering). A level of at most 0, or a
    /// nearest-filtered sampler, reads the full-resolution image exactly
    /// as [`ImageTexture::sample_with`]; levels beyond the last read the
    /// last (1x1) level.
    pub fn sample_level(&self, uv: Vec2, sampler: TextureSampler, level: f32) -> Vec3 {
        // `!(level > 0)` also catches NaN.
        if !(level > 0.0) || !sampler.linear || self.levels.is_empty() {
            return self.sample_with(uv, sampler);
        }
        let last = self.levels.len();
        let read = |k: usize| match k {
            0 => self.sample_with(uv, sampler),
            k => {
                let l = &self.levels[k - 1];
                bilinear(l.width, l.height, &l.texels, uv, sampler)
            }
        };
        if level >= last as f32 {
            return read(last);
        }
        let k = level.floor();
        let f = level - k;
        let k = k as usize;
        let lo = read(k);
        if f == 0.0 {
            return lo;
        }
        lo.lerp(read(k + 1), f)
    }

    /// Alpha at `uv` with `sampler` (1 for an image without alpha).
    pub fn alpha_with(&self, uv: Vec2, sampler: TextureSampler) -> f32 {
        let al = &self.alpha;
        if al.is_empty() {
            return 1.0;
        }
        let Some(([a, b, c, d], fx, fy)) = self.taps(uv, sampler) else {
            return al[0];
        };
        let lerp = |p: f32, q: f32, f: f32| p + (q - p) * f;
        lerp(lerp(al[a], al[b], fx), lerp(al[c], al[d], fx), fy)
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
        /// Wrapping and filtering.
        sampler: TextureSampler,
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
            Texture::Image {
                image,
                transform,
                sampler,
            } => image.sample_with(transform.apply(uv), *sampler),
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

impl Texture {
    /// Colour at texture coordinate `uv` for a footprint `width_uv` wide in
    /// texture coordinates (texture level of detail; 0 reads exactly what
    /// [`Texture::sample`] reads). An image reads its mipmaps at the level
    /// where the footprint (scaled by the texture transform) covers one
    /// texel ([`ImageTexture::level_of`], [`ImageTexture::sample_level`]).
    /// A checkerboard whose squares are at least four times wider than the
    /// footprint is read exactly; otherwise it is box-filtered over the
    /// footprint analytically (the mean of the pattern over a square of
    /// that width), so that distant squares blend to their mean instead of
    /// aliasing.
    pub fn sample_lod(&self, uv: Vec2, width_uv: f32) -> Color {
        if !(width_uv > 0.0) {
            return self.sample(uv);
        }
        match self {
            Texture::Image {
                image,
                transform,
                sampler,
            } => {
                let stretch = (transform.scale.x * transform.scale.y).abs().sqrt();
                let level = image.level_of(width_uv * stretch);
                image.sample_level(transform.apply(uv), *sampler, level)
            }
            Texture::Checker { scale, even, odd } => {
                let w = width_uv * *scale;
                if w < 0.25 || !w.is_finite() {
                    return self.sample(uv);
                }
                let p = uv * *scale;
                // The mean over [p - w/2, p + w/2] of the square wave that
                // is +1 on even unit intervals and -1 on odd ones: its
                // antiderivative is -2 |fract(x/2) - 1/2|.
                let tri = |x: f32| 2.0 * ((x * 0.5 - (x * 0.5).floor()) - 0.5).abs();
                let mean = |x: f32| (tri(x - 0.5 * w) - tri(x + 0.5 * w)) / w;
                let even_fraction = 0.5 * (1.0 + mean(p.x) * mean(p.y));
                *odd + (*even - *odd) * even_fraction
            }
        }
    }

    /// Alpha (coverage) at `uv`: the image's alpha channel, 1 for images
    /// without one and for procedural textures.
    pub fn alpha(&self, uv: Vec2) -> f32 {
        match self {
            Texture::Image {
                image,
                transform,
                sampler,
            } => image.alpha_with(transform.apply(uv), *sampler),
            Texture::Checker { .. } => 1.0,
        }
    }
}

/// How a surface's alpha (coverage) is used (glTF `alphaMode`; `OPAQUE`
/// is the absence of an [`Alpha`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaMode {
    /// Cut-out: where alpha is below `cutoff` the surface does not exist,
    /// for every ray (camera, shadow and scattered rays alike).
    Mask {
        /// Alpha below which the surface is cut away (glTF default 0.5).
        cutoff: f32,
    },
    /// Transparency: a ray passes through the surface with probability
    /// `1 - alpha` (stochastic transparency, decided by a hash of the ray
    /// and the hit, so it is the same for the same ray whatever the
    /// thread; averaged over a pixel's samples it blends the surface with
    /// what is behind it).
    Blend,
}

/// A surface's coverage: `factor` times the alpha channel of `texture`
/// (glTF's base colour factor and texture alpha), used as `mode` says.
#[derive(Clone, Debug)]
pub struct Alpha {
    /// Cut-out or transparency.
    pub mode: AlphaMode,
    /// Constant alpha factor.
    pub factor: f32,
    /// Texture whose alpha channel scales `factor`.
    pub texture: Option<Texture>,
}

impl Alpha {
    /// Coverage at texture coordinate `uv`.
    #[inline]
    pub fn coverage(&self, uv: Vec2) -> f32 {
        match &self.texture {
            Some(t) => self.factor * t.alpha(uv),
            None => self.factor,
        }
    }

    /// True when a ray passes through the surface at `uv`; `u` is the ray's
    /// uniform number in `[0, 1)` for stochastic transparency (see
    /// [`AlphaMode::Blend`]).
    #[inline]
    pub fn passes(&self, uv: Vec2, u: f32) -> bool {
        let a = self.coverage(uv);
        match self.mode {
            AlphaMode::Mask { cutoff } => !(a >= cutoff),
            AlphaMode::Blend => !(u < a),
        }
    }
}

/// A tangent-space normal map (glTF `normalTexture`): texel `(r, g, b)` is
/// the vector `(2r-1, 2g-1, 2b-1)` in the frame (tangent, bitangent,
/// normal), with `x` and `y` multiplied by `scale`. The bitangent is
/// `w * cross(normal, tangent)` from the mesh's tangents
/// ([`Mesh::with_tangents`](crate::geometry::mesh::Mesh::with_tangents)):
/// glTF's convention, green pointing "up" in the image, towards
/// decreasing `v`.
#[derive(Clone, Debug)]
pub struct NormalMap {
    /// The map (linear, not sRGB).
    pub texture: Texture,
    /// glTF `normalTexture.scale`.
    pub scale: f32,
}

impl NormalMap {
    /// The unit tangent-space normal at `uv` (a zero texel vector gives
    /// `(0, 0, 1)`, the unmapped normal).
    #[inline]
    pub fn normal(&self, uv: Vec2) -> Vec3 {
        let t = self.texture.sample(uv) * 2.0 - Vec3::ONE;
        let n = Vec3::new(t.x * self.scale, t.y * self.scale, t.z);
        n.try_normalize().unwrap_or(Vec3::Z)
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
    /// Absorption coefficient `sigma_a` of the object's interior, per
    /// channel, in inverse scene units (zero: a clear or opaque interior).
    /// A ray that travels a distance `d` inside the object, from entering
    /// its surface to leaving it, is attenuated by `exp(-sigma_a d)`
    /// (Beer-Lambert); see [`crate::transport::medium`].
    pub absorption: Color,
    /// Scattering coefficient `sigma_s` of the object's interior, per
    /// channel, in inverse scene units (zero: the interior only absorbs).
    /// With it the interior is a participating medium that path transport
    /// scatters in (see `transport::volume`); the object must be closed.
    pub scattering: Color,
    /// Henyey-Greenstein asymmetry `g` of the interior's scattering, in
    /// `(-1, 1)`.
    pub phase_g: f32,
    /// A subsurface material: under path transport the surface is a
    /// diffuse-transmission boundary into the scattering interior (light
    /// enters with cosine-distributed directions and leaves through a
    /// Lambertian transmission; see `transport::volume::diffuse_crossing`)
    /// instead of the dielectric its other fields describe, which Whitted
    /// and photon transport keep.
    pub subsurface: bool,
    /// How the index of refraction depends on wavelength (`None`: it does
    /// not, `ior` holds for every wavelength). A scene with a dispersive
    /// material is path traced spectrally (see [`crate::core::spectrum`]);
    /// other transports use `ior`.
    pub dispersion: Option<Dispersion>,
    /// Emitted radiance (W sr^-1 m^-2 in the renderer's units).
    pub emission: Color,
    /// Optional texture multiplied into `emission`.
    pub emission_texture: Option<Texture>,
    /// glTF metallic-roughness texture (roughness in G, metallic in B);
    /// when present the surface is re-derived per hit, see
    /// [`Material::from_metallic_roughness`].
    pub metallic_roughness: Option<MetallicRoughness>,
    /// Coverage (glTF `alphaMode` MASK or BLEND); `None`: opaque. Read by
    /// intersection queries, which skip the surface where it is cut away.
    pub alpha: Option<Alpha>,
    /// Tangent-space normal map; applied to the shading normal of meshes
    /// (which provide the tangents) when their hits are completed.
    pub normal_map: Option<NormalMap>,
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
            absorption: Color::ZERO,
            scattering: Color::ZERO,
            phase_g: 0.0,
            subsurface: false,
            dispersion: None,
            emission: Color::ZERO,
            emission_texture: None,
            metallic_roughness: None,
            alpha: None,
            normal_map: None,
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
    /// Absorption coefficient of the interior behind this surface
    /// ([`Material::absorption`]).
    pub absorption: Color,
    /// [`Material::dispersion`].
    pub dispersion: Option<Dispersion>,
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
        // A subsurface boundary is lit and scatters diffusely under path
        // transport; under Whitted transport its dielectric lobe is all
        // the general kernel finds.
        if self.metallic_roughness.is_some() || self.subsurface {
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

    /// The medium filling the object's interior: `None` when it is clear
    /// (no absorption, no scattering).
    #[inline]
    pub fn interior(&self) -> Option<Medium> {
        let m = Medium {
            sigma_a: self.absorption,
            sigma_s: self.scattering,
            g: self.phase_g,
        };
        (!m.is_clear()).then_some(m)
    }

    /// True when the interior scatters light (a participating medium, not
    /// only an absorber).
    #[inline]
    pub fn has_scattering_interior(&self) -> bool {
        self.scattering.max_element() > 0.0
    }

    /// True when the surface is an index-matched boundary that path
    /// transport crosses without a bounce: a smooth dielectric of index 1,
    /// full transmission, white tint, nothing else (no other lobe, no
    /// emission, no texture, no dispersion, no cut-out). It only marks
    /// where a medium begins and ends.
    #[inline]
    pub fn is_interface(&self) -> bool {
        self.class() == MaterialClass::Glass
            && self.transmission == 1.0
            && self.ior == 1.0
            && self.base_color == Color::ONE
            && self.base_color_texture.is_none()
            && self.emission == Color::ZERO
            && self.dispersion.is_none()
            && self.alpha.is_none()
    }

    /// True when a lookup of the material depends on its texture level of
    /// detail: it has a colour, emission or metallic-roughness texture.
    #[inline]
    pub fn has_textures(&self) -> bool {
        self.base_color_texture.is_some()
            || self.emission_texture.is_some()
            || self
                .metallic_roughness
                .as_ref()
                .is_some_and(|mr| mr.texture.is_some())
    }

    /// Emitted radiance at texture coordinate `uv` (full-resolution
    /// texture): [`Material::sample`]'s `emission` without evaluating the
    /// rest of the surface (next-event estimation reads it at every light
    /// sample).
    #[inline]
    pub fn emission_at(&self, uv: Vec2) -> Color {
        match &self.emission_texture {
            Some(t) => self.emission * t.sample_lod(uv, 0.0),
            None => self.emission,
        }
    }

    /// Evaluates the material at texture coordinate `uv` (full-resolution
    /// textures).
    pub fn sample(&self, uv: Vec2) -> SurfaceSample {
        self.sample_lod(uv, 0.0)
    }

    /// Evaluates the material at texture coordinate `uv` with a footprint
    /// `width_uv` wide in texture coordinates: colour, emission and
    /// metallic-roughness textures are read at that level of detail
    /// ([`Texture::sample_lod`]); 0 is [`Material::sample`].
    pub fn sample_lod(&self, uv: Vec2, width_uv: f32) -> SurfaceSample {
        let mut base = self.base_color;
        if let Some(t) = &self.base_color_texture {
            base *= t.sample_lod(uv, width_uv);
        }
        let mut emission = self.emission;
        if let Some(t) = &self.emission_texture {
            emission *= t.sample_lod(uv, width_uv);
        }
        if let Some(mr) = &self.metallic_roughness {
            let (mut metallic, mut roughness) = (mr.metallic, mr.roughness);
            if let Some(t) = &mr.texture {
                let texel = t.sample_lod(uv, width_uv);
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
                absorption: self.absorption,
                dispersion: self.dispersion,
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
            absorption: self.absorption,
            dispersion: self.dispersion,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3x1 image with texels 0, 1, 2 (red channel) and alpha 0, 0.5, 1.
    fn strip() -> ImageTexture {
        ImageTexture {
            alpha: vec![0.0, 0.5, 1.0],
            ..ImageTexture::new(3, 1, (0..3).map(|i| Vec3::splat(i as f32)).collect())
        }
    }

    /// Mipmaps, worked by hand on a 4x2 image of texels 0..8 (rows 0..4
    /// and 4..8): level 1 averages 2x2 blocks (2.5 and 4.5), level 2 is the
    /// mean (3.5) and is read beyond the last level; a fractional level
    /// blends the two around it; a level of at most 0 (or NaN), or a
    /// nearest-filtered sampler, is the plain lookup bit for bit; an odd
    /// size folds its last texel into the last block; `level_of` is `log2`
    /// of the footprint in texels.
    #[test]
    fn mipmaps_average_blocks_and_blend_levels() {
        let t = ImageTexture::new(4, 2, (0..8).map(|i| Vec3::splat(i as f32)).collect());
        assert_eq!(t.level_count(), 3);
        assert_eq!(t.level_size(1), (2, 1));
        assert_eq!(t.level_size(2), (1, 1));
        assert_eq!(t.level_size(9), (1, 1));
        let s = TextureSampler {
            wrap_u: Wrap::ClampToEdge,
            wrap_v: Wrap::ClampToEdge,
            linear: true,
        };
        let (left, right) = (Vec2::new(0.25, 0.5), Vec2::new(0.75, 0.5));
        assert_eq!(t.sample_level(left, s, 1.0), Vec3::splat(2.5));
        assert_eq!(t.sample_level(right, s, 1.0), Vec3::splat(4.5));
        assert_eq!(
            t.sample_level(Vec2::new(0.3, 0.1), s, 2.0),
            Vec3::splat(3.5)
        );
        assert_eq!(
            t.sample_level(Vec2::new(0.3, 0.1), s, 7.5),
            Vec3::splat(3.5)
        );
        assert!(
            (t.sample_level(left, s, 1.5) - Vec3::splat(3.0))
                .abs()
                .max_element()
                < 1e-6
        );
        assert!(
            (t.sample_level(left, s, 0.25).x - (0.75 * t.sample_with(left, s).x + 0.25 * 2.5))
                .abs()
                < 1e-6
        );
        let nearest = TextureSampler { linear: false, ..s };
        for (uv, level) in [(left, 0.0), (right, -3.0), (Vec2::new(0.6, 0.2), f32::NAN)] {
            assert_eq!(t.sample_level(uv, s, level), t.sample_with(uv, s));
            assert_eq!(t.sample_level(uv, nearest, 2.0), t.sample_with(uv, nearest));
        }
        let odd = ImageTexture::new(3, 1, (0..3).map(|i| Vec3::splat(i as f32)).collect());
        assert_eq!(odd.level_count(), 2);
        assert_eq!(odd.sample_level(Vec2::splat(0.5), s, 1.0), Vec3::splat(1.0));
        assert!((t.level_of(1.0 / 8f32.sqrt())).abs() < 1e-6);
        assert!((t.level_of(4.0 / 8f32.sqrt()) - 2.0).abs() < 1e-6);
    }

    /// The filtered checkerboard is the mean of the pattern over the
    /// footprint's square, checked against a 400x400 grid average
    /// (tolerance: the grid misplaces at most 4 of its 400 lines per
    /// square edge it crosses); a footprint under a quarter square reads
    /// the pattern exactly.
    #[test]
    fn filtered_checker_is_the_box_mean_of_the_pattern() {
        let c = Texture::Checker {
            scale: 2.0,
            even: Color::new(1.0, 0.5, 0.0),
            odd: Color::new(0.0, 0.25, 1.0),
        };
        for (uv, w) in [
            (Vec2::new(0.13, 0.71), 0.3),
            (Vec2::new(-1.4, 2.05), 0.9),
            (Vec2::new(3.3, -0.2), 2.6),
        ] {
            let n = 400;
            let mut sum = Color::ZERO;
            for j in 0..n {
                for i in 0..n {
                    let d = (Vec2::new(i as f32, j as f32) + 0.5) / n as f32 - 0.5;
                    sum += c.sample(uv + d * w);
                }
            }
            let brute = sum / (n * n) as f32;
            let got = c.sample_lod(uv, w);
            assert!(
                (got - brute).abs().max_element() < 0.02,
                "uv {uv}, width {w}: filtered {got}, grid mean {brute}"
            );
        }
        let uv = Vec2::new(0.37, 0.12);
        assert_eq!(c.sample_lod(uv, 0.1), c.sample(uv));
    }

    /// Texel indices of each wrap mode, worked by hand for a 3-texel axis.
    #[test]
    fn wrap_modes_index_texels() {
        let idx = |w: Wrap| (-4..7).map(|i| w.index(i, 3)).collect::<Vec<_>>();
        assert_eq!(idx(Wrap::Repeat), [2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0]);
        assert_eq!(idx(Wrap::MirroredRepeat), [2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0]);
        assert_eq!(idx(Wrap::ClampToEdge), [0, 0, 0, 0, 0, 1, 2, 2, 2, 2, 2]);
    }

    /// Nearest filtering reads one texel; linear interpolates between
    /// texel centres; clamping holds the edge texel beyond the image,
    /// where repeat wraps around to the other side.
    #[test]
    fn samplers_filter_and_wrap() {
        let t = strip();
        let nearest = TextureSampler {
            linear: false,
            ..Default::default()
        };
        let clamp = TextureSampler {
            wrap_u: Wrap::ClampToEdge,
            ..Default::default()
        };
        let at = |u: f32, s: TextureSampler| t.sample_with(Vec2::new(u, 0.5), s).x;
        assert_eq!(at(0.5, nearest), 1.0);
        assert_eq!(at(0.6, nearest), 1.0);
        assert_eq!(at(0.7, nearest), 2.0);
        // Between the centres of texels 1 and 2 (u = 1/2 and 5/6).
        assert!((at(2.0 / 3.0, TextureSampler::default()) - 1.5).abs() < 1e-6);
        // Beyond the right edge: clamp stays at 2, repeat blends to 0.
        assert_eq!(at(0.99, clamp), 2.0);
        assert!(at(0.99, TextureSampler::default()) < 2.0);
        assert!((t.alpha_with(Vec2::new(2.0 / 3.0, 0.5), Default::default()) - 0.75).abs() < 1e-6);
        // The default sampler is the lookup textures always had.
        for u in [0.1f32, 0.37, 0.5, 0.93] {
            assert_eq!(
                t.sample(Vec2::new(u, 0.2)),
                t.sample_with(Vec2::new(u, 0.2), Default::default())
            );
        }
    }

    /// MASK keeps the surface where alpha reaches the cutoff; BLEND lets a
    /// ray through with probability 1 - alpha.
    #[test]
    fn alpha_modes_decide_coverage() {
        let texture = Texture::Image {
            image: Arc::new(strip()),
            transform: UvTransform::default(),
            sampler: TextureSampler {
                linear: false,
                ..Default::default()
            },
        };
        let mask = Alpha {
            mode: AlphaMode::Mask { cutoff: 0.5 },
            factor: 1.0,
            texture: Some(texture.clone()),
        };
        let uv = |u: f32| Vec2::new(u, 0.5);
        assert!(mask.passes(uv(0.1), 0.0));
        assert!(!mask.passes(uv(0.5), 0.0));
        assert!(!mask.passes(uv(0.9), 0.99));
        let blend = Alpha {
            mode: AlphaMode::Blend,
            factor: 0.8,
            texture: Some(texture),
        };
        // alpha = 0.8 * 0.5 = 0.4 in the middle texel.
        assert!(!blend.passes(uv(0.5), 0.39));
        assert!(blend.passes(uv(0.5), 0.41));
        assert!(blend.passes(uv(0.1), 0.0));
    }

    /// A flat normal-map texel (0.5, 0.5, 1) is the unmapped normal; the
    /// scale tilts x and y only.
    #[test]
    fn normal_map_texels_decode() {
        let tex = |c: Vec3| Texture::Image {
            image: Arc::new(ImageTexture::new(1, 1, vec![c])),
            transform: UvTransform::default(),
            sampler: TextureSampler::default(),
        };
        let flat = NormalMap {
            texture: tex(Vec3::new(0.5, 0.5, 1.0)),
            scale: 1.0,
        };
        assert!((flat.normal(Vec2::ZERO) - Vec3::Z).length() < 1e-6);
        // Texel (1, 0.5, 1) is the tangent-space vector (1, 0, 1); a
        // scale of 2 makes it (2, 0, 1).
        let tilted = NormalMap {
            texture: tex(Vec3::new(1.0, 0.5, 1.0)),
            scale: 2.0,
        };
        let n = tilted.normal(Vec2::ZERO);
        assert!(
            (n - Vec3::new(2.0, 0.0, 1.0).normalize()).length() < 1e-6,
            "{n}"
        );
    }
}
