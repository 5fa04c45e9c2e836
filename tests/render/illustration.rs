//! Rendering for illustration: Gooch shading against its closed form in
//! both integrators, feature lines from ray casting, and their vector form.

use glam::DVec3;
use prism::core::settings::Style;
use prism::io::desc::SettingsDesc;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;

use crate::common::render::{config, render_desc};
use crate::common::scenes::load_toml;

/// A unit sphere of base colour (0.8, 0.2, 0.2) at the origin seen from
/// (0, 0, 10) with a narrow field, lit by a directional light arriving from
/// `towards_light`, in the Gooch style.
fn gooch_sphere_toml(towards_light: [f64; 3], vfov: f64, extra: &str) -> String {
    let d = towards_light.map(|c| -c);
    format!(
        r#"
[settings]
style = "gooch"
{extra}
[camera]
look_from = [0, 0, 10]
look_at = [0, 0, 0]
vfov = {vfov}
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {{ color = [0.8, 0.2, 0.2] }}
[[lights]]
type = "directional"
direction = [{}, {}, {}]
illuminance = 3
"#,
        d[0], d[1], d[2]
    )
}

/// The f64 ray through film position `(px, py)` of a camera at (0, 0, 10)
/// looking at the origin with +Y up: the same construction as
/// `CameraRays`, in double precision.
fn ray_f64(px: f64, py: f64, w: u32, h: u32, vfov: f64) -> (DVec3, DVec3) {
    let origin = DVec3::new(0.0, 0.0, 10.0);
    let forward = DVec3::new(0.0, 0.0, -1.0);
    let right = DVec3::X;
    let up = DVec3::Y;
    let half_h = (vfov.to_radians() * 0.5).tan();
    let half_w = half_h * w as f64 / h as f64;
    let top_left = forward - right * half_w + up * half_h;
    let dx = right * (2.0 * half_w / w as f64);
    let dy = -up * (2.0 * half_h / h as f64);
    (origin, (top_left + dx * px + dy * py).normalize())
}

/// Closest hit of a unit ray on the unit sphere at the origin, and how far
/// the ray passes from grazing (1 - its distance from the centre).
fn unit_sphere_hit(o: DVec3, d: DVec3) -> Option<(DVec3, f64)> {
    let b = o.dot(d);
    let c = o.length_squared() - 1.0;
    let disc = b * b - c;
    let miss_distance = (o - d * b).length();
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    Some((o + d * t, 1.0 - miss_distance))
}

/// Gooch's colour in closed form, default parameters.
fn gooch_f64(kd: DVec3, n_dot_l: f64) -> DVec3 {
    let t = (1.0 + n_dot_l) / 2.0;
    let cool = DVec3::new(0.0, 0.0, 0.4) + kd * 0.2;
    let warm = DVec3::new(0.4, 0.4, 0.0) + kd * 0.6;
    warm * t + cool * (1.0 - t)
}

fn pixel(f: &Film, x: u32, y: u32) -> glam::Vec3 {
    f.pixels[(y * f.width + x) as usize]
}

#[test]
fn gooch_sphere_matches_the_closed_form_at_every_pixel_in_both_integrators() {
    let (w, h, vfov) = (64u32, 64u32, 12.0);
    let l = DVec3::new(1.0, 0.5, 0.0).normalize();
    let desc = || load_toml(&gooch_sphere_toml(l.to_array(), vfov, "")).unwrap();
    let kd = DVec3::new(0.8, 0.2, 0.2);
    // The scene file's [settings] ask for the style.
    let settings = SettingsDesc {
        width: Some(w),
        height: Some(h),
        ..Default::default()
    }
    .resolve(&desc().settings);
    assert_eq!(settings.style, Style::Gooch);
    let mut n_dot_l_range = (f64::INFINITY, f64::NEG_INFINITY);
    for kind in IntegratorKind::ALL {
        let frame = render_desc(desc(), config(settings.clone(), kind));
        assert_eq!(frame.counters.rays.shadow, 0, "Gooch traces no shadow rays");
        let film = frame.film.unwrap();
        let mut checked = 0;
        for y in 0..h {
            for x in 0..w {
                let (o, d) = ray_f64(x as f64 + 0.5, y as f64 + 0.5, w, h, vfov);
                let got = pixel(&film, x, y);
                let want = match unit_sphere_hit(o, d) {
                    // Rays within 1e-5 of grazing: f32 and f64 may disagree
                    // on hit or miss.
                    Some((_, margin)) if margin < 1e-5 => continue,
                    Some((p, _)) => {
                        let ndl = p.normalize().dot(l);
                        n_dot_l_range.0 = n_dot_l_range.0.min(ndl);
                        n_dot_l_range.1 = n_dot_l_range.1.max(ndl);
                        gooch_f64(kd, ndl)
                    }
                    None => DVec3::ZERO,
                };
                let err = (got.as_dvec3() - want).abs().max_element();
                assert!(
                    err <= 1e-4,
                    "{kind:?} pixel ({x}, {y}): {got} against the closed form {want}"
                );
                checked += 1;
            }
        }
        assert!(checked > w * h - 16, "{checked} pixels checked");
    }
    // The sphere shows the whole range of tones.
    assert!(n_dot_l_range.0 < -0.9 && n_dot_l_range.1 > 0.9, "{n_dot_l_range:?}");
}
