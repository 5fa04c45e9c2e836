//! Runs the `prism` binary as a user would: bad input must give a clear
//! message and a non-zero exit, never a panic and never an output file.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::assets;
use crate::common::cli::{assert_failed_without_panic, assert_success, prism};

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus")
}

/// Asserts a clean failure: non-zero status that is not a panic (101),
/// an `error:` message, and no output file.
fn assert_clean_failure(out: &Output, output_file: &Path, must_mention: &[&str]) {
    let stderr = assert_failed_without_panic(out);
    assert!(stderr.contains("error"), "no error message: {stderr}");
    for m in must_mention {
        assert!(
            stderr.to_lowercase().contains(&m.to_lowercase()),
            "message should mention {m:?}: {stderr}"
        );
    }
    assert!(
        !output_file.exists(),
        "a failed run left {} behind",
        output_file.display()
    );
}

fn render(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    prism()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .args(extra)
        .output()
        .expect("run prism")
}

/// What each corpus file's message must contain besides its file name.
fn expected_words(name: &str) -> &'static [&'static str] {
    match name {
        "malformed_json.gltf" | "empty.gltf" => &["json"],
        "missing_buffer.gltf" => &["does_not_exist.bin"],
        "missing_texture.gltf" => &["no_such_texture.png"],
        "node_cycle.gltf" => &["cycle"],
        "index_out_of_range.gltf" => &["index"],
        "nan_radius.toml" | "negative_radius.toml" => &["radius"],
        "zero_size.toml" => &["size"],
        "unknown_key.toml" => &["radus"],
        "unknown_material.toml" => &["unobtainium"],
        "nan_light.toml" => &["intensity"],
        "degenerate_camera.toml" => &["camera"],
        "missing_include.toml" => &["model.gltf"],
        "singular_scale.toml" => &["scale"],
        "nonconvex_polygon.toml" => &["convex"],
        "huge_accessor_count.gltf" => &["accessor", "48000000000"],
        "huge_buffer.gltf" => &["buffer", "4000000000000"],
        "device_buffer.gltf" => &["/dev/zero", "regular file"],
        "deep_nodes.gltf" => &["deeper than 1024"],
        "json_chunk_overrun.glb" => &["json chunk"],
        "huge_mesh_index.toml" => &["4000000000"],
        "nan_transform.toml" => &["translate", "nan"],
        "huge_pixel_count.toml" => &["pixels"],
        "huge_image.toml" => &["image size", "32768"],
        "device_include.toml" => &["/dev/zero", "regular file"],
        "huge_torus_knot.toml" => &["torus_knot", "4000000"],
        "zero_area_polygon.toml" => &["zero area"],
        "deep_recursion.toml" => &["max_depth", "1024"],
        "bad_rr_weight.toml" => &["rr_weight", "(0, 1]"],
        _ => &[],
    }
}

#[test]
fn every_corpus_file_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let mut count = 0;
    for entry in std::fs::read_dir(corpus()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        if name.ends_with(".md") {
            continue;
        }
        count += 1;
        let out_file = dir.path().join(format!("{name}.png"));
        // No size on the command line: the scene's own settings must be checked.
        let start = std::time::Instant::now();
        let out = render(&path, &out_file, &[]);
        // Hostile sizes must be refused before any work is done, not after
        // minutes of allocation (each file takes milliseconds).
        let seconds = start.elapsed().as_secs_f64();
        assert!(seconds < 20.0, "{name} took {seconds:.1} s to fail");
        let mut words = vec![name.as_str()];
        words.extend_from_slice(expected_words(&name));
        assert_clean_failure(&out, &out_file, &words);
    }
    assert!(count >= 26, "corpus has only {count} files");
}

#[test]
fn zero_image_size_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("a.png");
    for size in [["--width", "0"], ["--height", "0"]] {
        let out = prism()
            .arg("render")
            .arg(assets().join("whitted.toml"))
            .arg("-o")
            .arg(&out_file)
            .args(size)
            .output()
            .unwrap();
        assert_clean_failure(&out, &out_file, &["size"]);
    }
}

