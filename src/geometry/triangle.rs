//! The watertight ray-triangle test of Woop, Benthin and Wald (2013),
//! with a double-precision fallback for edge functions within their
//! rounding error.

use glam::{DVec3, Vec3A, Vec4};

use crate::accel::node::max4;
use crate::core::math::Ray;

/// A ray prepared for the watertight triangle test of Woop, Benthin and
/// Wald (2013): the axis permutation and shear are computed once per ray.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    origin: Vec3A,
    direction: Vec3A,
    /// `[kx, ky, kz]`, kept as bytes (the struct is copied per lane of
    /// every packet).
    k: [u8; 3],
    shear: Vec3A,
    /// The origin's coordinates in the order `k` (read by the leaf tests
    /// without indexing a vector by a run-time axis).
    o_k: [f32; 3],
}

impl WatertightRay {
    /// The axis permutation `[kx, ky, kz]` (for tests).
    #[cfg(test)]
    pub(crate) fn permutation(&self) -> [usize; 3] {
        self.k.map(usize::from)
    }

    /// Row `k[j]` (the ray's `j`-th axis in its permutation) of vertex
    /// `vi` of `block`, without a bounds check: every leaf visit reads
    /// nine of them, and the checks of `k` were a tenth of the
    /// instructions of a visit (callgrind, anchors' bounce rays).
    #[inline(always)]
    fn row<'b>(&self, block: &'b Tri8, vi: usize, j: usize) -> &'b [f32; 8] {
        let a = self.k[j] as usize;
        debug_assert!(a < 3);
        // SAFETY: `k` is a permutation of 0, 1, 2: it is private and
        // written only by `new` and `lanes`, which build it from `NEXT`.
        #[allow(unsafe_code)]
        unsafe {
            block.v[vi].get_unchecked(a)
        }
    }

    /// Prepares `ray` (direction must be non-zero).
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let d = ray.direction;
        let a = d.abs();
        // The axis of largest |d| (x before y before z on ties), the next
        // two in turn, swapped when d points down that axis: without
        // branches, which incoherent rays would mispredict.
        let x_first = a.x > a.y;
        let is_x = x_first & (a.x > a.z);
        let is_y = !x_first & (a.y > a.z);
        let kz = 2 - 2 * is_x as usize - is_y as usize;
        const NEXT: [usize; 3] = [1, 2, 0];
        let dk = d.to_array();
        let (kx, ky) = (NEXT[kz], NEXT[NEXT[kz]]);
        let swap = (kx ^ ky) & 0usize.wrapping_sub((dk[kz] < 0.0) as usize);
        let (kx, ky) = (kx ^ swap, ky ^ swap);
        let o = ray.origin.to_array();
        Self {
            origin: ray.origin,
            direction: d,
            k: [kx as u8, ky as u8, kz as u8],
            shear: Vec3A::new(dk[kx] / dk[kz], dk[ky] / dk[kz], 0.0),
            o_k: [o[kx], o[ky], o[kz]],
        }
    }

    /// [`WatertightRay::new`] of each of the `N` rays of a packet,
    /// computed axis by axis across the rays (plain loops over the lanes,
    /// which the compiler widens: the axis choice by comparisons and
    /// selects, the shear by one division per lane and axis in one
    /// register), with the same IEEE operations on the same values, so
    /// each lane is `new`'s ray bit for bit. A packet's rays were prepared
    /// one at a time before: a tenth of the time of camera packets of 16
    /// (`perf`, anchors 100k), the run-time axis indexing and the two
    /// divisions of each ray in turn.
    #[inline(always)]
    pub fn lanes<const N: usize>(rays: &[Ray; N]) -> [Self; N] {
        let mut d = [[0.0f32; N]; 3];
        let mut o = [[0.0f32; N]; 3];
        for (l, r) in rays.iter().enumerate() {
            for a in 0..3 {
                d[a][l] = r.direction[a];
                o[a][l] = r.origin[a];
            }
        }
        let mut kz = [0u8; N];
        let mut swap = [false; N];
        let mut sx = [0.0f32; N];
        let mut sy = [0.0f32; N];
        for l in 0..N {
            let (dx, dy, dz) = (d[0][l], d[1][l], d[2][l]);
            let (ax, ay, az) = (dx.abs(), dy.abs(), dz.abs());
            // `new`'s choice of `kz`, and `kx`, `ky` as `NEXT[kz]`,
            // `NEXT[NEXT[kz]]` before the swap.
            let x_first = ax > ay;
            let is_x = x_first & (ax > az);
            let is_y = !x_first & (ay > az);
            let (dkx, dky, dkz) = if is_x {
                (dy, dz, dx)
            } else if is_y {
                (dz, dx, dy)
            } else {
                (dx, dy, dz)
            };
            let down = dkz < 0.0;
            let (dkx, dky) = if down { (dky, dkx) } else { (dkx, dky) };
            kz[l] = if is_x {
                0
            } else if is_y {
                1
            } else {
                2
            };
            swap[l] = down;
            sx[l] = dkx / dkz;
            sy[l] = dky / dkz;
        }
        // A loop rather than `std::array::from_fn`, whose closure was not
        // inlined into the SIMD entry points.
        const NEXT: [usize; 3] = [1, 2, 0];
        let mut out = [Self {
            origin: Vec3A::ZERO,
            direction: Vec3A::ZERO,
            k: [0, 1, 2],
            shear: Vec3A::ZERO,
            o_k: [0.0; 3],
        }; N];
        for (l, w) in out.iter_mut().enumerate() {
            let kz = kz[l] as usize;
            let (kx, ky) = (NEXT[kz], NEXT[NEXT[kz]]);
            let (kx, ky) = if swap[l] { (ky, kx) } else { (kx, ky) };
            *w = Self {
                origin: rays[l].origin,
                direction: rays[l].direction,
                k: [kx as u8, ky as u8, kz as u8],
                shear: Vec3A::new(sx[l], sy[l], 0.0),
                o_k: [o[kx][l], o[ky][l], o[kz][l]],
            };
        }
        out
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
    /// `tests/kernels/watertight.rs`). A ray whose three edge functions are all zero
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
        let [kx, ky, kz] = self.k.map(usize::from);
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
        let t = self.plane_t_within(p0, p1, p2, t_min, t_max)?;
        let inv = 1.0 / det;
        Some((t, v * inv, w * inv))
    }

    /// Ray parameter of the crossing with the triangle's plane, in double
    /// precision: `n.(p0 - o) / n.d` with `n = (p1 - p0) x (p2 - p0)`.
    ///
    /// The usual interpolation `(u z0 + v z1 + w z2) / det` inherits the
    /// barycentrics' rounding, which grows with the triangle's aspect ratio
    /// times the distance of the origin: a 1:500 sliver seen from 80 units
    /// away was hit 4.5e-4 off its plane (`tests/kernels/watertight.rs`), enough
    /// for secondary rays to self-intersect. In f64 the differences of f32
    /// coordinates and their products are exact, so `t` is correct to f32
    /// rounding for any triangle. Only called for rays that pass the edge
    /// test.
    ///
    /// Returns `t` when `t_min < t < t_max`, deciding exactly as computing
    /// `t = (num / den) as f32` and comparing would, but without the
    /// division when the quotient is negative (with `t_min >= 0`) or
    /// beyond `t_max`, which is read off `num` and `den`. The rounding
    /// `q -> (q as f64) as f32` is monotone and keeps `0` and `t_max`
    /// (an f32): a negative quotient gives `t <= 0`, one beyond `t_max`
    /// gives `t >= t_max`. Planes crossed behind the origin are common
    /// (a bounce ray's own triangle, the back faces of its
    /// neighbourhood); only quotients the test cannot settle are divided.
    #[inline(always)]
    fn plane_t_within(
        &self,
        p0: Vec3A,
        p1: Vec3A,
        p2: Vec3A,
        t_min: f32,
        t_max: f32,
    ) -> Option<f32> {
        let p0 = p0.as_dvec3();
        let n = (p1.as_dvec3() - p0).cross(p2.as_dvec3() - p0);
        self.plane_t_normal(p0, n, t_min, t_max)
    }

    /// [`Self::plane_t_within`] from the plane's point `p0` and its
    /// normal `n = (p1 - p0) x (p2 - p0)` already computed in f64 (the
    /// same values, so the same bits).
    #[inline(always)]
    fn plane_t_normal(&self, p0: DVec3, n: DVec3, t_min: f32, t_max: f32) -> Option<f32> {
        let num = n.dot(p0 - self.origin.as_dvec3());
        let den = n.dot(self.direction.as_dvec3());
        let negative = (num < 0.0 && den > 0.0) || (num > 0.0 && den < 0.0);
        if negative && t_min >= 0.0 {
            return None;
        }
        let positive = (num > 0.0 && den > 0.0) || (num < 0.0 && den < 0.0);
        // |den| t_max, rounded up: the product and the scaling each round
        // by at most 2^-53 relatively, well inside the factor 1 + 2^-49.
        // (No overflow: f32 coordinates give |num|, |den| below 2^400.)
        if positive && num.abs() > den.abs() * t_max as f64 * (1.0 + f64::EPSILON * 8.0) {
            return None;
        }
        let t = (num / den) as f32;
        (t > t_min && t < t_max).then_some(t)
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
        let [kx, ky, kz] = self.k.map(usize::from);
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
        let t = self.plane_t_within(p[0], p[1], p[2], t_min, t_max)?;
        Some((t, (v / det) as f32, (w / det) as f32))
    }
}

