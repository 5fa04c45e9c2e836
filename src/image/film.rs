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

/// Scale of the fixed-point pixel sums: one unit is `2^-63` of radiance.
const FIXED_SCALE: f64 = 9_223_372_036_854_775_808.0; // 2^63

/// Largest magnitude a sample channel keeps: larger values (far beyond any
/// physical radiance) are clamped to it, so that [`MAX_SPP`] samples
/// summed in fixed point cannot overflow (`2^20 * 2^42 * 2^63 < 2^127`).
///
/// [`MAX_SPP`]: crate::core::settings::MAX_SPP
pub const MAX_SAMPLE_MAGNITUDE: f32 = 4_398_046_511_104.0; // 2^42

/// One channel of a finite sample in units of `2^-63`, truncated toward
/// zero: exact for every `f32` of magnitude `2^-39` or more (the bits
/// below `2^-63` of smaller values are dropped). Equal to
/// `(v as f64 * 2^63) as i128` for `|v| <= MAX_SAMPLE_MAGNITUDE`, but
/// made from the float's bits (mantissa shifted by its exponent) instead
/// of the 128-bit library conversion.
#[inline]
pub fn to_fixed(v: f32) -> i128 {
    let v = v.clamp(-MAX_SAMPLE_MAGNITUDE, MAX_SAMPLE_MAGNITUDE);
    let bits = v.to_bits();
    let exponent = ((bits >> 23) & 0xff) as i32;
    if exponent == 0 {
        // Zero or subnormal: below 2^-126, far below one unit.
        return 0;
    }
    let mantissa = ((bits & 0x7f_ffff) | 0x80_0000) as i128;
    // v = mantissa * 2^(exponent - 150), so in units of 2^-63 it is
    // mantissa * 2^(exponent - 87).
    let shift = exponent - 87;
    let magnitude = if shift >= 0 {
        mantissa << shift
    } else if shift > -24 {
        mantissa >> -shift
    } else {
        0
    };
    if bits >> 31 != 0 { -magnitude } else { magnitude }
}

/// A 128-bit fixed-point sum in radiance, as `f64`: its upper 64 bits
/// (signed) and its lower 64 bits without the last (which no sum of
/// samples of magnitude `2^-39` or more has) converted with the cheap
/// signed conversions and added, then scaled. Exact for a single
/// non-negative sample; always a fixed sequence of IEEE operations, so
/// the same sum gives the same bits.
#[inline]
fn fixed_to_f64(s: i128) -> f64 {
    let high = (s >> 64) as i64 as f64;
    let low = ((s as u64) >> 1) as i64 as f64;
    (high * 18_446_744_073_709_551_616.0 + low * 2.0) * (1.0 / FIXED_SCALE)
}

/// One pixel's sum over its finite samples, exact: each sample channel is
/// converted to a fixed-point integer of 63 fractional bits ([`to_fixed`]) and added in
/// 128-bit integers, so the sum does not depend on the order in which
/// samples are added nor on how they are split into partial sums
/// ([`PixelSum::merge`]). That is what makes a render split across
/// threads, batches, progressive frames, image regions or sample ranges
/// bit for bit the render done at once: every path ends in the same
/// [`PixelSum::mean`] of the same exact sum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelSum {
    sum: [i128; 3],
    valid: u32,
}

impl PixelSum {
    /// A sum from its parts: the three channel sums in units of `2^-63`
    /// and the number of samples added (as stored in sample shards).
    pub fn from_parts(sum: [i128; 3], valid: u32) -> Self {
        Self { sum, valid }
    }

    /// The three channel sums in units of `2^-63`.
    pub fn sums(&self) -> [i128; 3] {
        self.sum
    }

    /// The number of finite samples added.
    pub fn count(&self) -> u32 {
        self.valid
    }

    /// Adds `sample` if it is finite. A NaN or infinite sample is dropped
    /// so that none reaches the image: then nothing is added and `false` is
    /// returned, for the caller to count.
    #[inline]
    pub fn add(&mut self, sample: Color) -> bool {
        if !sample.is_finite() {
            return false;
        }
        self.sum[0] += to_fixed(sample.x);
        self.sum[1] += to_fixed(sample.y);
        self.sum[2] += to_fixed(sample.z);
        self.valid += 1;
        true
    }

    /// Adds another partial sum of the same pixel (disjoint samples):
    /// exact, so any split of a pixel's samples merges to the same sum.
    /// `None` on overflow, which sums of at most
    /// [`MAX_SPP`](crate::core::settings::MAX_SPP) samples never reach.
    pub fn merge(&self, other: &PixelSum) -> Option<PixelSum> {
        Some(PixelSum {
            sum: [
                self.sum[0].checked_add(other.sum[0])?,
                self.sum[1].checked_add(other.sum[1])?,
                self.sum[2].checked_add(other.sum[2])?,
            ],
            valid: self.valid.checked_add(other.valid)?,
        })
    }

