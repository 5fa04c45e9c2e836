//! Only the stages a scene needs: stage systems gated by the scene's
//! features, queues for absent features never allocated, no triangle BVH
//! for a scene without meshes.
//!
//! No test in this file loads a mesh, so the process-wide count of
//! triangle BVH builds is this file's own: `cargo test --test gating` is
//! a binary of its own for that reason (not a module of `render`).

mod common;

use prism::core::settings::{RenderSettings, Transport};
use prism::geometry::mesh::BuildQuality;
use prism::integrators::IntegratorKind;
use prism::integrators::wavefront::queues::QueueBytes;
use prism::integrators::wavefront::{Stage, StageRuns};
use prism::scene::material::MaterialClass;
use prism::systems::wavefront::{ShadowRays, StageGating, StageScratch, hit_queue};
use prism::systems::{Frame, Renderer};

use common::render::{config, renderer};
use common::scenes::{load_toml, sphere_on_disk};

/// Spheres and a disk, all Lambertian, one point light.
fn diffuse_only() -> String {
    sphere_on_disk(
        "{ color = 0.7 }",
        r#"[[objects]]
shape = { type = "sphere", radius = 0.4 }
translate = [1.5, 0.4, 0]
material = { color = [0.2, 0.6, 0.3] }
"#,
    )
}

/// Renders `toml` with the wavefront integrator and returns the renderer
/// after the frame, with its queues and scratch buffers as they were left.
fn wavefront_world(toml: &str, transport: Transport, force_all: bool) -> Renderer {
    let settings = RenderSettings {
        width: 32,
        height: 24,
        spp: 2,
        max_depth: 4,
        transport,
        ..Default::default()
    };
    let mut r = renderer(
        load_toml(toml).unwrap(),
        config(settings, IntegratorKind::Wavefront),
    );
    r.insert_resource(StageGating { force_all });
    assert!(r.run().film.is_some());
    r
}

fn runs(r: &Renderer) -> StageRuns {
    r.world().resource::<Frame>().wavefront.unwrap().runs
}

#[test]
fn a_diffuse_only_scene_runs_no_reflection_or_refraction_stage() {
    for transport in [Transport::Whitted, Transport::Path] {
        let renderer = wavefront_world(&diffuse_only(), transport, false);
        let world = renderer.world();
        let r = runs(&renderer);
        assert_eq!(r.get(Stage::ShadeMirror), 0, "{transport:?}");
        assert_eq!(r.get(Stage::ShadeGlass), 0, "{transport:?}");
        assert_eq!(r.get(Stage::ShadeGeneral), 0, "{transport:?}");
        assert_eq!(r.get(Stage::ShadeEmissive), 0, "{transport:?}");
        assert!(
            r.get(Stage::ShadeDiffuse) > 0 && r.get(Stage::TraceShadowRays) > 0,
            "{r:?}"
        );
        assert_eq!(
            world
                .resource::<Frame>()
                .wavefront
                .unwrap()
                .runs
                .names_run(),
            [
                "generate_camera_rays",
                "intersect_closest",
                "handle_escaped_rays",
                "shade_diffuse",
                "trace_shadow_rays",
                "update_film"
            ]
        );
        // The hit queues of the absent classes were never allocated.
        for class in [
            MaterialClass::Mirror,
            MaterialClass::Glass,
            MaterialClass::General,
            MaterialClass::Emissive,
        ] {
            assert_eq!(hit_queue(world, class).bytes(), 0, "{class:?}");
        }
        assert!(hit_queue(world, MaterialClass::Diffuse).bytes() > 0);
        let scratch = world.resource::<StageScratch>();
        // No refraction queue ever; under Whitted transport no secondary
        // ray queue at all (diffuse surfaces spawn none), so one bounce.
        assert_eq!(scratch.refraction_bytes(), 0, "{transport:?}");
        if transport == Transport::Whitted {
            assert_eq!(scratch.secondary_bytes(), 0);
            assert_eq!(
                r.get(Stage::IntersectClosest),
                r.get(Stage::GenerateCameraRays)
            );
        } else {
            assert!(r.get(Stage::IntersectClosest) > r.get(Stage::GenerateCameraRays));
        }
    }
}

