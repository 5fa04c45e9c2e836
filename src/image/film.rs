//! The image being rendered: linear radiance per pixel.

use crate::core::math::Color;

/// A `width` x `height` image of linear RGB radiance, row-major, top row
/// first.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, `width * height` of them.
    pub pixels: Vec<Color>,
}

impl Film {
    /// A black film.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![Color::ZERO; width as usize * height as usize],
        }
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> Color {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// True when every pixel is finite.
    pub fn is_finite(&self) -> bool {
        self.pixels.iter().all(|p| p.is_finite())
    }
}

/// One pixel's running sum over its finite samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelSum {
    sum: Color,
    valid: u32,
}

impl PixelSum {
    /// Adds `sample` if it is finite. A NaN or infinite sample is dropped
    /// so that none reaches the image: then nothing is added and `false` is
    /// returned, for the caller to count.
    #[inline]
    pub fn add(&mut self, sample: Color) -> bool {
        if !sample.is_finite() {
            return false;
        }
        self.sum += sample;
        self.valid += 1;
        true
    }

    /// The mean of the samples added, black when there are none.
    #[inline]
    pub fn mean(&self) -> Color {
        if self.valid > 0 {
            self.sum / self.valid as f32
        } else {
            Color::ZERO
        }
    }
}

/// Running per-pixel sums of a `width` x `height` image, laid out like
/// [`Film::pixels`]: samples are added as they are rendered (across
/// batches, or across frames), and [`PixelAccumulator::resolve`] averages
/// them into a film.
#[derive(Clone, Debug, Default)]
pub struct PixelAccumulator {
    width: u32,
    height: u32,
    pixels: Vec<PixelSum>,
}

impl PixelAccumulator {
    /// Empty sums for a `width` x `height` image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![PixelSum::default(); width as usize * height as usize],
        }
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Every pixel's sum, row-major, to add samples to with
    /// [`PixelSum::add`] (rows in parallel, for instance).
    pub fn pixels_mut(&mut self) -> &mut [PixelSum] {
        &mut self.pixels
    }

    /// Forgets every sample.
    pub fn reset(&mut self) {
        self.pixels.fill(PixelSum::default());
    }

    /// The averaged image: each pixel's mean over its finite samples.
    pub fn resolve(&self) -> Film {
        let mut film = Film::new(self.width, self.height);
        for (px, sum) in film.pixels.iter_mut().zip(&self.pixels) {
            *px = sum.mean();
        }
        film
    }
}