/// Up to eight triangles side by side, for one SIMD test
/// ([`WatertightRay::intersect8`], one 8-wide pass on the AVX2 path, or
/// two 4-wide ones; a leaf of four or fewer in one 4-wide pass,
/// [`WatertightRay::intersect4`]): `v[vertex][axis][lane]`, each row
/// one aligned AVX load. Unused lanes repeat lane 0 and are masked by
/// [`Tri8::count`]. The block also names its triangles, so a leaf test
/// reads nothing else.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Tri8 {
    /// Vertex coordinates.
    pub v: [[[f32; 8]; 3]; 3],
    /// Index of lane 0's triangle; lane `l` holds triangle `first + l`.
    pub first: u32,
    /// Triangles in the block (1 to 8).
    pub count: u32,
}

impl Tri8 {
    /// Packs one to eight triangles, the first of which is triangle
    /// `first`.
    pub fn new(tris: &[[Vec3A; 3]], first: u32) -> Self {
        debug_assert!(!tris.is_empty() && tris.len() <= 8);
        let mut v = [[[0.0; 8]; 3]; 3];
        for l in 0..8 {
            let t = tris[if l < tris.len() { l } else { 0 }];
            for (vi, p) in t.iter().enumerate() {
                for a in 0..3 {
                    v[vi][a][l] = p[a];
                }
            }
        }
        Self {
            v,
            first,
            count: tris.len() as u32,
        }
    }

    /// The corners of lane `l`.
    #[inline(always)]
    pub fn corners(&self, l: usize) -> [Vec3A; 3] {
        std::array::from_fn(|vi| Vec3A::new(self.v[vi][0][l], self.v[vi][1][l], self.v[vi][2][l]))
    }

    /// Lanes `4 h .. 4 h + 4` of row `a` of vertex `vi`.
    #[inline(always)]
    fn half(&self, vi: usize, a: usize, h: usize) -> Vec4 {
        Vec4::from_slice(&self.v[vi][a][4 * h..4 * h + 4])
    }
}

impl WatertightRay {
    /// The nearest hit among the first `count` triangles of `block` with
    /// `t` in `(t_min, t_max)`, as `(lane, t, b1, b2)`.
    ///
    /// The four triangles' sheared coordinates, edge functions and
    /// rounding bounds are computed side by side with exactly the
    /// operations of [`Self::intersect`], so every lane's result is bit for
    /// bit what `intersect` gives for that triangle, and the nearest is
    /// chosen as testing the lanes in order would (a later lane must be
    /// strictly nearer). Edge functions within their rounding bound go to
    /// the same double-precision re-check; the plane distance, the only
    /// division, is computed only for lanes whose edge test passed.
    #[inline(always)]
    pub fn intersect4(
        &self,
        block: &Tri8,
        count: u32,
        t_min: f32,
        mut t_max: f32,
    ) -> Option<(u32, f32, f32, f32)> {
        debug_assert!(count <= 4);
        let (lanes, e, bound) = self.edges4(block, 0);
        let interesting = lanes & ((1u32 << count) - 1);
        if interesting == 0 {
            return None;
        }
        self.finish(
            |l| block.corners(l),
            interesting,
            &e,
            &bound,
            t_min,
            &mut t_max,
        )
    }

    /// The nearest hit among the `count` (1 to 8) triangles of a leaf
    /// stored side by side in `block`, as `(lane, t, b1, b2)` with lane `l` the
    /// leaf's triangle `l`: [`Self::intersect4`] over eight lanes, one
    /// 8-wide pass with `AVX` (valid only on a CPU with AVX2, see
    /// [`crate::core::simd`]), two 4-wide ones otherwise. Every lane
    /// computes exactly the operations of [`Self::intersect`] for its
    /// triangle, so both paths and the one-triangle test agree bit for
    /// bit; the nearest wins, a later lane only when strictly nearer.
    #[inline(always)]
    pub fn intersect8<const AVX: bool>(
        &self,
        block: &Tri8,
        count: u32,
        t_min: f32,
        mut t_max: f32,
    ) -> Option<(u32, f32, f32, f32)> {
        if count <= 4 {
            return self.intersect4(block, count, t_min, t_max);
        }
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only by the AVX2 entry points, which run
            // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
            #[allow(unsafe_code)]
            let (lanes, e, bound) = unsafe { self.edges8_avx2(block) };
            let interesting = lanes & ((1u32 << count) - 1);
            if interesting == 0 {
                return None;
            }
            return self.finish(
                |l| block.corners(l),
                interesting,
                &e,
                &bound,
                t_min,
                &mut t_max,
            );
        }
        let (lo, e0, b0) = self.edges4(block, 0);
        let (hi, e1, b1) = self.edges4(block, 1);
        let interesting = (lo | hi << 4) & ((1u32 << count) - 1);
        if interesting == 0 {
            return None;
        }
        let join = |a: &[[f32; 4]; 3], b: &[[f32; 4]; 3]| {
            std::array::from_fn::<[f32; 8], 3, _>(|k| {
                std::array::from_fn(|l| if l < 4 { a[k][l] } else { b[k][l - 4] })
            })
        };
        self.finish(
            |l| block.corners(l),
            interesting,
            &join(&e0, &e1),
            &join(&b0, &b1),
            t_min,
            &mut t_max,
        )
    }

    /// The edge functions and their rounding bounds of the four lanes of
    /// `block`, and the lanes that need the re-check or whose edge test
    /// passed (all four lanes; the caller masks the unused ones).
    #[inline(always)]
    fn edges4(&self, block: &Tri8, h: usize) -> (u32, [[f32; 4]; 3], [[f32; 4]; 3]) {
        let sx = Vec4::splat(self.shear.x);
        let sy = Vec4::splat(self.shear.y);
        let (ox, oy, oz) = (
            Vec4::splat(self.o_k[0]),
            Vec4::splat(self.o_k[1]),
            Vec4::splat(self.o_k[2]),
        );
        let half = {
            #[inline(always)]
            |vi: usize, j: usize| Vec4::from_slice(&self.row(block, vi, j)[4 * h..4 * h + 4])
        };
        // Per vertex: sheared x, y; largest |coordinate|; |x| + |y|.
        let vertex = {
            #[inline(always)]
            |vi: usize| {
                let rx = half(vi, 0) - ox;
                let ry = half(vi, 1) - oy;
                let rz = half(vi, 2) - oz;
                let x = rx - sx * rz;
                let y = ry - sy * rz;
                // Exact maxima (no NaN here): the value `max_element` gives.
                let mag = max4(max4(rx.abs(), ry.abs()), rz.abs());
                (x, y, mag, x.abs() + y.abs())
            }
        };
        let (ax, ay, ma, sa) = vertex(0);
        let (bx, by, mb, sb) = vertex(1);
        let (cx, cy, mc, sc) = vertex(2);
        let tol = Vec4::splat(8.0 * f32::EPSILON);
        let b0 = tol * max4(mb, mc) * (sb + sc);
        let b1 = tol * max4(mc, ma) * (sc + sa);
        let b2 = tol * max4(ma, mb) * (sa + sb);
        edge_lanes4([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2])
    }

    /// [`Self::edges4`] for the eight lanes of a block in AVX
    /// registers: the same operations in the same order.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA. `#[inline(always)]` without a
    /// `#[target_feature]` of its own, so that it is inlined into the AVX2
    /// entry point with its intrinsics (see [`crate::core::simd`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn edges8_avx2(&self, block: &Tri8) -> (u32, [[f32; 8]; 3], [[f32; 8]; 3]) {
        // SAFETY: the caller runs on a CPU with AVX2 and FMA.
        unsafe {
            use std::arch::x86_64::*;
            let row = {
                #[inline(always)]
                |vi: usize, j: usize| -> __m256 { _mm256_load_ps(self.row(block, vi, j).as_ptr()) }
            };
            let sign = _mm256_set1_ps(-0.0);
            let abs = {
                #[inline(always)]
                |x: __m256| _mm256_andnot_ps(sign, x)
            };
            let sx = _mm256_set1_ps(self.shear.x);
            let sy = _mm256_set1_ps(self.shear.y);
            let (ox, oy, oz) = (
                _mm256_set1_ps(self.o_k[0]),
                _mm256_set1_ps(self.o_k[1]),
                _mm256_set1_ps(self.o_k[2]),
            );
            let vertex = {
                #[inline(always)]
                |vi: usize| {
                    let rx = _mm256_sub_ps(row(vi, 0), ox);
                    let ry = _mm256_sub_ps(row(vi, 1), oy);
                    let rz = _mm256_sub_ps(row(vi, 2), oz);
                    let x = _mm256_sub_ps(rx, _mm256_mul_ps(sx, rz));
                    let y = _mm256_sub_ps(ry, _mm256_mul_ps(sy, rz));
                    let mag = _mm256_max_ps(_mm256_max_ps(abs(rx), abs(ry)), abs(rz));
                    (x, y, mag, _mm256_add_ps(abs(x), abs(y)))
                }
            };
            let (ax, ay, ma, sa) = vertex(0);
            let (bx, by, mb, sb) = vertex(1);
            let (cx, cy, mc, sc) = vertex(2);
            let tol = _mm256_set1_ps(8.0 * f32::EPSILON);
            let bound = {
                #[inline(always)]
                |m1: __m256, m2: __m256, s1: __m256, s2: __m256| {
                    _mm256_mul_ps(
                        _mm256_mul_ps(tol, _mm256_max_ps(m1, m2)),
                        _mm256_add_ps(s1, s2),
                    )
                }
            };
            let b0 = bound(mb, mc, sb, sc);
            let b1 = bound(mc, ma, sc, sa);
            let b2 = bound(ma, mb, sa, sb);
            edge_lanes8_avx2([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2])
        }
    }

    /// The lanes whose edge test passed or needs the re-check, in lane
    /// order (`corners(l)`: lane `l`'s triangle): the nearest hit inside
    /// `(t_min, t_max)`, which shrinks to each hit found.
    #[inline(always)]
    fn finish<const N: usize>(
        &self,
        corners: impl Fn(usize) -> [Vec3A; 3],
        mut lanes: u32,
        e: &[[f32; N]; 3],
        bound: &[[f32; N]; 3],
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(u32, f32, f32, f32)> {
        let mut best = None;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if let Some((t, b1, b2)) = self.finish_lane(corners(l), e, bound, l, t_min, *t_max) {
                *t_max = t;
                best = Some((l as u32, t, b1, b2));
            }
        }
        best
    }

    /// [`Self::finish_one`] for lane `l` of edge functions `e` and bounds
    /// `bound` computed side by side (lanes of triangles or of rays).
    #[inline(always)]
    pub(crate) fn finish_lane<const N: usize>(
        &self,
        p: [Vec3A; 3],
        e: &[[f32; N]; 3],
        bound: &[[f32; N]; 3],
        l: usize,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let uvw = [e[0][l], e[1][l], e[2][l]];
        let b = [bound[0][l], bound[1][l], bound[2][l]];
        self.finish_one(p, uvw, b, t_min, t_max)
    }

    /// [`Self::finish_lane`] for a triangle whose f64 normal `n = (p1 -
    /// p0) x (p2 - p0)` (of its corners converted to f64) was computed
    /// once beforehand: the same bits, without the cross product per lane.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn finish_lane_normal<const N: usize>(
        &self,
        p: [Vec3A; 3],
        n: DVec3,
        e: &[[f32; N]; 3],
        bound: &[[f32; N]; 3],
        l: usize,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let uvw = [e[0][l], e[1][l], e[2][l]];
        let b = [bound[0][l], bound[1][l], bound[2][l]];
        self.finish_one_normal(p, n, uvw, b, t_min, t_max)
    }

    /// The end of the test of one triangle `p` whose edge test passed or
    /// needs the re-check, from its edge functions `uvw` and their
    /// rounding bounds `b`: `(t, b1, b2)` for a hit inside `(t_min,
    /// t_max)`. Shared by the lane-by-lane and the lane-major leaf tests.
    #[inline(always)]
    fn finish_one(
        &self,
        p: [Vec3A; 3],
        uvw: [f32; 3],
        b: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let p0 = p[0].as_dvec3();
        let n = (p[1].as_dvec3() - p0).cross(p[2].as_dvec3() - p0);
        self.finish_one_normal(p, n, uvw, b, t_min, t_max)
    }

    /// [`Self::finish_one`] with the triangle's f64 normal `n = (p1 - p0)
    /// x (p2 - p0)` given ([`Self::plane_t_within`]'s, the same bits).
    #[inline(always)]
    fn finish_one_normal(
        &self,
        p: [Vec3A; 3],
        n: DVec3,
        uvw: [f32; 3],
        b: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let [u, v, w] = uvw;
        if !(u.abs() > b[0] && v.abs() > b[1] && w.abs() > b[2]) {
            return self.intersect_careful(p, uvw, b, t_min, t_max);
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let t = self.plane_t_normal(p[0].as_dvec3(), n, t_min, t_max)?;
        let inv = 1.0 / det;
        Some((t, v * inv, w * inv))
    }
}

