//! Cameras and real models: thin-lens depth of field against the circle of
//! confusion, the orthographic projection, alpha cut-outs and their
//! shadows, and every glTF sample model rendered with no options.

use prism::core::math::Color;
use prism::core::settings::RenderSettings;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;

use crate::common::images::film_bits;
use crate::common::render::{config, render_desc, render_toml, sized};
use crate::common::scenes::load_toml;

/// Vertical field of view of the depth-of-field scenes, degrees.
const VFOV: f32 = 20.0;
/// Image side of the depth-of-field scenes, pixels.
const SIDE: u32 = 64;

/// Image-plane size of one pixel at distance 1 from the eye.
fn pixel_size() -> f64 {
    2.0 * (VFOV as f64 / 2.0).to_radians().tan() / SIDE as f64
}

/// A camera at the origin looking down -Z (`lens` adds keys to its
/// table) and an emissive disk of radius `r` facing it at depth `z`.
fn disk_scene(lens: &str, r: f64, z: f64) -> String {
    format!(
        r#"
[camera]
look_from = [0, 0, 0]
look_at = [0, 0, -1]
vfov = {VFOV}
{lens}

[[objects]]
shape = {{ type = "disk", radius = {r} }}
rotate = [90, 0, 0]
translate = [0, 0, {}]
material = {{ color = 0.0, diffuse = 0.0, emission = 1.0 }}
"#,
        -z
    )
}

fn whitted(spp: u32) -> RenderSettings {
    RenderSettings {
        spp,
        ..sized(SIDE, SIDE)
    }
}

/// Mean squared distance (pixels squared) of the image's radiance from
/// its centroid, with the centroid.
fn second_moment(film: &Film) -> (f64, (f64, f64)) {
    let (mut w, mut sx, mut sy) = (0.0f64, 0.0f64, 0.0f64);
    for y in 0..film.height {
        for x in 0..film.width {
            let v = film.get(x, y).x as f64;
            w += v;
            sx += v * (x as f64 + 0.5);
            sy += v * (y as f64 + 0.5);
        }
    }
    assert!(w > 0.0, "the spot is missing");
    let (cx, cy) = (sx / w, sy / w);
    let mut m = 0.0;
    for y in 0..film.height {
        for x in 0..film.width {
            let v = film.get(x, y).x as f64;
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            m += v * (dx * dx + dy * dy);
        }
    }
    (m / w, (cx, cy))
}

/// The second moment of a uniform disk image of radius `r` pixels
/// (`r^2 / 2`) plus binning into pixels (`1/12` per axis, Sheppard).
fn disk_moment(r: f64) -> f64 {
    r * r / 2.0 + 1.0 / 6.0
}

fn render(text: &str, settings: RenderSettings) -> Film {
    render_toml(text, config(settings, IntegratorKind::Recursive))
        .film
        .unwrap()
}

/// A disk behind the plane in focus images as the disk convolved with the
/// circle of confusion: on the plane of focus, the lens of radius `a`
/// spreads a point at depth `z` over a disk of radius `a |z - z_f| / z`,
/// which is `a |z - z_f| / (z z_f)` on the image plane at distance 1.
/// Second moments of independent blurs add, so the spot's second moment
/// is `R^2/2 + r^2/2 + 1/6` with `R` that radius and `r` the disk's own
/// image radius, in pixels. Measured within 2%; the pinhole's spot (no
/// `R`) is checked the same way, so the measurement itself is right.
#[test]
fn defocused_disk_images_as_the_circle_of_confusion() {
    let (a, z_f, z, r) = (1.0, 5.0, 10.0, 0.3);
    let lens = format!("aperture_radius = {a}\nfocus_distance = {z_f}");
    let film = render(&disk_scene(&lens, r, z), whitted(256));
    assert!(film.is_finite());
    let (m, (cx, cy)) = second_moment(&film);
    let coc = a * (z - z_f) / (z * z_f) / pixel_size();
    let own = r / z / pixel_size();
    let expect = disk_moment(own) + coc * coc / 2.0;
    assert!(
        (m / expect - 1.0).abs() < 0.02,
        "second moment {m:.2} px^2, expected {expect:.2} (circle of confusion {coc:.2} px)"
    );
    let centre = SIDE as f64 / 2.0;
    assert!((cx - centre).abs() < 0.2 && (cy - centre).abs() < 0.2);

    let pinhole = render(&disk_scene("", r, z), whitted(256));
    let (m0, _) = second_moment(&pinhole);
    let expect0 = disk_moment(own);
    assert!(
        (m0 / expect0 - 1.0).abs() < 0.02,
        "pinhole second moment {m0:.2}, expected {expect0:.2}"
    );
}

