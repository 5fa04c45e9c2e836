//! Path-tracing kernels shared by both integrators: sampling the surface
//! model's lobes, next-event estimation of area lights with multiple
//! importance sampling, the weight of emission found by scattered rays,
//! and Russian roulette.
//!
//! The surface model is the Whitted model's ([`crate::scene::material`]): a
//! Lambertian lobe, a normalised Blinn-Phong lobe, a perfect mirror and a
//! smooth dielectric. Path tracing chooses one lobe per bounce, with
//! probability proportional to its weight, so a path never branches.
//!
//! # Random numbers
//! Every decision reads a fixed dimension of the path's [`Sampler`], in
//! sets of four: set 0 (dimensions 0-3) jitters the film position (and
//! the lens); bounce `b` (the hit of a ray that has bounced `b` times)
//! owns one set per light sample and one for its lobe choice and roulette
//! ([`bounce_dimension`]); the BSDF directions of bounces `2j` and `2j + 1`
//! share one set far above those ([`direction_set`]). Both integrators
//! therefore draw the same numbers for the same path.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, Ray, luminance, max_component, orthonormal_basis};
use crate::core::optics::{OFFSET_ULPS, fresnel_dielectric, reflect, refract};
use crate::core::rng::Sampler;
use crate::core::sampling::{cosine_hemisphere, power_heuristic, power_heuristic_over_density};
use crate::core::settings::{RenderSettings, Transport};
use crate::core::spectrum::{sample_wavelength, wavelength_weight};
use crate::scene::RenderScene;
use crate::scene::environment::Environment;
use crate::transport::interaction::{Interaction, RayKind, ShadowQuery, brdf_cos};
use crate::transport::whitted::{direct_light, direct_light_with};

/// Probabilities of choosing each lobe of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeChoice {
    /// Lambertian lobe.
    pub diffuse: f32,
    /// Blinn-Phong lobe.
    pub glossy: f32,
    /// Perfect mirror.
    pub mirror: f32,
    /// Smooth dielectric (Fresnel then picks reflection or refraction).
    pub dielectric: f32,
}

impl LobeChoice {
    /// Proportional to each lobe's weight (luminance of its colour);
    /// all zero when the surface scatters nothing.
    #[inline]
    pub fn new(it: &Interaction) -> Self {
        let s = &it.surface;
        let w = if let Some(g) = &s.gltf {
            // The glTF BRDF: its Lambertian base and its specular layers
            // (drawn by visible normals), and the smooth glass lobe.
            let (diffuse, specular) = g.lobe_weights(it.ns.dot(it.wo));
            if g.is_smooth() {
                // A smooth layer is the mirror lobe.
                [diffuse, 0.0, specular, s.transmission.max(0.0)]
            } else {
                [diffuse, specular, 0.0, s.transmission.max(0.0)]
            }
        } else {
            [
                luminance(s.diffuse).max(0.0),
                luminance(s.specular).max(0.0),
                luminance(s.mirror).max(0.0),
                // The dielectric's reflection is untinted: weigh it by its
                // transmission alone, so a dark tint still reflects.
                s.transmission.max(0.0),
            ]
        };
        let total: f32 = w.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Self {
                diffuse: 0.0,
                glossy: 0.0,
                mirror: 0.0,
                dielectric: 0.0,
            };
        }
        Self {
            diffuse: w[0] / total,
            glossy: w[1] / total,
            mirror: w[2] / total,
            dielectric: w[3] / total,
        }
    }

    /// True when a non-specular lobe can be chosen.
    #[inline]
    pub fn has_smooth(&self) -> bool {
        self.diffuse > 0.0 || self.glossy > 0.0
    }
}

/// Blinn-Phong half-vector density `(s+1)/(2 pi) (n.h)^s`, converted to
/// the density of the reflected direction.
#[inline]
fn glossy_pdf(it: &Interaction, wi: Vec3A) -> f32 {
    let h = (it.wo + wi).normalize_or_zero();
    let cos_h = it.ns.dot(h);
    let wo_h = it.wo.dot(h);
    if cos_h <= 0.0 || wo_h <= 0.0 {
        return 0.0;
    }
    let s = it.surface.shininess;
    (s + 1.0) / (2.0 * PI) * cos_h.powf(s) / (4.0 * wo_h)
}

