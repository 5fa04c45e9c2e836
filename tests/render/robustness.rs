//! Numerical robustness at the extremes, rendered end to end: IOR exactly 1
//! and 10, total internal reflection at the critical angle, a camera inside
//! glass, coincident surfaces, degenerate triangles and zero normals,
//! extreme light intensities, zero-area polygons, and scale invariance of a
//! whole scene under translation and scaling.

use glam::{Vec2, Vec3, Vec3A};
use prism::core::math::Color;
use prism::geometry::mesh::BuildQuality;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::material::SurfaceSample;
use prism::systems::{Frame, Renderer};
use prism::transport::interaction::{Interaction, RayKind};
use prism::transport::whitted::scatter;

use crate::common::render::{config, render_desc, sized};
use crate::common::scenes::lambert::{self, ALBEDO, lit_floor};
use crate::common::scenes::load_toml;

/// Every integrator the tests run; adding one is one line.
const KINDS: &[IntegratorKind] = &[IntegratorKind::Recursive, IntegratorKind::Wavefront];

const W: u32 = 32;
const H: u32 = 24;

/// Loads TOML scene text and renders it.
fn render(text: &str, width: u32, height: u32, kind: IntegratorKind) -> Frame {
    try_render(text, width, height, kind).unwrap()
}

fn try_render(
    text: &str,
    width: u32,
    height: u32,
    kind: IntegratorKind,
) -> Result<Frame, prism::Error> {
    let desc = load_toml(text)?;
    Renderer::with_scene(desc, config(sized(width, height), kind), 0)?.render()
}

fn film(frame: &Frame) -> &Film {
    frame.film.as_ref().expect("a rendered frame")
}

/// Every pixel finite and non-negative.
fn assert_clean(film: &Film, what: &str) {
    for (i, p) in film.pixels.iter().enumerate() {
        assert!(
            p.is_finite() && p.min_element() >= 0.0,
            "{what}: pixel {i} = {p}"
        );
    }
}

/// An emissive backdrop of coloured tiles (so that any bending of rays
/// shows), seen by a camera on the +Z axis; no lights. `extra` is added
/// to the file.
fn backdrop_scene(extra: &str) -> String {
    let mut s = String::from(
        r#"
[camera]
look_from = [0, 0, 6]
look_at = [0, 0, 0]
vfov = 30

[[objects]]
shape = { type = "plane" }
rotate = [90, 0, 0]
translate = [0, 0, -4]
material = { diffuse = 0.0, emission = 0.2 }
"#,
    );
    // A 4x4 grid of tiles in front of the plane, each its own colour.
    for i in 0..4 {
        for j in 0..4 {
            let (x, y) = (-3.0 + 1.5 * i as f32 + 0.75, -3.0 + 1.5 * j as f32 + 0.75);
            let c = [
                0.1 + 0.25 * i as f32,
                0.1 + 0.25 * j as f32,
                0.9 - 0.2 * (i + j) as f32 / 2.0,
            ];
            s += &format!(
                r#"
[[objects]]
shape = {{ type = "disk", radius = 0.6 }}
rotate = [90, 0, 0]
translate = [{x}, {y}, -3.9]
material = {{ diffuse = 0.0, emission = [{}, {}, {}] }}
"#,
                c[0], c[1], c[2]
            );
        }
    }
    s + extra
}

/// Largest relative difference between two images, with an absolute floor
/// of `floor`.
fn max_rel_diff(a: &Film, b: &Film, floor: f32) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| ((*p - *q).abs() / (p.abs().max(q.abs()) + floor)).max_element())
        .fold(0.0, f32::max)
}

#[test]
fn glass_of_ior_one_is_invisible() {
    let sphere = |ior: f32| {
        format!(
            r#"
[[objects]]
shape = {{ type = "sphere", radius = 1.3 }}
material = {{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = {ior} }}
"#
        )
    };
    for &kind in KINDS {
        let without = render(&backdrop_scene(""), W, H, kind);
        let with = render(&backdrop_scene(&sphere(1.0)), W, H, kind);
        assert_clean(film(&with), "ior 1");
        assert_eq!(with.counters.nonfinite_samples, 0);
        // At IOR 1 the Fresnel reflectance is 0 and the refracted ray keeps
        // its direction; only the origin offsets (a few hundred ulps)
        // displace it. 1e-5 relative is far below any visible change and
        // far above f32 rounding of the radiance.
        let d = max_rel_diff(film(&with), film(&without), 1e-6);
        assert!(d <= 1e-5, "{kind:?}: IOR 1 glass changed the image by {d}");
        // The same sphere at IOR 1.5 does change it: the test can fail.
        let glass = render(&backdrop_scene(&sphere(1.5)), W, H, kind);
        let d = max_rel_diff(film(&glass), film(&without), 1e-6);
        assert!(d > 0.1, "IOR 1.5 glass left the image unchanged ({d})");
    }
}

