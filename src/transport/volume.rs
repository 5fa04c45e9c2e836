//! Participating media under path transport: the kernels both
//! integrators call to move a path through fog and through the scattering
//! interiors of closed objects.
//!
//! # Which medium a segment runs through
//! No medium stack is carried along a path: the medium of a ray segment
//! is read off the surface it ends on ([`segment_medium`]), as the
//! absorption of [`crate::transport::medium`] is. A segment that ends on
//! the *back* face of a surface (it ran inside the object) is in that
//! object's interior medium if its material has one, in clear space if
//! the material transmits (glass) without one, and otherwise in the fog
//! (an opaque surface seen from behind is an open sheet, not a closed
//! object). A segment that ends on a front face or escapes is in the fog.
//! The model assumes closed objects that do not overlap or nest, and a
//! camera outside every object (in the fog, if there is one). The loaders
//! refuse an open mesh or shape that holds a medium.
//!
//! # Index-matched boundaries
//! A surface whose material [`is_interface`](crate::scene::material::Material::is_interface)
//! (a glass of index 1, white, with nothing else) only marks where a
//! medium starts: [`propagate`] and [`shadow_transmittance`] cross it
//! without a bounce (up to [`MAX_CROSSINGS`] per segment), so that
//! next-event estimation reaches lights through it and multiple
//! importance sampling measures distances from the last real vertex.
//!
//! # Distance sampling
//! In a scattering medium the distance to the next scattering event is
//! drawn by extinction, one channel's (a hero channel per path): while
//! the channels the path still carries (those where its throughput is not
//! zero) share one extinction `s`, `t` is drawn with density
//! `s exp(-s t)` and a scattering event weighs `sigma_s / s` per channel,
//! passing the segment weighs one: exact, with no colour noise, for grey
//! extinction. When the carried channels' extinctions differ, the path is
//! first narrowed to one of its `k` carried channels, chosen uniformly
//! (its throughput keeps that channel, times `k`), and is monochrome from
//! then on. (Averaging the distance density over channels event by event
//! was tried first: in the long random walks of dense media the product of
//! per-event ratios diverged, a 32x32 slab at 64 spp had 15% standard
//! error.)
//!
//! # Transmittance
//! Media are homogeneous, so the transmittance of a shadow ray is the
//! closed form `exp(-sigma_t d)` per medium crossed ([`shadow_transmittance`]):
//! ratio tracking with the extinction as majorant would give exactly this
//! value with no noise, so the closed form is used directly.
//!
//! # Light at scattering events
//! At a scattering event the path samples area lights and the environment
//! as at a surface ([`medium_next_event`], the phase function in place of
//! the BSDF, multiple importance sampling against phase sampling), and
//! continues in a direction drawn from the Henyey-Greenstein phase
//! function ([`continue_in_medium`]). Point and spot lights are sampled in
//! [`propagate`] itself, per segment, by two strategies combined with the
//! power heuristic: at the distance-sampled scattering point, and at a
//! point drawn by equiangular sampling towards one of them (Kulla and
//! Fajardo 2012), which keeps thin fog lit by a small light from being
//! noisy. Directional lights are sampled at the scattering point only.
//!
//! # Random numbers
//! A scattering event of bounce `b` reads bounce `b`'s sets of the path
//! sampler ([`crate::transport::path::bounce_dimension`]) as a surface
//! vertex does, but for its direction: the phase function is sampled with
//! the first pair of the bounce's BSDF set, which surfaces leave unused
//! (they draw theirs from [`crate::transport::path::direction_numbers`]);
//! the roulette number is where a surface's is. Distance and equiangular
//! sampling on the segment that follows bounce `b` read sets of their
//! own, one per boundary crossed, far above the bounces'
//! ([`medium_dimension`]).

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, Ray, fast_atan2, fast_tan, max_component};
use crate::core::medium::{Medium, henyey_greenstein, sample_henyey_greenstein};
use crate::core::optics::{OFFSET_ULPS, offset_origin_relative};
use crate::core::rng::Sampler;
use crate::core::sampling::power_heuristic;
use crate::core::settings::RenderSettings;
use crate::scene::environment::Environment;
use crate::scene::light::WorldLight;
use crate::scene::{Hit, RenderScene};
use crate::transport::interaction::{Interaction, RayKind, ShadowQuery};
use crate::transport::path::{BsdfSample, Continuation, bounce_dimension, roulette};

/// Most index-matched boundaries a segment or a shadow ray crosses; a
/// path that would cross more ends there (a shadow ray counts as blocked).
pub const MAX_CROSSINGS: u32 = 64;

/// First sampler dimension of the medium sets (above every bounce's).
const MEDIUM_DIMENSION: u32 = 0x4000_0000;

