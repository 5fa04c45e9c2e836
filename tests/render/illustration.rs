//! Rendering for illustration: Gooch shading against its closed form in
//! both integrators, feature lines from ray casting, and their vector form.

use glam::DVec3;
use prism::core::settings::{LineSettings, RenderSettings, Style};
use prism::image::film::Film;
use prism::image::lines::LineOverlay;
use prism::image::output::{PngOptions, write_image_with_lines};
use prism::integrators::IntegratorKind;
use prism::integrators::vector_lines::{EdgeKind, VectorLines, to_svg, vector_lines};
use prism::integrators::wavefront::Stage;
use prism::io::desc::SettingsDesc;
use prism::scene::camera::CameraRays;

use crate::common::images::assert_same_image;
use crate::common::render::{config, render_desc, renderer};
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
    assert!(
        n_dot_l_range.0 < -0.9 && n_dot_l_range.1 > 0.9,
        "{n_dot_l_range:?}"
    );
}

// ---------------------------------------------------------------------------
// Feature lines

/// A pinhole camera in f64, built as `CameraRays` builds it: the
/// independent projection the line tests compare against.
pub(crate) struct Pinhole {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    half_w: f64,
    half_h: f64,
    w: f64,
    h: f64,
}

impl Pinhole {
    pub(crate) fn new(eye: [f64; 3], at: [f64; 3], vfov: f64, w: u32, h: u32) -> Self {
        let eye = DVec3::from(eye);
        let forward = (DVec3::from(at) - eye).normalize();
        let right = forward.cross(DVec3::Y).normalize();
        let up = right.cross(forward);
        let half_h = (vfov.to_radians() * 0.5).tan();
        Self {
            eye,
            right,
            up,
            forward,
            half_w: half_h * w as f64 / h as f64,
            half_h,
            w: w as f64,
            h: h as f64,
        }
    }

    /// Distance of world point `p` in front of the eye along the view.
    pub(crate) fn depth(&self, p: DVec3) -> f64 {
        (p - self.eye).dot(self.forward)
    }

    /// Film position in pixels of world point `p`.
    pub(crate) fn project(&self, p: DVec3) -> glam::DVec2 {
        let d = p - self.eye;
        let z = d.dot(self.forward);
        let (x, y) = (d.dot(self.right) / z, d.dot(self.up) / z);
        glam::DVec2::new(
            (x + self.half_w) / (2.0 * self.half_w) * self.w,
            (self.half_h - y) / (2.0 * self.half_h) * self.h,
        )
    }
}

/// Distance from `p` to the segment `a`-`b`.
fn to_segment(p: glam::DVec2, a: glam::DVec2, b: glam::DVec2) -> f64 {
    let d = b - a;
    let t = ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
    (a + d * t - p).length()
}

