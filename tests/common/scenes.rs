//! Scene text and loading.

use std::path::{Path, PathBuf};

use prism::geometry::mesh::BuildQuality;
use prism::image::film::Film;
use prism::io::desc::SceneDesc;

/// Loads a scene file with the medium BVH preset.
pub fn load(path: &Path) -> SceneDesc {
    prism::io::load(path, BuildQuality::Medium).unwrap()
}

/// Loads scene text (TOML), written as `scene.toml` in a fresh temporary
/// folder (error messages name that file).
pub fn load_toml(text: &str) -> prism::Result<SceneDesc> {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "scene.toml", text);
    prism::io::load(&path, BuildQuality::Medium)
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A unit sphere of `sphere_material` on a grey disk of radius 3, the
/// `objects` given, and one point light, seen from (0, 1, 6).
pub fn sphere_on_disk(sphere_material: &str, objects: &str) -> String {
    format!(
        r#"
[camera]
look_from = [0, 1, 6]
look_at = [0, 0.5, 0]
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {sphere_material}
{objects}[[objects]]
shape = {{ type = "disk", radius = 3.0 }}
material = {{ color = 0.5 }}
[[lights]]
type = "point"
position = [2, 4, 3]
intensity = 30
"#
    )
}

/// A glass ball (radius 1, IOR 1.5) at the origin before a red emissive
/// backdrop above y = 0 in the plane z = -4, seen from (0, 0, 10) with a
/// 20 degree field of view; `rest` is added.
pub fn glass_ball(rest: &str) -> String {
    format!(
        r#"
[camera]
look_from = [0, 0, 10]
look_at = [0, 0, 0]
vfov = 20
[[objects]]
shape = {{ type = "sphere", radius = 1.0 }}
material = {{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }}
[[objects]]
shape = {{ type = "polygon", vertices = [[-8, 0, -4], [8, 0, -4], [8, 8, -4], [-8, 8, -4]] }}
material = {{ color = 0.0, emission = [1, 0, 0] }}
{rest}"#
    )
}

/// A Lambertian floor under a directional light, with its analytic
/// radiance.
pub mod lambert {
    use super::Film;

    pub const ALBEDO: f32 = 0.5;
    pub const E_LUX: f32 = 2.0;
    pub const THETA_DEG: f32 = 30.0;

    /// Radiance of a Lambertian surface under a directional light:
    /// `albedo / pi * E * cos(theta)`.
    pub fn radiance() -> f32 {
        ALBEDO / std::f32::consts::PI * E_LUX * THETA_DEG.to_radians().cos()
    }

    /// A camera looking straight down at the plane y = 0 from height 3,
    /// lit by a directional light at `THETA_DEG` from the vertical;
    /// `objects` are added.
    pub fn lit_floor(objects: &str) -> String {
        let t = THETA_DEG.to_radians();
        format!(
            r#"
[camera]
look_from = [0, 3, 0]
look_at = [0, 0, 0]
up = [0, 0, -1]
vfov = 30

[[lights]]
type = "directional"
direction = [{}, {}, 0]
illuminance = {E_LUX}
{objects}
"#,
            t.sin(),
            -t.cos()
        )
    }

    /// Asserts the analytic radiance within 0.5 % on every channel of the
    /// pixels in `xs` x `ys` (at least one).
    pub fn assert_lit(film: &Film, xs: std::ops::Range<u32>, ys: std::ops::Range<u32>, what: &str) {
        let expect = radiance();
        assert!(!xs.is_empty() && !ys.is_empty());
        for y in ys {
            for x in xs.clone() {
                for v in film.get(x, y).to_array() {
                    assert!(
                        (v - expect).abs() <= 0.005 * expect,
                        "{what}: pixel ({x},{y}) = {v}, expected {expect}"
                    );
                }
            }
        }
    }
}
