//! Lines as a coverage mask over an image: how much of each pixel is ink,
//! and the ink's colour. Feature lines find their mask by ray casting
//! (`crate::integrators::lines`); the structure overlays draw segments
//! into it ([`LineOverlay::draw_segment`]). Masks are composited only when
//! an image is written, after exposure and tone mapping, so lines keep
//! their colour whatever the exposure.

use glam::Vec2;

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

    /// An empty mask (no ink) of `width` x `height` pixels in `color`.
    pub fn empty(width: u32, height: u32, color: [f32; 3]) -> Self {
        Self {
            width,
            height,
            coverage: vec![0.0; width as usize * height as usize],
            color,
        }
    }

    /// Draws the segment `a`-`b` (film pixels, `(0, 0)` the top-left
    /// corner) `width` pixels wide with round ends, anti-aliased: a pixel
    /// whose centre is at distance `d` from the segment gets coverage
    /// `clamp(width / 2 + 1/2 - d, 0, 1)` (the area of a pixel-wide box
    /// filter over a straight edge), times `alpha`. With `dash = (on,
    /// off)` only the stretches `[k (on + off), k (on + off) + on]` pixels
    /// from `a` are drawn. Coverage keeps the larger of old and new, so the
    /// order in which segments are drawn does not matter. Non-finite
    /// input draws nothing.
    pub fn draw_segment(
        &mut self,
        a: Vec2,
        b: Vec2,
        width: f32,
        dash: Option<(f32, f32)>,
        alpha: f32,
    ) {
        if !(a.is_finite() && b.is_finite() && width > 0.0 && alpha > 0.0) {
            return;
        }
        let reach = 0.5 * width + 0.5;
        let d = b - a;
        let length = d.length();
        let (w, h) = (self.width as f32, self.height as f32);
        let y0 = (a.y.min(b.y) - reach).floor().max(0.0);
        let y1 = (a.y.max(b.y) + reach).ceil().min(h);
        let mut y = y0;
        while y < y1 {
            let yc = y + 0.5;
            // The part of the segment within `reach` of this row's centre.
            let (t0, t1) = if d.y.abs() <= f32::EPSILON * length.max(1.0) {
                if (a.y - yc).abs() > reach {
                    y += 1.0;
                    continue;
                }
                (0.0, 1.0)
            } else {
                let (p, q) = ((yc - reach - a.y) / d.y, (yc + reach - a.y) / d.y);
                (p.min(q).max(0.0), p.max(q).min(1.0))
            };
            if t0 <= t1 {
                let (xa, xb) = (a.x + d.x * t0, a.x + d.x * t1);
                let x0 = (xa.min(xb) - reach).floor().max(0.0);
                let x1 = (xa.max(xb) + reach).ceil().min(w);
                let mut x = x0;
                while x < x1 {
                    let p = Vec2::new(x + 0.5, yc);
                    let t = if length > 0.0 {
                        ((p - a).dot(d) / (length * length)).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    let on = dash.is_none_or(|(on, off)| (t * length).rem_euclid(on + off) <= on);
                    let c = (reach - (a + d * t).distance(p)).clamp(0.0, 1.0) * alpha;
                    if on && c > 0.0 {
                        let i = y as usize * self.width as usize + x as usize;
                        self.coverage[i] = self.coverage[i].max(c);
                    }
                    x += 1.0;
                }
            }
            y += 1.0;
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ink(o: &LineOverlay) -> f32 {
        o.coverage.iter().sum()
    }

    #[test]
    fn a_pixel_wide_row_segment_covers_its_pixels_exactly() {
        let mut o = LineOverlay::empty(32, 24, [0.0; 3]);
        o.draw_segment(Vec2::new(2.5, 10.5), Vec2::new(20.5, 10.5), 1.0, None, 1.0);
        for y in 0..24 {
            for x in 0..32 {
                let want = if y == 10 && (2..=20).contains(&x) {
                    1.0
                } else {
                    0.0
                };
                assert_eq!(o.get(x, y), want, "({x}, {y})");
            }
        }
        // Length 18 plus two half-pixel round caps.
        assert_eq!(ink(&o), 19.0);
    }

    #[test]
    fn ink_is_length_times_width_at_any_angle_and_dashes_keep_their_share() {
        // clamp(w/2 + 1/2 - d, 0, 1) integrates to w across the line, so a
        // long line's ink is L w, up to its two caps and the sampling at
        // pixel centres: within 2 (w + 1).
        for (k, width) in [1.0f32, 2.5].into_iter().enumerate() {
            for step in 0..12 {
                let angle = step as f32 * 0.27 + k as f32 * 0.1;
                let centre = Vec2::new(50.0, 50.0);
                let half = Vec2::new(angle.cos(), angle.sin()) * 30.0;
                let mut o = LineOverlay::empty(100, 100, [0.0; 3]);
                o.draw_segment(centre - half, centre + half, width, None, 1.0);
                let want = 60.0 * width;
                assert!(
                    (ink(&o) - want).abs() <= 2.0 * (width + 1.0),
                    "angle {angle}, width {width}: {} vs {want}",
                    ink(&o)
                );
            }
        }
        // Dashes 4 on, 3 off along 70 pixels: ten dashes of 4.
        let mut o = LineOverlay::empty(100, 20, [0.0; 3]);
        o.draw_segment(
            Vec2::new(10.0, 10.5),
            Vec2::new(80.0, 10.5),
            1.0,
            Some((4.0, 3.0)),
            1.0,
        );
        assert!((ink(&o) - 40.0).abs() <= 4.0, "{}", ink(&o));
        // Half the opacity, half the ink.
        let mut half = LineOverlay::empty(100, 20, [0.0; 3]);
        half.draw_segment(
            Vec2::new(10.0, 10.5),
            Vec2::new(80.0, 10.5),
            1.0,
            Some((4.0, 3.0)),
            0.5,
        );
        assert!((ink(&half) - 0.5 * ink(&o)).abs() < 1e-3);
    }

    #[test]
    fn segments_outside_or_not_finite_draw_nothing_and_order_does_not_matter() {
        let mut o = LineOverlay::empty(16, 16, [0.0; 3]);
        o.draw_segment(
            Vec2::new(-10.0, -5.0),
            Vec2::new(-2.0, 30.0),
            1.0,
            None,
            1.0,
        );
        o.draw_segment(
            Vec2::new(0.0, f32::NAN),
            Vec2::new(5.0, 5.0),
            1.0,
            None,
            1.0,
        );
        o.draw_segment(Vec2::new(1.0, 1.0), Vec2::new(5.0, 5.0), 0.0, None, 1.0);
        assert_eq!(o.inked_pixels(), 0);
        let (a, b) = (
            (Vec2::new(1.0, 2.0), Vec2::new(15.0, 9.0)),
            (Vec2::new(3.0, 14.0), Vec2::new(12.0, 0.5)),
        );
        let mut ab = LineOverlay::empty(16, 16, [0.0; 3]);
        ab.draw_segment(a.0, a.1, 1.5, None, 1.0);
        ab.draw_segment(b.0, b.1, 1.5, None, 0.7);
        let mut ba = LineOverlay::empty(16, 16, [0.0; 3]);
        ba.draw_segment(b.0, b.1, 1.5, None, 0.7);
        ba.draw_segment(a.0, a.1, 1.5, None, 1.0);
        assert_eq!(ab, ba);
        assert!(ab.coverage.iter().all(|c| (0.0..=1.0).contains(c)));
    }
}