/// Settings at `w` x `h` with lines of width 1 and crease angle `crease`.
fn line_settings(w: u32, h: u32, crease: f32) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        lines: Some(LineSettings {
            crease_degrees: crease,
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn overlay(toml: &str, s: &RenderSettings, kind: IntegratorKind) -> LineOverlay {
    let frame = render_desc(load_toml(toml).unwrap(), config(s.clone(), kind));
    frame.lines.expect("lines were asked for")
}

const SPHERE_AT_FIVE: &str = r#"
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
vfov = 40
[[objects]]
shape = { type = "sphere", radius = 1.0 }
[[lights]]
type = "point"
position = [2, 3, 4]
intensity = 20
"#;

#[test]
fn sphere_silhouette_is_the_circle_of_angular_radius_asin_r_over_d() {
    let (w, h) = (96u32, 96u32);
    let lines = overlay(
        SPHERE_AT_FIVE,
        &line_settings(w, h, 45.57),
        IntegratorKind::Recursive,
    );
    let cam = Pinhole::new([0.0, 0.0, 5.0], [0.0; 3], 40.0, w, h);
    // The silhouette's angular radius asin(r/d), on the image plane.
    let rho = (1.0f64 / 5.0).asin().tan() / cam.half_h * h as f64 / 2.0;
    let centre = glam::DVec2::new(w as f64 / 2.0, h as f64 / 2.0);
    let mut inked = 0;
    for y in 0..h {
        for x in 0..w {
            if lines.get(x, y) > 0.0 {
                inked += 1;
                let p = glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let off = ((p - centre).length() - rho).abs();
                assert!(
                    off <= 1.0,
                    "line pixel ({x}, {y}) is {off} px off the circle"
                );
            }
        }
    }
    // Covered without gaps: the pixel under every point of the circle is ink.
    for k in 0..1440 {
        let phi = k as f64 / 1440.0 * std::f64::consts::TAU;
        let p = centre + glam::DVec2::new(phi.cos(), phi.sin()) * rho;
        let (x, y) = (p.x.floor() as u32, p.y.floor() as u32);
        assert!(
            lines.get(x, y) > 0.0,
            "gap at angle {phi}: pixel ({x}, {y})"
        );
    }
    // About one pixel wide: the ring's area is 2 pi rho pixels.
    let ring = std::f64::consts::TAU * rho;
    assert!(
        (inked as f64) < 2.5 * ring,
        "{inked} inked pixels for a ring of {ring}"
    );
}

/// A flat-shaded cube of side 2 at the origin in three-quarter view.
pub(crate) const CUBE: &str = r#"
[camera]
look_from = [3, 2.5, 4]
look_at = [0, 0, 0]
vfov = 40
[[objects]]
shape = { type = "mesh", smooth = false, positions = [[-1,-1,-1],[1,-1,-1],[1,1,-1],[-1,1,-1],[-1,-1,1],[1,-1,1],[1,1,1],[-1,1,1]], indices = [[0,2,1],[0,3,2],[4,5,6],[4,6,7],[0,1,5],[0,5,4],[3,7,6],[3,6,2],[0,4,7],[0,7,3],[1,2,6],[1,6,5]] }
material = { color = [0.8, 0.2, 0.2] }
[[lights]]
type = "directional"
direction = [-1, -2, -1]
illuminance = 3
"#;

/// The cube's corners and its edges as corner pairs.
fn cube_edges() -> Vec<(DVec3, DVec3)> {
    let c = |i: usize| {
        DVec3::new(
            if i & 1 == 0 { -1.0 } else { 1.0 },
            if i & 2 == 0 { -1.0 } else { 1.0 },
            if i & 4 == 0 { -1.0 } else { 1.0 },
        )
    };
    let mut v = Vec::new();
    for i in 0..8 {
        for bit in [1, 2, 4] {
            if i & bit == 0 {
                v.push((c(i), c(i | bit)));
            }
        }
    }
    v
}

/// Edges as pairs of end points.
type Edges = Vec<(DVec3, DVec3)>;

/// The cube's edges seen from (3, 2.5, 4): the 3 interior edges meeting at
/// the near corner (1, 1, 1), the 6 outline edges, and the 3 hidden ones
/// meeting at (-1, -1, -1).
fn classified_cube_edges() -> (Edges, Edges, Edges) {
    let near = DVec3::ONE;
    let far = -DVec3::ONE;
    let (mut interior, mut outline, mut hidden) = (Vec::new(), Vec::new(), Vec::new());
    for e in cube_edges() {
        if e.0 == near || e.1 == near {
            interior.push(e);
        } else if e.0 == far || e.1 == far {
            hidden.push(e);
        } else {
            outline.push(e);
        }
    }
    (interior, outline, hidden)
}

#[test]
fn cube_shows_its_three_interior_edges_exactly_below_ninety_degrees() {
    let (w, h) = (120u32, 90u32);
    let cam = Pinhole::new([3.0, 2.5, 4.0], [0.0; 3], 40.0, w, h);
    let (interior, outline, _) = classified_cube_edges();
    let proj = |e: &(DVec3, DVec3)| (cam.project(e.0), cam.project(e.1));
    let near_any = |p: glam::DVec2, edges: &[(DVec3, DVec3)], tol: f64| {
        edges.iter().any(|e| {
            let (a, b) = proj(e);
            to_segment(p, a, b) <= tol
        })
    };
    for crease in [10.0, 45.57, 89.0, 90.0, 120.0, 180.0] {
        let lines = overlay(
            CUBE,
            &line_settings(w, h, crease),
            IntegratorKind::Recursive,
        );
        let mut interior_ink = 0;
        for y in 0..h {
            for x in 0..w {
                let p = glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                if lines.get(x, y) == 0.0 || near_any(p, &outline, 1.5) {
                    continue;
                }
                interior_ink += 1;
                assert!(
                    crease < 90.0 && near_any(p, &interior, 1.0),
                    "crease {crease}: ink at ({x}, {y}) off every interior edge"
                );
            }
        }
        if crease < 90.0 {
            // Every interior edge is drawn along its whole length (away
            // from the outline).
            for e in &interior {
                let (a, b) = proj(e);
                for k in 1..40 {
                    let p = a + (b - a) * (k as f64 / 40.0);
                    if near_any(p, &outline, 2.0) {
                        continue;
                    }
                    let (x, y) = (p.x.floor() as u32, p.y.floor() as u32);
                    assert!(lines.get(x, y) > 0.0, "crease {crease}: gap at ({x}, {y})");
                }
            }
            assert!(interior_ink > 50, "crease {crease}: {interior_ink}");
        } else {
            assert_eq!(interior_ink, 0, "crease {crease}");
        }
    }
}

/// A UV sphere mesh of radius 1 with `segments` x `rings` quads as TOML
/// arrays: positions and indices.
pub(crate) fn uv_sphere(segments: usize, rings: usize) -> (String, String) {
    let mut pos = Vec::new();
    for r in 0..=rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for s in 0..segments {
            let phi = std::f64::consts::TAU * s as f64 / segments as f64;
            pos.push(format!(
                "[{:.7},{:.7},{:.7}]",
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin()
            ));
        }
    }
    let mut idx = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let a = r * segments + s;
            let b = r * segments + (s + 1) % segments;
            let (c, d) = (a + segments, b + segments);
            idx.push(format!("[{a},{b},{d}]"));
            idx.push(format!("[{a},{d},{c}]"));
        }
    }
    (pos.join(","), idx.join(","))
}

