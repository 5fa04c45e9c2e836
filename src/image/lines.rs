//! Feature lines as a coverage mask over an image: how much of each pixel
//! is ink, and the ink's colour. The mask is found by ray casting
//! (`crate::integrators::lines`) and composited only when an image is
//! written, after exposure and tone mapping, so lines keep their colour
//! whatever the exposure.

use crate::core::math::Color;
use crate::image::film::Film;

/// Line coverage per pixel, `width` x `height`, row-major like
/// [`Film::pixels`].
#[derive(Clone, Debug, PartialEq)]
pub struct LineOverlay {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Fraction of each pixel covered by lines, in `[0, 1]`.
    pub coverage: Vec<f32>,
    /// Ink colour: display values for 8-bit output, linear for float output.
    pub color: [f32; 3],
}

impl LineOverlay {
    /// Coverage at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> f32 {
        self.coverage[y as usize * self.width as usize + x as usize]
    }

    /// Number of pixels with some ink.
    pub fn inked_pixels(&self) -> usize {
        self.coverage.iter().filter(|&&c| c > 0.0).count()
    }

    /// `film` with the lines mixed in linearly (`(1 - a) L + a ink`): what
    /// float output stores.
    pub fn over_linear(&self, film: &Film) -> Film {
        let ink = Color::from(self.color);
        let pixels = film
            .pixels
            .iter()
            .zip(&self.coverage)
            .map(|(&c, &a)| {
                let c = if c.is_finite() { c } else { Color::ZERO };
                c * (1.0 - a) + ink * a
            })
            .collect();
        Film {
            width: film.width,
            height: film.height,
            pixels,
        }
    }

    /// Mixes the ink into one 8-bit display pixel by its coverage.
    pub fn over_srgb8(&self, index: usize, rgb: [u8; 3]) -> [u8; 3] {
        let a = self.coverage[index];
        std::array::from_fn(|i| {
            let v = rgb[i] as f32 / 255.0 * (1.0 - a) + self.color[i] * a;
            (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8
        })
    }
}
