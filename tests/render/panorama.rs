//! Panoramic cameras: a panorama rendered by Prism, read back as the
//! environment of an empty scene, reproduces the perspective render of the
//! scene it was made from; cube-map and equirectangular panoramas agree.

use std::sync::Arc;

use glam::{DVec3, Vec2};
use prism::core::math::Color;
use prism::core::settings::{Panorama, RenderSettings};
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::io::desc::SceneDesc;
use prism::scene::camera::{Camera, CameraRays};
use prism::scene::environment::{Environment, EnvironmentMap, EnvironmentSource};

use crate::common::render::{config, render_desc};
use crate::common::scenes::load_toml;

/// Matte spheres on an infinite floor around the eye, lit by a point
/// light: piecewise smooth radiance with edges (silhouettes, shadows) but
/// no feature thinner than a few degrees seen from the eye.
const SCENE: &str = r#"
[settings]
background = [0.2, 0.3, 0.5]
[camera]
look_from = [0.2, 1.0, 0.3]
look_at = [1.2, 1.0, 0.3]
[[objects]]
shape = { type = "plane" }
material = { color = [0.8, 0.7, 0.6] }
[[objects]]
shape = { type = "sphere", radius = 0.8 }
material = { color = [0.9, 0.2, 0.2] }
translate = [3, 0.8, 0.5]
[[objects]]
shape = { type = "sphere", radius = 0.6 }
material = { color = [0.2, 0.9, 0.3] }
translate = [-1.5, 0.6, 2.5]
[[objects]]
shape = { type = "sphere", radius = 1.0 }
material = { color = [0.3, 0.4, 0.9] }
translate = [0.5, 1.5, -3]
[[lights]]
type = "point"
position = [1, 5, 1]
intensity = 30
"#;

fn settings(width: u32, height: u32, panorama: Option<Panorama>) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp: 1,
        max_depth: 2,
        panorama,
        ..Default::default()
    }
}

/// The scene rendered from `camera` (the scene's own eye) with `settings`.
fn render_scene(camera: Camera, s: RenderSettings) -> Film {
    let mut desc = load_toml(SCENE).unwrap();
    desc.cameras = vec![camera];
    render_desc(desc, config(s, IntegratorKind::Recursive))
        .film
        .unwrap()
}

/// The eye looking along world `+X` with `+Y` up: the panorama's frame is
/// then the environment's.
fn panorama_camera() -> Camera {
    let eye = DVec3::new(0.2, 1.0, 0.3);
    Camera {
        look_from: eye,
        look_at: eye + DVec3::X,
        ..Camera::default()
    }
}

/// The eye looking a little up and to the side: the equator of its
/// panoramas is not the floor's horizon (on the horizon the last bit of a
/// direction decides between the sky and a floor point 1e8 away).
fn tilted_camera() -> Camera {
    let eye = DVec3::new(0.2, 1.0, 0.3);
    Camera {
        look_from: eye,
        look_at: eye + DVec3::new(1.0, 0.08, 0.05),
        ..Camera::default()
    }
}

/// Perspective views from the same eye, in several directions.
fn views() -> Vec<Camera> {
    let eye = DVec3::new(0.2, 1.0, 0.3);
    [
        DVec3::new(3.0, 0.8, 0.5),
        DVec3::new(-1.5, 0.3, 2.5),
        DVec3::new(0.5, 1.8, -3.0),
    ]
    .into_iter()
    .map(|at| Camera {
        look_from: eye,
        look_at: at,
        vfov_degrees: 50.0,
        ..Camera::default()
    })
    .collect()
}

/// Root mean square of the per-pixel difference, over the mean value.
fn relative_rmse(a: &Film, b: &Film) -> f64 {
    let n = a.pixels.len() as f64;
    let mse: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| ((*x - *y) * (*x - *y)).element_sum() as f64 / 3.0)
        .sum::<f64>()
        / n;
    let mean: f64 = b
        .pixels
        .iter()
        .map(|x| x.element_sum() as f64 / 3.0)
        .sum::<f64>()
        / n;
    mse.sqrt() / mean
}