#[test]
fn smooth_sphere_mesh_has_no_crease_lines_inside_its_outline() {
    let (w, h) = (96u32, 96u32);
    let (pos, idx) = uv_sphere(48, 24);
    let toml = format!(
        r#"
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
vfov = 40
[[objects]]
shape = {{ type = "mesh", smooth = true, positions = [{pos}], indices = [{idx}] }}
[[lights]]
type = "point"
position = [2, 3, 4]
intensity = 20
"#
    );
    let lines = overlay(
        &toml,
        &line_settings(w, h, 45.57),
        IntegratorKind::Recursive,
    );
    let cam = Pinhole::new([0.0, 0.0, 5.0], [0.0; 3], 40.0, w, h);
    let rho = (1.0f64 / 5.0).asin().tan() / cam.half_h * h as f64 / 2.0;
    let centre = glam::DVec2::new(w as f64 / 2.0, h as f64 / 2.0);
    let mut inked = 0;
    for y in 0..h {
        for x in 0..w {
            if lines.get(x, y) > 0.0 {
                inked += 1;
                let p = glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                // The polygonal outline is within 0.3% of the circle.
                let off = (p - centre).length() - rho;
                assert!(
                    off.abs() <= 1.5,
                    "ink at ({x}, {y}), {off} px from the outline"
                );
            }
        }
    }
    assert!(inked > 100, "the outline is drawn: {inked}");
}

