//! Counter-based random numbers keyed by what they are for.
//!
//! Every random number is a pure function of `(seed, pixel, sample,
//! dimension)`, so an image does not depend on the order in which pixels
//! are rendered, on the thread count, or on the integrator's control flow.

use std::sync::atomic::{AtomicU32, Ordering};

/// Which numbers a [`Sampler`] draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Owen-scrambled Sobol points (Burley 2020, through the
    /// `sobol_burley` crate), padded in sets of four dimensions: the
    /// samples of one pixel are stratified in every set of four
    /// consecutive dimensions (pairs `(4k, 4k+1)` are the best
    /// stratified), and the sets, the pixels and the seeds are
    /// decorrelated by hashing them into the scrambling seed. Beyond 2^16
    /// samples per pixel the numbers fall back to the hash.
    #[default]
    Sobol,
    /// Independent hashed numbers (a splitmix64 finaliser): every
    /// dimension of every sample is its own uniform number.
    Hash,
}

impl SamplerKind {
    /// The name used on the command line and in scene files.
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Sobol => "sobol",
            SamplerKind::Hash => "hash",
        }
    }
}

/// Longest Sobol sequence per pixel (`sobol_burley`'s limit).
const SOBOL_SAMPLES: u32 = 1 << 16;

/// Mixed into the hash sampler's key of a split path's parts
/// ([`Sampler::split`]).
const SPLIT_SALT: u64 = 0x5a17_c0de_9e37_79b9;

/// The sampler of one pixel sample. Successive calls to
/// [`Sampler::next_f32`] advance the dimension; every number is a pure
/// function of `(kind, seed, pixel, sample, dimension)`.
#[derive(Clone, Copy, Debug)]
pub struct Sampler {
    /// Key of this (seed, pixel, sample): the hash sampler's numbers.
    key: u64,
    /// Key of this (seed, pixel): the Sobol scrambles, shared by the
    /// pixel's samples so that they stratify.
    pixel_key: u64,
    sample: u32,
    dimension: u32,
    sobol: bool,
    /// The Sobol set last computed (`u32::MAX`: none) and its four values:
    /// one `sample_4d` call (SIMD) serves four draws.
    cached_set: u32,
    cached: [f32; 4],
    /// A second cached set, kept by [`Sampler::set_of_four_kept`] apart
    /// from the one above, for a set read at several path vertices.
    kept_set: u32,
    kept: [f32; 4],
}

/// A path's kept Sobol set ([`Sampler::kept`]) between two vertices
/// shaded by different passes of a wavefront stage: written by the pass
/// that shades the path's vertex (at most one per path per pass, so the
/// relaxed atomics never race) and read by the next bounce's pass, after
/// the stage boundary. Saves the second vertex of a direction pair
/// ([`crate::transport::path::direction_numbers`]) a Sobol set.
#[derive(Debug, Default)]
pub struct KeptSlot([AtomicU32; 5]);

impl KeptSlot {
    /// The kept set, or none (`u32::MAX`) after [`KeptSlot::clear`].
    #[inline]
    pub fn load(&self) -> (u32, [f32; 4]) {
        let v = |k: usize| f32::from_bits(self.0[k + 1].load(Ordering::Relaxed));
        (self.0[0].load(Ordering::Relaxed), [v(0), v(1), v(2), v(3)])
    }

    /// The kept set's number, or `u32::MAX` for none.
    #[inline]
    pub fn set(&self) -> u32 {
        self.0[0].load(Ordering::Relaxed)
    }

    /// Holds `kept` for the path's next vertex.
    #[inline]
    pub fn store(&self, (set, values): (u32, [f32; 4])) {
        self.0[0].store(set, Ordering::Relaxed);
        for (slot, v) in self.0[1..].iter().zip(values) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
    }

    /// Holds no set: a new path starts here.
    #[inline]
    pub fn clear(&self) {
        self.0[0].store(u32::MAX, Ordering::Relaxed);
    }
}

/// The hashed keys of one pixel sample's [`Sampler`], computed once: a
/// stage that draws numbers for the same path at every bounce keeps the
/// seed and makes the sampler from it without hashing the keys again
/// ([`SamplerSeed::sampler`] is [`Sampler::with_kind`] of the same
/// arguments).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SamplerSeed {
    key: u64,
    pixel_key: u64,
    sample: u32,
    sobol: bool,
}

impl SamplerSeed {
    /// The seed of the sampler of `kind` for sample `sample` of pixel
    /// `pixel` under `seed`.
    #[inline]
    pub fn new(kind: SamplerKind, seed: u64, pixel: u32, sample: u32) -> Self {
        Self {
            key: mix64(seed ^ mix64(((pixel as u64) << 32) | sample as u64)),
            pixel_key: mix64(seed.rotate_left(17) ^ mix64(pixel as u64 ^ 0x5bd1_e995_0000_0000)),
            sample,
            sobol: kind == SamplerKind::Sobol && sample < SOBOL_SAMPLES,
        }
    }

