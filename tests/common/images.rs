//! Comparing films.

use prism::image::film::Film;

/// Asserts the same size and every channel of every pixel within 1e-6
/// absolute or 1e-4 relative.
pub fn assert_same_image(a: &Film, b: &Film, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        for (x, y) in p.to_array().into_iter().zip(q.to_array()) {
            let diff = (x - y).abs();
            assert!(
                diff <= 1e-6 || diff <= 1e-4 * x.abs().max(y.abs()),
                "{what}: pixel {i} differs: {p} vs {q}"
            );
        }
    }
}

/// The bits of every channel of every pixel, for bit-for-bit comparisons.
pub fn film_bits(f: &Film) -> Vec<u32> {
    f.pixels
        .iter()
        .flat_map(|p| p.to_array().map(f32::to_bits))
        .collect()
}
