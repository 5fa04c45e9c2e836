//! Photon mapping kernels: tracing photons from the lights into a caustic
//! and a global map, the density estimate that reads them, and the
//! camera side that finds where to read them.
//!
//! # Photons
//! Photons leave the lights as [`emit`] describes, carrying power in the
//! units the path tracer's radiance is in (a point light of `I` cd emits
//! `4 pi I`). At every surface with a diffuse or glossy lobe a photon is
//! stored: in the **caustic map** when every bounce before it was specular
//! (mirror or glass: light, specular+, diffuse), else in the **global
//! map** (direct hits included). It then scatters by the same lobe choice
//! and BSDF sampling as a path-traced ray (the model's BRDFs are
//! symmetric; a dielectric transmits flux without the `eta^2` radiance
//! scaling), with Russian roulette keeping its power from growing: it
//! survives with probability `min(1, max(power') / max(power))` and is
//! divided by it.
//!
//! # Density estimate
//! The kernel is the constant (uniform disk) kernel: outgoing radiance at
//! `x` is `sum_p f(x, wo, wi_p) power_p / (pi r^2)` over the photons within
//! distance `r` whose stored normal is within 60 degrees of the surface's
//! (which keeps photons on the other side of a thin wall or around a
//! corner out). With `f = 1` it estimates the irradiance averaged over
//! the disk of radius `r`, so its bias is that of the average: it blurs
//! over `r` and darkens corners and edges within `r` (fewer photons fit).
//!
//! # Camera side
//! A camera ray follows specular lobes (mirror, glass) one lobe per
//! bounce, as path tracing chooses them, adding the emission it sees. At
//! each surface with a diffuse or glossy part it adds that part's
//! reflected radiance from the maps: directly from both maps (direct
//! visualisation), or with final gathering: direct light by next-event
//! estimation exactly as the path tracer does, caustics from the caustic
//! map, and indirect light from `gather_rays` BSDF-sampled rays that read
//! both maps where they land (after any specular bounces; gather rays
//! ignore emission, which next-event estimation and the caustic map
//! already count). The background is seen by camera rays but lights
//! nothing (it emits no photons).
//!
//! # Random numbers
//! Photon `p` of iteration `i` draws from the hash sampler keyed by
//! `(seed ^ PHOTON_KEY, p, i)`: dimensions 0-7 emit it, bounce `b` takes
//! `8 + 4b ..` (direction pair, lobe, roulette). A camera sample uses its
//! pixel's sampler (dimensions 0-1 film, specular bounce `b` takes
//! `4 + 4b ..`, next-event estimation the path tracer's dimensions of
//! bounce `max_depth`); gather ray `j` uses the hash sampler keyed by
//! `(seed ^ GATHER_KEY * (j + 1), pixel, sample)`.

pub mod emit;
pub mod grid;
#[cfg(test)]
mod tests;

use crate::transport::medium::interior_transmittance;
use std::f32::consts::PI;

use glam::{Vec2, Vec3, Vec3A};
use rayon::prelude::*;

use crate::core::counters::RenderCounters;
use crate::core::math::{Color, Ray, max_component};
use crate::core::rng::Sampler;
use crate::core::settings::RenderSettings;
use crate::scene::RenderScene;
use crate::transport::interaction::{Interaction, RayKind, brdf};
use crate::transport::path::{self, LobeChoice, sample_bsdf};
use emit::{EmittedPhoton, PhotonSources};
use grid::HashGrid;

/// Mixed into the seed of photon samplers (they must not repeat the
/// camera's numbers).
pub const PHOTON_KEY: u64 = 0x7068_6f74_6f6e_0001;

/// Mixed into the seed of final-gather samplers.
pub const GATHER_KEY: u64 = 0x6761_7468_6572_0001;

/// Cosine of the largest angle between a photon's stored normal and the
/// normal of the surface reading it (60 degrees).
pub const NORMAL_COS: f32 = 0.5;

/// Photons traced per parallel work item (fixed: the result does not
/// depend on it, only the progress granularity does).
const CHUNK: u32 = 4096;

