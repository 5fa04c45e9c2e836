//! `prism bench rays DIR`: closest-hit throughput of every traversal mode
//! on the ray-tracing anchors workload (a mesh, camera rays, incoherent
//! bounce rays and reference hits, as written by the generator in
//! `shared/traversal-anchors/`), in the same terms as its Embree harness:
//! Mrays/s of the best of several passes after a warm-up, build time, and
//! the fraction of rays whose hit or miss and primitive agree with the
//! reference.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use serde::Serialize;

use prism::accel::packet::{LANES, Packet};
use prism::accel::packet16::{LANES16, Packet16};
use prism::accel::single::octant_order;
use prism::accel::stream::Stream;
use prism::core::error::{Error, Result};
use prism::core::math::Ray;
use prism::core::simd;
use prism::geometry::mesh::{BuildQuality, Mesh, MeshData, MeshHit, NormalMode};

/// Options of `prism bench rays`.
#[derive(clap::Args, Debug)]
pub struct RaysArgs {
    /// Workload folder: mesh.bin, primary.rays, incoherent.rays,
    /// primary.ref, incoherent.ref.
    pub dir: PathBuf,
    /// Worker threads, one run per value (comma-separated) [default: one per core].
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Timed passes per mode after a warm-up; the best is reported.
    #[arg(long, default_value_t = 5)]
    pub reps: usize,
    /// BVH builds timed; the best is reported.
    #[arg(long, default_value_t = 3)]
    pub build_reps: usize,
    /// BVH build preset.
    #[arg(long, value_enum, default_value_t = crate::args::QualityArg::Medium)]
    pub bvh_quality: crate::args::QualityArg,
    /// SIMD code path [default: the fastest this CPU has].
    #[arg(long, value_enum)]
    pub isa: Option<IsaArg>,
    /// Structure over the mesh (the BVH's packets and streams are traced
    /// one ray at a time by the others).
    #[arg(long, value_enum, default_value_t = crate::args::AccelArg::Bvh)]
    pub accel: crate::args::AccelArg,
    /// Traversal modes to measure (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Mode::Single, Mode::Packet8, Mode::Packet16, Mode::Stream, Mode::Binned])]
    pub modes: Vec<Mode>,
    /// Ray sets to measure (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [String::from("primary"), String::from("incoherent")], value_parser = ["primary", "incoherent"])]
    pub sets: Vec<String>,
    /// Use only the first N rays of each set (quick runs, profiling).
    #[arg(long)]
    pub limit: Option<usize>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Traversal modes.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// One ray at a time.
    Single,
    /// Packets of 8 consecutive rays.
    Packet8,
    /// Packets of 16 consecutive rays (one register per quantity on the
    /// AVX-512 path).
    Packet16,
    /// Streams of 256 consecutive rays.
    Stream,
    /// One ray at a time, each work item of 65,536 rays traced octant by
    /// octant of direction (the sort is timed with the tracing).
    Binned,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Single => "single",
            Mode::Packet8 => "packet8",
            Mode::Packet16 => "packet16",
            Mode::Stream => "stream",
            Mode::Binned => "binned",
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `--isa` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum IsaArg {
    /// Portable code (SSE2 on x86-64).
    Portable,
    /// AVX2 and FMA.
    Avx2,
    /// AVX-512F, AVX2 and FMA.
    Avx512,
}

/// One traversal mode on one ray set.
#[derive(Serialize, Debug, Clone)]
pub struct ModeResult {
    /// `primary` or `incoherent`.
    pub rays: &'static str,
    /// `single`, `packet8`, `packet16` or `stream`.
    pub mode: &'static str,
    /// Threads.
    pub threads: usize,
    /// Best pass, Mrays/s.
    pub best_mrays: f64,
    /// Median pass, Mrays/s.
    pub median_mrays: f64,
    /// Best pass in rays per CPU second of all the process's threads
    /// (millions; as the Embree harness's `best_mrays_per_cpu_s`): less
    /// disturbed than wall time on a loaded machine. Absent where the
    /// process CPU time cannot be read (only Unix has the clock).
    pub best_mrays_per_cpu_s: Option<f64>,
    /// Rays that hit.
    pub hits: usize,
    /// Fraction of rays with the reference's hit or miss and primitive.
    pub ref_agree: f64,
}

/// Everything measured on one workload.
#[derive(Serialize, Debug, Clone)]
pub struct RaysResult {
    /// Workload folder.
    pub dir: String,
    /// Triangles.
    pub triangles: usize,
    /// SIMD code path.
    pub isa: &'static str,
    /// Structure traced.
    pub accel: &'static str,
    /// Bytes of the structure (nodes or cells, leaves, triangle blocks
    /// or lists).
    pub accel_bytes: usize,
    /// Best build (boxes, build, layout), milliseconds, per thread count.
    pub build_ms: Vec<(usize, f64)>,
    /// Every mode.
    pub modes: Vec<ModeResult>,
}

fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::Invalid(format!("cannot read {}: {e}", path.display())))
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

