//! Writing films to disk.
//!
//! * `.exr`: linear float RGB radiance exactly as computed (no exposure,
//!   no tone map).
//! * `.png`: 8-bit sRGB. Radiance is multiplied by `2^exposure`, passed
//!   through the tone map ([`ToneMap::Clamp`] by default: values above 1
//!   saturate), then encoded with the sRGB transfer curve.
//!
//! Every file is written to a temporary file in the destination directory
//! and renamed into place once complete, so a failed render or write never
//! leaves a truncated image behind.

use std::io::{Cursor, Write};
use std::path::Path;

use image::{ExtendedColorType, ImageEncoder};

use crate::core::error::{Error, Result};
use crate::core::math::Color;
use crate::image::film::Film;
use crate::image::lines::LineOverlay;

/// How radiance is mapped into `[0, 1]` for 8-bit output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ToneMap {
    /// Clip each channel at 1.
    #[default]
    Clamp,
    /// `x / (1 + x)` per channel: compresses highlights, never clips.
    Reinhard,
}

/// Options for 8-bit output.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PngOptions {
    /// Exposure in stops: radiance is multiplied by `2^exposure`.
    pub exposure: f32,
    /// Tone map applied after exposure.
    pub tone_map: ToneMap,
}

/// Image formats, chosen by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// 32-bit float OpenEXR.
    Exr,
}

impl OutputFormat {
    /// The format for `path`'s extension, or an error naming the supported ones.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(OutputFormat::Png),
            Some("exr") => Ok(OutputFormat::Exr),
            _ => Err(Error::Output {
                path: path.to_path_buf(),
                message: "unsupported output format: use a .png or .exr file name".into(),
            }),
        }
    }
}

/// The sRGB transfer function applied to a linear value in `[0, 1]`.
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse of [`linear_to_srgb`].
#[inline]
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// Maps one linear radiance value to an 8-bit sRGB code.
pub fn to_srgb8(c: Color, opts: &PngOptions) -> [u8; 3] {
    let scale = opts.exposure.exp2();
    let c = c * scale;
    let map = |v: f32| -> u8 {
        let v = if v.is_finite() { v.max(0.0) } else { 0.0 };
        let v = match opts.tone_map {
            ToneMap::Clamp => v.min(1.0),
            ToneMap::Reinhard => v / (1.0 + v),
        };
        (linear_to_srgb(v) * 255.0 + 0.5).clamp(0.0, 255.0) as u8
    };
    [map(c.x), map(c.y), map(c.z)]
}

/// Writes `film` to `path` in the format its extension names, through
/// [`write_atomic`].
pub fn write_image(path: &Path, film: &Film, opts: &PngOptions) -> Result<()> {
    write_image_with_lines(path, film, None, opts)
}

/// [`write_image`] with feature lines drawn over the image: for PNG after
/// exposure and tone mapping (the ink keeps its colour at any exposure),
/// for EXR mixed into the linear radiance. The overlay must have the
/// film's size.
pub fn write_image_with_lines(
    path: &Path,
    film: &Film,
    lines: Option<&LineOverlay>,
    opts: &PngOptions,
) -> Result<()> {
    write_image_with_overlays(path, film, lines.as_slice(), opts)
}

/// [`write_image_with_lines`] with any number of line masks, mixed in
/// one after the other (later ones over earlier ones). Each must have the
/// film's size.
pub fn write_image_with_overlays(
    path: &Path,
    film: &Film,
    overlays: &[&LineOverlay],
    opts: &PngOptions,
) -> Result<()> {
    for l in overlays {
        if (l.width, l.height) != (film.width, film.height) {
            return Err(Error::Output {
                path: path.to_path_buf(),
                message: format!(
                    "line overlay is {}x{} but the image is {}x{}",
                    l.width, l.height, film.width, film.height
                ),
            });
        }
    }
    let linear;
    let film = match OutputFormat::from_path(path) {
        Ok(OutputFormat::Exr) if !overlays.is_empty() => {
            let mut f = film.clone();
            for l in overlays {
                f = l.over_linear(&f);
            }
            linear = f;
            &linear
        }
        _ => film,
    };
    let format = OutputFormat::from_path(path)?;
    let err = |message: String| Error::Output {
        path: path.to_path_buf(),
        message,
    };
    // The EXR encoder seeks back to write its offset table.
    let mut w = Cursor::new(Vec::new());
    match format {
        OutputFormat::Png => {
            let bytes: Vec<u8> = film
                .pixels
                .iter()
                .enumerate()
                .flat_map(|(i, &c)| {
                    overlays
                        .iter()
                        .fold(to_srgb8(c, opts), |rgb, l| l.over_srgb8(i, rgb))
                })
                .collect();
            image::codecs::png::PngEncoder::new(&mut w)
                .write_image(&bytes, film.width, film.height, ExtendedColorType::Rgb8)
                .map_err(|e| err(e.to_string()))?;
        }
        OutputFormat::Exr => {
            let floats: Vec<f32> = film
                .pixels
                .iter()
                .flat_map(|c| {
                    let c = if c.is_finite() { *c } else { Color::ZERO };
                    [c.x, c.y, c.z]
                })
                .collect();
            let bytes: &[u8] = bytemuck::cast_slice::<f32, u8>(&floats);
            image::codecs::openexr::OpenExrEncoder::new(&mut w)
                .write_image(bytes, film.width, film.height, ExtendedColorType::Rgb32F)
                .map_err(|e| err(e.to_string()))?;
        }
    }
    write_atomic(path, &w.into_inner())
}

