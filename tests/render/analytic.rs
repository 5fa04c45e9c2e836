//! System tests: small scenes rendered end to end, checked against what
//! geometry and radiometry say the image must be.

use std::f32::consts::PI;
use std::path::Path;

use glam::{Quat, Vec2, Vec3, Vec3A};
use prism::core::settings::RenderSettings;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::camera::{Camera, CameraRays};

use crate::common::cli::{assert_success, prism};
use crate::common::images::film_bits;
use crate::common::render::{config, render_desc, sized};
use crate::common::scenes::lambert::{self, ALBEDO, E_LUX, THETA_DEG};
use crate::common::scenes::{self, glass_ball, write};
use crate::common::{assets, render};

fn render_file(
    path: &Path,
    width: u32,
    height: u32,
) -> (Film, prism::integrators::counters::RenderCounters) {
    let frame = render::render_file(
        path,
        config(sized(width, height), IntegratorKind::default()),
    );
    (frame.film.unwrap(), frame.counters)
}

/// Renders with the `prism` binary to an EXR and reads it back.
fn render_exr_with_binary(scene: &Path, dir: &Path, width: u32, height: u32) -> Film {
    let out = dir.join(format!(
        "{}.exr",
        scene.file_stem().unwrap().to_str().unwrap()
    ));
    let status = prism()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(&out)
        .args([
            "--width",
            &width.to_string(),
            "--height",
            &height.to_string(),
            "--quiet",
        ])
        .output()
        .unwrap();
    assert_success(&status);
    prism::image::output::read_image(&out).unwrap()
}

/// Checks that the central quarter of the image (all on the quad) has the
/// analytic radiance within 0.5 %.
fn assert_lambert_quad(film: &Film) {
    let (w, h) = (film.width, film.height);
    lambert::assert_lit(film, w / 4..3 * w / 4, h / 4..3 * h / 4, "the quad");
}

#[test]
fn lambertian_quad_from_the_project_format() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lambert::lit_floor(&format!(
        r#"
[[objects]]
shape = {{ type = "polygon", vertices = [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]] }}
material = {{ color = {ALBEDO}, diffuse = 1.0 }}
"#
    ));
    let path = write(dir.path(), "quad.toml", &scene);
    let film = render_exr_with_binary(&path, dir.path(), 32, 32);
    assert_lambert_quad(&film);
}

#[test]
fn lambertian_quad_from_gltf() {
    let dir = tempfile::tempdir().unwrap();
    // Quad in y = 0, two triangles, counter-clockwise seen from +Y.
    let floats: [f32; 12] = [-2., 0., -2., -2., 0., 2., 2., 0., 2., 2., 0., -2.];
    let indices: [u32; 6] = [0, 1, 2, 0, 2, 3];
    let mut bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
    bytes.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    std::fs::write(dir.path().join("quad.bin"), &bytes).unwrap();
    // Camera: -Z turned to -Y. Light: -Z turned to (sin t, -cos t, 0).
    let cam = Quat::from_rotation_x(-PI / 2.0);
    let light = Quat::from_rotation_z(THETA_DEG.to_radians()) * cam;
    let q = |q: Quat| format!("[{}, {}, {}, {}]", q.x, q.y, q.z, q.w);
    let gltf = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_specular"],
  "extensions": {{"KHR_lights_punctual": {{"lights": [{{"type": "directional", "intensity": {E_LUX}}}]}}}},
  "buffers": [{{"byteLength": 72, "uri": "quad.bin"}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}}, {{"buffer": 0, "byteOffset": 48, "byteLength": 24}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-2, 0, -2], "max": [2, 0, 2]}},
    {{"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}}
  ],
  "materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [{ALBEDO}, {ALBEDO}, {ALBEDO}, 1], "metallicFactor": 0, "roughnessFactor": 1}},
                  "extensions": {{"KHR_materials_specular": {{"specularFactor": 0}}}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": {}, "znear": 0.1}}}}],
  "nodes": [
    {{"mesh": 0}},
    {{"camera": 0, "translation": [0, 3, 0], "rotation": {}}},
    {{"rotation": {}, "extensions": {{"KHR_lights_punctual": {{"light": 0}}}}}}
  ],
  "scenes": [{{"nodes": [0, 1, 2]}}]
}}"#,
        30f32.to_radians(),
        q(cam),
        q(light)
    );
    let path = write(dir.path(), "quad.gltf", &gltf);
    let film = render_exr_with_binary(&path, dir.path(), 32, 32);
    assert_lambert_quad(&film);
}

