//! The wavefront integrator against the recursive one, and its queues.

use std::path::{Path, PathBuf};

use bevy_ecs::prelude::*;
use prism::core::settings::RenderSettings;
use prism::integrators::IntegratorKind;
use prism::scene::material::MaterialClass;
use prism::systems::wavefront::{
    self, BatchSize, Bounce, CurrentRays, EscapedRays, NextRays, ShadowRays, StartBatch,
    WavefrontFrame, hit_queue, hit_queue_mut,
};
use prism::systems::{Frame, RenderConfig, Renderer};

use crate::common::assets;
use crate::common::images::{assert_same_image, film_bits};
use crate::common::render::{config, renderer};
use crate::common::scenes::{self, glass_ball, load_toml, sphere_on_disk};

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
    renderer(scenes::load(path), config(s.clone(), kind))
        .insert_resource(BatchSize(batch))
        .render()
        .unwrap()
}

/// Every scene in assets/ (and the sample scenes when present). Scene
/// files that include a model from `../shared/samples` are skipped when
/// that folder is absent.
fn every_scene() -> Vec<PathBuf> {
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/samples");
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
                let needs_samples = p.extension().is_some_and(|e| e == "toml")
                    && std::fs::read_to_string(&p)
                        .unwrap()
                        .contains("shared/samples");
                if needs_samples && !samples.exists() {
                    eprintln!("skipped {}: ../shared/samples not found", p.display());
                } else {
                    v.push(p);
                }
            }
        }
    }
    v.sort();
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
    let scenes = every_scene();
    assert!(scenes.len() >= 3);
    for path in scenes {
        let desc = scenes::load(&path);
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

/// Under path transport the wavefront hands each path's kept direction
/// set from one bounce's shading to the next through a slot per path
/// index, which every batch must start empty: a path of the next batch
/// with the same index would otherwise read the previous path's numbers.
/// Batches of 1001 paths over an open scene (many paths end after a
/// bounce or two, leaving their first pair's set behind) and the Cornell
/// box, both integrators, the same image.
#[test]
fn path_traced_batches_start_with_their_own_numbers() {
    for (scene, max_depth) in [("gltf/spheres.gltf", 6), ("cornell.toml", 4)] {
        let path = assets().join(scene);
        let s = RenderSettings {
            transport: prism::core::settings::Transport::Path,
            max_depth,
            ..settings(48, 36, 4)
        };
        let rec = render(&path, IntegratorKind::Recursive, &s, 1001);
        let wav = render(&path, IntegratorKind::Wavefront, &s, 1001);
        assert_same_image(
            rec.film.as_ref().unwrap(),
            wav.film.as_ref().unwrap(),
            scene,
        );
    }
}

/// Under Whitted transport a scene of `LANES_MIN_POINT_LIGHTS` (8) or more point lights shades
/// its hits in lanes (eight hits of one material class, each light's
/// shadow rays set up side by side: `shade_lit_in_lanes`); its image is
/// the recursive tracer's bit for bit, on the SIMD path this CPU takes.
#[test]
fn point_lights_in_lanes_give_the_recursive_image_bit_for_bit() {
    let path = assets().join("bench/many_lights.toml");
    let s = settings(64, 48, 2);
    let rec = render(&path, IntegratorKind::Recursive, &s, 1000);
    let wav = render(&path, IntegratorKind::Wavefront, &s, 1001);
    let (rec, wav) = (rec.film.unwrap(), wav.film.unwrap());
    assert!(rec.pixels.iter().filter(|p| p.max_element() > 0.05).count() > 1000);
    assert_eq!(
        film_bits(&rec),
        film_bits(&wav),
        "many_lights: images differ"
    );
}

#[test]
fn test_scenes_match_too() {
    // The analytic scenes of tests/render/analytic.rs, through both integrators.
    let dir = tempfile::tempdir().unwrap();
    let lens = scenes::write(
        dir.path(),
        "lens.toml",
        &glass_ball(
            r#"[[objects]]
shape = { type = "plane" }
material = { color = 0.5, mirror = 0.3 }
translate = [0, -1.5, 0]
[[lights]]
type = "spot"
position = [0, 5, 3]
direction = [0, -1, -0.5]
intensity = 40
"#,
        ),
    );
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
            pool.install(|| film_bits(&render(&path, kind, &s, 700).film.unwrap()))
        };
        let one = bits(1);
        assert_eq!(one, bits(2), "{kind:?}: 1 vs 2 threads");
        assert_eq!(one, bits(3), "{kind:?}: 1 vs 3 threads");
        assert_eq!(one, bits(2), "{kind:?}: run to run");
    }
}