/// The part of the eight-triangle test of a leaf (a [`Tri8`] block)
/// that does not depend on the ray's direction, shared by the rays of a
/// packet that start at the same point and have the same axis
/// permutation (the camera rays of a pinhole): each vertex minus the
/// origin along the permuted axes, and the first factor of each edge's
/// rounding bound. [`WatertightRay::intersect8_framed`] then skips those
/// operations and gives the bits [`WatertightRay::intersect8`] gives.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct LeafFrame {
    /// `r[vertex][axis][lane]`: vertex minus origin along `kx`, `ky`, `kz`.
    r: [[[f32; 8]; 3]; 3],
    /// `tm[edge][lane]`: `8 EPS` times the larger coordinate magnitude of
    /// the edge's two vertices (edge `k` joins vertices `k + 1` and `k + 2`).
    tm: [[f32; 8]; 3],
}

impl WatertightRay {
    /// True when `other` starts at the same point (bit for bit) with the
    /// same axis permutation, so that a [`LeafFrame`] made by one serves
    /// the other.
    #[inline(always)]
    pub fn shares_frame(&self, other: &Self) -> bool {
        self.k == other.k
            && self.origin.to_array().map(f32::to_bits) == other.origin.to_array().map(f32::to_bits)
    }

    /// The [`LeafFrame`] of a leaf of `count` triangles stored as two
    /// block, for rays that share this ray's origin and permutation. `AVX`
    /// as in [`Self::intersect8`].
    #[inline(always)]
    pub fn frame8<const AVX: bool>(&self, block: &Tri8, count: u32) -> LeafFrame {
        let mut f = LeafFrame {
            r: [[[0.0; 8]; 3]; 3],
            tm: [[0.0; 8]; 3],
        };
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only by the AVX2 entry points, which run
            // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
            #[allow(unsafe_code)]
            unsafe {
                self.frame8_avx2(block, &mut f)
            };
            return f;
        }
        let [kx, ky, kz] = self.k.map(usize::from);
        let o = [
            Vec4::splat(self.origin[kx]),
            Vec4::splat(self.origin[ky]),
            Vec4::splat(self.origin[kz]),
        ];
        let tol = Vec4::splat(8.0 * f32::EPSILON);
        let halves = if count <= 4 { 1 } else { 2 };
        for h in 0..halves {
            let mut m = [Vec4::ZERO; 3];
            for (vi, mv) in m.iter_mut().enumerate() {
                let r = [
                    block.half(vi, kx, h) - o[0],
                    block.half(vi, ky, h) - o[1],
                    block.half(vi, kz, h) - o[2],
                ];
                for (a, ra) in r.iter().enumerate() {
                    f.r[vi][a][4 * h..4 * h + 4].copy_from_slice(&ra.to_array());
                }
                *mv = max4(max4(r[0].abs(), r[1].abs()), r[2].abs());
            }
            for k in 0..3 {
                let tm = tol * max4(m[(k + 1) % 3], m[(k + 2) % 3]);
                f.tm[k][4 * h..4 * h + 4].copy_from_slice(&tm.to_array());
            }
        }
        f
    }

    /// [`Self::frame8`] in AVX registers.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA; inlined into the AVX2 entry point
    /// as [`Self::edges8_avx2`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn frame8_avx2(&self, block: &Tri8, f: &mut LeafFrame) {
        // SAFETY: the caller runs on a CPU with AVX2 and FMA.
        unsafe {
            use std::arch::x86_64::*;
            let k = self.k.map(usize::from);
            let sign = _mm256_set1_ps(-0.0);
            // (Plain loops: a closure passed to `std::array::from_fn` is not
            // inlined here and would call every intrinsic as a function.)
            let mut m = [_mm256_setzero_ps(); 3];
            for (vi, mv) in m.iter_mut().enumerate() {
                for (a, &ka) in k.iter().enumerate() {
                    let r = _mm256_sub_ps(
                        _mm256_load_ps(block.v[vi][ka].as_ptr()),
                        _mm256_set1_ps(self.origin[ka]),
                    );
                    f.r[vi][a] = bytemuck::cast(r);
                    let abs = _mm256_andnot_ps(sign, r);
                    // max(max(|x|, |y|), |z|), in the order of `edges8_avx2`.
                    *mv = if a == 0 { abs } else { _mm256_max_ps(*mv, abs) };
                }
            }
            let tol = _mm256_set1_ps(8.0 * f32::EPSILON);
            for e in 0..3 {
                let tm = _mm256_mul_ps(tol, _mm256_max_ps(m[(e + 1) % 3], m[(e + 2) % 3]));
                f.tm[e] = bytemuck::cast(tm);
            }
        }
    }

    /// [`Self::intersect8`] with the direction-independent part taken
    /// from `frame`, made by a ray that [`Self::shares_frame`] with this
    /// one for the same `block`: the same result, bit for bit.
    #[inline(always)]
    pub fn intersect8_framed<const AVX: bool>(
        &self,
        frame: &LeafFrame,
        block: &Tri8,
        count: u32,
        t_min: f32,
        mut t_max: f32,
    ) -> Option<(u32, f32, f32, f32)> {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `intersect8`.
            #[allow(unsafe_code)]
            let (lanes, e, bound) = unsafe { self.edges8_framed_avx2(frame) };
            let interesting = lanes & ((1u32 << count) - 1);
            if interesting == 0 {
                return None;
            }
            return self.finish(
                |l| block.corners(l),
                interesting,
                &e,
                &bound,
                t_min,
                &mut t_max,
            );
        }
        let mut e = [[0.0f32; 8]; 3];
        let mut bound = [[0.0f32; 8]; 3];
        let mut lanes = 0;
        let (sx, sy) = (Vec4::splat(self.shear.x), Vec4::splat(self.shear.y));
        for h in 0..if count <= 4 { 1 } else { 2 } {
            let row = |vi: usize, a: usize| Vec4::from_slice(&frame.r[vi][a][4 * h..4 * h + 4]);
            let vertex = |vi: usize| {
                let (rx, ry, rz) = (row(vi, 0), row(vi, 1), row(vi, 2));
                let x = rx - sx * rz;
                let y = ry - sy * rz;
                (x, y, x.abs() + y.abs())
            };
            let (ax, ay, sa) = vertex(0);
            let (bx, by, sb) = vertex(1);
            let (cx, cy, sc) = vertex(2);
            let tm = |k: usize| Vec4::from_slice(&frame.tm[k][4 * h..4 * h + 4]);
            let b0 = tm(0) * (sb + sc);
            let b1 = tm(1) * (sc + sa);
            let b2 = tm(2) * (sa + sb);
            let (l, eh, bh) = edge_lanes4([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2]);
            lanes |= l << (4 * h);
            for k in 0..3 {
                e[k][4 * h..4 * h + 4].copy_from_slice(&eh[k]);
                bound[k][4 * h..4 * h + 4].copy_from_slice(&bh[k]);
            }
        }
        let interesting = lanes & ((1u32 << count) - 1);
        if interesting == 0 {
            return None;
        }
        self.finish(
            |l| block.corners(l),
            interesting,
            &e,
            &bound,
            t_min,
            &mut t_max,
        )
    }

    /// The edge functions and bounds of [`Self::edges8_avx2`] from a
    /// [`LeafFrame`].
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA; inlined into the AVX2 entry point
    /// as [`Self::edges8_avx2`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn edges8_framed_avx2(&self, frame: &LeafFrame) -> (u32, [[f32; 8]; 3], [[f32; 8]; 3]) {
        // SAFETY: the caller runs on a CPU with AVX2 and FMA.
        unsafe {
            use std::arch::x86_64::*;
            let sign = _mm256_set1_ps(-0.0);
            let abs = {
                #[inline(always)]
                |x: __m256| _mm256_andnot_ps(sign, x)
            };
            let sx = _mm256_set1_ps(self.shear.x);
            let sy = _mm256_set1_ps(self.shear.y);
            let vertex = {
                #[inline(always)]
                |vi: usize| {
                    let rx: __m256 = bytemuck::cast(frame.r[vi][0]);
                    let ry: __m256 = bytemuck::cast(frame.r[vi][1]);
                    let rz: __m256 = bytemuck::cast(frame.r[vi][2]);
                    let x = _mm256_sub_ps(rx, _mm256_mul_ps(sx, rz));
                    let y = _mm256_sub_ps(ry, _mm256_mul_ps(sy, rz));
                    (x, y, _mm256_add_ps(abs(x), abs(y)))
                }
            };
            let (ax, ay, sa) = vertex(0);
            let (bx, by, sb) = vertex(1);
            let (cx, cy, sc) = vertex(2);
            let tm = {
                #[inline(always)]
                |k: usize| -> __m256 { bytemuck::cast(frame.tm[k]) }
            };
            let b0 = _mm256_mul_ps(tm(0), _mm256_add_ps(sb, sc));
            let b1 = _mm256_mul_ps(tm(1), _mm256_add_ps(sc, sa));
            let b2 = _mm256_mul_ps(tm(2), _mm256_add_ps(sa, sb));
            edge_lanes8_avx2([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2])
        }
    }
}

