//! Light tracing of caustics: an estimator of the caustics seen directly
//! by the camera, which path tracing samples worst.
//!
//! A path tracer finds light that reached a diffuse surface through a
//! specular chain (`L S+ D`) only when a BSDF sample happens to leave the
//! diffuse surface towards the chain and the chain happens to end on an
//! emitter: rare, bright samples, the speckle over the walls and floor of
//! `assets/gltf/spheres.gltf` that dominates its error long after the
//! rest has converged. A *light subpath* goes the other way: it leaves an
//! emitter (a point by the emitters' own distribution, a direction on
//! either side aimed at the bounding spheres of the specular-like objects,
//! [`aim`]), follows specular-like
//! surfaces ([`specular_like`]) and stops at the first other surface, the
//! *caustic vertex* `D`, which is then connected to the eye and added to
//! the pixel it projects to ([`splat`]).
//!
//! The two estimators share the path space without overlap, so no
//! weights are needed: light tracing takes exactly the paths
//! `E D S+ L` in which `D` is the camera ray's hit, a non-specular-like
//! surface that the camera path leaves through a non-specular lobe, every
//! `S` is a specular-like surface and `L` an area emitter; path tracing
//! skips exactly those ([`ChainState`]): the emission its BSDF samples
//! find at the end of such a chain, and the area-light samples of
//! next-event estimation from the chain's vertices. Every other path
//! (caustics seen through a mirror or after another diffuse bounce,
//! punctual lights, the environment) stays with path tracing.
//!
//! A light subpath's weight `beta` is the emitted radiance over the
//! density of its point and direction, times each chain vertex's BSDF
//! weight with the adjoint shading-normal factor
//! `|w_o.n_s| |w_i.n_g| / (|w_o.n_g| |w_i.n_s|)` (Veach 1997, 5.3.2).
//! With `w` the direction from `D` to the eye at distance `r`, `w_l` the
//! direction back along the chain and `cos_e` the cosine between `w` and
//! the viewing direction, the pixel under `D` receives
//! `beta f_D(w, w_l) |n_s.w_l| / |n_g.w_l| |n_g.w| / (r^2 cos_e^3 A)`
//! (`A` the area of one pixel on the image plane at distance 1) divided by
//! the number of light subpaths: the change of variables from the film
//! position of a camera ray to the point `D` it hits.

use std::f32::consts::PI;

use glam::Vec2;

use crate::core::math::{Color, Ray, max_component};
use crate::core::optics::{OFFSET_ULPS, offset_origin_scaled};
use crate::core::rng::Sampler;
use crate::core::sampling::cosine_hemisphere;
use crate::core::settings::RenderSettings;
use crate::scene::RenderScene;
use crate::scene::camera::{CameraProjection, CameraRays};
use crate::scene::material::{Material, SurfaceSample};
use crate::transport::interaction::{Interaction, ShadowQuery, brdf_cos};
use crate::transport::medium::interior_transmittance;
use crate::transport::path::{LobeChoice, bsdf_cos, sample_bsdf};

/// GGX `alpha` below which a glTF surface's specular layer counts as
/// specular-like (roughness about 0.1): a lobe that narrow sends next-event
/// estimation's shadow rays nowhere useful, so path tracing finds light
/// through it only by its BSDF samples, as through a mirror.
pub const SPECULAR_ALPHA: f32 = 0.01;

/// Salt of the light subpath's sampler ([`Sampler::fork`]).
const LIGHT_SUBPATH_SALT: u64 = 0xc4a5_71c0_11ec_7100;

/// Whether the surface `s` is specular-like: it scatters only through
/// perfect mirrors, smooth glass or glTF specular layers narrower than
/// [`SPECULAR_ALPHA`] (no Lambertian part, no Blinn-Phong highlight), and
/// scatters at all. Depends on the surface only, never on directions, so
/// that the light subpath and path tracing classify a vertex alike.
#[inline]
pub fn specular_like(s: &SurfaceSample) -> bool {
    match &s.gltf {
        Some(g) => {
            let layer = g.metallic > 0.0 || g.dielectric_weight > 0.0;
            g.diffuse == Color::ZERO
                && (!layer || g.alpha < SPECULAR_ALPHA)
                && (layer || s.transmission > 0.0)
        }
        None => {
            s.diffuse == Color::ZERO
                && s.specular == Color::ZERO
                && (s.mirror != Color::ZERO || s.transmission > 0.0)
        }
    }
}