#[test]
fn mirror_shows_the_object_it_faces() {
    // Camera at z = 4 looks at a mirror in the plane z = 0; a lit red
    // sphere sits behind the camera at z = 8, so the mirror's centre
    // reflects it. Replacing the mirror by grey paint removes the red.
    let dir = tempfile::tempdir().unwrap();
    let scene = |mirror: &str| {
        format!(
            r#"
[camera]
look_from = [0, 0, 4]
look_at = [0, 0, 0]
vfov = 30
[[objects]]
shape = {{ type = "polygon", vertices = [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]] }}
material = {mirror}
[[objects]]
shape = {{ type = "sphere", radius = 1.5 }}
material = {{ color = [0.9, 0.05, 0.05] }}
translate = [0, 0, 8]
[[lights]]
type = "point"
position = [0, 4, 6]
intensity = 50
"#
        )
    };
    let mirror = write(
        dir.path(),
        "mirror.toml",
        &scene("{ color = 0.0, diffuse = 0.0, mirror = 1.0 }"),
    );
    let paint = write(dir.path(), "paint.toml", &scene("{ color = 0.5 }"));
    let (film, _) = render_file(&mirror, 33, 33);
    let c = film.get(16, 16);
    assert!(
        c.x > 0.05 && c.x > 5.0 * c.y && c.x > 5.0 * c.z,
        "mirror centre should show the red sphere: {c}"
    );
    let (film, _) = render_file(&paint, 33, 33);
    let c = film.get(16, 16);
    assert!(
        (c.x - c.y).abs() < 1e-6 && (c.y - c.z).abs() < 1e-6,
        "painted wall is grey: {c}"
    );
}

#[test]
fn glass_sphere_shows_the_pattern_behind_it_inverted() {
    // An emissive backdrop at z = -4: red above y = 0, blue below. A glass
    // ball (n = 1.5, R = 1, focal length 1.5 R from its centre) images it
    // inverted: through the ball, above the centre shows blue.
    let dir = tempfile::tempdir().unwrap();
    let scene = glass_ball(
        r#"[[objects]]
shape = { type = "polygon", vertices = [[-8, -8, -4], [8, -8, -4], [8, 0, -4], [-8, 0, -4]] }
material = { color = 0.0, emission = [0, 0, 1] }
"#,
    );
    let path = write(dir.path(), "lens.toml", &scene);
    let (w, h) = (41, 41);
    let (film, counters) = render_file(&path, w, h);
    assert!(counters.rays.refraction > 0);
    let cam = CameraRays::new(
        &Camera {
            look_from: glam::DVec3::new(0.0, 0.0, 10.0),
            look_at: glam::DVec3::ZERO,
            up: Vec3::Y,
            vfov_degrees: 20.0,
            shift: glam::Vec2::ZERO,
            name: None,
            ..Default::default()
        },
        w,
        h,
    );
    let (mut inside, mut outside) = (0, 0);
    for y in 0..h {
        let x = w / 2;
        let ray = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
        // Height at which the ray passes the sphere's centre plane.
        let s = -ray.origin.z / ray.direction.z;
        let b = ray.at(s).y;
        let c = film.get(x, y);
        let (red, blue) = (c.x > 2.0 * c.z, c.z > 2.0 * c.x);
        if b.abs() > 0.15 && b.abs() < 0.6 {
            inside += 1;
            if b > 0.0 {
                assert!(
                    blue,
                    "through the ball above centre (b={b}) expected blue, got {c}"
                );
            } else {
                assert!(
                    red,
                    "through the ball below centre (b={b}) expected red, got {c}"
                );
            }
        } else if b.abs() > 1.1 {
            outside += 1;
            if b > 0.0 {
                assert!(red, "beside the ball above (b={b}) expected red, got {c}");
            } else {
                assert!(blue, "beside the ball below (b={b}) expected blue, got {c}");
            }
        }
    }
    assert!(inside >= 6 && outside >= 6, "{inside} {outside}");
}

#[test]
fn shadows_fall_where_geometry_says() {
    // A sphere of radius 1 at height 2 above a grey floor, sun straight
    // down: the shadow is exactly the unit disk under the sphere.
    let dir = tempfile::tempdir().unwrap();
    let scene = r#"
[camera]
look_from = [0, 6, 6]
look_at = [0, 0, 0]
vfov = 45
[[objects]]
shape = { type = "plane" }
material = { color = 0.5 }
[[objects]]
shape = { type = "sphere", radius = 1.0 }
material = { color = 0.5 }
translate = [0, 2, 0]
[[lights]]
type = "directional"
direction = [0, -1, 0]
illuminance = 3.0
"#;
    let path = write(dir.path(), "shadow.toml", scene);
    let (w, h) = (64, 64);
    let (film, _) = render_file(&path, w, h);
    let cam = CameraRays::new(
        &Camera {
            look_from: glam::DVec3::new(0.0, 6.0, 6.0),
            look_at: glam::DVec3::ZERO,
            up: Vec3::Y,
            vfov_degrees: 45.0,
            shift: glam::Vec2::ZERO,
            name: None,
            ..Default::default()
        },
        w,
        h,
    );
    let lit = 0.5 / PI * 3.0;
    let centre = Vec3A::new(0.0, 2.0, 0.0);
    let (mut shadowed, mut lit_count) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            // Skip pixels that see the sphere.
            let oc = ray.origin - centre;
            let b = oc.dot(ray.direction);
            if b * b - (oc.length_squared() - 1.0) > -0.05 {
                continue;
            }
            if ray.direction.y >= 0.0 {
                continue;
            }
            let p = ray.at(-ray.origin.y / ray.direction.y);
            let r = Vec2::new(p.x, p.z).length();
            let v = film.get(x, y).x;
            if r < 0.9 {
                shadowed += 1;
                assert_eq!(v, 0.0, "pixel ({x},{y}) at r={r} p={p} should be in shadow");
            } else if r > 1.1 {
                lit_count += 1;
                assert!(
                    (v - lit).abs() < 1e-4 * lit,
                    "pixel ({x},{y}) at r={r}: {v} vs {lit}"
                );
            }
        }
    }
    assert!(shadowed > 20 && lit_count > 1000, "{shadowed} {lit_count}");
}

