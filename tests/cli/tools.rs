//! Measuring tools: the error trend against samples per pixel, and the
//! `prism compare` and `prism tradeoff` commands run as a user would.

use std::path::{Path, PathBuf};
use std::process::Output;

use glam::Vec3;
use prism::core::settings::{RenderSettings, Transport};
use prism::image::film::Film;
use prism::image::metrics;
use prism::image::output::PngOptions;
use prism::integrators::IntegratorKind;

use crate::common::cli::{assert_failed_without_panic, assert_success, prism};
use crate::common::render::{config, render_file};
use crate::common::{assets, scenes};

/// The Cornell box with its panel dimmed tenfold and a point light added,
/// so that both transports light the room: Whitted from the point light
/// (hard shadow and block edges to antialias), path tracing from both.
/// The full-strength panel makes single rare hits on its edge dominate
/// the error of a tiny image, which would test luck, not convergence.
fn lit_cornell(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(assets().join("cornell.toml")).unwrap();
    let dimmed = text.replace("emission = [17.0, 12.0, 4.0]", "emission = [1.7, 1.2, 0.4]");
    assert_ne!(
        dimmed, text,
        "cornell.toml's panel emission changed: update this test"
    );
    let scene = format!(
        "{dimmed}\n[[lights]]\ntype = \"point\"\nposition = [2.0, 4.5, 1.5]\nintensity = 30.0\n"
    );
    scenes::write(dir, "lit_cornell.toml", &scene)
}

fn render(scene: &Path, settings: RenderSettings) -> Film {
    render_file(scene, config(settings, IntegratorKind::default()))
        .film
        .unwrap()
}

/// Error must fall as samples per pixel rise.
///
/// Each pixel's estimate is a mean of `spp` independent samples and the
/// reference one of `R` samples under another seed, both with the same
/// expectation, so the expected squared error is `v (1/spp + 1/R)` for
/// the per-pixel variance `v`. With `R = 512` each fourfold step in spp
/// divides it by (1/4 + 1/512) / (1/16 + 1/512) = 3.9 and then by
/// (1/16 + 1/512) / (1/64 + 1/512) = 3.7. The measured error is itself a
/// random estimate over 24x24 pixels, so we ask for a factor of 2: about
/// half the expected fall. (One spp is left out: it samples the pixel
/// centre, without jitter.) Holds for Whitted, where the randomness is
/// the antialiasing jitter, and for path tracing.
#[test]
fn error_falls_as_spp_rises() {
    let dir = tempfile::tempdir().unwrap();
    let scene = lit_cornell(dir.path());
    for transport in [Transport::Whitted, Transport::Path] {
        let settings = |spp, seed| RenderSettings {
            width: 24,
            height: 24,
            spp,
            max_depth: 4,
            seed,
            transport,
            ..Default::default()
        };
        let reference = render(&scene, settings(512, 1));
        let mut previous: Option<(u32, f64, f64)> = None;
        for spp in [4, 16, 64] {
            let film = render(&scene, settings(spp, 0));
            let rel = metrics::rel_mse(&film, &reference).unwrap();
            let mse = metrics::rmse(&film, &reference).unwrap().powi(2);
            assert!(
                rel > 0.0 && mse > 0.0,
                "{transport:?} {spp} spp: no error at all"
            );
            if let Some((p, prev_rel, prev_mse)) = previous {
                assert!(
                    prev_rel > 2.0 * rel,
                    "{transport:?}: relMSE {prev_rel:.3e} at {p} spp, {rel:.3e} at {spp} spp"
                );
                assert!(
                    prev_mse > 2.0 * mse,
                    "{transport:?}: MSE {prev_mse:.3e} at {p} spp, {mse:.3e} at {spp} spp"
                );
            }
            previous = Some((spp, rel, mse));
        }
    }
}

