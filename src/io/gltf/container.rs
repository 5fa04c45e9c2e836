//! Reading the file: the `.gltf` JSON or `.glb` container, its buffers
//! (GLB binary chunk, `data:` and `file:` URIs, relative paths) and the
//! bytes of buffer views.

use std::path::{Path, PathBuf};

use super::Ctx;

/// Parses and validates the document and loads its buffers.
pub(super) fn open(bytes: &[u8], path: &Path) -> Result<Ctx, String> {
    let is_glb = bytes.starts_with(b"glTF");
    if is_glb {
        check_glb_header(bytes)?;
    }
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| match e {
            gltf::Error::Deserialize(e) => format!("cannot parse glTF JSON: {e}"),
            gltf::Error::Binary(e) => format!("invalid GLB container: {e}"),
            e => format!("cannot parse glTF: {e}"),
        })?;
    let raw = raw_nodes(bytes, is_glb);
    let mut json = document.into_json();
    precheck_json(&json)?;
    let warnings = check_extensions(&mut json)?;
    let document = gltf::Document::from_json(json).map_err(|e| match e {
        gltf::Error::Validation(errors) => {
            let list: Vec<String> = errors
                .iter()
                .take(10)
                .map(|(path, error)| format!("{path}: {error}"))
                .collect();
            let more = errors.len().saturating_sub(list.len());
            let more = if more > 0 {
                format!(" (and {more} more)")
            } else {
                String::new()
            };
            format!("invalid glTF: {}{more}", list.join("; "))
        }
        e => format!("invalid glTF: {e}"),
    })?;
    let base = path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let buffers = load_buffers(&document, &base, blob)?;
    Ok(Ctx {
        document,
        buffers,
        base,
        node_transforms: raw.iter().map(|n| n.transform).collect(),
        node_instancing: raw.into_iter().map(|n| n.instancing).collect(),
        extension_warnings: warnings,
    })
}

/// The extensions this loader reads (some in part: of `KHR_materials_volume`
/// only the attenuation and whether the surface is thin-walled, see the
/// module documentation).
pub(super) const UNDERSTOOD_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_materials_volume",
    "KHR_materials_dispersion",
    "KHR_materials_specular",
    "KHR_texture_transform",
    "KHR_mesh_quantization",
    "EXT_mesh_gpu_instancing",
];

/// Fails on an extension in `extensionsRequired` that this loader does
/// not read (the file cannot be shown correctly without it), and returns
/// a warning for each one in `extensionsUsed` that it does not read (an
/// optional extension, whose content is ignored). The required list is
/// then emptied: every entry is understood, and the `gltf` crate's own
/// check knows fewer extensions than this loader.
fn check_extensions(json: &mut gltf::json::Root) -> Result<Vec<String>, String> {
    let unknown = |e: &&String| !UNDERSTOOD_EXTENSIONS.contains(&e.as_str());
    let required: Vec<&String> = json.extensions_required.iter().filter(unknown).collect();
    if !required.is_empty() {
        let list: Vec<&str> = required.iter().map(|s| s.as_str()).collect();
        return Err(format!(
            "the file requires glTF extension{} {} which Prism does not support \
             (supported: {})",
            if list.len() == 1 { "" } else { "s" },
            list.join(", "),
            UNDERSTOOD_EXTENSIONS.join(", ")
        ));
    }
    json.extensions_required.clear();
    Ok(json
        .extensions_used
        .iter()
        .filter(unknown)
        .map(|e| format!("optional extension {e} is not supported; its content is ignored"))
        .collect())
}