#[test]
fn example_scenes_render_without_nan_or_inf() {
    for name in ["whitted.toml", "quadrics.toml", "gltf/showroom.gltf"] {
        let (film, counters) = render_file(&assets().join(name), 48, 36);
        assert!(film.is_finite(), "{name} has non-finite pixels");
        assert_eq!(counters.nonfinite_samples, 0, "{name}");
        assert!(
            film.pixels.iter().any(|p| p.max_element() > 0.0),
            "{name} rendered black"
        );
    }
}

#[test]
fn same_seed_same_image_whatever_the_thread_count() {
    let path = assets().join("whitted.toml");
    let render_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let settings = RenderSettings {
                width: 40,
                height: 30,
                spp: 3,
                seed: 11,
                ..Default::default()
            };
            let config = config(settings, IntegratorKind::default());
            render_desc(scenes::load(&path), config).film.unwrap()
        })
    };
    let a = render_with(1);
    let b = render_with(2);
    let c = render_with(2);
    assert_eq!(film_bits(&a), film_bits(&b));
    assert_eq!(film_bits(&b), film_bits(&c));
}

#[test]
fn quadric_hit_points_lie_on_the_surface_so_shadow_rays_do_not_self_intersect() {
    // Camera rays from 10 units away onto every open quadric; each hit
    // point's shadow ray (offset off the surface) towards a light must not
    // hit the same shape again. Before Newton refinement of the roots, a
    // quarter of the cone's lit points shadowed themselves.
    use prism::core::math::Ray;
    use prism::core::optics::offset_origin_relative;
    use prism::geometry::shapes::Shape;
    let shapes = [
        Shape::Cone {
            radius: 0.7,
            height: 1.8,
        },
        Shape::Paraboloid {
            radius: 0.7,
            height: 1.4,
        },
        Shape::Hyperboloid {
            waist_radius: 0.35,
            top_radius: 0.7,
            half_height: 0.9,
        },
        Shape::Cylinder {
            radius: 0.6,
            y_min: 0.0,
            y_max: 1.6,
        },
        Shape::Ellipsoid {
            radii: Vec3::new(0.9, 0.6, 0.6),
        },
        Shape::Sphere { radius: 0.8 },
    ];
    let cam = CameraRays::new(
        &Camera {
            look_from: glam::DVec3::new(0.0, 3.2, 10.0),
            look_at: glam::DVec3::new(0.0, 0.8, 0.0),
            up: Vec3::Y,
            vfov_degrees: 12.0,
            shift: glam::Vec2::ZERO,
            name: None,
            ..Default::default()
        },
        120,
        120,
    );
    let light = Vec3A::new(-3.0, 6.0, 4.5);
    for shape in &shapes {
        let (mut lit, mut self_shadowed) = (0, 0);
        for y in 0..120 {
            for x in 0..120 {
                let r = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                let Some(h) = shape.intersect(&r, 0.0, f32::INFINITY) else {
                    continue;
                };
                // As the shading path does: the object-space surface point
                // and the scale-free relative offset.
                let p = h.point;
                let n = h.normal.normalize();
                let ng = if n.dot(r.direction) < 0.0 { n } else { -n };
                let wi = (light - p).normalize();
                if ng.dot(wi) <= 0.0 {
                    continue;
                }
                lit += 1;
                let shadow = Ray::new(offset_origin_relative(p, ng), wi);
                // Open surfaces may legitimately shadow themselves far away
                // (the inside wall); acne is a hit right at the origin.
                if let Some(s) = shape.intersect(&shadow, 0.0, f32::INFINITY)
                    && s.t < 1e-2
                {
                    self_shadowed += 1;
                }
            }
        }
        assert!(lit > 500, "{shape:?}: only {lit} lit hits");
        assert_eq!(
            self_shadowed, 0,
            "{shape:?}: acne on {self_shadowed} of {lit}"
        );
    }
}