#[test]
fn forcing_every_stage_runs_them_all_and_changes_nothing() {
    let gated = wavefront_world(&diffuse_only(), Transport::Whitted, false);
    let forced = wavefront_world(&diffuse_only(), Transport::Whitted, true);
    let r = runs(&forced);
    assert!(Stage::ALL.iter().all(|&s| r.get(s) > 0), "{r:?}");
    let a = gated.world().resource::<Frame>().film.as_ref().unwrap();
    let b = forced.world().resource::<Frame>().film.as_ref().unwrap();
    assert!(a.pixels == b.pixels);
}

#[test]
fn a_scene_without_lights_traces_no_shadow_rays() {
    let unlit = diffuse_only().replace(
        "[[lights]]\ntype = \"point\"\nposition = [2, 4, 3]\nintensity = 30\n",
        "",
    );
    assert!(!unlit.contains("[[lights]]"));
    for transport in [Transport::Whitted, Transport::Path] {
        let renderer = wavefront_world(&unlit, transport, false);
        assert_eq!(
            runs(&renderer).get(Stage::TraceShadowRays),
            0,
            "{transport:?}"
        );
        assert_eq!(renderer.world().resource::<ShadowRays>().0.bytes(), 0);
    }
    // An emissive sphere lights the scene only under path transport.
    let glowing = format!(
        "{unlit}\n[[objects]]\nshape = {{ type = \"sphere\", radius = 0.3 }}\ntranslate = [0, 3, 0]\nmaterial = {{ color = 0.0, diffuse = 0.0, emission = 20 }}\n"
    );
    assert_eq!(
        runs(&wavefront_world(&glowing, Transport::Whitted, false)).get(Stage::TraceShadowRays),
        0
    );
    assert!(
        runs(&wavefront_world(&glowing, Transport::Path, false)).get(Stage::TraceShadowRays) > 0
    );
}

/// The medium stage runs, and its buffers are allocated, only for path
/// transport of a scene with media; a fog under Whitted transport only
/// attenuates and needs no medium stage either.
#[test]
fn only_path_transport_of_a_scene_with_media_runs_the_medium_stage() {
    for transport in [Transport::Whitted, Transport::Path] {
        let r = wavefront_world(&diffuse_only(), transport, false);
        assert_eq!(runs(&r).get(Stage::SampleMedia), 0, "{transport:?}");
        assert_eq!(r.world().resource::<StageScratch>().media_bytes(), 0);
    }
    let foggy = format!(
        "{}\n[medium]\nscattering = 0.2\nabsorption = 0.05\n",
        diffuse_only()
    );
    let r = wavefront_world(&foggy, Transport::Path, false);
    assert!(runs(&r).get(Stage::SampleMedia) > 0);
    assert!(r.world().resource::<StageScratch>().media_bytes() > 0);
    let r = wavefront_world(&foggy, Transport::Whitted, false);
    assert_eq!(runs(&r).get(Stage::SampleMedia), 0);
    assert_eq!(r.world().resource::<StageScratch>().media_bytes(), 0);
}

#[test]
fn a_sphere_only_scene_builds_no_triangle_bvh() {
    let before = prism::geometry::mesh::mesh_bvh_builds();
    for transport in [Transport::Whitted, Transport::Path] {
        let renderer = wavefront_world(&diffuse_only(), transport, false);
        let scene = renderer.scene().unwrap();
        let features = prism::scene::features::SceneFeatures::of(&scene);
        assert_eq!(features.mesh_instances, 0, "{transport:?}");
        assert_eq!(features.shapes, ["disk", "sphere"]);
    }
    assert_eq!(prism::geometry::mesh::mesh_bvh_builds(), before);
    // The counter does count: a one-triangle mesh builds one.
    let _ = prism::geometry::mesh::Mesh::new(
        "triangle",
        prism::geometry::mesh::MeshData {
            positions: vec![glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        },
        prism::geometry::mesh::NormalMode::Flat,
        BuildQuality::Fastest,
    )
    .unwrap();
    assert_eq!(prism::geometry::mesh::mesh_bvh_builds(), before + 1);
}
