//! Image error metrics: how far a render is from a reference.
//!
//! All metrics compare a *test* image against a *reference* image of the
//! same size, both linear RGB radiance ([`Film`]):
//!
//! * [`rmse`]: root mean squared error over every pixel and channel, in
//!   radiance units.
//! * [`rel_mse`]: relative mean squared error, the mean over pixels and
//!   channels of `(v - ref)^2 / (ref^2 + 0.01)`. Dividing by the reference
//!   makes dark and bright regions count alike; the `0.01` keeps black
//!   reference pixels from dividing by zero.
//! * [`flip`]: the mean of NVIDIA's FLIP perceptual error map (LDR-FLIP,
//!   through the `nv-flip` crate), between 0 (identical) and 1. FLIP works
//!   on displayed 8-bit images, so both films are first mapped exactly as
//!   `prism render` writes a PNG with the given [`PngOptions`] (exposure,
//!   tone map, sRGB).
//!
//! Inputs are checked first: mismatched sizes, empty images, pixel buffers
//! of the wrong length and non-finite values are errors, never panics.

use std::path::Path;

use crate::core::error::{Error, Result};
use crate::image::film::Film;
use crate::image::output::{OutputFormat, PngOptions, to_srgb8};

/// The constant in the denominator of [`rel_mse`].
pub const REL_MSE_EPSILON: f64 = 0.01;

/// Every metric for one test image against one reference.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Metrics {
    /// Root mean squared error (radiance units).
    pub rmse: f64,
    /// Relative mean squared error, see [`rel_mse`].
    pub rel_mse: f64,
    /// Mean LDR-FLIP error in `[0, 1]`, see [`flip`].
    pub flip: f64,
}

impl Metrics {
    /// Names of the metrics, in the order of [`Metrics::values`].
    pub const NAMES: [&'static str; 3] = ["rmse", "rel_mse", "flip"];

    /// The metrics in the order of [`Metrics::NAMES`].
    pub fn values(&self) -> [f64; 3] {
        [self.rmse, self.rel_mse, self.flip]
    }
}

/// Checks that `film` is usable: at least 1x1, a pixel buffer of
/// `width * height` entries, and only finite values. `what` names the
/// image in the message.
pub fn check_film(film: &Film, what: &str) -> Result<()> {
    if film.width == 0 || film.height == 0 {
        return Err(Error::Invalid(format!(
            "{what} is empty ({}x{})",
            film.width, film.height
        )));
    }
    let expected = film.width as usize * film.height as usize;
    if film.pixels.len() != expected {
        return Err(Error::Invalid(format!(
            "{what} is {}x{} but holds {} pixels instead of {expected}",
            film.width,
            film.height,
            film.pixels.len()
        )));
    }
    if let Some(i) = film.pixels.iter().position(|p| !p.is_finite()) {
        let (x, y) = (i % film.width as usize, i / film.width as usize);
        return Err(Error::Invalid(format!(
            "{what} has a non-finite value at pixel ({x}, {y}): {}",
            film.pixels[i]
        )));
    }
    Ok(())
}

/// Checks both images and that their sizes agree.
fn check_pair(test: &Film, reference: &Film) -> Result<()> {
    check_film(test, "the test image")?;
    check_film(reference, "the reference image")?;
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err(Error::Invalid(format!(
            "image sizes differ: the test image is {}x{}, the reference {}x{}",
            test.width, test.height, reference.width, reference.height
        )));
    }
    Ok(())
}

/// Mean over every pixel and channel of `f(value, reference value)`, in f64.
fn channel_mean(test: &Film, reference: &Film, f: impl Fn(f64, f64) -> f64) -> f64 {
    let sum: f64 = test
        .pixels
        .iter()
        .zip(&reference.pixels)
        .map(|(t, r)| {
            f(t.x as f64, r.x as f64) + f(t.y as f64, r.y as f64) + f(t.z as f64, r.z as f64)
        })
        .sum();
    sum / (3 * test.pixels.len()) as f64
}

