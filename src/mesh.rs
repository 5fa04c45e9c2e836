//! Triangle meshes with their own bottom-level BVH and a watertight
//! ray-triangle test.

use std::time::Instant;

use glam::{Vec2, Vec3, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, cwbvh::CwBvh, cwbvh::builder::build_cwbvh};

use crate::math::Ray;

/// How a mesh's shading normal is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NormalMode {
    /// The triangle's geometric normal everywhere.
    Flat,
    /// Vertex normals interpolated with barycentric coordinates (computed
    /// as area-weighted averages when the input has none).
    #[default]
    Smooth,
}

/// Raw mesh input, as read by a loader.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Optional vertex normals (same length as `positions`).
    pub normals: Option<Vec<Vec3>>,
    /// Optional texture coordinates (same length as `positions`).
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex index triples.
    pub indices: Vec<[u32; 3]>,
}

/// A triangle mesh in object space, with a BVH over its triangles.
///
/// Triangles are stored in BVH leaf order so traversal reads them without
/// an indirection; [`MeshHit::triangle`] indexes that order.
#[derive(Debug)]
pub struct Mesh {
    /// Name for messages.
    pub name: String,
    positions: Vec<Vec3A>,
    normals: Option<Vec<Vec3A>>,
    uvs: Option<Vec<Vec2>>,
    /// Vertex indices, in BVH order.
    triangles: Vec<[u32; 3]>,
    /// Vertex positions per triangle, in BVH order.
    corners: Vec<[Vec3A; 3]>,
    bvh: CwBvh,
    bounds: (Vec3A, Vec3A),
    /// Seconds spent building the BVH.
    pub build_seconds: f64,
}

/// A ray-mesh intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshHit {
    /// Ray parameter.
    pub t: f32,
    /// Triangle index in BVH order.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub b1: f32,
    /// Barycentric weight of the third vertex.
    pub b2: f32,
}

/// Surface attributes at a mesh hit, in object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshSurface {
    /// Geometric normal (unnormalised, by winding order).
    pub geometric_normal: Vec3A,
    /// Shading normal (unnormalised; equals the geometric one for flat meshes).
    pub shading_normal: Vec3A,
    /// Texture coordinates (zero when the mesh has none).
    pub uv: Vec2,
}

/// A ray prepared for the watertight triangle test of Woop, Benthin and
/// Wald (2013): the axis permutation and shear are computed once per ray.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    origin: Vec3A,
    k: [usize; 3],
    shear: Vec3A,
}

impl WatertightRay {
    /// Prepares `ray` (direction must be non-zero).
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let d = ray.direction;
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Self {
            origin: ray.origin,
            k: [kx, ky, kz],
            shear: Vec3A::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]),
        }
    }

    /// Intersects the triangle `(p0, p1, p2)`; returns `(t, b1, b2)` for a
    /// hit with `t` in `(t_min, t_max)`. Hits on shared edges and vertices
    /// are never lost: every edge function is evaluated identically for
    /// the two triangles that share the edge, and exact zeros are
    /// re-evaluated in double precision.
    #[inline]
    pub fn intersect(
        &self,
        p0: Vec3A,
        p1: Vec3A,
        p2: Vec3A,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let a = p0 - self.origin;
        let b = p1 - self.origin;
        let c = p2 - self.origin;
        let (sx, sy, sz) = (self.shear.x, self.shear.y, self.shear.z);
        let ax = a[kx] - sx * a[kz];
        let ay = a[ky] - sy * a[kz];
        let bx = b[kx] - sx * b[kz];
        let by = b[ky] - sy * b[kz];
        let cx = c[kx] - sx * c[kz];
        let cy = c[ky] - sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let (ax, ay, bx, by, cx, cy) = (
                ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
            );
            u = (cx * by - cy * bx) as f32;
            v = (ax * cy - ay * cx) as f32;
            w = (bx * ay - by * ax) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let az = sz * a[kz];
        let bz = sz * b[kz];
        let cz = sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        if !(t > t_min && t < t_max) {
            return None;
        }
        Some((t, v * inv, w * inv))
    }
}

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
pub(crate) fn padded_aabb(min: Vec3A, max: Vec3A) -> Aabb {
    let pad = min.abs().max(max.abs()) * (4.0 * f32::EPSILON) + Vec3A::splat(f32::MIN_POSITIVE);
    Aabb::new(min - pad, max + pad)
}