#[test]
fn lines_do_not_depend_on_lighting_spp_threads_or_integrator_and_run_only_when_asked() {
    let (w, h) = (64u32, 48u32);
    let base = line_settings(w, h, 45.57);
    let reference = overlay(CUBE, &base, IntegratorKind::Recursive);
    assert!(reference.inked_pixels() > 100);
    let other_light = CUBE
        .replace("direction = [-1, -2, -1]", "direction = [2, -1, 0.5]")
        .replace("illuminance = 3", "illuminance = 300");
    assert_eq!(
        overlay(&other_light, &base, IntegratorKind::Recursive),
        reference,
        "lighting"
    );
    let spp = RenderSettings {
        spp: 4,
        seed: 9,
        ..base.clone()
    };
    assert_eq!(
        overlay(CUBE, &spp, IntegratorKind::Recursive),
        reference,
        "spp"
    );
    assert_eq!(
        overlay(CUBE, &base, IntegratorKind::Wavefront),
        reference,
        "integrator"
    );
    let gooch = RenderSettings {
        style: Style::Gooch,
        ..base.clone()
    };
    assert_eq!(
        overlay(CUBE, &gooch, IntegratorKind::Wavefront),
        reference,
        "style"
    );
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let l = pool.install(|| overlay(CUBE, &base, IntegratorKind::Recursive));
        assert_eq!(l, reference, "{threads} threads");
    }
    // No lines asked for: no line stage, no line rays.
    let frame = render_desc(
        load_toml(CUBE).unwrap(),
        config(
            RenderSettings {
                lines: None,
                ..base.clone()
            },
            IntegratorKind::Recursive,
        ),
    );
    assert!(frame.lines.is_none() && frame.line_rays == 0);
    // Exposure: fully inked pixels keep the ink colour in the PNG (lines
    // two pixels wide, to have some).
    let wide = RenderSettings {
        lines: Some(LineSettings {
            width: 2.0,
            ..Default::default()
        }),
        ..base.clone()
    };
    let frame = render_desc(
        load_toml(CUBE).unwrap(),
        config(wide, IntegratorKind::Recursive),
    );
    let dir = tempfile::tempdir().unwrap();
    let mut codes = Vec::new();
    for ev in [0.0, 4.0] {
        let path = dir.path().join(format!("ev{ev}.png"));
        let opts = PngOptions {
            exposure: ev,
            ..Default::default()
        };
        write_image_with_lines(
            &path,
            frame.film.as_ref().unwrap(),
            frame.lines.as_ref(),
            &opts,
        )
        .unwrap();
        codes.push(image::open(&path).unwrap().to_rgb8());
    }
    let l = frame.lines.as_ref().unwrap();
    let full: Vec<(u32, u32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| l.get(x, y) == 1.0)
        .collect();
    assert!(full.len() > 20);
    for (x, y) in full {
        for c in &codes {
            assert_eq!(c.get_pixel(x, y).0, [0, 0, 0], "ink at ({x}, {y})");
        }
    }
}

#[test]
fn lines_are_seen_in_a_mirror() {
    // The camera looks at a mirror square; the only object, a sphere, is
    // behind the camera, seen in the mirror alone.
    let toml = r#"
[settings]
background = [1, 1, 1]
[camera]
look_from = [0, 0, 4]
look_at = [0, 0, 0]
vfov = 40
[[objects]]
shape = { type = "polygon", vertices = [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]] }
material = { diffuse = 0, mirror = 1 }
[[objects]]
shape = { type = "sphere", radius = 1.0 }
translate = [0, 0, 6]
"#;
    let (w, h) = (96u32, 96u32);
    let lines = overlay(toml, &line_settings(w, h, 45.57), IntegratorKind::Recursive);
    // The reflected sphere is a sphere of radius 1 at distance 10.
    let cam = Pinhole::new([0.0, 0.0, 4.0], [0.0; 3], 40.0, w, h);
    let rho = (1.0f64 / 10.0).asin().tan() / cam.half_h * h as f64 / 2.0;
    let centre = glam::DVec2::new(w as f64 / 2.0, h as f64 / 2.0);
    let mut inked = 0;
    for y in 0..h {
        for x in 0..w {
            if lines.get(x, y) > 0.0 {
                inked += 1;
                let p = glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let off = ((p - centre).length() - rho).abs();
                assert!(
                    off <= 1.0,
                    "ink at ({x}, {y}) {off} px off the reflected outline"
                );
            }
        }
    }
    assert!(inked as f64 > std::f64::consts::TAU * rho * 0.8, "{inked}");
}

// ---------------------------------------------------------------------------
// Vector lines

/// The cube with a smooth sphere mesh in front of one corner.
pub(crate) fn cube_and_sphere_mesh() -> String {
    let (pos, idx) = uv_sphere(24, 12);
    format!(
        r#"{CUBE}
[[objects]]
shape = {{ type = "mesh", smooth = true, positions = [{pos}], indices = [{idx}] }}
translate = [1.6, 1.45, 1.9]
scale = 0.6
"#
    )
}

