//! `prism render --shard/--pixel-bounds/--samples` and `prism merge` as a
//! user runs them: merged shards are byte for byte the single render, and
//! every bad set of shards is refused with exit status 1, a message naming
//! the file, and no output.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::assets;
use crate::common::cli::{assert_failed_without_panic, assert_success, prism};

/// The small render every test shards: 24x16 pixels, 2 samples.
const SIZE: [&str; 6] = ["--width", "24", "--height", "16", "--spp", "2"];

fn whitted() -> PathBuf {
    assets().join("whitted.toml")
}

fn render(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    prism()
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .args(SIZE)
        .args(extra)
        .env_remove("PRISM_SHARD_INDEX")
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap()
}

fn rendered(scene: &Path, out: &Path, extra: &[&str]) -> PathBuf {
    assert_success(&render(scene, out, extra));
    out.to_path_buf()
}

fn merge(shards: &[&Path], out: &Path) -> Output {
    prism()
        .arg("merge")
        .args(shards)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .output()
        .unwrap()
}

/// Asserts exit status 1 (no panic), a message naming `file` and saying
/// `what`, and that nothing was written to the output's folder.
fn assert_refused(out: &Output, output: &Path, file: &Path, what: &str) {
    let stderr = assert_failed_without_panic(out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(
        stderr.contains(name),
        "message should name {name}: {stderr}"
    );
    assert!(
        stderr.contains(what),
        "message should say {what:?}: {stderr}"
    );
    assert!(
        !output.exists(),
        "a refused merge wrote {}",
        output.display()
    );
    let dir = output.parent().unwrap();
    let leftovers: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".prism-"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn merged_shards_are_the_single_render_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let single = rendered(&whitted(), &d.join("single.exr"), &[]);
    let single_png = rendered(&whitted(), &d.join("single.png"), &[]);
    let shards: Vec<PathBuf> = (0..3)
        .map(|i| {
            rendered(
                &whitted(),
                &d.join(format!("s{i}.exr")),
                &["--shard", &format!("{i}/3")],
            )
        })
        .collect();
    let refs: Vec<&Path> = shards.iter().map(|p| p.as_path()).collect();
    // Any order.
    let merged = d.join("merged.exr");
    assert_success(&merge(&[refs[2], refs[0], refs[1]], &merged));
    assert!(std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap());
    // The PNG is tone mapped after the merge: the single render's bytes too.
    let merged_png = d.join("merged.png");
    assert_success(&merge(&refs, &merged_png));
    assert!(std::fs::read(&merged_png).unwrap() == std::fs::read(&single_png).unwrap());

    // Sample shards of region shards, the index from a scheduler's variable.
    let mut parts = Vec::new();
    for (i, var) in ["PRISM_SHARD_INDEX", "SLURM_ARRAY_TASK_ID"]
        .iter()
        .enumerate()
    {
        for samples in ["0..1", "1..2"] {
            let out = d.join(format!("a{i}-{samples}.exr"));
            let o = prism()
                .args(["render", whitted().to_str().unwrap(), "-q", "-o"])
                .arg(&out)
                .args(SIZE)
                .args(["--shard", "auto/2", "--samples", samples])
                .env_remove("PRISM_SHARD_INDEX")
                .env(var, i.to_string())
                .output()
                .unwrap();
            assert_success(&o);
            parts.push(out);
        }
    }
    let refs: Vec<&Path> = parts.iter().map(|p| p.as_path()).collect();
    let merged2 = d.join("merged2.exr");
    assert_success(&merge(&refs, &merged2));
    assert!(std::fs::read(&merged2).unwrap() == std::fs::read(&single).unwrap());
}

/// A mesh scene: its BVHs are built again in every shard, with whatever
/// thread count the shard has, and must come out the same.
#[test]
fn mesh_shards_with_other_thread_counts_merge_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = d.join("knot.toml");
    std::fs::write(
        &scene,
        r#"
[camera]
look_from = [0, 1, 4]
look_at = [0, 0, 0]

[[lights]]
type = "point"
position = [2, 4, 3]
intensity = 40

[[objects]]
shape = { type = "torus_knot", radius = 1.0, tube = 0.3, segments = 300, sides = 24 }
material = { color = [0.8, 0.5, 0.3], mirror = 0.2 }
"#,
    )
    .unwrap();
    let single = rendered(
        &scene,
        &d.join("single.exr"),
        &["--threads", "2", "--max-depth", "3"],
    );
    let shards: Vec<PathBuf> = (0..3)
        .map(|i| {
            let args = [
                "--threads",
                "1",
                "--max-depth",
                "3",
                "--shard",
                &format!("{i}/3"),
            ];
            rendered(&scene, &d.join(format!("k{i}.exr")), &args)
        })
        .collect();
    let refs: Vec<&Path> = shards.iter().map(|p| p.as_path()).collect();
    let merged = d.join("merged.exr");
    assert_success(&merge(&refs, &merged));
    assert!(std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap());
}