    /// The seed of [`Sampler::split`]`(j, k)` of this seed's sampler.
    #[inline]
    pub fn split(&self, j: u32, k: u32) -> Self {
        let sample = self.sample.wrapping_mul(k).wrapping_add(j);
        Self {
            key: split_key(self.key, j, k),
            pixel_key: self.pixel_key,
            sample,
            sobol: self.sobol && sample < SOBOL_SAMPLES,
        }
    }

    /// What [`sobol_sets`] needs to draw Sobol set `set` (dimensions
    /// `4 set .. 4 set + 4`) of this seed's sampler, or `None` when the
    /// sampler's numbers are not Sobol's (the hash sampler, or a sample
    /// beyond the sequence).
    #[inline]
    pub fn sobol_request(&self, set: u32) -> Option<SetRequest> {
        self.sobol.then(|| SetRequest {
            sample: self.sample,
            seed: Sampler::set_seed(self.pixel_key, set),
        })
    }

    /// A sampler at dimension 0.
    #[inline]
    pub fn sampler(&self) -> Sampler {
        Sampler {
            key: self.key,
            pixel_key: self.pixel_key,
            sample: self.sample,
            dimension: 0,
            sobol: self.sobol,
            cached_set: u32::MAX,
            cached: [0.0; 4],
            kept_set: u32::MAX,
            kept: [0.0; 4],
        }
    }
}

/// The first four Sobol dimensions of every 16-bit (bit-reversed) index,
/// as two tables of 256 entries: entry `b` of the first half holds the
/// XOR of the direction vectors of the set bits of `b << 24`, of the
/// second half those of `b << 16`. The Sobol matrix is linear over bits,
/// so an index's point is one entry of each half XORed: two loads instead
/// of a loop over the index's set bits (`sobol_burley::parts::sobol_int4_rev`,
/// about eight passes for a shuffled index).
static SOBOL_BYTES: std::sync::LazyLock<Box<[[u32; 4]; 512]>> = std::sync::LazyLock::new(|| {
    let mut t = Box::new([[0u32; 4]; 512]);
    for b in 0..256u32 {
        t[b as usize] = sobol_burley::parts::sobol_int4_rev(b << 24, 0).into();
        t[256 + b as usize] = sobol_burley::parts::sobol_int4_rev(b << 16, 0).into();
    }
    t
});

/// `sobol_burley::sample_4d(sample, 0, seed)`, bit for bit (tested): on
/// CPUs with AVX2 by [`sobol_set_avx2`], else by [`sobol_set_portable`].
#[inline(always)]
fn sobol_set(sample: u32, seed: u32) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    if crate::core::simd::use_avx2() {
        // SAFETY: `use_avx2` holds only on CPUs with AVX2 and FMA
        // (`simd::active` checks them at run time).
        #[allow(unsafe_code)]
        return unsafe { sobol_set_avx2(sample, seed) };
    }
    sobol_set_portable(sample, seed)
}

/// The index shuffle of [`sobol_set`] (a seeded Owen scramble of the
/// reversed index) and the two [`SOBOL_BYTES`] entries it selects.
#[inline(always)]
fn sobol_rows(sample: u32, seed: u32) -> ([u32; 4], [u32; 4]) {
    table_rows(shuffled_index(sample, seed))
}

/// The index shuffle of [`sobol_set`]: a seeded Owen scramble of the
/// reversed index, of which only the top 16 bits select the point.
#[inline(always)]
fn shuffled_index(sample: u32, seed: u32) -> u32 {
    use sobol_burley::parts::{hash, owen_scramble_rev};
    debug_assert!(sample < SOBOL_SAMPLES);
    owen_scramble_rev(sample.reverse_bits(), hash(seed ^ 0x79c6_8e4a)) >> 16
}

/// The two [`SOBOL_BYTES`] entries of a shuffled index.
#[inline(always)]
fn table_rows(shuffled: u32) -> ([u32; 4], [u32; 4]) {
    let t = &**SOBOL_BYTES;
    (
        t[(shuffled >> 8) as usize],
        t[256 + (shuffled & 0xff) as usize],
    )
}

/// The per-dimension output scramble seeds of dimension set 0 (before
/// hashing), as `sobol_burley::sample_4d` makes them.
#[inline(always)]
fn scramble_seeds(seed: u32) -> [u32; 4] {
    let s = seed.wrapping_mul(0x9c8f_2d3b);
    [
        s ^ 0x912f_69ba,
        s ^ 0x174f_18ab,
        s ^ 0x691e_72ca,
        s ^ 0xb40c_c1b8,
    ]
}