/// First sampler dimension of the distance and equiangular numbers of the
/// `crossing`-th part of the segment after bounce `depth`: one set of
/// four (channel, distance, light, equiangular point).
#[inline]
pub fn medium_dimension(depth: u32, crossing: u32) -> u32 {
    MEDIUM_DIMENSION
        .wrapping_add(depth.wrapping_mul(4 * MAX_CROSSINGS))
        .wrapping_add(4 * crossing)
}

/// First sampler dimension of the set that a scattering event of bounce
/// `depth` continues with ([`continue_in_medium`]): the set after the
/// bounce's light samples, a multiple of four.
#[inline]
pub fn continue_dimension(settings: &RenderSettings, depth: u32) -> u32 {
    bounce_dimension(settings, depth) + 4 * settings.light_samples
}

/// The medium a ray segment of direction `dir` ran through, read off the
/// surface it ended on (`None`: it escaped); see the module notes. `None`
/// for clear space.
#[inline]
pub fn segment_medium(scene: &RenderScene, hit: Option<&Hit>, dir: Vec3A) -> Option<Medium> {
    let fog = || scene.fog().copied();
    let Some(h) = hit else {
        return fog();
    };
    if h.geometric_normal.dot(dir) <= 0.0 {
        return fog();
    }
    let m = &scene.materials()[h.material as usize];
    match m.interior() {
        Some(i) => Some(i),
        None if m.transmission > 0.0 => None,
        None => fog(),
    }
}

/// True when a segment of direction `dir` that ended on `hit` ran inside
/// a subsurface material, whose diffuse boundary
/// ([`diffuse_crossing`]) no light crosses
/// directly: lights are not sampled from such a segment (every shadow ray
/// would end on the boundary).
#[inline]
fn behind_diffuse_boundary(scene: &RenderScene, hit: Option<&Hit>, dir: Vec3A) -> bool {
    hit.is_some_and(|h| {
        h.geometric_normal.dot(dir) > 0.0 && scene.materials()[h.material as usize].subsurface
    })
}

/// True when `hit`, found by a ray of direction `dir` that started on a
/// subsurface material's surface to enter it
/// ([`start_walk`]), is that surface again at the
/// ray's origin (within the ulps [`beyond`] moves by): the ray crosses it
/// as an index-matched boundary, so that its random walk is measured from
/// the surface point itself.
#[inline]
fn is_own_entry(scene: &RenderScene, hit: &Hit, dir: Vec3A) -> bool {
    hit.geometric_normal.dot(dir) < 0.0
        && scene.materials()[hit.material as usize].subsurface
        && (beyond(scene, hit, dir) - hit.point).length() >= hit.t
}

/// True when [`propagate`] would leave a segment of direction `dir` that
/// ends at `hit` as it is: no medium along it, and its end (a surface or
/// an escape) is not a boundary the ray crosses. [`propagate`] then ends it
/// on `hit` itself (or escapes it) with weight one, no radiance, no rays
/// and no numbers drawn; only its ray would restart at the hit point.
#[inline]
pub fn is_plain_segment(scene: &RenderScene, hit: Option<&Hit>, dir: Vec3A) -> bool {
    is_plain_segment_in(scene, segment_medium(scene, hit, dir).as_ref(), hit, dir)
}

/// [`is_plain_segment`] for a caller that has the segment's medium
/// already (`medium` is [`segment_medium`]`(scene, hit, dir)`).
#[inline]
pub fn is_plain_segment_in(
    scene: &RenderScene,
    medium: Option<&Medium>,
    hit: Option<&Hit>,
    dir: Vec3A,
) -> bool {
    medium.is_none() && hit.is_none_or(|h| !is_interface(scene, h) && !is_own_entry(scene, h, dir))
}

/// True when `hit` is on an index-matched boundary that rays cross.
#[inline]
fn is_interface(scene: &RenderScene, hit: &Hit) -> bool {
    scene.materials()[hit.material as usize].is_interface()
}

/// The origin of a ray that carries on through `hit` in direction `dir`:
/// the hit point moved off the surface to the side `dir` goes, by
/// [`OFFSET_ULPS`] ulps of the larger of the point's and its instance's
/// largest coordinate. The hit point's error scales with its object (a
/// sphere of radius 1000 computes its points to ulps of 1000, even where
/// the render frame puts them near the origin), so the point's own ulps
/// ([`offset_origin_relative`], used at scattering surfaces) do not clear a
/// large boundary seen from close by; without this a ray leaving a large
/// index-matched sphere found it again just outside.
#[inline]
pub fn beyond(scene: &RenderScene, hit: &Hit, dir: Vec3A) -> Vec3A {
    let n = hit.geometric_normal;
    let side = if n.dot(dir) > 0.0 { n } else { -n };
    let size = scene.instances()[hit.instance as usize]
        .world_bounds()
        .map_or(0.0, |b| b.min.abs().max(b.max.abs()).max_element());
    let magnitude = hit
        .point
        .abs()
        .max_element()
        .max(size)
        .max(f32::MIN_POSITIVE);
    let q = hit.point + side * (OFFSET_ULPS * f32::EPSILON * magnitude);
    if q.is_finite() {
        q
    } else {
        offset_origin_relative(hit.point, side)
    }
}

