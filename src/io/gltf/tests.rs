//! Tests of the glTF loader, mostly end to end through [`load_gltf`] on
//! small documents written by the tests.

use super::container::{base64_decode, has_scheme, percent_decode_str};
use super::nodes::MAX_DEPTH;
use super::*;
use crate::geometry::mesh::BuildQuality;
use crate::image::output::srgb_to_linear;
use crate::io::desc::{Geometry, ObjectDesc};
use crate::scene::light::{Light, WorldLight};
use crate::scene::material::Texture;
use glam::{Vec2, Vec3, Vec3A};
use serde_json::{Value, json};

fn b64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// A unit quad in the XY plane: positions (48 bytes), normals (48),
/// uvs (32), u16 indices (12), then a sparse index (4) and value (12).
fn quad_buffer(indices: [u16; 6]) -> Vec<u8> {
    let mut b = Vec::new();
    for p in [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        p.iter().for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    for _ in 0..4 {
        [0.0f32, 0.0, 1.0]
            .iter()
            .for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    for uv in [[0.0f32, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]] {
        uv.iter()
            .for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    indices
        .iter()
        .for_each(|i| b.extend_from_slice(&i.to_le_bytes()));
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(&[0, 0]);
    [5.0f32, 5.0, 5.0]
        .iter()
        .for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    b
}

const QUAD: [u16; 6] = [0, 1, 2, 0, 2, 3];

/// A document with the quad's buffer views and accessors; `buffer` is
/// the buffer object (uri or not).
fn quad_doc(buffer: Value) -> Value {
    json!({
        "asset": {"version": "2.0"},
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48},
            {"buffer": 0, "byteOffset": 96, "byteLength": 32},
            {"buffer": 0, "byteOffset": 128, "byteLength": 12},
            {"buffer": 0, "byteOffset": 140, "byteLength": 2},
            {"buffer": 0, "byteOffset": 144, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0, 0, 0], "max": [5, 5, 5],
             "sparse": {"count": 1,
                        "indices": {"bufferView": 4, "componentType": 5123},
                        "values": {"bufferView": 5}}}
        ],
        "meshes": [{"name": "quad", "primitives": [
            {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3}
        ]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}]
    })
}

const BUFFER_LEN: usize = 156;

fn embedded(indices: [u16; 6]) -> Value {
    json!({
        "byteLength": BUFFER_LEN,
        "uri": format!("data:application/octet-stream;base64,{}", b64(&quad_buffer(indices)))
    })
}

fn write(dir: &Path, name: &str, doc: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec_pretty(doc).unwrap()).unwrap();
    path
}

fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(doc).unwrap();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

fn load(path: &Path) -> crate::Result<SceneDesc> {
    load_gltf(path, BuildQuality::Fastest)
}

/// Loads a file that must fail and returns the message.
fn error_of(path: &Path) -> String {
    match load(path) {
        Ok(_) => panic!("{} loaded but should have failed", path.display()),
        Err(e) => {
            let message = e.to_string();
            assert!(
                message.starts_with(&path.display().to_string()),
                "error does not name the file: {message}"
            );
            message
        }
    }
}

fn mesh_of(object: &ObjectDesc) -> &Arc<Mesh> {
    match &object.geometry {
        Geometry::Mesh(m) => m,
        Geometry::Shape(_) => panic!("expected a mesh"),
    }
}

fn close(a: impl Into<glam::DVec3>, b: impl Into<glam::DVec3>) -> bool {
    (a.into() - b.into()).abs().max_element() < 1e-5
}