/// [`sobol_set`] with SSE4.1's 32-bit lane multiply (under AVX2) and a
/// byte-shuffle bit reversal. The crate's 4-lane type is compiled for
/// plain x86-64, where each of the scramble's six lane multiplies is
/// emulated by two 64-bit multiplies and four shuffles and masks, and the
/// bit reversal takes five shift-and-mask rounds: on the path-traced
/// `assets/gltf/cornell.gltf` those made drawing the numbers 10% of all
/// instructions (callgrind). The same integer operations in the same
/// order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn sobol_set_avx2(sample: u32, seed: u32) -> [f32; 4] {
    use std::arch::x86_64::*;
    let (hi, lo) = sobol_rows(sample, seed);
    let u = |v: [u32; 4]| _mm_set_epi32(v[3] as i32, v[2] as i32, v[1] as i32, v[0] as i32);
    let k = |c: u32| _mm_set1_epi32(c as i32);
    let sobol = _mm_xor_si128(u(hi), u(lo));
    // `hash_int4` of the scramble seeds.
    let mut h = _mm_xor_si128(u(scramble_seeds(seed)), k(0xe6fe_3beb));
    h = _mm_xor_si128(h, _mm_srli_epi32::<16>(h));
    h = _mm_mullo_epi32(h, k(0x7feb_352d));
    h = _mm_xor_si128(h, _mm_srli_epi32::<15>(h));
    h = _mm_mullo_epi32(h, k(0x846c_a68b));
    h = _mm_xor_si128(h, _mm_srli_epi32::<16>(h));
    // `owen_scramble_int4_rev(sobol, h)`.
    let mut n = sobol;
    n = _mm_xor_si128(n, _mm_mullo_epi32(n, k(0x3d20_adea)));
    n = _mm_add_epi32(n, h);
    n = _mm_mullo_epi32(n, _mm_or_si128(_mm_srli_epi32::<16>(h), k(1)));
    n = _mm_xor_si128(n, _mm_mullo_epi32(n, k(0x0552_6c56)));
    n = _mm_xor_si128(n, _mm_mullo_epi32(n, k(0x53a2_2864)));
    // Bit reversal: each byte's bits by two nibble lookups, then the bytes
    // of each lane in reverse order.
    let rev_nibble = _mm_setr_epi8(0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15);
    let low = _mm_and_si128(n, k(0x0f0f_0f0f));
    let high = _mm_and_si128(_mm_srli_epi32::<4>(n), k(0x0f0f_0f0f));
    let bytes = _mm_or_si128(
        _mm_slli_epi32::<4>(_mm_shuffle_epi8(rev_nibble, low)),
        _mm_shuffle_epi8(rev_nibble, high),
    );
    let rev = _mm_shuffle_epi8(
        bytes,
        _mm_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12),
    );
    // `to_f32_norm`: the top 23 bits as the mantissa of [1, 2), minus 1.
    let f = _mm_sub_ps(
        _mm_castsi128_ps(_mm_or_si128(_mm_srli_epi32::<9>(rev), k(0x3f80_0000))),
        _mm_set1_ps(1.0),
    );
    let mut out = [0.0f32; 4];
    // SAFETY: `out` has room for the four lanes (unaligned store).
    #[allow(unsafe_code)]
    unsafe {
        _mm_storeu_ps(out.as_mut_ptr(), f)
    };
    out
}

/// [`sobol_set`] through the crate's public parts, with the Sobol matrix
/// applied by [`SOBOL_BYTES`].
#[inline(always)]
fn sobol_set_portable(sample: u32, seed: u32) -> [f32; 4] {
    use sobol_burley::parts::{Int4, hash_int4, owen_scramble_int4_rev};
    let (hi, lo) = sobol_rows(sample, seed);
    let sobol: Int4 = std::array::from_fn::<u32, 4, _>(|k| hi[k] ^ lo[k]).into();
    // The per-dimension output scramble of dimension set 0.
    let scramble: Int4 = scramble_seeds(seed).into();
    owen_scramble_int4_rev(sobol, hash_int4(scramble))
        .reverse_bits()
        .to_f32_norm()
}

/// Sobol sets drawn side by side by [`sobol_sets`]: one AVX-512
/// register of `u32` per quantity (two AVX2 ones, four SSE ones).
pub const SET_LANES: usize = 16;

/// One Sobol set to draw with [`sobol_sets`]: the pixel sample's index
/// and the set's scramble seed ([`SamplerSeed::sobol_request`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SetRequest {
    sample: u32,
    seed: u32,
}