/// Which way a path crosses the diffuse boundary of a subsurface
/// material ([`diffuse_crossing`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crossing {
    /// From outside into the scattering interior: no light can be sampled
    /// from here (every light is outside), so next-event estimation is
    /// skipped.
    Into,
    /// From the interior out: next-event estimation as at a diffuse
    /// surface.
    OutOf,
}

/// Turns a hit on a subsurface material's surface into its
/// diffuse-transmission boundary (the approach of random-walk subsurface
/// scattering): a white Lambertian lobe facing the side the path goes
/// on to, `1/pi` times the cosine there, with no Fresnel term. A path
/// arriving from outside enters the interior in a cosine-distributed
/// direction about the inward normal; a path arriving from inside (its
/// random walk reached the boundary) leaves in a cosine-distributed
/// direction about the outward normal, and lights outside are sampled
/// from there as at a diffuse surface. Both crossings keep the
/// throughput (the lobe's albedo is 1). The normals of `it` are turned
/// to the far side and its surface becomes that lobe (emission kept);
/// `None`, and `it` untouched, for any other surface.
///
/// Where the walk starts and ends matters: a walk that starts a distance
/// `d` inside loses about `d ln(1/d)` (in mean free paths) of its albedo
/// (the light that would leave at grazing angles), so the entering ray
/// must start on the surface itself, not at an origin offset inwards
/// (seen: 3% too dark with a mean free path of 1e-3 on a ball of radius
/// 1). The caller therefore starts the ray that continues an
/// [`Crossing::Into`] at `it.point` ([`start_walk`]); if it finds its own
/// surface again at once, that is one more entry, which changes nothing.
/// On the way out the point is moved off `hit` by the object's scale
/// ([`beyond`]: a walk's exit point on a large
/// object is off by ulps of the object, which a point's own ulps do not
/// clear).
///
/// A semi-infinite slab behind such a boundary reflects like a
/// Lambertian surface whatever its radius: the light that comes back out
/// leaves in a cosine distribution, with the slab's diffuse albedo
/// ([`crate::core::medium::slab_diffuse_albedo`]) as its albedo.
#[inline]
pub fn diffuse_crossing(scene: &RenderScene, hit: &Hit, it: &mut Interaction) -> Option<Crossing> {
    if !scene.materials()[hit.material as usize].subsurface {
        return None;
    }
    Some(cross_diffusely(scene, hit, it))
}

/// [`diffuse_crossing`] at a subsurface surface; out of line, so that
/// scenes without subsurface materials carry none of it in their shading
/// loops.
#[cold]
#[inline(never)]
fn cross_diffusely(scene: &RenderScene, hit: &Hit, it: &mut Interaction) -> Crossing {
    it.ng = -it.ng;
    it.ns = -it.ns;
    if !it.front_face {
        it.point = beyond(scene, hit, it.ng);
    }
    let s = &mut it.surface;
    s.diffuse = Color::ONE;
    s.base = Color::ONE;
    s.diffuse_weight = 1.0;
    s.specular = Color::ZERO;
    s.mirror = Color::ZERO;
    s.transmission = 0.0;
    s.gltf = None;
    if it.front_face {
        Crossing::Into
    } else {
        Crossing::OutOf
    }
}

/// The ray that continues a path from a [`Crossing::Into`] at `it`: the
/// sampled ray from the surface point itself, not offset (see
/// [`diffuse_crossing`]); other rays unchanged.
#[inline]
pub fn start_walk(crossing: Option<Crossing>, it: &Interaction, ray: Ray) -> Ray {
    if crossing == Some(Crossing::Into) {
        Ray::new(it.point, ray.direction)
    } else {
        ray
    }
}

/// The extinction a path samples distances with in medium `m`, given
/// the channels `live` its throughput still carries (see the module
/// notes): when every live channel has the same extinction, that one (the
/// path keeps all its channels); otherwise the path is narrowed to one
/// live channel, chosen with `u` among the `k` live ones, and `weight`
/// (the path's multiplier so far) keeps only that channel, times `k`.
/// Returns `None` when no channel is live.
#[inline]
fn extinction_for(m: &Medium, live: [bool; 3], u: f32, weight: &mut Color) -> Option<f32> {
    let st = m.sigma_t();
    let first = live.iter().position(|&l| l)?;
    // Extinctions within a few ulps count as one: `sigma_a + sigma_s` of
    // an albedo and a grey mean free path rounds differently per channel,
    // and an exact comparison would narrow such paths at random (colour
    // noise for nothing; the bias of treating them as equal is ~1e-7).
    let grey = (0..3).all(|c| !live[c] || (st[c] - st[first]).abs() <= 4e-7 * st[first].abs());
    if grey {
        return Some(st[first]);
    }
    let k = live.iter().filter(|&&l| l).count();
    let pick = ((u * k as f32) as usize).min(k - 1);
    let c = (0..3).filter(|&c| live[c]).nth(pick)?;
    let mut narrowed = Color::ZERO;
    narrowed[c] = weight[c] * k as f32;
    *weight = narrowed;
    Some(st[c])
}