#[test]
fn quad_scene_with_materials_light_and_camera() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["extensionsUsed"] = json!([
        "KHR_lights_punctual",
        "KHR_materials_specular",
        "KHR_materials_emissive_strength"
    ]);
    doc["scene"] = json!(0);
    doc["scenes"] = json!([{"nodes": [0, 2, 3]}]);
    doc["nodes"] = json!([
        {"name": "parent", "translation": [1, 0, 0], "scale": [2, 2, 2], "children": [1, 4]},
        {"name": "quad", "mesh": 0, "translation": [0, 0, -1]},
        {"name": "sun", "rotation": [-std::f32::consts::FRAC_1_SQRT_2, 0, 0, std::f32::consts::FRAC_1_SQRT_2],
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "eye", "translation": [0, 1, 5], "camera": 0},
        {"name": "quad2", "mesh": 0, "translation": [3, 0, 0]}
    ]);
    doc["meshes"] = json!([{"name": "quad", "primitives": [
        {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0},
        {"attributes": {"POSITION": 0}, "indices": 3, "material": 1},
        {"attributes": {"POSITION": 0}, "indices": 3}
    ]}]);
    doc["materials"] = json!([
        {"name": "matte",
         "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0],
                                  "metallicFactor": 0.0, "roughnessFactor": 0.5},
         "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}},
        {"name": "mirror",
         "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.3, 1.0],
                                  "metallicFactor": 1.0, "roughnessFactor": 0.0},
         "emissiveFactor": [1.0, 0.5, 0.0],
         "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}
    ]);
    doc["cameras"] = json!([{"type": "perspective", "name": "main",
                             "perspective": {"yfov": 0.8, "znear": 0.1}}]);
    doc["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"type": "directional", "name": "sun", "color": [1.0, 0.5, 0.25], "intensity": 3.0}
    ]}});
    let path = write(dir.path(), "quad.gltf", &doc);
    let scene = load(&path).unwrap();

    // Two nodes instance the mesh, three primitives each.
    assert_eq!(scene.objects.len(), 6);
    let names: Vec<_> = scene
        .objects
        .iter()
        .map(|o| o.name.clone().unwrap())
        .collect();
    assert_eq!(names, ["quad", "quad", "quad", "quad2", "quad2", "quad2"]);
    for o in &scene.objects {
        assert_eq!(mesh_of(o).triangle_count(), 2);
    }
    assert!(Arc::ptr_eq(
        mesh_of(&scene.objects[0]),
        mesh_of(&scene.objects[3])
    ));
    assert!(!Arc::ptr_eq(
        mesh_of(&scene.objects[0]),
        mesh_of(&scene.objects[1])
    ));

    // parent (T(1,0,0) S(2)) * child T(0,0,-1).
    let t = scene.objects[0].transform.0;
    assert!(close(
        t.transform_point3(glam::DVec3::ZERO),
        Vec3::new(1.0, 0.0, -2.0)
    ));
    assert!(close(
        t.transform_vector3(glam::DVec3::X),
        Vec3::new(2.0, 0.0, 0.0)
    ));
    let t2 = scene.objects[3].transform.0;
    assert!(close(
        t2.transform_point3(glam::DVec3::ZERO),
        Vec3::new(7.0, 0.0, 0.0)
    ));

    // Specular factor 0: pure Lambertian with the base colour.
    let matte = scene.objects[0].material.sample(Vec2::ZERO);
    assert_eq!(matte.specular, Vec3::ZERO);
    assert_eq!(matte.mirror, Vec3::ZERO);
    assert!(close(matte.diffuse, Vec3::new(0.5, 0.25, 1.0)));
    assert_eq!(matte.emission, Vec3::ZERO);

    // Metallic 1, roughness 0: a mirror tinted by the base colour; the
    // emissive strength scales the emissive factor.
    let mirror = scene.objects[1].material.sample(Vec2::ZERO);
    assert!(close(mirror.mirror, Vec3::new(0.9, 0.6, 0.3)));
    assert_eq!(mirror.diffuse, Vec3::ZERO);
    assert_eq!(mirror.specular, Vec3::ZERO);
    assert!(close(mirror.emission, Vec3::new(4.0, 2.0, 0.0)));

    // No material: glTF's default (white, metallic 1, roughness 1).
    let default = &scene.objects[2].material;
    assert_eq!(default.base_color, Vec3::ONE);
    let mr = default.metallic_roughness.as_ref().unwrap();
    assert_eq!((mr.metallic, mr.roughness), (1.0, 1.0));
    assert!(close(mr.dielectric_f0, Vec3::splat(0.04)));

    // The directional light points down its node's rotated -Z.
    assert_eq!(scene.lights.len(), 1);
    let light = &scene.lights[0];
    assert_eq!(light.name.as_deref(), Some("sun"));
    match light.light {
        Light::Directional { illuminance } => {
            assert!(close(illuminance, Vec3::new(3.0, 1.5, 0.75)))
        }
        other => panic!("expected a directional light, got {other:?}"),
    }
    match WorldLight::new(&light.light, &light.transform, glam::DVec3::ZERO) {
        WorldLight::Directional { direction, .. } => {
            assert!(close(Vec3::from(direction), Vec3::new(0.0, -1.0, 0.0)))
        }
        other => panic!("unexpected {other:?}"),
    }

    assert_eq!(scene.cameras.len(), 1);
    let cam = &scene.cameras[0];
    assert_eq!(cam.name.as_deref(), Some("main"));
    assert!(close(cam.look_from, Vec3::new(0.0, 1.0, 5.0)));
    assert!(close(cam.look_at, Vec3::new(0.0, 1.0, 4.0)));
    assert!(close(cam.up, Vec3::Y));
    assert!((cam.vfov_degrees - 0.8f32.to_degrees()).abs() < 1e-4);
    assert_eq!(scene.background, Vec3::ZERO);
    assert_eq!(scene.settings, Default::default());
}