/// The shears of up to 16 rays lane by lane, for the lane-major leaf
/// test [`WatertightRay::intersect8_lanes16`].
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Shears16 {
    sx: [f32; 16],
    sy: [f32; 16],
    /// `d[axis][lane]`: the directions, for the hits' distances.
    d: [[f32; 16]; 3],
}

impl Shears16 {
    /// The shears of `rays`.
    #[inline(always)]
    pub fn new(rays: &[WatertightRay; 16]) -> Self {
        let mut s = Shears16 {
            sx: [0.0; 16],
            sy: [0.0; 16],
            d: [[0.0; 16]; 3],
        };
        for (l, r) in rays.iter().enumerate() {
            s.sx[l] = r.shear.x;
            s.sy[l] = r.shear.y;
            for a in 0..3 {
                s.d[a][l] = r.direction[a];
            }
        }
        s
    }
}

impl WatertightRay {
    /// The leaf test of [`Self::intersect8_framed`] for the lanes of
    /// `lanes` at once, triangle by triangle: each of the leaf's `count`
    /// triangles is tested against every lane side by side (16 lanes in
    /// one register on the AVX-512 path), and the lanes whose edge test
    /// passes or needs the re-check finish it one by one. All rays in
    /// `lanes` must [`Self::shares_frame`] with the one that made `frame`.
    ///
    /// Every lane computes exactly the operations of
    /// [`Self::intersect8_framed`] and meets the leaf's triangles in the
    /// same order, a later one winning only when strictly nearer, so the
    /// result is that of testing the lanes one at a time, bit for bit:
    /// for each lane `l` that hits, `t_max[l]` shrinks to the hit and
    /// `out[l]` holds `(triangle, t, b1, b2)`. Returns the lanes that hit.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn intersect8_lanes16<const AVX512: bool>(
        rays: &[WatertightRay; 16],
        shears: &Shears16,
        frame: &LeafFrame,
        block: &Tri8,
        count: u32,
        lanes: u32,
        t_min: &[f32; 16],
        t_max: &mut [f32; 16],
        out: &mut [(u32, f32, f32, f32); 16],
    ) -> u32 {
        let mut found = 0;
        for j in 0..count as usize {
            let r: [[f32; 3]; 3] =
                std::array::from_fn(|vi| std::array::from_fn(|a| frame.r[vi][a][j]));
            let tm = [frame.tm[0][j], frame.tm[1][j], frame.tm[2][j]];
            #[cfg(target_arch = "x86_64")]
            let (pass, e, b) = if AVX512 {
                // SAFETY: `AVX512` is set only by the AVX-512 entry points,
                // which run only on CPUs with AVX-512F (`simd::use_avx512`).
                #[allow(unsafe_code)]
                unsafe {
                    edges_lanes16_avx512(shears, &r, &tm)
                }
            } else {
                edges_lanes16(shears, &r, &tm)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let (pass, e, b) = edges_lanes16(shears, &r, &tm);
            let mut pass = pass & lanes;
            if pass == 0 {
                continue;
            }
            let corners = block.corners(j);
            // Lanes with every edge clear of its bound finish side by side;
            // the others (an edge within rounding) take the careful path.
            let mut clean = 0;
            for l in 0..16 {
                let c =
                    e[0][l].abs() > b[0][l] && e[1][l].abs() > b[1][l] && e[2][l].abs() > b[2][l];
                clean |= (c as u32) << l;
            }
            let clean = clean & pass;
            // (A lane alone finishes faster by itself.)
            let clean = if clean.count_ones() >= 2 { clean } else { 0 };
            pass &= !clean;
            if clean != 0 {
                let lead = clean.trailing_zeros() as usize;
                let (hit, t, b1, b2) =
                    finish_lanes16::<AVX512>(shears, corners, rays[lead].origin, &e, t_min, t_max);
                let mut hit = hit & clean;
                while hit != 0 {
                    let l = hit.trailing_zeros() as usize;
                    hit &= hit - 1;
                    t_max[l] = t[l];
                    out[l] = (j as u32, t[l], b1[l], b2[l]);
                    found |= 1 << l;
                }
            }
            while pass != 0 {
                let l = pass.trailing_zeros() as usize;
                pass &= pass - 1;
                if let Some((t, b1, b2)) =
                    rays[l].finish_lane(corners, &e, &b, l, t_min[l], t_max[l])
                {
                    t_max[l] = t;
                    out[l] = (j as u32, t, b1, b2);
                    found |= 1 << l;
                }
            }
        }
        found
    }
}