/// With several worker threads the wavefront runs batches side by side,
/// one lane (world) per thread, each batch on whichever lane asks first:
/// the frame (image, ray counts, stage runs) is the one a single lane
/// gives, bit for bit, and every lane really ran.
#[test]
fn lanes_running_batches_side_by_side_give_the_one_lane_frame() {
    let path = assets().join("cornell.toml");
    let s = RenderSettings {
        transport: prism::core::settings::Transport::Path,
        max_depth: 5,
        ..settings(32, 24, 4)
    };
    let frame = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| render(&path, IntegratorKind::Wavefront, &s, 200))
    };
    let one = frame(1);
    let w1 = one.wavefront.unwrap();
    assert_eq!((w1.lanes, w1.batches), (1, 16));
    for threads in [2, 3, 5] {
        let many = frame(threads);
        let w = many.wavefront.unwrap();
        assert_eq!(w.lanes, threads, "{threads} threads");
        assert_eq!(w.batches, 16);
        assert_eq!(
            film_bits(one.film.as_ref().unwrap()),
            film_bits(many.film.as_ref().unwrap()),
            "{threads} threads"
        );
        assert_eq!(one.counters, many.counters, "{threads} threads");
        assert_eq!(w1.runs, w.runs, "{threads} threads");
    }
}

/// A world ready to step through the wavefront stages by hand.
fn stepping_world(scene_toml: &str, s: RenderSettings) -> Renderer {
    let mut r = renderer(
        load_toml(scene_toml).unwrap(),
        config(s, IntegratorKind::default()),
    );
    // Run one (recursive) frame so the scene is extracted and built.
    r.run();
    let scene = r.scene().unwrap();
    let world = r.world_mut();
    let camera = world
        .query::<&prism::scene::camera::Camera>()
        .single(world)
        .unwrap()
        .clone();
    let config = world.resource::<RenderConfig>().settings.clone();
    let classes: Vec<MaterialClass> = scene.materials().iter().map(|m| m.class()).collect();
    let features = prism::scene::features::SceneFeatures::of(&scene);
    let shadows = features.needs_shadow_rays(config.transport);
    world.insert_resource(WavefrontFrame {
        paths: config.path_map(),
        camera: prism::scene::camera::CameraRays::new(&camera, config.width, config.height),
        batches: prism::integrators::wavefront::batch_ranges(&config, 1 << 20).collect(),
        batch: 0,
        scene,
        classes,
        features,
        shadows,
        media: false,
    });
    r
}

fn diffuse_scene() -> String {
    sphere_on_disk("{ color = 0.7, specular = 0.2, shininess = 30 }", "")
}

#[test]
fn stages_drain_their_queues_and_misses_are_escaped() {
    let mut renderer = stepping_world(&diffuse_scene(), settings(32, 24, 1));
    let world = renderer.world_mut();
    world.run_schedule(StartBatch);
    let n = world.resource::<CurrentRays>().0.len();
    assert_eq!(n, 32 * 24);
    // Run the closest-hit stage alone to look at its output.
    let mut only_intersect = Schedule::default();
    only_intersect.add_systems(wavefront::intersect_closest);
    only_intersect.run(world);
    let escaped = world.resource::<EscapedRays>().0.len();
    let hits: usize = MaterialClass::ALL
        .iter()
        .map(|&c| hit_queue(world, c).len())
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
    let diffuse = hit_queue(world, MaterialClass::Diffuse).len();
    assert_eq!(diffuse, hits, "both materials are diffuse");

    // A whole bounce drains every queue it consumes.
    world.resource_mut::<EscapedRays>().0.clear();
    for class in MaterialClass::ALL {
        hit_queue_mut(world, class).clear();
    }
    world.run_schedule(Bounce);
    assert!(world.resource::<EscapedRays>().0.is_empty());
    assert!(
        MaterialClass::ALL
            .iter()
            .all(|&c| hit_queue(world, c).is_empty())
    );
    assert!(world.resource::<ShadowRays>().0.is_empty());
    assert!(world.resource::<NextRays>().0.is_empty());
    // Diffuse surfaces spawn no secondary rays: the frame ends after one bounce.
    assert!(world.resource::<CurrentRays>().0.is_empty());
}

#[test]
fn a_scene_without_glass_never_pushes_a_refraction_ray() {
    let mirror_scene = diffuse_scene().replace(
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
    let glass = diffuse_scene().replace(
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