/// Root mean squared error of `test` against `reference`, over all pixels
/// and the three channels.
pub fn rmse(test: &Film, reference: &Film) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(channel_mean(test, reference, |v, r| (v - r) * (v - r)).sqrt())
}

/// Relative mean squared error: the mean over pixels and channels of
/// `(v - ref)^2 / (ref^2 + 0.01)` ([`REL_MSE_EPSILON`]).
pub fn rel_mse(test: &Film, reference: &Film) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(channel_mean(test, reference, |v, r| {
        (v - r) * (v - r) / (r * r + REL_MSE_EPSILON)
    }))
}

/// Mean LDR-FLIP error of `test` against `reference`, in `[0, 1]`, at
/// FLIP's default viewing distance (67 pixels per degree). Both films are
/// first mapped to 8-bit sRGB with `display` (as PNG output would be).
pub fn flip(test: &Film, reference: &Film, display: &PngOptions) -> Result<f64> {
    check_pair(test, reference)?;
    if !display.exposure.is_finite() {
        return Err(Error::Invalid("the display exposure must be finite".into()));
    }
    let to_flip = |film: &Film| {
        let bytes: Vec<u8> = film
            .pixels
            .iter()
            .flat_map(|&c| to_srgb8(c, display))
            .collect();
        nv_flip::FlipImageRgb8::with_data(film.width, film.height, &bytes)
    };
    let map = nv_flip::flip(
        to_flip(reference),
        to_flip(test),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&map).mean() as f64;
    if !mean.is_finite() {
        return Err(Error::Invalid("FLIP returned a non-finite error".into()));
    }
    Ok(mean)
}

/// Every metric of `test` against `reference`; FLIP uses `display`.
pub fn compare(test: &Film, reference: &Film, display: &PngOptions) -> Result<Metrics> {
    Ok(Metrics {
        rmse: rmse(test, reference)?,
        rel_mse: rel_mse(test, reference)?,
        flip: flip(test, reference, display)?,
    })
}

