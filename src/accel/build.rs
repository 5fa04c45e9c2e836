//! Building BVHs over boxes: obvhs's presets, and boxes padded so that
//! the node test never culls what the exact primitive test accepts.

use glam::Vec3A;
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
    /// `medium_build`, the default (mesh BVHs: see [`BuildQuality::mesh_params`]).
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

impl BuildQuality {
    /// The obvhs parameters of mesh BVHs of this preset: [`Self::params`],
    /// except that `Medium` looks for PLOC merge partners among the 6
    /// nearest clusters on either side (obvhs's `Low` search distance)
    /// instead of 14. On the traversal-anchors meshes this takes about a
    /// fifth off the build's instructions (100k triangles, one thread,
    /// callgrind: 271 M -> 217 M) and traversal did not slow down: per ray
    /// instructions -3.4% / -0.8% (100k, camera / bounce rays) and -7.2% /
    /// -0.3% (1M); CPU-time Mrays/s of single rays, packets and streams
    /// within 0.7% on 100k and 1-8% faster on 1M.
    pub fn mesh_params(self) -> BvhBuildParams {
        let mut params = self.params();
        if self == BuildQuality::Medium {
            params.ploc_search_distance = obvhs::ploc::PlocSearchDistance::Low;
        }
        params
    }
}

/// How meshes are built: the BVH preset, and the structure (`None`: the
/// scene file's `[settings] accel`, else the BVH). A plain
/// [`BuildQuality`] converts into options with no structure named.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct BuildOptions {
    /// obvhs preset of mesh BVHs.
    pub quality: BuildQuality,
    /// Structure over each mesh's triangles.
    pub accel: Option<crate::core::settings::Accel>,
}

impl From<BuildQuality> for BuildOptions {
    fn from(quality: BuildQuality) -> Self {
        Self {
            quality,
            accel: None,
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
