//! What both transports need at a hit: the surface interaction oriented
//! towards the viewer, the local lighting model's BRDF, and the shadow and
//! secondary rays that shading hands to an integrator.
//!
//! They take plain values and return plain values, so the recursive and
//! the wavefront tracers share the math while keeping their own control
//! flow.

use std::f32::consts::PI;

use glam::Vec3A;

use crate::core::math::{Color, Ray, RayCone};
use crate::scene::material::SurfaceSample;
use crate::scene::{Hit, RenderScene};

/// Everything shading needs to know about a hit, oriented towards the
/// viewer.
#[derive(Clone, Copy, Debug)]
pub struct Interaction {
    /// World position.
    pub point: Vec3A,
    /// Geometric normal on the viewer's side.
    pub ng: Vec3A,
    /// Shading normal on the viewer's side.
    pub ns: Vec3A,
    /// Unit direction towards the viewer.
    pub wo: Vec3A,
    /// True when the ray arrived on the side the geometric normal points to
    /// (entering a closed object).
    pub front_face: bool,
    /// The material evaluated at the hit.
    pub surface: SurfaceSample,
    /// The ray cone at the hit: what a perfectly specular reflection or
    /// refraction carries on ([`RayCone::NONE`] after other bounces).
    pub cone: RayCone,
    /// A magnitude whose ulps bound the rounding error of `point` when it
    /// is larger than the point's own coordinates (see
    /// [`Interaction::offset`]); 0 when the point's own ulps do.
    pub offset_scale: f32,
}

/// What an [`Interaction`] holds besides its surface sample, and the
/// texture footprint that sample is looked up with: computed once for
/// [`Interaction::with_cone_at`] and [`Interaction::set_with_cone`].
struct Frame {
    wo: Vec3A,
    front_face: bool,
    ng: Vec3A,
    ns: Vec3A,
    cone: RayCone,
    width_uv: f32,
    offset_scale: f32,
}

impl Frame {
    #[inline(always)]
    fn new(scene: &RenderScene, direction: Vec3A, hit: &Hit, cone: RayCone, distance: f32) -> Self {
        let wo = (-direction).normalize();
        let front_face = hit.geometric_normal.dot(wo) >= 0.0;
        let (ng, ns) = if front_face {
            (hit.geometric_normal, hit.shading_normal)
        } else {
            (-hit.geometric_normal, -hit.shading_normal)
        };
        let cone = cone.at(distance);
        let cos = ng.dot(wo).abs().max(1.0 / 64.0);
        Frame {
            wo,
            front_face,
            ng,
            ns,
            cone,
            width_uv: cone.width * hit.uv_density / cos,
            offset_scale: offset_scale(scene, hit),
        }
    }

    /// The interaction of `hit` with these parts and `surface`.
    #[inline(always)]
    fn interaction(&self, hit: &Hit, surface: SurfaceSample) -> Interaction {
        Interaction {
            point: hit.point,
            ng: self.ng,
            ns: self.ns,
            wo: self.wo,
            front_face: self.front_face,
            surface,
            cone: self.cone,
            offset_scale: self.offset_scale,
        }
    }
}

impl Interaction {
    /// Orients the hit towards the incoming ray and evaluates its material
    /// at full texture resolution (no ray cone).
    #[inline]
    pub fn new(scene: &RenderScene, ray: &Ray, hit: &Hit) -> Self {
        Self::with_cone(scene, ray, hit, RayCone::NONE)
    }

    /// Orients the hit towards the incoming ray and evaluates its material
    /// with the texture level of detail of the ray's `cone` (at the ray's
    /// origin): the cone's width at the hit, divided by the cosine between
    /// the ray and the geometric normal (the footprint stretches at grazing
    /// angles; the cosine is floored at 1/64) and multiplied by the hit's
    /// [`Hit::uv_density`], is the footprint in texture coordinates.
    #[inline]
    pub fn with_cone(scene: &RenderScene, ray: &Ray, hit: &Hit, cone: RayCone) -> Self {
        Self::with_cone_at(
            scene,
            ray.direction,
            hit,
            cone,
            hit.t * ray.direction.length(),
        )
    }

    /// [`Interaction::with_cone`] of a hit at `distance` from the ray's
    /// origin along `direction` (`hit.t` times the direction's length,
    /// computed as `with_cone` computes it), for a caller that has the
    /// distance already: multiplying it by the length again would change
    /// its last bit wherever the direction is not exactly of unit length.
    #[inline]
    pub fn with_cone_at(
        scene: &RenderScene,
        direction: Vec3A,
        hit: &Hit,
        cone: RayCone,
        distance: f32,
    ) -> Self {
        let f = Frame::new(scene, direction, hit, cone, distance);
        let with = |surface| f.interaction(hit, surface);
        // An untextured material's sample is copied once, from the scene
        // straight into the interaction (through a returned value, it was
        // copied twice: 2 of the 3.8% `memmove` of the wavefront's glTF
        // Cornell box).
        match scene.cached_surface(hit.material) {
            Some(s) => with(*s),
            None => with(scene.surface(hit.material, hit.uv, f.width_uv)),
        }
    }