/// Asserts a clean failure: non-zero status that is not a panic, an
/// `error:` line mentioning `words`.
fn assert_clean_failure(out: &Output, words: &[&str]) {
    let stderr = assert_failed_without_panic(out);
    assert!(stderr.contains("error:"), "no error message: {stderr}");
    for w in words {
        assert!(stderr.contains(w), "message should mention {w:?}: {stderr}");
    }
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn compare_prints_the_metrics_and_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Reference: a ramp; test: the ramp plus 0.5 in every channel.
    let reference = Film {
        width: 4,
        height: 3,
        pixels: (0..12).map(|i| Vec3::splat(i as f32 * 0.25)).collect(),
    };
    let mut test = reference.clone();
    for p in &mut test.pixels {
        *p += Vec3::splat(0.5);
    }
    let (a, b) = (d.join("a.exr"), d.join("b.exr"));
    prism::image::output::write_image(&a, &test, &PngOptions::default()).unwrap();
    prism::image::output::write_image(&b, &reference, &PngOptions::default()).unwrap();

    let out = prism()
        .arg("compare")
        .arg(&a)
        .arg(&b)
        .arg("--json")
        .output()
        .unwrap();
    assert_success(&out);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // RMSE of a constant offset is the offset; relMSE by hand:
    // mean over i of 0.25 / ((0.25 i)^2 + 0.01).
    let expected_rel: f64 = (0..12)
        .map(|i| 0.25 / ((0.25 * i as f64).powi(2) + 0.01))
        .sum::<f64>()
        / 12.0;
    assert!(
        (json["rmse"].as_f64().unwrap() - 0.5).abs() < 1e-9,
        "{json}"
    );
    assert!(
        (json["rel_mse"].as_f64().unwrap() - expected_rel).abs() < 1e-9 * expected_rel,
        "{json}"
    );
    let flip = json["flip"].as_f64().unwrap();
    assert!(flip > 0.0 && flip <= 1.0, "{json}");
    assert_eq!(
        (json["width"].as_u64(), json["height"].as_u64()),
        (Some(4), Some(3))
    );

    // The table: the same numbers, and identical images give zero.
    let out = prism().arg("compare").arg(&b).arg(&b).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("RMSE:      0.000000e0"), "{text}");
    assert!(text.contains("FLIP:      0.000000"), "{text}");

    // Bad input: a clean error, and nothing written.
    let before = files_in(d);
    let missing = d.join("missing.exr");
    let out = prism()
        .arg("compare")
        .arg(&missing)
        .arg(&b)
        .output()
        .unwrap();
    assert_clean_failure(&out, &["missing.exr"]);
    let small = d.join("small.exr");
    prism::image::output::write_image(&small, &Film::new(2, 2), &PngOptions::default()).unwrap();
    let out = prism().arg("compare").arg(&small).arg(&b).output().unwrap();
    assert_clean_failure(&out, &["2x2", "4x3"]);
    let garbage = d.join("garbage.exr");
    std::fs::write(&garbage, b"not an image").unwrap();
    let out = prism()
        .arg("compare")
        .arg(&a)
        .arg(&garbage)
        .output()
        .unwrap();
    assert_clean_failure(&out, &["garbage.exr"]);
    let png = d.join("a.png");
    let out = prism().arg("compare").arg(&png).arg(&b).output().unwrap();
    assert_clean_failure(&out, &["a.png"]);
    let mut after = files_in(d);
    after.retain(|f| f != "small.exr" && f != "garbage.exr");
    assert_eq!(after, before, "compare wrote files");
}

const HEADER: &str = "knob,value,transport,spp,max_depth,min_contribution,light_samples,\
russian_roulette,bvh,integrator,seconds,rays,rmse,rel_mse,flip,accel,rr_weight,split";

fn tradeoff(out: &Path, extra: &[&str]) -> Output {
    prism()
        .arg("tradeoff")
        .arg(assets().join("cornell.toml"))
        .arg("--out")
        .arg(out)
        .args([
            "--width",
            "8",
            "--height",
            "8",
            "--reference-spp",
            "32",
            // A coarse radiosity solve for the transport knob's row.
            "--patch-size",
            "1.4",
            "--refine-levels",
            "0",
            "-q",
        ])
        .args(extra)
        .output()
        .unwrap()
}

/// The CSV without its timing column, for determinism checks.
fn without_seconds(csv: &str) -> Vec<String> {
    csv.lines()
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(10);
            f.join(",")
        })
        .collect()
}

