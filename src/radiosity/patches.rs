//! Patches: the scene's polygons and mesh triangles cut into small
//! triangles that each carry one radiosity.
//!
//! Every polygon (split into a fan) and every mesh triangle of the scene
//! is a *base triangle* in the render frame. Each side of a base triangle
//! that can see anything is a *surface* with its own tree of elements:
//! the root is the base triangle, and an element splits into four at its
//! edge midpoints (corner children `a`, `b`, `c` and the inverted centre
//! child). The leaves are the patches.
//!
//! * **Patch size.** Elements are split until their area is at most half
//!   the square of the patch size (the halves of a square of side `s`
//!   are split until their legs are at most `s`). All fan triangles of
//!   one polygon are split to the same depth, so their patches meet
//!   vertex to vertex across the fan's diagonals.
//! * **Adaptive subdivision.** After a solve, a patch whose radiosity
//!   differs from the Gouraud value at one of its corners by more than a
//!   threshold (relative to the scene's mean radiosity) is split again:
//!   this is where radiosity changes fast, at shadow boundaries and in
//!   corners.
//! * **Lookup.** A point given by its base triangle, side and barycentric
//!   coordinates descends the tree to its patch, with the point's
//!   coordinates in that patch for Gouraud interpolation.
//!
//! The back side of a base triangle becomes a surface only when part of
//! the scene's bounding box lies behind its plane (the outside of a
//! closed room's walls does not).

use std::collections::HashMap;

use glam::Vec3A;

use crate::core::math::{Color, luminance};

/// A triangle of the scene in the render frame.
#[derive(Clone, Copy, Debug)]
pub struct BaseTriangle {
    /// Corners, in the order of the mesh or polygon fan.
    pub corners: [Vec3A; 3],
    /// Unit normal by winding (the polygon's normal).
    pub normal: Vec3A,
    /// Instance it belongs to.
    pub instance: u32,
    /// Material index.
    pub material: u32,
    /// Surface of the front (normal) side and of the back side, if any.
    pub surfaces: [Option<u32>; 2],
}

/// One node of a surface's element tree.
#[derive(Clone, Copy, Debug)]
pub struct Element {
    /// Corners in the base triangle's order (children are laid out so that
    /// barycentric coordinates map without flips, see [`child_coordinates`]).
    pub corners: [Vec3A; 3],
    /// First of four children, or `u32::MAX` for a leaf.
    pub children: u32,
    /// Patch index when a leaf.
    pub patch: u32,
}

/// A side of a base triangle with its element tree.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    /// Base triangle.
    pub base: u32,
    /// 0 for the front side, 1 for the back.
    pub side: u8,
    /// Root element.
    pub root: u32,
    /// Unit normal of this side.
    pub normal: Vec3A,
    /// Diffuse reflectance.
    pub reflectance: Color,
    /// Emitted radiant exitance (pi times the emitted radiance).
    pub exitance: Color,
}

/// The patches of a scene: per patch its element, surface, area, normal
/// and centroid, in one structure-of-arrays.
#[derive(Clone, Debug, Default)]
pub struct Patches {
    /// Base triangles.
    pub bases: Vec<BaseTriangle>,
    /// Surfaces (sides of base triangles).
    pub surfaces: Vec<Surface>,
    /// Element trees of all surfaces.
    pub elements: Vec<Element>,
    /// Element of each patch.
    pub element: Vec<u32>,
    /// Surface of each patch.
    pub surface: Vec<u32>,
    /// Area of each patch.
    pub area: Vec<f32>,
}

/// Midpoint of two points (commutative bit for bit, so neighbouring
/// elements share their edge midpoints exactly).
#[inline]
fn mid(a: Vec3A, b: Vec3A) -> Vec3A {
    (a + b) * 0.5
}

/// The four children of triangle `[a, b, c]` at its edge midpoints.
pub fn split_corners([a, b, c]: [Vec3A; 3]) -> [[Vec3A; 3]; 4] {
    let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [bc, ca, ab]]
}

/// Which child of a split element holds the point with coordinates
/// `(u, v)` (weights of the second and third corner), and its
/// coordinates in that child.
#[inline]
pub fn child_coordinates(u: f32, v: f32) -> (usize, f32, f32) {
    if u >= 0.5 {
        (1, 2.0 * u - 1.0, 2.0 * v)
    } else if v >= 0.5 {
        (2, 2.0 * u, 2.0 * v - 1.0)
    } else if u + v <= 0.5 {
        (0, 2.0 * u, 2.0 * v)
    } else {
        (3, 1.0 - 2.0 * u, 1.0 - 2.0 * v)
    }
}

/// Area of a triangle.
#[inline]
pub fn triangle_area([a, b, c]: &[Vec3A; 3]) -> f32 {
    0.5 * (b - a).cross(c - a).length()
}

