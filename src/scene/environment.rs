//! Environment lighting: radiance arriving from infinitely far away, in
//! every direction no surface blocks.
//!
//! An [`Environment`] is either a uniform colour or an equirectangular
//! (latitude-longitude) image, scaled by an intensity and turned about the
//! vertical axis. It is the background of escaped rays, and path transport
//! also samples it as a light ([`Environment::sample`], [`Environment::pdf`])
//! with multiple importance sampling against the BSDF.
//!
//! # Direction convention
//! glTF's and Blender's: `+Y` is up. A direction
//! `d = (sin theta cos phi, cos theta, sin theta sin phi)` reads the map at
//! `u = 0.5 + phi / (2 pi)` (left to right) and `v = theta / pi` (top row
//! `v = 0` is straight up, the bottom row straight down). So the centre of
//! the image is seen looking along `+X`, `u = 0.75` along `+Z`, `u = 0.25`
//! along `-Z` (glTF's default view direction), and the left and right edges
//! along `-X`: an equirectangular map shows the same view as in Blender's
//! world shader with the scene exported to glTF.
//!
//! [`Environment::rotation`] (radians) turns the map about `+Y`,
//! right-handed: what the unrotated map shows in direction `d` appears in
//! direction `R_y(rotation) d`, so a quarter turn moves the map's `+X` view
//! to `-Z`.
//!
//! # Radiance within a texel
//! The map is piecewise constant: every direction inside a texel's
//! latitude-longitude rectangle has that texel's radiance (times the
//! intensity). This is exactly the function the light sampler draws from,
//! so sampling needs no guard band, and a single bright texel is a light of
//! known solid angle.
//!
//! # Sampling
//! Texels are drawn from a 2D piecewise-constant distribution proportional
//! to `luminance * sin(theta)` at the texel centre (rows from a marginal
//! table, columns from the row's conditional table), then a point uniformly
//! inside the texel's `(u, v)` rectangle. The density per solid angle is
//! the `(u, v)` density over `2 pi^2 sin(theta)`. A uniform environment is
//! sampled uniformly over the sphere.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, luminance};

/// A texel grid of linear RGB radiance, row-major from the top row.
#[derive(Debug)]
pub struct EnvironmentMap {
    width: u32,
    height: u32,
    texels: Vec<Color>,
    /// Marginal cumulative distribution over rows, `height + 1` entries
    /// from 0 to 1.
    row_cdf: Vec<f32>,
    /// Per row, the conditional cumulative distribution over its columns,
    /// `width + 1` entries each from 0 to 1 (uniform for a black row).
    column_cdf: Vec<f32>,
    /// Density over `(u, v)` of each texel (zero for texels never drawn).
    texel_pdf: Vec<f32>,
}

/// Why an environment map cannot be used.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EnvironmentMapError(pub String);

impl std::fmt::Display for EnvironmentMapError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for EnvironmentMapError {}

/// Largest accepted map side, in texels.
pub const MAX_MAP_SIDE: u32 = 1 << 15;