/// A disk on the plane in focus is as sharp through the lens as through
/// the pinhole: every lens ray of a film position meets that plane where
/// the pinhole ray does.
#[test]
fn focal_plane_is_as_sharp_as_the_pinhole() {
    let (z_f, r) = (5.0, 0.15);
    let lens = format!("aperture_radius = 1.0\nfocus_distance = {z_f}");
    let (m_lens, _) = second_moment(&render(&disk_scene(&lens, r, z_f), whitted(64)));
    let (m_pin, _) = second_moment(&render(&disk_scene("", r, z_f), whitted(64)));
    assert!(
        (m_lens / m_pin - 1.0).abs() < 0.01,
        "in focus: lens {m_lens:.3} px^2, pinhole {m_pin:.3}"
    );
}

/// A lens of radius 0 is the pinhole, bit for bit, with path transport
/// (whose sampler dimensions the lens must not disturb) and a focus
/// distance given.
#[test]
fn lens_radius_zero_is_the_pinhole_bit_for_bit() {
    let scene = |lens: &str| {
        format!(
            r#"
[camera]
look_from = [0, 1, 4]
look_at = [0, 0.5, 0]
{lens}

[[objects]]
shape = {{ type = "sphere", radius = 0.5 }}
translate = [0, 0.5, 0]
material = {{ color = [0.8, 0.3, 0.2] }}

[[objects]]
shape = {{ type = "plane" }}
material = {{ color = 0.7 }}

[[objects]]
shape = {{ type = "sphere", radius = 0.3 }}
translate = [1, 2, 0]
material = {{ color = 0.0, emission = 20.0 }}
"#
        )
    };
    let settings = RenderSettings {
        spp: 4,
        transport: prism::core::settings::Transport::Path,
        ..sized(24, 18)
    };
    let pinhole = render(&scene(""), settings.clone());
    let zero = render(
        &scene("aperture_radius = 0.0\nfocus_distance = 2.5"),
        settings.clone(),
    );
    assert_eq!(film_bits(&pinhole), film_bits(&zero));
    let open = render(
        &scene("aperture_radius = 0.05\nfocus_distance = 2.5"),
        settings,
    );
    assert_ne!(film_bits(&pinhole), film_bits(&open), "the lens does blur");
}

/// An orthographic camera images a sphere of radius `r` as a disk of
/// radius `r / (2 h / height)` pixels whatever its distance (`h` the half
/// height of the view).
#[test]
fn orthographic_camera_keeps_size_at_any_distance() {
    let (h, r) = (2.0, 1.0);
    for z in [3.0, 30.0] {
        let text = format!(
            r#"
[camera]
look_from = [0, 0, 0]
look_at = [0, 0, -1]
ortho_half_height = {h}

[[objects]]
shape = {{ type = "sphere", radius = {r} }}
translate = [0, 0, {}]
material = {{ color = 0.0, diffuse = 0.0, emission = 1.0 }}
"#,
            -z
        );
        let film = render(&text, sized(64, 64));
        let lit = film.pixels.iter().filter(|c| c.x > 0.5).count() as f64;
        let radius_px = r / (2.0 * h / 64.0);
        let expect = std::f64::consts::PI * radius_px * radius_px;
        assert!(
            (lit / expect - 1.0).abs() < 0.03,
            "z = {z}: {lit} pixels lit, expected {expect:.1}"
        );
    }
}