#[test]
fn bad_shard_sets_are_refused_naming_the_file_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out").join("merged.exr");
    std::fs::create_dir(out.parent().unwrap()).unwrap();
    let shard = |name: &str, extra: &[&str]| rendered(&whitted(), &d.join(name), extra);
    let s0 = shard("s0.exr", &["--shard", "0/2"]);
    let s1 = shard("s1.exr", &["--shard", "1/2"]);

    // Another scene (same settings).
    let other_scene = d.join("other.toml");
    std::fs::write(
        &other_scene,
        std::fs::read_to_string(whitted())
            .unwrap()
            .replace("vfov = 40", "vfov = 41"),
    )
    .unwrap();
    let foreign_scene = rendered(
        &other_scene,
        &d.join("other-scene.exr"),
        &["--shard", "1/2"],
    );
    assert_refused(
        &merge(&[&s0, &foreign_scene], &out),
        &out,
        &foreign_scene,
        "different scene",
    );

    // Other settings.
    let deeper = shard("deeper.exr", &["--shard", "1/2", "--max-depth", "3"]);
    assert_refused(&merge(&[&s0, &deeper], &out), &out, &deeper, "settings");

    // Overlapping regions.
    let top = shard("top.exr", &["--pixel-bounds", "0,24,0,9"]);
    let bottom = shard("bottom.exr", &["--pixel-bounds", "0,24,8,16"]);
    assert_refused(&merge(&[&top, &bottom], &out), &out, &bottom, "overlap");

    // A gap: half the shards.
    assert_refused(&merge(&[&s0], &out), &out, &s0, "gap");

    // The same shard twice, as one file or a copy.
    assert_refused(&merge(&[&s0, &s1, &s0], &out), &out, &s0, "duplicate");
    let copy = d.join("s1-copy.exr");
    std::fs::copy(&s1, &copy).unwrap();
    assert_refused(&merge(&[&s0, &s1, &copy], &out), &out, &copy, "duplicate");

    // Sample ranges: one missing, and the same range twice.
    let first = shard("first.exr", &["--samples", "0..1"]);
    assert_refused(&merge(&[&first], &out), &out, &first, "missing samples");
    let again = shard("again.exr", &["--samples", "0..1"]);
    assert_refused(&merge(&[&first, &again], &out), &out, &again, "duplicate");

    // A truncated shard, a plain render and a file that is no EXR at all.
    let bytes = std::fs::read(&s1).unwrap();
    for keep in [bytes.len() / 2, bytes.len() - 1, 100] {
        let truncated = d.join(format!("truncated{keep}.exr"));
        std::fs::write(&truncated, &bytes[..keep]).unwrap();
        assert_refused(&merge(&[&s0, &truncated], &out), &out, &truncated, "");
    }
    let plain = rendered(&whitted(), &d.join("plain.exr"), &[]);
    assert_refused(&merge(&[&plain], &out), &out, &plain, "not a Prism shard");
    let png = rendered(&whitted(), &d.join("picture.png"), &[]);
    let renamed = d.join("picture.exr");
    std::fs::rename(&png, &renamed).unwrap();
    assert_refused(&merge(&[&s0, &renamed], &out), &out, &renamed, "OpenEXR");

    // And the good set merges.
    assert_success(&merge(&[&s0, &s1], &out));
}

#[test]
fn bad_shard_options_fail_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&[&str], &str); 6] = [
        (&["--shard", "3/3"], "below"),
        (&["--shard", "0/17"], "at most 16 shards"),
        (&["--shard", "auto/2"], "PRISM_SHARD_INDEX"),
        (&["--pixel-bounds", "0,25,0,4"], "outside"),
        (&["--samples", "1..3"], "beyond"),
        (
            &["--shard", "0/2", "--pixel-bounds", "0,4,0,4"],
            "cannot be used with",
        ),
    ];
    for (args, what) in cases {
        let out = d.join("s.exr");
        let o = render(&whitted(), &out, args);
        let stderr = assert_failed_without_panic(&o);
        assert!(stderr.contains(what), "{args:?}: {stderr}");
        assert!(!out.exists());
    }
    let png = d.join("s.png");
    let o = render(&whitted(), &png, &["--shard", "0/2"]);
    assert!(assert_failed_without_panic(&o).contains(".exr"));
    assert!(!png.exists());
}
