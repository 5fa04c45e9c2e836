//! Reading environment maps: equirectangular Radiance `.hdr` and OpenEXR
//! `.exr` images of linear radiance (see
//! [`crate::scene::environment`] for the direction convention).

use std::path::Path;
use std::sync::Arc;

use crate::core::error::{Error, Result};
use crate::core::math::Color;
use crate::scene::environment::{EnvironmentMap, MAX_MAP_SIDE};

/// Decodes an environment map from the bytes of a `.hdr` or `.exr` file
/// (the format is recognised from its content). The error is the message
/// for the user.
pub fn decode_environment_map(bytes: &[u8]) -> std::result::Result<EnvironmentMap, String> {
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    match reader.format() {
        Some(image::ImageFormat::Hdr) | Some(image::ImageFormat::OpenExr) => {}
        Some(f) => {
            return Err(format!(
                "{f:?} images are not environment maps: expected Radiance .hdr or OpenEXR .exr"
            ));
        }
        None => {
            return Err(
                "not a Radiance .hdr or OpenEXR .exr image (unrecognised content)".to_string(),
            );
        }
    }
    let (width, height) = reader.into_dimensions().map_err(|e| e.to_string())?;
    if width == 0 || height == 0 {
        return Err(format!(
            "the environment map is empty ({width}x{height} texels)"
        ));
    }
    if width > MAX_MAP_SIDE || height > MAX_MAP_SIDE {
        return Err(format!(
            "the environment map is {width}x{height} texels; at most {MAX_MAP_SIDE} a side"
        ));
    }
    let img = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| e.to_string())?
        .to_rgb32f();
    let (width, height) = img.dimensions();
    let texels: Vec<Color> = img.pixels().map(|p| Color::new(p[0], p[1], p[2])).collect();
    EnvironmentMap::new(width, height, texels).map_err(|e| e.0)
}

/// Reads an environment map file (`.hdr` or `.exr`). Errors name the file:
/// missing, not a regular file, undecodable, empty, or holding negative,
/// NaN or infinite texels.
pub fn load_environment_map(path: &Path) -> Result<Arc<EnvironmentMap>> {
    let bytes = crate::io::read_regular_file(path)
        .map_err(|e| Error::load(path, format!("cannot read the environment map: {e}")))?;
    decode_environment_map(&bytes)
        .map(Arc::new)
        .map_err(|e| Error::load(path, format!("bad environment map: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Radiance file of `w x h` texels, all `c` (flat RGBE scanlines).
    pub(crate) fn hdr_bytes(w: u32, h: u32, c: [f32; 3]) -> Vec<u8> {
        let img = image::Rgb32FImage::from_fn(w, h, |_, _| image::Rgb(c));
        let mut out = Vec::new();
        image::DynamicImage::ImageRgb32F(img)
            .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Hdr)
            .unwrap();
        out
    }

    fn exr_bytes(w: u32, h: u32, c: [f32; 3]) -> Vec<u8> {
        let img = image::Rgb32FImage::from_fn(w, h, |_, _| image::Rgb(c));
        let mut out = Vec::new();
        image::DynamicImage::ImageRgb32F(img)
            .write_to(
                &mut std::io::Cursor::new(&mut out),
                image::ImageFormat::OpenExr,
            )
            .unwrap();
        out
    }

    #[test]
    fn reads_hdr_and_exr() {
        let m = decode_environment_map(&hdr_bytes(8, 4, [0.5, 1.0, 2.0])).unwrap();
        assert_eq!((m.width(), m.height()), (8, 4));
        // RGBE keeps 8 bits of mantissa: these values are exact.
        assert_eq!(m.texels()[0], Color::new(0.5, 1.0, 2.0));
        let m = decode_environment_map(&exr_bytes(3, 2, [0.25, 3.0, 7.5])).unwrap();
        assert_eq!(m.texels()[5], Color::new(0.25, 3.0, 7.5));
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let nan = decode_environment_map(&exr_bytes(3, 2, [0.25, f32::NAN, 1.0])).unwrap_err();
        assert!(nan.contains("NaN"), "{nan}");
        let mut hdr = hdr_bytes(8, 4, [1.0; 3]);
        hdr.truncate(hdr.len() / 2);
        assert!(decode_environment_map(&hdr).is_err());
        let e = decode_environment_map(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 0 +X 0\n")
            .unwrap_err();
        assert!(e.contains("empty") || !e.is_empty(), "{e}");
        assert!(decode_environment_map(b"hello").is_err());
        let png = {
            let mut out = Vec::new();
            image::DynamicImage::ImageRgb8(image::RgbImage::new(2, 2))
                .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
                .unwrap();
            out
        };
        assert!(decode_environment_map(&png).unwrap_err().contains("Png"));
        let missing = load_environment_map(Path::new("/nonexistent/sky.hdr")).unwrap_err();
        assert!(
            missing.to_string().contains("/nonexistent/sky.hdr"),
            "{missing}"
        );
    }
}
