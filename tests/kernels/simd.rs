//! The portable, AVX2 and AVX-512 code paths of every traversal mode give
//! bit-identical hits: same distance, same triangle, same barycentrics,
//! same instance, on random scenes with meshes and shapes, coherent and
//! incoherent rays, axis-aligned rays with signed zeros, and rays far from
//! the origin.
//!
//! The path is switched process-wide with `simd::force`; other tests
//! running meanwhile stay valid because both paths give the same hits.

use glam::Vec3A;
use prism::accel::packet::LANES;
use prism::accel::packet16::LANES16;
use prism::core::math::Ray;
use prism::core::simd::{self, Isa};
use prism::scene::{Hit, RenderScene, StreamScratch};

use crate::bvh::{merged_scene, random_scene};
use crate::common::rng::{Random, SamplerRng as Rng};

/// Everything every query mode returns for `rays`, as bits.
fn answers(scene: &RenderScene, rays: &[Ray], t_max: &[f32]) -> Vec<u64> {
    let bits = |h: &Option<Hit>| match h {
        None => vec![u64::MAX],
        Some(h) => vec![
            h.t.to_bits() as u64,
            h.instance as u64,
            h.point.x.to_bits() as u64 | (h.point.y.to_bits() as u64) << 32,
            h.point.z.to_bits() as u64,
            h.uv.x.to_bits() as u64 | (h.uv.y.to_bits() as u64) << 32,
        ],
    };
    let mut out = Vec::new();
    for r in rays {
        out.extend(bits(&scene.intersect(r, 0.0, f32::INFINITY)));
    }
    for (r, &t) in rays.iter().zip(t_max) {
        out.push(scene.occluded(r, 0.0, t) as u64);
    }
    for (chunk, t) in rays.chunks(LANES).zip(t_max.chunks(LANES)) {
        let mut hits = [None; LANES];
        scene.intersect_packet(chunk, &mut hits);
        for h in &hits[..chunk.len()] {
            out.extend(bits(h));
        }
        out.push(scene.occluded_packet(chunk, t) as u64);
    }
    for chunk in rays.chunks(LANES16) {
        let mut hits = [None; LANES16];
        scene.intersect_packet16(chunk, &mut hits);
        for h in &hits[..chunk.len()] {
            out.extend(bits(h));
        }
    }
    let mut scratch = StreamScratch::default();
    let mut hits = vec![None; rays.len()];
    scene.intersect_stream(rays, &mut hits, &mut scratch);
    for h in &hits {
        out.extend(bits(h));
    }
    out
}

fn rays(rng: &mut Rng, offset: Vec3A) -> (Vec<Ray>, Vec<f32>) {
    let mut rays = Vec::new();
    for k in 0..1500 {
        let r = match k % 3 {
            // Coherent bundles from outside.
            0 => {
                let o = Vec3A::from(rng.dir() * 14.0);
                let aim = (Vec3A::from(rng.vec(-5.0, 5.0)) - o).normalize();
                Ray::new(o, (aim + Vec3A::from(rng.vec(-0.05, 0.05))).normalize())
            }
            // Incoherent rays from inside.
            1 => Ray::new(rng.vec(-7.0, 7.0).into(), rng.dir().into()),
            // Axis-aligned, with signed zeros.
            _ => {
                let mut d = Vec3A::ZERO;
                let a = (rng.f32() * 3.0) as usize % 3;
                d[a] = if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                d[(a + 1) % 3] = if rng.f32() < 0.5 { 0.0 } else { -0.0 };
                Ray::new(Vec3A::from(rng.vec(-7.0, 7.0)), d)
            }
        };
        rays.push(Ray::new(r.origin + offset, r.direction));
    }
    let t_max = rays.iter().map(|_| rng.range(0.5, 30.0)).collect();
    (rays, t_max)
}

#[test]
fn portable_and_avx2_paths_give_identical_hits() {
    portable_and_avx2_paths_give_identical_hits_with(random_scene);
}

/// [`portable_and_avx2_paths_give_identical_hits`] on a scene whose single-use mesh instances are merged.
#[test]
fn portable_and_avx2_paths_give_identical_hits_merged() {
    portable_and_avx2_paths_give_identical_hits_with(merged_scene);
}

fn portable_and_avx2_paths_give_identical_hits_with(make: fn(&mut Rng, bool) -> RenderScene) {
    if !simd::supported(Isa::Avx2) {
        eprintln!("skipped: this CPU has no AVX2 and FMA");
        return;
    }
    let mut rng = Rng::new(2024);
    let scene = make(&mut rng, true);
    let mut compared = 0;
    for offset in [Vec3A::ZERO, Vec3A::new(3.0e4, -2.0e4, 1.0e4)] {
        let (rays, t_max) = rays(&mut rng, offset);
        assert!(simd::force(Isa::Portable));
        let portable = answers(&scene, &rays, &t_max);
        assert!(simd::force(Isa::Avx2));
        let avx2 = answers(&scene, &rays, &t_max);
        // The AVX-512 path (packets of 16 in 16-lane registers), where
        // the CPU has it.
        let avx512 = simd::force(Isa::Avx512).then(|| answers(&scene, &rays, &t_max));
        simd::force(simd::detected());
        for (name, other) in [("AVX2", Some(avx2)), ("AVX-512", avx512)] {
            let Some(other) = other else {
                eprintln!("{name} path skipped: not on this CPU");
                continue;
            };
            assert_eq!(portable.len(), other.len());
            for (i, (a, b)) in portable.iter().zip(&other).enumerate() {
                assert_eq!(
                    a, b,
                    "answer {i} differs between the portable and {name} paths (offset {offset})"
                );
            }
        }
        compared += portable.iter().filter(|&&v| v != u64::MAX).count();
    }
    assert!(compared > 10_000, "only {compared} answers compared");
}