/// A photon stored on a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Photon {
    /// Where it landed.
    pub position: Vec3,
    /// Unit direction it came from (towards the light).
    pub wi: Vec3,
    /// Unit geometric normal on the side it arrived from.
    pub normal: Vec3,
    /// Power (flux).
    pub power: Color,
}

/// Photons with a grid for lookups within one radius.
#[derive(Clone, Debug, Default)]
pub struct PhotonMap {
    photons: Vec<Photon>,
    grid: HashGrid,
    radius2: f32,
}

impl PhotonMap {
    /// Builds the lookup structure for gathers of radius `radius` (finite,
    /// above zero).
    pub fn new(photons: Vec<Photon>, radius: f32) -> Self {
        let grid = HashGrid::build(photons.iter().map(|p| Vec3A::from(p.position)), radius);
        Self {
            photons,
            grid,
            radius2: radius * radius,
        }
    }

    /// The photons.
    pub fn photons(&self) -> &[Photon] {
        &self.photons
    }

    /// Bytes held (photons and grid).
    pub fn bytes(&self) -> usize {
        self.photons.len() * std::mem::size_of::<Photon>() + self.grid.bytes()
    }

    /// Calls `f` with every photon within the radius of `x` whose normal
    /// agrees with `n` (see [`NORMAL_COS`]), in a fixed order.
    #[inline]
    pub fn gather(&self, x: Vec3A, n: Vec3A, mut f: impl FnMut(&Photon)) {
        self.grid.candidates(x, |i| {
            let p = &self.photons[i as usize];
            let pos = Vec3A::from(p.position);
            if pos.distance_squared(x) <= self.radius2 && n.dot(Vec3A::from(p.normal)) > NORMAL_COS
            {
                f(p);
            }
        });
    }

    /// Irradiance at `x` on a surface of normal `n`: the photons' power
    /// within the radius over the disk's area `pi r^2`.
    pub fn irradiance(&self, x: Vec3A, n: Vec3A) -> Color {
        let mut sum = Color::ZERO;
        self.gather(x, n, |p| sum += p.power);
        sum / (PI * self.radius2)
    }

    /// Radiance reflected by the diffuse and glossy lobes at `it`
    /// towards `it.wo`, from the photons within the radius.
    pub fn radiance(&self, it: &Interaction) -> Color {
        let mut sum = Color::ZERO;
        self.gather(it.point, it.ng, |p| {
            let wi = Vec3A::from(p.wi);
            sum += brdf(&it.surface, it.ns, it.wo, wi) * p.power;
        });
        sum / (PI * self.radius2)
    }
}

/// The two maps of one iteration.
#[derive(Clone, Debug, Default)]
pub struct PhotonMaps {
    /// Photons whose every bounce before landing was specular.
    pub caustic: PhotonMap,
    /// All other photons (direct ones included).
    pub global: PhotonMap,
    /// Photon rays traced (emitted and scattered).
    pub rays: u64,
}

impl PhotonMaps {
    /// Bytes held by both maps.
    pub fn bytes(&self) -> usize {
        self.caustic.bytes() + self.global.bytes()
    }
}

/// Traces one photon from `start` and stores it wherever it lands on a
/// diffuse or glossy surface: `caustic` and `global` receive the stored
/// photons. Bounce `b` reads the sampler's dimensions `8 + 4b ..`. Returns
/// the rays traced.
pub fn trace_photon(
    scene: &RenderScene,
    settings: &RenderSettings,
    start: EmittedPhoton,
    sampler: &mut Sampler,
    caustic: &mut Vec<Photon>,
    global: &mut Vec<Photon>,
) -> u64 {
    let mut ray = start.ray;
    let mut power = start.power;
    let mut specular_only = true;
    let mut rays = 0;
    for depth in 0..=settings.max_depth {
        rays += 1;
        let Some(hit) = scene.intersect(&ray, 0.0, f32::INFINITY) else {
            break;
        };
        let it = Interaction::new(scene, &ray, &hit);
        if let Some(tr) = interior_transmittance(&it, hit.t * ray.direction.length()) {
            power *= tr;
        }
        let lobes = LobeChoice::new(&it);
        if lobes.has_smooth() {
            let photon = Photon {
                position: it.point.into(),
                wi: it.wo.into(),
                normal: it.ng.into(),
                power,
            };
            if depth > 0 && specular_only {
                caustic.push(photon);
            } else {
                global.push(photon);
            }
        }
        if depth >= settings.max_depth {
            break;
        }
        sampler.set_dimension(8 + 4 * depth);
        let u = Vec2::new(sampler.next_f32(), sampler.next_f32());
        let u_lobe = sampler.next_f32();
        let u_rr = sampler.next_f32();
        let Some(s) = sample_bsdf(&it, &lobes, u_lobe, u) else {
            break;
        };
        let next = power * s.weight;
        let q = (max_component(next) / max_component(power)).min(1.0);
        if !(q > 0.0) || u_rr >= q {
            break;
        }
        power = next / q;
        if !power.is_finite() {
            break;
        }
        specular_only &= s.pdf == 0.0;
        ray = s.ray;
    }
    rays
}