/// The density of drawing distance `t` by extinction `s`.
#[inline]
pub fn distance_pdf(s: f32, t: f32) -> f32 {
    if s > 0.0 { s * (-s * t).exp() } else { 0.0 }
}

/// A distance drawn by extinction `s` with `u`; infinite for `s = 0`.
#[inline]
pub fn sample_distance(s: f32, u: f32) -> f32 {
    if s > 0.0 {
        -(1.0 - u).ln() / s
    } else {
        f32::INFINITY
    }
}

/// How a segment ended.
#[derive(Clone, Copy, Debug)]
pub enum SegmentEnd {
    /// On a surface (not an index-matched boundary): `hit` as found by
    /// `ray`, whose origin is the hit point and whose direction is the
    /// segment's (unit), with `hit.t` the segment's whole length from the
    /// vertex it left (across every boundary crossed). Shading builds its
    /// interaction from this pair.
    Surface {
        /// The hit, `t` the whole length.
        hit: Hit,
        /// Origin at the hit, unit direction of the segment.
        ray: Ray,
    },
    /// Left the scene in this (unit) direction.
    Escaped(Vec3A),
    /// Scattered inside a medium.
    Scattered(MediumVertex),
    /// Ended without light: too many boundaries crossed.
    Lost,
}

/// A scattering event inside a medium.
#[derive(Clone, Copy, Debug)]
pub struct MediumVertex {
    /// Where.
    pub point: Vec3A,
    /// Unit direction the path was travelling in.
    pub direction: Vec3A,
    /// The medium.
    pub medium: Medium,
    /// False inside a subsurface material, where no light is sampled (its
    /// diffuse boundary blocks every shadow ray).
    pub lit: bool,
}

/// What [`propagate`] did with a segment.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// How it ended.
    pub end: SegmentEnd,
    /// Multiplier of the path throughput (transmittance over sampling
    /// probability, times `sigma_s` at a scattering event).
    pub weight: Color,
    /// Light of point, spot and directional lights scattered towards the
    /// path's origin inside the segment, to be multiplied by the
    /// throughput the segment started with.
    pub radiance: Color,
    /// Closest-hit rays traced beyond boundaries, and shadow rays.
    pub rays: (u64, u64),
}

impl Segment {
    /// The length of the segment from the vertex it left to the surface
    /// it ended on (for the MIS weight of emission found there).
    #[inline]
    pub fn distance(&self) -> f32 {
        match self.end {
            SegmentEnd::Surface { hit, .. } => hit.t,
            _ => f32::INFINITY,
        }
    }
}

