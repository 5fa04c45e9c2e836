//! Texture level of detail (ray cones and mipmaps): a checkerboard plane
//! seen at grazing angles renders at 1 sample per pixel as the converged
//! (1024-sample) image does far away, for a procedural checkerboard and
//! for a mipmapped image of one; and the mipmap level a hit reads is the
//! one the ray-cone rule gives, computed here independently in f64.

use std::path::Path;
use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3};
use prism::accel::build::BuildQuality;
use prism::core::math::Color;
use prism::core::settings::{RenderSettings, Transport};
use prism::geometry::shapes::Shape;
use prism::geometry::transform::Transform;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::camera::{Camera, CameraRays};
use prism::scene::material::{ImageTexture, Material, Texture, TextureSampler, UvTransform};
use prism::scene::{Instance, InstanceGeometry, RenderScene};
use prism::transport::interaction::Interaction;

use crate::common::images::film_bits;
use crate::common::render::{config, render_file, render_toml, sized};
use crate::common::rng::{Random, SplitMix64};

const W: u32 = 64;
const H: u32 = 48;
const VFOV: f64 = 30.0;
/// Camera height over the plane and the depth of the point it looks at
/// (on the plane's horizon side): a grazing view.
const EYE_Y: f64 = 1.0;
const LOOK_Z: f64 = -6.0;

/// The grazing scene: a camera at height 1 looking at a point 6 units
/// away on the plane `y = 0`, which carries `texture` and is lit from
/// straight above.
fn grazing_scene(texture: &str) -> String {
    format!(
        r#"
[camera]
look_from = [0, {EYE_Y}, 0]
look_at = [0, 0, {LOOK_Z}]
vfov = {VFOV}

[[lights]]
type = "directional"
direction = [0, -1, 0]
illuminance = 3.14159265

[[objects]]
shape = {{ type = "plane" }}
material = {{ color = 1.0, diffuse = 1.0, texture = {texture} }}
"#
    )
}

fn render(text: &str, spp: u32) -> Film {
    let settings = RenderSettings {
        spp,
        max_depth: 0,
        ..sized(W, H)
    };
    render_toml(text, config(settings, IntegratorKind::Recursive))
        .film
        .unwrap()
}

/// The width, in checker squares of side `square`, of the footprint of
/// row `y`'s centre pixel on the plane (one pixel's angle times the
/// distance, over the cosine of incidence; f64, from the camera's
/// geometry), or `None` above the horizon.
fn footprint_squares(y: u32, square: f64) -> Option<f64> {
    let forward = DVec3::new(0.0, -EYE_Y, LOOK_Z).normalize();
    let right = forward.cross(DVec3::Y).normalize();
    let up = right.cross(forward);
    let tan = (VFOV / 2.0).to_radians().tan();
    let pixel = 2.0 * tan / H as f64;
    let dir = (forward + up * (tan - pixel * (y as f64 + 0.5))).normalize();
    if dir.y >= 0.0 {
        return None;
    }
    let t = EYE_Y / -dir.y;
    Some(pixel * t / -dir.y / square)
}

/// Rows whose pixels each cover at least ten squares (where a one-sample
/// image without filtering aliases) and at most 200 (short of the horizon).
fn far_rows(square: f64) -> Vec<u32> {
    (0..H)
        .filter(|&y| footprint_squares(y, square).is_some_and(|n| (10.0..200.0).contains(&n)))
        .collect()
}

/// Every pixel of the far rows of the 1-sample image within 2% of the
/// 1024-sample image (the converged pixel average), and those rows near
/// the checkerboard's mean, half the white level.
fn assert_no_moire(text: &str, square: f64, what: &str) {
    let rows = far_rows(square);
    assert!(rows.len() >= 4, "{what}: only {} far rows", rows.len());
    let one = render(text, 1);
    let reference = render(text, 1024);
    // The white level: albedo 1 under E = pi from straight above.
    let white = 1.0f64;
    let mut worst = 0.0f64;
    for &y in &rows {
        for x in 0..W {
            let a = one.get(x, y).x as f64;
            let b = reference.get(x, y).x as f64;
            assert!(a.is_finite() && b.is_finite());
            let e = (a - b).abs() / b;
            worst = worst.max(e);
            assert!(
                e < 0.02,
                "{what}: pixel ({x}, {y}) at 1 spp is {a}, at 1024 spp {b} ({:.1}% apart)",
                100.0 * e
            );
            assert!(
                (b - 0.5 * white).abs() < 0.02 * white,
                "{what}: reference pixel ({x}, {y}) is {b}, not the mean 0.5"
            );
        }
    }
    eprintln!(
        "{what}: {} far rows, worst 1-spp pixel {:.2}% from the 1024-spp image",
        rows.len(),
        100.0 * worst
    );
}

/// A procedural checkerboard of squares 0.25 wide.
#[test]
fn grazing_procedural_checkerboard_does_not_alias() {
    let text = grazing_scene("{ checker = { scale = 4.0, even = 1.0, odd = 0.0 } }");
    assert_no_moire(&text, 0.25, "procedural checker");
}

/// Writes a 64x64 PNG of 8x8-texel black and white squares (eight squares
/// per unit of the plane's texture coordinates).
fn checker_png(dir: &Path) -> std::path::PathBuf {
    let img = image::RgbImage::from_fn(64, 64, |x, y| {
        if (x / 8 + y / 8) % 2 == 0 {
            image::Rgb([255, 255, 255])
        } else {
            image::Rgb([0, 0, 0])
        }
    });
    let path = dir.join("checker.png");
    img.save(&path).unwrap();
    path
}

