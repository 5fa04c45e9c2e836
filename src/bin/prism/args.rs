//! Flags and values more than one subcommand takes.

use clap::ValueEnum;

use prism::core::error::{Error, Result};
use prism::core::settings::Transport;
use prism::geometry::mesh::BuildQuality;
use prism::integrators::IntegratorKind;

/// `--tonemap` (render, compare).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ToneMapArg {
    /// Clip at 1.
    Clamp,
    /// x / (1 + x).
    Reinhard,
}

/// `--integrator` (render, tradeoff).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum IntegratorArg {
    /// Depth-first recursive Whitted tracing, one ray at a time.
    Recursive,
    /// Breadth-first wavefront tracing over SoA queues, one ECS system per stage.
    Wavefront,
}

impl From<IntegratorArg> for IntegratorKind {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Recursive => IntegratorKind::Recursive,
            IntegratorArg::Wavefront => IntegratorKind::Wavefront,
        }
    }
}

/// `--transport` (render).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum TransportArg {
    /// Whitted: point lights, mirror reflection and refraction.
    Whitted,
    /// Path tracing with next-event estimation and MIS; emissive surfaces
    /// are area lights.
    Path,
}

impl From<TransportArg> for Transport {
    fn from(a: TransportArg) -> Self {
        match a {
            TransportArg::Whitted => Transport::Whitted,
            TransportArg::Path => Transport::Path,
        }
    }
}

/// `--bvh-quality` (render). The variants have no doc comments on purpose:
/// clap would list them in `--help`, which shows only the names.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum QualityArg {
    Fastest,
    VeryFast,
    Fast,
    Medium,
    Slow,
    VerySlow,
}

impl From<QualityArg> for BuildQuality {
    fn from(q: QualityArg) -> Self {
        match q {
            QualityArg::Fastest => BuildQuality::Fastest,
            QualityArg::VeryFast => BuildQuality::VeryFast,
            QualityArg::Fast => BuildQuality::Fast,
            QualityArg::Medium => BuildQuality::Medium,
            QualityArg::Slow => BuildQuality::Slow,
            QualityArg::VerySlow => BuildQuality::VerySlow,
        }
    }
}

/// A rayon pool of `threads` workers (one per core by default).
pub fn thread_pool(threads: Option<usize>) -> Result<(rayon::ThreadPool, usize)> {
    let threads = match threads {
        Some(0) => return Err(Error::Invalid("--threads must be at least 1".into())),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Invalid(format!("cannot start {threads} threads: {e}")))?;
    Ok((pool, threads))
}