/// Largest coordinate magnitude accepted in a BVH. Beyond it box surface
/// areas overflow f32 and obvhs's builder breaks (seen panicking at 1.7e38).
pub const MAX_COORDINATE: f32 = 1.0e15;

/// Converts a ray for obvhs traversal.
///
/// Negative zeros in the direction are made positive: obvhs 0.4 picks the
/// child order from `direction < 0` but the slab test's reciprocal from the
/// sign bit, so a `-0.0` component makes CwBvh traversal miss boxes the ray
/// passes through (found by `tests/bvh.rs`).
#[inline]
pub(crate) fn obvhs_ray(ray: &Ray, t_min: f32, t_max: f32) -> obvhs::ray::Ray {
    obvhs::ray::Ray::new(ray.origin, ray.direction + Vec3A::ZERO, t_min, t_max)
}

/// Builds a CwBvh over boxes; the BVH's own `primitive_indices` map leaf
/// slots back to positions in `boxes`.
pub(crate) fn build_bvh(boxes: &[Aabb], quality: BuildQuality) -> CwBvh {
    // Some obvhs presets split large triangles; with plain boxes that is
    // meaningless, so the split flag is cleared.
    let mut params = quality.params();
    params.pre_split = false;
    build_cwbvh(boxes, params, &mut std::time::Duration::default())
}

