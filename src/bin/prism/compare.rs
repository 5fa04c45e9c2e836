//! `prism compare`: error metrics of one EXR against a reference EXR.

use std::path::PathBuf;

use serde::Serialize;

use prism::core::error::{Error, Result};
use prism::image::metrics::{self, Metrics};

use crate::args::{ToneMapArg, png_options};

/// Options of `prism compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// The image to judge (.exr, linear radiance).
    pub test: PathBuf,
    /// The reference it is judged against (.exr, same size).
    pub reference: PathBuf,
    /// Exposure in stops applied to both images before FLIP, which
    /// compares displayed 8-bit images (RMSE and relMSE use raw radiance).
    #[arg(
        long,
        value_name = "EV",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    pub exposure: f32,
    /// Tone map applied to both images before FLIP.
    #[arg(long, value_enum, default_value_t = ToneMapArg::Clamp)]
    pub tonemap: ToneMapArg,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// What `--json` prints.
#[derive(Serialize)]
struct Report<'a> {
    test: &'a str,
    reference: &'a str,
    width: u32,
    height: u32,
    #[serde(flatten)]
    metrics: Metrics,
}

/// Reads both images, computes the metrics and prints them.
pub fn run(args: CompareArgs) -> Result<()> {
    // The display mapping FLIP sees.
    let display = png_options(args.exposure, args.tonemap)?;
    let test = metrics::read_exr(&args.test)?;
    let reference = metrics::read_exr(&args.reference)?;
    let m = metrics::compare(&test, &reference, &display).map_err(|e| {
        Error::Invalid(format!(
            "{} against {}: {e}",
            args.test.display(),
            args.reference.display()
        ))
    })?;
    let (test_name, ref_name) = (
        args.test.display().to_string(),
        args.reference.display().to_string(),
    );
    if args.json {
        let report = Report {
            test: &test_name,
            reference: &ref_name,
            width: test.width,
            height: test.height,
            metrics: m,
        };
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| Error::Invalid(format!("cannot write JSON: {e}")))?;
        println!("{text}");
    } else {
        println!("test:      {test_name} ({}x{})", test.width, test.height);
        println!("reference: {ref_name}");
        println!("RMSE:      {:.6e}", m.rmse);
        println!("relMSE:    {:.6e}", m.rel_mse);
        println!("FLIP:      {:.6}", m.flip);
    }
    Ok(())
}
