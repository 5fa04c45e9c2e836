//! Small deterministic generators for test inputs, so that failures replay.

use glam::Vec3;
use prism::core::rng::Sampler;

/// Uniform random numbers derived from one uniform `f32` stream.
pub trait Random {
    /// Uniform in [0, 1).
    fn f32(&mut self) -> f32;

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// Each coordinate uniform in [lo, hi), drawn x, y, z.
    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    /// Uniform on the unit sphere.
    fn dir(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// SplitMix64, seeded with its state.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

impl Random for SplitMix64 {
    fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The renderer's own sampler (stream 0 of pixel 0 of `seed`).
pub struct SamplerRng(Sampler);

impl SamplerRng {
    pub fn new(seed: u64) -> Self {
        SamplerRng(Sampler::new(seed, 0, 0))
    }
}

impl Random for SamplerRng {
    fn f32(&mut self) -> f32 {
        self.0.next_f32()
    }
}
