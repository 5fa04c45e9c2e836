//! `prism`: the command-line renderer.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Large blocks (BVH builds, films, photon maps) on transparent huge pages:
/// fewer page faults (see `prism::core::alloc`).
#[global_allocator]
static ALLOC: prism::core::alloc::HugePageAlloc = prism::core::alloc::HugePageAlloc;

/// Prism: a data-oriented Whitted ray tracer whose scene is an ECS world.
#[derive(Parser, Debug)]
#[command(name = "prism", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

mod args;
mod bench;
mod compare;
mod lightfield;
mod radiosity_args;
mod rays;
mod render;
mod shard;
mod stats;
mod tradeoff;
mod vector;

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene file (.toml, .gltf or .glb) to an image (.png or .exr).
    Render(Box<render::RenderArgs>),
    /// Compare the recursive and the wavefront integrator on scenes: run
    /// both alternately and report median times, rays, Mrays/s, queue
    /// memory, wavefront stage times, the speedup, and closest-hit
    /// throughput of single rays and packets.
    Bench(bench::BenchArgs),
    /// Error metrics (RMSE, relative MSE, FLIP) of a test EXR against a
    /// reference EXR of the same size.
    Compare(compare::CompareArgs),
    /// Measure speed against accuracy: render a converged reference, sweep
    /// one knob at a time (spp, depth, contribution threshold, light
    /// samples, Russian roulette, BVH preset, transport, sampler, photon iterations) around a base
    /// configuration, and write tradeoff.csv and a plot of error against
    /// render time with the Pareto front.
    Tradeoff(tradeoff::TradeoffArgs),
    /// Merge shards written by `prism render --shard/--pixel-bounds/--samples`
    /// into the whole image (.exr or .png), after checking that they are of
    /// one render and cover every pixel's samples exactly once.
    Merge(shard::MergeArgs),
    /// Image-based rendering from a two-plane light field: `capture` a
    /// grid of views of a scene, `render` new views from the images alone,
    /// `compare` a new view with its direct render, `sweep` the grid
    /// density.
    Lightfield(lightfield::LightFieldArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render::run(*args),
        Command::Bench(args) => bench::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Tradeoff(args) => tradeoff::run(args),
        Command::Merge(args) => shard::run_merge(args),
        Command::Lightfield(args) => lightfield::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
