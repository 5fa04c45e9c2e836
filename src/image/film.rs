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

/// 64-bit words of an [`ExactSum`].
pub const SUM_WORDS: usize = 5;

/// An exact sum of `f32` values: a 320-bit two's-complement integer in
/// units of `2^-149`, the smallest `f32`. Every finite `f32` is an integer
/// multiple of that unit below `2^277`, so any value converts exactly, and
/// [`MAX_SPP`](crate::core::settings::MAX_SPP) of the largest still sum
/// far below `2^319`: the sum is exact over the whole `f32` range, and
/// independent of the order and grouping of the additions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExactSum(pub [u64; SUM_WORDS]);

impl ExactSum {
    /// Adds a finite `f32`: its 24-bit mantissa, shifted to its exponent,
    /// lands on two adjacent words, with the carry (or borrow) rippling up.
    #[inline]
    pub fn add(&mut self, v: f32) {
        let bits = v.to_bits();
        let exponent = (bits >> 23) & 0xff;
        let fraction = (bits & 0x7f_ffff) as u64;
        let mantissa = if exponent == 0 {
            fraction
        } else {
            fraction | 0x80_0000
        };
        if mantissa == 0 {
            return;
        }
        // v = mantissa * 2^(max(exponent, 1) - 150) = mantissa units << p.
        let p = exponent.max(1) - 1;
        let (i, shift) = ((p / 64) as usize, p % 64);
        let low = mantissa << shift;
        let high = if shift == 0 {
            0
        } else {
            mantissa >> (64 - shift)
        };
        let w = &mut self.0;
        // p <= 253, so i <= 3 and the two words exist.
        if bits >> 31 == 0 {
            let (a, c0) = w[i].overflowing_add(low);
            let (b, c1) = w[i + 1].overflowing_add(high);
            let (b, c2) = b.overflowing_add(c0 as u64);
            w[i] = a;
            w[i + 1] = b;
            let mut carry = c1 | c2;
            for x in &mut w[i + 2..] {
                if !carry {
                    break;
                }
                (*x, carry) = x.overflowing_add(1);
            }
        } else {
            let (a, b0) = w[i].overflowing_sub(low);
            let (b, b1) = w[i + 1].overflowing_sub(high);
            let (b, b2) = b.overflowing_sub(b0 as u64);
            w[i] = a;
            w[i + 1] = b;
            let mut borrow = b1 | b2;
            for x in &mut w[i + 2..] {
                if !borrow {
                    break;
                }
                (*x, borrow) = x.overflowing_sub(1);
            }
        }
    }

    /// True when negative.
    fn is_negative(&self) -> bool {
        self.0[SUM_WORDS - 1] >> 63 != 0
    }

    /// The sum of two exact sums; `None` on overflow (which sums of valid
    /// samples never reach).
    pub fn checked_add(&self, other: &ExactSum) -> Option<ExactSum> {
        let mut out = [0u64; SUM_WORDS];
        let mut carry = false;
        for (k, o) in out.iter_mut().enumerate() {
            let (a, c0) = self.0[k].overflowing_add(other.0[k]);
            let (a, c1) = a.overflowing_add(carry as u64);
            *o = a;
            carry = c0 | c1;
        }
        let out = ExactSum(out);
        let same_sign = self.is_negative() == other.is_negative();
        (!same_sign || out.is_negative() == self.is_negative()).then_some(out)
    }

    /// The sum as `f64`: the magnitude's two highest non-zero words
    /// converted and scaled, then signed. A fixed sequence of IEEE operations,
    /// so the same sum always gives the same bits; a single `f32`
    /// converts exactly (its bits lie in two words whose values, and whose
    /// sum, need at most 24 significant bits).
    pub fn to_f64(&self) -> f64 {
        let negative = self.is_negative();
        let mut m = self.0;
        if negative {
            let mut carry = true;
            for x in &mut m {
                (*x, carry) = (!*x).overflowing_add(carry as u64);
            }
        }
        // 2^(64 k - 149) for word k.
        const SCALE: [f64; SUM_WORDS] = [
            1.401298464324817e-45,
            2.5849394142282115e-26,
            4.76837158203125e-7,
            8_796_093_022_208.0,
            1.6225927682921336e32,
        ];
        // The highest non-zero word and the one below it carry at least 64
        // significant bits, more than an f64 keeps; lower words change the
        // result by less than 2^-64 of it and are left out.
        let Some(k) = (0..SUM_WORDS).rev().find(|&k| m[k] != 0) else {
            return 0.0;
        };
        let mut f = m[k] as f64 * SCALE[k];
        if k > 0 {
            f += m[k - 1] as f64 * SCALE[k - 1];
        }
        if negative { -f } else { f }
    }
}