fn f32_at(b: &[u8], i: usize) -> f32 {
    f32::from_bits(u32_at(b, i))
}

/// Checks the 32-byte header's magic and that `count` records of
/// `record` bytes follow; returns the first header field.
fn header(
    b: &[u8],
    path: &Path,
    magic: &[u8; 8],
    record: impl Fn(&[u8]) -> usize,
) -> Result<usize> {
    let bad = |what: &str| Error::Invalid(format!("{}: {what}", path.display()));
    if b.len() < 32 || &b[..8] != magic {
        return Err(bad(&format!(
            "not an anchors file (expected magic {})",
            String::from_utf8_lossy(magic)
        )));
    }
    let want = 32 + record(b);
    if b.len() != want {
        return Err(bad(&format!("{} bytes, the header says {want}", b.len())));
    }
    Ok(u32_at(b, 8) as usize)
}

fn load_mesh(dir: &Path) -> Result<MeshData> {
    let path = dir.join("mesh.bin");
    let b = read(&path)?;
    let nv = header(&b, &path, b"ANCMESH1", |b| {
        u32_at(b, 8) as usize * 12 + u32_at(b, 12) as usize * 12
    })?;
    let nt = u32_at(&b, 12) as usize;
    let positions = (0..nv)
        .map(|i| {
            let o = 32 + 12 * i;
            Vec3::new(f32_at(&b, o), f32_at(&b, o + 4), f32_at(&b, o + 8))
        })
        .collect();
    let base = 32 + 12 * nv;
    let indices = (0..nt)
        .map(|i| {
            let o = base + 12 * i;
            [u32_at(&b, o), u32_at(&b, o + 4), u32_at(&b, o + 8)]
        })
        .collect();
    Ok(MeshData {
        positions,
        normals: None,
        uvs: None,
        indices,
    })
}

/// Rays with their intervals.
struct RaySet {
    rays: Vec<Ray>,
    t_min: Vec<f32>,
    t_max: Vec<f32>,
    /// Reference primitive per ray (`u32::MAX` for a miss).
    reference: Vec<u32>,
}

fn load_rays(dir: &Path, name: &str) -> Result<RaySet> {
    let path = dir.join(format!("{name}.rays"));
    let b = read(&path)?;
    let n = header(&b, &path, b"ANCRAYS1", |b| u32_at(b, 8) as usize * 32)?;
    let mut set = RaySet {
        rays: Vec::with_capacity(n),
        t_min: Vec::with_capacity(n),
        t_max: Vec::with_capacity(n),
        reference: Vec::with_capacity(n),
    };
    for i in 0..n {
        let f = |k: usize| f32_at(&b, 32 + 32 * i + 4 * k);
        let d = Vec3A::new(f(4), f(5), f(6));
        if !(d.is_finite() && d != Vec3A::ZERO) {
            return Err(Error::Invalid(format!(
                "{}: ray {i} has no direction",
                path.display()
            )));
        }
        set.rays.push(Ray::new(Vec3A::new(f(0), f(1), f(2)), d));
        set.t_min.push(f(3));
        set.t_max.push(f(7));
    }
    let rpath = dir.join(format!("{name}.ref"));
    let r = read(&rpath)?;
    let m = header(&r, &rpath, b"ANCREFS1", |b| u32_at(b, 8) as usize * 8)?;
    if m != n {
        return Err(Error::Invalid(format!(
            "{}: {m} reference hits for {n} rays",
            rpath.display()
        )));
    }
    set.reference = (0..n).map(|i| u32_at(&r, 32 + 8 * i)).collect();
    Ok(set)
}

/// Rays per work item, as the Embree harness.
const CHUNK: usize = 4096;

/// Rays per stream.
const STREAM: usize = 256;

/// Rays per work item of the `binned` mode: large enough that each
/// octant's share of an item is long.
const BIN_CHUNK: usize = 1 << 16;