/// Follows the ray of bounce `depth` (unit direction), whose closest hit
/// is `hit`, through the media on its way: samples a scattering event in
/// each scattering medium it crosses, attenuates it in absorbing ones,
/// crosses index-matched boundaries, and gathers the light that point,
/// spot and directional lights scatter into it. Reads the medium
/// dimensions of `depth` ([`medium_dimension`]).
pub fn propagate(
    scene: &RenderScene,
    ray: &Ray,
    hit: Option<Hit>,
    depth: u32,
    throughput: Color,
    sampler: &mut Sampler,
) -> Segment {
    let dir = ray.direction;
    let mut out = Segment {
        end: SegmentEnd::Lost,
        weight: Color::ONE,
        radiance: Color::ZERO,
        rays: (0, 0),
    };
    // Each part is measured from `origin`, where the segment or its last
    // crossing began; its closest hit was found from `origin` moved off the
    // boundary (see `beyond`), `lead` further along the ray, so that the
    // sliver between the boundary and the moved origin keeps its medium.
    let mut origin = ray.origin;
    let mut lead = 0.0f32;
    let mut hit = hit;
    let mut travelled = 0.0f32;
    for crossing in 0..MAX_CROSSINGS {
        let t_end = hit.map_or(f32::INFINITY, |h| h.t + lead);
        if let Some(m) = segment_medium(scene, hit.as_ref(), dir) {
            if m.scatters() {
                // One Sobol set: what four `next_f32` calls from the
                // set's first dimension give, with one look-up.
                let [u_c, u_t, u_l, u_e] = sampler.set_of_four(medium_dimension(depth, crossing));
                let carried = throughput * out.weight;
                let live = [carried.x != 0.0, carried.y != 0.0, carried.z != 0.0];
                let Some(s) = extinction_for(&m, live, u_c, &mut out.weight) else {
                    out.weight = Color::ZERO;
                    return out;
                };
                let t = sample_distance(s, u_t);
                let scatter = (t < t_end).then_some(t);
                let lit = !behind_diffuse_boundary(scene, hit.as_ref(), dir);
                if lit && !scene.lights().is_empty() {
                    let part = Ray::new(origin, dir);
                    let (l, shadows) =
                        punctual_in_segment(scene, &m, s, &part, t_end, scatter, (u_l, u_e));
                    out.radiance += out.weight * l;
                    out.rays.1 += shadows;
                }
                if let Some(t) = scatter {
                    // exp(-s t) sigma_s / (s exp(-s t)) in every live channel.
                    out.weight *= m.sigma_s / s;
                    out.end = SegmentEnd::Scattered(MediumVertex {
                        point: origin + dir * t,
                        direction: dir,
                        medium: m,
                        lit,
                    });
                    return out;
                }
                // Passing: exp(-s d) / exp(-s d), one in every live channel.
            } else {
                out.weight *= m.transmittance(t_end);
            }
        }
        let Some(h) = hit else {
            out.end = SegmentEnd::Escaped(dir);
            return out;
        };
        travelled += t_end;
        // Crossed: index-matched boundaries, and a walk's own entry surface
        // found again at its start.
        let crossed = is_interface(scene, &h) || (crossing == 0 && is_own_entry(scene, &h, dir));
        if !crossed {
            out.end = SegmentEnd::Surface {
                hit: Hit { t: travelled, ..h },
                ray: Ray::new(h.point, dir),
            };
            return out;
        }
        if out.weight == Color::ZERO {
            return out;
        }
        let start = beyond(scene, &h, dir);
        origin = h.point;
        lead = (start - h.point).dot(dir).max(0.0);
        out.rays.0 += 1;
        hit = scene.intersect(&Ray::new(start, dir), 0.0, f32::INFINITY);
    }
    out
}

/// Light of the scene's punctual lights scattered towards the origin of
/// `ray` (unit direction) inside the medium part `[0, t_end)`, by the two
/// strategies of the module notes: at the distance-sampled point
/// `scatter` (when the path scatters in this part) for every light, and
/// at an equiangular point for one point or spot light chosen with `u.0`
/// (the point drawn with `u.1`). Relative to the throughput at the part's
/// start. Also returns the number of shadow rays.
#[allow(clippy::too_many_arguments)]
fn punctual_in_segment(
    scene: &RenderScene,
    m: &Medium,
    s: f32,
    ray: &Ray,
    t_end: f32,
    scatter: Option<f32>,
    u: (f32, f32),
) -> (Color, u64) {
    let lights = scene.lights();
    let positioned = lights
        .iter()
        .filter(|l| !matches!(l, WorldLight::Directional { .. }))
        .count();
    let count = positioned as f32;
    let mut radiance = Color::ZERO;
    let mut shadows = 0;
    // The light at point `t` of the part from `light`, with the path weight
    // `weight` of reaching and scattering there, MIS weight `w`.
    let mut gather = |light: &WorldLight, t: f32, weight: Color, w: &dyn Fn(f32) -> f32| {
        let p = ray.at(t);
        let Some(ls) = light.illuminate(p) else {
            return;
        };
        let f = henyey_greenstein(ray.direction.dot(ls.wi), m.g);
        let l = weight * ls.irradiance * f * w(t);
        if !(max_component(l) > 0.0) || !l.is_finite() {
            return;
        }
        shadows += 1;
        let tr = shadow_transmittance(scene, &Ray::new(p, ls.wi), ls.distance);
        radiance += l * tr;
    };
    // The positioned light chosen for equiangular sampling (its index in
    // `lights`) and its sampling of this part, computed once: the
    // scattering point's weights below read its density too.
    let chosen = (positioned > 0).then(|| {
        let k = ((u.0 * count) as usize).min(positioned - 1);
        let (i, light) = lights
            .iter()
            .enumerate()
            .filter(|(_, l)| !matches!(l, WorldLight::Directional { .. }))
            .nth(k)
            .expect("k < positioned");
        (i, light, equiangular(light, ray, t_end))
    });
    if let Some(t) = scatter {
        let pd = distance_pdf(s, t);
        let weight = m.sigma_s / s;
        for (i, light) in lights.iter().enumerate() {
            let e = match chosen {
                Some((c, _, e)) if c == i => e,
                _ => equiangular(light, ray, t_end),
            };
            let pe = e.map_or(0.0, |e| e.pdf(t) / count);
            gather(light, t, weight, &|_| power_heuristic(1.0, pd, 1.0, pe));
        }
    }
    if let Some((_, light, Some(e))) = chosen {
        let t = e.sample(u.1).min(t_end);
        let pe = e.pdf(t) / count;
        if pe > 0.0 && pe.is_finite() {
            let weight = Color::splat((-s * t).exp()) * m.sigma_s / pe;
            let pd = distance_pdf(s, t);
            gather(light, t, weight, &|_| power_heuristic(1.0, pe, 1.0, pd));
        }
    }
    (radiance, shadows)
}

