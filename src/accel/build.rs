//! Building BVHs over boxes: obvhs's presets, boxes padded so that the
//! node test never culls what the exact primitive test accepts, and the
//! depth of a built tree.

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::{BvhBuildParams, aabb::Aabb};

/// Mesh BVH build quality, obvhs's presets from fastest to slowest build.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BuildQuality {
    /// `fastest_build`.
    Fastest,
    /// `very_fast_build`.
    VeryFast,
    /// `fast_build`.
    Fast,
    /// `medium_build`, the default.
    #[default]
    Medium,
    /// `slow_build`.
    Slow,
    /// `very_slow_build`.
    VerySlow,
}

impl BuildQuality {
    /// The obvhs parameters of this preset.
    pub fn params(self) -> BvhBuildParams {
        match self {
            BuildQuality::Fastest => BvhBuildParams::fastest_build(),
            BuildQuality::VeryFast => BvhBuildParams::very_fast_build(),
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
            BuildQuality::Slow => BvhBuildParams::slow_build(),
            BuildQuality::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// Pads a box by a few ulps of its magnitude so the BVH's box test never
/// rejects a ray the watertight triangle test would accept.
pub fn padded_aabb(min: Vec3A, max: Vec3A) -> Aabb {
    let pad = min.abs().max(max.abs()) * (4.0 * f32::EPSILON) + Vec3A::splat(f32::MIN_POSITIVE);
    Aabb::new(min - pad, max + pad)
}

/// Largest coordinate magnitude accepted in a BVH. Beyond it box surface
/// areas overflow f32 and obvhs's builder breaks (seen panicking at 1.7e38).
pub const MAX_COORDINATE: f32 = 1.0e15;

/// Builds a CwBvh over boxes; the BVH's own `primitive_indices` map leaf
/// slots back to positions in `boxes`.
pub fn build_bvh(boxes: &[Aabb], quality: BuildQuality) -> CwBvh {
    // Some obvhs presets split large triangles; with plain boxes that is
    // meaningless, so the split flag is cleared.
    let mut params = quality.params();
    params.pre_split = false;
    build_cwbvh(boxes, params, &mut std::time::Duration::default())
}

/// Levels of a CwBvh (0 when empty, 1 for a root whose children are all
/// leaves). obvhs checks its traversal stack against this only in debug
/// builds; Prism's traversals accept any depth (see
/// [`crate::accel::single`]).
pub fn cwbvh_depth(cw: &CwBvh) -> usize {
    fn depth(cw: &CwBvh, node: usize) -> usize {
        let n = &cw.nodes[node];
        let mut d = 0;
        for c in 0..8 {
            if !n.is_child_empty(c) && !n.is_leaf(c) {
                d = d.max(depth(cw, n.child_node_index(c) as usize));
            }
        }
        d + 1
    }
    if cw.nodes.is_empty() { 0 } else { depth(cw, 0) }
}
