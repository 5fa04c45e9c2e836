//! Integrators: turn a [`RenderScene`] and a
//! camera into a [`Film`](crate::image::film::Film).

/// The ray and sample counters, kept in `core` so transport kernels can fill
/// them; re-exported here where integrators and their callers name them.
pub use crate::core::counters;
pub mod caustics;
pub mod lines;
pub mod overlay;
pub mod photon;
pub mod progressive;
pub mod radiosity;
pub mod recursive;
pub mod vector_lines;
pub mod wavefront;

use glam::Vec2;

use crate::core::math::{Color, Ray};
use crate::core::rng::Sampler;
use crate::core::settings::RenderSettings;
use crate::image::film::PixelSum;
use crate::integrators::counters::RenderCounters;
use crate::scene::RenderScene;
use crate::scene::camera::{Camera, CameraRays};

/// Called with the number of rows finished since the last call.
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

/// Film position of sample `s` of a pixel: the centre for a single sample,
/// uniformly jittered otherwise.
#[inline]
pub fn film_sample(x: u32, y: u32, spp: u32, sampler: &mut Sampler) -> Vec2 {
    if spp == 1 {
        Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
    } else {
        Vec2::new(x as f32 + sampler.next_f32(), y as f32 + sampler.next_f32())
    }
}

/// The camera ray of sample `s` of pixel `(x, y)`: through its film
/// position ([`film_sample`], dimensions 0 and 1) and, for a camera with a
/// lens, from the lens point of dimensions 2 and 3 (the spare pair of the
/// first set of four, see [`crate::transport::path::bounce_dimension`]).
/// A pinhole camera's ray is the one it always was.
#[inline]
pub fn camera_ray(cam: &CameraRays, x: u32, y: u32, spp: u32, sampler: &mut Sampler) -> Ray {
    let p = film_sample(x, y, spp, sampler);
    if !cam.has_lens() {
        return cam.ray(p);
    }
    sampler.set_dimension(2);
    let u = Vec2::new(sampler.next_f32(), sampler.next_f32());
    cam.lens_ray(p, u)
}

/// [`camera_ray`], bit for bit (tested), with its numbers drawn by
/// [`Sampler::pair`], which is always inlined: for the wavefront's
/// camera-ray stage, where the compiler kept [`Sampler::next_f32`] out of
/// line (two calls per ray of about 120 instructions each, callgrind).
/// The recursive tracer keeps [`camera_ray`]: given this body, the
/// compiler stopped inlining it into the row loop, which then took 1.7%
/// more instructions on `diffuse_only.toml` and 2.7% on the depth of
/// field scene.
#[inline(always)]
pub fn camera_ray_paired(cam: &CameraRays, x: u32, y: u32, spp: u32, sampler: &mut Sampler) -> Ray {
    let p = if spp == 1 {
        Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
    } else {
        let [u, v] = sampler.pair(0);
        Vec2::new(x as f32 + u, y as f32 + v)
    };
    if !cam.has_lens() {
        return cam.ray(p);
    }
    let [u, v] = sampler.pair(2);
    cam.lens_ray(p, Vec2::new(u, v))
}

/// Adds one sample to a pixel's sum, counting it in `counters` when it is
/// dropped as non-finite (see [`PixelSum::add`]).
#[inline]
pub fn accumulate(pixel: &mut PixelSum, sample: Color, counters: &mut RenderCounters) {
    if !pixel.add(sample) {
        counters.nonfinite_samples += 1;
    }
}

/// Prepares camera rays for the settings' image size and projection, in
/// the frame of `scene`'s render origin.
pub fn camera_rays(scene: &RenderScene, camera: &Camera, settings: &RenderSettings) -> CameraRays {
    CameraRays::panoramic(
        camera,
        scene.origin(),
        settings.width,
        settings.height,
        settings.panorama,
    )
}

/// Which integrator renders the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash)]
pub enum IntegratorKind {
    /// Depth-first recursive tracing, pixel by pixel (under Whitted
    /// transport, camera and shadow rays in packets of eight pixels).
    #[default]
    Recursive,
    /// Breadth-first wavefront tracing over structure-of-arrays queues,
    /// one ECS system per stage.
    Wavefront,
}

impl IntegratorKind {
    /// Both integrators.
    pub const ALL: [IntegratorKind; 2] = [IntegratorKind::Recursive, IntegratorKind::Wavefront];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            IntegratorKind::Recursive => "recursive",
            IntegratorKind::Wavefront => "wavefront",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::SamplerKind;

    /// The wavefront's camera rays are the recursive tracer's, bit for
    /// bit: every pixel of a small image, 1 and 4 samples, with and without
    /// a lens, both samplers (a sample past the Sobol sequence's 2^16
    /// falls back to hashes).
    #[test]
    fn paired_camera_rays_are_the_camera_rays() {
        for lens_radius in [0.0, 0.2] {
            let cam = Camera {
                lens_radius,
                focus_distance: 3.0,
                ..Camera::default()
            };
            let rays = CameraRays::new(&cam, 12, 9);
            for kind in [SamplerKind::Sobol, SamplerKind::Hash] {
                for (spp, samples) in [(1, vec![0]), (4, vec![0, 1, 2, 3, 70_000])] {
                    for (x, y) in (0..9).flat_map(|y| (0..12).map(move |x| (x, y))) {
                        for &s in &samples {
                            let pixel = y * 12 + x;
                            let mut a = Sampler::with_kind(kind, 7, pixel, s);
                            let mut b = a;
                            let (ra, rb) = (
                                camera_ray(&rays, x, y, spp, &mut a),
                                camera_ray_paired(&rays, x, y, spp, &mut b),
                            );
                            let bits = |r: Ray| {
                                [r.origin.to_array(), r.direction.to_array()]
                                    .map(|v| v.map(f32::to_bits))
                            };
                            assert_eq!(
                                bits(ra),
                                bits(rb),
                                "lens {lens_radius} {kind:?} spp {spp} pixel ({x}, {y}) sample {s}"
                            );
                        }
                    }
                }
            }
        }
    }
}