/// Density of drawing `wi` with [`sample_bsdf`] through its non-specular
/// lobes (the specular ones are Dirac and never drawn twice).
#[inline]
pub fn bsdf_pdf(it: &Interaction, lobes: &LobeChoice, wi: Vec3A) -> f32 {
    let mut p = 0.0;
    if lobes.diffuse > 0.0 {
        p += lobes.diffuse * it.ns.dot(wi).max(0.0) / PI;
    }
    if lobes.glossy > 0.0 {
        p += lobes.glossy
            * match &it.surface.gltf {
                Some(g) => g.specular_pdf(it.ns, it.wo, wi),
                None => glossy_pdf(it, wi),
            };
    }
    p
}

/// The BRDF times the cosine that path transport uses: the glTF
/// microfacet BRDF for glTF surfaces that have one, else the Whitted
/// model's Lambert plus Blinn-Phong ([`brdf_cos`]).
#[inline]
pub fn bsdf_cos(it: &Interaction, wi: Vec3A) -> Color {
    match &it.surface.gltf {
        Some(g) => g.eval_cos(it.ns, it.wo, wi),
        None => brdf_cos(&it.surface, it.ns, it.wo, wi),
    }
}

/// True when next-event estimation can reach the surface: it has a
/// diffuse or glossy lobe (a smooth glTF layer without a Lambertian base
/// has neither).
#[inline]
pub fn is_lit(it: &Interaction) -> bool {
    match &it.surface.gltf {
        Some(g) => !g.is_smooth() || g.diffuse != Color::ZERO,
        None => it.is_lit_by_lights(),
    }
}

/// A direction drawn from the surface's lobes.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The continuation ray (origin offset from the surface).
    pub ray: Ray,
    /// BSDF times cosine over density: the throughput multiplier.
    pub weight: Color,
    /// Density of the direction for multiple importance sampling; zero
    /// for specular lobes.
    pub pdf: f32,
    /// Reflection or refraction.
    pub kind: RayKind,
}

/// Draws the next direction: `u_lobe` chooses the lobe, `u` the direction
/// within it. `None` when the surface scatters nothing or the direction
/// falls below the surface.
pub fn sample_bsdf(
    it: &Interaction,
    lobes: &LobeChoice,
    u_lobe: f32,
    u: Vec2,
) -> Option<BsdfSample> {
    let s = &it.surface;
    let smooth = lobes.diffuse + lobes.glossy;
    if u_lobe < smooth {
        let wi = if u_lobe < lobes.diffuse {
            cosine_hemisphere(it.ns, u)
        } else if let Some(g) = &s.gltf {
            g.sample_specular(it.ns, it.wo, u)?
        } else {
            // Half vector around the shading normal, then reflect.
            let cos_h = u.x.powf(1.0 / (s.shininess + 1.0));
            let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
            let phi = 2.0 * PI * u.y;
            let (t, b) = orthonormal_basis(it.ns);
            let h = t * (sin_h * phi.cos()) + b * (sin_h * phi.sin()) + it.ns * cos_h;
            reflect(-it.wo, h)
        };
        if it.ng.dot(wi) <= 0.0 {
            return None;
        }
        let pdf = bsdf_pdf(it, lobes, wi);
        let f = bsdf_cos(it, wi);
        if !(pdf > 0.0) || f == Color::ZERO {
            return None;
        }
        return Some(BsdfSample {
            ray: Ray::new(it.offset(it.ng), wi),
            weight: f / pdf,
            pdf,
            kind: RayKind::Reflection,
        });
    }
    let d = -it.wo;
    let mirror_dir = || {
        let r = reflect(d, it.ns);
        if r.dot(it.ng) <= 0.0 {
            reflect(d, it.ng)
        } else {
            r
        }
    };
    if u_lobe < smooth + lobes.mirror || lobes.dielectric == 0.0 {
        if lobes.mirror == 0.0 {
            return None;
        }
        let (direction, reflectance) = match &s.gltf {
            // A smooth glTF layer: the limit of its microfacet lobe, the
            // reflection about the shading normal with the Fresnel
            // reflectance, and none where that falls below the surface.
            Some(g) => {
                let cos_o = it.ns.dot(it.wo);
                let r = reflect(d, it.ns);
                if !(cos_o > 0.0) || r.dot(it.ng) <= 0.0 {
                    return None;
                }
                (r, g.smooth_reflectance(cos_o))
            }
            None => (mirror_dir(), s.mirror),
        };
        return Some(BsdfSample {
            ray: Ray::new(it.offset(it.ng), direction),
            weight: reflectance / lobes.mirror,
            pdf: 0.0,
            kind: RayKind::Reflection,
        });
    }
    // Dielectric: Fresnel decides between reflection and refraction, so
    // each keeps the weight transmission / P(dielectric).
    let eta = if it.front_face { 1.0 / s.ior } else { s.ior };
    let cos_i = it.ns.dot(it.wo).max(0.0);
    let f = fresnel_dielectric(cos_i, eta);
    // Reuse the lobe number's position within the dielectric's interval.
    let u_f = ((u_lobe - smooth - lobes.mirror) / lobes.dielectric).clamp(0.0, 1.0);
    let base = s.transmission / lobes.dielectric;
    if u_f >= f
        && let Some(t) = refract(d, it.ns, eta)
        && t.dot(it.ng) < 0.0
    {
        return Some(BsdfSample {
            ray: Ray::new(it.offset(-it.ng), t),
            weight: s.transmission_tint * base,
            pdf: 0.0,
            kind: RayKind::Refraction,
        });
    }
    Some(BsdfSample {
        ray: Ray::new(it.offset(it.ng), mirror_dir()),
        weight: Color::splat(base),
        pdf: 0.0,
        kind: RayKind::Reflection,
    })
}