/// The vector lines of `toml` at `w` x `h` from its first camera, the
/// scene they were found in, and the camera.
fn vectors(toml: &str, w: u32, h: u32) -> (VectorLines, std::sync::Arc<prism::scene::RenderScene>) {
    let desc = load_toml(toml).unwrap();
    let camera = desc.cameras[0].clone();
    let mut r = renderer(
        desc,
        config(line_settings(w, h, 45.57), IntegratorKind::Recursive),
    );
    r.run();
    let scene = r.scene().unwrap();
    let rays = CameraRays::relative_to(&camera, scene.origin(), w, h);
    let mut v = vector_lines(&scene, &rays, (w, h), 45.57, None);
    // Back to world coordinates (the scene's frame is centred on its
    // render origin, the camera by default); exact for these small values.
    let o = scene.origin().as_vec3a();
    for s in &mut v.segments {
        s.world = s.world.map(|p| p + o);
    }
    (v, scene)
}

/// Visibility of world point `p` from `eye` by testing every object and
/// triangle (no BVH), with a margin of 1e-3 of the distance.
fn brute_visible(scene: &prism::scene::RenderScene, eye: DVec3, p: DVec3) -> bool {
    let (eye, p) = (eye - scene.origin(), p - scene.origin());
    let o = eye.as_vec3a();
    let ray = prism::core::math::Ray::new(o, p.as_vec3a() - o);
    scene.intersect_brute_force(&ray, 0.0, 1.0 - 1e-3).is_none()
}

