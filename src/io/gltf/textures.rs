//! Textures: images (files, data URIs or buffer views) decoded once into
//! linear RGB [`ImageTexture`]s, and material texture references with
//! their `KHR_texture_transform`.

use std::io::Cursor;
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::image::output::srgb_to_linear;
use crate::scene::material::{ImageTexture, Texture, TextureSampler, UvTransform, Wrap};

use super::container::{read_uri, uri_label, view_bytes};
use super::{Ctx, State};

/// Decodes image `index` (once; cached).
fn decoded_image<'s>(
    ctx: &Ctx,
    st: &'s mut State,
    index: usize,
) -> Result<&'s image::DynamicImage, String> {
    match st.decoded.entry(index) {
        std::collections::hash_map::Entry::Occupied(e) => Ok(e.into_mut()),
        std::collections::hash_map::Entry::Vacant(e) => Ok(e.insert(decode_image(ctx, index)?)),
    }
}

fn decode_image(ctx: &Ctx, index: usize) -> Result<image::DynamicImage, String> {
    let json = ctx
        .document
        .as_json()
        .images
        .get(index)
        .ok_or_else(|| format!("image {index} does not exist"))?;
    let mime = json.mime_type.as_ref().map(|m| m.0.as_str());
    let (bytes, label): (Vec<u8>, String) = if let Some(view) = json.buffer_view {
        let view = ctx
            .document
            .views()
            .nth(view.value())
            .ok_or_else(|| format!("image {index} refers to a missing buffer view"))?;
        let label = match &json.name {
            Some(name) => format!("image {index} ('{name}')"),
            None => format!("image {index}"),
        };
        (view_bytes(ctx, &view)?.to_vec(), label)
    } else if let Some(uri) = &json.uri {
        let label = format!("image '{}'", uri_label(uri));
        let bytes = read_uri(&ctx.base, uri).map_err(|e| format!("cannot read {label}: {e}"))?;
        (bytes, label)
    } else {
        return Err(format!("image {index} has neither a uri nor a bufferView"));
    };
    let format = image::guess_format(&bytes)
        .ok()
        .or(match mime {
            Some("image/png") => Some(image::ImageFormat::Png),
            Some("image/jpeg") => Some(image::ImageFormat::Jpeg),
            _ => None,
        })
        .ok_or_else(|| format!("cannot decode {label}: unrecognised image format"))?;
    image::ImageReader::with_format(Cursor::new(bytes), format)
        .decode()
        .map_err(|e| format!("cannot decode {label}: {e}"))
}

/// Converts a decoded image to linear RGB texels.
fn to_texture(img: &image::DynamicImage, srgb: bool) -> Result<ImageTexture, String> {
    use image::DynamicImage as D;
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err("image has no pixels".into());
    }
    let texels: Vec<Vec3> = match img {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
            let lut: [f32; 256] = std::array::from_fn(|i| {
                let c = i as f32 / 255.0;
                if srgb { srgb_to_linear(c) } else { c }
            });
            img.to_rgb8()
                .pixels()
                .map(|p| Vec3::from(p.0.map(|c| lut[c as usize])))
                .collect()
        }
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => img
            .to_rgb32f()
            .pixels()
            .map(|p| {
                let v = Vec3::from(p.0);
                if srgb { v.map(srgb_to_linear) } else { v }
            })
            .collect(),
        D::ImageRgb32F(_) | D::ImageRgba32F(_) => img
            .to_rgb32f()
            .pixels()
            .map(|p| {
                let v = Vec3::from(p.0);
                if v.is_finite() { v } else { Vec3::ZERO }
            })
            .collect(),
        other => {
            return Err(format!("unsupported pixel format {:?}", other.color()));
        }
    };
    // Alpha is kept only where there is some (cut-outs and transparency
    // read it); it is linear in every format.
    let alpha = if img.color().has_alpha() {
        let a: Vec<f32> = img.to_rgba32f().pixels().map(|p| p.0[3]).collect();
        if a.iter().all(|&x| x >= 1.0) {
            Vec::new()
        } else {
            a.into_iter()
                .map(|x| {
                    if x.is_finite() {
                        x.clamp(0.0, 1.0)
                    } else {
                        1.0
                    }
                })
                .collect()
        }
    } else {
        Vec::new()
    };
    Ok(ImageTexture::with_alpha(width, height, texels, alpha))
}