/// Whether some point of a surface of material `m` can be specular-like
/// ([`specular_like`]) whatever its textures: it has a mirror or a
/// transmission, or a glTF specular layer whose roughness is textured or
/// below [`SPECULAR_ALPHA`]'s. Light subpaths aim at every object for
/// which this holds, so none that path tracing leaves to them is missed.
pub fn could_be_specular(m: &Material) -> bool {
    m.transmission > 0.0
        || m.mirror != Color::ZERO
        || m.metallic_roughness
            .as_ref()
            .is_some_and(|mr| mr.texture.is_some() || mr.roughness * mr.roughness < SPECULAR_ALPHA)
}

/// The end of a light subpath: where light arrived through a specular
/// chain.
#[derive(Clone, Copy, Debug)]
pub struct CausticVertex {
    /// The surface reached; its `wo` points back along the chain.
    pub it: Interaction,
    /// The subpath's weight (see the module documentation).
    pub beta: Color,
    /// Specular-like bounces between the emitter and [`Self::it`].
    pub chain: u32,
}

/// Traces one light subpath with `sampler` (a sampler of its own, see
/// [`light_sampler`]): `None` when its first hit is not specular-like,
/// when it leaves the scene, or when its chain would make paths longer
/// than the settings' depth allows. The second value counts the rays
/// traced.
pub fn light_subpath(
    scene: &RenderScene,
    settings: &RenderSettings,
    targets: &[Target],
    sampler: &mut Sampler,
) -> (Option<CausticVertex>, u32) {
    let mut rays = 0;
    let [u, vx, vy, u_side] = sampler.set_of_four(0);
    let Some(ls) =
        scene
            .emitters()
            .sample(scene.instances(), scene.materials(), u, Vec2::new(vx, vy))
    else {
        return (None, rays);
    };
    if !(ls.pdf_area > 0.0) || ls.radiance == Color::ZERO {
        return (None, rays);
    }
    // Either side emits: one chosen with probability 1/2, then a
    // direction aimed at the specular-like objects ([`aim`]), weighted
    // `Le cos / (pdf_area / 2 pdf_dir)`. (Letting the aimed direction
    // pick the side instead doubles the subpaths that reach a caustic
    // vertex, but cost more time than the error it saved: measurement
    // log, stop 41.)
    let n = if u_side < 0.5 { ls.normal } else { -ls.normal };
    let [a, b, c, _] = sampler.set_of_four(4);
    let Some((dir, pdf_dir)) = aim(targets, ls.point, n, Vec2::new(a, b), c) else {
        return (None, rays);
    };
    let cos = n.dot(dir);
    if !(cos > 0.0 && pdf_dir > 0.0) {
        return (None, rays);
    }
    let mut beta = ls.radiance * (2.0 * cos / (ls.pdf_area * pdf_dir));
    let mut ray = Ray::new(
        offset_origin_scaled(ls.point, n, ls.point.abs().max_element()),
        dir,
    );
    // The emitter of a path `E D S^k L` is at bounce `k + 1`, and path
    // tracing finds emitters by BSDF samples up to bounce `max_depth`:
    // `k` at most `max_depth - 1`.
    let max_chain = settings.max_depth.saturating_sub(1);
    let mut chain = 0u32;
    loop {
        rays += 1;
        let Some(hit) = scene.intersect(&ray, 0.0, f32::INFINITY) else {
            return (None, rays);
        };
        let it = Interaction::new(scene, &ray, &hit);
        if let Some(tr) = interior_transmittance(&it, hit.t * ray.direction.length()) {
            beta *= tr;
        }
        if !specular_like(&it.surface) {
            if chain == 0 {
                return (None, rays);
            }
            return (Some(CausticVertex { it, beta, chain }), rays);
        }
        if chain >= max_chain {
            return (None, rays);
        }
        let lobes = LobeChoice::new(&it);
        let [ux, uy, u_lobe, _] = sampler.set_of_four(8 + 4 * chain);
        let Some(s) = sample_bsdf(&it, &lobes, u_lobe, Vec2::new(ux, uy)) else {
            return (None, rays);
        };
        let wi = s.ray.direction;
        let num = it.wo.dot(it.ns).abs() * wi.dot(it.ng).abs();
        let den = it.wo.dot(it.ng).abs() * wi.dot(it.ns).abs();
        if !(den > 0.0) {
            return (None, rays);
        }
        beta = beta * s.weight * (num / den);
        if !(max_component(beta) > 0.0) || !beta.is_finite() {
            return (None, rays);
        }
        chain += 1;
        ray = s.ray;
    }
}