impl EnvironmentMap {
    /// Builds the map and its sampling tables from `width * height` texels
    /// (row-major, top row first). Errors for an empty map, a texel count
    /// that does not match, a side above [`MAX_MAP_SIDE`], and texels that
    /// are negative, NaN or infinite (named by column and row).
    pub fn new(width: u32, height: u32, texels: Vec<Color>) -> Result<Self, EnvironmentMapError> {
        if width == 0 || height == 0 {
            return Err(EnvironmentMapError(format!(
                "the environment map is empty ({width}x{height} texels)"
            )));
        }
        if width > MAX_MAP_SIDE || height > MAX_MAP_SIDE {
            return Err(EnvironmentMapError(format!(
                "the environment map is {width}x{height} texels; at most {MAX_MAP_SIDE} a side"
            )));
        }
        if texels.len() != width as usize * height as usize {
            return Err(EnvironmentMapError(format!(
                "the environment map has {} texels for {width}x{height}",
                texels.len()
            )));
        }
        if let Some(i) = texels
            .iter()
            .position(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            let t = texels[i];
            let what = if t.is_nan() {
                "NaN"
            } else if !t.is_finite() {
                "infinite"
            } else {
                "negative"
            };
            return Err(EnvironmentMapError(format!(
                "the environment map's texel at column {}, row {} is {what} ({}, {}, {})",
                i % width as usize,
                i / width as usize,
                t.x,
                t.y,
                t.z
            )));
        }
        let (w, h) = (width as usize, height as usize);
        let mut column_cdf = vec![0.0f32; h * (w + 1)];
        let mut row_weight = vec![0.0f64; h];
        let mut texel_pdf = vec![0.0f32; w * h];
        for j in 0..h {
            let sin = ((j as f64 + 0.5) * std::f64::consts::PI / h as f64).sin();
            let row = &texels[j * w..(j + 1) * w];
            let cdf = &mut column_cdf[j * (w + 1)..(j + 1) * (w + 1)];
            let mut acc = 0.0f64;
            for (i, t) in row.iter().enumerate() {
                acc += luminance(*t) as f64 * sin;
                cdf[i + 1] = acc as f32;
            }
            row_weight[j] = acc;
            if acc > 0.0 {
                let mut a = 0.0f64;
                for (i, t) in row.iter().enumerate() {
                    a += luminance(*t) as f64 * sin;
                    cdf[i + 1] = (a / acc) as f32;
                }
            } else {
                for (i, c) in cdf.iter_mut().enumerate() {
                    *c = i as f32 / w as f32;
                }
            }
            cdf[w] = 1.0;
        }
        let total: f64 = row_weight.iter().sum();
        let mut row_cdf = vec![0.0f32; h + 1];
        if total > 0.0 && total.is_finite() {
            let mut acc = 0.0f64;
            for j in 0..h {
                acc += row_weight[j];
                row_cdf[j + 1] = (acc / total) as f32;
                let sin = ((j as f64 + 0.5) * std::f64::consts::PI / h as f64).sin();
                for i in 0..w {
                    // Texel probability over its (u, v) area 1 / (w h).
                    let p = luminance(texels[j * w + i]) as f64 * sin / total;
                    texel_pdf[j * w + i] = (p * (w * h) as f64) as f32;
                }
            }
            row_cdf[h] = 1.0;
        }
        Ok(Self {
            width,
            height,
            texels,
            row_cdf,
            column_cdf,
            texel_pdf,
        })
    }

    /// Width in texels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The texels, row-major from the top row.
    pub fn texels(&self) -> &[Color] {
        &self.texels
    }

    /// True when some texel has light to sample.
    fn has_light(&self) -> bool {
        self.row_cdf[self.height as usize] > 0.0
    }

    /// Texel (column, row) holding map coordinates `uv` in `[0, 1]^2`.
    #[inline]
    fn texel_at(&self, uv: Vec2) -> (usize, usize) {
        let i = ((uv.x * self.width as f32) as usize).min(self.width as usize - 1);
        let j = ((uv.y * self.height as f32) as usize).min(self.height as usize - 1);
        (i, j)
    }
}

/// What the environment is made of.
#[derive(Clone, Debug)]
pub enum EnvironmentSource {
    /// The same radiance from every direction.
    Uniform(Color),
    /// An equirectangular map.
    Map(Arc<EnvironmentMap>),
}

impl PartialEq for EnvironmentSource {
    /// Uniform colours by value, maps by identity (the same loaded map).
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::Uniform(a), Self::Uniform(b)) => a == b,
            (Self::Map(a), Self::Map(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

/// Radiance from infinitely far away: a uniform colour or an
/// equirectangular map, times `intensity`, turned by `rotation` about `+Y`
/// (see the [module documentation](self) for the direction convention).
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    source: EnvironmentSource,
    intensity: f32,
    rotation: f32,
    /// `(sin, cos)` of the rotation.
    sin_cos: (f32, f32),
}

/// A direction drawn towards the environment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvironmentSample {
    /// Unit world direction towards the environment.
    pub direction: Vec3A,
    /// Radiance arriving from it.
    pub radiance: Color,
    /// Density per solid angle of having drawn it.
    pub pdf: f32,
}

/// Map coordinates `(u, v)` of a unit direction in the map's own frame.
#[inline]
pub fn direction_to_uv(d: Vec3A) -> Vec2 {
    let u = 0.5 + d.z.atan2(d.x) * (0.5 / PI);
    // atan2 rather than acos: precise near the poles too.
    let v = (d.x * d.x + d.z * d.z).sqrt().atan2(d.y) * (1.0 / PI);
    Vec2::new(u.clamp(0.0, 1.0), v.clamp(0.0, 1.0))
}