impl Mesh {
    /// Validates `data` and builds the mesh and its BVH.
    ///
    /// Errors name the problem: non-finite positions, normals or uvs,
    /// attribute arrays of the wrong length, or indices out of range.
    /// Degenerate (zero-area) triangles are kept: they can never be hit.
    pub fn new(
        name: impl Into<String>,
        data: MeshData,
        mode: NormalMode,
        quality: BuildQuality,
    ) -> Result<Self, String> {
        let name = name.into();
        let n = data.positions.len();
        if let Some(i) = data.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a non-finite position"));
        }
        if let Some(i) = data
            .positions
            .iter()
            .position(|p| p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(format!(
                "vertex {i} lies farther than {MAX_COORDINATE:e} from the origin"
            ));
        }
        if let Some(normals) = &data.normals {
            if normals.len() != n {
                return Err(format!("{} normals for {} vertices", normals.len(), n));
            }
            if let Some(i) = normals.iter().position(|p| !p.is_finite()) {
                return Err(format!("vertex {i} has a non-finite normal"));
            }
        }
        if let Some(uvs) = &data.uvs {
            if uvs.len() != n {
                return Err(format!(
                    "{} texture coordinates for {} vertices",
                    uvs.len(),
                    n
                ));
            }
            if let Some(i) = uvs.iter().position(|p| !p.is_finite()) {
                return Err(format!("vertex {i} has non-finite texture coordinates"));
            }
        }
        if let Some((i, t)) = data
            .indices
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= n))
        {
            return Err(format!(
                "triangle {i} uses vertex index {} but there are only {n} vertices",
                t.iter().max().unwrap()
            ));
        }
        let positions: Vec<Vec3A> = data.positions.iter().map(|&p| p.into()).collect();
        let normals = match mode {
            NormalMode::Flat => None,
            NormalMode::Smooth => Some(match data.normals {
                Some(ns) => ns
                    .into_iter()
                    .map(|n| Vec3A::from(n).normalize_or_zero())
                    .collect(),
                None => vertex_normals(&positions, &data.indices),
            }),
        };

        let start = Instant::now();
        let boxes: Vec<Aabb> = data
            .indices
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                padded_aabb(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        let bvh = build_bvh(&boxes, quality);
        let triangles: Vec<[u32; 3]> = bvh
            .primitive_indices
            .iter()
            .map(|&i| data.indices[i as usize])
            .collect();
        let build_seconds = start.elapsed().as_secs_f64();
        let corners = triangles
            .iter()
            .map(|t| t.map(|i| positions[i as usize]))
            .collect();
        let mut lo = Vec3A::splat(f32::INFINITY);
        let mut hi = Vec3A::splat(f32::NEG_INFINITY);
        for t in &triangles {
            for &i in t {
                lo = lo.min(positions[i as usize]);
                hi = hi.max(positions[i as usize]);
            }
        }
        Ok(Self {
            name,
            positions,
            normals,
            uvs: data.uvs,
            triangles,
            corners,
            bvh,
            bounds: (lo, hi),
            build_seconds,
        })
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Object-space bounds, or `None` for a mesh without triangles.
    pub fn bounds(&self) -> Option<(Vec3A, Vec3A)> {
        (!self.triangles.is_empty()).then_some(self.bounds)
    }

    /// Vertex positions of triangle `i` (BVH order).
    pub fn triangle(&self, i: usize) -> [Vec3A; 3] {
        self.corners[i]
    }

    /// Closest hit with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<MeshHit> {
        let wt = WatertightRay::new(ray);
        let mut best: Option<MeshHit> = None;
        let mut hit = obvhs::ray::RayHit::none();
        self.bvh
            .ray_traverse(obvhs_ray(ray, t_min, t_max), &mut hit, |r, id| {
                let [p0, p1, p2] = self.corners[id];
                match wt.intersect(p0, p1, p2, r.tmin, r.tmax) {
                    Some((t, b1, b2)) => {
                        best = Some(MeshHit {
                            t,
                            triangle: id as u32,
                            b1,
                            b2,
                        });
                        t
                    }
                    None => f32::INFINITY,
                }
            });
        best
    }

    /// Closest hit by testing every triangle: the reference for BVH tests.
    pub fn intersect_brute_force(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<MeshHit> {
        let wt = WatertightRay::new(ray);
        let mut best = None;
        let mut t_max = t_max;
        for (i, [p0, p1, p2]) in self.corners.iter().enumerate() {
            if let Some((t, b1, b2)) = wt.intersect(*p0, *p1, *p2, t_min, t_max) {
                t_max = t;
                best = Some(MeshHit {
                    t,
                    triangle: i as u32,
                    b1,
                    b2,
                });
            }
        }
        best
    }

    /// True if any triangle is hit with `t` in `(t_min, t_max)`; stops at
    /// the first one found.
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        let wt = WatertightRay::new(ray);
        !self
            .bvh
            .ray_traverse_miss(obvhs_ray(ray, t_min, t_max), |r, id| {
                let [p0, p1, p2] = self.corners[id];
                wt.intersect(p0, p1, p2, r.tmin, r.tmax)
                    .map_or(f32::INFINITY, |h| h.0)
            })
    }

    /// Normals and texture coordinates at a hit.
    pub fn surface(&self, hit: &MeshHit) -> MeshSurface {
        let [i0, i1, i2] = self.triangles[hit.triangle as usize].map(|i| i as usize);
        let [p0, p1, p2] = self.corners[hit.triangle as usize];
        let b0 = 1.0 - hit.b1 - hit.b2;
        let geometric_normal = (p1 - p0).cross(p2 - p0);
        let shading_normal = match &self.normals {
            Some(ns) => {
                let n = ns[i0] * b0 + ns[i1] * hit.b1 + ns[i2] * hit.b2;
                if n.length_squared() > 0.0 {
                    n
                } else {
                    geometric_normal
                }
            }
            None => geometric_normal,
        };
        let uv = match &self.uvs {
            Some(uvs) => uvs[i0] * b0 + uvs[i1] * hit.b1 + uvs[i2] * hit.b2,
            None => Vec2::ZERO,
        };
        MeshSurface {
            geometric_normal,
            shading_normal,
            uv,
        }
    }

    /// Positions of all vertices (object space).
    pub fn positions(&self) -> &[Vec3A] {
        &self.positions
    }
}

/// Area-weighted vertex normals.
fn vertex_normals(positions: &[Vec3A], indices: &[[u32; 3]]) -> Vec<Vec3A> {
    let mut normals = vec![Vec3A::ZERO; positions.len()];
    for t in indices {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            normals[i as usize] += n;
        }
    }
    normals.iter().map(|n| n.normalize_or_zero()).collect()
}

/// ECS component: the entity is an instance of this shared mesh.
#[derive(bevy_ecs::component::Component, Clone, Debug)]
pub struct MeshInstance(pub std::sync::Arc<Mesh>);