#[test]
fn svg_lines_of_a_cube_are_its_projected_edges_with_hidden_ones_classified() {
    let (w, h) = (160u32, 120u32);
    let (v, scene) = vectors(CUBE, w, h);
    let eye = DVec3::new(3.0, 2.5, 4.0);
    let cam = Pinhole::new(eye.to_array(), [0.0; 3], 40.0, w, h);
    let (interior, outline, hidden) = classified_cube_edges();
    let d2 = |p: glam::Vec2| p.as_dvec2();
    let mut visible_length = [0.0; 12];
    let all: Vec<_> = interior.iter().chain(&outline).chain(&hidden).collect();
    for s in &v.segments {
        // Each end is the projection of its world point, within half a pixel.
        for (end, world) in [(s.a, s.world[0]), (s.b, s.world[1])] {
            let want = cam.project(world.as_dvec3());
            assert!((d2(end) - want).length() <= 0.5, "{s:?}: {want}");
        }
        // The segment lies on one cube edge, and on its projection.
        let on = |p: DVec3, e: &(DVec3, DVec3)| {
            let d = e.1 - e.0;
            let t = ((p - e.0).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            (e.0 + d * t - p).length() < 1e-4
        };
        let (k, e) = all
            .iter()
            .enumerate()
            .find(|(_, e)| s.world.iter().all(|p| on(p.as_dvec3(), e)))
            .unwrap_or_else(|| panic!("{s:?} lies on no cube edge"));
        let (pa, pb) = (cam.project(e.0), cam.project(e.1));
        assert!(to_segment(d2(s.a), pa, pb) <= 0.5 && to_segment(d2(s.b), pa, pb) <= 0.5);
        let length = (s.b - s.a).length() as f64;
        let kind = if k < 3 {
            EdgeKind::Crease
        } else if k < 9 {
            EdgeKind::Silhouette
        } else {
            EdgeKind::Crease
        };
        assert_eq!(s.kind, kind, "{s:?} on edge {e:?}");
        if length > 0.25 {
            // Classified as ray casting says: visible except the hidden three.
            let mid = (s.world[0].as_dvec3() + s.world[1].as_dvec3()) * 0.5;
            assert_eq!(s.visible, brute_visible(&scene, eye, mid), "{s:?}");
            assert_eq!(s.visible, k < 9, "{s:?}");
        }
        if s.visible {
            visible_length[k] += length;
        }
    }
    // Every visible edge is drawn along its whole projected length.
    for (k, e) in all.iter().enumerate().take(9) {
        let want = (cam.project(e.1) - cam.project(e.0)).length();
        assert!(
            (visible_length[k] - want).abs() < 0.5,
            "edge {k}: {} of {want}",
            visible_length[k]
        );
    }
    // The SVG has one <line> per segment (hidden ones only when asked), at
    // the segments' coordinates.
    let svg = to_svg(&v, [0.0; 3], 1.0, true);
    let lines: Vec<&str> = svg.split("<line ").skip(1).collect();
    assert_eq!(lines.len(), v.segments.len());
    let visible_only = to_svg(&v, [0.0; 3], 1.0, false);
    let n_visible = v.segments.iter().filter(|s| s.visible).count();
    assert_eq!(visible_only.matches("<line ").count(), n_visible);
    assert!(n_visible < v.segments.len());
    let attr = |l: &str, name: &str| -> f32 {
        let start = l.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        l[start..].split('"').next().unwrap().parse().unwrap()
    };
    for l in lines {
        let (a, b) = (
            glam::Vec2::new(attr(l, "x1"), attr(l, "y1")),
            glam::Vec2::new(attr(l, "x2"), attr(l, "y2")),
        );
        assert!(
            v.segments
                .iter()
                .any(|s| (s.a - a).length() < 2e-3 && (s.b - b).length() < 2e-3),
            "{l}"
        );
    }
}

#[test]
fn svg_lines_of_a_mesh_lie_on_its_projected_edges_and_hide_behind_it() {
    let (w, h) = (160u32, 120u32);
    let (v, scene) = vectors(&cube_and_sphere_mesh(), w, h);
    let eye = DVec3::new(3.0, 2.5, 4.0);
    let cam = Pinhole::new(eye.to_array(), [0.0; 3], 40.0, w, h);
    // Sphere mesh edges in world space, for the "lies on an edge" check.
    let (pos, idx) = uv_sphere(24, 12);
    let parse = |s: &str| -> Vec<Vec<f64>> {
        s.split("],[")
            .map(|t| {
                t.trim_matches(|c| c == '[' || c == ']')
                    .split(',')
                    .map(|x| x.parse().unwrap())
                    .collect()
            })
            .collect()
    };
    let to_world = |p: &Vec<f64>| DVec3::new(p[0], p[1], p[2]) * 0.6 + DVec3::new(1.6, 1.45, 1.9);
    let verts: Vec<DVec3> = parse(&pos).iter().map(to_world).collect();
    let mut edges: Vec<(DVec3, DVec3)> = cube_edges();
    for t in parse(&idx) {
        for k in 0..3 {
            edges.push((verts[t[k] as usize], verts[t[(k + 1) % 3] as usize]));
        }
    }
    let on_edge = |p: DVec3| {
        edges.iter().any(|&(a, b)| {
            let d = b - a;
            let t = ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            (a + d * t - p).length() < 1e-4
        })
    };
    let on_sphere = |s: &prism::integrators::vector_lines::Segment2| {
        s.world
            .iter()
            .all(|p| (p.as_dvec3() - DVec3::new(1.6, 1.45, 1.9)).length() < 0.6 + 1e-4)
    };
    let mut sphere_silhouettes = 0;
    let mut hidden_checked = 0;
    for s in &v.segments {
        for (end, world) in [(s.a, s.world[0]), (s.b, s.world[1])] {
            let want = cam.project(world.as_dvec3());
            assert!((end.as_dvec2() - want).length() <= 0.5, "{s:?}: {want}");
            assert!(on_edge(world.as_dvec3()), "{s:?} is off every mesh edge");
        }
        if (s.b - s.a).length() > 0.25 {
            let mid = (s.world[0].as_dvec3() + s.world[1].as_dvec3()) * 0.5;
            assert_eq!(s.visible, brute_visible(&scene, eye, mid), "{s:?}");
            hidden_checked += !s.visible as u32;
        }
        sphere_silhouettes += (on_sphere(s) && s.kind == EdgeKind::Silhouette) as u32;
    }
    // The smooth sphere's facets meet at 15 degrees: no creases, a
    // silhouette all round; the sphere hides part of the cube.
    assert!(
        !v.segments
            .iter()
            .any(|s| on_sphere(s) && s.kind == EdgeKind::Crease),
        "creases on the smooth sphere"
    );
    assert!(sphere_silhouettes >= 12, "{sphere_silhouettes}");
    // The three back edges, and the three interior edges where the sphere
    // covers the near corner.
    assert!(hidden_checked >= 6, "{hidden_checked}");
}

#[test]
fn gooch_through_mirrors_and_glass_is_the_same_in_both_integrators_without_shadow_rays() {
    let path = crate::common::assets().join("illustration.toml");
    let desc = || crate::common::scenes::load(&path);
    let settings = SettingsDesc {
        width: Some(60),
        height: Some(40),
        ..Default::default()
    }
    .resolve(&desc().settings);
    assert_eq!(settings.style, Style::Gooch);
    let rec = render_desc(desc(), config(settings.clone(), IntegratorKind::Recursive));
    let wav = render_desc(desc(), config(settings.clone(), IntegratorKind::Wavefront));
    let (a, b) = (rec.film.unwrap(), wav.film.unwrap());
    assert_same_image(&a, &b, "Gooch, recursive against wavefront");
    assert!(a.is_finite());
    assert_eq!(rec.counters.rays, wav.counters.rays);
    assert!(rec.counters.rays.reflection > 0 && rec.counters.rays.refraction > 0);
    assert_eq!(rec.counters.rays.shadow, 0);
    let runs = wav.wavefront.unwrap().runs;
    assert_eq!(
        runs.get(Stage::TraceShadowRays),
        0,
        "the shadow stage is gated off"
    );
    assert_eq!(rec.lines, wav.lines, "the scene asks for lines");
    assert!(rec.lines.unwrap().inked_pixels() > 100);
}

#[test]
fn lines_are_seen_through_glass() {
    // A sheet of glass of index 1 (rays pass straight through) covers the
    // whole view in front of the sphere: the lines seen through it are the
    // sphere's outline, as without the glass.
    let glass = r#"
[[objects]]
shape = { type = "polygon", vertices = [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]] }
material = { diffuse = 0, transmission = 1, ior = 1.0 }
translate = [0, 0, 2.5]
"#;
    let (w, h) = (96u32, 96u32);
    let s = line_settings(w, h, 45.57);
    let through = overlay(
        &format!("{SPHERE_AT_FIVE}{glass}"),
        &s,
        IntegratorKind::Recursive,
    );
    let direct = overlay(SPHERE_AT_FIVE, &s, IntegratorKind::Recursive);
    let differ = through
        .coverage
        .iter()
        .zip(&direct.coverage)
        .filter(|(a, b)| (*a - *b).abs() > 1.0 / 16.0 + 1e-6)
        .count();
    assert!(through.inked_pixels() > 100);
    assert!(
        differ <= 4,
        "{differ} pixels differ by more than one sub-sample"
    );
    // A glass sheet that bends the rays (index 1.5) still shows an outline
    // (shifted and scaled), not an empty view.
    let bent = overlay(
        &format!(
            "{SPHERE_AT_FIVE}{}",
            glass.replace("ior = 1.0", "ior = 1.5")
        ),
        &s,
        IntegratorKind::Recursive,
    );
    assert!(bent.inked_pixels() > 100);
}