/// The end of the test of triangle `p` for 16 lanes that share `origin`
/// and whose edge functions `e` are all clear of their rounding bounds:
/// the operations of [`WatertightRay::finish_one`]'s clean path lane by
/// lane (the plane's normal and its distance from the shared origin are
/// one value for all lanes), so the same bits. Returns the lanes with a
/// hit inside `(t_min, t_max)` and each lane's `t`, `b1`, `b2` (garbage in
/// the others).
#[allow(clippy::type_complexity)]
#[inline(always)]
fn finish_lanes16<const AVX512: bool>(
    shears: &Shears16,
    p: [Vec3A; 3],
    origin: Vec3A,
    e: &[[f32; 16]; 3],
    t_min: &[f32; 16],
    t_max: &[f32; 16],
) -> (u32, [f32; 16], [f32; 16], [f32; 16]) {
    // As `plane_t_within`: the normal and the numerator in f64.
    let p0 = p[0].as_dvec3();
    let n = (p[1].as_dvec3() - p0).cross(p[2].as_dvec3() - p0);
    let num = n.dot(p0 - origin.as_dvec3());
    #[cfg(target_arch = "x86_64")]
    if AVX512 {
        // SAFETY: `AVX512` is set only by the AVX-512 entry points, which
        // run only on CPUs with AVX-512F (`simd::use_avx512`).
        #[allow(unsafe_code)]
        return unsafe { finish_lanes16_avx512(shears, n, num, e, t_min, t_max) };
    }
    let mut hit = 0;
    let mut t = [0.0f32; 16];
    let mut b1 = [0.0f32; 16];
    let mut b2 = [0.0f32; 16];
    for l in 0..16 {
        let [u, v, w] = [e[0][l], e[1][l], e[2][l]];
        let det = u + v + w;
        let d = [shears.d[0][l], shears.d[1][l], shears.d[2][l]];
        let den = n.x * d[0] as f64 + n.y * d[1] as f64 + n.z * d[2] as f64;
        let negative = (num < 0.0 && den > 0.0) || (num > 0.0 && den < 0.0);
        let positive = (num > 0.0 && den > 0.0) || (num < 0.0 && den < 0.0);
        let beyond =
            positive && num.abs() > den.abs() * t_max[l] as f64 * (1.0 + f64::EPSILON * 8.0);
        let tl = (num / den) as f32;
        let ok = det != 0.0
            && det.is_finite()
            && !(negative && t_min[l] >= 0.0)
            && !beyond
            && tl > t_min[l]
            && tl < t_max[l];
        let inv = 1.0 / det;
        hit |= (ok as u32) << l;
        t[l] = tl;
        b1[l] = v * inv;
        b2[l] = w * inv;
    }
    (hit, t, b1, b2)
}

/// [`finish_lanes16`] in AVX-512 registers (the f64 parts eight lanes at
/// a time): the same operations.
///
/// # Safety
/// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::type_complexity)]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn finish_lanes16_avx512(
    shears: &Shears16,
    n: glam::DVec3,
    num: f64,
    e: &[[f32; 16]; 3],
    t_min: &[f32; 16],
    t_max: &[f32; 16],
) -> (u32, [f32; 16], [f32; 16], [f32; 16]) {
    // SAFETY: the caller runs on a CPU with AVX-512F.
    unsafe {
        use std::arch::x86_64::*;
        let ld = |x: &[f32; 16]| -> __m512 { std::mem::transmute(*x) };
        let (u, v, w) = (ld(&e[0]), ld(&e[1]), ld(&e[2]));
        let det = _mm512_add_ps(_mm512_add_ps(u, v), w);
        let zero = _mm512_setzero_ps();
        let mut ok = _mm512_cmp_ps_mask::<_CMP_NEQ_OQ>(det, zero)
            & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_abs_ps(det), _mm512_set1_ps(f32::INFINITY));
        let (tmin, tmax) = (ld(t_min), ld(t_max));
        let numv = _mm512_set1_pd(num);
        let (nx, ny, nz) = (
            _mm512_set1_pd(n.x),
            _mm512_set1_pd(n.y),
            _mm512_set1_pd(n.z),
        );
        let zero_d = _mm512_setzero_pd();
        let scale = _mm512_set1_pd(1.0 + f64::EPSILON * 8.0);
        let num_pos = num > 0.0;
        let num_neg = num < 0.0;
        let mut t = [0.0f32; 16];
        for h in 0..2 {
            let half = |x: __m512| -> __m512d {
                let x: [__m256; 2] = std::mem::transmute(x);
                _mm512_cvtps_pd(x[h])
            };
            let dx = half(ld(&shears.d[0]));
            let dy = half(ld(&shears.d[1]));
            let dz = half(ld(&shears.d[2]));
            let den = _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(nx, dx), _mm512_mul_pd(ny, dy)),
                _mm512_mul_pd(nz, dz),
            );
            let den_pos = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(den, zero_d);
            let den_neg = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(den, zero_d);
            let negative = if num_neg { den_pos } else { 0 } | if num_pos { den_neg } else { 0 };
            let positive = if num_pos { den_pos } else { 0 } | if num_neg { den_neg } else { 0 };
            let ahead = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(tmin, zero) >> (8 * h);
            let far = _mm512_mul_pd(_mm512_mul_pd(_mm512_abs_pd(den), half(tmax)), scale);
            let beyond = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(_mm512_abs_pd(numv), far);
            let reject = (negative & ahead as u8) | (positive & beyond);
            ok &= !((reject as u16) << (8 * h));
            let th = _mm512_cvtpd_ps(_mm512_div_pd(numv, den));
            t[8 * h..8 * h + 8].copy_from_slice(&std::mem::transmute::<__m256, [f32; 8]>(th));
        }
        let tv = ld(&t);
        ok &=
            _mm512_cmp_ps_mask::<_CMP_GT_OQ>(tv, tmin) & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(tv, tmax);
        let inv = _mm512_div_ps(_mm512_set1_ps(1.0), det);
        let b1 = _mm512_mul_ps(v, inv);
        let b2 = _mm512_mul_ps(w, inv);
        (
            ok as u32,
            t,
            std::mem::transmute::<__m512, [f32; 16]>(b1),
            std::mem::transmute::<__m512, [f32; 16]>(b2),
        )
    }
}

/// One triangle, given as its vertices minus the shared origin along the
/// permuted axes (`r[vertex][axis]`) and its bound factors `tm` (as in a
/// [`LeafFrame`]), against 16 rays' shears: the lanes whose edge test
/// passed or needs the re-check, the edge functions and their bounds.
/// The operations of the framed test, lane by lane.
#[inline(always)]
fn edges_lanes16(
    shears: &Shears16,
    r: &[[f32; 3]; 3],
    tm: &[f32; 3],
) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
    let mut e = [[0.0f32; 16]; 3];
    let mut bound = [[0.0f32; 16]; 3];
    let mut lanes = 0;
    for l in 0..16 {
        let (sx, sy) = (shears.sx[l], shears.sy[l]);
        let vertex = |vi: usize| {
            let x = r[vi][0] - sx * r[vi][2];
            let y = r[vi][1] - sy * r[vi][2];
            (x, y, x.abs() + y.abs())
        };
        let (ax, ay, sa) = vertex(0);
        let (bx, by, sb) = vertex(1);
        let (cx, cy, sc) = vertex(2);
        let b = [tm[0] * (sb + sc), tm[1] * (sc + sa), tm[2] * (sa + sb)];
        lanes |= edge_lane([(ax, ay), (bx, by), (cx, cy)], b, l, &mut e, &mut bound);
    }
    (lanes, e, bound)
}

/// One lane of [`edge_lanes4`]: the edge functions `u, v, w` from the
/// sheared vertices `(x, y)`, stored with their rounding bounds `b` in
/// lane `l` of `e` and `bound`; returns lane `l`'s bit when the edge test
/// passed (all signs alike) or needs the re-check (some edge within its
/// bound). The same operations, so the same bits.
#[inline(always)]
fn edge_lane(
    xy: [(f32, f32); 3],
    b: [f32; 3],
    l: usize,
    e: &mut [[f32; 16]; 3],
    bound: &mut [[f32; 16]; 3],
) -> u32 {
    let [(ax, ay), (bx, by), (cx, cy)] = xy;
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let clean = u.abs() > b[0] && v.abs() > b[1] && w.abs() > b[2];
    let negative = u < 0.0 || v < 0.0 || w < 0.0;
    let positive = u > 0.0 || v > 0.0 || w > 0.0;
    for (k, x) in [u, v, w].into_iter().enumerate() {
        e[k][l] = x;
        bound[k][l] = b[k];
    }
    (!(clean && negative && positive) as u32) << l
}