/// The unit direction, in the map's own frame, of map coordinates
/// `(u, v)`, with `sin(theta)`.
#[inline]
pub fn uv_to_direction(uv: Vec2) -> (Vec3A, f32) {
    let phi = 2.0 * PI * (uv.x - 0.5);
    let theta = PI * uv.y;
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    (
        Vec3A::new(sin_t * cos_p, cos_t, sin_t * sin_p),
        sin_t.max(0.0),
    )
}

/// Index of the interval of `cdf` (non-decreasing, from 0 to 1) holding
/// `u`, skipping empty intervals, and the position of `u` within it.
#[inline]
fn invert_cdf(cdf: &[f32], u: f32) -> (usize, f32) {
    let n = cdf.len() - 1;
    let k = cdf.partition_point(|&c| c <= u).clamp(1, n) - 1;
    let (lo, hi) = (cdf[k], cdf[k + 1]);
    let t = if hi > lo {
        ((u - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    (k, t)
}

impl Environment {
    /// A uniform environment of radiance `color`.
    pub fn uniform(color: Color) -> Self {
        Self::new(EnvironmentSource::Uniform(color), 1.0, 0.0)
    }

    /// An environment from `source`, scaled by `intensity` and turned by
    /// `rotation` radians about `+Y`.
    pub fn new(source: EnvironmentSource, intensity: f32, rotation: f32) -> Self {
        Self {
            source,
            intensity,
            rotation,
            sin_cos: rotation.sin_cos(),
        }
    }

    /// What the environment is made of.
    pub fn source(&self) -> &EnvironmentSource {
        &self.source
    }

    /// Scale of the radiance.
    pub fn intensity(&self) -> f32 {
        self.intensity
    }

    /// Turn about `+Y` in radians.
    pub fn rotation(&self) -> f32 {
        self.rotation
    }

    /// World direction to the map's frame: the inverse rotation.
    #[inline]
    fn to_map(&self, d: Vec3A) -> Vec3A {
        let (s, c) = self.sin_cos;
        Vec3A::new(c * d.x - s * d.z, d.y, s * d.x + c * d.z)
    }

    /// The map's frame to world directions.
    #[inline]
    fn to_world(&self, d: Vec3A) -> Vec3A {
        let (s, c) = self.sin_cos;
        Vec3A::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z)
    }

    /// Radiance arriving from direction `d` (need not be unit length; zero
    /// for a zero or non-finite direction).
    pub fn radiance(&self, d: Vec3A) -> Color {
        match &self.source {
            EnvironmentSource::Uniform(c) => *c * self.intensity,
            EnvironmentSource::Map(map) => {
                let d = d.normalize_or_zero();
                if d == Vec3A::ZERO {
                    return Color::ZERO;
                }
                let (i, j) = map.texel_at(direction_to_uv(self.to_map(d)));
                map.texels[j * map.width as usize + i] * self.intensity
            }
        }
    }

    /// Density per solid angle with which [`Environment::sample`] draws
    /// the unit direction `d`.
    pub fn pdf(&self, d: Vec3A) -> f32 {
        match &self.source {
            EnvironmentSource::Uniform(_) => 1.0 / (4.0 * PI),
            EnvironmentSource::Map(map) => {
                let m = self.to_map(d);
                let uv = direction_to_uv(m);
                let sin = (m.x * m.x + m.z * m.z).sqrt();
                if !(sin > 0.0) {
                    return 0.0;
                }
                let (i, j) = map.texel_at(uv);
                map.texel_pdf[j * map.width as usize + i] / (2.0 * PI * PI * sin)
            }
        }
    }

    /// Draws a direction from two uniform numbers; `None` when the
    /// environment has no light to sample.
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        match &self.source {
            EnvironmentSource::Uniform(c) => {
                let radiance = *c * self.intensity;
                (radiance.max_element() > 0.0).then(|| EnvironmentSample {
                    direction: crate::core::sampling::uniform_sphere(u),
                    radiance,
                    pdf: 1.0 / (4.0 * PI),
                })
            }
            EnvironmentSource::Map(map) => {
                if !map.has_light() {
                    return None;
                }
                let w = map.width as usize;
                let (j, tv) = invert_cdf(&map.row_cdf, u.y);
                let (i, tu) = invert_cdf(&map.column_cdf[j * (w + 1)..(j + 1) * (w + 1)], u.x);
                let uv = Vec2::new(
                    (i as f32 + tu) / map.width as f32,
                    (j as f32 + tv) / map.height as f32,
                );
                let (d, sin) = uv_to_direction(uv);
                let texel_pdf = map.texel_pdf[j * w + i];
                if !(sin > 0.0 && texel_pdf > 0.0) {
                    return None;
                }
                Some(EnvironmentSample {
                    direction: self.to_world(d),
                    radiance: map.texels[j * w + i] * self.intensity,
                    pdf: texel_pdf / (2.0 * PI * PI * sin),
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    fn map(w: u32, h: u32, f: impl Fn(u32, u32) -> Color) -> Arc<EnvironmentMap> {
        let texels = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| f(i, j))
            .collect();
        Arc::new(EnvironmentMap::new(w, h, texels).unwrap())
    }

    #[test]
    fn the_convention_is_gltfs() {
        // Straight up is the top row, +X the centre column, +Z at u = 3/4,
        // -Z (glTF's view direction) at u = 1/4.
        assert!(direction_to_uv(Vec3A::Y).y < 1e-6);
        assert!((direction_to_uv(-Vec3A::Y).y - 1.0).abs() < 1e-6);
        let c = |d: Vec3A| direction_to_uv(d);
        assert!((c(Vec3A::X) - Vec2::new(0.5, 0.5)).length() < 1e-6);
        assert!((c(Vec3A::Z) - Vec2::new(0.75, 0.5)).length() < 1e-6);
        assert!((c(-Vec3A::Z) - Vec2::new(0.25, 0.5)).length() < 1e-6);
        // Round trip.
        for k in 0..100 {
            let uv = Vec2::new(
                (k as f32 * 0.37).fract() * 0.98 + 0.01,
                (k as f32 * 0.61).fract() * 0.98 + 0.01,
            );
            let (d, _) = uv_to_direction(uv);
            assert!((direction_to_uv(d) - uv).length() < 1e-5, "{uv}");
        }
        // A quarter turn moves the map's +X view to -Z.
        let m = map(4, 2, |i, _| Color::splat(i as f32 + 1.0));
        let e = Environment::new(EnvironmentSource::Map(m.clone()), 1.0, PI / 2.0);
        let plain = Environment::new(EnvironmentSource::Map(m), 1.0, 0.0);
        let d = Vec3A::new(1.0, 0.1, 0.0).normalize();
        let turned = Vec3A::new(0.0, 0.1, -1.0).normalize();
        assert_eq!(e.radiance(turned), plain.radiance(d));
    }

    #[test]
    fn seams_and_poles_read_their_neighbours() {
        let w = 8;
        let m = map(w, 4, |i, j| Color::new(i as f32, j as f32, 1.0));
        let e = Environment::new(EnvironmentSource::Map(m), 1.0, 0.0);
        // Just either side of the seam (direction -X): the last and the
        // first column, never outside the map.
        let eps = 1e-4;
        let above = Vec3A::new(-1.0, 0.0, eps).normalize();
        let below = Vec3A::new(-1.0, 0.0, -eps).normalize();
        assert_eq!(e.radiance(above).x, (w - 1) as f32);
        assert_eq!(e.radiance(below).x, 0.0);
        // Exactly on the seam: either side, never outside the map.
        let on = e.radiance(-Vec3A::X).x;
        assert!(on == (w - 1) as f32 || on == 0.0, "{on}");
        // The poles: top and bottom rows, finite densities near them.
        assert_eq!(e.radiance(Vec3A::Y).y, 0.0);
        assert_eq!(e.radiance(-Vec3A::Y).y, 3.0);
        for d in [Vec3A::Y, -Vec3A::Y, Vec3A::new(1e-7, 1.0, 0.0)] {
            assert!(e.pdf(d).is_finite() && e.pdf(d) >= 0.0);
        }
        assert_eq!(e.radiance(Vec3A::ZERO), Color::ZERO);
        assert_eq!(e.radiance(Vec3A::splat(f32::NAN)), Color::ZERO);
    }

    #[test]
    fn bad_maps_are_refused() {
        assert!(EnvironmentMap::new(0, 4, vec![]).is_err());
        assert!(EnvironmentMap::new(2, 1, vec![Color::ONE]).is_err());
        let e = EnvironmentMap::new(2, 1, vec![Color::ONE, Color::new(0.0, f32::NAN, 0.0)])
            .unwrap_err();
        assert!(e.0.contains("column 1, row 0 is NaN"), "{e}");
        assert!(EnvironmentMap::new(1, 1, vec![Color::splat(-1.0)]).is_err());
        assert!(EnvironmentMap::new(1, 1, vec![Color::splat(f32::INFINITY)]).is_err());
    }

    /// Samples in bins of `(cos theta, phi)` (not aligned with texels, and
    /// with the map turned) against `N` times the integral of
    /// [`Environment::pdf`] over each bin, by a fine midpoint rule: a
    /// chi-square test of sampling against the density MIS uses.
    #[test]
    fn sampling_matches_its_density_chi_square() {
        let m = map(24, 12, |i, j| {
            let base = 0.05 + 0.5 * ((i * 7 + j * 3) % 5) as f32;
            if (i, j) == (5, 3) {
                Color::new(40.0, 30.0, 20.0)
            } else if j == 7 {
                Color::ZERO
            } else {
                Color::new(base, 0.5 * base, 0.2)
            }
        });
        let env = Environment::new(EnvironmentSource::Map(m), 2.0, 0.7);
        chi_square(&env);
        chi_square(&Environment::uniform(Color::splat(0.3)));
    }

    fn chi_square(env: &Environment) {
        let (nc, np) = (10usize, 20usize);
        let n = 200_000u32;
        let mut counts = vec![0.0f64; nc * np];
        let bin = |d: Vec3A| {
            let c = ((d.y * 0.5 + 0.5) * nc as f32) as usize;
            let p = ((d.z.atan2(d.x) / (2.0 * PI) + 0.5) * np as f32) as usize;
            c.min(nc - 1) * np + p.min(np - 1)
        };
        for k in 0..n {
            let mut s = Sampler::new(7, k, 0);
            let u = Vec2::new(s.next_f32(), s.next_f32());
            let es = env.sample(u).expect("has light");
            assert!((es.direction.length() - 1.0).abs() < 1e-4);
            // The density it reports is the density MIS evaluates.
            let p = env.pdf(es.direction);
            assert!((es.pdf - p).abs() <= 1e-3 * p, "{} vs {p}", es.pdf);
            counts[bin(es.direction)] += 1.0;
        }
        // Expected counts: the density integrated over each bin.
        let sub = 48;
        let mut expected = vec![0.0f64; nc * np];
        let mut total = 0.0;
        for c in 0..nc * sub {
            let z = -1.0 + 2.0 * (c as f64 + 0.5) / (nc * sub) as f64;
            for p in 0..np * sub {
                let phi = -std::f64::consts::PI
                    + 2.0 * std::f64::consts::PI * (p as f64 + 0.5) / (np * sub) as f64;
                let r = (1.0 - z * z).sqrt();
                let d = Vec3A::new((r * phi.cos()) as f32, z as f32, (r * phi.sin()) as f32);
                let dw =
                    (2.0 / (nc * sub) as f64) * (2.0 * std::f64::consts::PI / (np * sub) as f64);
                let mass = env.pdf(d) as f64 * dw;
                expected[(c / sub) * np + p / sub] += mass;
                total += mass;
            }
        }
        assert!((total - 1.0).abs() < 2e-3, "density integrates to {total}");
        let mut chi2 = 0.0;
        let mut dof = 0usize;
        let (mut pool_o, mut pool_e) = (0.0, 0.0);
        for (o, e) in counts.iter().zip(&expected) {
            let e = e * n as f64;
            if e < 5.0 {
                pool_o += o;
                pool_e += e;
                continue;
            }
            chi2 += (o - e) * (o - e) / e;
            dof += 1;
        }
        if pool_e >= 5.0 {
            chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
            dof += 1;
        }
        let dof = (dof - 1) as f64;
        // Wilson-Hilferty: z of the chi-square statistic; fail beyond
        // z = 4.5 (p ~ 3e-6).
        let z = ((chi2 / dof).cbrt() - (1.0 - 2.0 / (9.0 * dof))) / (2.0 / (9.0 * dof)).sqrt();
        assert!(z < 4.5, "chi2 {chi2} with {dof} dof (z = {z})");
    }
}
