//! Absorbing interiors: Beer-Lambert attenuation inside closed objects,
//! from the project's format and from glTF `KHR_materials_volume`, in
//! every transport and both integrators.
//!
//! The scene is an index-matched slab (IOR 1, so no Fresnel reflection and
//! no bending: every camera ray crosses it straight) of thickness `d` in
//! front of an emitter of radiance `L`, seen by an orthographic camera
//! along the slab's normal: each ray runs exactly `d` inside, and the
//! image is `L exp(-sigma_a d)` on every pixel, with no noise (the only
//! lobe is the dielectric's refraction, and one channel absorbs nothing,
//! so Russian roulette always keeps the path).

use glam::Vec3;
use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;

use crate::common::render::{config, render_file};
use crate::common::scenes::{self, write};

/// Radiance of the emitter behind the slab.
const L: f32 = 2.0;

/// A closed box from `lo` to `hi` as TOML `positions` and `indices`, every
/// triangle wound counter-clockwise seen from outside (outward normals).
fn box_mesh(lo: Vec3, hi: Vec3) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let corner = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let positions: Vec<[f32; 3]> = (0..8).map(|i| corner(i).to_array()).collect();
    let centre = (lo + hi) / 2.0;
    // Each face: the four corners whose bit `axis` is `side`, in cyclic order.
    let mut indices = Vec::new();
    for axis in 0..3 {
        for side in 0..2u32 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let at = |u: u32, v: u32| (side << axis) | (u << a) | (v << b);
            let q = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)];
            let mut tris = [[q[0], q[1], q[2]], [q[0], q[2], q[3]]];
            for t in &mut tris {
                let [p0, p1, p2] = t.map(corner);
                let n = (p1 - p0).cross(p2 - p0);
                if n.dot((p0 + p1 + p2) / 3.0 - centre) < 0.0 {
                    t.swap(1, 2);
                }
            }
            indices.extend(tris);
        }
    }
    (positions, indices)
}

/// The emitter, the camera and `slab` (TOML objects or an include).
fn scene(slab: &str) -> String {
    format!(
        r#"
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
ortho_half_height = 0.5
[[objects]]
shape = {{ type = "polygon", vertices = [[-3, -3, -3], [3, -3, -3], [3, 3, -3], [-3, 3, -3]] }}
material = {{ color = 0.0, emission = {L} }}
{slab}
"#
    )
}

/// The slab as a TOML mesh object, `thickness` deep along z, with the
/// material `material`.
fn toml_slab(thickness: f32, material: &str) -> String {
    let (p, i) = box_mesh(
        Vec3::new(-1.0, -1.0, -thickness / 2.0),
        Vec3::new(1.0, 1.0, thickness / 2.0),
    );
    format!(
        "[[objects]]\nshape = {{ type = \"mesh\", positions = {p:?}, indices = {i:?} }}\nmaterial = {material}\n"
    )
}

