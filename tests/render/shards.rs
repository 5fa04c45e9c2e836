//! Shards: a render split into region shards or sample-range shards,
//! written as shard files, read back and merged, is bit for bit the
//! render done at once (and its EXR file byte for byte), for both
//! integrators, both transports and any thread count.

use std::ops::Range;

use proptest::prelude::*;

use prism::core::settings::{RenderSettings, Transport};
use prism::core::window::{RenderWindow, shard_rows};
use prism::image::film::Film;
use prism::image::output::{PngOptions, write_image};
use prism::image::shard::{self, Manifest, Shard, ShardFile};
use prism::integrators::IntegratorKind;
use prism::systems::Renderer;
use prism::systems::wavefront::BatchSize;

use crate::common::assets;
use crate::common::images::film_bits;
use crate::common::render::{config, renderer};
use crate::common::scenes;

const WIDTH: u32 = 20;
const HEIGHT: u32 = 14;
const SPP: u32 = 4;

fn settings(transport: Transport, spp: u32) -> RenderSettings {
    RenderSettings {
        width: WIDTH,
        height: HEIGHT,
        spp,
        max_depth: 4,
        seed: 11,
        transport,
        ..Default::default()
    }
}

/// A renderer of an example scene at the test settings; wavefront
/// batches are small so that shards span several batches.
fn scene_renderer(file: &str, transport: Transport, kind: IntegratorKind, spp: u32) -> Renderer {
    let mut r = renderer(
        scenes::load(&assets().join(file)),
        config(settings(transport, spp), kind),
    );
    r.insert_resource(BatchSize(37));
    r
}

/// Renders `window` (`None`: the whole image) with the renderer's scene.
fn frame(r: &mut Renderer, window: Option<RenderWindow>) -> prism::systems::Frame {
    r.config_mut().settings.window = window;
    r.render().unwrap()
}

fn manifest(s: &RenderSettings, samples: Range<u32>) -> Manifest {
    Manifest {
        version: "test".into(),
        scene_hash: "0".into(),
        settings: "test".into(),
        seed: s.seed,
        spp: s.spp,
        shard: "test".into(),
        samples,
    }
}

/// Renders each window as a shard, writes them to files, reads them back
/// and merges them.
fn render_and_merge(r: &mut Renderer, windows: &[RenderWindow]) -> Film {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for (i, w) in windows.iter().enumerate() {
        let f = frame(r, Some(w.clone()));
        let s = r.config_mut().settings.clone();
        let shard = Shard::from_window(
            manifest(&s, w.samples.clone()),
            &s,
            w,
            f.film.as_ref().unwrap(),
            f.sums.as_ref(),
        );
        let path = dir.path().join(format!("shard{i}.exr"));
        shard::write_shard(&path, &shard).unwrap();
        let back = shard::read_shard(&path).unwrap();
        assert_eq!(back, shard, "shard {i} round trip");
        files.push(ShardFile { path, shard: back });
    }
    r.config_mut().settings.window = None;
    shard::merge(&files).unwrap()
}

/// Number of channels whose bits differ.
fn differing_channels(a: &Film, b: &Film) -> usize {
    assert_eq!((a.width, a.height), (b.width, b.height));
    film_bits(a)
        .iter()
        .zip(film_bits(b))
        .filter(|(x, y)| **x != *y)
        .count()
}

fn assert_same_bits(merged: &Film, single: &Film, case: &str) {
    let n = differing_channels(merged, single);
    assert_eq!(n, 0, "{case}: {n} channels differ from the single render");
}

fn exr_bytes(film: &Film) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.exr");
    write_image(&path, film, &PngOptions::default()).unwrap();
    std::fs::read(path).unwrap()
}

/// The row shards of `--shard I/N`.
fn region_shards(n: u32) -> Vec<RenderWindow> {
    (0..n)
        .map(|i| RenderWindow {
            rows: shard_rows(i, n, HEIGHT).unwrap(),
            ..RenderWindow::full(WIDTH, HEIGHT, SPP)
        })
        .collect()
}