/// The same with an image of the checkerboard, read through its mipmaps.
#[test]
fn grazing_image_checkerboard_does_not_alias() {
    let dir = tempfile::tempdir().unwrap();
    let png = checker_png(dir.path());
    let text = grazing_scene(&format!(
        "{{ image = {{ path = {:?} }} }}",
        png.to_str().unwrap()
    ));
    assert_no_moire(&text, 0.125, "image checker");
}

/// A 32x32 texture of random texels, so that every mipmap level and every
/// blend between two reads a different value.
fn noise_texture() -> Arc<ImageTexture> {
    let mut rng = SplitMix64(19);
    let texels = (0..32 * 32)
        .map(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()))
        .collect();
    Arc::new(ImageTexture::new(32, 32, texels))
}

/// The level a hit reads: a camera looks at the plane `y = 0`, scaled by
/// `s` (so its texture coordinates per unit length are `1 / s`), from
/// several heights and angles; the colour of each centre-pixel hit equals
/// the trilinear lookup at the level `log2(beta t / cos / s * 32)` (beta
/// the pixel's angle, t the distance, cos the incidence cosine, 32 texels
/// across), computed here in f64, and differs from the lookups a quarter
/// level either side (so the comparison can tell levels apart). The
/// cases span the full-resolution image (level below 0), blends, and
/// beyond the last level.
#[test]
fn a_hit_reads_the_mip_level_of_its_ray_cone() {
    let image = noise_texture();
    let sampler = TextureSampler::default();
    let material = Material {
        base_color: Color::ONE,
        base_color_texture: Some(Texture::Image {
            image: image.clone(),
            transform: UvTransform::default(),
            sampler,
        }),
        ..Default::default()
    };
    let mut seen = Vec::new();
    for (s, height, tilt) in [
        (1.0, 0.5, 0.0),
        (2.0, 3.0, 0.3),
        (0.5, 4.0, 0.6),
        (1.0, 40.0, 0.2),
        (0.25, 200.0, 0.1),
    ] {
        let scene = RenderScene::new(
            vec![Instance::new(
                InstanceGeometry::Shape(Shape::Plane),
                &Transform::from_trs(DVec3::ZERO, Default::default(), DVec3::splat(s)),
                0,
            )],
            vec![material.clone()],
            Vec::new(),
            Color::ZERO,
            BuildQuality::Medium,
        );
        let camera = Camera {
            look_from: DVec3::new(0.1, height, 0.2),
            look_at: DVec3::new(0.1 + height * tilt, 0.0, 0.2),
            up: glam::Vec3::Z,
            vfov_degrees: 40.0,
            ..Default::default()
        };
        let (w, h) = (33, 25);
        let rays = CameraRays::new(&camera, w, h);
        let ray = rays.ray(Vec2::new(w as f32 / 2.0, h as f32 / 2.0));
        let hit = scene.intersect(&ray, 0.0, f32::INFINITY).unwrap();
        let it = Interaction::with_cone(&scene, &ray, &hit, rays.cone());

        let beta = 2.0 * (20.0f64).to_radians().tan() / h as f64;
        let d = DVec3::new(
            ray.direction.x as f64,
            ray.direction.y as f64,
            ray.direction.z as f64,
        )
        .normalize();
        let t = height / -d.y;
        let cos = -d.y;
        let level = (beta * t / cos / s * 32.0).log2();
        let at = |l: f64| image.sample_level(hit.uv, sampler, l as f32);
        let expected = at(level);
        let got = it.surface.base;
        assert!(
            (got - expected).abs().max_element() < 2e-4,
            "scale {s}, height {height}: level {level:.3} reads {expected}, the hit read {got}"
        );
        if level > 0.25 && level < 4.75 {
            for l in [level - 0.25, level + 0.25] {
                assert!(
                    (at(l) - expected).abs().max_element() > 1e-3,
                    "level {level:.3}: a quarter level away reads the same ({})",
                    at(l)
                );
            }
        }
        seen.push(level);
    }
    assert!(seen.iter().any(|&l| l < 0.0), "{seen:?}");
    assert!(
        seen.iter().any(|&l| l > 0.0 && l < 5.0 && l.fract() > 0.1),
        "{seen:?}"
    );
    assert!(seen.iter().any(|&l| l > 5.0), "{seen:?}");
    eprintln!("levels checked: {seen:?}");
}

/// Both integrators read the same mip levels: `assets/texture_lod.toml`
/// (a grazing checkerboard to the horizon and a mirror ball) under both
/// transports, 1 sample per pixel, the same bits. The wavefront carries
/// each hit's distance along the ray; it had multiplied it by the
/// direction's length a second time, which changed the cone's width in its
/// last bit wherever a direction was not exactly of unit length, and with
/// it the filtered texture (1.5e-6 apart on 159 of 3072 pixels).
#[test]
fn both_integrators_read_the_same_mip_levels() {
    let path = crate::common::assets().join("texture_lod.toml");
    for transport in [Transport::Whitted, Transport::Path] {
        let settings = RenderSettings {
            spp: 1,
            transport,
            ..sized(W, H)
        };
        let [rec, wav] = [IntegratorKind::Recursive, IntegratorKind::Wavefront].map(|kind| {
            render_file(&path, config(settings.clone(), kind))
                .film
                .unwrap()
        });
        let (a, b) = (film_bits(&rec), film_bits(&wav));
        let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert_eq!(differ, 0, "{transport:?}: channels that differ");
    }
}
