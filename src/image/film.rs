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
        // v = mantissa * 2^(max(exponent, 1) - 150) = mantissa units << p.
        self.add_units(mantissa, exponent.max(1) - 1, bits >> 31 != 0);
    }

    /// Adds a finite `f64` that is a whole number of `2^-149` units (as
    /// every exact sum of `f32` values below `2^148` is), exactly.
    fn add_f64(&mut self, v: f64) {
        let bits = v.to_bits();
        let exponent = ((bits >> 52) & 0x7ff) as i32;
        let fraction = bits & 0xf_ffff_ffff_ffff;
        let mantissa = if exponent == 0 {
            fraction
        } else {
            fraction | 1 << 52
        };
        if mantissa == 0 {
            return;
        }
        // v = mantissa * 2^(max(exponent, 1) - 1075) = mantissa units << p,
        // p = max(exponent, 1) - 926; a negative p drops only zero bits.
        let p = exponent.max(1) - 926;
        debug_assert!(p >= 0 || mantissa.trailing_zeros() >= p.unsigned_abs());
        let (mantissa, p) = if p < 0 {
            (mantissa >> p.unsigned_abs(), 0)
        } else {
            (mantissa, p as u32)
        };
        self.add_units(mantissa, p, bits >> 63 != 0);
    }

    /// Adds (or subtracts, when `negative`) `mantissa << p` units, where
    /// `mantissa < 2^53` and `p <= 253`: the shifted value lands on two
    /// adjacent words, with the carry (or borrow) rippling up.
    #[inline]
    fn add_units(&mut self, mantissa: u64, p: u32, negative: bool) {
        if mantissa == 0 {
            return;
        }
        let (i, shift) = ((p / 64) as usize, p % 64);
        let low = mantissa << shift;
        let high = if shift == 0 {
            0
        } else {
            mantissa >> (64 - shift)
        };
        let w = &mut self.0;
        // p <= 253, so i <= 3 and the two words exist.
        if !negative {
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

/// One pixel's sum over its finite samples, exact: the sum does not
/// depend on the order in which samples are added nor on how they are
/// split into partial sums ([`PixelSum::merge`]). That is what makes a
/// render split across threads, batches, progressive frames, image regions
/// or sample ranges bit for bit the render done at once: every path ends in
/// the same [`PixelSum::mean`] of the same exact sum.
///
/// Each channel's sum is held as `spill + fast`: `fast` is an `f64` to
/// which samples are added as long as the `f64` addition is exact (it
/// almost always is: an `f64` holds 29 more bits than an `f32` sample, so
/// only a sample below `2^-29` of the running sum, or a sum spanning more
/// than 53 bits, rounds), and `spill` an [`ExactSum`] that takes the `f64`
/// sum over, exactly, whenever an addition would round. The spill is
/// allocated only then, so a pixel normally costs 40 bytes and three
/// checked `f64` additions per sample, not a 320-bit addition per channel.
/// The mean is computed from the exact value alone ([`ExactSum::to_f64`]
/// is exact for every value an `f64` holds), so it is the same whichever
/// part holds the sum.
#[derive(Clone, Debug, Default)]
pub struct PixelSum {
    fast: [f64; 3],
    spill: Option<Box<[ExactSum; 3]>>,
    valid: u32,
}

/// `a + b` in `f64`, and whether that addition was exact. With
/// `s = a + b` rounded, `s - a` is exact when `|a| >= |b|` (and `s - b`
/// when `|b| >= |a|`), so both differences give back the other operand
/// exactly if and only if no rounding happened.
#[inline]
fn exact_add(a: f64, b: f64) -> (f64, bool) {
    let s = a + b;
    (s, (s - a == b) & (s - b == a))
}

impl PartialEq for PixelSum {
    /// Equal when the exact sums and the counts are equal, whichever part
    /// holds them.
    fn eq(&self, other: &Self) -> bool {
        self.valid == other.valid && self.sums() == other.sums()
    }
}

impl Eq for PixelSum {}

impl PixelSum {
    /// A sum from its parts: the three channel sums and the number of
    /// samples added (as stored in sample shards).
    pub fn from_parts(sum: [ExactSum; 3], valid: u32) -> Self {
        Self {
            fast: [0.0; 3],
            spill: Some(Box::new(sum)),
            valid,
        }
    }

    /// The three channel sums.
    pub fn sums(&self) -> [ExactSum; 3] {
        let mut sums = self.spill.as_deref().copied().unwrap_or_default();
        for (s, &f) in sums.iter_mut().zip(&self.fast) {
            s.add_f64(f);
        }
        sums
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
        let v = [sample.x as f64, sample.y as f64, sample.z as f64];
        // Three checks, one branch.
        let (r, r_exact) = exact_add(self.fast[0], v[0]);
        let (g, g_exact) = exact_add(self.fast[1], v[1]);
        let (b, b_exact) = exact_add(self.fast[2], v[2]);
        if r_exact & g_exact & b_exact {
            self.fast = [r, g, b];
        } else {
            self.spill_and_add(v);
        }
        self.valid += 1;
        true
    }

    /// The rare case of [`PixelSum::add`]: an `f64` addition would round,
    /// so the `f64` sums move into the exact spill (exactly) and the sample
    /// starts them afresh.
    #[cold]
    fn spill_and_add(&mut self, v: [f64; 3]) {
        let spill = self.spill.get_or_insert_with(Default::default);
        for ((s, f), v) in spill.iter_mut().zip(&mut self.fast).zip(v) {
            s.add_f64(*f);
            *f = v;
        }
    }

    /// Adds another partial sum of the same pixel (disjoint samples):
    /// exact, so any split of a pixel's samples merges to the same sum.
    /// `None` on overflow, which sums of at most
    /// [`MAX_SPP`](crate::core::settings::MAX_SPP) samples never reach.
    pub fn merge(&self, other: &PixelSum) -> Option<PixelSum> {
        let valid = self.valid.checked_add(other.valid)?;
        if self.spill.is_none() && other.spill.is_none() {
            let f = |c: usize| exact_add(self.fast[c], other.fast[c]);
            let ((r, r_exact), (g, g_exact), (b, b_exact)) = (f(0), f(1), f(2));
            if r_exact & g_exact & b_exact {
                return Some(PixelSum {
                    fast: [r, g, b],
                    spill: None,
                    valid,
                });
            }
        }
        let (a, b) = (self.sums(), other.sums());
        Some(PixelSum::from_parts(
            [
                a[0].checked_add(&b[0])?,
                a[1].checked_add(&b[1])?,
                a[2].checked_add(&b[2])?,
            ],
            valid,
        ))
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
        let total = match &self.spill {
            // The f64 sums are exact: they are what `to_f64` would give.
            None => self.fast,
            Some(_) => self.sums().map(|s| s.to_f64()),
        };
        Color::new(
            (total[0] / n) as f32,
            (total[1] / n) as f32,
            (total[2] / n) as f32,
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
            assert_eq!(a.merge(&b).as_ref(), Some(&forward));
            assert_eq!(b.merge(&a).as_ref(), Some(&forward));
        }
        // The mean is the exact mean to within the roundings to f64 and f32.

        let exact: f64 = samples.iter().map(|c| c.y as f64).sum::<f64>() / 1000.0;
        let m = forward.mean().y as f64;
        assert!(
            (m - exact).abs() <= exact * 2f64.powi(-23),
            "{m} vs {exact}"
        );
    }

    /// The mean as the 320-bit sums alone give it (the reference for
    /// [`PixelSum`]'s `f64` fast path): every channel through
    /// [`ExactSum::add`] and [`ExactSum::to_f64`].
    fn reference_mean(samples: &[Color]) -> Color {
        let mut sums = [ExactSum::default(); 3];
        for s in samples {
            for (c, v) in sums.iter_mut().zip(s.to_array()) {
                c.add(v);
            }
        }
        let n = samples.len() as f64;
        Color::from_array(sums.map(|s| (s.to_f64() / n) as f32))
    }

    #[test]
    fn the_f64_fast_path_gives_the_exact_sums_bits_in_any_order_and_split() {
        // Three regimes: samples of one magnitude (no spill), samples over
        // 80 binary orders with signs (spills in every order), and sums
        // that stay exact until one tiny sample arrives.
        let mut r = Sampler::new(21, 4, 5);
        let mut sets: Vec<Vec<Color>> = Vec::new();
        sets.push(
            (0..4096)
                .map(|_| Color::new(r.next_f32(), r.next_f32(), r.next_f32()))
                .collect(),
        );
        sets.push(
            (0..4096)
                .map(|_| {
                    let e = (r.next_f32() * 80.0) as i32 - 40;
                    let sign = if r.next_f32() < 0.3 { -1.0 } else { 1.0 };
                    Color::new(r.next_f32(), sign, r.next_f32()) * 2f32.powi(e)
                })
                .collect(),
        );
        let mut late = vec![Color::splat(0.75); 100];
        late.push(Color::new(1.0e-12, 3.0e-20, 0.1));
        late.extend(vec![Color::splat(1.5); 100]);
        sets.push(late);
        for samples in &sets {
            let want = reference_mean(samples);
            let mut forward = PixelSum::default();
            samples.iter().for_each(|s| _ = forward.add(*s));
            assert_eq!(
                forward.mean().to_array().map(f32::to_bits),
                want.to_array().map(f32::to_bits)
            );
            let mut exact = [ExactSum::default(); 3];
            for s in samples {
                for (c, v) in exact.iter_mut().zip(s.to_array()) {
                    c.add(v);
                }
            }
            assert_eq!(forward.sums(), exact);
            // Shuffled orders, and splits merged either way round.
            for round in 0..4u32 {
                let mut order: Vec<usize> = (0..samples.len()).collect();
                let mut q = Sampler::new(99, round, 0);
                for i in (1..order.len()).rev() {
                    let j = ((q.next_f32() * (i + 1) as f32) as usize).min(i);
                    order.swap(i, j);
                }
                let cut = order.len() * (round as usize + 1) / 5;
                let (mut a, mut b, mut all) = (
                    PixelSum::default(),
                    PixelSum::default(),
                    PixelSum::default(),
                );
                for (k, &i) in order.iter().enumerate() {
                    all.add(samples[i]);
                    if k < cut {
                        a.add(samples[i])
                    } else {
                        b.add(samples[i])
                    };
                }
                for sum in [all, a.merge(&b).unwrap(), b.merge(&a).unwrap()] {
                    assert_eq!(sum, forward);
                    assert_eq!(
                        sum.mean().to_array().map(f32::to_bits),
                        want.to_array().map(f32::to_bits)
                    );
                }
            }
        }
        // The three regimes really are what they claim: the first never
        // leaves the fast path, the other two spill.
        let spills = |samples: &[Color]| {
            let mut p = PixelSum::default();
            samples.iter().for_each(|s| _ = p.add(*s));
            p.spill.is_some()
        };
        assert_eq!(
            sets.iter().map(|s| spills(s)).collect::<Vec<_>>(),
            [false, true, true]
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
