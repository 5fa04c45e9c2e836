//! Light-field capture: one world, one BVH, one frame per grid camera of
//! a [`Rig`].
//!
//! The scene is spawned once; between frames only the camera component
//! changes, so the sync systems find nothing to update and the top-level
//! BVH (and the meshes' BVHs, built at load) serve every view. The render
//! origin is fixed at the rig's centre, so every view is rendered in the
//! same single-precision frame whatever order the views come in.

use crate::accel::tlas::TlasUpdate;
use crate::image::film::Film;
use crate::io::desc::SceneDesc;
use crate::lightfield::Rig;

use super::frame::{RenderConfig, RenderOrigin};
use super::renderer::Renderer;

/// What a capture cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CaptureReport {
    /// Seconds spent tracing, over all views.
    pub render_seconds: f64,
    /// Seconds spent building the top-level BVH at the first view.
    pub tlas_seconds: f64,
    /// Views after the first whose frame rebuilt the top level or the
    /// scene (0 when the BVH was reused throughout).
    pub rebuilds: u32,
    /// Mesh BVHs built during the capture (0: the meshes' BVHs from load
    /// time served every view).
    pub mesh_bvh_builds: u64,
}

/// Renders the view of every camera of `rig` (rows from the top, columns
/// from the left) of `desc` with `config` (its image size is replaced by
/// the rig's resolution, its projection by the perspective one), calling
/// `each(column, row, image)` after each view; an error from `each` stops
/// the capture. `camera` picks the scene camera entity whose component is
/// replaced view by view.
pub fn capture_light_field(
    desc: SceneDesc,
    mut config: RenderConfig,
    camera: usize,
    rig: &Rig,
    mut each: impl FnMut(u32, u32, Film) -> crate::Result<()>,
) -> crate::Result<CaptureReport> {
    rig.validate().map_err(crate::Error::Invalid)?;
    config.settings.width = rig.resolution[0];
    config.settings.height = rig.resolution[1];
    config.settings.panorama = None;
    config.settings.window = None;
    let mut renderer = Renderer::with_scene(desc, config, camera)?;
    renderer.insert_resource(RenderOrigin::Fixed(rig.centre));
    let entity = renderer.cameras()[camera];
    let builds_before = crate::geometry::mesh::mesh_bvh_builds();
    let mut report = CaptureReport::default();
    let mut first = true;
    for row in 0..rig.grid[1] {
        for column in 0..rig.grid[0] {
            renderer
                .world_mut()
                .entity_mut(entity)
                .insert(rig.camera(column, row));
            let frame = renderer.render()?;
            if first {
                report.tlas_seconds = frame.update.accel_seconds;
                first = false;
            } else if frame.update.reset || frame.update.tlas == TlasUpdate::Rebuilt {
                report.rebuilds += 1;
            }
            report.render_seconds += frame.render_seconds;
            let film = frame
                .film
                .ok_or_else(|| crate::Error::Invalid("the renderer produced no image".into()))?;
            each(column, row, film)?;
        }
    }
    report.mesh_bvh_builds = crate::geometry::mesh::mesh_bvh_builds() - builds_before;
    Ok(report)
}
