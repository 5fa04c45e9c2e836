//! Whitted transport: direct light from punctual lights through shadow
//! rays, and the perfectly specular reflection and refraction rays.

use glam::Vec3A;

use std::f32::consts::PI;

use crate::core::math::{Color, Ray};
use crate::core::optics::{fresnel_dielectric, reflect, refract};
use crate::scene::light::{LightSample, WorldLight};
use crate::transport::interaction::{Interaction, RayKind, Secondary, ShadowQuery, brdf_cos};

/// Sets up the shadow ray for one light, or `None` when the light cannot
/// contribute (below the horizon, outside a spot cone, zero BRDF).
#[inline]
pub fn direct_light(it: &Interaction, light: &WorldLight) -> Option<ShadowQuery> {
    direct_light_with(it, light, |wi| brdf_cos(&it.surface, it.ns, it.wo, wi))
}

/// [`direct_light`] with another BRDF: `brdf_cos(wi)` is the BRDF times
/// the cosine for the direction `wi` towards the light. Always inlined:
/// as a call (with the BRDF as a closure) it cost Whitted scenes of many
/// lights 3% more instructions (callgrind, `many_lights`).
#[inline(always)]
pub fn direct_light_with(
    it: &Interaction,
    light: &WorldLight,
    brdf_cos: impl Fn(Vec3A) -> Color,
) -> Option<ShadowQuery> {
    let LightSample {
        wi,
        distance,
        irradiance,
    } = light.illuminate(it.point)?;
    if it.ng.dot(wi) <= 0.0 {
        return None;
    }
    let radiance = brdf_cos(wi) * irradiance;
    if !(radiance.max_element() > 0.0) {
        return None;
    }
    let origin = it.offset(it.ng);
    let t_max = if distance.is_finite() {
        // Distance from the offset origin, shortened by a relative margin
        // so the light's own position is never counted as a blocker.
        (it.point + wi * distance - origin).length() * (1.0 - 1e-5)
    } else {
        f32::INFINITY
    };
    Some(ShadowQuery {
        ray: Ray::new(origin, wi),
        t_max,
        radiance,
    })
}

/// Lanes of [`direct_point_lights`]: hits side by side.
pub const LIGHT_LANES: usize = 8;

/// Up to [`LIGHT_LANES`] hits of the local shading model, side by side
/// (structure of arrays), for [`direct_point_lights`]: what
/// [`direct_light`] reads of each [`Interaction`], and the shadow rays'
/// offset origin.
#[derive(Clone, Copy, Debug, Default)]
pub struct HitLanes {
    /// Hit points, per axis.
    pub point: [[f32; LIGHT_LANES]; 3],
    /// Geometric normals.
    pub ng: [[f32; LIGHT_LANES]; 3],
    /// Shading normals.
    pub ns: [[f32; LIGHT_LANES]; 3],
    /// Directions towards the viewer.
    pub wo: [[f32; LIGHT_LANES]; 3],
    /// Shadow-ray origins ([`Interaction::offset`] along `ng`).
    pub origin: [[f32; LIGHT_LANES]; 3],
    /// Diffuse colours.
    pub diffuse: [[f32; LIGHT_LANES]; 3],
    /// Specular colours.
    pub specular: [[f32; LIGHT_LANES]; 3],
    /// Blinn-Phong exponents.
    pub shininess: [f32; LIGHT_LANES],
    /// Whether the hit has a specular lobe (`specular.max_element() > 0`).
    pub glossy: [bool; LIGHT_LANES],
    /// Lanes in use (the first `count`); the others are never lit.
    pub count: usize,
}

impl HitLanes {
    /// The lanes of `its` (at most [`LIGHT_LANES`]).
    pub fn new(its: &[&Interaction]) -> Self {
        let mut h = HitLanes::default();
        for it in its {
            h.push(it);
        }
        h
    }

    /// Puts `it` in the next lane (at most [`LIGHT_LANES`]).
    #[inline(always)]
    pub fn push(&mut self, it: &Interaction) {
        let l = self.count;
        debug_assert!(l < LIGHT_LANES);
        let origin = it.offset(it.ng);
        let s = &it.surface;
        for a in 0..3 {
            self.point[a][l] = it.point[a];
            self.ng[a][l] = it.ng[a];
            self.ns[a][l] = it.ns[a];
            self.wo[a][l] = it.wo[a];
            self.origin[a][l] = origin[a];
            self.diffuse[a][l] = s.diffuse[a];
            self.specular[a][l] = s.specular[a];
        }
        self.shininess[l] = s.shininess;
        self.glossy[l] = s.specular.max_element() > 0.0;
        self.count += 1;
    }
}