/// Centroid of a triangle.
#[inline]
pub fn centroid([a, b, c]: &[Vec3A; 3]) -> Vec3A {
    (a + b + c) * (1.0 / 3.0)
}

/// Number of splits needed to bring `area` down to `max_area`.
fn depth_for(area: f32, max_area: f32) -> u32 {
    let mut d = 0;
    let mut a = area;
    while a > max_area && d < 16 {
        a *= 0.25;
        d += 1;
    }
    d
}

impl Patches {
    /// Builds the surfaces of `bases` (filling in their `surfaces`) and
    /// splits each to the depth its group asks for: `depth[g]` for base
    /// triangles of group `group[i]` (one group per polygon; one per mesh
    /// triangle). `shading[i]` is base triangle `i`'s diffuse reflectance
    /// and emitted exitance; `bounds` is the scene's bounding box.
    /// Fails when more than `max_patches` patches would be made.
    pub fn build(
        mut bases: Vec<BaseTriangle>,
        group: &[u32],
        patch_size: f32,
        bounds: (Vec3A, Vec3A),
        shading: &[(Color, Color)],
        max_patches: usize,
    ) -> Result<Self, String> {
        let max_area = 0.5 * patch_size * patch_size;
        let groups = group.iter().copied().max().map_or(0, |g| g as usize + 1);
        let mut depth = vec![0u32; groups];
        for (b, &g) in bases.iter().zip(group) {
            let d = depth_for(triangle_area(&b.corners), max_area);
            depth[g as usize] = depth[g as usize].max(d);
        }
        let (lo, hi) = bounds;
        let extent = (hi - lo).max_element().max(f32::MIN_POSITIVE);
        let mut out = Patches::default();
        let mut count = 0usize;
        for (i, b) in bases.iter_mut().enumerate() {
            let (rho, exitance) = shading[i];
            for side in 0..2u8 {
                let normal = if side == 0 { b.normal } else { -b.normal };
                // A side sees something only if part of the scene's box is
                // in front of it.
                let p = b.corners[0];
                let sees = (0..8).any(|k| {
                    let c = Vec3A::new(
                        if k & 1 == 0 { lo.x } else { hi.x },
                        if k & 2 == 0 { lo.y } else { hi.y },
                        if k & 4 == 0 { lo.z } else { hi.z },
                    );
                    normal.dot(c - p) > 1e-4 * extent
                });
                if !sees {
                    continue;
                }
                let d = depth[group[i] as usize];
                count += 1usize << (2 * d);
                if count > max_patches {
                    return Err(format!(
                        "the scene would need more than {max_patches} radiosity patches at patch size {patch_size}: \
                         raise the patch size (--patch-size) or the limit (--max-patches)"
                    ));
                }
                let root = out.elements.len() as u32;
                out.elements.push(Element {
                    corners: b.corners,
                    children: u32::MAX,
                    patch: u32::MAX,
                });
                let s = out.surfaces.len() as u32;
                out.surfaces.push(Surface {
                    base: i as u32,
                    side,
                    root,
                    normal,
                    reflectance: rho,
                    exitance,
                });
                b.surfaces[side as usize] = Some(s);
                out.split_to_depth(root, d);
            }
        }
        out.bases = bases;
        out.collect_leaves();
        Ok(out)
    }

    /// Splits element `e` into four.
    fn split(&mut self, e: u32) {
        let first = self.elements.len() as u32;
        for corners in split_corners(self.elements[e as usize].corners) {
            self.elements.push(Element {
                corners,
                children: u32::MAX,
                patch: u32::MAX,
            });
        }
        self.elements[e as usize].children = first;
    }

    fn split_to_depth(&mut self, e: u32, depth: u32) {
        if depth == 0 {
            return;
        }
        self.split(e);
        let first = self.elements[e as usize].children;
        for k in 0..4 {
            self.split_to_depth(first + k, depth - 1);
        }
    }

    /// Numbers the leaves of every surface, depth first, surface by
    /// surface (a deterministic order).
    fn collect_leaves(&mut self) {
        self.element.clear();
        self.surface.clear();
        self.area.clear();
        for s in 0..self.surfaces.len() {
            let mut stack = vec![self.surfaces[s].root];
            while let Some(e) = stack.pop() {
                let el = self.elements[e as usize];
                if el.children == u32::MAX {
                    let p = self.element.len() as u32;
                    self.elements[e as usize].patch = p;
                    self.element.push(e);
                    self.surface.push(s as u32);
                    self.area.push(triangle_area(&el.corners));
                } else {
                    for k in (0..4).rev() {
                        stack.push(el.children + k);
                    }
                }
            }
        }
    }

    /// Number of patches.
    pub fn len(&self) -> usize {
        self.element.len()
    }

    /// True when there are no patches.
    pub fn is_empty(&self) -> bool {
        self.element.is_empty()
    }

    /// Corners of patch `p`.
    #[inline]
    pub fn corners(&self, p: usize) -> [Vec3A; 3] {
        self.elements[self.element[p] as usize].corners
    }