/// The sampler dimension of a path's wavelength in spectral mode: a set
/// of its own, far beyond every bounce's.
pub const WAVELENGTH_DIMENSION: u32 = 0xFFFF_FFF0;

/// The path's wavelength (nm) when path transport is spectral (the scene
/// has a dispersive material), read from its own sampler dimension so
/// that both integrators draw the same; `None` otherwise, and then nothing
/// of the path changes.
#[inline]
pub fn path_wavelength(
    scene: &RenderScene,
    settings: &RenderSettings,
    sampler: &mut Sampler,
) -> Option<f32> {
    if !(scene.is_spectral() && settings.transport == Transport::Path) {
        return None;
    }
    sampler.set_dimension(WAVELENGTH_DIMENSION);
    Some(sample_wavelength(sampler.next_f32()))
}

/// Sets the index of refraction of a dispersive surface to its value at
/// the path's wavelength `lambda` (nothing without one).
#[inline]
pub fn at_wavelength(it: &mut Interaction, lambda: Option<f32>) {
    if let (Some(l), Some(d)) = (lambda, it.surface.dispersion) {
        it.surface.ior = d.ior(l);
    }
}

/// The film weight of a path of wavelength `lambda`: its RGB radiance
/// times the wavelength's RGB response ([`wavelength_weight`]); unchanged
/// without a wavelength.
#[inline]
pub fn weigh_wavelength(radiance: Color, lambda: Option<f32>) -> Color {
    match lambda {
        Some(l) => radiance * wavelength_weight(l),
        None => radiance,
    }
}

/// First dimension of bounce `depth` in a path's sampler.
///
/// Dimensions come in sets of four, which the Sobol sampler stratifies
/// together (its best pair is the first two of a set): the film position
/// takes set 0 (`(x, y)` jitter, two spare); each bounce takes one set per
/// light sample, `(point u, point v, which light, spare)`, and one for the
/// BSDF, `(medium, medium, lobe, roulette)`, whose first two numbers only
/// a scattering event in a medium draws (see [`crate::transport::volume`]).
/// A surface's BSDF direction comes from [`direction_numbers`] instead.
#[inline]
pub fn bounce_dimension(settings: &RenderSettings, depth: u32) -> u32 {
    let stride = 4 * (1 + settings.light_samples);
    4u32.wrapping_add(depth.wrapping_mul(stride))
}

/// First dimension of the sets that hold the BSDF directions of surface
/// vertices: far above the bounces' own ([`bounce_dimension`] of the
/// deepest bounce with the most light samples stays below it) and below
/// the media's (`volume::medium_dimension`).
pub const DIRECTION_DIMENSION: u32 = 0x2000_0000;

/// The Sobol set (dimensions `4 set .. 4 set + 4`) that holds the BSDF
/// direction of a surface vertex at bounce `depth` ([`direction_numbers`]).
#[inline]
pub fn direction_set(depth: u32) -> u32 {
    DIRECTION_DIMENSION.wrapping_add(4 * (depth / 2)) / 4
}