/// The shadow rays of one light for every lane of a [`HitLanes`].
#[derive(Clone, Copy, Debug, Default)]
pub struct LightLanes {
    /// Whether the lane has a shadow ray ([`direct_light`] gave `Some`).
    pub lit: [bool; LIGHT_LANES],
    /// Unit directions towards the light.
    pub wi: [[f32; LIGHT_LANES]; 3],
    /// Ends of the shadow rays.
    pub t_max: [f32; LIGHT_LANES],
    /// Radiance each brings if unoccluded.
    pub radiance: [[f32; LIGHT_LANES]; 3],
}

impl LightLanes {
    /// The shadow query of lane `l` (when `lit[l]`), as [`direct_light`]
    /// gives it, from the hits' lanes `hits`.
    #[inline]
    pub fn query(&self, hits: &HitLanes, l: usize) -> ShadowQuery {
        let v = |r: &[[f32; LIGHT_LANES]; 3]| Vec3A::new(r[0][l], r[1][l], r[2][l]);
        ShadowQuery {
            ray: Ray::new(v(&hits.origin), v(&self.wi)),
            t_max: self.t_max[l],
            radiance: Color::new(
                self.radiance[0][l],
                self.radiance[1][l],
                self.radiance[2][l],
            ),
        }
    }
}

/// [`direct_light`] of a point light at `position` of intensity
/// `intensity` for every lane of `hits`: with `AVX` in 8-wide AVX
/// registers (only inside functions compiled with AVX2, see
/// [`crate::core::simd`]), else lane by lane. The Blinn-Phong power is
/// `f32::powf` of each lane whose hit has a highlight and faces the light.
///
/// Each lane performs the IEEE operations of [`direct_light`] with
/// [`WorldLight::illuminate`] and [`brdf_cos`], in the same order (glam's
/// dot product is `(x x + y y) + z z`, `normalize_or_zero` multiplies by
/// `1 / length`), so its shadow query is the scalar one bit for bit
/// (unit test): the wavefront, which shades hits of one material class
/// side by side, and the recursive tracer give the same images.
#[inline(always)]
pub fn direct_point_lights<const AVX: bool>(
    hits: &HitLanes,
    position: Vec3A,
    intensity: Color,
    out: &mut LightLanes,
) {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is set only inside functions compiled with AVX2
        // and FMA, which run only on CPUs that have them.
        #[allow(unsafe_code)]
        return unsafe { direct_point_lights_avx2(hits, position, intensity, out) };
    }
    direct_point_lights_portable(hits, position, intensity, out)
}

/// [`direct_point_lights`] lane by lane.
#[inline(always)]
fn direct_point_lights_portable(
    hits: &HitLanes,
    position: Vec3A,
    intensity: Color,
    out: &mut LightLanes,
) {
    const INV_PI: f32 = 1.0 / PI;
    const NORM: f32 = 8.0 * PI;
    let dot = |a: [f32; 3], b: [f32; 3]| (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2];
    for l in 0..LIGHT_LANES {
        let p = [hits.point[0][l], hits.point[1][l], hits.point[2][l]];
        let d = [position.x - p[0], position.y - p[1], position.z - p[2]];
        let dist2 = dot(d, d);
        let dist = dist2.sqrt();
        let wi = [d[0] / dist, d[1] / dist, d[2] / dist];
        let irr = [
            intensity.x / dist2,
            intensity.y / dist2,
            intensity.z / dist2,
        ];
        let ng = [hits.ng[0][l], hits.ng[1][l], hits.ng[2][l]];
        let n = [hits.ns[0][l], hits.ns[1][l], hits.ns[2][l]];
        let cos_i = dot(n, wi);
        let h = [
            hits.wo[0][l] + wi[0],
            hits.wo[1][l] + wi[1],
            hits.wo[2][l] + wi[2],
        ];
        let rcp = 1.0 / dot(h, h).sqrt();
        let keep = rcp.is_finite() && rcp > 0.0;
        let h = [
            if keep { h[0] * rcp } else { 0.0 },
            if keep { h[1] * rcp } else { 0.0 },
            if keep { h[2] * rcp } else { 0.0 },
        ];
        let cos_h = dot(n, h);
        let cos_h = if cos_h > 0.0 { cos_h } else { 0.0 };
        let s = hits.shininess[l];
        let glossy = hits.glossy[l];
        let lit =
            l < hits.count && dist2 > 0.0 && dist2.is_finite() && dot(ng, wi) > 0.0 && cos_i > 0.0;
        let lobe = if glossy && lit {
            (s + 8.0) / NORM * cos_h.powf(s)
        } else {
            0.0
        };
        let mut rad = [0.0f32; 3];
        for a in 0..3 {
            let f = hits.diffuse[a][l] * INV_PI;
            let f = if glossy {
                f + hits.specular[a][l] * lobe
            } else {
                f
            };
            rad[a] = f * cos_i * irr[a];
        }
        let m = if rad[1] > rad[2] { rad[1] } else { rad[2] };
        let m = if rad[0] > m { rad[0] } else { m };
        let o = [hits.origin[0][l], hits.origin[1][l], hits.origin[2][l]];
        let e = [
            (p[0] + wi[0] * dist) - o[0],
            (p[1] + wi[1] * dist) - o[1],
            (p[2] + wi[2] * dist) - o[2],
        ];
        out.lit[l] = lit && m > 0.0;
        out.t_max[l] = dot(e, e).sqrt() * (1.0 - 1e-5);
        for a in 0..3 {
            out.wi[a][l] = wi[a];
            out.radiance[a][l] = rad[a];
        }
    }
}