/// A bounding sphere of a specular-like object, which light subpaths aim
/// at ([`targets`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// Centre.
    pub centre: glam::Vec3A,
    /// Radius, padded.
    pub radius: f32,
}

/// The bounding spheres of the scene's instances whose material could be
/// specular-like somewhere ([`could_be_specular`]); empty when one of them
/// is unbounded (light subpaths then leave in cosine-distributed
/// directions).
pub fn targets(scene: &RenderScene) -> Vec<Target> {
    let mut out = Vec::new();
    for inst in scene.instances() {
        if !could_be_specular(&scene.materials()[inst.material as usize]) {
            continue;
        }
        let Some(b) = inst.world_bounds() else {
            return Vec::new();
        };
        let centre = (b.min + b.max) * 0.5;
        let radius = (b.max - b.min).length() * 0.5;
        let pad = 1e-4 * (radius + centre.abs().max_element());
        if !(radius.is_finite() && centre.is_finite()) {
            return Vec::new();
        }
        out.push(Target {
            centre,
            radius: radius + pad,
        });
    }
    out
}

/// A light subpath's first direction from `p` on the side `n`, drawn with
/// `u` and `u_pick`, and its density per steradian. With `targets`, one is
/// picked uniformly and the direction drawn uniformly in the cone of
/// directions from `p` that meet its sphere; the density sums over every
/// cone that holds the direction, so that any direction towards any of
/// them can be drawn (the only ones whose first hit can be specular-like:
/// the estimator stays unbiased). From inside a sphere, or without
/// targets, the cosine-distributed direction instead.
#[inline]
pub fn aim(
    targets: &[Target],
    p: glam::Vec3A,
    n: glam::Vec3A,
    u: Vec2,
    u_pick: f32,
) -> Option<(glam::Vec3A, f32)> {
    if targets.is_empty() || targets.iter().any(|t| cone(t, p).is_none()) {
        let dir = cosine_hemisphere(n, u);
        return Some((dir, n.dot(dir).max(0.0) / PI));
    }
    let k = ((u_pick * targets.len() as f32) as usize).min(targets.len() - 1);
    let (axis, cos_max) = cone(&targets[k], p)?;
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let (t, b) = crate::core::math::orthonormal_basis(axis);
    let dir = (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize();
    Some((dir, aim_pdf(targets, p, n, dir)))
}

/// The cone of directions from `p` that meet `t`'s sphere: its unit axis
/// and the cosine of its half-angle; `None` from inside the sphere.
#[inline]
fn cone(t: &Target, p: glam::Vec3A) -> Option<(glam::Vec3A, f32)> {
    let to = t.centre - p;
    let d2 = to.length_squared();
    let r2 = t.radius * t.radius;
    (d2 > r2).then(|| {
        let d = d2.sqrt();
        (to / d, (d2 - r2).max(0.0).sqrt() / d)
    })
}

/// The density per steradian with which [`aim`] draws `dir` from `p` on
/// the side `n`.
#[inline]
pub fn aim_pdf(targets: &[Target], p: glam::Vec3A, n: glam::Vec3A, dir: glam::Vec3A) -> f32 {
    let mut pdf = 0.0;
    for t in targets {
        let Some((axis, cos_max)) = cone(t, p) else {
            return n.dot(dir).max(0.0) / PI;
        };
        if dir.dot(axis) >= cos_max {
            pdf += 1.0 / (2.0 * PI * (1.0 - cos_max));
        }
    }
    if targets.is_empty() {
        return n.dot(dir).max(0.0) / PI;
    }
    pdf / targets.len() as f32
}

/// The sampler of light subpath `n` of a frame of `pixels` pixels: its
/// numbers are a pure function of (seed, `n`, dimension). Subpath `n`
/// takes the keys of sample `n / pixels` of pixel `n % pixels`, forked
/// ([`Sampler::fork`]), so the Sobol sampler stratifies them as it does
/// a pixel's samples.
#[inline]
pub fn light_sampler(settings: &RenderSettings, pixels: u64, n: u64) -> Sampler {
    let pixel = (n % pixels) as u32;
    let sample = (n / pixels) as u32;
    Sampler::with_kind(settings.sampler, settings.seed, pixel, sample).fork(LIGHT_SUBPATH_SALT)
}

/// Rows of progress that a recursive render with these settings reports
/// for its light pass ([`crate::integrators::Progress`]), on top of one
/// per pixel row of the camera pass: the image's height when light
/// tracing was asked for under path transport on the whole image (also
/// when [`applicable`] then finds nothing to trace: the pass is reported
/// done at once), else 0.
pub fn light_pass_rows(settings: &RenderSettings) -> u64 {
    let asked = settings.caustics
        && settings.transport == crate::core::settings::Transport::Path
        && settings.window.is_none();
    if asked { settings.height as u64 } else { 0 }
}

/// Whether light tracing of caustics runs for this frame: asked for,
/// path transport in RGB without participating media, area emitters, a
/// material that could be specular-like ([`could_be_specular`]; without
/// one no light subpath could reach a caustic vertex), a pinhole
/// perspective camera (`cam`) and no render window. Otherwise path
/// tracing keeps every path and nothing of light tracing runs.
pub fn applicable(scene: &RenderScene, settings: &RenderSettings, cam: &CameraRays) -> bool {
    settings.caustics
        && settings.transport == crate::core::settings::Transport::Path
        && settings.window.is_none()
        && !scene.has_media()
        && !scene.is_spectral()
        && !scene.emitters().is_empty()
        && settings.max_depth >= 1
        && cam.pinhole_perspective()
        && scene.materials().iter().any(could_be_specular)
}

/// The BSDF times cosine of `it`'s non-specular lobes towards `wi` (what
/// next-event estimation evaluates).
#[inline]
fn smooth_f(it: &Interaction, wi: glam::Vec3A) -> Color {
    if it.surface.gltf.is_some() {
        bsdf_cos(it, wi)
    } else {
        brdf_cos(&it.surface, it.ns, it.wo, wi)
    }
}

/// Film positions per unit area of a surface at `point` with normal `n`
/// seen by the pinhole camera `cam`: `|n.w| / (r^2 cos_e^3 A)` for the
/// direction `w` from the point to the eye at distance `r`, `cos_e` its
/// cosine with the viewing direction and `A` the area of one pixel on the
/// image plane at distance 1 (film positions counted in pixels). `None`
/// behind the eye.
#[inline]
pub fn film_density(cam: &CameraRays, point: glam::Vec3A, n: glam::Vec3A) -> Option<f32> {
    let to = cam.origin() - point;
    let d2 = to.length_squared();
    if !(d2 > 0.0 && d2.is_finite()) {
        return None;
    }
    let w = to / d2.sqrt();
    let cos_e = cam.forward().dot(-w);
    if !(cos_e > 0.0) {
        return None;
    }
    Some(n.dot(w).abs() / (d2 * cos_e * cos_e * cos_e * cam.pixel_area()))
}

/// The eye's view of caustic vertex `v`: the pixel (row-major index) it
/// projects to, a shadow ray to the eye, and the radiance it adds to that
/// pixel per light subpath if the ray is unblocked (see the module
/// documentation); `None` outside the image or when it carries nothing.
#[inline]
pub fn splat(
    settings: &RenderSettings,
    cam: &CameraRays,
    proj: &CameraProjection,
    v: &CausticVertex,
) -> Option<(u32, ShadowQuery)> {
    let eye = cam.origin();
    let to = eye - v.it.point;
    let d2 = to.length_squared();
    if !(d2 > 0.0 && d2.is_finite()) {
        return None;
    }
    let (film, depth) = proj.project(v.it.point);
    if !(depth > 0.0) {
        return None;
    }
    let (w_px, h_px) = (settings.width as f32, settings.height as f32);
    if !(film.x >= 0.0 && film.x < w_px && film.y >= 0.0 && film.y < h_px) {
        return None;
    }
    let pixel = film.y as u32 * settings.width + film.x as u32;
    let dist = d2.sqrt();
    let w = to / dist;
    // `D` seen from the eye: its BSDF with `wo` towards the eye, the
    // light arriving from `v.it.wo`, both on one side.
    let mut d = v.it;
    let wl = v.it.wo;
    d.wo = w;
    if d.ng.dot(w) < 0.0 {
        d.ng = -d.ng;
        d.ns = -d.ns;
        d.front_face = !d.front_face;
    }
    let cos_gl = d.ng.dot(wl);
    if cos_gl <= 0.0 {
        return None;
    }
    let f = smooth_f(&d, wl);
    if f == Color::ZERO {
        return None;
    }
    let radiance = f * v.beta * (film_density(cam, d.point, d.ng)? / cos_gl);
    if !(max_component(radiance) > 0.0) || !radiance.is_finite() {
        return None;
    }
    let origin = d.offset(d.ng);
    let t_end = (eye - origin).dot(w);
    let scale = eye
        .abs()
        .max_element()
        .max(origin.abs().max_element())
        .max(t_end);
    let t_max = t_end - OFFSET_ULPS * f32::EPSILON * scale;
    if !(t_max > 0.0) {
        return None;
    }
    Some((
        pixel,
        ShadowQuery {
            ray: Ray::new(origin, w),
            t_max,
            radiance,
        },
    ))
}

/// What path tracing needs to know, vertex by vertex, to skip the paths
/// that light tracing takes (see the module documentation).
#[derive(Clone, Copy, Debug, Default)]
pub struct ChainState {
    /// The camera ray's hit is non-specular-like and was left through a
    /// non-specular lobe.
    first_smooth: bool,
    /// The current vertex is specular-like and every vertex between it
    /// and such a first hit is too.
    in_chain: bool,
    /// The previous vertex was (the emission found by its BSDF sample is
    /// light tracing's).
    came_from_chain: bool,
}

impl ChainState {
    /// Enters the vertex of surface `s` at bounce `depth` (call before
    /// its emission and next-event estimation).
    #[inline]
    pub fn enter(&mut self, s: &SurfaceSample, depth: u32) {
        self.came_from_chain = self.in_chain;
        self.in_chain = depth >= 1
            && specular_like(s)
            && if depth == 1 {
                self.first_smooth
            } else {
                self.in_chain
            };
    }

    /// Leaves the vertex of surface `s` at bounce `depth` through a
    /// sample of density `pdf` (zero for a specular lobe).
    #[inline]
    pub fn leave(&mut self, s: &SurfaceSample, depth: u32, pdf: f32) {
        if depth == 0 {
            self.first_smooth = pdf > 0.0 && !specular_like(s);
        }
    }

    /// Whether the emission found at the current vertex is light
    /// tracing's.
    #[inline]
    pub fn skip_emission(&self) -> bool {
        self.came_from_chain
    }

    /// Whether the area-light samples of next-event estimation at the
    /// current vertex, at bounce `depth`, are light tracing's (it takes
    /// emitters up to bounce `max_depth`).
    #[inline]
    pub fn skip_area_lights(&self, depth: u32, settings: &RenderSettings) -> bool {
        self.in_chain && depth < settings.max_depth
    }
}