/// The JSON text of a `.gltf` file or of a GLB's first chunk.
fn json_bytes(bytes: &[u8], is_glb: bool) -> Option<&[u8]> {
    if !is_glb {
        return Some(bytes);
    }
    let word = |i: usize| {
        bytes
            .get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (len, kind) = (word(12)? as usize, word(16)?);
    // "JSON" in little-endian byte order.
    (kind == 0x4E4F_534A).then_some(())?;
    bytes.get(20..20usize.checked_add(len)?)
}

/// What this loader re-reads of a node's JSON itself.
#[derive(Default)]
pub(super) struct RawNode {
    /// The local transform in double precision; `None` when it could not
    /// be read (the `gltf` crate's f32 value is used instead).
    pub transform: Option<glam::DAffine3>,
    /// `EXT_mesh_gpu_instancing` accessor indices.
    pub instancing: Option<Instancing>,
}

/// The attributes of a node's `EXT_mesh_gpu_instancing` extension: accessor
/// indices of per-instance translations (VEC3), rotations (unit
/// quaternions, VEC4) and scales (VEC3).
#[derive(Clone, Copy, Debug, Default, serde::Deserialize)]
pub(super) struct Instancing {
    #[serde(rename = "TRANSLATION")]
    pub translation: Option<usize>,
    #[serde(rename = "ROTATION")]
    pub rotation: Option<usize>,
    #[serde(rename = "SCALE")]
    pub scale: Option<usize>,
}

/// Every node's local transform (in double precision) and instancing
/// attributes, read from the JSON. The `gltf` crate has already parsed and
/// validated the same text, so a failure here only means falling back to
/// its f32 transforms (and no instancing).
fn raw_nodes(bytes: &[u8], is_glb: bool) -> Vec<RawNode> {
    #[derive(serde::Deserialize)]
    struct Root {
        #[serde(default)]
        nodes: Vec<Node>,
    }
    #[derive(serde::Deserialize)]
    struct Node {
        matrix: Option<[f64; 16]>,
        translation: Option<[f64; 3]>,
        rotation: Option<[f64; 4]>,
        scale: Option<[f64; 3]>,
        extensions: Option<Extensions>,
    }
    #[derive(serde::Deserialize)]
    struct Extensions {
        #[serde(rename = "EXT_mesh_gpu_instancing")]
        instancing: Option<InstancingExt>,
    }
    #[derive(serde::Deserialize)]
    struct InstancingExt {
        #[serde(default)]
        attributes: Instancing,
    }
    let Some(root) = json_bytes(bytes, is_glb).and_then(|j| serde_json::from_slice::<Root>(j).ok())
    else {
        return Vec::new();
    };
    root.nodes
        .into_iter()
        .map(|n| {
            let instancing = n
                .extensions
                .and_then(|e| e.instancing)
                .map(|i| i.attributes);
            let transform = match n.matrix {
                Some(m) => Some(glam::DAffine3::from_mat4(glam::DMat4::from_cols_array(&m))),
                None => {
                    let q = glam::DQuat::from_array(n.rotation.unwrap_or([0.0, 0.0, 0.0, 1.0]));
                    let length = q.length();
                    (length.is_finite() && length > 0.0).then(|| {
                        glam::DAffine3::from_scale_rotation_translation(
                            glam::DVec3::from(n.scale.unwrap_or([1.0; 3])),
                            q / length,
                            glam::DVec3::from(n.translation.unwrap_or([0.0; 3])),
                        )
                    })
                }
            };
            RawNode {
                transform,
                instancing,
            }
        })
        .collect()
}

/// Checks the 12-byte GLB header before the `gltf` crate reads it (it
/// trusts the declared length).
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    let word = |i: usize| {
        bytes
            .get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (Some(version), Some(length)) = (word(4), word(8)) else {
        return Err(format!(
            "truncated GLB: the file has {} bytes, less than the 12-byte header",
            bytes.len()
        ));
    };
    if version != 2 {
        return Err(format!("unsupported GLB version {version} (expected 2)"));
    }
    if length < 12 {
        return Err(format!(
            "invalid GLB header: declared length {length} is shorter than the header"
        ));
    }
    if length as usize > bytes.len() {
        return Err(format!(
            "truncated GLB: the header declares {length} bytes but the file has {}",
            bytes.len()
        ));
    }
    Ok(())
}

/// Checks what the `gltf` crate's validation indexes without a bounds
/// check (attribute accessors of primitives).
fn precheck_json(json: &gltf::json::Root) -> Result<(), String> {
    for (mi, mesh) in json.meshes.iter().enumerate() {
        for (pi, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                if index.value() >= json.accessors.len() {
                    return Err(format!(
                        "invalid glTF: meshes[{mi}].primitives[{pi}] attribute {} refers to \
                         accessor {} but the file has {} accessors",
                        semantic.to_string(),
                        index.value(),
                        json.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// A short description of a URI for messages (data URIs are not quoted).
pub(super) fn uri_label(uri: &str) -> String {
    if uri.starts_with("data:") {
        "<data URI>".to_string()
    } else {
        uri.to_string()
    }
}

/// Loads every buffer of the document.
fn load_buffers(
    document: &gltf::Document,
    base: &Path,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, String> {
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let (data, label) = match buffer.source() {
            gltf::buffer::Source::Bin => (
                blob.take().ok_or_else(|| {
                    format!("buffer {i} refers to the GLB binary chunk, but there is none")
                })?,
                format!("buffer {i} (GLB binary chunk)"),
            ),
            gltf::buffer::Source::Uri(uri) => (
                read_uri(base, uri)
                    .map_err(|e| format!("cannot read buffer '{}': {e}", uri_label(uri)))?,
                format!("buffer '{}'", uri_label(uri)),
            ),
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "{label} has {} bytes but the file declares {}",
                data.len(),
                buffer.length()
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// True when `uri` starts with a URI scheme (`name:`), as opposed to a
/// relative path.
pub(super) fn has_scheme(uri: &str) -> bool {
    match uri.split_once(':') {
        Some((scheme, _)) => {
            scheme.len() > 1
                && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
                && scheme
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
        }
        None => false,
    }
}

/// Reads the bytes a buffer or image URI refers to: a data URI, a
/// `file:` URI or a path relative to the glTF file.
pub(super) fn read_uri(base: &Path, uri: &str) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (meta, data) = rest
            .split_once(',')
            .ok_or("malformed data URI (no comma)")?;
        return if meta.ends_with(";base64") {
            base64_decode(data)
        } else {
            percent_decode(data)
        };
    }
    let file = if let Some(rest) = uri.strip_prefix("file://") {
        PathBuf::from(percent_decode_str(rest)?)
    } else if let Some(rest) = uri.strip_prefix("file:") {
        PathBuf::from(percent_decode_str(rest)?)
    } else if has_scheme(uri) {
        return Err("unsupported URI scheme (only relative paths, file: and data: URIs)".into());
    } else {
        base.join(percent_decode_str(uri)?)
    };
    crate::io::read_regular_file(&file)
}

/// Decodes `%XX` escapes.
fn percent_decode(s: &str) -> Result<Vec<u8>, String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        if b == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("invalid percent-encoding at offset {i}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b);
            i += 1;
        }
    }
    Ok(out)
}

/// Decodes `%XX` escapes into a UTF-8 string.
pub(super) fn percent_decode_str(s: &str) -> Result<String, String> {
    String::from_utf8(percent_decode(s)?)
        .map_err(|_| "percent-encoded path is not valid UTF-8".to_string())
}

/// Decodes standard or URL-safe base64, with or without padding.
pub(super) fn base64_decode(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    let mut acc: u32 = 0;
    let mut bits = 0u32;
    for (i, c) in s.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\t' | b'\r' | b'\n' => continue,
            _ => return Err(format!("invalid base64 character at offset {i}")),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// The bytes of a buffer view, bounds-checked against its buffer.
pub(super) fn view_bytes<'c>(ctx: &'c Ctx, view: &gltf::buffer::View) -> Result<&'c [u8], String> {
    let buffer = ctx
        .buffers
        .get(view.buffer().index())
        .ok_or_else(|| format!("buffer view {} has no buffer", view.index()))?;
    let start = view.offset();
    start
        .checked_add(view.length())
        .and_then(|end| buffer.get(start..end))
        .ok_or_else(|| {
            format!(
                "buffer view {} (bytes {start}..{}) exceeds its buffer of {} bytes",
                view.index(),
                start.saturating_add(view.length()),
                buffer.len()
            )
        })
}