    /// Unit normal of patch `p`'s side.
    #[inline]
    pub fn normal(&self, p: usize) -> Vec3A {
        self.surfaces[self.surface[p] as usize].normal
    }

    /// Diffuse reflectance of patch `p`.
    #[inline]
    pub fn reflectance(&self, p: usize) -> Color {
        self.surfaces[self.surface[p] as usize].reflectance
    }

    /// Emitted exitance of patch `p`.
    #[inline]
    pub fn exitance(&self, p: usize) -> Color {
        self.surfaces[self.surface[p] as usize].exitance
    }

    /// The patch holding the point of base triangle `base` with
    /// barycentric coordinates `(u, v)` on side `side`, and the point's
    /// coordinates in it; `None` when that side is not a surface.
    pub fn locate(&self, base: u32, side: usize, u: f32, v: f32) -> Option<(u32, f32, f32)> {
        let s = self.bases.get(base as usize)?.surfaces[side]?;
        let mut e = self.surfaces[s as usize].root;
        let (mut u, mut v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
        loop {
            let el = &self.elements[e as usize];
            if el.children == u32::MAX {
                return Some((el.patch, u, v));
            }
            let (k, cu, cv) = child_coordinates(u, v);
            e = el.children + k as u32;
            u = cu;
            v = cv;
        }
    }

    /// Radiosity at each patch's three corners: the area-weighted mean of
    /// the patches of the same instance that share the corner point and
    /// face nearly the same way (normals within about 25 degrees), as
    /// Gouraud shading interpolates it.
    pub fn corner_values(&self, b: &[Color]) -> Vec<[Color; 3]> {
        // (instance, side, corner bits) -> patches touching it.
        let mut touching: HashMap<(u32, [u32; 3]), Vec<u32>> = HashMap::new();
        for p in 0..self.len() {
            let inst = self.bases[self.surfaces[self.surface[p] as usize].base as usize].instance;
            for c in self.corners(p) {
                touching
                    .entry((inst, c.to_array().map(f32::to_bits)))
                    .or_default()
                    .push(p as u32);
            }
        }
        (0..self.len())
            .map(|p| {
                let inst =
                    self.bases[self.surfaces[self.surface[p] as usize].base as usize].instance;
                let n = self.normal(p);
                self.corners(p).map(|c| {
                    let list = &touching[&(inst, c.to_array().map(f32::to_bits))];
                    let (mut sum, mut w) = (Color::ZERO, 0.0f32);
                    for &q in list {
                        let q = q as usize;
                        if self.normal(q).dot(n) > 0.9 {
                            sum += b[q] * self.area[q];
                            w += self.area[q];
                        }
                    }
                    if w > 0.0 { sum / w } else { b[p] }
                })
            })
            .collect()
    }

    /// Splits the patches whose radiosity differs from one of their
    /// corner values by more than `threshold` times the area-weighted
    /// mean radiosity (luminance), without going over `max_patches`
    /// patches. Returns how many were split.
    pub fn refine(&mut self, b: &[Color], threshold: f32, max_patches: usize) -> usize {
        let corners = self.corner_values(b);
        let total_area: f64 = self.area.iter().map(|&a| a as f64).sum();
        let mean = self
            .area
            .iter()
            .zip(b)
            .map(|(&a, &c)| a as f64 * luminance(c) as f64)
            .sum::<f64>()
            / total_area.max(f64::MIN_POSITIVE);
        let limit = threshold as f64 * mean;
        let mut split = 0;
        let mut count = self.len();
        for p in 0..self.len() {
            let own = luminance(b[p]) as f64;
            let worst = corners[p]
                .iter()
                .map(|&c| (luminance(c) as f64 - own).abs())
                .fold(0.0, f64::max);
            if worst > limit && count + 3 <= max_patches {
                let e = self.element[p];
                self.split(e);
                count += 3;
                split += 1;
            }
        }
        if split > 0 {
            self.collect_leaves();
        }
        split
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn child_coordinates_map_points_into_the_child_that_holds_them() {
        let t = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(2.0, 0.0, 0.0),
            Vec3A::new(0.0, 3.0, 1.0),
        ];
        let kids = split_corners(t);
        for i in 0..=20 {
            for j in 0..=(20 - i) {
                let (u, v) = (i as f32 / 20.0, j as f32 / 20.0);
                let p = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                let (k, cu, cv) = child_coordinates(u, v);
                assert!(
                    (0.0..=1.0).contains(&cu) && (0.0..=1.0).contains(&cv) && cu + cv <= 1.0 + 1e-6
                );
                let c = kids[k];
                let q = c[0] + (c[1] - c[0]) * cu + (c[2] - c[0]) * cv;
                assert!((p - q).length() < 1e-5, "{u} {v}: {p} vs {q}");
            }
        }
    }
}