/// The two numbers from which a surface vertex at bounce `depth` draws
/// its BSDF direction. Bounces `2j` and `2j + 1` share one Sobol set of
/// four: `(u, v)` of the first, then `(u, v)` of the second, so that the
/// directions of consecutive bounces are stratified together, in four
/// dimensions, rather than each pair on its own with a random pairing
/// between them (Burley's padding, as the other sets have it). Light that
/// bounces twice or more is two thirds of the Cornell box's error; this
/// lowers its mean relative error by 3% at 64 and 5% at 256 samples per
/// pixel (README, "Path transport", "Sampler"). The set is kept apart from
/// the one-set cache ([`Sampler::set_of_four_kept`]), so the second
/// bounce of a pair finds it without computing it again.
#[inline]
pub fn direction_numbers(sampler: &mut Sampler, depth: u32) -> Vec2 {
    let set = sampler.set_of_four_kept(4 * direction_set(depth));
    if depth.is_multiple_of(2) {
        Vec2::new(set[0], set[1])
    } else {
        Vec2::new(set[2], set[3])
    }
}

/// Shadow rays of next-event estimation at a path vertex of bounce
/// `depth`: one per punctual light that can contribute (as the Whitted
/// model has them), and `settings.light_samples` samples of the area
/// lights. Area-light samples are weighted by multiple importance sampling
/// against the BSDF, except at the last vertex (`depth == max_depth`),
/// whose BSDF ray is never traced: there they take the full weight. `emit`
/// receives each query; the radiance is not yet multiplied by the path
/// throughput.
#[inline]
pub fn next_event(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    lobes: &LobeChoice,
    sampler: &mut Sampler,
    depth: u32,
    emit: impl FnMut(ShadowQuery),
) {
    next_event_with(scene, settings, it, lobes, sampler, depth, true, emit);
}

/// [`next_event`], with the area lights' samples drawn but dropped unless
/// `area` (at a vertex whose paths to area emitters caustic connections
/// take, see [`crate::transport::caustic`]): the other lights and the
/// sampler's dimensions are unchanged.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn next_event_with(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    lobes: &LobeChoice,
    sampler: &mut Sampler,
    depth: u32,
    area: bool,
    mut emit: impl FnMut(ShadowQuery),
) {
    let first = bounce_dimension(settings, depth);
    if !is_lit(it) {
        return;
    }
    for light in scene.lights() {
        let q = if it.surface.gltf.is_some() {
            direct_light_with(it, light, |wi| bsdf_cos(it, wi))
        } else {
            direct_light(it, light)
        };
        if let Some(q) = q {
            emit(q);
        }
    }
    let n = settings.light_samples;
    // One set of four per light sample: the point's pair first, then the
    // light number.
    let mut numbers = |i: u32| {
        let [a, b, c, _] = sampler.set_of_four(first + 4 * i);
        (Vec2::new(a, b), c)
    };
    let Some(env) = scene.environment() else {
        if scene.emitters().is_empty() {
            return;
        }
        if !area {
            return;
        }
        for i in 0..n {
            let (v, u) = numbers(i);
            if let Some(q) = area_light_sample(scene, settings, it, lobes, (u, v), 1.0, depth) {
                emit(q);
            }
        }
        return;
    };
    // With an environment, the light number first picks it (with
    // probability `p_env`) or the area lights, then is stretched back to
    // [0, 1) for the area lights' own choice.
    let p_env = scene.environment_selection();
    for i in 0..n {
        let (v, u) = numbers(i);
        let q = if u < p_env {
            environment_sample(settings, it, lobes, env, p_env, v, depth)
        } else if !area {
            None
        } else {
            let u = ((u - p_env) / (1.0 - p_env)).min(1.0 - f32::EPSILON / 2.0);
            area_light_sample(scene, settings, it, lobes, (u, v), 1.0 - p_env, depth)
        };
        if let Some(q) = q {
            emit(q);
        }
    }
}