/// Writes the slab as a glTF file (with its `.bin`) with the volume
/// extension `volume` and returns the TOML that includes it.
fn gltf_slab(dir: &std::path::Path, thickness: f32, volume: &str) -> String {
    let (p, i) = box_mesh(
        Vec3::new(-1.0, -1.0, -thickness / 2.0),
        Vec3::new(1.0, 1.0, thickness / 2.0),
    );
    let mut bytes: Vec<u8> = p.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    bytes.extend(i.iter().flatten().flat_map(|i| i.to_le_bytes()));
    std::fs::write(dir.join("slab.bin"), &bytes).unwrap();
    let h = thickness / 2.0;
    let gltf = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"],
  "buffers": [{{"byteLength": {len}, "uri": "slab.bin"}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 96}}, {{"buffer": 0, "byteOffset": 96, "byteLength": 144}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3", "min": [-1, -1, -{h}], "max": [1, 1, {h}]}},
    {{"bufferView": 1, "componentType": 5125, "count": 36, "type": "SCALAR"}}
  ],
  "materials": [{{"name": "absorbing glass",
                  "pbrMetallicRoughness": {{"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0}},
                  "extensions": {{"KHR_materials_transmission": {{"transmissionFactor": 1}},
                                  "KHR_materials_ior": {{"ior": 1.0}},
                                  "KHR_materials_volume": {volume}}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "nodes": [{{"mesh": 0}}],
  "scenes": [{{"nodes": [0]}}]
}}"#,
        len = bytes.len(),
    );
    write(dir, "slab.gltf", &gltf);
    "[[gltf]]\npath = \"slab.gltf\"\n".to_string()
}

/// Every transport and integrator the slab is rendered with.
fn setups() -> Vec<(Transport, IntegratorKind)> {
    let mut v = Vec::new();
    for t in [Transport::Whitted, Transport::Path] {
        for k in IntegratorKind::ALL {
            v.push((t, k));
        }
    }
    // Photon transport runs on the recursive integrator only.
    v.push((Transport::Photon, IntegratorKind::Recursive));
    v
}

fn render(path: &std::path::Path, transport: Transport, kind: IntegratorKind) -> Film {
    let settings = RenderSettings {
        width: 6,
        height: 6,
        spp: 1,
        transport,
        ..Default::default()
    };
    render_file(path, config(settings, kind)).film.unwrap()
}

/// Every pixel of `film` is `expected` within a relative 0.1%.
fn assert_every_pixel(film: &Film, expected: Vec3, what: &str) {
    for (i, p) in film.pixels.iter().enumerate() {
        let err = (*p - expected).abs().max_element() / expected.max_element();
        assert!(err < 1e-3, "{what}: pixel {i} is {p}, expected {expected}");
    }
}

/// Optical thickness tau = 1 and 4 in the red channel (half of it in
/// green, none in blue) from `absorption`: `L exp(-tau)` within 0.1%.
#[test]
fn absorbing_slab_from_the_project_format_follows_beer_lambert() {
    let dir = tempfile::tempdir().unwrap();
    let d = 0.5;
    for tau in [1.0f32, 4.0] {
        let sigma = Vec3::new(tau, tau / 2.0, 0.0) / d;
        let material = format!(
            "{{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, absorption = [{}, {}, {}] }}",
            sigma.x, sigma.y, sigma.z
        );
        let path = write(dir.path(), "slab.toml", &scene(&toml_slab(d, &material)));
        let expected = L * Vec3::new((-tau).exp(), (-tau / 2.0).exp(), 1.0);
        for (t, k) in setups() {
            let film = render(&path, t, k);
            assert_every_pixel(&film, expected, &format!("tau {tau}, {t:?}, {k:?}"));
        }
    }
}

/// The artist's form (`attenuation_color` after `attenuation_distance`)
/// and doubling the thickness: the transmittance squares.
#[test]
fn doubling_the_thickness_squares_the_transmittance() {
    let dir = tempfile::tempdir().unwrap();
    let c = Vec3::new(0.6, 0.3, 1.0);
    let material = "{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, attenuation_color = [0.6, 0.3, 1.0], attenuation_distance = 0.7 }";
    let mut centre = Vec::new();
    for d in [0.7f32, 1.4] {
        let path = write(dir.path(), "slab.toml", &scene(&toml_slab(d, material)));
        let film = render(&path, Transport::Path, IntegratorKind::Wavefront);
        centre.push(film.pixels[film.pixels.len() / 2]);
    }
    let (one, two) = (centre[0] / L, centre[1] / L);
    assert!(
        (one - c).abs().max_element() < 1e-3 * c.max_element(),
        "{one}"
    );
    assert!(
        (two - one * one).abs().max_element() < 1e-3,
        "{two} vs {}",
        one * one
    );
}

/// `KHR_materials_volume`: attenuation colour `exp(-tau)` after the
/// attenuation distance, which is the slab's thickness; a thin-walled
/// surface (thickness factor 0) absorbs nothing.
#[test]
fn absorbing_slab_from_gltf_follows_beer_lambert() {
    let dir = tempfile::tempdir().unwrap();
    let d = 0.5;
    for tau in [1.0f32, 4.0] {
        let c = Vec3::new((-tau).exp(), (-tau / 2.0).exp(), 1.0);
        let volume = format!(
            r#"{{"thicknessFactor": {d}, "attenuationDistance": {d}, "attenuationColor": [{}, {}, {}]}}"#,
            c.x, c.y, c.z
        );
        let include = gltf_slab(dir.path(), d, &volume);
        let path = write(dir.path(), "slab.toml", &scene(&include));
        for (t, k) in setups() {
            let film = render(&path, t, k);
            assert_every_pixel(&film, L * c, &format!("glTF, tau {tau}, {t:?}, {k:?}"));
        }
    }
    let thin = r#"{"thicknessFactor": 0, "attenuationDistance": 0.5, "attenuationColor": [0.1, 0.1, 0.1]}"#;
    let include = gltf_slab(dir.path(), d, thin);
    let path = write(dir.path(), "slab.toml", &scene(&include));
    let film = render(&path, Transport::Path, IntegratorKind::Recursive);
    assert_every_pixel(&film, Vec3::splat(L), "thin-walled glTF");
}

/// Negative or NaN coefficients, colours outside [0, 1] and distances that
/// are not positive are load errors naming the material or object.
#[test]
fn bad_absorption_parameters_are_errors_naming_the_owner() {
    let bad = [
        ("absorption = [1, -1, 0]", "non-negative"),
        ("absorption = [1, nan, 0]", "non-negative"),
        (
            "attenuation_color = [0.5, 1.5, 0.5], attenuation_distance = 1.0",
            "[0, 1]",
        ),
        (
            "attenuation_color = 0.5, attenuation_distance = -1.0",
            "positive",
        ),
        (
            "attenuation_color = 0.5, attenuation_distance = nan",
            "positive",
        ),
        ("attenuation_color = 0.5", "together"),
        (
            "absorption = 1.0, attenuation_color = 0.5, attenuation_distance = 1",
            "not both",
        ),
    ];
    for (params, says) in bad {
        let slab = format!(
            "[[objects]]\nname = \"the slab\"\nshape = {{ type = \"sphere\", radius = 1.0 }}\nmaterial = {{ transmission = 1.0, {params} }}\n"
        );
        let err = scenes::load_toml(&scene(&slab)).err().unwrap().to_string();
        assert!(
            err.contains("the slab") && err.contains(says),
            "{params}: {err}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    for (volume, says) in [
        (
            r#"{"thicknessFactor": 1, "attenuationDistance": -2}"#,
            "positive",
        ),
        (r#"{"thicknessFactor": -1}"#, "thicknessFactor"),
        (
            r#"{"thicknessFactor": 1, "attenuationDistance": 1, "attenuationColor": [2, 0, 0]}"#,
            "[0, 1]",
        ),
    ] {
        let include = gltf_slab(dir.path(), 0.5, volume);
        let path = write(dir.path(), "slab.toml", &scene(&include));
        let err = prism::io::load(&path, prism::geometry::mesh::BuildQuality::Medium)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("absorbing glass") && err.contains(says),
            "{volume}: {err}"
        );
    }
}