#[test]
fn point_and_spot_lights() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([
        {"translation": [0, 2, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 1}}}
    ]);
    doc["scenes"] = json!([{"nodes": [0, 1]}]);
    doc["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 100.0, "range": 5.0},
        {"type": "spot", "color": [0.0, 1.0, 0.0], "intensity": 10.0,
         "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5}}
    ]}});
    let scene = load(&write(dir.path(), "lights.gltf", &doc)).unwrap();
    assert_eq!(scene.lights.len(), 2);
    assert_eq!(
        scene.lights[0].light,
        Light::Point {
            intensity: Vec3::splat(100.0)
        }
    );
    assert!(close(
        scene.lights[0].transform.0.translation,
        Vec3::new(0.0, 2.0, 0.0)
    ));
    assert_eq!(
        scene.lights[1].light,
        Light::Spot {
            intensity: Vec3::new(0.0, 10.0, 0.0),
            inner_angle: 0.1,
            outer_angle: 0.5
        }
    );

    // Negative intensity is an error naming the light.
    doc["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(-1.0);
    let message = error_of(&write(dir.path(), "negative.gltf", &doc));
    assert!(
        message.contains("light 0") && message.contains("negative"),
        "{message}"
    );
}

#[test]
fn textures_are_decoded_once_with_transform() {
    let dir = tempfile::tempdir().unwrap();
    let mut img = image::RgbImage::new(2, 1);
    img.put_pixel(0, 0, image::Rgb([255, 0, 0]));
    img.put_pixel(1, 0, image::Rgb([128, 128, 128]));
    img.save(dir.path().join("tex.png")).unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["meshes"] = json!([{"primitives": [
        {"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 0},
        {"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 1}
    ]}]);
    doc["materials"] = json!([
        {"pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform":
                {"offset": [0.5, 0.0], "rotation": 0.25, "scale": [2.0, 3.0]}}},
            "metallicRoughnessTexture": {"index": 1}},
         "emissiveFactor": [1, 1, 1],
         "emissiveTexture": {"index": 0}},
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": 1, "texCoord": 1}}}
    ]);
    doc["textures"] = json!([{"source": 0}, {"source": 0}]);
    doc["images"] = json!([{"uri": "tex.png"}]);
    let scene = load(&write(dir.path(), "textured.gltf", &doc)).unwrap();
    let m0 = &scene.objects[0].material;
    let m1 = &scene.objects[1].material;
    let image_of = |t: &Option<Texture>| match t {
        Some(Texture::Image {
            image, transform, ..
        }) => (image.clone(), *transform),
        other => panic!("expected an image texture, got {other:?}"),
    };
    let (base, transform) = image_of(&m0.base_color_texture);
    assert_eq!((base.width, base.height), (2, 1));
    assert!(close(base.texels[0], Vec3::X));
    assert!(close(
        base.texels[1],
        Vec3::splat(srgb_to_linear(128.0 / 255.0))
    ));
    assert!((base.texels[1].x - 0.2158605).abs() < 1e-4);
    assert_eq!(transform.offset, Vec2::new(0.5, 0.0));
    assert_eq!(transform.rotation, 0.25);
    assert_eq!(transform.scale, Vec2::new(2.0, 3.0));
    let (mr, _) = image_of(&m0.metallic_roughness.as_ref().unwrap().texture);
    assert!(close(mr.texels[1], Vec3::splat(128.0 / 255.0)));
    let (emissive, _) = image_of(&m0.emission_texture);
    assert!(Arc::ptr_eq(&base, &emissive));
    let (other, _) = image_of(&m1.base_color_texture);
    assert!(Arc::ptr_eq(&base, &other));
}