/// The camera's lens keys are checked like every other number.
#[test]
fn bad_lens_values_are_errors() {
    for (lens, words) in [
        ("aperture_radius = -1", "lens radius"),
        ("aperture_radius = 0.1\nf_number = 2", "not both"),
        ("f_number = 0", "f_number"),
        ("focus_distance = -3", "focus distance"),
        ("ortho_half_height = 0", "half height"),
    ] {
        let e = load_toml(&disk_scene(lens, 0.1, 5.0))
            .unwrap_err()
            .to_string();
        assert!(e.contains(words), "{lens}: {e}");
    }
}

/// Radiance of a pixel, averaged over channels.
fn grey(c: Color) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// A quad whose left half is cut away by a MASK texture (alpha 0 | 1,
/// nearest filtering) floats above a floor lit from straight above: the
/// floor is lit under the cut-away half and in shadow under the kept half,
/// and the camera looking down sees the floor through the cut.
#[test]
fn alpha_masked_quad_casts_a_cut_out_shadow() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cutout.gltf");
    std::fs::write(&path, cutout_gltf()).unwrap();
    let mut desc = prism::io::load(&path, prism::geometry::mesh::BuildOptions::default()).unwrap();
    assert!(desc.objects.iter().any(|o| o.material.alpha.is_some()));
    // A camera straight above, seeing x in [-2, 2] and z in [-2, 2].
    desc.cameras.push(prism::scene::camera::Camera {
        look_from: glam::DVec3::new(0.0, 10.0, 0.0),
        look_at: glam::DVec3::ZERO,
        up: glam::Vec3::NEG_Z,
        vfov_degrees: 2.0 * (2.0f32 / 10.0).atan().to_degrees(),
        ..Default::default()
    });
    let film = render_desc(desc, config(sized(40, 40), IntegratorKind::Recursive))
        .film
        .unwrap();
    // Floor (albedo 0.5, E = pi lux from above): radiance 0.5. The quad
    // covers x, z in [-1, 1] at height 1; its kept right half is white
    // (albedo 1: radiance 1), its cut left half shows the lit floor.
    let at = |x: f32, z: f32| {
        let px = ((x + 2.0) / 4.0 * 40.0) as u32;
        let py = ((z + 2.0) / 4.0 * 40.0) as u32;
        grey(film.get(px, py))
    };
    let lit_floor = 0.5;
    assert!((at(-1.5, 0.0) - lit_floor).abs() < 0.01, "open floor");
    assert!(
        (at(-0.5, 0.0) - lit_floor).abs() < 0.01,
        "floor seen through the cut"
    );
    assert!((at(0.5, 0.0) - 1.0).abs() < 0.01, "kept half of the quad");
    // Through the wavefront integrator (packet and stream traversal).
    let mut desc = prism::io::load(&path, prism::geometry::mesh::BuildOptions::default()).unwrap();
    desc.cameras.push(prism::scene::camera::Camera {
        look_from: glam::DVec3::new(0.0, 10.0, 0.0),
        look_at: glam::DVec3::ZERO,
        up: glam::Vec3::NEG_Z,
        vfov_degrees: 2.0 * (2.0f32 / 10.0).atan().to_degrees(),
        ..Default::default()
    });
    let wave = render_desc(desc, config(sized(40, 40), IntegratorKind::Wavefront))
        .film
        .unwrap();
    assert_eq!(film_bits(&film), film_bits(&wave));
    // The shadow: seen from below the quad is invisible, so look at the
    // floor under it from a low camera, under the quad's kept half (x > 0)
    // and its cut half (x < 0).
    let mut desc = prism::io::load(&path, prism::geometry::mesh::BuildOptions::default()).unwrap();
    desc.cameras.push(prism::scene::camera::Camera {
        look_from: glam::DVec3::new(0.0, 0.5, 6.0),
        look_at: glam::DVec3::new(0.0, 0.0, 0.0),
        up: glam::Vec3::Y,
        vfov_degrees: 30.0,
        ..Default::default()
    });
    let cam = prism::scene::camera::CameraRays::new(&desc.cameras[0], 64, 48);
    let film = render_desc(desc, config(sized(64, 48), IntegratorKind::Recursive))
        .film
        .unwrap();
    let proj = cam.projection();
    let floor = |x: f32, z: f32| {
        let (p, _) = proj.project(glam::Vec3A::new(x, 0.0, z));
        grey(film.get(p.x as u32, p.y as u32))
    };
    assert!(
        (floor(-0.5, 0.0) - lit_floor).abs() < 0.01,
        "lit through the cut"
    );
    assert!(floor(0.5, 0.0) < 0.01, "shadow of the kept half");
    assert!(
        (floor(1.5, 0.0) - lit_floor).abs() < 0.01,
        "lit beside the quad"
    );
}