/// [`edges_lanes16`] in 16-wide AVX-512 registers: the same operations.
///
/// # Safety
/// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point (see
/// [`crate::core::simd`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn edges_lanes16_avx512(
    shears: &Shears16,
    r: &[[f32; 3]; 3],
    tm: &[f32; 3],
) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
    // SAFETY: the caller runs on a CPU with AVX-512F.
    unsafe {
        use std::arch::x86_64::*;
        let sx: __m512 = std::mem::transmute(shears.sx);
        let sy: __m512 = std::mem::transmute(shears.sy);
        let abs = {
            #[inline(always)]
            |x: __m512| _mm512_abs_ps(x)
        };
        let vertex = {
            #[inline(always)]
            |vi: usize| {
                let rz = _mm512_set1_ps(r[vi][2]);
                let x = _mm512_sub_ps(_mm512_set1_ps(r[vi][0]), _mm512_mul_ps(sx, rz));
                let y = _mm512_sub_ps(_mm512_set1_ps(r[vi][1]), _mm512_mul_ps(sy, rz));
                (x, y, _mm512_add_ps(abs(x), abs(y)))
            }
        };
        let (ax, ay, sa) = vertex(0);
        let (bx, by, sb) = vertex(1);
        let (cx, cy, sc) = vertex(2);
        let b0 = _mm512_mul_ps(_mm512_set1_ps(tm[0]), _mm512_add_ps(sb, sc));
        let b1 = _mm512_mul_ps(_mm512_set1_ps(tm[1]), _mm512_add_ps(sc, sa));
        let b2 = _mm512_mul_ps(_mm512_set1_ps(tm[2]), _mm512_add_ps(sa, sb));
        edge_lanes16_avx512([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2])
    }
}

/// [`edge_lanes4`] for sixteen lanes in AVX-512 registers: the same
/// operations.
///
/// # Safety
/// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn edge_lanes16_avx512(
    xy: [(std::arch::x86_64::__m512, std::arch::x86_64::__m512); 3],
    b: [std::arch::x86_64::__m512; 3],
) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
    // SAFETY: the caller runs on a CPU with AVX-512F.
    unsafe {
        use std::arch::x86_64::*;
        let [(ax, ay), (bx, by), (cx, cy)] = xy;
        let u = _mm512_sub_ps(_mm512_mul_ps(cx, by), _mm512_mul_ps(cy, bx));
        let v = _mm512_sub_ps(_mm512_mul_ps(ax, cy), _mm512_mul_ps(ay, cx));
        let w = _mm512_sub_ps(_mm512_mul_ps(bx, ay), _mm512_mul_ps(by, ax));
        let gt = {
            #[inline(always)]
            |a: __m512, b: __m512| _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b)
        };
        let lt = {
            #[inline(always)]
            |a: __m512, b: __m512| _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b)
        };
        let clean =
            gt(_mm512_abs_ps(u), b[0]) & gt(_mm512_abs_ps(v), b[1]) & gt(_mm512_abs_ps(w), b[2]);
        let zero = _mm512_setzero_ps();
        let negative = lt(u, zero) | lt(v, zero) | lt(w, zero);
        let positive = gt(u, zero) | gt(v, zero) | gt(w, zero);
        let lanes = (!clean | !(negative & positive)) as u32;
        (
            lanes,
            [u, v, w].map(|x| std::mem::transmute::<__m512, [f32; 16]>(x)),
            b.map(|x| std::mem::transmute::<__m512, [f32; 16]>(x)),
        )
    }
}

/// Up to 16 rays that share one axis permutation (the `k` of their
/// [`WatertightRay`]s), lane by lane: each ray's origin along the permuted
/// axes and its shears. Rays of any origins and directions can test one
/// triangle side by side once their permutation is the same, since the
/// triangle's permuted coordinates are then one value for every lane
/// ([`PermutedLanes16::edges`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct PermutedLanes16 {
    /// `o[axis][lane]`: the origin along `kx`, `ky`, `kz`.
    o: [[f32; 16]; 3],
    sx: [f32; 16],
    sy: [f32; 16],
    /// The permutation shared by every lane.
    k: [u8; 3],
}

impl WatertightRay {
    /// A key for the ray's axis permutation (one of six values below 9):
    /// rays with equal keys can share a [`PermutedLanes16`].
    #[inline(always)]
    pub fn permutation_key(&self) -> usize {
        self.k[0] as usize * 3 + self.k[1] as usize
    }
}

impl PermutedLanes16 {
    /// The lanes of `rays[group[l]]` (`group`: 1 to 16 indices, all of
    /// rays with one [`WatertightRay::permutation_key`]); lanes past
    /// `group.len()` repeat the last ray.
    #[inline(always)]
    pub fn new(rays: &[WatertightRay], group: &[u32]) -> Self {
        debug_assert!(!group.is_empty() && group.len() <= 16);
        let first = &rays[group[0] as usize];
        debug_assert!(group.iter().all(|&i| rays[i as usize].k == first.k));
        let mut s = PermutedLanes16 {
            o: [[0.0; 16]; 3],
            sx: [0.0; 16],
            sy: [0.0; 16],
            k: first.k,
        };
        for l in 0..16 {
            let r = &rays[group[l.min(group.len() - 1)] as usize];
            for a in 0..3 {
                s.o[a][l] = r.o_k[a];
            }
            s.sx[l] = r.shear.x;
            s.sy[l] = r.shear.y;
        }
        s
    }

    /// Triangle `j` of `block` against all 16 lanes: the lanes whose edge
    /// test passed or needs the re-check, with the edge functions and
    /// their rounding bounds, lane by lane exactly the operations of
    /// [`WatertightRay::intersect8`] (so the same bits; the caller
    /// finishes those lanes with `WatertightRay::finish_lane`). With
    /// `AVX512` (only inside an AVX-512 entry point, see
    /// [`crate::core::simd`]) in 16-wide registers; otherwise plain loops
    /// over the lanes, which the AVX2 entry points compile to 8-wide ones.
    #[inline(always)]
    pub fn edges<const AVX512: bool>(
        &self,
        block: &Tri8,
        j: usize,
    ) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
        let [kx, ky, kz] = self.k.map(usize::from);
        let p: [[f32; 3]; 3] =
            std::array::from_fn(|vi| [block.v[vi][kx][j], block.v[vi][ky][j], block.v[vi][kz][j]]);
        #[cfg(target_arch = "x86_64")]
        if AVX512 {
            // SAFETY: `AVX512` is set only by the AVX-512 entry points,
            // which run only on CPUs with AVX-512F (`simd::use_avx512`).
            #[allow(unsafe_code)]
            return unsafe { self.edges_avx512(&p) };
        }
        self.edges_lanes(&p)
    }

    /// [`Self::edges`] as plain loops over the lanes.
    #[inline(always)]
    fn edges_lanes(&self, p: &[[f32; 3]; 3]) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
        // `maxps`: the second operand unless the first is greater, as
        // `max4` and the AVX maxima of the leaf tests.
        #[inline(always)]
        fn max(a: f32, b: f32) -> f32 {
            if a > b { a } else { b }
        }
        let tol = 8.0 * f32::EPSILON;
        let mut e = [[0.0f32; 16]; 3];
        let mut bound = [[0.0f32; 16]; 3];
        let mut lanes = 0;
        for l in 0..16 {
            let (sx, sy) = (self.sx[l], self.sy[l]);
            let (ox, oy, oz) = (self.o[0][l], self.o[1][l], self.o[2][l]);
            let vertex = |vi: usize| {
                let rx = p[vi][0] - ox;
                let ry = p[vi][1] - oy;
                let rz = p[vi][2] - oz;
                let x = rx - sx * rz;
                let y = ry - sy * rz;
                let mag = max(max(rx.abs(), ry.abs()), rz.abs());
                (x, y, mag, x.abs() + y.abs())
            };
            let (ax, ay, ma, sa) = vertex(0);
            let (bx, by, mb, sb) = vertex(1);
            let (cx, cy, mc, sc) = vertex(2);
            let b = [
                tol * max(mb, mc) * (sb + sc),
                tol * max(mc, ma) * (sc + sa),
                tol * max(ma, mb) * (sa + sb),
            ];
            lanes |= edge_lane([(ax, ay), (bx, by), (cx, cy)], b, l, &mut e, &mut bound);
        }
        (lanes, e, bound)
    }

    /// [`Self::edges`] in 16-wide AVX-512 registers: the same operations.
    ///
    /// # Safety
    /// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn edges_avx512(&self, p: &[[f32; 3]; 3]) -> (u32, [[f32; 16]; 3], [[f32; 16]; 3]) {
        // SAFETY: the caller runs on a CPU with AVX-512F.
        unsafe {
            use std::arch::x86_64::*;
            let load = {
                #[inline(always)]
                |x: &[f32; 16]| _mm512_load_ps(x.as_ptr())
            };
            let (ox, oy, oz) = (load(&self.o[0]), load(&self.o[1]), load(&self.o[2]));
            let (sx, sy) = (load(&self.sx), load(&self.sy));
            let abs = {
                #[inline(always)]
                |x: __m512| _mm512_abs_ps(x)
            };
            let vertex = {
                #[inline(always)]
                |vi: usize| {
                    let rx = _mm512_sub_ps(_mm512_set1_ps(p[vi][0]), ox);
                    let ry = _mm512_sub_ps(_mm512_set1_ps(p[vi][1]), oy);
                    let rz = _mm512_sub_ps(_mm512_set1_ps(p[vi][2]), oz);
                    let x = _mm512_sub_ps(rx, _mm512_mul_ps(sx, rz));
                    let y = _mm512_sub_ps(ry, _mm512_mul_ps(sy, rz));
                    let mag = _mm512_max_ps(_mm512_max_ps(abs(rx), abs(ry)), abs(rz));
                    (x, y, mag, _mm512_add_ps(abs(x), abs(y)))
                }
            };
            let (ax, ay, ma, sa) = vertex(0);
            let (bx, by, mb, sb) = vertex(1);
            let (cx, cy, mc, sc) = vertex(2);
            let tol = _mm512_set1_ps(8.0 * f32::EPSILON);
            let bound = {
                #[inline(always)]
                |m1: __m512, m2: __m512, s1: __m512, s2: __m512| {
                    _mm512_mul_ps(
                        _mm512_mul_ps(tol, _mm512_max_ps(m1, m2)),
                        _mm512_add_ps(s1, s2),
                    )
                }
            };
            let b0 = bound(mb, mc, sb, sc);
            let b1 = bound(mc, ma, sc, sa);
            let b2 = bound(ma, mb, sa, sb);
            edge_lanes16_avx512([(ax, ay), (bx, by), (cx, cy)], [b0, b1, b2])
        }
    }
}