#[test]
fn glb_strips_fans_points_and_sparse() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(json!({"byteLength": BUFFER_LEN}));
    doc["meshes"] = json!([{"primitives": [
        {"attributes": {"POSITION": 0}, "mode": 5},
        {"attributes": {"POSITION": 0}, "mode": 6},
        {"attributes": {"POSITION": 0}, "mode": 0},
        {"attributes": {"POSITION": 0}, "mode": 1},
        {"attributes": {"POSITION": 4}, "indices": 3}
    ]}]);
    let path = dir.path().join("modes.glb");
    std::fs::write(&path, glb(&doc, &quad_buffer(QUAD))).unwrap();
    let scene = load(&path).unwrap();
    assert_eq!(scene.objects.len(), 3);
    assert_eq!(mesh_of(&scene.objects[0]).triangle_count(), 2);
    assert_eq!(mesh_of(&scene.objects[1]).triangle_count(), 2);
    let sparse = mesh_of(&scene.objects[2]);
    assert_eq!(sparse.positions()[2], Vec3A::splat(5.0));
    assert_eq!(sparse.positions()[1], Vec3A::X);
}

#[test]
fn no_scene_uses_root_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc.as_object_mut().unwrap().remove("scenes");
    doc["nodes"] = json!([{"children": [1]}, {"mesh": 0}, {"mesh": 0}]);
    let scene = load(&write(dir.path(), "noscene.gltf", &doc)).unwrap();
    assert_eq!(scene.objects.len(), 2);
}

#[test]
fn malformed_json_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.gltf");
    std::fs::write(&path, b"{\"asset\": {\"version\": \"2.0\"").unwrap();
    let message = error_of(&path);
    assert!(message.contains("cannot parse glTF JSON"), "{message}");

    std::fs::write(&path, b"").unwrap();
    error_of(&path);
    let message = error_of(&dir.path().join("absent.gltf"));
    assert!(message.contains("cannot read file"), "{message}");
}

#[test]
fn truncated_glb_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let doc = quad_doc(json!({"byteLength": BUFFER_LEN}));
    let bytes = glb(&doc, &quad_buffer(QUAD));
    let path = dir.path().join("t.glb");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let message = error_of(&path);
    assert!(message.contains("truncated GLB"), "{message}");
    std::fs::write(&path, &bytes[..7]).unwrap();
    assert!(error_of(&path).contains("truncated GLB"));
    let mut short = bytes.clone();
    short[8..12].copy_from_slice(&4u32.to_le_bytes());
    std::fs::write(&path, &short).unwrap();
    assert!(error_of(&path).contains("invalid GLB header"));
    // A GLB without its BIN chunk.
    let mut no_bin = glb(&doc, &[]);
    let json_end = 20 + u32::from_le_bytes(no_bin[12..16].try_into().unwrap()) as usize;
    no_bin.truncate(json_end);
    let len = no_bin.len() as u32;
    no_bin[8..12].copy_from_slice(&len.to_le_bytes());
    std::fs::write(&path, &no_bin).unwrap();
    let message = error_of(&path);
    assert!(message.contains("binary chunk"), "{message}");
}