#[test]
fn glass_of_ior_ten_renders_finite() {
    let scene = backdrop_scene(
        r#"
[[objects]]
shape = { type = "sphere", radius = 1.3 }
material = { color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 10.0 }

[[objects]]
shape = { type = "sphere", radius = 0.5 }
translate = [1.2, 1.0, 1.5]
material = { color = 0.9, diffuse = 0.0, transmission = 1.0, ior = 10.0, mirror = 0.2 }

[[lights]]
type = "point"
position = [2, 3, 5]
intensity = 20
"#,
    );
    for &kind in KINDS {
        let f = render(&scene, W, H, kind);
        assert_clean(film(&f), "ior 10");
        assert_eq!(f.counters.nonfinite_samples, 0, "{kind:?}");
        // Fresnel reflectance at normal incidence is ((10-1)/11)^2 = 0.67:
        // the sphere's centre reflects mostly the (black) space behind the
        // camera, so it is darker than the backdrop but light still gets
        // through.
        let centre = film(&f).get(W / 2, H / 2);
        assert!(
            centre.max_element() > 0.0 && centre.max_element() < 0.2,
            "{centre}"
        );
    }
}

/// A surface sample of clear glass.
fn glass(ior: f32) -> SurfaceSample {
    SurfaceSample {
        diffuse: Color::ZERO,
        specular: Color::ZERO,
        shininess: 1.0,
        mirror: Color::ZERO,
        transmission: 1.0,
        transmission_tint: Color::ONE,
        ior,
        absorption: Color::ZERO,
        dispersion: None,
        emission: Color::ZERO,
        base: Color::ONE,
        diffuse_weight: 0.0,
        gltf: None,
    }
}

#[test]
fn total_internal_reflection_starts_at_the_critical_angle() {
    for ior in [1.000_5f32, 1.333, 1.5, 2.42, 10.0] {
        let critical = (1.0 / ior).asin();
        // Angles a little inside and outside the critical angle; the
        // margin is well above the f32 rounding of the angle (1e-7) and of
        // sin^2 (relative 1e-7), but small enough to bracket it tightly.
        for (theta, tir) in [(critical - 2e-4, false), (critical + 2e-4, true)] {
            // Inside the glass, travelling up towards the surface y = 0
            // whose outward normal is +Y: the ray arrives at the back face.
            let d = Vec3A::new(theta.sin(), theta.cos(), 0.0);
            let it = Interaction {
                point: Vec3A::new(0.3, 0.0, -0.2),
                ng: -Vec3A::Y,
                ns: -Vec3A::Y,
                wo: -d,
                front_face: false,
                surface: glass(ior),
                cone: Default::default(),
                offset_scale: 0.0,
            };
            let [reflection, refraction] = scatter(&it);
            let r = reflection.expect("a reflection");
            assert_eq!(r.kind, RayKind::Reflection);
            assert!(r.ray.origin.y < 0.0, "reflection leaves from inside");
            assert!(r.ray.direction.y < 0.0, "reflected back down");
            if tir {
                assert!(
                    refraction.is_none(),
                    "ior {ior}: refraction past the critical angle"
                );
                assert!(
                    (r.weight - Color::ONE).abs().max_element() < 1e-6,
                    "{}",
                    r.weight
                );
            } else {
                let t = refraction.unwrap_or_else(|| {
                    panic!("ior {ior}: no refraction just below the critical angle")
                });
                assert_eq!(t.kind, RayKind::Refraction);
                assert!(t.ray.origin.y > 0.0, "refraction leaves from outside");
                assert!(t.ray.direction.y > 0.0);
                // Snell: n sin(theta) = sin(theta_t), close to 1 here.
                let sin_t = t.ray.direction.x / t.ray.direction.length();
                assert!((ior * theta.sin() - sin_t).abs() < 1e-4, "{sin_t}");
                // Energy is split between the two rays.
                let sum = r.weight + t.weight;
                assert!((sum - Color::ONE).abs().max_element() < 1e-5, "{sum}");
            }
        }
    }
}