/// The edge functions `u, v, w` of four triangles from their sheared
/// vertices `(x, y)`, given their rounding bounds: the lanes whose edge
/// test passed (all signs alike) or needs the re-check (some edge within
/// its bound), with the edge functions and the bounds as arrays. Shared by
/// the per-ray and the framed tests: the same operations, so the same bits.
#[inline(always)]
fn edge_lanes4(xy: [(Vec4, Vec4); 3], b: [Vec4; 3]) -> (u32, [[f32; 4]; 3], [[f32; 4]; 3]) {
    let [(ax, ay), (bx, by), (cx, cy)] = xy;
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let clean = u.abs().cmpgt(b[0]) & v.abs().cmpgt(b[1]) & w.abs().cmpgt(b[2]);
    let zero = Vec4::ZERO;
    let negative = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
    let positive = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
    let lanes = (!clean | !(negative & positive)).bitmask();
    (
        lanes,
        [u.to_array(), v.to_array(), w.to_array()],
        b.map(|x| x.to_array()),
    )
}

/// [`edge_lanes4`] for eight lanes in AVX registers.
///
/// # Safety
/// Only on a CPU with AVX2 and FMA; `#[inline(always)]` without a
/// `#[target_feature]`, inlined into the AVX2 entry point with its
/// intrinsics (see [`crate::core::simd`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn edge_lanes8_avx2(
    xy: [(std::arch::x86_64::__m256, std::arch::x86_64::__m256); 3],
    b: [std::arch::x86_64::__m256; 3],
) -> (u32, [[f32; 8]; 3], [[f32; 8]; 3]) {
    // SAFETY: the caller runs on a CPU with AVX2 and FMA.
    unsafe {
        use std::arch::x86_64::*;
        let [(ax, ay), (bx, by), (cx, cy)] = xy;
        let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
        let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
        let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
        let abs = {
            #[inline(always)]
            |x: __m256| _mm256_andnot_ps(_mm256_set1_ps(-0.0), x)
        };
        let gt = {
            #[inline(always)]
            |a: __m256, b: __m256| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(a, b)) as u32
        };
        let lt = {
            #[inline(always)]
            |a: __m256, b: __m256| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(a, b)) as u32
        };
        let clean = gt(abs(u), b[0]) & gt(abs(v), b[1]) & gt(abs(w), b[2]);
        let zero = _mm256_setzero_ps();
        let negative = lt(u, zero) | lt(v, zero) | lt(w, zero);
        let positive = gt(u, zero) | gt(v, zero) | gt(w, zero);
        let lanes = (!clean | !(negative & positive)) & 0xff;
        (
            lanes,
            [bytemuck::cast(u), bytemuck::cast(v), bytemuck::cast(w)],
            [
                bytemuck::cast(b[0]),
                bytemuck::cast(b[1]),
                bytemuck::cast(b[2]),
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers in `[-1, 1)` from a 64-bit LCG seeded with `seed`: each
    /// test's own repeatable stream.
    fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        }
    }

    /// [`WatertightRay::lanes`] prepares every lane as
    /// [`WatertightRay::new`] does, bit for bit: random directions, and
    /// directions whose components tie in magnitude (every pair, with
    /// either sign), have signed zeros, or point along an axis, in packets
    /// of 8 and 16.
    #[test]
    fn packet_lanes_are_new_rays_bit_for_bit() {
        let mut next = uniform(77);
        let specials = [0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0];
        let mut rays = Vec::new();
        for i in 0..4096 {
            let o = Vec3A::new(next() * 9.0, next() * 9.0, next() * 9.0);
            let d = match i % 4 {
                0 => Vec3A::new(next(), next(), next()),
                1 => {
                    // Ties: two or three components of equal magnitude.
                    let m = next();
                    let sign = |k: usize| if (i >> k) & 1 == 1 { -1.0 } else { 1.0 };
                    match (i / 4) % 4 {
                        0 => Vec3A::new(m * sign(3), m * sign(4), next()),
                        1 => Vec3A::new(m * sign(3), next(), m * sign(5)),
                        2 => Vec3A::new(next(), m * sign(4), m * sign(5)),
                        _ => Vec3A::new(m * sign(3), m * sign(4), m * sign(5)),
                    }
                }
                _ => Vec3A::new(
                    specials[(i / 4) % 6],
                    specials[(i / 24) % 6],
                    specials[(i / 144) % 6],
                ),
            };
            if d.abs().max_element() > 0.0 {
                rays.push(Ray::new(o, d));
            }
        }
        let bits = |w: &WatertightRay| format!("{w:?}");
        let mut checked = 0;
        for chunk in rays.chunks_exact(16) {
            let packet: [Ray; 16] = std::array::from_fn(|l| chunk[l]);
            for (l, w) in WatertightRay::lanes(&packet).iter().enumerate() {
                assert_eq!(bits(w), bits(&WatertightRay::new(&packet[l])), "lane {l}");
                checked += 1;
            }
            let eight: [Ray; 8] = std::array::from_fn(|l| chunk[8 + l]);
            for (l, w) in WatertightRay::lanes(&eight).iter().enumerate() {
                assert_eq!(
                    bits(w),
                    bits(&WatertightRay::new(&eight[l])),
                    "lane {l} of 8"
                );
            }
        }
        assert!(checked > 3500, "{checked}");
    }

    /// The plane distance's tests without division decide exactly as
    /// dividing and comparing: random triangles and rays (origins near
    /// the plane on either side, directions nearly in it), with interval
    /// ends at the distance itself, one ulp either side, zeros of both
    /// signs, negative, tiny and infinite values.
    #[test]
    fn plane_distance_decides_as_the_division() {
        let mut next = uniform(5);
        let (mut early, mut divided) = (0, 0);
        for k in 0..4000 {
            let tri: [Vec3A; 3] = std::array::from_fn(|_| Vec3A::new(next(), next(), next()) * 3.0);
            let normal = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
            let on = tri[0] + (tri[1] - tri[0]) * next().abs() * 0.5;
            // Origins at distances from 1e-6 to 10 off the plane, either side.
            let off = next() * 10f32.powi(-(k % 7));
            let o = on + normal * off + Vec3A::new(next(), next(), next()) * 0.1;
            let mut d = Vec3A::new(next(), next(), next());
            if k % 5 == 0 {
                // Nearly in the plane.
                d = (tri[2] - tri[1]) + normal * next() * 1e-4;
            }
            if d == Vec3A::ZERO {
                continue;
            }
            let wt = WatertightRay::new(&Ray::new(o, d));
            let p0 = tri[0].as_dvec3();
            let n = (tri[1].as_dvec3() - p0).cross(tri[2].as_dvec3() - p0);
            let t = (n.dot(p0 - o.as_dvec3()) / n.dot(d.as_dvec3())) as f32;
            let ends = [
                t,
                t.next_up(),
                t.next_down(),
                -t,
                0.0,
                -0.0,
                -1.0,
                1.0,
                1e-30,
                f32::INFINITY,
                f32::NEG_INFINITY,
            ];
            for &lo in &ends {
                for &hi in &ends {
                    let want = (t > lo && t < hi).then_some(t.to_bits());
                    let got = wt.plane_t_within(tri[0], tri[1], tri[2], lo, hi);
                    assert_eq!(
                        got.map(f32::to_bits),
                        want,
                        "case {k}: t {t:e} in ({lo:e}, {hi:e})"
                    );
                    if want.is_none() {
                        // Whether the division was needed to reject.
                        let q_negative = t < 0.0 || (t == 0.0 && t.is_sign_negative());
                        if (q_negative && lo >= 0.0) || t > hi {
                            early += 1;
                        } else {
                            divided += 1;
                        }
                    }
                }
            }
        }
        assert!(early > 10_000 && divided > 10_000, "{early} / {divided}");
    }

    /// Four (and eight) triangles side by side give, lane by lane, bit
    /// for bit what the one-triangle test gives, and the nearest of them,
    /// as testing them in order would, on both code paths: random
    /// triangles, rays through their corners and edges (the re-check
    /// path), rays in their planes, and a triangle repeated in both
    /// halves of a leaf (equal `t`: the first lane wins).
    #[test]
    fn side_by_side_lanes_equal_one_at_a_time() {
        let avx2 = crate::core::simd::supported(crate::core::simd::Isa::Avx2);
        let mut next = uniform(11);
        let mut hits = 0;
        for k in 0..8000 {
            let mut tris: Vec<[Vec3A; 3]> = Vec::new();
            let base = Vec3A::new(next(), next(), next());
            for _ in 0..8 {
                let p0 = base + Vec3A::new(next(), next(), next()) * 0.5;
                // Neighbours share an edge now and then.
                let p1 = if k % 5 == 0 && !tris.is_empty() {
                    tris.last().unwrap()[1]
                } else {
                    base + Vec3A::new(next(), next(), next()) * 0.5
                };
                let p2 = base + Vec3A::new(next(), next(), next()) * 0.5;
                tris.push([p0, p1, p2]);
            }
            let count = 1 + k % 8;
            if k % 7 == 0 {
                tris[5] = tris[1];
            }
            let aim = &tris[(k / 8) % count];
            let target = match k % 3 {
                0 => aim[1],
                1 => (aim[0] + aim[1]) * 0.5,
                _ => base,
            };
            let o = Vec3A::new(next(), next(), next()) * 4.0;
            let mut d = target - o;
            if k % 17 == 0 {
                // In the plane of triangle 0.
                d = tris[0][1] - tris[0][0];
            }
            let ray = Ray::new(o, d);
            let wt = WatertightRay::new(&ray);
            let mut t_max = f32::INFINITY;
            let mut want = None;
            for (l, t) in tris[..count].iter().enumerate() {
                if let Some((t, b1, b2)) = wt.intersect(t[0], t[1], t[2], 0.0, t_max) {
                    t_max = t;
                    want = Some((l as u32, t.to_bits(), b1.to_bits(), b2.to_bits()));
                }
            }
            let bits = |h: Option<(u32, f32, f32, f32)>| {
                h.map(|(l, t, b1, b2)| (l, t.to_bits(), b1.to_bits(), b2.to_bits()))
            };
            let block = Tri8::new(&tris[..count], 0);
            if count <= 4 {
                let got = bits(wt.intersect4(&block, count as u32, 0.0, f32::INFINITY));
                assert_eq!(got, want, "case {k}, four wide");
            }
            let pair = &block;
            let got = bits(wt.intersect8::<false>(pair, count as u32, 0.0, f32::INFINITY));
            assert_eq!(got, want, "case {k}, portable");
            if avx2 {
                let got = bits(wt.intersect8::<true>(pair, count as u32, 0.0, f32::INFINITY));
                assert_eq!(got, want, "case {k}, avx2");
            }
            hits += want.is_some() as u32;
        }
        assert!(hits > 2000, "only {hits} hits");
    }

    /// A leaf's [`LeafFrame`], made by one ray of a packet, gives every
    /// ray that shares it what the eight-triangle test gives, bit for bit
    /// (the same triangle, `t` and barycentrics), on both code paths; rays
    /// with another permutation or origin do not share it. Random leaves,
    /// packets of rays from one origin fanned around the diagonal between
    /// two axes (so their dominant axis or its sign differs from lane to
    /// lane), aimed at corners, edges and a point inside (the re-check
    /// path), some lanes moved to another origin, finite and infinite
    /// interval ends.
    #[test]
    fn framed_lanes_equal_the_eight_triangle_test() {
        let avx2 = crate::core::simd::supported(crate::core::simd::Isa::Avx2);
        let mut next = uniform(5);
        let bits = |h: Option<(u32, f32, f32, f32)>| {
            h.map(|(l, t, b1, b2)| (l, t.to_bits(), b1.to_bits(), b2.to_bits()))
        };
        let (mut framed, mut apart, mut hits) = (0, 0, 0);
        for k in 0..3000 {
            let base = Vec3A::new(next(), next(), next());
            let mut tris: Vec<[Vec3A; 3]> = Vec::new();
            for _ in 0..8 {
                let p = |n: &mut dyn FnMut() -> f32| base + Vec3A::new(n(), n(), n()) * 0.5;
                let p0 = p(&mut next);
                // Neighbours share an edge now and then.
                let p1 = match tris.last() {
                    Some(t) if k % 3 == 0 => t[2],
                    _ => p(&mut next),
                };
                let p2 = p(&mut next);
                tris.push([p0, p1, p2]);
            }
            let count = 1 + k % 8;
            let block = Tri8::new(&tris[..count], 0);
            let blocks = &block;
            // The fan: around the diagonal between axis `a` and the next,
            // on the side `sign`, from a distance.
            let a = k % 3;
            let mut axis = Vec3A::ZERO;
            axis[a] = 1.0;
            axis[(a + 1) % 3] = if k % 2 == 0 { 1.0 } else { -1.0 };
            let o =
                base - axis * (2.0 + 2.0 * next().abs()) + Vec3A::new(next(), next(), next()) * 0.2;
            let t_max = if k % 4 == 0 {
                1.0 + 3.0 * next().abs()
            } else {
                f32::INFINITY
            };
            let rays: Vec<WatertightRay> = (0..8)
                .map(|l| {
                    let aim = &tris[(k + l) % count];
                    let target = match l % 3 {
                        0 => aim[(k / 3) % 3],
                        1 => (aim[0] + aim[1]) * 0.5,
                        _ => (aim[0] + aim[1] + aim[2]) / 3.0,
                    };
                    let origin = if k % 5 == 0 && l == 3 {
                        o + Vec3A::X * 1e-3
                    } else {
                        o
                    };
                    WatertightRay::new(&Ray::new(origin, target - origin))
                })
                .collect();
            let lead = (k / 8) % 8;
            let frames = [
                rays[lead].frame8::<false>(blocks, count as u32),
                if avx2 {
                    rays[lead].frame8::<true>(blocks, count as u32)
                } else {
                    rays[lead].frame8::<false>(blocks, count as u32)
                },
            ];
            for (l, wt) in rays.iter().enumerate() {
                let same = wt.k == rays[lead].k && wt.origin == rays[lead].origin;
                assert_eq!(wt.shares_frame(&rays[lead]), same, "case {k} lane {l}");
                if !same {
                    apart += 1;
                    continue;
                }
                framed += 1;
                // One triangle at a time, as the eight-triangle test must.
                let mut reach = t_max;
                let mut want = None;
                for (i, t) in tris[..count].iter().enumerate() {
                    if let Some((t, b1, b2)) = wt.intersect(t[0], t[1], t[2], 0.0, reach) {
                        reach = t;
                        want = Some((i as u32, t.to_bits(), b1.to_bits(), b2.to_bits()));
                    }
                }
                hits += want.is_some() as u32;
                let got = bits(wt.intersect8_framed::<false>(
                    &frames[0],
                    blocks,
                    count as u32,
                    0.0,
                    t_max,
                ));
                assert_eq!(got, want, "case {k} lane {l}, portable");
                if avx2 {
                    let got = bits(wt.intersect8_framed::<true>(
                        &frames[1],
                        blocks,
                        count as u32,
                        0.0,
                        t_max,
                    ));
                    assert_eq!(got, want, "case {k} lane {l}, avx2");
                }
            }
        }
        assert!(
            framed > 10_000 && apart > 2000 && hits > 5000,
            "{framed} lanes framed, {apart} apart, {hits} hits"
        );
    }
}