#[test]
fn corrupted_glb_never_panics() {
    let dir = tempfile::tempdir().unwrap();
    let doc = quad_doc(json!({"byteLength": BUFFER_LEN}));
    let bytes = glb(&doc, &quad_buffer(QUAD));
    let path = dir.path().join("c.glb");
    for len in 0..bytes.len() {
        std::fs::write(&path, &bytes[..len]).unwrap();
        assert!(load(&path).is_err(), "prefix of {len} bytes loaded");
    }
    // Change every digit of the JSON chunk (counts, offsets, indices,
    // lengths) and every byte of the file.
    let json_end = 20 + u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    for i in 20..json_end {
        if bytes[i].is_ascii_digit() {
            for digit in [b'0', b'9'] {
                let mut corrupt = bytes.clone();
                corrupt[i] = digit;
                std::fs::write(&path, &corrupt).unwrap();
                let _ = load(&path);
            }
        }
    }
    for i in 0..bytes.len() {
        for value in [0x00, 0xff, 0x7f] {
            let mut corrupt = bytes.clone();
            corrupt[i] = value;
            std::fs::write(&path, &corrupt).unwrap();
            let _ = load(&path);
        }
    }
}

#[test]
fn missing_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let doc = quad_doc(json!({"byteLength": BUFFER_LEN, "uri": "missing.bin"}));
    let message = error_of(&write(dir.path(), "nobuf.gltf", &doc));
    assert!(
        message.contains("cannot read buffer 'missing.bin'"),
        "{message}"
    );

    // A buffer file that is too short.
    std::fs::write(dir.path().join("short.bin"), [0u8; 10]).unwrap();
    let doc = quad_doc(json!({"byteLength": BUFFER_LEN, "uri": "short.bin"}));
    let message = error_of(&write(dir.path(), "shortbuf.gltf", &doc));
    assert!(
        message.contains("short.bin") && message.contains("10 bytes"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["meshes"][0]["primitives"][0]["material"] = json!(0);
    doc["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    doc["textures"] = json!([{"source": 0}]);
    doc["images"] = json!([{"uri": "nope.png"}]);
    let message = error_of(&write(dir.path(), "notex.gltf", &doc));
    assert!(
        message.contains("cannot read image 'nope.png'"),
        "{message}"
    );

    // A texture that is not an image.
    std::fs::write(dir.path().join("junk.png"), b"not a png").unwrap();
    doc["images"] = json!([{"uri": "junk.png"}]);
    let message = error_of(&write(dir.path(), "junktex.gltf", &doc));
    assert!(
        message.contains("cannot decode image 'junk.png'"),
        "{message}"
    );
}

#[test]
fn node_cycles_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([
        {"name": "a", "children": [1]},
        {"name": "b", "mesh": 0, "children": [0]}
    ]);
    let message = error_of(&write(dir.path(), "cycle.gltf", &doc));
    assert!(
        message.contains("cycle") && message.contains("'a'"),
        "{message}"
    );
    doc["nodes"] = json!([{"name": "self", "children": [0]}]);
    let message = error_of(&write(dir.path(), "self.gltf", &doc));
    assert!(
        message.contains("cycle") && message.contains("'self'"),
        "{message}"
    );
}

#[test]
fn deep_hierarchy_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    let nodes: Vec<Value> = (0..MAX_DEPTH + 5)
        .map(|i| json!({"children": [i + 1]}))
        .chain([json!({"mesh": 0})])
        .collect();
    doc["nodes"] = Value::Array(nodes);
    let message = error_of(&write(dir.path(), "deep.gltf", &doc));
    assert!(message.contains("deeper than"), "{message}");
}