/// One pixel's sum over its finite samples, exact: each channel is an
/// [`ExactSum`], so the sum does not depend on the order in which samples
/// are added nor on how they are split into partial sums
/// ([`PixelSum::merge`]). That is what makes a render split across
/// threads, batches, progressive frames, image regions or sample ranges
/// bit for bit the render done at once: every path ends in the same
/// [`PixelSum::mean`] of the same exact sum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelSum {
    sum: [ExactSum; 3],
    valid: u32,
}

impl PixelSum {
    /// A sum from its parts: the three channel sums and the number of
    /// samples added (as stored in sample shards).
    pub fn from_parts(sum: [ExactSum; 3], valid: u32) -> Self {
        Self { sum, valid }
    }

    /// The three channel sums.
    pub fn sums(&self) -> [ExactSum; 3] {
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
        self.sum[0].add(sample.x);
        self.sum[1].add(sample.y);
        self.sum[2].add(sample.z);
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
                self.sum[0].checked_add(&other.sum[0])?,
                self.sum[1].checked_add(&other.sum[1])?,
                self.sum[2].checked_add(&other.sum[2])?,
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
        let channel = |s: ExactSum| (s.to_f64() / n) as f32;
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

    /// The value of an exact sum as an exact rational: an `i128` count of
    /// `2^-149` units, for sums small enough (brute-force reference).
    fn as_units(s: &ExactSum) -> Option<i128> {
        let w = s.0;
        let top = ((w[1] as i64) >> 63) as u64;
        (w[2] == top && w[3] == top && w[4] == top)
            .then(|| ((w[1] as u128) << 64 | w[0] as u128) as i128)
    }

    #[test]
    fn exact_sums_match_integer_arithmetic_and_convert_back_exactly() {
        let mut r = Sampler::new(3, 0, 0);
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            1e-30,
        ];
        values.extend([f32::MAX, -f32::MAX, 1e30, -3.0e-39]);
        for _ in 0..100_000 {
            let hi = (r.next_f32() * 65536.0) as u32;
            let lo = (r.next_f32() * 65536.0) as u32;
            let v = f32::from_bits(hi << 16 | lo);
            if v.is_finite() {
                values.push(v);
            }
        }
        for &v in &values {
            // Every finite f32 comes back exactly from its exact sum.
            let mut s = ExactSum::default();
            s.add(v);
            assert_eq!(s.to_f64(), v as f64, "{v:e}");
            // Adding and subtracting it leaves zero; x + x is 2x.
            let mut z = s;
            z.add(-v);
            assert_eq!(z, ExactSum::default(), "{v:e}");
            s.add(v);
            assert_eq!(s.to_f64(), 2.0 * v as f64, "{v:e}");
        }
        // Against 128-bit integer arithmetic on values below 2^-40 (whose
        // sums fit in 127 bits of 2^-149 units).
        let mut acc = ExactSum::default();
        let mut units: i128 = 0;
        for &v in values.iter().filter(|v| v.abs() < 2f32.powi(-40)) {
            acc.add(v);
            units += (v as f64 * 2f64.powi(149)) as i128;
        }
        assert_eq!(as_units(&acc), Some(units));
        // The largest values MAX_SPP times do not overflow.
        let mut big = ExactSum::default();
        big.add(f32::MAX);
        let mut sum = big;
        for _ in 0..20 {
            sum = sum.checked_add(&sum).unwrap();
        }
        assert_eq!(sum.to_f64(), f32::MAX as f64 * 1048576.0);
        let huge = ExactSum([u64::MAX, u64::MAX, u64::MAX, u64::MAX, u64::MAX >> 1]);
        assert_eq!(huge.checked_add(&big), None);
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

        let exact: f64 = samples.iter().map(|c| c.y as f64).sum::<f64>() / 1000.0;
        let m = forward.mean().y as f64;
        assert!(
            (m - exact).abs() <= exact * 2f64.powi(-23),
            "{m} vs {exact}"
        );
    }

    #[test]
    fn single_samples_come_back_unchanged_and_bad_ones_are_dropped() {
        for v in [0.18f32, 1.0, 3.0e-7, 12345.678, 1e-30, 1e30, -2.5, f32::MAX] {
            let mut p = PixelSum::default();
            assert!(p.add(Color::splat(v)));
            assert_eq!(p.mean(), Color::splat(v));
        }
        let mut p = PixelSum::default();
        assert!(!p.add(Color::new(f32::NAN, 0.0, 0.0)));
        assert!(!p.add(Color::new(0.0, f32::INFINITY, 0.0)));
        assert_eq!((p.count(), p.mean()), (0, Color::ZERO));
        let huge = PixelSum::from_parts([ExactSum([0, 0, 0, 0, u64::MAX >> 1]); 3], 1);
        assert_eq!(huge.merge(&huge), None);
    }
}