/// Equiangular sampling of a ray part `[0, t_end)` towards a light
/// position: the ray parameter of the foot of the perpendicular, the
/// light's distance from the ray, and the angles of the part's ends.
#[derive(Clone, Copy, Debug)]
struct Equiangular {
    foot: f32,
    height: f32,
    theta_a: f32,
    theta_b: f32,
}

/// Equiangular sampling towards `light` (`None` for a directional light
/// or one on the ray's line).
#[inline]
fn equiangular(light: &WorldLight, ray: &Ray, t_end: f32) -> Option<Equiangular> {
    let position = match *light {
        WorldLight::Point { position, .. } | WorldLight::Spot { position, .. } => position,
        WorldLight::Directional { .. } => return None,
    };
    let to = position - ray.origin;
    let foot = to.dot(ray.direction);
    let height = (to - ray.direction * foot).length();
    if !(height > 1e-6 * to.length().max(1e-30)) {
        return None;
    }
    let theta_a = fast_atan2(-foot, height);
    let theta_b = if t_end.is_finite() {
        fast_atan2(t_end - foot, height)
    } else {
        std::f32::consts::FRAC_PI_2
    };
    (theta_b > theta_a).then_some(Equiangular {
        foot,
        height,
        theta_a,
        theta_b,
    })
}

impl Equiangular {
    /// The ray parameter drawn with `u`.
    #[inline]
    fn sample(&self, u: f32) -> f32 {
        let theta = self.theta_a + u * (self.theta_b - self.theta_a);
        (self.foot + self.height * fast_tan(theta)).max(0.0)
    }

    /// The density of drawing ray parameter `t`.
    #[inline]
    fn pdf(&self, t: f32) -> f32 {
        let x = t - self.foot;
        self.height / ((self.theta_b - self.theta_a) * (self.height * self.height + x * x))
    }
}

/// Transmittance of the shadow ray `ray` up to parameter `t_max` through
/// the media it crosses (closed form per medium, see the module notes):
/// zero when a surface other than an index-matched boundary blocks it.
/// The medium of its last part, beyond the last boundary, is read off
/// the first surface past `t_max` like any segment's.
pub fn shadow_transmittance(scene: &RenderScene, ray: &Ray, t_max: f32) -> Color {
    let len = ray.direction.length();
    let dir = ray.direction / len;
    // As in `propagate`: distances from the boundary last crossed, hits
    // found from just beyond it, `lead` further on.
    let mut start = ray.origin;
    let mut lead = 0.0f32;
    let mut remaining = t_max * len;
    let mut tr = Color::ONE;
    for _ in 0..MAX_CROSSINGS {
        let hit = scene.intersect(&Ray::new(start, dir), 0.0, f32::INFINITY);
        let reach = hit.map_or(f32::INFINITY, |h| h.t + lead);
        if let Some(m) = segment_medium(scene, hit.as_ref(), dir) {
            tr *= m.transmittance(reach.min(remaining));
        }
        let Some(h) = hit else {
            return tr;
        };
        if reach >= remaining {
            return tr;
        }
        if !is_interface(scene, &h) || tr == Color::ZERO {
            return Color::ZERO;
        }
        start = beyond(scene, &h, dir);
        remaining -= reach;
        lead = (start - h.point).dot(dir).max(0.0);
    }
    Color::ZERO
}

/// Whitted transport's attenuation of the segment of length `distance`
/// that ended on `hit` (`None`: escaped) in direction `dir`: Beer-Lambert
/// with the extinction of its medium (scattering only removes light, none
/// is scattered in); `None` in clear space.
#[inline]
pub fn whitted_transmittance(
    scene: &RenderScene,
    hit: Option<&Hit>,
    dir: Vec3A,
    distance: f32,
) -> Option<Color> {
    segment_medium(scene, hit, dir).map(|m| m.transmittance(distance))
}