#[test]
fn bad_indices_and_accessors_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let doc = quad_doc(embedded([0, 1, 2, 0, 2, 7]));
    let message = error_of(&write(dir.path(), "index.gltf", &doc));
    assert!(
        message.contains("mesh 'quad' primitive 0") && message.contains("vertex index 7"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(9);
    let message = error_of(&write(dir.path(), "accessor.gltf", &doc));
    assert!(message.contains("accessor 9"), "{message}");

    let mut doc = quad_doc(embedded(QUAD));
    doc["meshes"][0]["primitives"][0]["indices"] = json!(9);
    let message = error_of(&write(dir.path(), "indices.gltf", &doc));
    assert!(message.contains("invalid glTF"), "{message}");

    let mut doc = quad_doc(embedded(QUAD));
    doc["accessors"][3]["count"] = json!(60);
    let message = error_of(&write(dir.path(), "long.gltf", &doc));
    assert!(
        message.contains("indices") && message.contains("buffer view 3"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["accessors"][0]["count"] = json!(u64::MAX / 2);
    error_of(&write(dir.path(), "huge.gltf", &doc));

    let mut doc = quad_doc(embedded(QUAD));
    doc["bufferViews"][0]["byteLength"] = json!(100000);
    let message = error_of(&write(dir.path(), "view.gltf", &doc));
    assert!(message.contains("exceeds its buffer"), "{message}");

    let mut doc = quad_doc(embedded(QUAD));
    doc["accessors"][0]["type"] = json!("VEC2");
    let message = error_of(&write(dir.path(), "type.gltf", &doc));
    assert!(message.contains("POSITION"), "{message}");

    let mut doc = quad_doc(embedded(QUAD));
    doc["accessors"][4]["sparse"]["count"] = json!(0);
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(4);
    load(&write(dir.path(), "sparse0.gltf", &doc)).unwrap();
    doc["accessors"][4]["sparse"]["count"] = json!(3);
    error_of(&write(dir.path(), "sparse3.gltf", &doc));

    let mut doc = quad_doc(embedded(QUAD));
    doc["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    doc["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    let message = error_of(&write(dir.path(), "draco.gltf", &doc));
    assert!(message.contains("KHR_draco_mesh_compression"), "{message}");
}

#[test]
fn invalid_numbers_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"name": "far", "mesh": 0, "translation": [1e39, 0, 0]}]);
    let message = error_of(&write(dir.path(), "inf.gltf", &doc));
    assert!(
        message.contains("'far'") && message.contains("finite"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"name": "big", "scale": [1e30, 1e30, 1e30], "children": [1]},
                          {"mesh": 0, "scale": [1e30, 1e30, 1e30]}]);
    // 1e60 overflows f32 but not the f64 the hierarchy is composed in: the
    // mesh is refused for its distance instead.
    let message = error_of(&write(dir.path(), "overflow.gltf", &doc));
    assert!(
        message.contains("node 1") && message.contains("farther than"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"mesh": 0, "rotation": [0, 0, 0, 0]}]);
    let message = error_of(&write(dir.path(), "quat.gltf", &doc));
    assert!(
        message.contains("node 0") && message.contains("quaternion"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"mesh": 0, "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 1, 2, 3, 1]}]);
    let scene = load(&write(dir.path(), "matrix.gltf", &doc)).unwrap();
    let t = scene.objects[0].transform.0;
    assert!(close(
        t.transform_point3(glam::DVec3::X),
        Vec3::new(3.0, 2.0, 3.0)
    ));

    let mut doc = quad_doc(embedded(QUAD));
    doc["meshes"][0]["primitives"][0]["material"] = json!(0);
    doc["materials"] = json!([{"name": "hot", "emissiveFactor": [1, 1, 1],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -2.0}}}]);
    let message = error_of(&write(dir.path(), "strength.gltf", &doc));
    assert!(
        message.contains("'hot'") && message.contains("negative"),
        "{message}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"camera": 0}]);
    doc["cameras"] = json!([{"type": "perspective", "perspective": {"yfov": 4.0, "znear": 0.1}}]);
    let message = error_of(&write(dir.path(), "fov.gltf", &doc));
    assert!(message.contains("yfov"), "{message}");

    // Coordinates so large that BVH costs would overflow.
    let mut far = quad_buffer(QUAD);
    far[0..4].copy_from_slice(&1.0e20f32.to_le_bytes());
    let mut doc = quad_doc(json!({"byteLength": BUFFER_LEN,
        "uri": format!("data:application/octet-stream;base64,{}", b64(&far))}));
    doc["accessors"][0]["max"] = json!([1e20, 1, 0]);
    let message = error_of(&write(dir.path(), "farvertex.gltf", &doc));
    assert!(message.contains("vertex 0 position"), "{message}");
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"name": "giant", "mesh": 0, "scale": [1e16, 1, 1]}]);
    let message = error_of(&write(dir.path(), "giant.gltf", &doc));
    assert!(
        message.contains("'giant'") && message.contains("farther"),
        "{message}"
    );

    // Zero-scale nodes are skipped, not errors; orthographic cameras are
    // read (see `orthographic_camera_is_read`), but not with ymag 0.
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"mesh": 0, "scale": [0, 0, 0]}]);
    let scene = load(&write(dir.path(), "zero.gltf", &doc)).unwrap();
    assert!(scene.objects.is_empty());
    let mut doc = quad_doc(embedded(QUAD));
    doc["nodes"] = json!([{"camera": 0}]);
    doc["cameras"] = json!([{"type": "orthographic",
        "orthographic": {"xmag": 1, "ymag": 0, "znear": 0.1, "zfar": 10}}]);
    let message = error_of(&write(dir.path(), "ortho.gltf", &doc));
    assert!(message.contains("ymag 0"), "{message}");
}