/// One next-event sample of the area lights, drawn with `u` (which light)
/// and `v` (where on it), the area lights being chosen with probability
/// `select` among all lights: a shadow ray to the point carrying its
/// MIS-weighted radiance (full weight at the last vertex).
#[inline]
fn area_light_sample(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    lobes: &LobeChoice,
    (u, v): (f32, Vec2),
    select: f32,
    depth: u32,
) -> Option<ShadowQuery> {
    let n = settings.light_samples;
    let ls = scene
        .emitters()
        .sample(scene.instances(), scene.materials(), u, v)?;
    let to = ls.point - it.point;
    let dist2 = to.length_squared();
    if !(dist2 > 0.0 && dist2.is_finite()) {
        return None;
    }
    let dist = dist2.sqrt();
    let wi = to / dist;
    let cos_l = ls.normal.dot(wi).abs();
    if it.ng.dot(wi) <= 0.0 || !(cos_l > 0.0) {
        return None;
    }
    let f = if it.surface.gltf.is_some() {
        bsdf_cos(it, wi)
    } else {
        brdf_cos(&it.surface, it.ns, it.wo, wi)
    };
    if f == Color::ZERO {
        return None;
    }
    let pdf_light = ls.pdf_area * dist2 / cos_l * select;
    // The MIS weight over the density of the `n` samples.
    let w_over_pdf = if depth < settings.max_depth {
        power_heuristic_over_density(n as f32, pdf_light, bsdf_pdf(it, lobes, wi))
    } else {
        1.0 / (n as f32 * pdf_light)
    };
    let radiance = f * ls.radiance * w_over_pdf;
    if !(max_component(radiance) > 0.0) || !radiance.is_finite() {
        return None;
    }
    // End the segment just short of the emitter, so that the emitter
    // itself never counts as a blocker. The shadow ray's own hit on
    // it is off by a few ulps of the largest of its origin, its length
    // and the point, in the direction of the surface normal, which is
    // that divided by the cosine along the ray: at grazing angles a
    // fixed offset along the normal was not enough (seen: 11% of a
    // sphere light's visible samples lost to self-shadowing, more when
    // the light sat nearer the render origin than the receiver).
    let origin = it.offset(it.ng);
    let t_light = (ls.point - origin).dot(wi);
    let scale = ls
        .point
        .abs()
        .max_element()
        .max(origin.abs().max_element())
        .max(t_light);
    let t_max = t_light - OFFSET_ULPS * f32::EPSILON * scale / cos_l;
    if !(t_max > 0.0) {
        return None;
    }
    Some(ShadowQuery {
        ray: Ray::new(origin, wi),
        t_max,
        radiance,
    })
}

/// One next-event sample of the environment, drawn with `v`, chosen with
/// probability `p_env` among the lights: a shadow ray to infinity carrying
/// its MIS-weighted radiance (full weight at the last vertex).
fn environment_sample(
    settings: &RenderSettings,
    it: &Interaction,
    lobes: &LobeChoice,
    env: &Environment,
    p_env: f32,
    v: Vec2,
    depth: u32,
) -> Option<ShadowQuery> {
    let n = settings.light_samples;
    let es = env.sample(v)?;
    let wi = es.direction;
    if it.ng.dot(wi) <= 0.0 {
        return None;
    }
    let f = bsdf_cos(it, wi);
    if f == Color::ZERO {
        return None;
    }
    let pdf_light = es.pdf * p_env;
    let w_over_pdf = if depth < settings.max_depth {
        power_heuristic_over_density(n as f32, pdf_light, bsdf_pdf(it, lobes, wi))
    } else {
        1.0 / (n as f32 * pdf_light)
    };
    let radiance = f * es.radiance * w_over_pdf;
    if !(max_component(radiance) > 0.0) || !radiance.is_finite() {
        return None;
    }
    Some(ShadowQuery {
        ray: Ray::new(it.offset(it.ng), wi),
        t_max: f32::INFINITY,
        radiance,
    })
}

/// Radiance brought back by a ray that left the scene in `direction`:
/// the background, or the environment weighted against next-event
/// estimation when the previous vertex drew the ray with density
/// `prev_pdf` (zero after the camera or a specular lobe: weight 1).
#[inline]
pub fn escaped(
    scene: &RenderScene,
    settings: &RenderSettings,
    direction: Vec3A,
    prev_pdf: f32,
) -> Color {
    let Some(env) = scene.environment() else {
        return scene.background();
    };
    let l = env.radiance(direction);
    if prev_pdf <= 0.0 || l == Color::ZERO {
        return l;
    }
    let pdf_light = scene.environment_selection() * env.pdf(direction.normalize());
    l * power_heuristic(1.0, prev_pdf, settings.light_samples as f32, pdf_light)
}

/// Emission seen at a hit, weighted against next-event estimation:
/// `prev_pdf` is the density with which the previous vertex drew this
/// ray's direction (zero after the camera or a specular lobe: weight 1),
/// `distance` the ray's length to the hit.
#[inline]
pub fn emitted(
    scene: &RenderScene,
    settings: &RenderSettings,
    it: &Interaction,
    instance: u32,
    prev_pdf: f32,
    distance: f32,
) -> Color {
    let le = it.surface.emission;
    if le == Color::ZERO || prev_pdf <= 0.0 {
        return le;
    }
    let pdf_area = scene
        .emitters()
        .pdf_area(scene.instances(), instance, it.point);
    if pdf_area <= 0.0 {
        return le;
    }
    let cos_l = it.ng.dot(it.wo).abs();
    if !(cos_l > 0.0) {
        return Color::ZERO;
    }
    let mut pdf_light = pdf_area * distance * distance / cos_l;
    if scene.environment().is_some() {
        pdf_light *= 1.0 - scene.environment_selection();
    }
    le * power_heuristic(1.0, prev_pdf, settings.light_samples as f32, pdf_light)
}