    /// [`Interaction::with_cone`] built in `slot` (and returned from it):
    /// the interaction is one value written once where it is kept. Made
    /// and then moved into an array's slot, it was built on the stack and
    /// copied (304 bytes through `memcpy`), which `perf` put at 4% of the
    /// frame-loop benchmark's frame (the recursive integrator's camera
    /// packets).
    #[inline]
    pub fn set_with_cone<'s>(
        slot: &'s mut Option<Self>,
        scene: &RenderScene,
        ray: &Ray,
        hit: &Hit,
        cone: RayCone,
    ) -> &'s mut Self {
        let distance = hit.t * ray.direction.length();
        let f = Frame::new(scene, ray.direction, hit, cone, distance);
        let owned;
        let surface = match scene.cached_surface(hit.material) {
            Some(s) => s,
            None => {
                owned = scene.surface(hit.material, hit.uv, f.width_uv);
                &owned
            }
        };
        *slot = Some(f.interaction(hit, *surface));
        slot.as_mut().expect("just set")
    }

    /// The origin of a new ray leaving the surface on the side of `n`
    /// (`ng` or `-ng`): the point moved off the surface by a few ulps of
    /// the larger of its own largest coordinate and
    /// [`Interaction::offset_scale`]
    /// ([`offset_origin_scaled`](crate::core::optics::offset_origin_scaled)).
    #[inline]
    pub fn offset(&self, n: Vec3A) -> Vec3A {
        crate::core::optics::offset_origin_scaled(self.point, n, self.offset_scale)
    }

    /// True when the surface has a diffuse or glossy lobe that point lights
    /// can illuminate.
    #[inline]
    pub fn is_lit_by_lights(&self) -> bool {
        self.surface.diffuse.max_element() > 0.0 || self.surface.specular.max_element() > 0.0
    }
}

/// The magnitude whose ulps bound the rounding error of `hit.point` when
/// cancellation made the point small: the point is `M p + t` (object
/// point `p`, the instance's render-frame translation `t`), whose error is
/// a few ulps of `|M p| + |t|` per coordinate. Half of
/// `max|hit.point - t| + max|t|` (at least `max|M p| + max|t|` over 2): for
/// an instance at the origin, or wherever the point is not much smaller
/// than the terms it was summed from, this is below the point's own
/// magnitude and changes nothing; at the top of a sphere of radius 1000
/// centred 1000 below the origin it is 1000, where the point's own
/// coordinates are near 0 (the shadow rays of such a ground sphere found
/// the sphere again at grazing views: a Lambertian ground of albedo 0.8
/// under a white sky rendered 0.56 at 80 degrees).
#[inline]
fn offset_scale(scene: &RenderScene, hit: &Hit) -> f32 {
    let Some(inst) = scene.instances().get(hit.instance as usize) else {
        return 0.0;
    };
    let t = inst.transform.to_world.translation;
    let s = 0.5 * ((hit.point - t).abs().max_element() + t.abs().max_element());
    if s.is_finite() { s } else { 0.0 }
}

/// Lambert plus normalised Blinn-Phong: the BRDF of the local model,
/// `kd/pi + ks (s+8)/(8 pi) (n.h)^s`, times the cosine `n.l`.
#[inline]
pub fn brdf_cos(surface: &SurfaceSample, n: Vec3A, wo: Vec3A, wi: Vec3A) -> Color {
    let cos_i = n.dot(wi);
    if cos_i <= 0.0 {
        return Color::ZERO;
    }
    brdf(surface, n, wo, wi) * cos_i
}

/// The local model's BRDF `kd/pi + ks (s+8)/(8 pi) (n.h)^s` alone (no
/// cosine, no test of which side `wi` is on): photon density estimates
/// weigh each photon's flux by it.
#[inline]
pub fn brdf(surface: &SurfaceSample, n: Vec3A, wo: Vec3A, wi: Vec3A) -> Color {
    let mut f = surface.diffuse * (1.0 / PI);
    if surface.specular.max_element() > 0.0 {
        let h = (wo + wi).normalize_or_zero();
        let cos_h = n.dot(h).max(0.0);
        let s = surface.shininess;
        f += surface.specular * ((s + 8.0) / (8.0 * PI) * cos_h.powf(s));
    }
    f
}

/// A shadow ray and the radiance it carries if unoccluded.
#[derive(Clone, Copy, Debug)]
pub struct ShadowQuery {
    /// Ray from the (offset) surface point towards the light.
    pub ray: Ray,
    /// Parameter of the light along the ray (infinite for directional).
    pub t_max: f32,
    /// Radiance reflected towards the viewer if the light is visible
    /// (not yet multiplied by the path throughput).
    pub radiance: Color,
}

/// Kind of a secondary ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayKind {
    /// Primary ray from the camera.
    Camera,
    /// Mirror or Fresnel reflection.
    Reflection,
    /// Refraction through a dielectric.
    Refraction,
}

/// A secondary ray with the weight its radiance is multiplied by.
#[derive(Clone, Copy, Debug)]
pub struct Secondary {
    /// The ray (origin already offset from the surface).
    pub ray: Ray,
    /// Multiplier of the radiance it brings back.
    pub weight: Color,
    /// Reflection or refraction.
    pub kind: RayKind,
}