#[test]
fn camera_inside_glass_renders_finite() {
    let scene = backdrop_scene(
        r#"
[[objects]]
shape = { type = "sphere", radius = 8.0 }
translate = [0, 0, 6]
material = { color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }

[[lights]]
type = "point"
position = [0, 2, 3]
intensity = 5
"#,
    );
    for &kind in KINDS {
        let f = render(&scene, W, H, kind);
        assert_clean(film(&f), "camera in glass");
        assert_eq!(f.counters.nonfinite_samples, 0, "{kind:?}");
        // Rays leave the sphere (below the critical angle at its far side)
        // and see the backdrop: the image is not black.
        let lit = film(&f)
            .pixels
            .iter()
            .filter(|p| p.max_element() > 0.05)
            .count();
        assert!(lit > film(&f).pixels.len() / 2, "{lit}");
    }
}

/// Every pixel has the Lambertian radiance within 0.5 % (the tolerance of
/// the analytic tests; shadow acne would make pixels black).
fn assert_all_lit(film: &Film, what: &str) {
    lambert::assert_lit(
        film,
        0..film.width,
        0..film.height,
        &format!("{what} (acne?)"),
    );
}

#[test]
fn coincident_surfaces_have_no_acne() {
    let m = format!("material = {{ color = {ALBEDO} }}");
    let quad = format!(
        "[[objects]]\nshape = {{ type = \"polygon\", vertices = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]] }}\n{m}\n"
    );
    let plane = format!("[[objects]]\nshape = {{ type = \"plane\" }}\n{m}\n");
    let mesh = format!(
        "[[objects]]\nshape = {{ type = \"mesh\", positions = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]], indices = [[0, 1, 2], [0, 2, 3]] }}\n{m}\n"
    );
    let cases = [
        ("two identical quads", format!("{quad}{quad}")),
        ("a quad on a plane", format!("{plane}{quad}")),
        (
            "a mesh on a quad on a plane",
            format!("{plane}{quad}{mesh}"),
        ),
        // The same, translated and rotated so no coordinate is exact.
        (
            "rotated coincident quads",
            format!(
                "{quad}rotate = [0, 37, 0]\ntranslate = [0.1, 0, 0.3]\n{quad}rotate = [0, 37, 0]\ntranslate = [0.1, 0, 0.3]\n{plane}"
            ),
        ),
    ];
    for (what, objects) in cases {
        for &kind in KINDS {
            let f = render(&lit_floor(&objects), W, H, kind);
            assert_all_lit(film(&f), what);
        }
    }
}

#[test]
fn degenerate_triangles_and_zero_normals() {
    // A quad of two good triangles, plus degenerate ones: a repeated
    // vertex, three collinear vertices, and a vertex used only by
    // degenerate triangles (its smooth normal is zero length).
    let objects = format!(
        r#"
[[objects]]
shape = {{ type = "mesh", smooth = true, positions = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3], [0, 0, 0], [1, 0, 1], [5, 0, 5]], indices = [[0, 1, 2], [0, 2, 3], [0, 0, 1], [4, 5, 6], [4, 4, 4], [6, 5, 4]] }}
material = {{ color = {ALBEDO} }}
"#
    );
    for &kind in KINDS {
        let f = render(&lit_floor(&objects), W, H, kind);
        assert_eq!(f.counters.nonfinite_samples, 0);
        assert_all_lit(film(&f), "degenerate triangles");
    }
    // Explicit zero-length vertex normals through the library: the
    // shading normal falls back to the geometric one.
    use prism::geometry::mesh::{Mesh, MeshData, NormalMode};
    use prism::io::desc::{Geometry, ObjectDesc};
    let positions = vec![
        Vec3::new(-3.0, 0.0, -3.0),
        Vec3::new(-3.0, 0.0, 3.0),
        Vec3::new(3.0, 0.0, 3.0),
        Vec3::new(3.0, 0.0, -3.0),
    ];
    for &kind in KINDS {
        let mut desc = load_toml(&lit_floor("")).unwrap();
        desc.objects.push(ObjectDesc {
            name: None,
            transform: Default::default(),
            geometry: Geometry::Mesh(std::sync::Arc::new(
                Mesh::new(
                    "zero normals",
                    MeshData {
                        positions: positions.clone(),
                        normals: Some(vec![Vec3::ZERO; 4]),
                        uvs: Some(vec![Vec2::ZERO; 4]),
                        indices: vec![[0, 1, 2], [0, 2, 3], [1, 1, 1]],
                    },
                    NormalMode::Smooth,
                    BuildQuality::Medium,
                )
                .unwrap(),
            )),
            material: prism::scene::material::Material {
                base_color: Color::splat(ALBEDO),
                ..Default::default()
            },
        });
        let f = render_desc(desc, config(sized(W, H), kind));
        assert_eq!(f.counters.nonfinite_samples, 0);
        assert_all_lit(film(&f), "zero-length normals");
    }
}