#[test]
fn uri_helpers() {
    assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
    assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
    assert!(base64_decode("a$b").is_err());
    assert_eq!(percent_decode_str("a%20b.bin").unwrap(), "a b.bin");
    assert!(percent_decode_str("%FF").is_err());
    assert!(percent_decode_str("%4").is_err());
    assert!(has_scheme("http://x") && !has_scheme("dir/file.bin") && !has_scheme("C:x"));
    assert_eq!(b64(b"hello"), "aGVsbG8=");
}

#[test]
fn samples_load() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/samples");
    if !root.is_dir() {
        println!("skipped: ../shared/samples not found");
        return;
    }
    let triangles = |scene: &SceneDesc| -> usize {
        scene
            .objects
            .iter()
            .map(|o| mesh_of(o).triangle_count())
            .sum()
    };
    for (file, expected) in [
        ("Box/glTF/Box.gltf", 12),
        ("Box/glTF-Binary/Box.glb", 12),
        ("BoxTextured/glTF/BoxTextured.gltf", 12),
        ("Avocado/glTF/Avocado.gltf", 682),
        ("CornellBox/CornellBox.glb", 36),
        ("EmissiveStrengthTest/glTF/EmissiveStrengthTest.gltf", 90),
        ("DamagedHelmet/glTF/DamagedHelmet.gltf", 15452),
    ] {
        let path = root.join(file);
        let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(triangles(&scene), expected, "{file}");
        let emissive = scene
            .objects
            .iter()
            .any(|o| o.material.emission.max_element() > 0.0);
        match file {
            "CornellBox/CornellBox.glb" | "DamagedHelmet/glTF/DamagedHelmet.gltf" => {
                assert!(emissive, "{file} has no emissive material")
            }
            "EmissiveStrengthTest/glTF/EmissiveStrengthTest.gltf" => assert!(
                scene
                    .objects
                    .iter()
                    .any(|o| o.material.emission.max_element() > 1.0),
                "emissive strength not applied"
            ),
            "BoxTextured/glTF/BoxTextured.gltf" | "Avocado/glTF/Avocado.gltf" => assert!(
                scene
                    .objects
                    .iter()
                    .all(|o| o.material.base_color_texture.is_some()),
                "{file}: texture missing"
            ),
            _ => {}
        }
    }
}

/// An extension the file requires but Prism does not read is an error
/// naming it; one it only uses is a warning, and the file loads; the
/// extensions Prism reads may be required.
#[test]
fn required_and_optional_extensions() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    doc["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let e = error_of(&write(dir.path(), "required.gltf", &doc));
    assert!(
        e.contains("requires glTF extension KHR_draco_mesh_compression"),
        "{e}"
    );

    let mut doc = quad_doc(embedded(QUAD));
    doc["extensionsUsed"] = json!(["KHR_materials_clearcoat", "EXT_mesh_gpu_instancing"]);
    doc["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing"]);
    let path = write(dir.path(), "optional.gltf", &doc);
    assert_eq!(load(&path).unwrap().objects.len(), 1);
    let bytes = std::fs::read(&path).unwrap();
    let ctx = container::open(&bytes, &path).unwrap();
    assert_eq!(
        ctx.extension_warnings.len(),
        1,
        "{:?}",
        ctx.extension_warnings
    );
    assert!(ctx.extension_warnings[0].contains("KHR_materials_clearcoat"));
}