/// [`direct_point_lights`] in 8-wide AVX registers: the same operations
/// in the same order (no fused multiply-add), so the same bits; the
/// Blinn-Phong power is `f32::powf` of each lane that needs it.
///
/// # Safety
/// Only on a CPU with AVX2, inlined into a function compiled with it.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn direct_point_lights_avx2(
    hits: &HitLanes,
    position: Vec3A,
    intensity: Color,
    out: &mut LightLanes,
) {
    use std::arch::x86_64::*;
    const INV_PI: f32 = 1.0 / PI;
    const NORM: f32 = 8.0 * PI;
    // SAFETY: the caller runs on a CPU with AVX2; every load and store is
    // of a whole `[f32; 8]` (`bytemuck` casts, no pointers).
    unsafe {
        let ld = |a: &[f32; LIGHT_LANES]| -> __m256 { bytemuck::cast(*a) };
        let ld3 = |r: &[[f32; LIGHT_LANES]; 3]| [ld(&r[0]), ld(&r[1]), ld(&r[2])];
        let dot = |a: [__m256; 3], b: [__m256; 3]| {
            _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])),
                _mm256_mul_ps(a[2], b[2]),
            )
        };
        let zero = _mm256_setzero_ps();
        let gt = |a: __m256, b: __m256| _mm256_cmp_ps::<_CMP_GT_OQ>(a, b);
        let finite = |a: __m256| {
            let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), a);
            _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(f32::INFINITY))
        };
        let p = ld3(&hits.point);
        let d = [
            _mm256_sub_ps(_mm256_set1_ps(position.x), p[0]),
            _mm256_sub_ps(_mm256_set1_ps(position.y), p[1]),
            _mm256_sub_ps(_mm256_set1_ps(position.z), p[2]),
        ];
        let dist2 = dot(d, d);
        let dist = _mm256_sqrt_ps(dist2);
        // Component by component, not `array::map`: a closure passed to a
        // generic function can be compiled outside this function's target
        // features, and then calls each intrinsic (`objdump -d` showed
        // `try_map` calling `_mm256_blendv_ps`: 12% of `many_lights`).
        let wi = [
            _mm256_div_ps(d[0], dist),
            _mm256_div_ps(d[1], dist),
            _mm256_div_ps(d[2], dist),
        ];
        let irr = [
            _mm256_div_ps(_mm256_set1_ps(intensity.x), dist2),
            _mm256_div_ps(_mm256_set1_ps(intensity.y), dist2),
            _mm256_div_ps(_mm256_set1_ps(intensity.z), dist2),
        ];
        let n = ld3(&hits.ns);
        let cos_i = dot(n, wi);
        let wo = ld3(&hits.wo);
        let h = [
            _mm256_add_ps(wo[0], wi[0]),
            _mm256_add_ps(wo[1], wi[1]),
            _mm256_add_ps(wo[2], wi[2]),
        ];
        let rcp = _mm256_div_ps(_mm256_set1_ps(1.0), _mm256_sqrt_ps(dot(h, h)));
        let keep = _mm256_and_ps(finite(rcp), gt(rcp, zero));
        let h = [
            _mm256_blendv_ps(zero, _mm256_mul_ps(h[0], rcp), keep),
            _mm256_blendv_ps(zero, _mm256_mul_ps(h[1], rcp), keep),
            _mm256_blendv_ps(zero, _mm256_mul_ps(h[2], rcp), keep),
        ];
        let cos_h = dot(n, h);
        let cos_h = _mm256_blendv_ps(zero, cos_h, gt(cos_h, zero));
        let lit = _mm256_and_ps(
            _mm256_and_ps(gt(dist2, zero), finite(dist2)),
            _mm256_and_ps(gt(dot(ld3(&hits.ng), wi), zero), gt(cos_i, zero)),
        );
        let glossy: [f32; LIGHT_LANES] = std::array::from_fn(|l| {
            if hits.glossy[l] {
                f32::from_bits(u32::MAX)
            } else {
                0.0
            }
        });
        let glossy = ld(&glossy);
        let used = (1u32 << hits.count) - 1;
        let need = _mm256_movemask_ps(_mm256_and_ps(lit, glossy)) as u32 & used;
        let mut lobe = [0.0f32; LIGHT_LANES];
        if need != 0 {
            let c: [f32; LIGHT_LANES] = bytemuck::cast(cos_h);
            let mut m = need;
            while m != 0 {
                let l = m.trailing_zeros() as usize;
                m &= m - 1;
                let s = hits.shininess[l];
                lobe[l] = (s + 8.0) / NORM * c[l].powf(s);
            }
        }
        let lobe = ld(&lobe);
        let mut rad = [zero; 3];
        for a in 0..3 {
            let f = _mm256_mul_ps(ld(&hits.diffuse[a]), _mm256_set1_ps(INV_PI));
            let g = _mm256_add_ps(f, _mm256_mul_ps(ld(&hits.specular[a]), lobe));
            let f = _mm256_blendv_ps(f, g, glossy);
            rad[a] = _mm256_mul_ps(_mm256_mul_ps(f, cos_i), irr[a]);
        }
        let m = _mm256_max_ps(rad[0], _mm256_max_ps(rad[1], rad[2]));
        let lit = _mm256_and_ps(lit, gt(m, zero));
        let o = ld3(&hits.origin);
        let mut e = [zero; 3];
        for a in 0..3 {
            e[a] = _mm256_sub_ps(_mm256_add_ps(p[a], _mm256_mul_ps(wi[a], dist)), o[a]);
        }
        let t_max = _mm256_mul_ps(_mm256_sqrt_ps(dot(e, e)), _mm256_set1_ps(1.0 - 1e-5));
        let bits = _mm256_movemask_ps(lit) as u32 & used;
        out.lit = std::array::from_fn(|l| bits & (1 << l) != 0);
        out.t_max = bytemuck::cast(t_max);
        for a in 0..3 {
            out.wi[a] = bytemuck::cast(wi[a]);
            out.radiance[a] = bytemuck::cast(rad[a]);
        }
    }
}

