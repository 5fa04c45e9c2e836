//! `prism lightfield`: capture, view synthesis from the folder alone, and
//! bad light-field folders refused with a message and nothing written.

use std::path::{Path, PathBuf};

use prism::image::film::Film;
use prism::image::output::{PngOptions, read_image, write_image};

use crate::common::cli::{assert_failed_without_panic, assert_success, prism};
use crate::common::scenes;

const SCENE: &str = r#"
[settings]
background = [0.1, 0.1, 0.15]
[camera]
look_from = [0, 1, 5]
look_at = [0, 1, 0]
[lightfield]
grid = [3, 2]
spacing = 0.25
resolution = [12, 8]
[[objects]]
shape = { type = "sphere", radius = 0.7 }
material = { color = [0.9, 0.3, 0.2] }
translate = [0, 1, 0]
[[lights]]
type = "point"
position = [2, 4, 4]
intensity = 40
"#;

/// Captures the scene (its [lightfield] table: 3x2 cameras of 12x8) into
/// `dir/lf`.
fn capture(dir: &Path) -> PathBuf {
    let scene = scenes::write(dir, "lf.toml", SCENE);
    let out = dir.join("lf");
    let o = prism()
        .args(["lightfield", "capture"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .arg("-q")
        .output()
        .unwrap();
    assert_success(&o);
    out
}

fn synth(dir: &Path, extra: &[&str], out: &Path) -> std::process::Output {
    prism()
        .args(["lightfield", "render"])
        .arg(dir)
        .args(extra)
        .arg("-o")
        .arg(out)
        .arg("-q")
        .output()
        .unwrap()
}

/// The scene file's rig is used, every view written, and `render
/// --grid-camera` reproduces a captured image bit for bit from the folder
/// alone (asked for by `--grid-camera` or as `--grid-position`);
/// `compare` of that view against the direct render reports an
/// error of zero (the capture and the reference are rendered alike).
#[test]
fn capture_then_render_a_grid_view() {
    let tmp = tempfile::tempdir().unwrap();
    let lf = capture(tmp.path());
    let manifest = std::fs::read_to_string(lf.join("lightfield.json")).unwrap();
    assert!(
        manifest.contains("\"grid\": [\n      3,\n      2\n    ]"),
        "{manifest}"
    );
    for r in 0..2 {
        for c in 0..3 {
            assert!(lf.join(format!("view_r{r:03}_c{c:03}.exr")).is_file());
        }
    }
    let out = tmp.path().join("v.exr");
    assert_success(&synth(&lf, &["--grid-camera", "2,1"], &out));
    let a = read_image(&out).unwrap();
    let b = read_image(&lf.join("view_r001_c002.exr")).unwrap();
    assert_eq!((a.width, a.height), (12, 8));
    assert!(
        a.pixels
            .iter()
            .zip(&b.pixels)
            .all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits))
    );
    // The same camera asked for by its (whole) grid position.
    let out2 = tmp.path().join("v2.exr");
    assert_success(&synth(&lf, &["--grid-position", "2,1"], &out2));
    let c = read_image(&out2).unwrap();
    assert!(
        c.pixels
            .iter()
            .zip(&b.pixels)
            .all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits))
    );
    let o = prism()
        .args(["lightfield", "compare"])
        .arg(&lf)
        .args(["--grid-camera", "0,0", "--json"])
        .output()
        .unwrap();
    assert_success(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("\"rmse\": 0.0"), "{text}");
}

/// Missing or inconsistent manifests, missing images, images of another
/// size and views outside the light field: a message naming the problem,
/// a non-zero exit, no panic and no output file.
#[test]
fn bad_light_fields_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let lf = capture(tmp.path());
    let out = tmp.path().join("bad.exr");
    let fails = |dir: &Path, extra: &[&str], want: &str| {
        let o = synth(dir, extra, &out);
        let e = assert_failed_without_panic(&o);
        assert!(e.contains(want), "expected {want:?} in: {e}");
        assert!(!out.exists(), "an output was written");
    };
    let view = ["--look-from", "0.05,1.02,5"];

    // No manifest: an empty folder, and a missing folder.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    fails(&empty, &view, "no light-field manifest");
    fails(&tmp.path().join("nowhere"), &view, "is not a folder");

    // A view outside: an eye beside the grid sees nothing of it; with
    // --outside error even a partly outside view is refused.
    fails(
        &lf,
        &["--look-from", "3,1,5"],
        "sees nothing of the light field",
    );
    fails(
        &lf,
        &["--look-from", "0,1,6", "--vfov", "70", "--outside", "error"],
        "outside the light field's valid region",
    );
    // The default fallback: black pixels, counted on stderr.
    let o = prism()
        .args(["lightfield", "render"])
        .arg(&lf)
        .args(["--look-from", "0,1,6", "--vfov", "70", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_success(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("outside the light field"));
    std::fs::remove_file(&out).unwrap();

    // Inconsistent manifests.
    let manifest = std::fs::read_to_string(lf.join("lightfield.json")).unwrap();
    let edit = |from: &str, to: &str| {
        assert!(manifest.contains(from), "{from} not in the manifest");
        std::fs::write(lf.join("lightfield.json"), manifest.replacen(from, to, 1)).unwrap();
    };
    edit("\"grid\": [\n      3,", "\"grid\": [\n      4,");
    fails(&lf, &view, "4x2 cameras but 6 images");
    edit("\"version\": 1", "\"version\": 7");
    fails(&lf, &view, "version 7");
    edit("\"format\": \"prism-lightfield\"", "\"format\": \"other\"");
    fails(&lf, &view, "format");
    std::fs::write(lf.join("lightfield.json"), "{ not json").unwrap();
    fails(&lf, &view, "not a light-field manifest");
    std::fs::write(lf.join("lightfield.json"), &manifest).unwrap();

    // An image of another size, then a missing one.
    let img = lf.join("view_r000_c001.exr");
    write_image(&img, &Film::new(10, 8), &PngOptions::default()).unwrap();
    fails(&lf, &view, "images of different sizes");
    std::fs::remove_file(&img).unwrap();
    fails(&lf, &view, "is missing");
}

/// `prism lightfield sweep` on a tiny scene: one CSV row per grid and
/// method, errors that fall with density, and the plot written; bad
/// grids refused.
#[test]
fn sweep_writes_csv_and_plot() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scenes::write(tmp.path(), "lf.toml", SCENE);
    let out = tmp.path().join("sweep");
    let o = prism()
        .args(["lightfield", "sweep"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args([
            "--grids",
            "2,3,5",
            "--resolution",
            "24x16",
            "--aperture",
            "0.8",
        ])
        .args(["--proxy-depth", "4.5", "--views", "2", "-q"])
        .output()
        .unwrap();
    assert_success(&o);
    let csv = std::fs::read_to_string(out.join("lightfield_sweep.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 6, "{csv}");
    let rel: Vec<f64> = rows
        .iter()
        .filter(|r| r[0] == "quadrilinear")
        .map(|r| r[7].parse().unwrap())
        .collect();
    assert!(rel[0] > rel[1] && rel[1] > rel[2], "{csv}");
    assert!(out.join("lightfield_sweep.png").is_file());
    assert!(out.join("lightfield_sweep.svg").is_file());
    let o = prism()
        .args(["lightfield", "sweep"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args(["--grids", "1,3"])
        .output()
        .unwrap();
    let e = assert_failed_without_panic(&o);
    assert!(e.contains("at least 2"), "{e}");
}
