//! The wavefront integrator against the recursive one, and its queues.

use std::path::{Path, PathBuf};

use bevy_ecs::prelude::*;
use prism::core::settings::RenderSettings;
use prism::geometry::mesh::BuildQuality;
use prism::image::film::Film;
use prism::integrators::IntegratorKind;
use prism::scene::material::MaterialClass;
use prism::systems::wavefront::{
    self, BatchSize, Bounce, CurrentRays, EscapedRays, NextRays, ShadowRays, StartBatch,
    WavefrontFrame, hit_queue, hit_queue_mut,
};
use prism::systems::{self, Frame, RenderConfig};

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

fn settings(width: u32, height: u32, spp: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp,
        seed: 5,
        ..Default::default()
    }
}

fn render(path: &Path, kind: IntegratorKind, s: &RenderSettings, batch: usize) -> Frame {
    let desc = prism::io::load(path, BuildQuality::Medium).unwrap();
    let mut world = World::new();
    let mut schedule = systems::setup(&mut world);
    let background = desc.background;
    let cameras = systems::spawn_scene(&mut world, desc);
    world.insert_resource(BatchSize(batch));
    world.insert_resource(RenderConfig {
        settings: s.clone(),
        integrator: kind,
        camera: Some(cameras[0]),
        background,
        ..Default::default()
    });
    schedule.run(&mut world);
    world.remove_resource::<Frame>().unwrap()
}

/// Every pixel within 1e-4 relative or 1e-6 absolute.
fn assert_same_image(a: &Film, b: &Film, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        for (x, y) in p.to_array().into_iter().zip(q.to_array()) {
            let diff = (x - y).abs();
            assert!(
                diff <= 1e-6 || diff <= 1e-4 * x.abs().max(y.abs()),
                "{what}: pixel {i} differs: {p} vs {q}"
            );
        }
    }
}

/// Every scene in assets/ (and the sample scenes when present).
fn scenes() -> Vec<PathBuf> {
    let mut v = Vec::new();
    let mut stack = vec![assets()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("toml" | "gltf" | "glb")
            ) {
                v.push(p);
            }
        }
    }
    v.sort();
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/samples");
    for s in [
        "CornellBox/CornellBox.glb",
        "DamagedHelmet/glTF/DamagedHelmet.gltf",
    ] {
        let p = samples.join(s);
        if p.exists() {
            v.push(p);
        } else {
            eprintln!("skipped {s}: ../shared/samples not found");
        }
    }
    v
}

#[test]
fn both_integrators_give_the_same_image_on_every_scene() {
    let s = settings(48, 36, 2);
    let scenes = scenes();
    assert!(scenes.len() >= 3);
    for path in scenes {
        let desc = prism::io::load(&path, BuildQuality::Medium).unwrap();
        if desc.cameras.is_empty() {
            continue;
        }
        let rec = render(&path, IntegratorKind::Recursive, &s, 1000);
        // A batch size that splits pixels' samples across batches.
        let wav = render(&path, IntegratorKind::Wavefront, &s, 1001);
        let name = path.display().to_string();
        assert_same_image(
            rec.film.as_ref().unwrap(),
            wav.film.as_ref().unwrap(),
            &name,
        );
        assert_eq!(rec.counters, wav.counters, "{name}: ray counts");
    }
}

#[test]
fn test_scenes_match_too() {
    // The analytic scenes of tests/render.rs, through both integrators.
    let dir = tempfile::tempdir().unwrap();
    let lens = dir.path().join("lens.toml");
    std::fs::write(
        &lens,
        r#"
[camera]
look_from = [0, 0, 10]
look_at = [0, 0, 0]
vfov = 20
[[objects]]
shape = { type = "sphere", radius = 1.0 }
material = { color = 1.0, diffuse = 0.0, transmission = 1.0, ior = 1.5 }
[[objects]]
shape = { type = "polygon", vertices = [[-8, 0, -4], [8, 0, -4], [8, 8, -4], [-8, 8, -4]] }
material = { color = 0.0, emission = [1, 0, 0] }
[[objects]]
shape = { type = "plane" }
material = { color = 0.5, mirror = 0.3 }
translate = [0, -1.5, 0]
[[lights]]
type = "spot"
position = [0, 5, 3]
direction = [0, -1, -0.5]
intensity = 40
"#,
    )
    .unwrap();
    let s = settings(40, 40, 1);
    let rec = render(&lens, IntegratorKind::Recursive, &s, 97);
    let wav = render(&lens, IntegratorKind::Wavefront, &s, 97);
    assert_same_image(
        rec.film.as_ref().unwrap(),
        wav.film.as_ref().unwrap(),
        "lens",
    );
}

#[test]
fn each_integrator_is_bit_identical_whatever_the_thread_count() {
    let path = assets().join("quadrics.toml");
    let s = settings(40, 24, 3);
    for kind in IntegratorKind::ALL {
        let bits = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                render(&path, kind, &s, 700)
                    .film
                    .unwrap()
                    .pixels
                    .iter()
                    .flat_map(|p| p.to_array().map(f32::to_bits))
                    .collect::<Vec<_>>()
            })
        };
        let one = bits(1);
        assert_eq!(one, bits(2), "{kind:?}: 1 vs 2 threads");
        assert_eq!(one, bits(3), "{kind:?}: 1 vs 3 threads");
        assert_eq!(one, bits(2), "{kind:?}: run to run");
    }
}