/// The perfectly specular rays leaving a hit: at most one reflection
/// (mirror plus the dielectric's Fresnel part, which share a direction)
/// and one refraction.
#[inline]
pub fn scatter(it: &Interaction) -> [Option<Secondary>; 2] {
    let s = &it.surface;
    let d = -it.wo;
    let mut reflect_w = s.mirror;
    let mut refraction = None;
    if s.transmission > 0.0 {
        // Relative index: outside -> inside when entering the front face.
        let eta = if it.front_face { 1.0 / s.ior } else { s.ior };
        let cos_i = it.ns.dot(it.wo).max(0.0);
        let f = fresnel_dielectric(cos_i, eta);
        reflect_w += Color::splat(s.transmission * f);
        if f < 1.0
            && let Some(t) = refract(d, it.ns, eta)
        {
            // The refracted ray must leave on the far side of the true surface.
            if t.dot(it.ng) < 0.0 {
                refraction = Some(Secondary {
                    ray: Ray::new(it.offset(-it.ng), t),
                    weight: s.transmission_tint * (s.transmission * (1.0 - f)),
                    kind: RayKind::Refraction,
                });
            }
        }
    }
    let reflection = (reflect_w.max_element() > 0.0).then(|| {
        let mut r = reflect(d, it.ns);
        if r.dot(it.ng) <= 0.0 {
            // A shading normal can reflect below the surface; fall back to
            // the geometric normal.
            r = reflect(d, it.ng);
        }
        Secondary {
            ray: Ray::new(it.offset(it.ng), r),
            weight: reflect_w,
            kind: RayKind::Reflection,
        }
    });
    [reflection, refraction]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::math::RayCone;
    use crate::scene::material::SurfaceSample;

    /// [`direct_point_lights`] gives every lane the shadow query of
    /// [`direct_light`], bit for bit: random hits (points near and on the
    /// light, normals facing it or not, with and without a highlight,
    /// exponents from 0 to 2000) and lights.
    #[test]
    fn point_light_lanes_are_direct_light_bit_for_bit() {
        let mut state = 0x2545_f491_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        let mut v = |scale: f32| Vec3A::new(next(), next(), next()) * scale;
        let (mut lit, mut glossy) = (0, 0);
        #[cfg(target_arch = "x86_64")]
        let mut avx2_checked = 0;
        for round in 0..4000 {
            let position = v(3.0);
            let intensity = Color::new(2.0, 1.0, 0.5) * (1.0 + round as f32 % 7.0);
            let its: Vec<Interaction> = (0..1 + round % LIGHT_LANES)
                .map(|k| {
                    let ng = v(1.0).normalize_or(Vec3A::Y);
                    let ns = (ng + v(0.3)).normalize_or(ng);
                    let point = match k % 5 {
                        0 => position,
                        1 => position + v(1e-3),
                        _ => v(3.0),
                    };
                    let kd = Color::new(0.5, 0.25, 0.125) * (k % 3) as f32;
                    let ks = if k % 2 == 0 {
                        Color::splat(0.25)
                    } else {
                        Color::ZERO
                    };
                    Interaction {
                        point,
                        ng,
                        ns,
                        wo: v(1.0).normalize_or(Vec3A::Z),
                        front_face: true,
                        surface: SurfaceSample {
                            diffuse: kd,
                            specular: ks,
                            shininess: [0.0, 1.0, 40.0, 2000.0][k % 4] * (1.0 + v(1.0).x.abs()),
                            mirror: Color::ZERO,
                            transmission: 0.0,
                            transmission_tint: Color::ONE,
                            ior: 1.5,
                            absorption: Color::ZERO,
                            dispersion: None,
                            emission: Color::ZERO,
                            base: kd,
                            diffuse_weight: 1.0,
                            gltf: None,
                        },
                        cone: RayCone::default(),
                        offset_scale: 0.0,
                    }
                })
                .collect();
            let refs: Vec<&Interaction> = its.iter().collect();
            let hits = HitLanes::new(&refs);
            let mut out = LightLanes::default();
            direct_point_lights::<false>(&hits, position, intensity, &mut out);
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut wide = LightLanes::default();
                direct_point_lights::<true>(&hits, position, intensity, &mut wide);
                let bits = |o: &LightLanes| {
                    let mut v = vec![o.lit.map(u32::from)];
                    v.push(o.t_max.map(f32::to_bits));
                    for a in 0..3 {
                        v.push(std::array::from_fn(|l| {
                            if o.lit[l] { o.wi[a][l].to_bits() } else { 0 }
                        }));
                        v.push(std::array::from_fn(|l| {
                            if o.lit[l] {
                                o.radiance[a][l].to_bits()
                            } else {
                                0
                            }
                        }));
                    }
                    v
                };
                assert_eq!(
                    bits(&wide),
                    bits(&out),
                    "round {round}: AVX2 and portable lanes differ"
                );
                avx2_checked += 1;
            }
            let light = WorldLight::Point {
                position,
                intensity,
            };
            for (l, it) in its.iter().enumerate() {
                let want = direct_light(it, &light);
                assert_eq!(out.lit[l], want.is_some(), "round {round} lane {l}");
                if let Some(w) = want {
                    let got = out.query(&hits, l);
                    let bits = |q: &ShadowQuery| {
                        let (o, d) = (q.ray.origin, q.ray.direction);
                        let r = q.radiance;
                        [o.x, o.y, o.z, d.x, d.y, d.z, q.t_max, r.x, r.y, r.z].map(f32::to_bits)
                    };
                    assert_eq!(bits(&got), bits(&w), "round {round} lane {l}");
                    lit += 1;
                    glossy += (it.surface.specular.max_element() > 0.0) as u32;
                }
            }
        }
        assert!(
            lit > 2000 && glossy > 1000,
            "{lit} lit lanes, {glossy} glossy"
        );
        #[cfg(target_arch = "x86_64")]
        assert!(avx2_checked > 0 || !std::arch::is_x86_feature_detected!("avx2"));
    }
}