#[test]
fn scene_files_set_the_style_its_parameters_and_the_lines() {
    let text = |settings: &str| {
        format!("[settings]\n{settings}\n[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n")
    };
    let s = load_toml(&text(
        "style = \"gooch\"\ngooch = { b = 0.5, beta = 0.7 }\nlines = { width = 2.5, color = [1, 0, 0] }",
    ))
    .unwrap()
    .settings;
    assert_eq!(s.style, Some(Style::Gooch));
    let g = s.gooch.unwrap();
    assert_eq!((g.b, g.y, g.alpha, g.beta), (0.5, 0.4, 0.2, 0.7));
    let l = s.lines.unwrap();
    assert_eq!(
        (l.width, l.color, l.crease_degrees),
        (2.5, [1.0, 0.0, 0.0], 45.57)
    );
    // No table, no lines; a misspelt key or a bad value is an error naming it.
    assert!(load_toml(&text("")).unwrap().settings.lines.is_none());
    for (bad, word) in [
        ("lines = { widht = 2 }", "widht"),
        ("lines = { width = -2 }", "line width"),
        ("gooch = { alpha = -1 }", "alpha"),
        ("style = \"sketch\"", "sketch"),
    ] {
        let e = load_toml(&text(bad)).unwrap_err().to_string();
        assert!(e.contains(word), "{bad}: {e}");
    }
}