/// Whole-image shards of the sample ranges `cuts[k]..cuts[k + 1]`.
fn sample_shards(cuts: &[u32]) -> Vec<RenderWindow> {
    cuts.windows(2)
        .map(|c| RenderWindow {
            samples: c[0]..c[1],
            ..RenderWindow::full(WIDTH, HEIGHT, SPP)
        })
        .collect()
}

#[test]
fn region_and_sample_shards_merge_to_the_exact_bytes_of_the_single_render() {
    let mut splits: Vec<(String, Vec<RenderWindow>)> = [1, 2, 3, 4, 7]
        .map(|n| (format!("{n} region shards"), region_shards(n)))
        .into();
    splits.push(("2 sample shards".into(), sample_shards(&[0, 1, SPP])));
    splits.push(("3 sample shards".into(), sample_shards(&[0, 1, 3, SPP])));
    // Region and sample splits together.
    let mut both = region_shards(2);
    for w in &mut both {
        w.samples = 0..2;
    }
    both.extend(region_shards(3).into_iter().map(|w| RenderWindow {
        samples: 2..SPP,
        ..w
    }));
    splits.push(("2 region shards of samples 0..2, 3 of 2..4".into(), both));

    for (file, transport) in [
        ("whitted.toml", Transport::Whitted),
        ("cornell.toml", Transport::Path),
    ] {
        for kind in IntegratorKind::ALL {
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    let mut r = scene_renderer(file, transport, kind, SPP);
                    let single = frame(&mut r, None).film.unwrap();
                    assert!(single.is_finite());
                    let single_bytes = exr_bytes(&single);
                    for (what, windows) in &splits {
                        let merged = render_and_merge(&mut r, windows);
                        let case = format!("{file}, {kind:?}, {threads} thread(s), {what}");
                        assert_same_bits(&merged, &single, &case);
                        assert!(exr_bytes(&merged) == single_bytes, "{case}: EXR bytes");
                    }
                });
            }
        }
    }
}

/// A random partition of `0..len` into at most `pieces` ranges.
fn cut(len: u32, pieces: usize, picks: &[u32]) -> Vec<Range<u32>> {
    let mut cuts: Vec<u32> = picks
        .iter()
        .take(pieces.saturating_sub(1))
        .map(|p| p % len)
        .filter(|&c| c > 0)
        .collect();
    cuts.sort_unstable();
    cuts.dedup();
    let mut bounds = vec![0];
    bounds.extend(cuts);
    bounds.push(len);
    bounds.windows(2).map(|b| b[0]..b[1]).collect()
}

proptest! {
    #![proptest_config(crate::common::prop::config(12))]

    /// Any grid of rectangles, each cut into any sample ranges, merges to
    /// the single render.
    #[test]
    fn random_partitions_of_regions_and_samples_merge_exactly(
        path in any::<bool>(),
        wavefront in any::<bool>(),
        spp in 1u32..6,
        columns in 1usize..4,
        rows in 1usize..4,
        picks in proptest::collection::vec(0u32..1000, 24),
    ) {
        let (file, transport) = if path {
            ("cornell.toml", Transport::Path)
        } else {
            ("whitted.toml", Transport::Whitted)
        };
        let kind = if wavefront { IntegratorKind::Wavefront } else { IntegratorKind::Recursive };
        let mut r = scene_renderer(file, transport, kind, spp);
        let single = frame(&mut r, None).film.unwrap();
        let xs = cut(WIDTH, columns, &picks[0..4]);
        let ys = cut(HEIGHT, rows, &picks[4..8]);
        let mut windows = Vec::new();
        let mut k = 8;
        for x in &xs {
            for y in &ys {
                // Each rectangle gets its own split of the samples.
                let pieces = 1 + picks[k % picks.len()] as usize % 3;
                let samples = cut(spp, pieces, &picks[(k + 1) % 20..(k + 1) % 20 + 3]);
                k += 1;
                for s in samples {
                    windows.push(RenderWindow { columns: x.clone(), rows: vec![y.clone()], samples: s });
                }
            }
        }
        let merged = render_and_merge(&mut r, &windows);
        let differing = differing_channels(&merged, &single);
        prop_assert_eq!(differing, 0, "channels differ from the single render");
    }
}