/// Writes `bytes` to `path` whole or not at all: into a temporary file in
/// `path`'s folder, which is synced, given the permissions of an ordinary
/// new file (temporary files are created readable by their owner only)
/// and renamed to `path`. On failure `path` is untouched and no temporary
/// file is left behind. Every file Prism writes goes through here.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let err = |message: String| Error::Output {
        path: path.to_path_buf(),
        message,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::Builder::new()
        .prefix(".prism-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| err(format!("cannot create a file in {}: {e}", dir.display())))?;
    tmp.write_all(bytes).map_err(|e| err(e.to_string()))?;
    tmp.as_file().sync_all().map_err(|e| err(e.to_string()))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(|e| err(e.to_string()))?;
    }
    tmp.persist(path)
        .map(|_| ())
        .map_err(|e| err(e.error.to_string()))
}

/// Reads an EXR or PNG back as linear radiance (PNG is decoded from sRGB).
/// Used by tests and by image comparison.
pub fn read_image(path: &Path) -> Result<Film> {
    let img = image::open(path).map_err(|e| Error::load(path, e.to_string()))?;
    let is_exr = OutputFormat::from_path(path).ok() == Some(OutputFormat::Exr);
    let rgb = img.to_rgb32f();
    let (width, height) = rgb.dimensions();
    let pixels = rgb
        .pixels()
        .map(|p| {
            let c = Color::new(p[0], p[1], p[2]);
            if is_exr {
                c
            } else {
                Color::new(
                    srgb_to_linear(c.x),
                    srgb_to_linear(c.y),
                    srgb_to_linear(c.z),
                )
            }
        })
        .collect();
    Ok(Film {
        width,
        height,
        pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip_and_known_values() {
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            assert!((srgb_to_linear(linear_to_srgb(x)) - x).abs() < 1e-5);
        }
        // Middle grey 0.18 encodes to 118/255 in sRGB.
        let c = to_srgb8(Color::splat(0.18), &PngOptions::default());
        assert_eq!(c, [118, 118, 118]);
        assert_eq!(
            to_srgb8(Color::splat(5.0), &PngOptions::default()),
            [255; 3]
        );
        assert_eq!(
            to_srgb8(Color::splat(f32::NAN), &PngOptions::default()),
            [0; 3]
        );
        let one_stop_down = PngOptions {
            exposure: -1.0,
            tone_map: ToneMap::Clamp,
        };
        assert_eq!(to_srgb8(Color::splat(0.36), &one_stop_down), [118; 3]);
    }

    #[test]
    fn exr_round_trips_exactly_and_png_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut film = Film::new(3, 2);
        for (i, p) in film.pixels.iter_mut().enumerate() {
            *p = Color::new(i as f32 * 0.1, 1e-7, 12345.678);
        }
        let exr = dir.path().join("a.exr");
        write_image(&exr, &film, &PngOptions::default()).unwrap();
        let back = read_image(&exr).unwrap();
        assert_eq!(back, film);
        let png = dir.path().join("a.png");
        write_image(&png, &film, &PngOptions::default()).unwrap();
        assert_eq!(read_image(&png).unwrap().width, 3);
        // Only the two images: no temporary file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&png).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o644, "images are readable by others");
        }
    }

    #[test]
    fn write_atomic_replaces_whole_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stats.json");
        write_atomic(&path, b"first, longer contents").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let e = write_atomic(&dir.path().join("no/such/dir/a.csv"), b"x").unwrap_err();
        assert!(e.to_string().contains("a.csv"), "{e}");
    }

    #[test]
    fn bad_output_paths_fail_cleanly() {
        let dir = tempfile::tempdir().unwrap();
        let film = Film::new(1, 1);
        assert!(write_image(&dir.path().join("a.bmp"), &film, &PngOptions::default()).is_err());
        let missing = dir.path().join("no/such/dir/a.png");
        let e = write_image(&missing, &film, &PngOptions::default()).unwrap_err();
        assert!(e.to_string().contains("a.png"), "{e}");
    }
}