/// The sets of `requests` (the four numbers that [`Sampler::set_of_four`]
/// gives for each), sixteen at a time side by side: the integer
/// operations of `sobol_set` lane by lane, so the same bits (tested on
/// every SIMD path). For a stage that has many paths' draws at hand (the
/// wavefront's shading): one call costs a fraction of a set drawn alone,
/// whose index shuffle is scalar and whose dimensions fill one 4-lane
/// register. `out` must be as long as `requests`.
pub fn sobol_sets(requests: &[SetRequest], out: &mut [[f32; 4]]) {
    assert_eq!(requests.len(), out.len(), "one output per request");
    #[cfg(target_arch = "x86_64")]
    {
        if crate::core::simd::use_avx512() {
            // SAFETY: `use_avx512` holds only on CPUs with AVX-512F, AVX2
            // and FMA (`simd::supported`).
            #[allow(unsafe_code)]
            return unsafe { sobol_sets_avx512(requests, out) };
        }
        if crate::core::simd::use_avx2() {
            // SAFETY: `use_avx2` holds only on CPUs with AVX2 and FMA.
            #[allow(unsafe_code)]
            return unsafe { sobol_sets_avx2(requests, out) };
        }
    }
    sobol_sets_with(requests, out)
}

/// [`sobol_sets`] compiled for AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn sobol_sets_avx512(requests: &[SetRequest], out: &mut [[f32; 4]]) {
    sobol_sets_with(requests, out)
}

/// [`sobol_sets`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn sobol_sets_avx2(requests: &[SetRequest], out: &mut [[f32; 4]]) {
    sobol_sets_with(requests, out)
}

/// [`sobol_sets`]'s body, inlined into each of its code paths: full
/// groups of [`SET_LANES`], then the rest padded with copies of the last
/// request.
#[inline(always)]
fn sobol_sets_with(requests: &[SetRequest], out: &mut [[f32; 4]]) {
    for (req, out) in requests.chunks(SET_LANES).zip(out.chunks_mut(SET_LANES)) {
        let lane = |l: usize| req[l.min(req.len() - 1)];
        let sample: [u32; SET_LANES] = std::array::from_fn(|l| lane(l).sample);
        let seed: [u32; SET_LANES] = std::array::from_fn(|l| lane(l).seed);
        // Dimension by dimension (one register each), then lane by lane:
        // writing each lane's four numbers in the lane loops had made the
        // compiler scatter them.
        let dims = sobol_set_lanes(&sample, &seed);
        for (l, o) in out.iter_mut().enumerate() {
            *o = [dims[0][l], dims[1][l], dims[2][l], dims[3][l]];
        }
    }
}

/// [`sobol_set`] of `SET_LANES` (sample, seed) pairs, in loops over the
/// lanes that the compiler widens: the index shuffle, the two table rows
/// ([`sobol_rows`]'s), the per-dimension scramble and the conversion,
/// each for every lane.
/// Dimension-major: `[k][l]` is dimension `k` of lane `l`.
#[inline(always)]
fn sobol_set_lanes(sample: &[u32; SET_LANES], seed: &[u32; SET_LANES]) -> [[f32; SET_LANES]; 4] {
    use sobol_burley::parts::{hash, owen_scramble_rev};
    // The shuffles in a loop of their own: with the table look-ups in the
    // same loop they were widened less (sets 1.2x the time).
    let shuffled: [u32; SET_LANES] = std::array::from_fn(|l| shuffled_index(sample[l], seed[l]));
    let mut sobol = [[0u32; SET_LANES]; 4];
    for l in 0..SET_LANES {
        let (hi, lo) = table_rows(shuffled[l]);
        for k in 0..4 {
            sobol[k][l] = hi[k] ^ lo[k];
        }
    }
    let mut out = [[0.0f32; SET_LANES]; 4];
    for (k, (dim, out)) in sobol.iter().zip(&mut out).enumerate() {
        for l in 0..SET_LANES {
            let scramble = hash(scramble_seeds(seed[l])[k]);
            let n = owen_scramble_rev(dim[l], scramble).reverse_bits();
            out[l] = f32::from_bits((n >> 9) | 0x3f80_0000) - 1.0;
        }
    }
    out
}

/// The hash key of part `j` of `k` of the path whose key is `key`.
#[inline]
fn split_key(key: u64, j: u32, k: u32) -> u64 {
    mix64(key ^ mix64(SPLIT_SALT ^ (((k as u64) << 32) | j as u64)))
}