/// Reads an OpenEXR file as linear radiance and checks it with
/// [`check_film`]. Other formats are refused: 8-bit images hold display
/// values, not radiance, and would make the metrics meaningless.
pub fn read_exr(path: &Path) -> Result<Film> {
    if OutputFormat::from_path(path).ok() != Some(OutputFormat::Exr) {
        return Err(Error::load(
            path,
            "not an OpenEXR file: comparisons need linear radiance in a .exr file",
        ));
    }
    let meta = std::fs::metadata(path).map_err(|e| Error::load(path, e.to_string()))?;
    if !meta.is_file() {
        return Err(Error::load(path, "not a regular file"));
    }
    let film = crate::image::output::read_image(path)?;
    check_film(&film, &path.display().to_string())?;
    Ok(film)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::math::Color;

    fn film(width: u32, height: u32, f: impl Fn(usize) -> Color) -> Film {
        Film {
            width,
            height,
            pixels: (0..(width * height) as usize).map(f).collect(),
        }
    }

    #[test]
    fn identical_images_have_zero_error() {
        let a = film(5, 3, |i| Color::new(i as f32 * 0.1, 0.5, 3.0));
        let m = compare(&a, &a, &PngOptions::default()).unwrap();
        assert_eq!(m.rmse, 0.0);
        assert_eq!(m.rel_mse, 0.0);
        assert_eq!(m.flip, 0.0);
    }

    #[test]
    fn constant_offset_gives_that_rmse() {
        // Every channel off by exactly 0.25 (representable in f32): RMSE is 0.25.
        let r = film(7, 4, |i| Color::new(i as f32, 0.5, 2.0));
        let t = film(7, 4, |i| Color::new(i as f32 + 0.25, 0.25, 2.25));
        assert_eq!(rmse(&t, &r).unwrap(), 0.25);
        // Offsets of 0, 2 and 0 on the three channels: mean square 4/3.
        let t2 = film(7, 4, |i| Color::new(i as f32, 2.5, 2.0));
        let expected = (4.0f64 / 3.0).sqrt();
        assert!((rmse(&t2, &r).unwrap() - expected).abs() < 1e-12);
    }

    #[test]
    fn rel_mse_matches_hand_computed_pixels() {
        // Two pixels, six channels:
        // ref (0, 1, 0.1) test (0.1, 1.5, 0.1): 0.01/0.01=1, 0.25/1.01, 0
        // ref (2, 0, 0.5) test (1, 0, 0.0):     1/4.01, 0, 0.25/0.26
        let r = Film {
            width: 2,
            height: 1,
            pixels: vec![Color::new(0.0, 1.0, 0.1), Color::new(2.0, 0.0, 0.5)],
        };
        let t = Film {
            width: 2,
            height: 1,
            pixels: vec![Color::new(0.1, 1.5, 0.1), Color::new(1.0, 0.0, 0.0)],
        };
        // Values as the f32 inputs hold them, so the check is exact to f64 rounding.
        let (a, b) = (0.1f32 as f64, 0.5f32 as f64);
        let terms = [
            a * a / REL_MSE_EPSILON,
            0.25 / 1.01,
            0.0,
            1.0 / 4.01,
            0.0,
            b * b / (b * b + REL_MSE_EPSILON),
        ];
        let expected = terms.iter().sum::<f64>() / 6.0;
        // Written out: (1 + 0.247525 + 0.249377 + 0.961538) / 6.
        assert!((expected - 0.40974).abs() < 1e-5);
        assert!((rel_mse(&t, &r).unwrap() - expected).abs() < 1e-12);
    }

    #[test]
    fn flip_grows_with_the_difference() {
        let r = film(32, 32, |i| Color::splat(((i * 37) % 100) as f32 / 100.0));
        let small = film(32, 32, |i| r.pixels[i] + Color::splat(0.02));
        let large = film(32, 32, |i| r.pixels[i] + Color::splat(0.3));
        let d = PngOptions::default();
        let (fs, fl) = (flip(&small, &r, &d).unwrap(), flip(&large, &r, &d).unwrap());
        assert!(0.0 < fs && fs < fl && fl <= 1.0, "{fs} {fl}");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = film(2, 2, |_| Color::ONE);
        let b = film(2, 3, |_| Color::ONE);
        let e = rmse(&a, &b).unwrap_err().to_string();
        assert!(e.contains("2x2") && e.contains("2x3"), "{e}");
        let mut nan = a.clone();
        nan.pixels[3].y = f32::NAN;
        let e = rel_mse(&nan, &a).unwrap_err().to_string();
        assert!(e.contains("non-finite") && e.contains("(1, 1)"), "{e}");
        let mut inf = a.clone();
        inf.pixels[0].x = f32::INFINITY;
        assert!(flip(&a, &inf, &PngOptions::default()).is_err());
        let empty = Film::new(0, 0);
        assert!(compare(&empty, &empty, &PngOptions::default()).is_err());
        let mut short = a.clone();
        short.pixels.pop();
        assert!(rmse(&short, &a).is_err());
    }

    #[test]
    fn reading_exr_files() {
        let dir = tempfile::tempdir().unwrap();
        let a = film(3, 2, |i| Color::new(i as f32, 0.5, 0.25));
        let path = dir.path().join("a.exr");
        crate::image::output::write_image(&path, &a, &PngOptions::default()).unwrap();
        assert_eq!(read_exr(&path).unwrap(), a);
        let missing = dir.path().join("missing.exr");
        assert!(
            read_exr(&missing)
                .unwrap_err()
                .to_string()
                .contains("missing.exr")
        );
        let png = dir.path().join("a.png");
        crate::image::output::write_image(&png, &a, &PngOptions::default()).unwrap();
        assert!(read_exr(&png).unwrap_err().to_string().contains("OpenEXR"));
        let garbage = dir.path().join("garbage.exr");
        std::fs::write(&garbage, b"not an exr").unwrap();
        assert!(read_exr(&garbage).is_err());
        assert!(read_exr(dir.path()).is_err());
    }
}
