//! `prism render --shard / --pixel-bounds / --samples`: which part of a
//! render a shard is, and the manifest it carries; and `prism merge`.

use std::ops::Range;
use std::path::PathBuf;

use prism::core::error::{Error, Result};
use prism::core::settings::RenderSettings;
use prism::image::output::OutputFormat;
use prism::image::shard::{self, ShardFile};

use crate::args::{ToneMapArg, png_options};

/// Environment variables `--shard auto/N` takes the index from, in this
/// order: Prism's own, Slurm job arrays', Kubernetes Indexed Jobs'.
pub const INDEX_VARIABLES: [&str; 3] = [
    "PRISM_SHARD_INDEX",
    "SLURM_ARRAY_TASK_ID",
    "JOB_COMPLETION_INDEX",
];

/// `--shard I/N` or `auto/N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShardSpec {
    /// The shard's index, `None` for `auto`.
    pub index: Option<u32>,
    /// Number of shards.
    pub count: u32,
}

/// Parses `I/N` or `auto/N` (for clap).
pub fn parse_shard(s: &str) -> std::result::Result<ShardSpec, String> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| format!("'{s}' is not I/N or auto/N"))?;
    let count: u32 = n
        .parse()
        .map_err(|_| format!("'{n}' is not a number of shards"))?;
    if count == 0 {
        return Err("the number of shards must be at least 1".into());
    }
    let index = if i == "auto" {
        None
    } else {
        let i: u32 = i
            .parse()
            .map_err(|_| format!("'{i}' is not a shard index (or auto)"))?;
        if i >= count {
            return Err(format!(
                "shard index {i} is not below the shard count {count} (indices count from 0)"
            ));
        }
        Some(i)
    };
    Ok(ShardSpec { index, count })
}

/// `--pixel-bounds x0,x1,y0,y1` (half-open columns and rows).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PixelBounds {
    /// Columns.
    pub columns: Range<u32>,
    /// Rows.
    pub rows: Range<u32>,
}

/// Parses `x0,x1,y0,y1` (for clap).
pub fn parse_pixel_bounds(s: &str) -> std::result::Result<PixelBounds, String> {
    let v: Vec<u32> = s
        .split(',')
        .map(|t| t.trim().parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}' is not four integers x0,x1,y0,y1"))?;
    let [x0, x1, y0, y1] = v[..] else {
        return Err(format!("'{s}' is not four integers x0,x1,y0,y1"));
    };
    if x0 >= x1 || y0 >= y1 {
        return Err(format!(
            "'{s}': bounds are half-open, so x0 < x1 and y0 < y1 are needed"
        ));
    }
    Ok(PixelBounds {
        columns: x0..x1,
        rows: y0..y1,
    })
}

/// Parses `A..B` (for clap).
pub fn parse_samples(s: &str) -> std::result::Result<Range<u32>, String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("'{s}' is not a sample range A..B"))?;
    let a: u32 = a
        .parse()
        .map_err(|_| format!("'{a}' is not a sample index"))?;
    let b: u32 = b
        .parse()
        .map_err(|_| format!("'{b}' is not a sample index"))?;
    if a >= b {
        return Err(format!("'{s}': the range is half-open, so A < B is needed"));
    }
    Ok(a..b)
}

/// The index of `--shard auto/N`, from the first of [`INDEX_VARIABLES`]
/// that is set.
pub fn auto_index(count: u32) -> Result<u32> {
    for var in INDEX_VARIABLES {
        if let Ok(v) = std::env::var(var) {
            let i: u32 = v.trim().parse().map_err(|_| {
                Error::Invalid(format!(
                    "--shard auto/{count}: {var}={v} is not a shard index"
                ))
            })?;
            if i >= count {
                return Err(Error::Invalid(format!(
                    "--shard auto/{count}: {var}={i} is not below the shard count {count} (use a job array numbered from 0, e.g. --array=0-{})",
                    count - 1
                )));
            }
            return Ok(i);
        }
    }
    Err(Error::Invalid(format!(
        "--shard auto/{count}: none of {} is set",
        INDEX_VARIABLES.join(", ")
    )))
}

/// Everything in the settings that determines the pixels, except the
/// seed and spp (stored on their own) and the window: shards merge only
/// when this text agrees.
pub fn settings_text(s: &RenderSettings, integrator: &str, camera: usize, bvh: &str) -> String {
    format!(
        "size={}x{} max_depth={} min_contribution={:?} transport={} light_samples={} russian_roulette={} rr_weight={:?} split={} sampler={} style={:?} gooch={:?} integrator={integrator} camera={camera} bvh={bvh}",
        s.width,
        s.height,
        s.max_depth,
        s.min_contribution,
        s.transport.name(),
        s.light_samples,
        s.rr_start_depth
            .map_or("off".to_string(), |d| format!("from {d}")),
        s.rr_weight,
        s.split,
        s.sampler.name(),
        s.style,
        s.gooch,
    )
}

/// Options of `prism merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Shard files written by `prism render --shard`, `--pixel-bounds` or
    /// `--samples` (OpenEXR), in any order.
    #[arg(required = true, value_name = "SHARD")]
    shards: Vec<PathBuf>,
    /// The merged image: `.exr` (linear radiance) or `.png` (exposure and
    /// tone map applied to the merged image).
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Exposure in stops for PNG output [default: 0]. Shards do not
    /// record a scene's `[settings] exposure`: pass it again here to get
    /// the PNG of the single render.
    #[arg(
        long,
        value_name = "EV",
        allow_hyphen_values = true,
        default_value_t = 0.0
    )]
    exposure: f32,
    /// Tone map for PNG output.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    tonemap: ToneMapArg,
    /// No summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// Reads and checks every shard, merges them and writes the image; on any
/// error nothing is written.
pub fn run_merge(args: MergeArgs) -> Result<()> {
    OutputFormat::from_path(&args.output)?;
    let png = png_options(args.exposure, args.tonemap)?;
    let bar = crate::render::progress_bar(
        args.shards.len() as u64,
        args.quiet,
        "{spinner} reading shards [{bar:40}] {pos}/{len} {elapsed_precise}",
    );
    let mut files = Vec::with_capacity(args.shards.len());
    for path in &args.shards {
        let shard = shard::read_shard(path)?;
        files.push(ShardFile {
            path: path.clone(),
            shard,
        });
        if let Some(b) = &bar {
            b.inc(1);
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let film = shard::merge(&files)?;
    prism::image::output::write_image(&args.output, &film, &png)?;
    if !args.quiet {
        let m = &files[0].shard.manifest;
        eprintln!(
            "{}: {}x{} at {} spp merged from {} shard(s)",
            args.output.display(),
            film.width,
            film.height,
            m.spp,
            files.len()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_bad_ones_say_why() {
        assert_eq!(
            parse_shard("2/7"),
            Ok(ShardSpec {
                index: Some(2),
                count: 7
            })
        );
        assert_eq!(parse_shard("auto/3").unwrap().index, None);
        assert!(parse_shard("7/7").unwrap_err().contains("below"));
        assert!(parse_shard("1/0").is_err());
        assert!(parse_shard("x").is_err());
        assert_eq!(
            parse_pixel_bounds("0,8,2,4"),
            Ok(PixelBounds {
                columns: 0..8,
                rows: 2..4
            })
        );
        assert!(parse_pixel_bounds("0,8,4,4").is_err());
        assert!(parse_pixel_bounds("0,8,4").is_err());
        assert_eq!(parse_samples("4..8"), Ok(4..8));
        assert!(parse_samples("8..4").is_err());
        assert!(parse_samples("4-8").is_err());
    }
}