/// A 64-bit finaliser (the "splitmix64" mixing function).
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Sampler {
    /// The hash sampler for sample `sample` of pixel `pixel` under `seed`
    /// (the same as [`Sampler::with_kind`] with [`SamplerKind::Hash`]).
    #[inline]
    pub fn new(seed: u64, pixel: u32, sample: u32) -> Self {
        Self::with_kind(SamplerKind::Hash, seed, pixel, sample)
    }

    /// The sampler of `kind` for sample `sample` of pixel `pixel` under
    /// `seed`.
    #[inline]
    pub fn with_kind(kind: SamplerKind, seed: u64, pixel: u32, sample: u32) -> Self {
        SamplerSeed::new(kind, seed, pixel, sample).sampler()
    }

    /// Another sampler for the same pixel sample, keyed by `salt`: its
    /// numbers are a pure function of (kind, seed, pixel, sample, salt,
    /// dimension), independent of this one's, and the Sobol sampler's
    /// still stratify across the pixel's samples.
    #[inline]
    pub fn fork(&self, salt: u64) -> Sampler {
        Sampler {
            key: mix64(self.key ^ salt),
            pixel_key: mix64(self.pixel_key ^ salt),
            sample: self.sample,
            dimension: 0,
            sobol: self.sobol,
            cached_set: u32::MAX,
            cached: [0.0; 4],
            kept_set: u32::MAX,
            kept: [0.0; 4],
        }
    }

    /// The sampler of part `j` of `k` into which a path is split
    /// ([`crate::core::settings::RenderSettings::split`]): the numbers of
    /// sample `sample * k + j` of the same pixel, so that the `spp * k`
    /// parts of a pixel stratify together as that many Sobol samples do;
    /// the hash sampler's keyed by (seed, pixel, sample, `j`, `k`). A pure
    /// function of those, like every sampler.
    #[inline]
    pub fn split(&self, j: u32, k: u32) -> Sampler {
        let sample = self.sample.wrapping_mul(k).wrapping_add(j);
        Sampler {
            key: split_key(self.key, j, k),
            pixel_key: self.pixel_key,
            sample,
            dimension: 0,
            sobol: self.sobol && sample < SOBOL_SAMPLES,
            cached_set: u32::MAX,
            cached: [0.0; 4],
            kept_set: u32::MAX,
            kept: [0.0; 4],
        }
    }

    /// Jumps to dimension `d` (integrators give each bounce a fixed
    /// range, aligned to sets of four).
    #[inline]
    pub fn set_dimension(&mut self, d: u32) {
        self.dimension = d;
    }

    /// The four numbers of dimensions `d .. d + 4` (`d` a multiple of four:
    /// one Sobol set), then continues at `d + 4`: the numbers that four
    /// calls of [`Sampler::next_f32`] from `d` give, drawn at once (one
    /// call instead of four in the path kernels' hot loop).
    #[inline]
    pub fn set_of_four(&mut self, d: u32) -> [f32; 4] {
        debug_assert_eq!(d % 4, 0, "sets of four start at multiples of four");
        self.dimension = d.wrapping_add(4);
        if self.sobol {
            let set = d / 4;
            self.cache_set(set);
            return self.cached;
        }
        std::array::from_fn(|k| self.hashed(d.wrapping_add(k as u32)))
    }

    /// The four numbers of dimensions `d .. d + 4` (`d` a multiple of four),
    /// as [`Sampler::set_of_four`] gives them, but cached in a slot of
    /// their own that the other draws do not replace: for a set read at
    /// several vertices of a path (the BSDF directions of two consecutive
    /// bounces, see [`crate::transport::path::direction_numbers`]) while
    /// other sets are drawn in between. Leaves the current dimension as it
    /// was.
    #[inline]
    pub fn set_of_four_kept(&mut self, d: u32) -> [f32; 4] {
        debug_assert_eq!(d % 4, 0, "sets of four start at multiples of four");
        if self.sobol {
            let set = d / 4;
            if set != self.kept_set {
                self.kept = sobol_set(self.sample, Self::set_seed(self.pixel_key, set));
                self.kept_set = set;
            }
            return self.kept;
        }
        std::array::from_fn(|k| self.hashed(d.wrapping_add(k as u32)))
    }

    /// The kept set (see [`Sampler::set_of_four_kept`]): its set number
    /// (`u32::MAX`: none) and its four numbers, for a stage that makes
    /// the path's sampler anew at every vertex to hand on
    /// ([`KeptSlot`]).
    #[inline]
    pub fn kept(&self) -> (u32, [f32; 4]) {
        (self.kept_set, self.kept)
    }

    /// Restores a kept set that [`Sampler::kept`] gave at an earlier
    /// vertex of the same path (the same seed, pixel and sample, so the
    /// same numbers `set_of_four_kept` would compute again).
    #[inline]
    pub fn restore_kept(&mut self, (set, values): (u32, [f32; 4])) {
        self.kept_set = set;
        self.kept = values;
    }

    /// Makes `values`, Sobol set `set` of this sampler drawn elsewhere
    /// ([`sobol_sets`] of its [`SamplerSeed::sobol_request`]), the cached
    /// set, so that the next draw from it computes nothing. Moves neither
    /// the dimension nor the kept set.
    #[inline]
    pub fn prime(&mut self, (set, values): (u32, [f32; 4])) {
        debug_assert!(self.sobol);
        self.cached_set = set;
        self.cached = values;
    }

    /// The two numbers of dimensions `d` and `d + 1` (`d` even), then
    /// continues at `d + 2`: what two calls of [`Sampler::next_f32`] from
    /// `d` give, bit for bit, with one look-up of their Sobol set. Always
    /// inlined: the camera-ray stage of the wavefront called
    /// [`Sampler::next_f32`] out of line twice per ray for its film
    /// position (callgrind: 123 instructions per call).
    #[inline(always)]
    pub fn pair(&mut self, d: u32) -> [f32; 2] {
        debug_assert_eq!(d % 2, 0, "pairs start at even dimensions");
        self.dimension = d.wrapping_add(2);
        if self.sobol {
            self.cache_set(d / 4);
            let k = (d % 4) as usize;
            return [self.cached[k], self.cached[k + 1]];
        }
        [self.hashed(d), self.hashed(d.wrapping_add(1))]
    }

    /// Makes Sobol set `set` the cached one (each set has its own scramble
    /// and index shuffle: Burley's padding).
    #[inline(always)]
    fn cache_set(&mut self, set: u32) {
        if set != self.cached_set {
            self.cached = sobol_set(self.sample, Self::set_seed(self.pixel_key, set));
            self.cached_set = set;
        }
    }

    /// The scramble seed of Sobol set `set` of a pixel.
    #[inline(always)]
    fn set_seed(pixel_key: u64, set: u32) -> u32 {
        (mix64(pixel_key ^ set as u64) >> 32) as u32
    }

    /// The hash sampler's number for dimension `d`.
    #[inline]
    fn hashed(&self, d: u32) -> f32 {
        let bits = mix64(self.key ^ mix64(d as u64 + 0x9e37_79b9_7f4a_7c15));
        // 24 random mantissa bits: exactly representable, strictly below 1.
        (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// The number for the current dimension in `[0, 1)`, then advances.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        let d = self.dimension;
        self.dimension += 1;
        if self.sobol {
            // Dimension d is component d % 4 of the set d / 4; each set has
            // its own scramble and index shuffle (Burley's padding).
            let set = d / 4;
            self.cache_set(set);
            return self.cached[(d % 4) as usize];
        }
        self.hashed(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pair(d)` draws what two `next_f32` calls from `d` draw, bit for
    /// bit, for both kinds, from a fresh sampler and from one whose cached
    /// Sobol set is another (d = 0 after d = 4 ...), and leaves the sampler
    /// at `d + 2` as they do.
    #[test]
    fn a_pair_is_two_draws() {
        for kind in [SamplerKind::Sobol, SamplerKind::Hash] {
            for (pixel, sample) in [(0u32, 0u32), (917, 3), (123_456, 70_000)] {
                let seed = SamplerSeed::new(kind, 11, pixel, sample);
                let mut warm = seed.sampler();
                for d in [0u32, 2, 4, 6, 10, 2, 0, 30, 8] {
                    let mut by_draws = seed.sampler();
                    by_draws.set_dimension(d);
                    let draws = [by_draws.next_f32(), by_draws.next_f32()];
                    let mut fresh = seed.sampler();
                    let pair = fresh.pair(d);
                    let again = warm.pair(d);
                    let bits = |v: [f32; 2]| v.map(f32::to_bits);
                    let at = format!("{kind:?} pixel {pixel} sample {sample} d {d}");
                    assert_eq!(bits(pair), bits(draws), "{at}");
                    assert_eq!(bits(again), bits(draws), "{at}, warm sampler");
                    assert_eq!(
                        fresh.next_f32().to_bits(),
                        by_draws.next_f32().to_bits(),
                        "{at}"
                    );
                }
            }
        }
    }

    /// The table-driven Sobol set is the crate's `sample_4d` bit for bit,
    /// by both of its paths (the AVX2 one where the CPU has it): every
    /// index of the sequence under a few seeds, and random seeds.
    #[test]
    fn sobol_set_is_the_crates_sample_4d() {
        #[cfg(target_arch = "x86_64")]
        let avx2 = crate::core::simd::supported(crate::core::simd::Isa::Avx2);
        let mut seeds = vec![0u32, 1, 0x79c6_8e4a, u32::MAX];
        let mut z = 3u64;
        for _ in 0..64 {
            z = mix64(z);
            seeds.push(z as u32);
        }
        for (k, &seed) in seeds.iter().enumerate() {
            let step = if k < 4 { 1 } else { 97 };
            for sample in (0..SOBOL_SAMPLES).step_by(step) {
                let theirs = sobol_burley::sample_4d(sample, 0, seed).map(f32::to_bits);
                let ours = sobol_set_portable(sample, seed).map(f32::to_bits);
                assert_eq!(ours, theirs, "portable: sample {sample}, seed {seed:#x}");
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: the CPU has AVX2 and FMA (checked above).
                    #[allow(unsafe_code)]
                    let ours = unsafe { sobol_set_avx2(sample, seed) }.map(f32::to_bits);
                    assert_eq!(ours, theirs, "avx2: sample {sample}, seed {seed:#x}");
                }
            }
        }
    }

    /// The sets drawn sixteen at a time ([`sobol_sets`]) are those drawn
    /// one at a time, bit for bit, on every SIMD path the CPU has, in
    /// full groups and in a partial one, and priming a sampler with one
    /// gives the draws it would have made.
    #[test]
    fn sets_drawn_side_by_side_are_the_sets_drawn_alone() {
        let mut z = 11u64;
        let seeds: Vec<SamplerSeed> = (0..53u32)
            .map(|k| {
                z = mix64(z);
                SamplerSeed::new(
                    SamplerKind::Sobol,
                    z,
                    z as u32 >> 7,
                    (z >> 40) as u32 % 4096 + k,
                )
            })
            .collect();
        let sets: Vec<u32> = (0..53u32).map(|k| k * 0x0100_0193 % 0x0900_0000).collect();
        let requests: Vec<SetRequest> = seeds
            .iter()
            .zip(&sets)
            .map(|(s, &set)| s.sobol_request(set).expect("Sobol"))
            .collect();
        let alone: Vec<[u32; 4]> = seeds
            .iter()
            .zip(&sets)
            .map(|(s, &set)| s.sampler().set_of_four(4 * set).map(f32::to_bits))
            .collect();
        type Path = fn(&[SetRequest], &mut [[f32; 4]]);
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))]
        let mut paths: Vec<(&str, Path)> = vec![("portable", sobol_sets_with)];
        #[cfg(target_arch = "x86_64")]
        {
            use crate::core::simd::{Isa, supported};
            if supported(Isa::Avx2) {
                // SAFETY: only called where the CPU has AVX2 and FMA.
                #[allow(unsafe_code)]
                paths.push(("avx2", |r, o| unsafe { sobol_sets_avx2(r, o) }));
            }
            if supported(Isa::Avx512) {
                // SAFETY: only called where the CPU has AVX-512F.
                #[allow(unsafe_code)]
                paths.push(("avx512", |r, o| unsafe { sobol_sets_avx512(r, o) }));
            }
        }
        for (name, path) in paths {
            for n in [53, 16, 7] {
                let mut out = vec![[0.0f32; 4]; n];
                path(&requests[..n], &mut out);
                for (k, o) in out.iter().enumerate() {
                    assert_eq!(o.map(f32::to_bits), alone[k], "{name}: request {k} of {n}");
                }
            }
        }
        let mut out = vec![[0.0f32; 4]; 53];
        sobol_sets(&requests, &mut out);
        for k in 0..53 {
            let mut primed = seeds[k].sampler();
            primed.prime((sets[k], out[k]));
            let mut fresh = seeds[k].sampler();
            for d in 4 * sets[k]..4 * sets[k] + 4 {
                primed.set_dimension(d);
                fresh.set_dimension(d);
                assert_eq!(primed.next_f32().to_bits(), fresh.next_f32().to_bits());
            }
        }
        assert!(
            SamplerSeed::new(SamplerKind::Hash, 1, 2, 3)
                .sobol_request(0)
                .is_none()
        );
    }

    /// The Sobol sampler's 64 samples of one pixel put exactly one point
    /// in each cell of an 8x8 grid over the pair of dimensions (4k, 4k+1)
    /// (the (0, 2)-sequence property, kept by Owen scrambling), and at
    /// least one point per 4x4 cell of every other pair of its set; the
    /// hash sampler does not (it fails with near certainty: the chance
    /// that 64 independent points fill all 64 cells is 64!/64^64).
    #[test]
    fn sobol_samples_of_a_pixel_are_stratified() {
        for (pixel, set) in [(0u32, 0u32), (12345, 3), (7, 40)] {
            let points = |kind| {
                (0..64)
                    .map(|s| {
                        let mut x = Sampler::with_kind(kind, 9, pixel, s);
                        x.set_dimension(4 * set);
                        [x.next_f32(), x.next_f32(), x.next_f32(), x.next_f32()]
                    })
                    .collect::<Vec<_>>()
            };
            let cells = |p: &[[f32; 4]], a: usize, b: usize, n: usize| {
                let mut count = vec![0u32; n * n];
                for q in p {
                    let (i, j) = ((q[a] * n as f32) as usize, (q[b] * n as f32) as usize);
                    count[i * n + j] += 1;
                }
                count
            };
            let sobol = points(SamplerKind::Sobol);
            assert!(
                cells(&sobol, 0, 1, 8).iter().all(|&c| c == 1),
                "pixel {pixel} set {set}"
            );
            for (a, b) in [(0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
                assert!(cells(&sobol, a, b, 4).iter().all(|&c| c >= 1), "{a} {b}");
            }
            let hash = points(SamplerKind::Hash);
            assert!(cells(&hash, 0, 1, 8).iter().any(|&c| c != 1));
        }
    }

    /// A set of four drawn at once is the four numbers drawn one by one,
    /// for both kinds, beyond the Sobol limit (hash fallback) and at the
    /// wavelength's far dimension, and the next number follows the set.
    #[test]
    fn a_set_of_four_is_four_single_draws() {
        for kind in [SamplerKind::Sobol, SamplerKind::Hash] {
            for (sample, d) in [
                (0u32, 0u32),
                (3, 4),
                (70_000, 8),
                (5, 0xFFFF_FFF0),
                (9, 400),
            ] {
                let mut one = Sampler::with_kind(kind, 11, 77, sample);
                one.set_dimension(d);
                let singles: [f32; 5] = std::array::from_fn(|_| one.next_f32());
                let mut four = Sampler::with_kind(kind, 11, 77, sample);
                assert_eq!(four.set_of_four(d), singles[..4], "{kind:?} {sample} {d}");
                assert_eq!(four.next_f32(), singles[4], "{kind:?} {sample} {d}");
            }
        }
    }

    /// The kept set is the set `set_of_four` gives, bit for bit, wherever
    /// the sampler stands and whatever it cached; it moves neither the
    /// current dimension nor the other cache.
    #[test]
    fn a_kept_set_is_the_set_of_four() {
        for kind in [SamplerKind::Sobol, SamplerKind::Hash] {
            for (sample, d) in [(0u32, 0u32), (3, 4), (70_000, 8), (9, 0x2000_0010)] {
                let expected = Sampler::with_kind(kind, 11, 77, sample).set_of_four(d);
                let next = Sampler::with_kind(kind, 11, 77, sample).set_of_four(d + 4);
                let mut s = Sampler::with_kind(kind, 11, 77, sample);
                let _ = s.set_of_four(12);
                let after = s.next_f32();
                let mut s = Sampler::with_kind(kind, 11, 77, sample);
                let _ = s.set_of_four(12);
                assert_eq!(s.set_of_four_kept(d), expected, "{kind:?} {sample} {d}");
                assert_eq!(s.set_of_four_kept(d + 4), next, "{kind:?} {sample} {d}");
                assert_eq!(s.set_of_four_kept(d), expected, "{kind:?} {sample} {d}");
                assert_eq!(s.next_f32(), after, "{kind:?} {sample} {d}");
            }
        }
    }

    #[test]
    fn deterministic_and_in_range() {
        for kind in [SamplerKind::Sobol, SamplerKind::Hash] {
            let mut a = Sampler::with_kind(kind, 7, 123, 4);
            let mut b = Sampler::with_kind(kind, 7, 123, 4);
            for _ in 0..100 {
                let x = a.next_f32();
                assert_eq!(x, b.next_f32());
                assert!((0.0..1.0).contains(&x));
            }
        }
    }

    #[test]
    fn keys_give_different_streams_and_a_uniform_mean() {
        let mut sum = 0.0f64;
        let n = 100_000;
        for i in 0..n {
            sum += Sampler::new(1, i, 0).next_f32() as f64;
        }
        // Mean of U(0,1): 0.5 with standard error sqrt(1/12/n) = 9.1e-4; 5 sigma.
        assert!((sum / n as f64 - 0.5).abs() < 5.0 * 9.2e-4);
        assert_ne!(
            Sampler::new(1, 2, 3).next_f32(),
            Sampler::new(2, 2, 3).next_f32()
        );
        assert_ne!(
            Sampler::new(1, 2, 3).next_f32(),
            Sampler::new(1, 2, 4).next_f32()
        );
    }

    /// Part `j` of `k` of a Sobol path draws exactly the numbers of
    /// sample `s k + j` of the same pixel (so a pixel's `spp k` parts
    /// stratify as that many samples), beyond Sobol's last sample the
    /// hash numbers; the hash sampler's parts differ from each other and
    /// from the path's own numbers, each a pure function of its keys.
    #[test]
    fn split_parts_are_the_later_samples_of_the_pixel() {
        for (s, k) in [(0u32, 2u32), (5, 2), (7, 3), (100, 64)] {
            let parent = Sampler::with_kind(SamplerKind::Sobol, 9, 1234, s);
            for j in 0..k {
                let mut part = parent.split(j, k);
                let mut direct = Sampler::with_kind(SamplerKind::Sobol, 9, 1234, s * k + j);
                for d in [0u32, 4, 8, 0x2000_0000] {
                    assert_eq!(
                        part.set_of_four(d),
                        direct.set_of_four(d),
                        "{s} {j}/{k} {d}"
                    );
                }
            }
        }
        let last = Sampler::with_kind(SamplerKind::Sobol, 9, 1234, SOBOL_SAMPLES / 2);
        assert!(!last.split(0, 2).sobol && last.split(0, 2).set_of_four(0)[0] < 1.0);
        let parent = Sampler::with_kind(SamplerKind::Hash, 9, 1234, 5);
        let draws: Vec<[f32; 4]> = (0..4)
            .map(|j| parent.split(j, 4).set_of_four(8))
            .chain([{
                let mut own = parent;
                own.set_of_four(8)
            }])
            .collect();
        for a in 0..draws.len() {
            for b in 0..a {
                assert_ne!(draws[a], draws[b], "{a} {b}");
            }
        }
        assert_eq!(parent.split(2, 4).set_of_four(8), draws[2]);
    }
}