/// Traces `settings.photon.photons` photons of iteration `iteration` and
/// builds the maps for gathers of radius `radius`. `progress` is called
/// with each finished chunk's share of `steps` (the shares add up to
/// `steps`). The maps do not depend on the thread count.
pub fn trace_photons(
    scene: &RenderScene,
    settings: &RenderSettings,
    sources: &PhotonSources,
    iteration: u32,
    radius: f32,
    progress: Option<(&(dyn Fn(u64) + Sync), u64)>,
) -> PhotonMaps {
    let n = settings.photon.photons;
    let scale = 1.0 / n as f32;
    let chunks = n.div_ceil(CHUNK);
    let seed = settings.seed ^ PHOTON_KEY;
    let parts: Vec<(Vec<Photon>, Vec<Photon>, u64)> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let (mut caustic, mut global) = (Vec::new(), Vec::new());
            let mut rays = 0;
            for p in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let mut sampler = Sampler::new(seed, p, iteration);
                let Some(start) = sources.emit(scene, &mut sampler) else {
                    continue;
                };
                let start = EmittedPhoton {
                    power: start.power * scale,
                    ..start
                };
                rays += trace_photon(
                    scene,
                    settings,
                    start,
                    &mut sampler,
                    &mut caustic,
                    &mut global,
                );
            }
            if let Some((f, steps)) = progress {
                f(steps * (c as u64 + 1) / chunks as u64 - steps * c as u64 / chunks as u64);
            }
            (caustic, global, rays)
        })
        .collect();
    let (mut caustic, mut global) = (Vec::new(), Vec::new());
    let mut rays = 0;
    for (c, g, r) in parts {
        caustic.extend(c);
        global.extend(g);
        rays += r;
    }
    PhotonMaps {
        caustic: PhotonMap::new(caustic, radius),
        global: PhotonMap::new(global, radius),
        rays,
    }
}

/// How the camera side reads the maps at a surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reading {
    /// A camera ray: emission counts; smooth surfaces are read as the
    /// settings say (directly or by final gathering).
    Camera,
    /// A final-gather ray: emission does not count; smooth surfaces are
    /// read from both maps.
    Gather,
}

/// What the camera side needs besides the ray.
pub struct CameraContext<'a> {
    /// The scene.
    pub scene: &'a RenderScene,
    /// The settings.
    pub settings: &'a RenderSettings,
    /// This iteration's maps.
    pub maps: &'a PhotonMaps,
    /// The pixel (row-major index) and the sample index, which key the
    /// gather rays' samplers.
    pub pixel: u32,
    /// Sample index within the pixel (over all iterations).
    pub sample: u32,
}

/// Radiance along a camera ray under photon mapping; `sampler` is the
/// camera sample's (its film dimensions already drawn).
pub fn camera_radiance(
    ctx: &CameraContext,
    ray: &Ray,
    sampler: &mut Sampler,
    counters: &mut RenderCounters,
) -> Color {
    specular_chain(ctx, ray, sampler, 4, Reading::Camera, counters)
}