/// `EXT_mesh_gpu_instancing` places the node's mesh once per instance:
/// here the quad's own four vertex positions as translations, after a
/// scale of 2 and a quarter turn about Z per instance (ROTATION and
/// SCALE accessors), then the node's translation.
#[test]
fn gpu_instancing_places_each_instance() {
    let dir = tempfile::tempdir().unwrap();
    let mut buffer = quad_buffer(QUAD);
    // Extra data at 156: four rotations (VEC4) and four scales (VEC3).
    let q = [
        0.0f32,
        0.0,
        std::f32::consts::FRAC_1_SQRT_2,
        std::f32::consts::FRAC_1_SQRT_2,
    ];
    for _ in 0..4 {
        q.iter()
            .for_each(|v| buffer.extend_from_slice(&v.to_le_bytes()));
    }
    for _ in 0..4 {
        [2.0f32; 3]
            .iter()
            .for_each(|v| buffer.extend_from_slice(&v.to_le_bytes()));
    }
    let mut doc = quad_doc(json!({
        "byteLength": buffer.len(),
        "uri": format!("data:application/octet-stream;base64,{}", b64(&buffer))
    }));
    doc["bufferViews"].as_array_mut().unwrap().extend([
        json!({"buffer": 0, "byteOffset": 156, "byteLength": 64}),
        json!({"buffer": 0, "byteOffset": 220, "byteLength": 48}),
    ]);
    doc["accessors"].as_array_mut().unwrap().extend([
        json!({"bufferView": 6, "componentType": 5126, "count": 4, "type": "VEC4"}),
        json!({"bufferView": 7, "componentType": 5126, "count": 4, "type": "VEC3"}),
    ]);
    doc["extensionsUsed"] = json!(["EXT_mesh_gpu_instancing"]);
    doc["nodes"][0]["translation"] = json!([10, 0, 0]);
    doc["nodes"][0]["extensions"] = json!({"EXT_mesh_gpu_instancing": {"attributes": {
        "TRANSLATION": 0, "ROTATION": 5, "SCALE": 6}}});
    let scene = load(&write(dir.path(), "instanced.gltf", &doc)).unwrap();
    assert_eq!(scene.objects.len(), 4);
    let translations = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    for (o, t) in scene.objects.iter().zip(translations) {
        let m = o.transform.0;
        // The quad's vertex (1, 0, 0): scaled to (2, 0, 0), turned to
        // (0, 2, 0), moved by the instance and then by the node.
        let p = m.transform_point3(glam::DVec3::X);
        let expect = glam::DVec3::new(10.0 + t[0], 2.0 + t[1], t[2]);
        assert!((p - expect).length() < 1e-5, "{p} vs {expect}");
    }
    // Mismatched counts are an error naming the node.
    doc["accessors"][5]["count"] = json!(3);
    doc["bufferViews"][6]["byteLength"] = json!(48);
    let e = error_of(&write(dir.path(), "mismatch.gltf", &doc));
    assert!(
        e.contains("node 0") && e.contains("different counts"),
        "{e}"
    );
}

/// Orthographic glTF cameras become orthographic cameras of half height
/// `ymag`.
#[test]
fn orthographic_camera_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = quad_doc(embedded(QUAD));
    doc["cameras"] = json!([{"type": "orthographic",
        "orthographic": {"xmag": 3, "ymag": 2, "znear": 0.1, "zfar": 100}}]);
    doc["nodes"] = json!([{"mesh": 0}, {"camera": 0, "translation": [0, 0, 5]}]);
    doc["scenes"] = json!([{"nodes": [0, 1]}]);
    let scene = load(&write(dir.path(), "ortho.gltf", &doc)).unwrap();
    assert_eq!(
        scene.cameras[0].projection,
        crate::scene::camera::Projection::Orthographic { half_height: 2.0 }
    );
}