/// Russian roulette at a path vertex of depth `depth`: `Some(scale)` if
/// the path goes on, its throughput multiplied by `scale` (at least 1),
/// `None` if it ends. Survival probability is the throughput's largest
/// channel over [`RenderSettings::rr_weight`], capped at 1.
#[inline]
pub fn roulette(settings: &RenderSettings, depth: u32, throughput: Color, u: f32) -> Option<f32> {
    match settings.rr_start_depth {
        Some(start) if depth >= start => {
            let q = (max_component(throughput) / settings.rr_weight).min(1.0);
            (q > 0.0 && u < q).then(|| 1.0 / q)
        }
        _ => Some(1.0),
    }
}

/// What a path vertex produced, for either integrator to route.
#[derive(Clone, Copy, Debug)]
pub struct Continuation {
    /// The next ray and its throughput multiplier and density.
    pub sample: BsdfSample,
    /// Roulette scale applied on top of `sample.weight`.
    pub scale: f32,
}

impl Continuation {
    /// The ray cone the continuation ray carries: the cone at the vertex
    /// `it` for a perfectly specular lobe (density 0), none otherwise.
    #[inline]
    pub fn cone(&self, it: &Interaction) -> crate::core::math::RayCone {
        if self.sample.pdf == 0.0 {
            it.cone
        } else {
            crate::core::math::RayCone::NONE
        }
    }
}