#[test]
fn tradeoff_writes_the_csv_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("run");
    let out = tradeoff(&out_dir, &[]);
    assert_success(&out);
    assert_eq!(
        files_in(&out_dir),
        [
            "reference.exr",
            "tradeoff.csv",
            "tradeoff.png",
            "tradeoff.svg"
        ]
    );
    let csv = std::fs::read_to_string(out_dir.join("tradeoff.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], HEADER);
    // The base, then every knob's values but the base's: spp 6 of 7, depth
    // 6 of 7, threshold 5 of 6, light samples 3 of 4, roulette 3 of 4,
    // roulette weight 3 of 4, BVH 5 of 6, transport 3 of 4 (whitted, photon, radiosity), sampler
    // 1 of 2, accel 2 of 3, split 2 of 3 (the photon-iterations knob is
    // not swept by default).
    assert_eq!(
        lines.len(),
        1 + 1 + 6 + 6 + 5 + 3 + 3 + 3 + 5 + 3 + 1 + 2 + 2
    );
    for t in ["transport,photon,", "transport,radiosity,"] {
        assert!(lines.iter().any(|l| l.starts_with(t)), "no {t} row");
    }
    assert!(lines[1].starts_with("base,,path,16,8,0.001,1,3,medium,recursive,"));
    let knobs: Vec<&str> = lines[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap())
        .collect();
    for k in [
        "spp",
        "max-depth",
        "min-contribution",
        "light-samples",
        "russian-roulette",
        "rr-weight",
        "bvh",
        "transport",
        "sampler",
        "accel",
        "split",
    ] {
        assert!(knobs.contains(&k), "no {k} rows");
    }
    for l in &lines[1..] {
        let f: Vec<&str> = l.split(',').collect();
        assert_eq!(f.len(), 18, "{l}");
        let spp: u64 = f[3].parse().unwrap();
        let seconds: f64 = f[10].parse().unwrap();
        let rays: u64 = f[11].parse().unwrap();
        assert!(seconds >= 0.0 && seconds.is_finite(), "{l}");
        // At least one camera ray per pixel sample.
        assert!(rays >= 64 * spp, "{l}");
        for m in &f[12..15] {
            let m: f64 = m.parse().unwrap();
            assert!(m.is_finite() && m >= 0.0, "{l}");
        }
        assert!(["bvh", "kdtree", "grid"].contains(&f[15]), "{l}");
        let w: f32 = f[16].parse().unwrap();
        assert!(w > 0.0 && w <= 1.0, "{l}");
        let split: u32 = f[17].parse().unwrap();
        assert!([1, 2, 4].contains(&split), "{l}");
    }
    let spp1 = lines.iter().find(|l| l.starts_with("spp,1,")).unwrap();
    assert!(spp1.starts_with("spp,1,path,1,8,"), "{spp1}");
    let png = image::open(out_dir.join("tradeoff.png")).unwrap();
    assert_eq!((png.width(), png.height()), (1100, 760));
    let svg = std::fs::read_to_string(out_dir.join("tradeoff.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("<circle"), "{svg}");
    // The legend needs a font; the machines have DejaVu Sans.
    if Path::new("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf").exists() {
        assert!(svg.contains("Pareto front"));
    }
    let reference = metrics::read_exr(&out_dir.join("reference.exr")).unwrap();
    assert_eq!((reference.width, reference.height), (8, 8));

    // Deterministic: the given reference gives the same rows but the times.
    let again = dir.path().join("again");
    let reference_arg = out_dir.join("reference.exr");
    let out = tradeoff(&again, &["--reference", reference_arg.to_str().unwrap()]);
    assert_success(&out);
    assert_eq!(
        files_in(&again),
        ["tradeoff.csv", "tradeoff.png", "tradeoff.svg"]
    );
    let csv2 = std::fs::read_to_string(again.join("tradeoff.csv")).unwrap();
    assert_eq!(without_seconds(&csv2), without_seconds(&csv));
}

#[test]
fn tradeoff_rejects_bad_input_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = d.join("small.exr");
    prism::image::output::write_image(&small, &Film::new(4, 4), &PngOptions::default()).unwrap();
    let out_dir = d.join("run");
    let out = tradeoff(&out_dir, &["--reference", small.to_str().unwrap()]);
    assert_clean_failure(&out, &["4x4", "8x8"]);
    assert!(!out_dir.exists(), "a failed run created its folder");
    let out = tradeoff(
        &out_dir,
        &["--reference", d.join("nope.exr").to_str().unwrap()],
    );
    assert_clean_failure(&out, &["nope.exr"]);
    let out = tradeoff(&out_dir, &["--reference-spp", "0"]);
    assert_clean_failure(&out, &["--reference-spp"]);
    let out = tradeoff(&out_dir, &["--knobs", "spp", "--spp", "0"]);
    assert_clean_failure(&out, &["samples per pixel"]);
    assert!(!out_dir.exists(), "a failed run created its folder");
    // An output path that is a file.
    let file = d.join("file");
    std::fs::write(&file, b"x").unwrap();
    let out = tradeoff(&file, &[]);
    assert_clean_failure(&out, &["file", "not a folder"]);
}

/// Writes an anchors-format workload: two triangles forming the square
/// [-1, 1]^2 at z = 0, rays down the z axis through a grid (inside and
/// outside the square), and reference hits computed here.
fn anchors_workload(dir: &Path, corrupt_refs: bool) {
    let header = |magic: &[u8; 8], a: u32, b: u32, c: u32| {
        let mut h = magic.to_vec();
        for v in [a, b, c, 0, 1, 0] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h
    };
    let mut mesh = header(b"ANCMESH1", 4, 2, 0);
    for p in [
        [-1.0f32, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ] {
        for c in p {
            mesh.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in [[0u32, 1, 2], [0, 2, 3]] {
        for i in t {
            mesh.extend_from_slice(&i.to_le_bytes());
        }
    }
    std::fs::write(dir.join("mesh.bin"), mesh).unwrap();
    for name in ["primary", "incoherent"] {
        let n = 64u32;
        let mut rays = header(b"ANCRAYS1", n, 8, 8);
        let mut refs = header(b"ANCREFS1", n - corrupt_refs as u32, 0, 0);
        for k in 0..n {
            // x, y in [-1.6, 1.6): points beyond |1| miss.
            let (x, y) = ((k % 8) as f32 * 0.4 - 1.5, (k / 8) as f32 * 0.4 - 1.5);
            for v in [x, y, 5.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY] {
                rays.extend_from_slice(&v.to_le_bytes());
            }
            let inside = x.abs() < 1.0 && y.abs() < 1.0;
            // Triangle 0 holds the points below the diagonal y = x.
            let prim = if !inside {
                u32::MAX
            } else if y < x {
                0
            } else {
                1
            };
            if !(corrupt_refs && k == n - 1) {
                refs.extend_from_slice(&prim.to_le_bytes());
                refs.extend_from_slice(
                    &(if inside { 5.0f32 } else { f32::INFINITY }).to_le_bytes(),
                );
            }
        }
        std::fs::write(dir.join(format!("{name}.rays")), rays).unwrap();
        std::fs::write(dir.join(format!("{name}.ref")), refs).unwrap();
    }
}

#[test]
fn bench_rays_measures_every_mode_and_agrees_with_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    anchors_workload(dir.path(), false);
    let out = prism()
        .args(["bench", "rays"])
        .arg(dir.path())
        .args([
            "--threads",
            "1,2",
            "--reps",
            "1",
            "--build-reps",
            "1",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["triangles"], 2);
    let modes = v["modes"].as_array().unwrap();
    // Two ray sets, five modes (single, packets of 8 and 16, streams,
    // octant-binned single rays), two thread counts.
    assert_eq!(modes.len(), 20);
    for m in modes {
        // 5 x 5 grid points inside the square; the 5 on the shared
        // diagonal go to exactly one of the two triangles, which the
        // reference may name differently.
        assert_eq!(m["hits"], 25, "{m}");
        let agree = m["ref_agree"].as_f64().unwrap();
        assert!(agree >= 1.0 - 5.0 / 64.0, "{m}");
        assert!(m["best_mrays"].as_f64().unwrap() > 0.0);
        // Unix also gives the rate per CPU second.
        if cfg!(unix) {
            assert!(m["best_mrays_per_cpu_s"].as_f64().unwrap() > 0.0, "{m}");
        }
    }
    // Both SIMD paths can be asked for; a wrong file is a clean error.
    let out = prism()
        .args(["bench", "rays"])
        .arg(dir.path())
        .args([
            "--isa",
            "portable",
            "--reps",
            "1",
            "--build-reps",
            "1",
            "--modes",
            "single",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("SIMD path portable"));
    let bad = tempfile::tempdir().unwrap();
    anchors_workload(bad.path(), true);
    let out = prism()
        .args(["bench", "rays"])
        .arg(bad.path())
        .output()
        .unwrap();
    assert_clean_failure(&out, &["primary.ref", "reference hits"]);
    let out = prism()
        .args(["bench", "rays", "/nonexistent/anchors"])
        .output()
        .unwrap();
    assert_clean_failure(&out, &["cannot read", "mesh.bin"]);
}