#[test]
fn unknown_option_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("a.png");
    let out = render(&assets().join("whitted.toml"), &out_file, &["--frobnicate"]);
    assert_clean_failure(&out, &out_file, &["--frobnicate"]);
}

#[test]
fn missing_scene_and_bad_output_names() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("a.png");
    let out = render(&dir.path().join("nope.toml"), &out_file, &[]);
    assert_clean_failure(&out, &out_file, &["nope.toml"]);

    let bmp = dir.path().join("a.bmp");
    let out = render(&assets().join("whitted.toml"), &bmp, &[]);
    assert_clean_failure(&out, &bmp, &["a.bmp", ".png"]);

    let nested = dir.path().join("no/such/dir/a.png");
    let out = render(&assets().join("whitted.toml"), &nested, &[]);
    assert_clean_failure(&out, &nested, &["a.png"]);

    let out = render(
        &assets().join("whitted.toml"),
        &out_file,
        &["--camera", "5"],
    );
    assert_clean_failure(&out, &out_file, &["camera"]);

    let out = render(
        &assets().join("whitted.toml"),
        &out_file,
        &["--threads", "0"],
    );
    assert_clean_failure(&out, &out_file, &["threads"]);

    let out = render(&dir.path().join("scene.obj"), &out_file, &[]);
    assert_clean_failure(&out, &out_file, &["scene.obj"]);
}

#[test]
fn help_explains_every_option() {
    let out = prism().args(["render", "--help"]).output().unwrap();
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for opt in [
        "--output",
        "--width",
        "--height",
        "--spp",
        "--max-depth",
        "--min-contribution",
        "--rr-weight",
        "--no-caustics",
        "--threads",
        "--seed",
        "--camera",
        "--stats",
        "--exposure",
        "--tonemap",
        "--integrator",
        "--bvh-quality",
        "--style",
        "--gooch",
        "--lines",
        "--line-width",
        "--line-color",
        "--crease-angle",
        "--lines-svg",
        "--hidden-lines",
        "--camera-projection",
        "--overlay",
        "--overlay-depth",
        "--overlay-svg",
        "--overlay-visible-only",
    ] {
        assert!(help.contains(opt), "--help lacks {opt}:\n{help}");
    }
}

#[test]
fn stats_file_reports_the_render() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("w.exr");
    let stats = dir.path().join("w.json");
    let out = render(
        &assets().join("whitted.toml"),
        &out_file,
        &[
            "--stats",
            stats.to_str().unwrap(),
            "--threads",
            "2",
            "--width",
            "16",
            "--height",
            "12",
        ],
    );
    assert_success(&out);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    for key in [
        "wall_seconds",
        "bvh_build_seconds",
        "render_seconds",
        "mrays_per_second",
        "width",
        "height",
        "spp",
        "threads",
        "triangles",
        "primitives",
        "nonfinite_samples",
    ] {
        assert!(json.get(key).is_some(), "stats lack {key}: {json}");
    }
    let rays = &json["rays"];
    assert_eq!(rays["camera"], 16 * 12);
    // The glass and mirror spheres are in view: both kinds of secondary ray.
    assert!(rays["reflection"].as_u64().unwrap() > 0);
    assert!(rays["refraction"].as_u64().unwrap() > 0);
    assert!(rays["shadow"].as_u64().unwrap() > 0);
    let total = ["camera", "shadow", "reflection", "refraction"]
        .iter()
        .map(|k| rays[k].as_u64().unwrap())
        .sum::<u64>();
    assert_eq!(rays["total"].as_u64().unwrap(), total);
    assert_eq!(json["threads"], 2);
    assert_eq!(json["nonfinite_samples"], 0);
    assert_eq!(json["primitives"], 3);
}