/// The equirectangular panorama, read back as the environment of an empty
/// scene, seen from the same eye by perspective cameras in three
/// directions.
///
/// * The convention: every read-back pixel is exactly the panorama texel
///   its direction falls in (at most 0.5% of pixels, whose direction
///   rounds onto a texel border, read the neighbour).
/// * The filtering error: the environment is piecewise constant over
///   texels, so the read-back is a nearest-texel resampling of the
///   direct render. Its relative RMSE against the direct render comes
///   from pixels within a texel of a silhouette or shadow edge (a share
///   proportional to the texel size, so the RMSE goes as its square root)
///   and from the smooth shading's slope across a texel (proportional to
///   the texel size): each doubling of the panorama's resolution should
///   cut it by a factor between 1/2 and 1/sqrt(2), two doublings by 1/4
///   to 1/2. With edge pixels few enough for chance to matter we ask for
///   less than 0.7 over the two doublings (256x128 to 1024x512, 1.41 to
///   0.35 degrees a texel), and below 10% at 1024x512. Measured (worst of
///   the three views, printed): 12.5%, 9.3%, 6.2%.
#[test]
fn equirect_panorama_reads_back_as_the_environment() {
    let (w, h) = (64, 48);
    let directs: Vec<Film> = views()
        .into_iter()
        .map(|v| render_scene(v, settings(w, h, None)))
        .collect();
    let mut worst = Vec::new();
    for (pw, ph) in [(256, 128), (512, 256), (1024, 512)] {
        let pano = render_scene(
            panorama_camera(),
            settings(pw, ph, Some(Panorama::Equirect)),
        );
        assert!(pano.is_finite());
        let map = EnvironmentMap::new(pw, ph, pano.pixels.clone()).unwrap();
        let env = Environment::new(EnvironmentSource::Map(Arc::new(map)), 1.0, 0.0);
        let pano_rays = CameraRays::panoramic(
            &panorama_camera(),
            DVec3::ZERO,
            pw,
            ph,
            Some(Panorama::Equirect),
        );
        let pano_rays = pano_rays.panorama().unwrap();
        let mut errors = Vec::new();
        for (view, direct) in views().into_iter().zip(&directs) {
            let desc = SceneDesc {
                cameras: vec![view.clone()],
                environment: Some(env.clone()),
                ..Default::default()
            };
            let read_back = render_desc(
                desc,
                config(settings(w, h, None), IntegratorKind::Recursive),
            )
            .film
            .unwrap();
            let rays = CameraRays::new(&view, w, h);
            let mut exact = 0;
            for y in 0..h {
                for x in 0..w {
                    let d = rays
                        .ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5))
                        .direction;
                    let q = pano_rays.film_position(d);
                    let i = (q.x.floor() as i64).clamp(0, pw as i64 - 1) as u32;
                    let j = (q.y.floor() as i64).clamp(0, ph as i64 - 1) as u32;
                    if read_back.get(x, y) == pano.get(i, j) {
                        exact += 1;
                    }
                }
            }
            let n = (w * h) as usize;
            assert!(
                exact * 1000 >= n * 995,
                "{pw}x{ph}: only {exact} of {n} pixels read their own texel"
            );
            errors.push(relative_rmse(&read_back, direct));
        }
        eprintln!("{pw}x{ph}: relative RMSE per view {errors:.4?}");
        worst.push(errors.iter().copied().fold(0.0, f64::max));
    }
    eprintln!("worst relative RMSE at 256x128, 512x256, 1024x512: {worst:.4?}");
    assert!(worst[2] < 0.7 * worst[0], "{worst:?}");
    assert!(worst[2] < 0.10, "{worst:?}");
}

/// A cube-map and an equirectangular panorama of the scene from one eye
/// agree wherever both see.
///
/// * Where both sample the same direction they agree to f32 rounding:
///   with faces of 49 pixels and equirectangular maps 257 and 258 texels
///   wide (129 high), the centre pixels of the +X and -Z faces and the
///   texels at `u = 1/2` and `1/4` on the equator look exactly along the
///   axes of the camera (looking a little up, so that no pixel looks
///   exactly along the floor's horizon).
/// * Elsewhere each cube pixel is compared with the equirectangular texel
///   its direction falls in (what `--env` would read): the relative RMSE
///   is filtering error, so it falls as the equirectangular map gets
///   finer: by at least a fifth from 256x128 to 1024x512 (measured 8.2%,
///   7.4%, 5.7%: most of what is left is pixels along the floor's horizon,
///   a sky-to-black edge the tilted panorama's rows run along), and at
///   1024x512 nine pixels in ten agree within 2% (measured 95%).
#[test]
fn cube_map_agrees_with_equirect() {
    let face = 49;
    let cube = render_scene(
        tilted_camera(),
        settings(6 * face, face, Some(Panorama::Cubemap)),
    );
    assert!(cube.is_finite());
    // Texel centres fall on u = 1/2 for an odd width, on u = 1/4 for a
    // width of 4k + 2; on v = 1/2 for an odd height.
    for (f, (pw, u)) in [(0u32, (257, 128)), (5, (258, 64))] {
        let eq = render_scene(tilted_camera(), settings(pw, 129, Some(Panorama::Equirect)));
        let c = cube.get(f * face + 24, 24);
        let e = eq.get(u, 64);
        let rel = ((c - e).abs() / e.max(Color::splat(1e-3))).max_element();
        assert!(rel < 1e-4, "face {f}: cube {c} equirect {e}");
    }
    let cube_rays = CameraRays::panoramic(
        &tilted_camera(),
        DVec3::ZERO,
        6 * face,
        face,
        Some(Panorama::Cubemap),
    );
    let mut errors = Vec::new();
    let mut close = 0.0;
    for (pw, ph) in [(256, 128), (512, 256), (1024, 512)] {
        let equirect = render_scene(tilted_camera(), settings(pw, ph, Some(Panorama::Equirect)));
        let eq_rays = CameraRays::panoramic(
            &tilted_camera(),
            DVec3::ZERO,
            pw,
            ph,
            Some(Panorama::Equirect),
        );
        let eq = eq_rays.panorama().unwrap();
        let mut resampled = Film::new(6 * face, face);
        let mut within = 0;
        for y in 0..face {
            for x in 0..6 * face {
                let d = cube_rays
                    .ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5))
                    .direction;
                let q = eq.film_position(d);
                let i = (q.x.floor() as i64).clamp(0, pw as i64 - 1) as u32;
                let j = (q.y.floor() as i64).clamp(0, ph as i64 - 1) as u32;
                let e = equirect.get(i, j);
                resampled.pixels[(y * 6 * face + x) as usize] = e;
                let c = cube.get(x, y);
                if ((c - e).abs() / c.max(Color::splat(1e-3))).max_element() < 0.02 {
                    within += 1;
                }
            }
        }
        errors.push(relative_rmse(&resampled, &cube));
        close = within as f64 / (6 * face * face) as f64;
    }
    eprintln!(
        "relative RMSE at 256x128, 512x256, 1024x512: {errors:.4?}; within 2% at 1024x512: {close:.3}"
    );
    assert!(errors[2] < 0.8 * errors[0], "{errors:?}");
    assert!(close >= 0.9, "{close}");
}
