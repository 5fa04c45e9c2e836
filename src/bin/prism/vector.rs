//! `prism render --lines-svg` and `--overlay`: the checks before
//! rendering, and the lines found and the SVG written after it.

use std::path::Path;

use prism::core::error::{Error, Result};
use prism::core::settings::{LineSettings, RenderSettings};
use prism::image::lines::LineOverlay;
use prism::integrators::overlay::{self, OverlayKind};
use prism::integrators::vector_lines::{edge_count, to_svg, vector_lines};
use prism::scene::RenderScene;
use prism::scene::camera::{Camera, CameraRays};

use crate::render::progress_bar;

/// Rejects an SVG path given with `flag` that does not end in `.svg` or
/// whose folder cannot take a new file, before anything is rendered.
pub fn check_svg_path(path: &Path, flag: &str) -> Result<()> {
    let err = |message: String| Error::Output {
        path: path.to_path_buf(),
        message,
    };
    if path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
        != Some("svg")
    {
        return Err(err(format!("{flag} needs a file name ending in .svg")));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if path.is_dir() {
        return Err(err(format!("{flag} names a folder, not a file")));
    }
    // The same temporary file the atomic write will create.
    tempfile::Builder::new()
        .prefix(".prism-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| err(format!("cannot write the SVG in {}: {e}", dir.display())))
}

/// Finds the vector lines of `scene` for `camera` and writes them to
/// `path` atomically.
pub fn write_svg(
    path: &Path,
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    hidden: bool,
    quiet: bool,
) -> Result<()> {
    let lines = settings.lines.unwrap_or_default();
    let rays = CameraRays::relative_to(camera, scene.origin(), settings.width, settings.height);
    let total = edge_count(scene, &rays, lines.crease_degrees) as u64;
    let bar = progress_bar(
        total,
        quiet,
        "{spinner} vector lines [{bar:40}] {pos}/{len} edges {elapsed_precise} (eta {eta})",
    );
    let progress = bar.clone().map(|b| move |n: u64| b.inc(n));
    let v = vector_lines(
        scene,
        &rays,
        (settings.width, settings.height),
        lines.crease_degrees,
        progress.as_ref().map(|p| p as &(dyn Fn(u64) + Sync)),
    );
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let LineSettings { color, width, .. } = lines;
    let svg = to_svg(&v, color, width, hidden);
    prism::image::output::write_atomic(path, svg.as_bytes())?;
    if !quiet {
        let visible = v.segments.iter().filter(|s| s.visible).count();
        eprintln!(
            "{}: {} segments ({} visible, {} hidden), {} visibility rays",
            path.display(),
            v.segments.len(),
            visible,
            v.segments.len() - visible,
            v.rays
        );
    }
    Ok(())
}

/// An overlay asked for on the command line.
#[derive(Clone, Debug)]
pub struct OverlayRequest {
    /// What to draw.
    pub kind: OverlayKind,
    /// Levels of the BVH or kd-tree.
    pub depth: u32,
    /// Draw hidden pieces dashed (else leave them out).
    pub hidden: bool,
    /// Where to write the SVG, if anywhere.
    pub svg: Option<std::path::PathBuf>,
}

/// Finds the overlay's lines in `scene` for `camera`: the mask to draw
/// over the image, and the SVG text when one was asked for (written by the
/// caller after the image, so a failed render writes neither).
pub fn overlay_lines(
    request: &OverlayRequest,
    scene: &RenderScene,
    camera: &Camera,
    settings: &RenderSettings,
    quiet: bool,
) -> Result<(LineOverlay, Option<String>)> {
    let rays = CameraRays::relative_to(camera, scene.origin(), settings.width, settings.height);
    let size = (settings.width, settings.height);
    let v = overlay::overlay_lines(scene, &rays, size, request.kind, request.depth, None)
        .map_err(|e| Error::Invalid(format!("--overlay {}: {e}", request.kind.name())))?;
    let mask = overlay::rasterize(&v, overlay::COLOR, overlay::STROKE, request.hidden);
    let svg = request
        .svg
        .as_ref()
        .map(|_| overlay::overlay_svg(&v, request.hidden));
    if !quiet {
        let visible = v.segments.iter().filter(|s| s.visible).count();
        eprintln!(
            "overlay {}: {} segments ({} visible, {} hidden{}), {} visibility rays",
            request.kind.name(),
            v.segments.len(),
            visible,
            v.segments.len() - visible,
            if request.hidden {
                ", dashed"
            } else {
                ", left out"
            },
            v.rays
        );
    }
    Ok((mask, svg))
}