/// Base64 without padding rules beyond the standard alphabet.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= c.len() {
                out.push(A[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A glTF scene: a floor quad (albedo 0.5) at y = 0 spanning [-4, 4], a
/// quad at y = 1 spanning [-1, 1] with a 2x1 RGBA texture (left texel
/// alpha 0, right texel alpha 1; white) in MASK mode with nearest
/// filtering, and a directional light of pi lux pointing down.
fn cutout_gltf() -> String {
    let mut png = Vec::new();
    let img = image::RgbaImage::from_raw(2, 1, vec![255, 255, 255, 0, 255, 255, 255, 255]).unwrap();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    // Two quads: positions (VEC3), uvs (VEC2), indices (u16).
    let quad =
        |s: f32, y: f32| -> Vec<[f32; 3]> { vec![[-s, y, -s], [s, y, -s], [s, y, s], [-s, y, s]] };
    let mut bin = Vec::new();
    for p in quad(4.0, 0.0).into_iter().chain(quad(1.0, 1.0)) {
        for v in p {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    for uv in [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        for v in uv {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    for i in [0u16, 2, 1, 0, 3, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let (pos_len, uv_off, idx_off) = (96, 96, 128);
    let total = bin.len();
    format!(
        r#"{{
  "asset": {{ "version": "2.0" }},
  "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {{ "KHR_lights_punctual": {{ "lights": [{{ "type": "directional", "intensity": {pi} }}] }} }},
  "scene": 0,
  "scenes": [{{ "nodes": [0, 1, 2] }}],
  "nodes": [
    {{ "mesh": 0 }},
    {{ "mesh": 1 }},
    {{ "rotation": [-0.7071068, 0, 0, 0.7071068], "extensions": {{ "KHR_lights_punctual": {{ "light": 0 }} }} }}
  ],
  "meshes": [
    {{ "primitives": [{{ "attributes": {{ "POSITION": 0 }}, "indices": 3, "material": 0 }}] }},
    {{ "primitives": [{{ "attributes": {{ "POSITION": 1, "TEXCOORD_0": 2 }}, "indices": 3, "material": 1 }}] }}
  ],
  "materials": [
    {{ "pbrMetallicRoughness": {{ "baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0 }},
       "extensions": {{ "KHR_materials_specular": {{ "specularFactor": 0 }} }} }},
    {{ "pbrMetallicRoughness": {{ "baseColorTexture": {{ "index": 0 }}, "metallicFactor": 0 }},
       "alphaMode": "MASK", "doubleSided": true,
       "extensions": {{ "KHR_materials_specular": {{ "specularFactor": 0 }} }} }}
  ],
  "textures": [{{ "source": 0, "sampler": 0 }}],
  "samplers": [{{ "magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071 }}],
  "images": [{{ "uri": "data:image/png;base64,{png}" }}],
  "buffers": [{{ "byteLength": {total}, "uri": "data:application/octet-stream;base64,{bin}" }}],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": {pos_len} }},
    {{ "buffer": 0, "byteOffset": {uv_off}, "byteLength": 32 }},
    {{ "buffer": 0, "byteOffset": {idx_off}, "byteLength": 12 }}
  ],
  "accessors": [
    {{ "bufferView": 0, "byteOffset": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-4, 0, -4], "max": [4, 0, 4] }},
    {{ "bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, 1, -1], "max": [1, 1, 1] }},
    {{ "bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2" }},
    {{ "bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR" }}
  ]
}}"#,
        pi = std::f32::consts::PI,
        png = base64(&png),
        bin = base64(&bin),
    )
}

/// Every glTF file among the sample models (`../shared/samples`; skipped
/// when absent), as `prism render MODEL -o out.png` sees it with no other
/// option: a camera framing it and, without lights, the default key light
/// are added; the image has no NaN or infinity, no sample was dropped as
/// non-finite, and the model is seen (some pixel is lit). Small images
/// keep it fast; the full-size timings are in the README.
#[test]
fn every_sample_model_renders_without_options() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/samples");
    if !root.is_dir() {
        eprintln!("skipped: ../shared/samples not found");
        return;
    }
    let mut files = Vec::new();
    let mut dirs = vec![root.clone()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")) {
                files.push(p);
            }
        }
    }
    files.sort();
    assert!(files.len() >= 10, "found only {files:?}");
    let (w, h) = (40, 30);
    for path in &files {
        let mut desc =
            prism::io::load(path, prism::geometry::mesh::BuildOptions::default()).unwrap();
        desc.ensure_camera(w as f64 / h as f64);
        let camera = desc.cameras[0].clone();
        desc.ensure_light(&camera, prism::core::settings::Transport::Whitted);
        let frame = render_desc(desc, config(sized(w, h), IntegratorKind::Recursive));
        let film = frame.film.unwrap();
        let name = path.display();
        assert!(film.is_finite(), "{name}: non-finite pixels");
        assert_eq!(frame.counters.nonfinite_samples, 0, "{name}");
        assert!(
            film.pixels.iter().any(|c| c.max_element() > 0.01),
            "{name}: the image is black"
        );
    }
}

/// NormalTangentTest (`../shared/samples`; skipped when absent) pairs real
/// bumps (left cell of each pair) with flat quads normal-mapped to look
/// the same (right cell), and its file has no tangents: Prism generates
/// them. Framed automatically and lit by the default key light (from the
/// upper left), each mapped bump must shade like its geometric twin: the
/// highlight (centroid of the pixels within 10% of the cell's brightest)
/// sits at the same place within 3 pixels (it moves by about 10 when wrong), and the lit half of the
/// cell (upper left of the diagonal; the real bump's cast shadow falls on
/// the other half) has the same mean within 6%. A flipped green channel, a
/// wrong handedness or a tangent along `v` moves the mapped highlight to
/// another side of the bump.
#[test]
fn normal_maps_shade_like_the_geometry_they_replace() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/samples/NormalTangentTest/glTF/NormalTangentTest.gltf");
    if !path.is_file() {
        eprintln!("skipped: {} not found", path.display());
        return;
    }
    let (w, h) = (320u32, 240u32);
    let mut desc = prism::io::load(&path, prism::geometry::mesh::BuildOptions::default()).unwrap();
    desc.ensure_camera(w as f64 / h as f64);
    let camera = desc.cameras[0].clone();
    desc.ensure_light(&camera, prism::core::settings::Transport::Whitted);
    let film = render_desc(desc, config(sized(w, h), IntegratorKind::Recursive))
        .film
        .unwrap();
    // Cell centres of the automatic framing, in pixels: the pink and the
    // blue pair of each of the five rows; a pair's right cell is `pitch`
    // to the right of its left one.
    let pitch = 31.0f32;
    let half = 13i32;
    // (highlight centroid, mean of the lit half) of the cell centred at c.
    let cell = |cx: f32, cy: f32| {
        let pixels: Vec<(i32, i32, f32)> = (-half..=half)
            .flat_map(|dy| (-half..=half).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| {
                let v = grey(film.get((cx as i32 + dx) as u32, (cy as i32 + dy) as u32));
                (dx, dy, v)
            })
            .collect();
        let max = pixels.iter().map(|p| p.2).fold(0.0, f32::max);
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
        for &(dx, dy, v) in &pixels {
            if v >= 0.9 * max {
                sx += dx as f32;
                sy += dy as f32;
                n += 1.0;
            }
        }
        let lit: Vec<f32> = pixels
            .iter()
            .filter(|p| p.0 + p.1 < 0)
            .map(|p| p.2)
            .collect();
        (
            glam::Vec2::new(sx / n, sy / n),
            lit.iter().sum::<f32>() / lit.len() as f32,
        )
    };
    for x in [66.0f32, 144.5] {
        for y in [29.5f32, 68.5, 107.5, 147.0, 186.0] {
            let (hl, ml) = cell(x, y);
            let (hr, mr) = cell(x + pitch, y);
            eprintln!("cell ({x}, {y}): highlights {hl} {hr}, lit means {ml} {mr}");
            assert!(
                (hl - hr).length() <= 3.0,
                "cell ({x}, {y}): highlight at {hl} on the bump, {hr} on the map"
            );
            assert!(
                (mr / ml - 1.0).abs() < 0.06,
                "cell ({x}, {y}): lit half {ml} on the bump, {mr} on the map"
            );
        }
    }
}

/// Which scenes count as lit decides whether the default lighting is
/// added: punctual lights light every transport; emissive surfaces light
/// path and photon transport (they are area lights and photon sources
/// there); an environment lights path transport only (the only one that
/// samples it). A model shown with `--env` under path transport must not
/// get a key light on top of the environment. An unlit scene gets a
/// uniform white environment under path transport and the key light under
/// the others.
#[test]
fn the_key_light_is_added_only_where_nothing_lights_the_scene() {
    use prism::core::settings::Transport::{Path, Photon, Whitted};
    use prism::scene::environment::{Environment, EnvironmentSource};
    let scene = |extra: &str| {
        load_toml(&format!(
            "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nshape = {{ type = \"sphere\", radius = 1.0 }}\n{extra}"
        ))
        .unwrap()
    };
    let bare = scene("");
    let emissive = scene(
        "[[objects]]\nshape = { type = \"sphere\", radius = 0.2 }\nmaterial = { emission = [1, 1, 1] }\n",
    );
    let mut env = scene("");
    env.environment = Some(Environment::new(
        EnvironmentSource::Uniform(Color::splat(1.0)),
        1.0,
        0.0,
    ));
    let point = scene("[[lights]]\ntype = \"point\"\nposition = [0, 3, 3]\nintensity = 5\n");
    for (name, desc, lit) in [
        ("bare", &bare, [false, false, false]),
        ("emissive", &emissive, [false, true, true]),
        ("environment", &env, [false, true, false]),
        ("point light", &point, [true, true, true]),
    ] {
        for (t, want) in [Whitted, Path, Photon].into_iter().zip(lit) {
            assert_eq!(desc.is_lit(t), want, "{name} under {t:?}");
            let mut d = desc.clone();
            let camera = d.cameras[0].clone();
            let added = d.ensure_light(&camera, t).is_some();
            assert_eq!(added, !want, "{name} under {t:?}");
            // Path transport gets a uniform white environment, the others
            // the key light.
            let env_added = added && t == Path;
            assert_eq!(
                d.lights.len(),
                desc.lights.len() + (added && !env_added) as usize,
                "{name} under {t:?}"
            );
            if env_added {
                assert!(desc.environment.is_none(), "{name}");
                assert!(d.is_lit(Path), "{name}");
                assert_eq!(
                    d.environment.as_ref().map(|e| e.radiance(glam::Vec3A::Y)),
                    Some(Color::ONE),
                    "{name}"
                );
            } else {
                assert_eq!(d.environment.is_some(), desc.environment.is_some());
            }
        }
    }
}