/// Next-event estimation of area lights and the environment at a
/// scattering event of bounce `depth`, like
/// [`next_event`](crate::transport::path::next_event) at a surface with
/// the phase function in place of the BSDF (point, spot and directional
/// lights are sampled by [`propagate`]). `emit` receives each shadow
/// query, whose radiance is not yet multiplied by the throughput nor by
/// the shadow ray's transmittance.
pub fn medium_next_event(
    scene: &RenderScene,
    settings: &RenderSettings,
    v: &MediumVertex,
    sampler: &mut Sampler,
    depth: u32,
    mut emit: impl FnMut(ShadowQuery),
) {
    let first = bounce_dimension(settings, depth);
    let env = scene.environment();
    let p_env = scene.environment_selection();
    if !v.lit || (env.is_none() && scene.emitters().is_empty()) {
        return;
    }
    for i in 0..settings.light_samples {
        sampler.set_dimension(first + 4 * i);
        let v2 = Vec2::new(sampler.next_f32(), sampler.next_f32());
        let u = sampler.next_f32();
        let q = match env {
            Some(env) if u < p_env => environment_sample(settings, v, env, p_env, v2, depth),
            _ if scene.emitters().is_empty() => None,
            Some(_) => {
                let u = ((u - p_env) / (1.0 - p_env)).min(1.0 - f32::EPSILON / 2.0);
                area_light_sample(scene, settings, v, (u, v2), 1.0 - p_env, depth)
            }
            None => area_light_sample(scene, settings, v, (u, v2), 1.0, depth),
        };
        if let Some(q) = q {
            emit(q);
        }
    }
}

/// The phase function's value (and density) for scattering from the
/// vertex's direction into `wi`.
#[inline]
fn phase(v: &MediumVertex, wi: Vec3A) -> f32 {
    henyey_greenstein(v.direction.dot(wi), v.medium.g)
}

/// One next-event sample of the area lights from a scattering event.
fn area_light_sample(
    scene: &RenderScene,
    settings: &RenderSettings,
    v: &MediumVertex,
    (u, uv): (f32, Vec2),
    select: f32,
    depth: u32,
) -> Option<ShadowQuery> {
    let n = settings.light_samples;
    let ls = scene
        .emitters()
        .sample(scene.instances(), scene.materials(), u, uv)?;
    let to = ls.point - v.point;
    let dist2 = to.length_squared();
    if !(dist2 > 0.0 && dist2.is_finite()) {
        return None;
    }
    let dist = dist2.sqrt();
    let wi = to / dist;
    let cos_l = ls.normal.dot(wi).abs();
    if !(cos_l > 0.0) {
        return None;
    }
    let f = phase(v, wi);
    let pdf_light = ls.pdf_area * dist2 / cos_l * select;
    let w = if depth < settings.max_depth {
        power_heuristic(n as f32, pdf_light, 1.0, f)
    } else {
        1.0
    };
    let radiance = ls.radiance * (f * w / (n as f32 * pdf_light));
    if !(max_component(radiance) > 0.0) || !radiance.is_finite() {
        return None;
    }
    // Stop just short of the emitter (as surface samples do).
    let scale = ls
        .point
        .abs()
        .max_element()
        .max(v.point.abs().max_element())
        .max(dist);
    let t_max = dist - OFFSET_ULPS * f32::EPSILON * scale / cos_l;
    (t_max > 0.0).then_some(ShadowQuery {
        ray: Ray::new(v.point, wi),
        t_max,
        radiance,
    })
}

/// One next-event sample of the environment from a scattering event.
fn environment_sample(
    settings: &RenderSettings,
    v: &MediumVertex,
    env: &Environment,
    p_env: f32,
    uv: Vec2,
    depth: u32,
) -> Option<ShadowQuery> {
    let n = settings.light_samples;
    let es = env.sample(uv)?;
    let wi = es.direction;
    let f = phase(v, wi);
    let pdf_light = es.pdf * p_env;
    let w = if depth < settings.max_depth {
        power_heuristic(n as f32, pdf_light, 1.0, f)
    } else {
        1.0
    };
    let radiance = es.radiance * (f * w / (n as f32 * pdf_light));
    if !(max_component(radiance) > 0.0) || !radiance.is_finite() {
        return None;
    }
    Some(ShadowQuery {
        ray: Ray::new(v.point, wi),
        t_max: f32::INFINITY,
        radiance,
    })
}