fn trace(mesh: &Mesh, set: &RaySet, mode: Mode, out: &mut [Option<MeshHit>]) {
    let size = if mode == Mode::Binned {
        BIN_CHUNK
    } else {
        CHUNK
    };
    let chunks = out.par_chunks_mut(size).enumerate().with_max_len(1);
    match mode {
        Mode::Binned => chunks.for_each_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(order, rays, hits), (c, out)| {
                let base = c * BIN_CHUNK;
                octant_order(&set.rays[base..base + out.len()], order);
                // Gathered into octant order, traced front to back, and
                // scattered back: tracing through the index list instead
                // measured no faster than the rays as given.
                rays.clear();
                rays.extend(order.iter().map(|&k| {
                    let i = base + k as usize;
                    (set.rays[i], set.t_min[i], set.t_max[i])
                }));
                hits.clear();
                hits.extend(rays.iter().map(|(r, t0, t1)| mesh.intersect(r, *t0, *t1)));
                for (&k, h) in order.iter().zip(hits.iter()) {
                    out[k as usize] = *h;
                }
            },
        ),
        Mode::Single => chunks.for_each(|(c, out)| {
            let base = c * CHUNK;
            for (k, o) in out.iter_mut().enumerate() {
                let i = base + k;
                *o = mesh.intersect(&set.rays[i], set.t_min[i], set.t_max[i]);
            }
        }),
        Mode::Packet8 => chunks.for_each(|(c, out)| {
            let base = c * CHUNK;
            for (p, o) in out.chunks_mut(LANES).enumerate() {
                let i = base + p * LANES;
                let n = o.len();
                let mut packet = Packet::new(
                    &set.rays[i..i + n],
                    &set.t_min[i..i + n],
                    &set.t_max[i..i + n],
                );
                let mut best = [None; LANES];
                let lanes = packet.valid;
                mesh.intersect_packet(&mut packet, lanes, &mut best);
                o.copy_from_slice(&best[..n]);
            }
        }),
        Mode::Packet16 => chunks.for_each(|(c, out)| {
            let base = c * CHUNK;
            for (p, o) in out.chunks_mut(LANES16).enumerate() {
                let i = base + p * LANES16;
                let n = o.len();
                let mut packet = Packet16::new(
                    &set.rays[i..i + n],
                    &set.t_min[i..i + n],
                    &set.t_max[i..i + n],
                );
                let mut best = [None; LANES16];
                let lanes = packet.valid;
                mesh.intersect_packet16(&mut packet, lanes, &mut best);
                o.copy_from_slice(&best[..n]);
            }
        }),
        Mode::Stream => chunks.for_each_init(
            || (Stream::default(), Vec::new(), Vec::new()),
            |(stream, wt, best), (c, out)| {
                let base = c * CHUNK;
                for (s, o) in out.chunks_mut(STREAM).enumerate() {
                    let i = base + s * STREAM;
                    stream.clear();
                    for k in i..i + o.len() {
                        stream.push(set.rays[k], set.t_min[k], set.t_max[k]);
                    }
                    mesh.intersect_stream(stream, wt, best);
                    o.copy_from_slice(best);
                }
            },
        ),
    }
}