#[test]
fn borders_of_an_open_mesh_are_lines_in_pixels_and_in_the_svg() {
    // The cube without its top face (y = 1), seen from above: the rim
    // separates the outside walls from the inside ones and the inside from
    // the background.
    let open = CUBE.replace("[3,7,6],[3,6,2],", "");
    assert_ne!(open, CUBE);
    let (w, h) = (120u32, 90u32);
    let cam = Pinhole::new([3.0, 2.5, 4.0], [0.0; 3], 40.0, w, h);
    let rim: Vec<(DVec3, DVec3)> = cube_edges()
        .into_iter()
        .filter(|e| e.0.y == 1.0 && e.1.y == 1.0)
        .collect();
    assert_eq!(rim.len(), 4);
    // Creases off: only borders and silhouettes remain.
    let lines = overlay(
        &open,
        &line_settings(w, h, 180.0),
        IntegratorKind::Recursive,
    );
    for e in &rim {
        let (a, b) = (cam.project(e.0), cam.project(e.1));
        for k in 1..30 {
            let p = a + (b - a) * (k as f64 / 30.0);
            let (x, y) = (p.x.floor() as u32, p.y.floor() as u32);
            assert!(lines.get(x, y) > 0.0, "rim gap at ({x}, {y}) on {e:?}");
        }
    }
    let (v, _) = vectors(&open, w, h);
    let on = |p: glam::Vec3A, e: &(DVec3, DVec3)| {
        let p = p.as_dvec3();
        let d = e.1 - e.0;
        let t = ((p - e.0).dot(d) / d.length_squared()).clamp(0.0, 1.0);
        (e.0 + d * t - p).length() < 1e-4
    };
    for e in &rim {
        let drawn: f32 = v
            .segments
            .iter()
            .filter(|s| s.visible && s.world.iter().all(|&p| on(p, e)))
            .map(|s| {
                assert_eq!(s.kind, EdgeKind::Border, "{s:?}");
                (s.b - s.a).length()
            })
            .sum();
        let want = (cam.project(e.1) - cam.project(e.0)).length() as f32;
        assert!((drawn - want).abs() < 0.5, "{e:?}: {drawn} of {want}");
    }
}

/// Edges that run behind the camera (the camera inside a room, next to an
/// edge that passes beside and behind it) are cut at the near plane: every
/// SVG piece lies inside the image and on the projection of its own world
/// points (within 1/50 pixel). The visibility search now works on the
/// piece inside the image and stops after 40 halvings; before, it worked
/// along the unclipped projection (which can be millions of pixels long)
/// and could in principle bisect forever, though this scene did not make
/// it do so.
#[test]
fn svg_lines_of_a_room_seen_from_inside_stay_on_their_edges() {
    let room = r#"
[camera]
look_from = [4.0, 2.0, 0.0]
look_at = [4.6, 2.6, -3.0]
vfov = 40
[[lights]]
type = "point"
position = [0, 2, 0]
intensity = 50
[[objects]]
name = "room"
shape = { type = "mesh", positions = [[-5, -3, -5], [5, -3, -5], [-5, 3, -5], [5, 3, -5], [-5, -3, 5], [5, -3, 5], [-5, 3, 5], [5, 3, 5]], indices = [[0, 6, 4], [0, 2, 6], [1, 7, 3], [1, 5, 7], [0, 5, 1], [0, 4, 5], [2, 7, 6], [2, 3, 7], [0, 3, 2], [0, 1, 3], [4, 7, 5], [4, 6, 7]] }
"#;
    let (w, h) = (320, 240);
    let (v, scene) = vectors(room, w, h);
    assert!(!v.segments.is_empty(), "the room's edges are in view");
    let desc = load_toml(room).unwrap();
    let rays = CameraRays::relative_to(&desc.cameras[0], scene.origin(), w, h);
    let proj = rays.projection();
    let o = scene.origin().as_vec3a();
    for s in &v.segments {
        for (film, world) in [(s.a, s.world[0]), (s.b, s.world[1])] {
            assert!(
                film.x >= -0.5
                    && film.x <= w as f32 + 0.5
                    && film.y >= -0.5
                    && film.y <= h as f32 + 0.5,
                "{film} outside the image"
            );
            let (p, z) = proj.project(world - o);
            assert!(z > 0.0 && (p - film).length() < 0.02, "{film} vs {p}");
        }
    }
}