/// Chooses how the path continues from a vertex at `depth` whose ray came
/// with `throughput`: lobe, direction, roulette, depth and contribution
/// limits. Reads the sampler's lobe, direction and roulette dimensions.
#[inline]
pub fn continue_path(
    settings: &RenderSettings,
    it: &Interaction,
    lobes: &LobeChoice,
    depth: u32,
    throughput: Color,
    sampler: &mut Sampler,
) -> Option<Continuation> {
    if depth >= settings.max_depth {
        return None;
    }
    let u = direction_numbers(sampler, depth);
    // The lobe and roulette numbers, drawn only when something reads them:
    // a surface whose diffuse lobe has probability 1 (a Lambertian one, all
    // of the Cornell box) chooses it for any number below 1, 0 included,
    // and roulette reads its number only from its first bounce on. Every
    // number is the same whether or not another was drawn.
    let bsdf_set = bounce_dimension(settings, depth) + 4 * settings.light_samples;
    let u_lobe = if lobes.diffuse == 1.0 {
        0.0
    } else {
        sampler.set_of_four(bsdf_set)[2]
    };
    let sample = sample_bsdf(it, lobes, u_lobe, u)?;
    let t = throughput * sample.weight;
    if max_component(t) < settings.min_contribution || !t.is_finite() {
        return None;
    }
    let u_rr = if settings
        .rr_start_depth
        .is_some_and(|start| depth + 1 >= start)
    {
        sampler.set_of_four(bsdf_set)[3]
    } else {
        0.0
    };
    let scale = roulette(settings, depth + 1, t, u_rr)?;
    Some(Continuation { sample, scale })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the (u, v) of bounce `a` and of bounce `b`, over a pixel's
    /// first 256 Sobol samples, form a (t, 8, 4)-net in base 2: exactly
    /// `2^t` points in every box `[i1/2^e1, (i1+1)/2^e1) x ...` of the
    /// four numbers with `e1 + e2 + e3 + e4 = 8 - t`.
    fn is_net(pixel: u32, a: u32, b: u32, t: u32) -> bool {
        use crate::core::rng::SamplerKind;
        let points: Vec<[f32; 4]> = (0..256)
            .map(|sample| {
                let mut s = Sampler::with_kind(SamplerKind::Sobol, 7, pixel, sample);
                let (p, q) = (direction_numbers(&mut s, a), direction_numbers(&mut s, b));
                [p.x, p.y, q.x, q.y]
            })
            .collect();
        for e in 0..8u32.pow(4) {
            let e = [e % 8, e / 8 % 8, e / 64 % 8, e / 512];
            if e.iter().sum::<u32>() != 8 - t {
                continue;
            }
            let mut count = std::collections::HashMap::new();
            for p in &points {
                let cell: [u32; 4] = std::array::from_fn(|k| (p[k] * (1u32 << e[k]) as f32) as u32);
                *count.entry(cell).or_insert(0u32) += 1;
            }
            if count.len() != (256 >> t) || count.values().any(|&c| c != 1 << t) {
                return false;
            }
        }
        true
    }

    /// Bounces 2j and 2j + 1 draw their directions from one Sobol set, so
    /// that the two directions are stratified together in four
    /// dimensions; bounces in different sets are not.
    #[test]
    fn consecutive_bounces_draw_directions_stratified_together() {
        // The first four Sobol dimensions form (3, m, 4)-nets (Owen
        // scrambling keeps that): eight points in every box of volume 2^-5.
        // Independently shuffled sets only stratify each pair on its own.
        for pixel in [0, 1, 77, 12345] {
            assert!(is_net(pixel, 0, 1, 3), "pixel {pixel}, bounces 0 and 1");
            assert!(is_net(pixel, 6, 7, 3), "pixel {pixel}, bounces 6 and 7");
            assert!(!is_net(pixel, 0, 2, 3), "pixel {pixel}, bounces 0 and 2");
            assert!(!is_net(pixel, 1, 2, 4), "pixel {pixel}, bounces 1 and 2");
        }
        // The pair's numbers are one set's, in order, and the set is the
        // same whether or not another set was drawn in between.
        let mut s = Sampler::with_kind(crate::core::rng::SamplerKind::Sobol, 3, 9, 5);
        let first = direction_numbers(&mut s, 4);
        let _ = s.set_of_four(bounce_dimension(&RenderSettings::default(), 5));
        let second = direction_numbers(&mut s, 5);
        let set = Sampler::with_kind(crate::core::rng::SamplerKind::Sobol, 3, 9, 5)
            .set_of_four(DIRECTION_DIMENSION + 8);
        assert_eq!([first.x, first.y, second.x, second.y], set);
    }

    #[test]
    fn roulette_keeps_the_expectation() {
        let settings = RenderSettings {
            rr_start_depth: Some(1),
            rr_weight: 1.0,
            ..Default::default()
        };
        let t = Color::new(0.3, 0.2, 0.1);
        let n = 100_000;
        let mut sum = 0.0f64;
        for i in 0..n {
            let u = Sampler::new(1, i, 0).next_f32();
            if let Some(s) = roulette(&settings, 1, t, u) {
                sum += s as f64 * 0.3;
            }
        }
        // Each survivor carries 0.3 / 0.3 = 1 with probability 0.3: mean
        // 0.3, standard error sqrt(0.3 * 0.7 / n) = 1.45e-3; 5 sigma.
        assert!((sum / n as f64 - 0.3).abs() < 5.0 * 1.45e-3);
        assert_eq!(roulette(&settings, 0, t, 0.99), Some(1.0));
    }

    #[test]
    fn roulette_spares_paths_at_its_weight_and_lifts_lighter_ones_to_it() {
        let settings = RenderSettings {
            rr_start_depth: Some(1),
            rr_weight: 0.25,
            ..Default::default()
        };
        // At or above the weight: never ended, never rescaled.
        for t in [Color::new(0.3, 0.2, 0.1), Color::new(0.0, 0.25, 0.0)] {
            for u in [0.0, 0.5, 0.999_999] {
                assert_eq!(roulette(&settings, 1, t, u), Some(1.0), "{t} {u}");
            }
        }
        // Below it: survival 0.05 / 0.25 = 0.2, survivors weighed up to
        // 0.25; the mean stays 0.05.
        let t = Color::new(0.05, 0.02, 0.01);
        let n = 100_000;
        let (mut sum, mut survivors) = (0.0f64, 0u32);
        for i in 0..n {
            let u = Sampler::new(2, i, 0).next_f32();
            if let Some(s) = roulette(&settings, 1, t, u) {
                assert!((s * 0.05 - 0.25).abs() < 1e-6, "{s}");
                sum += s as f64 * 0.05;
                survivors += 1;
            }
        }
        // Each survivor carries 0.25 with probability 0.2: mean 0.05,
        // standard error 0.25 sqrt(0.2 * 0.8 / n) = 3.2e-4; 5 sigma.
        assert!(
            (sum / n as f64 - 0.05).abs() < 5.0 * 3.2e-4,
            "{}",
            sum / n as f64
        );
        let p = survivors as f64 / n as f64;
        assert!(
            (p - 0.2).abs() < 5.0 * (0.2f64 * 0.8 / n as f64).sqrt(),
            "{p}"
        );
    }
    /// A glTF surface of roughness 0 has a smooth (Dirac) specular layer:
    /// a metal is not lit by next-event estimation and reflects about the
    /// normal with its Schlick Fresnel reflectance, worked out here in f64;
    /// a dielectric's layer over its Lambertian base is drawn as the
    /// mirror lobe, and its sampled weights average to the base's albedo
    /// (its `eval_cos`, which `bsdf_cos` is, integrated by a midpoint rule) plus the layer's
    /// reflectance.
    #[test]
    fn smooth_gltf_layers_are_dirac_lobes() {
        use crate::scene::material::Material;
        let cos_o = 0.6f32;
        let wo = Vec3A::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
        let interaction = |m: Material| Interaction {
            point: Vec3A::ZERO,
            ng: Vec3A::Z,
            ns: Vec3A::Z,
            wo,
            front_face: true,
            surface: m.sample(Vec2::ZERO),
            cone: Default::default(),
            offset_scale: 0.0,
        };
        let base = Color::new(0.9, 0.6, 0.3);
        let metal = interaction(Material::from_metallic_roughness(
            base,
            1.0,
            0.0,
            Color::splat(0.04),
            0.0,
            1.5,
        ));
        assert!(metal.surface.gltf.is_some_and(|g| g.is_smooth()));
        assert!(!is_lit(&metal));
        let lobes = LobeChoice::new(&metal);
        assert_eq!((lobes.diffuse, lobes.glossy, lobes.mirror), (0.0, 0.0, 1.0));
        let m5 = (1.0 - cos_o as f64).powi(5);
        for (u_lobe, u) in [(0.0, Vec2::ZERO), (0.7, Vec2::new(0.3, 0.9))] {
            let s = sample_bsdf(&metal, &lobes, u_lobe, u).expect("a reflection");
            assert_eq!(s.pdf, 0.0);
            assert_eq!(s.kind, RayKind::Reflection);
            assert_eq!(s.ray.direction, reflect(-wo, Vec3A::Z));
            for (w, b) in s.weight.to_array().into_iter().zip(base.to_array()) {
                let fresnel = b as f64 + (1.0 - b as f64) * m5;
                assert!((w as f64 - fresnel).abs() < 1e-6, "{w} vs {fresnel}");
            }
        }

        // A shading normal tilted so that the reflection about it falls
        // below the surface: absorbed, as by the microfacet lobe in the
        // limit (a Whitted mirror would reflect about the geometric
        // normal instead).
        let tilted = Interaction {
            ns: Vec3A::new(1.0, 0.0, 1.0).normalize(),
            wo: Vec3A::new(-0.5, 0.0, 1.0).normalize(),
            ..metal
        };
        assert!(tilted.ns.dot(tilted.wo) > 0.0);
        assert!(reflect(-tilted.wo, tilted.ns).z < 0.0);
        assert!(sample_bsdf(&tilted, &LobeChoice::new(&tilted), 0.5, Vec2::ZERO).is_none());

        let plastic = interaction(Material::from_metallic_roughness(
            Color::splat(0.5),
            0.0,
            0.0,
            Color::splat(0.04),
            0.0,
            1.5,
        ));
        let lobes = LobeChoice::new(&plastic);
        assert!(is_lit(&plastic) && lobes.diffuse > 0.0 && lobes.mirror > 0.0);
        assert_eq!(lobes.glossy, 0.0);
        // `bsdf_cos` of a glTF surface is its BRDF's `eval_cos` (here
        // with the shading normal +Z).
        let brdf = plastic.surface.gltf.unwrap();
        let albedo = crate::core::microfacet::tests::albedo_quadrature(&brdf, wo, 400, 400);
        let layer = brdf.smooth_reflectance(cos_o).x as f64;
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for k in 0..n {
            let mut r = Sampler::new(5, k, 0);
            let (u_lobe, u) = (r.next_f32(), Vec2::new(r.next_f32(), r.next_f32()));
            if let Some(s) = sample_bsdf(&plastic, &lobes, u_lobe, u) {
                let x = s.weight.x as f64;
                sum += x;
                sum2 += x * x;
            }
        }
        let mean = sum / n as f64;
        let err = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!(
            (mean - (albedo + layer)).abs() < 5.0 * err + 1e-4,
            "sampled {mean} +- {err}, integrated base {albedo} + layer {layer}"
        );
    }
}