#[test]
fn extreme_light_intensities() {
    let scene = |intensity: &str| {
        format!(
            r#"
[camera]
look_from = [0, 3, 5]
look_at = [0, 0.5, 0]

[[objects]]
shape = {{ type = "plane" }}
material = {{ color = 0.5 }}

[[objects]]
shape = {{ type = "sphere", radius = 0.8 }}
translate = [0, 0.8, 0]
material = {{ color = 0.7, specular = 0.3, shininess = 50 }}

[[objects]]
shape = {{ type = "sphere", radius = 0.4 }}
translate = [1.2, 0.4, 0.8]
material = {{ diffuse = 0.0, transmission = 1.0, ior = 1.5 }}

[[lights]]
type = "point"
position = [2, 4, 3]
intensity = {intensity}

[[lights]]
type = "spot"
position = [-2, 0.3, 2]
direction = [1, -0.2, -1]
intensity = {intensity}
"#
        )
    };
    for &kind in KINDS {
        let unit = render(&scene("1.0"), W, H, kind);
        assert!(film(&unit).pixels.iter().any(|p| p.max_element() > 0.01));
        for (text, k) in [("1e-30", 1e-30f32), ("1e30", 1e30)] {
            let f = render(&scene(text), W, H, kind);
            assert_clean(film(&f), text);
            assert_eq!(f.counters.nonfinite_samples, 0, "{kind:?} {text}");
            // Radiance is linear in the intensity: the image is the unit
            // one times k, to f32 rounding (1e-30 stays far above the
            // smallest normal f32 after the 1/pi and 1/d^2 factors).
            for (p, q) in film(&f).pixels.iter().zip(&film(&unit).pixels) {
                let expect = *q * k;
                assert!(
                    (*p - expect).abs().max_element() <= 1e-5 * expect.max_element().max(k * 1e-6),
                    "{kind:?} {text}: {p} vs {expect}"
                );
            }
        }
        // Near f32::MAX the sum of two lights overflows to infinity: those
        // samples are dropped, counted, and never reach the image.
        let f = render(&scene("3e38"), W, H, kind);
        assert_clean(film(&f), "3e38");
        assert!(
            f.counters.nonfinite_samples > 0,
            "{kind:?}: overflowing samples were not reported"
        );
    }
}

#[test]
fn zero_area_polygon_is_rejected_with_a_message() {
    let scene = r#"
[camera]
look_from = [0, 1, 5]
look_at = [0, 0, 0]

[[objects]]
name = "sliver"
shape = { type = "polygon", vertices = [[0, 0, 0], [1, 0, 0], [2, 0, 0]] }
"#;
    let err = try_render(scene, W, H, IntegratorKind::Recursive)
        .err()
        .expect("a zero-area polygon must be rejected")
        .to_string();
    assert!(err.contains("zero area") && err.contains("sliver"), "{err}");
    assert!(
        err.contains("scene.toml"),
        "the message names the file: {err}"
    );
}

// ---------------------------------------------------------------------------
// Scale invariance
// ---------------------------------------------------------------------------