/// Follows specular lobes from `ray`, adding what each surface's diffuse
/// and glossy part reflects (and, for camera rays, emission and the
/// background). Bounce `b` reads dimensions `dim0 + 4b ..`.
fn specular_chain(
    ctx: &CameraContext,
    ray: &Ray,
    sampler: &mut Sampler,
    dim0: u32,
    reading: Reading,
    counters: &mut RenderCounters,
) -> Color {
    let settings = ctx.settings;
    let mut radiance = Color::ZERO;
    let mut throughput = Color::ONE;
    let mut ray = *ray;
    for depth in 0..=settings.max_depth {
        let Some(hit) = ctx.scene.intersect(&ray, 0.0, f32::INFINITY) else {
            if reading == Reading::Camera {
                radiance += throughput * ctx.scene.background();
            }
            break;
        };
        let it = Interaction::new(ctx.scene, &ray, &hit);
        if let Some(tr) = interior_transmittance(&it, hit.t * ray.direction.length()) {
            throughput *= tr;
        }
        if reading == Reading::Camera {
            radiance += throughput * it.surface.emission;
        }
        let lobes = LobeChoice::new(&it);
        if lobes.has_smooth() {
            let smooth = match reading {
                Reading::Camera if settings.photon.gather_rays > 0 => {
                    final_gather(ctx, &it, &lobes, sampler, counters)
                }
                _ => ctx.maps.caustic.radiance(&it) + ctx.maps.global.radiance(&it),
            };
            radiance += throughput * smooth;
        }
        let specular = lobes.mirror + lobes.dielectric;
        if depth >= settings.max_depth || !(specular > 0.0) {
            break;
        }
        let only = LobeChoice {
            diffuse: 0.0,
            glossy: 0.0,
            mirror: lobes.mirror / specular,
            dielectric: lobes.dielectric / specular,
        };
        sampler.set_dimension(dim0 + 4 * depth);
        let u = Vec2::new(sampler.next_f32(), sampler.next_f32());
        let u_lobe = sampler.next_f32();
        let Some(s) = sample_bsdf(&it, &only, u_lobe, u) else {
            break;
        };
        throughput *= s.weight;
        if max_component(throughput) < settings.min_contribution || !throughput.is_finite() {
            break;
        }
        match s.kind {
            RayKind::Refraction => counters.rays.refraction += 1,
            _ => counters.rays.reflection += 1,
        }
        ray = s.ray;
    }
    radiance
}

/// The diffuse and glossy part of the radiance leaving a camera-side hit,
/// by final gathering (see the module documentation).
fn final_gather(
    ctx: &CameraContext,
    it: &Interaction,
    lobes: &LobeChoice,
    sampler: &mut Sampler,
    counters: &mut RenderCounters,
) -> Color {
    let (scene, settings) = (ctx.scene, ctx.settings);
    let mut radiance = ctx.maps.caustic.radiance(it);
    // Direct light exactly as the path tracer's last vertex takes it
    // (full weight: gather rays do not count emission).
    path::next_event(
        scene,
        settings,
        it,
        lobes,
        sampler,
        settings.max_depth,
        |q| {
            counters.rays.shadow += 1;
            if !scene.occluded(&q.ray, 0.0, q.t_max) {
                radiance += q.radiance;
            }
        },
    );
    let smooth = lobes.diffuse + lobes.glossy;
    let only = LobeChoice {
        diffuse: lobes.diffuse / smooth,
        glossy: lobes.glossy / smooth,
        mirror: 0.0,
        dielectric: 0.0,
    };
    let n = settings.photon.gather_rays;
    let mut indirect = Color::ZERO;
    for j in 0..n {
        let key = settings.seed ^ GATHER_KEY.wrapping_mul(j as u64 + 1);
        let mut g = Sampler::new(key, ctx.pixel, ctx.sample);
        let u = Vec2::new(g.next_f32(), g.next_f32());
        let u_lobe = g.next_f32();
        let Some(s) = sample_bsdf(it, &only, u_lobe, u) else {
            continue;
        };
        counters.rays.reflection += 1;
        indirect += s.weight * specular_chain(ctx, &s.ray, &mut g, 4, Reading::Gather, counters);
    }
    radiance + indirect / n as f32
}
