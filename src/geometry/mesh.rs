//! Triangle meshes with their own bottom-level BVH and a watertight
//! ray-triangle test.

use std::time::Instant;

use glam::{BVec3A, UVec2, Vec2, Vec3, Vec3A, Vec4};
use obvhs::cwbvh::node::{CwBvhNode, extract_byte64};
use obvhs::{BvhBuildParams, aabb::Aabb, cwbvh::CwBvh, cwbvh::builder::build_cwbvh};

use crate::accel::packet::{LANES, LaneMask, Packet, for_each_lane};
use crate::accel::stream::Stream;
use crate::core::math::Ray;

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
    /// Hit point in object space, interpolated from the triangle's
    /// vertices: correct to a few ulps of its own coordinates, whereas
    /// `ray.at(t)` carries the rounding of the ray's origin.
    pub point: Vec3A,
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
    direction: Vec3A,
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
            direction: d,
            k: [kx, ky, kz],
            shear: Vec3A::new(d[kx] / d[kz], d[ky] / d[kz], 0.0),
        }
    }

    /// Intersects the triangle `(p0, p1, p2)`; returns `(t, b1, b2)` for a
    /// hit with `t` in `(t_min, t_max)`.
    ///
    /// Hits on shared edges and vertices are never lost: each edge function
    /// depends only on the edge's two vertices and the ray, and is
    /// evaluated identically (up to sign) by the two triangles sharing the
    /// edge, so a ray near the edge is inside one of them.
    ///
    /// An edge function whose f32 value is within its rounding error bound
    /// (`8 EPS` times the larger vertex coordinate relative to the origin
    /// times the sum of the edge's sheared coordinates) is re-evaluated in
    /// double precision from the vertex positions. The decision and the
    /// re-evaluation use only that edge's data, which keeps the two
    /// triangles consistent. This fixes rays in (or within rounding of) the
    /// triangle's plane: the projected triangle is then a segment, every
    /// edge function is rounding noise, and the f32 test could report a hit
    /// where the ray is not even over the triangle (seen in
    /// `tests/watertight.rs`). A ray whose three edge functions are all zero
    /// within double precision rounding lies in the plane: no hit.
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
        let (sx, sy) = (self.shear.x, self.shear.y);
        let ax = a[kx] - sx * a[kz];
        let ay = a[ky] - sy * a[kz];
        let bx = b[kx] - sx * b[kz];
        let by = b[ky] - sy * b[kz];
        let cx = c[kx] - sx * c[kz];
        let cy = c[ky] - sy * c[kz];
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        // Rounding error bounds, symmetric in the edge's two vertices.
        let (ma, mb, mc) = (
            a.abs().max_element(),
            b.abs().max_element(),
            c.abs().max_element(),
        );
        let (sa, sb, sc) = (
            ax.abs() + ay.abs(),
            bx.abs() + by.abs(),
            cx.abs() + cy.abs(),
        );
        let tol = 8.0 * f32::EPSILON;
        let bounds = [
            tol * mb.max(mc) * (sb + sc),
            tol * mc.max(ma) * (sc + sa),
            tol * ma.max(mb) * (sa + sb),
        ];
        if !(u.abs() > bounds[0] && v.abs() > bounds[1] && w.abs() > bounds[2]) {
            return self.intersect_careful([p0, p1, p2], [u, v, w], bounds, t_min, t_max);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let t = self.plane_t(p0, p1, p2);
        if !(t > t_min && t < t_max) {
            return None;
        }
        let inv = 1.0 / det;
        Some((t, v * inv, w * inv))
    }

    /// Ray parameter of the crossing with the triangle's plane, in double
    /// precision: `n.(p0 - o) / n.d` with `n = (p1 - p0) x (p2 - p0)`.
    ///
    /// The usual interpolation `(u z0 + v z1 + w z2) / det` inherits the
    /// barycentrics' rounding, which grows with the triangle's aspect ratio
    /// times the distance of the origin: a 1:500 sliver seen from 80 units
    /// away was hit 4.5e-4 off its plane (`tests/watertight.rs`), enough
    /// for secondary rays to self-intersect. In f64 the differences of f32
    /// coordinates and their products are exact, so `t` is correct to f32
    /// rounding for any triangle. Only called for hits.
    #[inline]
    fn plane_t(&self, p0: Vec3A, p1: Vec3A, p2: Vec3A) -> f32 {
        let p0 = p0.as_dvec3();
        let n = (p1.as_dvec3() - p0).cross(p2.as_dvec3() - p0);
        (n.dot(p0 - self.origin.as_dvec3()) / n.dot(self.direction.as_dvec3())) as f32
    }

    /// [`Self::intersect`] when some edge function is within its f32
    /// rounding error: those edges are re-evaluated in double precision
    /// (the others keep their f32 values, exactly as the neighbouring
    /// triangles see them).
    #[cold]
    #[inline(never)]
    fn intersect_careful(
        &self,
        p: [Vec3A; 3],
        edges32: [f32; 3],
        bounds: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let o = self.origin.as_dvec3();
        let d = self.direction.as_dvec3();
        let (sx, sy) = (d[kx] / d[kz], d[ky] / d[kz]);
        // Sheared coordinates and magnitudes in f64. Differences of f32
        // values are exact in f64 (unless their exponents are more than 29
        // apart).
        let q = p.map(|v| {
            let r = v.as_dvec3() - o;
            let (x, y) = (r[kx] - sx * r[kz], r[ky] - sy * r[kz]);
            (x, y, r.abs().max_element(), x.abs() + y.abs())
        });
        // Edge k joins vertices (k+1, k+2): u = edge(b, c), v = edge(c, a),
        // w = edge(a, b), with edge(p, q) = q.x p.y - q.y p.x.
        let mut e = [0.0f64; 3];
        let mut all_zero = true;
        for k in 0..3 {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            if edges32[k].abs() > bounds[k] {
                e[k] = edges32[k] as f64;
                all_zero = false;
            } else {
                let (pi, pj) = (q[i], q[j]);
                e[k] = pj.0 * pi.1 - pj.1 * pi.0;
                let noise = 8.0 * f64::EPSILON * pi.2.max(pj.2) * (pi.3 + pj.3);
                if !(e[k].abs() <= noise) {
                    all_zero = false;
                }
            }
        }
        if all_zero {
            // The ray lies in the triangle's plane (or the input is not finite).
            return None;
        }
        let [u, v, w] = e;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let t = self.plane_t(p[0], p[1], p[2]);
        if !(t > t_min && t < t_max) {
            return None;
        }
        Some((t, (v / det) as f32, (w / det) as f32))
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

/// A ray prepared for conservative box tests against CwBvh nodes.
#[derive(Clone, Copy, Debug)]
struct BoxRay {
    origin: Vec3A,
    inv_dir: Vec3A,
    /// Axes along which the ray does not move (or whose reciprocal
    /// overflows): the slab test becomes an inside/outside test.
    parallel: BVec3A,
    /// Largest coordinate magnitude of the origin.
    origin_mag: f32,
}

impl BoxRay {
    #[inline]
    fn new(ray: &Ray) -> Self {
        let inv_dir = Vec3A::ONE / ray.direction;
        let parallel = !inv_dir.abs().cmplt(Vec3A::INFINITY);
        Self {
            origin: ray.origin,
            inv_dir,
            parallel,
            origin_mag: ray.origin.abs().max_element(),
        }
    }
}

/// Rounding margin of the node test, in units of `f32::EPSILON` times the
/// larger coordinate magnitude of the ray origin and the node.
///
/// The watertight triangle test accepts a ray when its *rounded* sheared
/// coordinates put it inside the triangle. Those coordinates are
/// differences `vertex - origin` followed by a shear, which carry about
/// 2 EPS (|vertex| + |origin|) of absolute error, so an accepted ray may
/// pass outside the exact triangle, and outside its exact box, by that
/// much. This matters at shared edges and vertices: the consistent edge
/// functions give the ray to exactly one of the neighbours, and if that
/// neighbour's box were culled the ray would pass through the mesh. Boxes
/// are therefore grown by 16 EPS (|origin| + |node|) per axis, which also
/// covers the rounding of the slab computation itself and of the
/// quantised child boxes. (obvhs's own node test pads nothing, ignores
/// `tmin` and rejects every box closer than `t = 1e-4`, a scene-scale
/// epsilon; both made rays leak through closed meshes.)
pub const NODE_MARGIN_EPS: f32 = 16.0;

/// Conservative ray-box test of the eight children of a CwBvh node;
/// returns the hit mask in obvhs's encoding.
///
/// The eight children are tested as two groups of four in SIMD registers
/// (`glam::Vec4`); testing one child at a time was four times slower.
#[inline(always)]
fn intersect_node(node: &CwBvhNode, ray: &BoxRay, t_min: f32, t_max: f32, oct_inv4: u32) -> u32 {
    let extent = node.compute_extent();
    let p = Vec3A::from(node.p);
    let node_mag = p.abs().max((p + extent * 255.0).abs()).max_element();
    let margin = NODE_MARGIN_EPS * f32::EPSILON * (ray.origin_mag + node_mag);
    let quads = |q: &[u8; 8]| {
        (
            Vec4::new(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32),
            Vec4::new(q[4] as f32, q[5] as f32, q[6] as f32, q[7] as f32),
        )
    };
    let mut enter = [Vec4::splat(t_min); 2];
    let mut exit = [Vec4::splat(t_max); 2];
    let axes = [
        (&node.child_min_x, &node.child_max_x),
        (&node.child_min_y, &node.child_max_y),
        (&node.child_min_z, &node.child_max_z),
    ];
    for (a, (q_lo, q_hi)) in axes.into_iter().enumerate() {
        let (lo0, lo1) = quads(q_lo);
        let (hi0, hi1) = quads(q_hi);
        if ray.parallel.test(a) {
            // The ray does not move along this axis: inside the slab or not.
            let e = Vec4::splat(extent[a]);
            let o = Vec4::splat(ray.origin[a]);
            let (base_lo, base_hi) = (Vec4::splat(p[a] - margin), Vec4::splat(p[a] + margin));
            for (k, (ql, qh)) in [(lo0, hi0), (lo1, hi1)].into_iter().enumerate() {
                let inside = (ql * e + base_lo).cmple(o) & o.cmple(qh * e + base_hi);
                enter[k] = Vec4::select(inside, enter[k], Vec4::INFINITY);
                exit[k] = Vec4::select(inside, exit[k], Vec4::NEG_INFINITY);
            }
        } else {
            // Plane distances as one multiply-add from the quantised
            // coordinates; the reassociation's rounding (a few ulps of
            // |origin - node| / |direction|) is far inside the margin.
            let inv = ray.inv_dir[a];
            let scale = Vec4::splat(extent[a] * inv);
            let off_lo = Vec4::splat((p[a] - margin - ray.origin[a]) * inv);
            let off_hi = Vec4::splat((p[a] + margin - ray.origin[a]) * inv);
            for (k, (ql, qh)) in [(lo0, hi0), (lo1, hi1)].into_iter().enumerate() {
                let t_lo = ql * scale + off_lo;
                let t_hi = qh * scale + off_hi;
                let (near, far) = if inv >= 0.0 {
                    (t_lo, t_hi)
                } else {
                    (t_hi, t_lo)
                };
                enter[k] = enter[k].max(near);
                exit[k] = exit[k].min(far);
            }
        }
    }
    // The products carry one rounding each: widen by a few ulps.
    let widen = 4.0 * f32::EPSILON;
    let mut hits = 0u32;
    for k in 0..2 {
        let e = enter[k] - enter[k].abs() * widen;
        let x = exit[k] + exit[k].abs() * widen;
        hits |= e.cmple(x).bitmask() << (4 * k);
    }
    if hits == 0 {
        return 0;
    }
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hit_mask = 0;
    while hits != 0 {
        let c = hits.trailing_zeros() as usize;
        hits &= hits - 1;
        hit_mask |= extract_byte64(child_bits8, c) << extract_byte64(bit_index8, c);
    }
    hit_mask
}

/// Traverses `bvh` with a conservative node test (see [`NODE_MARGIN_EPS`]).
///
/// `visit(slot, t_max)` tests the primitive in leaf slot `slot` (an index
/// into `bvh.primitive_indices`) and returns the `t` of a hit inside
/// `(t_min, t_max)`, which then shrinks `t_max`. With `stop_at_first` the
/// traversal ends at the first hit (shadow rays). Returns whether any
/// primitive was hit.
///
/// Used for every mesh; the top-level BVH can use it the same way.
pub fn traverse_bvh(
    bvh: &CwBvh,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    stop_at_first: bool,
    mut visit: impl FnMut(usize, f32) -> Option<f32>,
) -> bool {
    let box_ray = BoxRay::new(ray);
    let mut t_max = t_max;
    let mut any = false;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    'traversal: {
        obvhs::traverse!(
            bvh,
            node,
            state,
            intersect_node(node, &box_ray, t_min, t_max, state.oct_inv4),
            {
                if let Some(t) = visit(state.primitive_id as usize, t_max) {
                    any = true;
                    if stop_at_first {
                        break 'traversal;
                    }
                    t_max = t_max.min(t);
                }
            }
        );
    }
    any
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
        MESH_BVH_BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
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
        traverse_bvh(&self.bvh, ray, t_min, t_max, false, |id, t_max| {
            let [p0, p1, p2] = self.corners[id];
            let (t, b1, b2) = wt.intersect(p0, p1, p2, t_min, t_max)?;
            best = Some(MeshHit {
                t,
                triangle: id as u32,
                b1,
                b2,
            });
            Some(t)
        });
        best
    }

    /// Closest hits for the lanes of `packet` in `lanes` (rays in object
    /// space), by packet traversal: `best[l]` is replaced when lane `l`
    /// finds a nearer hit than `packet.t_max[l]`, which is shrunk to it.
    pub fn intersect_packet(
        &self,
        packet: &mut Packet,
        lanes: LaneMask,
        best: &mut [Option<MeshHit>; LANES],
    ) {
        let mut wt = [None; LANES];
        for_each_lane(lanes, |l| wt[l] = Some(WatertightRay::new(&packet.rays[l])));
        crate::accel::packet::traverse(&self.bvh, packet, lanes, |p, hit, slot| {
            let [p0, p1, p2] = self.corners[slot];
            for_each_lane(hit, |l| {
                if let Some(w) = &wt[l]
                    && let Some((t, b1, b2)) = w.intersect(p0, p1, p2, p.t_min[l], p.t_max[l])
                {
                    p.t_max[l] = t;
                    best[l] = Some(MeshHit {
                        t,
                        triangle: slot as u32,
                        b1,
                        b2,
                    });
                }
            });
            0
        });
    }

    /// The lanes of `packet` in `lanes` that hit any triangle within their
    /// intervals; each lane stops at its first blocker.
    pub fn occluded_packet(&self, packet: &mut Packet, lanes: LaneMask) -> LaneMask {
        let mut wt = [None; LANES];
        for_each_lane(lanes, |l| wt[l] = Some(WatertightRay::new(&packet.rays[l])));
        let mut blocked = 0;
        crate::accel::packet::traverse(&self.bvh, packet, lanes, |p, hit, slot| {
            let [p0, p1, p2] = self.corners[slot];
            let mut now = 0;
            for_each_lane(hit, |l| {
                if let Some(w) = &wt[l]
                    && w.intersect(p0, p1, p2, p.t_min[l], p.t_max[l]).is_some()
                {
                    now |= 1 << l;
                }
            });
            blocked |= now;
            now
        });
        blocked
    }

    /// Closest hits of every ray of `stream` (object space), by stream
    /// traversal ([`crate::accel::stream`]): `best[i]` is ray `i`'s nearest hit
    /// inside its interval, as [`Mesh::intersect`] finds it. `wt` is a
    /// reusable buffer.
    pub fn intersect_stream(
        &self,
        stream: &mut Stream,
        wt: &mut Vec<WatertightRay>,
        best: &mut Vec<Option<MeshHit>>,
    ) {
        wt.clear();
        wt.extend(stream.rays.iter().map(WatertightRay::new));
        best.clear();
        best.resize(stream.len(), None);
        crate::accel::stream::traverse(&self.bvh, stream, |slot, ids, s| {
            let [p0, p1, p2] = self.corners[slot];
            for &r in ids {
                let r = r as usize;
                if let Some((t, b1, b2)) = wt[r].intersect(p0, p1, p2, s.t_min[r], s.t_max[r]) {
                    s.t_max[r] = t;
                    best[r] = Some(MeshHit {
                        t,
                        triangle: slot as u32,
                        b1,
                        b2,
                    });
                }
            }
        });
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
        traverse_bvh(&self.bvh, ray, t_min, t_max, true, |id, t_max| {
            let [p0, p1, p2] = self.corners[id];
            wt.intersect(p0, p1, p2, t_min, t_max).map(|h| h.0)
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
            point: p0 + (p1 - p0) * hit.b1 + (p2 - p0) * hit.b2,
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

static MESH_BVH_BUILDS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Number of mesh BVHs built by this process so far (one per successful
/// [`Mesh::new`]). Scene updates never build one: tests compare this
/// counter before and after.
pub fn mesh_bvh_builds() -> u64 {
    MESH_BVH_BUILDS.load(std::sync::atomic::Ordering::Relaxed)
}