/// The test scene with every position mapped by `p -> offset + scale * p`
/// (camera and lights too; point intensities times `scale^2` keep the
/// image). Object-space positions are integers or simple fractions so that
/// at `scale = 1` the translated camera and lights are exact.
pub(crate) fn scale_scene(offset: f64, scale: f64) -> String {
    let p = |x: f64, y: f64, z: f64| {
        format!(
            "[{:?}, {:?}, {:?}]",
            offset + scale * x,
            offset + scale * y,
            offset + scale * z
        )
    };
    let s = |v: f64| format!("{:?}", scale * v);
    format!(
        r#"
[settings]
background = [0.05, 0.06, 0.08]

[camera]
look_from = {cam}
look_at = {at}
vfov = 40

[[objects]]
name = "floor"
shape = {{ type = "plane" }}
translate = {floor}
scale = {one}
material = {{ color = 0.6 }}

[[objects]]
name = "diffuse ball"
shape = {{ type = "sphere", radius = 1.0 }}
translate = {ball}
scale = {one}
material = {{ color = [0.8, 0.3, 0.2], specular = 0.2, shininess = 40 }}

[[objects]]
name = "mirror ball"
shape = {{ type = "sphere", radius = 0.75 }}
translate = {mirror}
scale = {one}
material = {{ color = 0.9, diffuse = 0.05, mirror = 0.9 }}

[[objects]]
name = "glass ball"
shape = {{ type = "sphere", radius = 0.625 }}
translate = {glass}
scale = {one}
material = {{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }}

[[objects]]
name = "box"
shape = {{ type = "mesh", positions = [[-1, -1, -1], [1, -1, -1], [-1, 1, -1], [1, 1, -1], [-1, -1, 1], [1, -1, 1], [-1, 1, 1], [1, 1, 1]], indices = [[0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5], [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3], [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6]] }}
translate = {boxp}
rotate = [0, 30, 0]
scale = {half}
material = {{ color = [0.3, 0.5, 0.8] }}

[[lights]]
type = "point"
position = {light}
intensity = {intensity:?}
"#,
        cam = p(0.0, 2.0, 7.0),
        at = p(0.0, 1.0, 0.0),
        floor = p(0.0, 0.0, 0.0),
        ball = p(-1.5, 1.0, 0.0),
        mirror = p(1.75, 0.75, -0.5),
        glass = p(0.25, 0.625, 1.5),
        boxp = p(0.0, 0.5, -2.0),
        light = p(3.0, 6.0, 4.0),
        one = s(1.0),
        half = s(0.5),
        intensity = 60.0 * scale * scale,
    )
}

const SW: u32 = 64;
const SH: u32 = 48;

/// Fraction of pixels of `b` within 1 % of `a` (relative, per channel,
/// with an absolute floor of 1e-3 of the reference's mean for black
/// pixels).
pub(crate) fn agreement(a: &Film, b: &Film) -> f64 {
    let mean = a.pixels.iter().map(|p| p.max_element()).sum::<f32>() / a.pixels.len() as f32;
    let floor = 1e-3 * mean;
    let ok = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(p, q)| {
            ((**p - **q).abs())
                .cmple(p.abs().max(q.abs()) * 0.01 + Vec3::splat(floor))
                .all()
        })
        .count();
    ok as f64 / a.pixels.len() as f64
}

/// Renders the scale-invariance scene under each transform with `kind` and
/// returns `(label, agreement with the untransformed render, film)`.
fn scale_runs(kind: IntegratorKind) -> (Film, Vec<(&'static str, f64, Film)>) {
    let reference = render(&scale_scene(0.0, 1.0), SW, SH, kind);
    let reference = film(&reference).clone();
    let transforms: [(&str, f64, f64); 4] = [
        ("translated by 1e5", 1e5, 1.0),
        ("translated by 1e7", 1e7, 1.0),
        ("scaled by 1e-4", 0.0, 1e-4),
        ("scaled by 1e4", 0.0, 1e4),
    ];
    let mut out = Vec::new();
    for (label, offset, scale) in transforms {
        let f = render(&scale_scene(offset, scale), SW, SH, kind);
        assert_clean(film(&f), label);
        assert_eq!(f.counters.nonfinite_samples, 0, "{kind:?} {label}");
        let a = agreement(&reference, film(&f));
        eprintln!(
            "scale invariance, {} integrator, {label}: {:.2} % of pixels within 1 %",
            kind.name(),
            100.0 * a
        );
        out.push((label, a, film(&f).clone()));
    }
    (reference, out)
}

/// Scale invariance: at least 99.5 % of the pixels within 1 % after
/// translating the whole scene by 1e5 and 1e7 or scaling it by 1e-4 and
/// 1e4, and no acne anywhere, for both integrators.
///
/// Measured (64x48, both integrators alike, see the `eprintln` output):
/// 100.00 % for all four. History: while hit points were `ray.at(t)` in
/// world space, acne on the floor at 1e4; while the top-level BVH used
/// obvhs's node test, missed occluders at 1e-4; while placements were
/// composed in f32 and rendered in world coordinates, 91.9 % at 1e5 and
/// 43.5 % at 1e7 (ulp(1e7) = 1 snapped hit points to a 1-unit grid).
/// Translations now cancel in f64 against the render origin (the camera);
/// `large_worlds` goes on to 1e9, glTF, path transport and moving scenes.
#[test]
fn scale_invariance() {
    for &kind in KINDS {
        let (reference, runs) = scale_runs(kind);
        for (label, a, f) in &runs {
            let (dark, smooth) = acne(&reference, f);
            eprintln!("  {label}: {dark} acne pixels of {smooth} smooth lit ones");
            assert!(smooth > (SW * SH / 4) as usize, "{smooth}");
            assert_eq!(dark, 0, "{kind:?} {label}: acne");
            assert!(
                *a >= 0.995,
                "{kind:?} {label}: only {:.2} % of pixels agree",
                100.0 * a
            );
        }
    }
}

/// Pixels that are lit and smooth in the reference (3x3 neighbourhood
/// within 2 %) but come out darker than a quarter of it: the signature of
/// acne (self-shadowing speckles). Returns (such pixels, smooth pixels).
fn acne(reference: &Film, f: &Film) -> (usize, usize) {
    let (w, h) = (reference.width, reference.height);
    let (mut dark, mut smooth) = (0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let c = reference.get(x, y);
            if c.max_element() < 0.05 {
                continue;
            }
            let flat = (0..9).all(|k| {
                let n = reference.get(x + k % 3 - 1, y + k / 3 - 1);
                (n - c).abs().cmple(c * 0.02).all()
            });
            if !flat {
                continue;
            }
            smooth += 1;
            if f.get(x, y).max_element() < 0.25 * c.max_element() {
                dark += 1;
            }
        }
    }
    (dark, smooth)
}