    /// The mean of the samples added, black when there are none: each
    /// exact sum converted to `f64`, divided by the count in `f64` and
    /// rounded to `f32`. A single sample comes back exactly.
    #[inline]
    pub fn mean(&self) -> Color {
        if self.valid == 0 {
            return Color::ZERO;
        }
        let n = self.valid as f64;
        let channel = |s: i128| (fixed_to_f64(s) / n) as f32;
        Color::new(
            channel(self.sum[0]),
            channel(self.sum[1]),
            channel(self.sum[2]),
        )
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

    /// Every pixel's sum, row-major.
    pub fn pixels(&self) -> &[PixelSum] {
        &self.pixels
    }

    /// An accumulator of `width` x `height` pixel sums, row-major; `None`
    /// when `pixels` has not `width * height` of them.
    pub fn from_pixels(width: u32, height: u32, pixels: Vec<PixelSum>) -> Option<Self> {
        (pixels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            pixels,
        })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    #[test]
    fn fixed_point_matches_the_float_conversion() {
        // Brute-force cross-check against the library conversion over
        // random bit patterns of every exponent, and the edges.
        let mut r = Sampler::new(3, 0, 0);
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::MIN_POSITIVE,
            1e-30,
            2f32.powi(-40),
        ];
        values.extend([MAX_SAMPLE_MAGNITUDE, -MAX_SAMPLE_MAGNITUDE, 1e13, -1e30]);
        for _ in 0..200_000 {
            let hi = (r.next_f32() * 65536.0) as u32;
            let lo = (r.next_f32() * 65536.0) as u32;
            let v = f32::from_bits(hi << 16 | lo);
            if v.is_finite() {
                values.push(v);
            }
        }
        for v in values {
            let c = v.clamp(-MAX_SAMPLE_MAGNITUDE, MAX_SAMPLE_MAGNITUDE);
            let expected = (c as f64 * FIXED_SCALE) as i128;
            assert_eq!(to_fixed(v), expected, "{v:e}");
        }
    }

    #[test]
    fn sums_are_exact_whatever_the_order_and_split() {
        // Values spread over 20 binary orders of magnitude, where f32
        // running sums visibly depend on the order.
        let mut r = Sampler::new(9, 1, 2);
        let samples: Vec<Color> = (0..1000)
            .map(|_| {
                let e = (r.next_f32() * 20.0) as i32 - 10;
                Color::new(r.next_f32(), 1.0, r.next_f32()) * 2f32.powi(e)
            })
            .collect();
        let mut forward = PixelSum::default();
        for s in &samples {
            forward.add(*s);
        }
        let mut backward = PixelSum::default();
        for s in samples.iter().rev() {
            backward.add(*s);
        }
        assert_eq!(forward, backward);
        for cut in [1, 7, 500, 999] {
            let (mut a, mut b) = (PixelSum::default(), PixelSum::default());
            samples[..cut].iter().for_each(|s| _ = a.add(*s));
            samples[cut..].iter().for_each(|s| _ = b.add(*s));
            assert_eq!(a.merge(&b), Some(forward));
            assert_eq!(b.merge(&a), Some(forward));
        }
        // The mean is the exact mean to within the roundings to f64 and f32.
        for c in forward.sums() {
            let split = fixed_to_f64(c);
            let direct = c as f64 / FIXED_SCALE;
            assert!((split - direct).abs() <= direct.abs() * 2f64.powi(-51));
        }
        let exact: f64 = samples.iter().map(|c| c.y as f64).sum::<f64>() / 1000.0;
        let m = forward.mean().y as f64;
        assert!(
            (m - exact).abs() <= exact * 2f64.powi(-23),
            "{m} vs {exact}"
        );
    }

    #[test]
    fn single_samples_come_back_unchanged_and_bad_ones_are_dropped() {
        for v in [0.18f32, 1.0, 3.0e-7, 12345.678, 2f32.powi(-39), MAX_SAMPLE_MAGNITUDE] {
            let mut p = PixelSum::default();
            assert!(p.add(Color::splat(v)));
            assert_eq!(p.mean(), Color::splat(v));
        }
        let mut p = PixelSum::default();
        assert!(!p.add(Color::new(f32::NAN, 0.0, 0.0)));
        assert!(!p.add(Color::new(0.0, f32::INFINITY, 0.0)));
        assert_eq!((p.count(), p.mean()), (0, Color::ZERO));
        // Huge samples are clamped, so the largest sums still fit.
        let mut big = PixelSum::default();
        big.add(Color::splat(f32::MAX));
        assert_eq!(big.mean(), Color::splat(MAX_SAMPLE_MAGNITUDE));
        let huge = PixelSum::from_parts([i128::MAX; 3], 1);
        assert_eq!(huge.merge(&big), None);
    }
}