#[test]
fn bench_compares_both_integrators_as_json() {
    let out = prism()
        .args([
            "bench", "--runs", "1", "--width", "24", "--height", "16", "--json",
        ])
        .arg(assets().join("whitted.toml"))
        .output()
        .unwrap();
    assert_success(&out);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let scene = &json[0];
    let ints = scene["integrators"].as_array().unwrap();
    assert_eq!(ints.len(), 2);
    assert_eq!(ints[0]["integrator"], "recursive");
    assert_eq!(ints[1]["integrator"], "wavefront");
    // Same rays, whichever integrator traces them.
    assert_eq!(ints[0]["rays"], ints[1]["rays"]);
    assert_eq!(ints[0]["rays"]["camera"], 24 * 16);
    assert!(ints[1]["peak_queue_bytes"].as_u64().unwrap() > 0);
    assert!(
        ints[1]["stage_seconds"]["intersect_closest"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(scene["speedup_wavefront"].as_f64().unwrap() > 0.0);
    assert!(scene["speedup_wavefront_fastest"].as_f64().unwrap() > 0.0);
    for i in ints {
        // One run: its time is the median and the fastest.
        assert_eq!(i["fastest_seconds"], i["median_seconds"]);
    }
    for key in ["camera_packets", "camera_streams", "secondary_streams"] {
        assert!(
            scene["closest_hit_mrays"][key].as_f64().unwrap() > 0.0,
            "{key}"
        );
    }
}

/// A scene that cannot be measured does not stop the others: it is named
/// on stderr and skipped, the rest are measured (here in the JSON), and
/// the command fails at the end.
#[test]
fn bench_skips_a_scene_it_cannot_measure_and_fails_at_the_end() {
    let out = prism()
        .args([
            "bench",
            "--runs",
            "1",
            "--width",
            "16",
            "--height",
            "12",
            "--json",
            "--transport",
            "path",
        ])
        .arg(assets().join("illustration.toml"))
        .arg(assets().join("whitted.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("illustration.toml") && err.contains("(skipped)"),
        "{err}"
    );
    assert!(err.contains("1 of 2 measurements failed"), "{err}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let scenes = json.as_array().unwrap();
    assert_eq!(scenes.len(), 1);
    assert!(
        scenes[0]["scene"]
            .as_str()
            .unwrap()
            .ends_with("whitted.toml")
    );
}

/// `--accel` and `[settings] accel`: every structure renders the same
/// image bit for bit (a small mesh scene); the scene file's choice is
/// used and reported, the command line overrides it, and a bad name is a
/// clean error.
#[test]
fn every_accel_renders_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("knot.toml");
    std::fs::write(
        &scene,
        r#"
[settings]
width = 40
height = 30
accel = "kdtree"
[camera]
look_from = [0, 0.5, 4]
look_at = [0, 0, 0]
[[objects]]
shape = { type = "torus_knot", radius = 1.0, tube = 0.3, segments = 64, sides = 8 }
material = { color = 0.7, mirror = 0.3 }
[[objects]]
shape = { type = "plane" }
translate = [0, -1.5, 0]
[[lights]]
type = "point"
position = [2, 3, 4]
intensity = 40
"#,
    )
    .unwrap();
    let mut images = Vec::new();
    for accel in [None, Some("bvh"), Some("grid"), Some("brute")] {
        let out = dir.path().join(format!("{}.exr", accel.unwrap_or("file")));
        let stats = dir.path().join(format!("{}.json", accel.unwrap_or("file")));
        let mut extra = vec!["--stats", stats.to_str().unwrap()];
        if let Some(a) = accel {
            extra.extend(["--accel", a]);
        }
        assert_success(&render(&scene, &out, &extra));
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert_eq!(json["accel"], accel.unwrap_or("kdtree"), "{json}");
        if accel != Some("brute") {
            assert!(json["accel_bytes"].as_u64().unwrap() > 0);
        }
        images.push(std::fs::read(&out).unwrap());
    }
    for (k, img) in images.iter().enumerate().skip(1) {
        assert!(img == &images[0], "image {k} differs from the kd-tree's");
    }
    let out = dir.path().join("bad.png");
    let bad = render(&scene, &out, &["--accel", "octree"]);
    assert_eq!(bad.status.code(), Some(2), "usage error");
    assert!(!out.exists());
    let bad_scene = dir.path().join("bad.toml");
    std::fs::write(&bad_scene, "[settings]\naccel = \"octree\"\n").unwrap();
    let out = dir.path().join("bad2.png");
    assert_clean_failure(&render(&bad_scene, &out, &[]), &out, &["accel"]);
}

#[test]
fn illustration_options_reject_bad_input_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = assets().join("whitted.toml");
    let out = dir.path().join("w.png");
    let small = ["--width", "16", "--height", "12"];
    let cases: &[(&[&str], &[&str])] = &[
        (&["--line-width", "-1"], &["line width"]),
        (&["--line-width", "0"], &["line width"]),
        (&["--crease-angle", "200"], &["crease angle", "180"]),
        (&["--crease-angle", "-5"], &["crease angle"]),
        (&["--line-color", "0,2,0"], &["colour"]),
        (
            &["--lines-svg", "/no/such/folder/lines.svg"],
            &["lines.svg"],
        ),
        (&["--lines-svg", "lines.txt"], &[".svg"]),
        (
            &["--style", "gooch", "--transport", "path"],
            &["gooch", "path"],
        ),
        (&["--gooch", "0.4,nan,0.2,0.6"], &["gooch"]),
    ];
    for (extra, words) in cases {
        let mut args: Vec<&str> = small.to_vec();
        args.extend_from_slice(extra);
        let o = render(&scene, &out, &args);
        assert_clean_failure(&o, &out, words);
    }
    // Bad [settings] in a scene file are reported with the key's name.
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[settings]\nlines = { crease_angle = 181 }\n[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n",
    )
    .unwrap();
    let o = render(&bad, &out, &[]);
    assert_clean_failure(&o, &out, &["settings.lines", "crease angle"]);
}

#[test]
fn lines_and_svg_are_written_whole() {
    let dir = tempfile::tempdir().unwrap();
    let scene = assets().join("whitted.toml");
    let out = dir.path().join("w.png");
    let svg = dir.path().join("w.svg");
    let o = render(
        &scene,
        &out,
        &[
            "--width",
            "48",
            "--height",
            "36",
            "--style",
            "gooch",
            "--lines",
            "--lines-svg",
        ],
    );
    // --lines-svg takes a value: without one the command line is refused.
    assert_failed_without_panic(&o);
    let o = prism()
        .arg("render")
        .arg(&scene)
        .arg("-o")
        .arg(&out)
        .args([
            "--width",
            "48",
            "--height",
            "36",
            "--style",
            "gooch",
            "--line-width",
            "1.5",
        ])
        .arg("--lines-svg")
        .arg(&svg)
        .arg("--hidden-lines")
        .output()
        .unwrap();
    assert_success(&o);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<?xml") && text.trim_end().ends_with("</svg>"));
    assert!(out.exists());
    // Only the image and the SVG: no temporary file is left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

/// `--render-origin`: a scene translated by 1e7 renders (EXR, bit for bit)
/// as at the origin by default, and visibly worse with the kernels centred
/// on the world origin.
#[test]
fn render_origin_follows_the_camera_unless_asked_otherwise() {
    let dir = tempfile::tempdir().unwrap();
    let scene = |t: f64| {
        let p = |x: f64, y: f64, z: f64| format!("[{:?}, {:?}, {:?}]", t + x, t + y, t + z);
        format!(
            r#"
[settings]
width = 48
height = 36
[camera]
look_from = {cam}
look_at = {at}
[[objects]]
shape = {{ type = "sphere", radius = 0.75 }}
translate = {ball}
material = {{ color = 0.9, diffuse = 0.05, mirror = 0.9 }}
[[objects]]
shape = {{ type = "plane" }}
translate = {floor}
material = {{ texture = {{ checker = {{ scale = 0.5, even = 0.9, odd = 0.2 }} }} }}
[[lights]]
type = "point"
position = {light}
intensity = 60
"#,
            cam = p(0.0, 1.5, 5.0),
            at = p(0.0, 0.75, 0.0),
            ball = p(0.0, 0.75, 0.0),
            floor = p(0.0, 0.0, 0.0),
            light = p(2.0, 5.0, 3.0),
        )
    };
    let near = dir.path().join("near.toml");
    let far = dir.path().join("far.toml");
    std::fs::write(&near, scene(0.0)).unwrap();
    std::fs::write(&far, scene(1e7)).unwrap();
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    for (input, output, extra) in [
        (&near, "near.exr", &[][..]),
        (&far, "far.exr", &[][..]),
        (&far, "far-world.exr", &["--render-origin", "world"][..]),
    ] {
        assert_success(&render(input, &dir.path().join(output), extra));
    }
    assert_eq!(
        read("near.exr"),
        read("far.exr"),
        "the default origin is the camera"
    );
    assert_ne!(read("near.exr"), read("far-world.exr"));
}

/// A small scene with a mesh (a torus knot) and a sphere.
const KNOT: &str = r#"
[settings]
width = 64
height = 48
[camera]
look_from = [0, 0.5, 4]
look_at = [0, 0, 0]
[[objects]]
shape = { type = "torus_knot", radius = 1.0, tube = 0.3, segments = 48, sides = 6 }
[[objects]]
shape = { type = "sphere", radius = 0.4 }
[[lights]]
type = "point"
position = [2, 3, 4]
intensity = 40
"#;

#[test]
fn overlay_options_reject_bad_input_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::common::scenes::write(dir.path(), "knot.toml", KNOT);
    let out = dir.path().join("o.png");
    let svg = dir.path().join("o.svg");
    let cases: &[(&[&str], &[&str])] = &[
        (&["--overlay", "octree"], &["octree"]),
        (&["--overlay-depth", "3"], &["--overlay"]),
        (
            &["--overlay", "kdtree", "--overlay-depth", "0"],
            &["--overlay-depth", "64"],
        ),
        (
            &["--overlay", "bvh", "--overlay-depth", "65"],
            &["--overlay-depth", "64"],
        ),
        (
            &["--overlay", "kdtree", "--overlay-depth", "99999999999"],
            &["--overlay-depth"],
        ),
        (
            &["--overlay", "wireframe", "--overlay-depth", "2"],
            &["levels"],
        ),
        (&["--overlay", "grid", "--overlay-depth", "2"], &["levels"]),
        (
            &["--overlay", "kdtree", "--accel", "grid"],
            &["--accel grid", "kd"],
        ),
        (
            &["--overlay", "bvh", "--overlay-svg", "/no/such/folder/o.svg"],
            &["o.svg"],
        ),
        (&["--overlay", "bvh", "--overlay-svg", "o.txt"], &[".svg"]),
    ];
    for (extra, words) in cases {
        let mut args: Vec<&str> = extra.to_vec();
        if !args.contains(&"--overlay-svg") && args.contains(&"--overlay") {
            args.extend(["--overlay-svg", svg.to_str().unwrap()]);
        }
        let o = render(&scene, &out, &args);
        assert_clean_failure(&o, &out, words);
        assert!(!svg.exists(), "{extra:?} left an SVG");
    }
    // Shards are refused too.
    let exr = dir.path().join("o.exr");
    let o = render(&scene, &exr, &["--overlay", "grid", "--shard", "0/2"]);
    assert_clean_failure(&o, &exr, &["--overlay", "shards"]);
}

#[test]
fn overlay_image_and_svg_are_written_whole() {
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::common::scenes::write(dir.path(), "knot.toml", KNOT);
    let plain = dir.path().join("plain.png");
    assert_success(&render(&scene, &plain, &["--accel", "kdtree"]));
    let out = dir.path().join("o.png");
    let svg = dir.path().join("o.svg");
    let o = render(
        &scene,
        &out,
        &[
            "--overlay",
            "kdtree",
            "--overlay-depth",
            "3",
            "--overlay-svg",
            svg.to_str().unwrap(),
        ],
    );
    assert_success(&o);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<?xml") && text.trim_end().ends_with("</svg>"));
    assert!(text.contains(r#"class="plane visible""#), "{text}");
    assert!(text.contains(r#"class="plane hidden""#), "{text}");
    assert!(text.contains(r#"class="bounds "#), "{text}");
    // The lines are drawn over the image, which is otherwise the render.
    let (a, b) = (
        image::open(&plain).unwrap().to_rgb8(),
        image::open(&out).unwrap().to_rgb8(),
    );
    let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(
        changed > 50 && changed < a.len() / 3 / 2,
        "{changed} pixels changed"
    );
    // Only the scene, the two images and the SVG: no temporary file left.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);
    // Visible pieces only: no hidden line in the SVG.
    let o = render(
        &scene,
        &out,
        &[
            "--overlay",
            "wireframe",
            "--overlay-visible-only",
            "--overlay-svg",
            svg.to_str().unwrap(),
        ],
    );
    assert_success(&o);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains(r#"class="triangle visible""#) && !text.contains("triangle hidden"));
}

/// Bad environment maps and options, given with `--env` or in a scene's
/// `[environment]`: a clear error naming the problem, no output file.
#[test]
fn bad_environment_maps_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out_file = d.join("a.png");
    let hdr = |name: &str, bytes: &[u8]| {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n".to_vec();
    let zero = hdr("zero.hdr", &[&header[..], b"-Y 0 +X 0\n"].concat());
    let mut flat = [&header[..], b"-Y 2 +X 4\n"].concat();
    flat.extend([128u8, 128, 128, 129].repeat(3));
    let truncated = hdr("truncated.hdr", &flat);
    let garbage = hdr("garbage.hdr", b"this is not an image");
    let nan = d.join("nan.exr");
    image::DynamicImage::ImageRgb32F(image::Rgb32FImage::from_fn(4, 2, |x, _| {
        image::Rgb([1.0, if x == 3 { f32::NAN } else { 0.5 }, 1.0])
    }))
    .save(&nan)
    .unwrap();
    let scene = assets().join("whitted.toml");
    for (map, words) in [
        (
            d.join("missing.hdr"),
            &["missing.hdr", "environment map"][..],
        ),
        (zero, &["zero.hdr", "empty"][..]),
        (truncated, &["truncated.hdr"][..]),
        (garbage, &["garbage.hdr", "not a radiance"][..]),
        (nan, &["nan.exr", "column 3, row 0 is nan"][..]),
    ] {
        let out = render(&scene, &out_file, &["--env", map.to_str().unwrap()]);
        assert_clean_failure(&out, &out_file, words);
        // The same map named by a scene file.
        let toml = d.join("env.toml");
        std::fs::write(
            &toml,
            format!(
                "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[environment]\npath = {:?}\n",
                map.file_name().unwrap().to_str().unwrap()
            ),
        )
        .unwrap();
        assert_clean_failure(&render(&toml, &out_file, &[]), &out_file, words);
    }
    for (extra, words) in [
        (&["--env-intensity", "-1"][..], &["--env-intensity"][..]),
        (&["--env-rotation", "nan"][..], &["--env-rotation"][..]),
        (&["--env-intensity", "2"][..], &["need an environment"][..]),
    ] {
        assert_clean_failure(&render(&scene, &out_file, extra), &out_file, words);
    }
    let toml = d.join("both.toml");
    std::fs::write(
        &toml,
        "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[environment]\ncolor = 1\npath = \"a.hdr\"\n",
    )
    .unwrap();
    assert_clean_failure(&render(&toml, &out_file, &[]), &out_file, &["exactly one"]);
}

/// `--env` with the sample map renders a finite image (skipped when the
/// samples are absent).
#[test]
fn the_sample_environment_map_renders() {
    let map = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/samples/envmaps/spiaggia_di_mondello_1k.hdr");
    if !map.exists() {
        eprintln!("skipped: {} is absent", map.display());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("a.exr");
    let out = render(
        &assets().join("whitted.toml"),
        &out_file,
        &[
            "--env",
            map.to_str().unwrap(),
            "--env-rotation",
            "90",
            "--transport",
            "path",
            "--width",
            "32",
            "--height",
            "24",
        ],
    );
    assert_success(&out);
    let img = image::open(&out_file).unwrap().to_rgb32f();
    assert!(img.pixels().all(|p| p.0.iter().all(|c| c.is_finite())));
    assert!(img.pixels().any(|p| p.0[1] > 0.1));
}

/// `--no-caustics` turns off the light tracing a scene's `[settings]`
/// ask for: the wavefront integrator, which refuses it, then renders.
#[test]
fn no_caustics_overrides_the_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("c.toml");
    std::fs::write(
        &scene,
        "[settings]\ntransport = \"path\"\ncaustics = true\n[camera]\nlook_from = [0, 0, 5]\n\
         look_at = [0, 0, 0]\n[[objects]]\nshape = { type = \"sphere\", radius = 1.0 }\n",
    )
    .unwrap();
    let out = dir.path().join("c.png");
    let small = ["--width", "8", "--height", "6", "--integrator", "wavefront"];
    assert_clean_failure(
        &render(&scene, &out, &small),
        &out,
        &["--integrator recursive"],
    );
    let mut args = small.to_vec();
    args.push("--no-caustics");
    assert_success(&render(&scene, &out, &args));
    assert!(out.exists());
}

/// `--rr-weight` outside (0, 1], or not a number, is refused with a
/// message naming it, before anything is written.
#[test]
fn rr_weight_rejects_bad_values_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = assets().join("cornell.toml");
    let out = dir.path().join("c.png");
    for w in ["0", "-0.5", "1.5", "nan", "inf"] {
        let flag = format!("--rr-weight={w}");
        let o = render(&scene, &out, &["--width", "8", "--height", "6", &flag]);
        assert_clean_failure(&o, &out, &["Russian roulette weight", "(0, 1]"]);
    }
}

/// Photon transport's options reject bad values with a clear message, and
/// the wavefront integrator says it does not run photon transport.
#[test]
fn photon_options_reject_bad_input_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = assets().join("caustic.toml");
    let out = dir.path().join("c.png");
    let small = ["--width", "8", "--height", "6"];
    let cases: &[(&[&str], &[&str])] = &[
        (&["--photons", "0"], &["photons per iteration"]),
        (&["--photon-radius", "0"], &["radius"]),
        (&["--photon-radius", "nan"], &["radius", "NaN"]),
        (&["--photon-radius", "-1"], &["radius"]),
        (&["--photon-alpha", "1"], &["alpha"]),
        (&["--photon-iterations", "0"], &["iterations"]),
        (
            &["--photon-iterations", "1048576", "--spp", "2"],
            &["iterations times samples"],
        ),
        (&["--integrator", "wavefront"], &["recursive"]),
    ];
    for (extra, words) in cases {
        let mut args: Vec<&str> = small.to_vec();
        args.extend_from_slice(extra);
        let o = render(&scene, &out, &args);
        assert_clean_failure(&o, &out, words);
    }
    // Shards need the whole image's photons per pixel row: refused.
    let exr = dir.path().join("c.exr");
    let mut args: Vec<&str> = small.to_vec();
    args.extend_from_slice(&["--shard", "0/2"]);
    assert_clean_failure(&render(&scene, &exr, &args), &exr, &["whole image"]);
    // The same in a scene file's [settings.photon], named by its key.
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[settings]\ntransport = \"photon\"\n[settings.photon]\nradius = 0.0\n[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n",
    )
    .unwrap();
    assert_clean_failure(
        &render(&bad, &out, &[]),
        &out,
        &["settings.photon", "radius"],
    );
    // A scene with nothing to emit photons.
    let dark = dir.path().join("dark.toml");
    std::fs::write(
        &dark,
        "[settings]\ntransport = \"photon\"\n[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nshape = { type = \"sphere\", radius = 1.0 }\n",
    )
    .unwrap();
    // It gets the default key light, like any unlit scene, and renders.
    let o = render(&dark, &out, &[]);
    assert_success(&o);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("adding a white directional key light"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Under path transport it gets a uniform white environment instead.
    let o = render(&dark, &out, &["--transport", "path"]);
    assert_success(&o);
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .contains("adding a uniform white environment of radiance 1"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Bad medium parameters, on an object's interior and on the global fog:
/// negative or NaN coefficients, |g| >= 1, half of the artist's pair, and
/// an open surface holding a scattering medium. Each gives an error that
/// names the object (or `medium`) and the parameter, exit status 1, no
/// image.
#[test]
fn bad_media_fail_cleanly_naming_the_object() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out_file = d.join("a.png");
    let camera = "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n";
    let ball = |name: &str, shape: &str, interior: &str| {
        format!(
            "{camera}[[objects]]\nname = \"{name}\"\nshape = {shape}\nmaterial = {{ color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.0, {interior} }}\n"
        )
    };
    let sphere = "{ type = \"sphere\", radius = 1.0 }";
    // An open mesh: one triangle.
    let open =
        "{ type = \"mesh\", positions = [[0, 0, 0], [1, 0, 0], [0, 1, 0]], indices = [[0, 1, 2]] }";
    for (i, (scene, words)) in [
        (
            ball("smoke", sphere, "scattering = [1, -1, 1]"),
            &["smoke", "sigma_s", "non-negative"][..],
        ),
        (
            ball("milk", sphere, "scattering = nan"),
            &["milk", "sigma_s"][..],
        ),
        (
            ball("haze", sphere, "scattering = 1, absorption = -0.5"),
            &["haze", "sigma_a"][..],
        ),
        (
            ball("cloud", sphere, "scattering = 1, g = 1.0"),
            &["cloud", "g must lie strictly between -1 and 1"][..],
        ),
        (
            ball("cloud2", sphere, "scattering = 1, g = -1.5"),
            &["cloud2", "g must lie"][..],
        ),
        (
            ball("wax", sphere, "albedo = 0.9"),
            &["wax", "mean_free_path"][..],
        ),
        (
            ball("jade", sphere, "albedo = 1.2, mean_free_path = 0.1"),
            &["jade", "albedo"][..],
        ),
        (
            ball("sheet", open, "scattering = 1"),
            &["sheet", "not closed"][..],
        ),
        (
            ball(
                "disk",
                "{ type = \"disk\", radius = 1.0 }",
                "scattering = 1",
            ),
            &["disk", "not closed"][..],
        ),
        (
            format!(
                "{camera}[[objects]]\nname = \"coated\"\nshape = {sphere}\nmaterial = {{ subsurface_color = 0.5, subsurface_radius = 0.1, ior = 1.4 }}\n"
            ),
            &["coated", "diffuse boundary", "ior"][..],
        ),
        (
            format!(
                "{camera}[[objects]]\nname = \"tinted\"\nshape = {sphere}\nmaterial = {{ subsurface_color = 0.5, subsurface_radius = 0.1, color = 0.3 }}\n"
            ),
            &["tinted", "diffuse boundary", "color"][..],
        ),
        (
            format!("{camera}[medium]\nscattering = -1\n"),
            &["medium", "sigma_s"][..],
        ),
        (
            format!("{camera}[medium]\nscattering = 1\ng = nan\n"),
            &["medium", "g must lie"][..],
        ),
        (
            format!("{camera}[medium]\nabsorption = inf\n"),
            &["medium", "sigma_a"][..],
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let toml = d.join(format!("bad{i}.toml"));
        std::fs::write(&toml, &scene).unwrap();
        assert_clean_failure(&render(&toml, &out_file, &[]), &out_file, words);
    }
}