/// The linear texture of image `index` (sRGB-decoded if `srgb`), cached.
fn image_texture(
    ctx: &Ctx,
    st: &mut State,
    index: usize,
    srgb: bool,
) -> Result<Arc<ImageTexture>, String> {
    if let Some(t) = st.textures.get(&(index, srgb)) {
        return Ok(t.clone());
    }
    let img = decoded_image(ctx, st, index)?;
    let texture = Arc::new(to_texture(img, srgb).map_err(|e| format!("image {index}: {e}"))?);
    st.textures.insert((index, srgb), texture.clone());
    Ok(texture)
}

/// A [`Texture`] for a material's texture reference.
pub(super) fn texture(
    ctx: &Ctx,
    st: &mut State,
    info: &gltf::texture::Info,
    srgb: bool,
    what: &str,
    material: &str,
) -> Result<Texture, String> {
    let mut set = info.tex_coord();
    let transform = match info.texture_transform() {
        Some(t) => {
            if let Some(s) = t.tex_coord() {
                set = s;
            }
            let transform = UvTransform {
                offset: Vec2::from(t.offset()),
                rotation: t.rotation(),
                scale: Vec2::from(t.scale()),
            };
            if !(transform.offset.is_finite()
                && transform.rotation.is_finite()
                && transform.scale.is_finite())
            {
                return Err(format!(
                    "{material}: {what} has a non-finite KHR_texture_transform"
                ));
            }
            transform
        }
        None => UvTransform::default(),
    };
    if set != 0 {
        st.warn(format!(
            "{material}: {what} uses TEXCOORD_{set}; TEXCOORD_0 is used instead"
        ));
    }
    let image_index = info.texture().source().index();
    let image = image_texture(ctx, st, image_index, srgb)
        .map_err(|e| format!("{material}: {what}: {e}"))?;
    let sampler = texture_sampler(&info.texture().sampler());
    Ok(Texture::Image {
        image,
        transform,
        sampler,
    })
}

/// The wrapping and filtering of a glTF sampler: each axis's wrap mode,
/// and nearest or linear filtering as the magnification filter says
/// (linear textures are minified through their mipmaps by the ray cones'
/// level of detail, nearest ones are not; the minification filter is not
/// read).
pub(super) fn texture_sampler(s: &gltf::texture::Sampler) -> TextureSampler {
    use gltf::texture::{MagFilter, WrappingMode};
    let wrap = |w: WrappingMode| match w {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        WrappingMode::ClampToEdge => Wrap::ClampToEdge,
    };
    TextureSampler {
        wrap_u: wrap(s.wrap_s()),
        wrap_v: wrap(s.wrap_t()),
        linear: s.mag_filter() != Some(MagFilter::Nearest),
    }
}

/// The [`Texture`] of a material's normal map (linear data; the `gltf`
/// crate does not expose `KHR_texture_transform` on normal textures, so
/// none is applied).
pub(super) fn normal_texture(
    ctx: &Ctx,
    st: &mut State,
    info: &gltf::material::NormalTexture,
    material: &str,
) -> Result<Texture, String> {
    let set = info.tex_coord();
    if set != 0 {
        st.warn(format!(
            "{material}: normal texture uses TEXCOORD_{set}; TEXCOORD_0 is used instead"
        ));
    }
    let image_index = info.texture().source().index();
    let image = image_texture(ctx, st, image_index, false)
        .map_err(|e| format!("{material}: normal texture: {e}"))?;
    Ok(Texture::Image {
        image,
        transform: UvTransform::default(),
        sampler: texture_sampler(&info.texture().sampler()),
    })
}