/// How a path goes on from a scattering event of bounce `depth` reached
/// with `throughput`: a direction drawn from the phase function (weight
/// one, density the phase function's), then the depth, contribution and
/// roulette tests of [`continue_path`](crate::transport::path::continue_path),
/// the roulette number from a surface's dimension (see the module
/// notes on random numbers).
pub fn continue_in_medium(
    settings: &RenderSettings,
    v: &MediumVertex,
    depth: u32,
    throughput: Color,
    sampler: &mut Sampler,
) -> Option<Continuation> {
    // The bounce's last set (direction, lobe, roulette), drawn at once.
    let [u0, u1, _lobe, u_rr] = sampler.set_of_four(continue_dimension(settings, depth));
    let u = Vec2::new(u0, u1);
    if depth >= settings.max_depth {
        return None;
    }
    let wi = sample_henyey_greenstein(v.direction, v.medium.g, u);
    let pdf = phase(v, wi);
    if !(pdf > 0.0) || !wi.is_finite() {
        return None;
    }
    if max_component(throughput) < settings.min_contribution || !throughput.is_finite() {
        return None;
    }
    let scale = roulette(settings, depth + 1, throughput, u_rr)?;
    Some(Continuation {
        sample: BsdfSample {
            ray: Ray::new(v.point, wi),
            weight: Color::ONE,
            pdf,
            kind: RayKind::Reflection,
        },
        scale,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distance density and the probability of passing `d` sum to
    /// one, and sampling follows them (the fraction of 90000 stratified
    /// samples below `d` against `1 - exp(-s d)`, exact up to 1/90000).
    #[test]
    fn distance_sampling_matches_its_density() {
        let (s, d) = (0.7f32, 3.0f32);
        let n = 30_000;
        let mut integral = 0.0f64;
        for i in 0..n {
            let t = (i as f32 + 0.5) * d / n as f32;
            integral += distance_pdf(s, t) as f64 * (d / n as f32) as f64;
        }
        let total = integral + (-s * d).exp() as f64;
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        let m = 90_000;
        let below = (0..m)
            .filter(|&i| sample_distance(s, (i as f32 + 0.5) / m as f32) < d)
            .count();
        let f = below as f64 / m as f64;
        assert!((f - (1.0 - (-s * d).exp() as f64)).abs() < 1e-3, "{f}");
    }

    /// A grey extinction keeps every live channel; a chromatic one narrows
    /// the path to one live channel, weighted by the number of live ones,
    /// so that the expectation over the choice is unchanged.
    #[test]
    fn chromatic_extinction_narrows_the_path_to_one_channel() {
        let grey =
            Medium::checked(Color::new(0.1, 0.2, 0.3), Color::new(0.9, 0.8, 0.7), 0.0).unwrap();
        let mut w = Color::new(0.5, 0.25, 1.0);
        assert_eq!(extinction_for(&grey, [true; 3], 0.9, &mut w), Some(1.0));
        assert_eq!(w, Color::new(0.5, 0.25, 1.0));
        // A coloured albedo over a grey mean free path is grey too, although
        // `sigma_a + sigma_s` rounds differently per channel (0.03 and 0.1
        // give 10.000001 against 10).
        let artist =
            Medium::from_albedo(Color::new(0.03, 0.5, 0.9), Color::splat(0.1), 0.0).unwrap();
        let mut w = Color::new(0.5, 0.25, 1.0);
        assert!(extinction_for(&artist, [true; 3], 0.9, &mut w).is_some());
        assert_eq!(w, Color::new(0.5, 0.25, 1.0), "{:?}", artist.sigma_t());
        let chroma = Medium::checked(Color::ZERO, Color::new(1.0, 2.0, 4.0), 0.0).unwrap();
        let mut mean = Color::ZERO;
        for u in [0.1f32, 0.5, 0.9] {
            let mut w = Color::new(0.5, 0.25, 1.0);
            let s = extinction_for(&chroma, [true; 3], u, &mut w).unwrap();
            assert_eq!(w.cmpgt(Color::ZERO).bitmask().count_ones(), 1);
            assert_eq!(s, chroma.sigma_t()[(u * 3.0) as usize]);
            mean += w / 3.0;
        }
        assert!((mean - Color::new(0.5, 0.25, 1.0)).abs().max_element() < 1e-6);
        // Only live channels count: a single live channel is kept as it is.
        let mut w = Color::new(0.0, 0.25, 0.0);
        assert_eq!(
            extinction_for(&chroma, [false, true, false], 0.7, &mut w),
            Some(2.0)
        );
        assert_eq!(w, Color::new(0.0, 0.25, 0.0));
        assert_eq!(extinction_for(&chroma, [false; 3], 0.7, &mut w), None);
    }

    /// The equiangular density integrates to one over the part.
    #[test]
    fn equiangular_density_is_normalised() {
        let light = WorldLight::Point {
            position: Vec3A::new(1.0, 0.5, 0.0),
            intensity: Color::ONE,
        };
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
        for t_end in [0.5f32, 3.0, 40.0] {
            let e = equiangular(&light, &ray, t_end).unwrap();
            let n = 200_000;
            let mut s = 0.0f64;
            for i in 0..n {
                let t = (i as f32 + 0.5) * t_end / n as f32;
                s += e.pdf(t) as f64 * (t_end / n as f32) as f64;
            }
            assert!((s - 1.0).abs() < 1e-3, "t_end {t_end}: {s}");
            // The sampled parameter is monotone in u and spans the part.
            assert!(e.sample(0.0) < 1e-5 && (e.sample(0.999_999) - t_end).abs() < 1e-2 * t_end);
        }
    }
}
