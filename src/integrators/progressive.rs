//! Progressive accumulation: while nothing changes, each frame adds `spp`
//! more samples per pixel to running sums, as an interactive viewport does.
//!
//! Frame `k` of an unchanged scene is bit for bit the image of `k * spp`
//! samples rendered at once with the same seed: accumulated frames use
//! the sample indices that follow the previous ones (samplers are keyed by
//! seed, pixel and sample index), film positions follow the same rule as a
//! single render of the total count, and each pixel's sum is continued in
//! sample order. The one wrinkle is the single-sample image, whose one
//! sample goes through the pixel centre while larger counts jitter every
//! sample: after a one-sample first frame the next frame renders all its
//! samples again from index 0 (one extra sample, once).

use rayon::prelude::*;

use crate::core::settings::{MAX_SPP, RenderSettings};
use crate::image::film::{Film, PixelAccumulator};
use crate::integrators::counters::RenderCounters;
use crate::integrators::recursive::pixel_sample;
use crate::integrators::{accumulate, camera_rays};
use crate::scene::RenderScene;
use crate::scene::camera::Camera;

/// Running per-pixel sums of a progressively refined image.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    pixels: PixelAccumulator,
    samples: u32,
}

impl Accumulator {
    /// An empty accumulator for a `width` x `height` image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            pixels: PixelAccumulator::new(width, height),
            samples: 0,
        }
    }

    /// Samples per pixel accumulated so far.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Forgets every sample.
    pub fn reset(&mut self) {
        self.pixels.reset();
        self.samples = 0;
    }

    /// Renders `settings.spp` more samples per pixel with the recursive
    /// tracer (Whitted or path transport, as the settings say) and adds
    /// them. Once [`MAX_SPP`] samples are reached
    /// nothing more is added. The image size must match the accumulator's.
    pub fn add_samples(
        &mut self,
        scene: &RenderScene,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> RenderCounters {
        assert_eq!(
            (settings.width, settings.height),
            self.pixels.size(),
            "accumulator size"
        );
        let Some(total) = self
            .samples
            .checked_add(settings.spp)
            .filter(|&t| t <= MAX_SPP)
        else {
            return RenderCounters::default();
        };
        // The single-sample image used the pixel centre; any larger count
        // jitters every sample, the first included.
        let first = if self.samples == 1 {
            self.reset();
            0
        } else {
            self.samples
        };
        let cam = camera_rays(scene, camera, settings);
        let width = settings.width as usize;
        let counters = self
            .pixels
            .pixels_mut()
            .par_chunks_mut(width)
            .enumerate()
            .with_max_len(1)
            .map(|(y, row)| {
                let mut counters = RenderCounters::default();
                for (x, sum) in row.iter_mut().enumerate() {
                    for s in first..total {
                        let l = pixel_sample(
                            scene,
                            settings,
                            &cam,
                            (x as u32, y as u32),
                            (s, total),
                            false,
                            &mut counters,
                        );
                        accumulate(sum, l, &mut counters);
                    }
                }
                counters
            })
            .reduce(RenderCounters::default, |mut a, b| {
                a.add(&b);
                a
            });
        self.samples = total;
        counters
    }

    /// The current image: each pixel's mean over its finite samples.
    pub fn film(&self) -> Film {
        self.pixels.resolve()
    }
}