/// A ground sphere of radius 1000 centred 1000 below the origin (the
/// classic way to model a floor), Lambertian of albedo 0.8 under a white
/// sky of radiance 1, seen from 5 units away at `angle` degrees from its
/// normal through a 1-degree lens: every pixel sees the top of the sphere,
/// whose radiance is the albedo at every angle (rendered by
/// [`ground_sphere_frame`]).
fn ground_sphere(angle: f32) -> String {
    let a = angle.to_radians();
    let (y, z) = (5.0 * a.cos(), 5.0 * a.sin());
    format!(
        r#"
[camera]
look_from = [0.0, {y}, {z}]
look_at = [0.0, 0.0, 0.0]
up = [1.0, 0.0, 0.0]
vfov = 1
[environment]
color = 1.0
[materials.ground]
color = 0.8
[[objects]]
name = "ground"
shape = {{ type = "sphere", radius = 1000.0 }}
material = "ground"
translate = [0.0, -1000.0, 0.0]
"#
    )
}

/// [`ground_sphere`] path traced, one bounce, 32 samples per pixel, 16x16.
fn ground_sphere_frame(angle: f32, kind: IntegratorKind) -> Frame {
    let settings = prism::core::settings::RenderSettings {
        spp: 32,
        max_depth: 1,
        transport: prism::core::settings::Transport::Path,
        ..sized(16, 16)
    };
    let desc = load_toml(&ground_sphere(angle)).unwrap();
    Renderer::with_scene(desc, config(settings, kind), 0)
        .unwrap()
        .render()
        .unwrap()
}

/// Mean of the pixels' first channel and its standard error.
fn mean_and_error(film: &Film) -> (f64, f64) {
    let v: Vec<f64> = (0..film.height)
        .flat_map(|y| (0..film.width).map(move |x| (x, y)))
        .map(|(x, y)| film.get(x, y).x as f64)
        .collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Points near the render frame's origin computed from an object of size
/// 1000 carry errors of ulps of 1000, not of their own coordinates: new
/// rays must leave from far enough to clear the surface. Seen at grazing
/// angles a ground sphere of radius 1000 found itself again on a quarter
/// of its shadow rays (0.56 instead of 0.80 at 80 degrees, 0.53 at 85)
/// while it rendered right seen from above. The grazing views must match
/// the view from above (which the bug did not reach) within four standard
/// errors (at least 0.1 %, the images being nearly noise-free).
#[test]
fn a_large_ground_sphere_is_lit_alike_at_every_angle() {
    for &kind in KINDS {
        let above = ground_sphere_frame(0.0, kind);
        let (m0, e0) = mean_and_error(film(&above));
        assert!((m0 - 0.8).abs() < 0.01, "{kind:?}: seen from above {m0}");
        for angle in [60.0, 80.0, 85.0] {
            let f = ground_sphere_frame(angle, kind);
            assert_clean(film(&f), "ground sphere");
            let (m, e) = mean_and_error(film(&f));
            let tol = (4.0 * (e * e + e0 * e0).sqrt()).max(1e-3 * m0);
            assert!(
                (m - m0).abs() < tol,
                "{kind:?} at {angle} degrees: {m} against {m0} from above (tolerance {tol})"
            );
        }
    }
}