/// CPU time used so far by all of the process's threads, in seconds
/// (`CLOCK_PROCESS_CPUTIME_ID`); `None` where there is no such clock.
#[cfg(unix)]
fn cpu_seconds() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid `timespec` for the call to write.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    (r == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

/// No process CPU clock here.
#[cfg(not(unix))]
fn cpu_seconds() -> Option<f64> {
    None
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Runs the benchmark and prints the report.
pub fn run(args: RaysArgs) -> Result<()> {
    if args.reps == 0 || args.build_reps == 0 {
        return Err(Error::Invalid(
            "--reps and --build-reps must be at least 1".into(),
        ));
    }
    match args.isa {
        Some(IsaArg::Portable) => {
            simd::force(simd::Isa::Portable);
        }
        Some(IsaArg::Avx2) if !simd::force(simd::Isa::Avx2) => {
            return Err(Error::Invalid("this CPU has no AVX2 and FMA".into()));
        }
        Some(IsaArg::Avx2) => {}
        Some(IsaArg::Avx512) if !simd::force(simd::Isa::Avx512) => {
            return Err(Error::Invalid(
                "this CPU has no AVX-512F, AVX2 and FMA".into(),
            ));
        }
        Some(IsaArg::Avx512) => {}
        None => {}
    }
    let threads: Vec<usize> = if args.threads.is_empty() {
        vec![std::thread::available_parallelism().map_or(1, |n| n.get())]
    } else {
        args.threads.clone()
    };
    if threads.contains(&0) {
        return Err(Error::Invalid("--threads must be at least 1".into()));
    }
    let data = load_mesh(&args.dir)?;
    let mut sets = Vec::new();
    for name in ["primary", "incoherent"] {
        if args.sets.iter().any(|s| s == name) {
            sets.push((name, load_rays(&args.dir, name)?));
        }
    }
    if let Some(n) = args.limit {
        for (_, s) in &mut sets {
            let n = n.min(s.rays.len());
            s.rays.truncate(n);
            s.t_min.truncate(n);
            s.t_max.truncate(n);
            s.reference.truncate(n);
        }
    }
    let mut result = RaysResult {
        dir: args.dir.display().to_string(),
        triangles: data.indices.len(),
        isa: simd::active().name(),
        accel: prism::core::settings::Accel::from(args.accel).name(),
        accel_bytes: 0,
        build_ms: Vec::new(),
        modes: Vec::new(),
    };
    let mut mesh = None;
    for &t in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start {t} threads: {e}")))?;
        let mut best = f64::INFINITY;
        for _ in 0..args.build_reps {
            let d = data.clone();
            let start = Instant::now();
            let m = pool
                .install(|| {
                    Mesh::with_accel(
                        "anchors",
                        d,
                        NormalMode::Flat,
                        BuildQuality::from(args.bvh_quality),
                        args.accel.into(),
                    )
                })
                .map_err(|e| Error::Invalid(format!("{}: {e}", args.dir.display())))?;
            best = best.min(start.elapsed().as_secs_f64());
            mesh = Some(m);
        }
        result.build_ms.push((t, best * 1e3));
        let mesh = mesh.as_ref().expect("built at least once");
        result.accel_bytes = mesh.accel_bytes();
        for (name, set) in &sets {
            for &mode in &args.modes {
                let mut out = vec![None; set.rays.len()];
                pool.install(|| trace(mesh, set, mode, &mut out));
                let mut rates = Vec::new();
                let mut cpu_rates = Vec::new();
                for _ in 0..args.reps {
                    let cpu = cpu_seconds();
                    let start = Instant::now();
                    pool.install(|| trace(mesh, set, mode, &mut out));
                    rates.push(set.rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6);
                    if let (Some(a), Some(b)) = (cpu, cpu_seconds())
                        && b > a
                    {
                        cpu_rates.push(set.rays.len() as f64 / (b - a) / 1e6);
                    }
                }
                let hits = out.iter().filter(|h| h.is_some()).count();
                let agree = out
                    .iter()
                    .zip(&set.reference)
                    .filter(|&(h, &r)| match h {
                        Some(h) => mesh.input_triangle(h.triangle as usize) == r,
                        None => r == u32::MAX,
                    })
                    .count();
                result.modes.push(ModeResult {
                    rays: name,
                    mode: mode.name(),
                    threads: t,
                    best_mrays: rates.iter().copied().fold(0.0, f64::max),
                    median_mrays: median(&rates),
                    best_mrays_per_cpu_s: (!cpu_rates.is_empty())
                        .then(|| cpu_rates.iter().copied().fold(0.0, f64::max)),
                    hits,
                    ref_agree: agree as f64 / set.rays.len() as f64,
                });
            }
        }
    }
    if args.json {
        let text = serde_json::to_string_pretty(&result)
            .map_err(|e| Error::Invalid(format!("cannot write JSON: {e}")))?;
        println!("{text}");
    } else {
        println!(
            "{}: {} triangles, SIMD path {}",
            result.dir, result.triangles, result.isa
        );
        for (t, ms) in &result.build_ms {
            if result.accel == "bvh" {
                println!(
                    "  build ({:?}, leaves of up to {}), {t} threads: {ms:.1} ms",
                    args.bvh_quality,
                    prism::geometry::mesh::LEAF_TRIANGLES
                );
            } else {
                println!("  build ({}), {t} threads: {ms:.1} ms", result.accel);
            }
        }
        println!(
            "  structure: {}, {:.1} MB",
            result.accel,
            result.accel_bytes as f64 / 1e6
        );
        println!(
            "  {:<11} {:<8} {:>7} {:>10} {:>12} {:>10} {:>9} {:>9}",
            "rays", "mode", "threads", "best Mr/s", "median Mr/s", "Mr/cpu-s", "hits", "agree"
        );
        for m in &result.modes {
            let cpu = m
                .best_mrays_per_cpu_s
                .map_or_else(|| "-".to_string(), |r| format!("{r:.2}"));
            println!(
                "  {:<11} {:<8} {:>7} {:>10.2} {:>12.2} {:>10} {:>9} {:>9.5}",
                m.rays, m.mode, m.threads, m.best_mrays, m.median_mrays, cpu, m.hits, m.ref_agree
            );
        }
    }
    Ok(())
}