/// A world ready to step through the wavefront stages by hand.
fn stepping_world(scene_toml: &str, s: RenderSettings) -> (World, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(&path, scene_toml).unwrap();
    let desc = prism::io::load(&path, BuildQuality::Medium).unwrap();
    let mut world = World::new();
    let mut schedule = systems::setup(&mut world);
    let cameras = systems::spawn_scene(&mut world, desc);
    world.insert_resource(RenderConfig {
        settings: s,
        camera: Some(cameras[0]),
        ..Default::default()
    });
    // Run one (recursive) frame so the scene is extracted and built.
    schedule.run(&mut world);
    let scene = world
        .resource::<systems::SceneAccel>()
        .scene
        .clone()
        .unwrap();
    let camera = world
        .query::<&prism::scene::camera::Camera>()
        .single(&world)
        .unwrap()
        .clone();
    let config = world.resource::<RenderConfig>().settings.clone();
    let classes: Vec<MaterialClass> = scene.materials().iter().map(|m| m.class()).collect();
    let features = prism::scene::features::SceneFeatures::of(&scene);
    let shadows = features.needs_shadow_rays(config.transport);
    world.insert_resource(WavefrontFrame {
        camera: prism::scene::camera::CameraRays::new(&camera, config.width, config.height),
        batches: prism::integrators::wavefront::batch_ranges(&config, 1 << 20).collect(),
        batch: 0,
        scene,
        classes,
        features,
        shadows,
    });
    (world, dir)
}

const DIFFUSE_SCENE: &str = r#"
[camera]
look_from = [0, 1, 6]
look_at = [0, 0.5, 0]
[[objects]]
shape = { type = "sphere", radius = 1.0 }
material = { color = 0.7, specular = 0.2, shininess = 30 }
[[objects]]
shape = { type = "disk", radius = 3.0 }
material = { color = 0.5 }
[[lights]]
type = "point"
position = [2, 4, 3]
intensity = 30
"#;

#[test]
fn stages_drain_their_queues_and_misses_are_escaped() {
    let (mut world, _dir) = stepping_world(DIFFUSE_SCENE, settings(32, 24, 1));
    world.run_schedule(StartBatch);
    let n = world.resource::<CurrentRays>().0.len();
    assert_eq!(n, 32 * 24);
    // Run the closest-hit stage alone to look at its output.
    let mut only_intersect = Schedule::default();
    only_intersect.add_systems(wavefront::intersect_closest);
    only_intersect.run(&mut world);
    let escaped = world.resource::<EscapedRays>().0.len();
    let hits: usize = MaterialClass::ALL
        .iter()
        .map(|&c| hit_queue(&world, c).len())
        .sum();
    assert_eq!(escaped + hits, n, "every ray is routed exactly once");
    assert!(escaped > 0 && hits > 0);
    // Rays that escaped are exactly those the scene says miss.
    let scene = world.resource::<WavefrontFrame>().scene.clone();
    let rays = &world.resource::<CurrentRays>().0;
    let misses = (0..rays.len())
        .filter(|&i| scene.intersect(&rays.ray(i), 0.0, f32::INFINITY).is_none())
        .count();
    assert_eq!(misses, escaped);
    let diffuse = hit_queue(&world, MaterialClass::Diffuse).len();
    assert_eq!(diffuse, hits, "both materials are diffuse");

    // A whole bounce drains every queue it consumes.
    world.resource_mut::<EscapedRays>().0.clear();
    for class in MaterialClass::ALL {
        hit_queue_mut(&mut world, class).clear();
    }
    world.run_schedule(Bounce);
    assert!(world.resource::<EscapedRays>().0.is_empty());
    assert!(
        MaterialClass::ALL
            .iter()
            .all(|&c| hit_queue(&world, c).is_empty())
    );
    assert!(world.resource::<ShadowRays>().0.is_empty());
    assert!(world.resource::<NextRays>().0.is_empty());
    // Diffuse surfaces spawn no secondary rays: the frame ends after one bounce.
    assert!(world.resource::<CurrentRays>().0.is_empty());
}

#[test]
fn a_scene_without_glass_never_pushes_a_refraction_ray() {
    let mirror_scene = DIFFUSE_SCENE.replace(
        "material = { color = 0.7, specular = 0.2, shininess = 30 }",
        "material = { color = 0.0, diffuse = 0.0, mirror = 0.9 }",
    );
    let s = settings(32, 24, 1);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.toml");
    std::fs::write(&path, &mirror_scene).unwrap();
    let frame = render(&path, IntegratorKind::Wavefront, &s, 100);
    assert_eq!(frame.counters.rays.refraction, 0);
    assert!(frame.counters.rays.reflection > 0);

    // And with glass, it does.
    let glass = DIFFUSE_SCENE.replace(
        "material = { color = 0.7, specular = 0.2, shininess = 30 }",
        "material = { color = 1.0, diffuse = 0.0, transmission = 1.0 }",
    );
    std::fs::write(&path, &glass).unwrap();
    let frame = render(&path, IntegratorKind::Wavefront, &s, 100);
    assert!(frame.counters.rays.refraction > 0);
}

#[test]
fn queue_memory_is_bounded_by_the_batch_not_the_image() {
    let path = assets().join("whitted.toml");
    let peak = |w: u32, h: u32| {
        render(&path, IntegratorKind::Wavefront, &settings(w, h, 1), 4096)
            .wavefront
            .unwrap()
            .peak_queue_bytes
    };
    let small = peak(128, 96);
    let large = peak(512, 384);
    assert!(small > 0);
    // 16 times the pixels, same batch: queue memory may differ only by how
    // many secondary rays a batch spawns, not by the image size.
    assert!(
        (large as f64) < 1.5 * small as f64,
        "peak queue bytes {small} at 128x96 but {large} at 512x384"
    );
}
