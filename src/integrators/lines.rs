//! Feature lines found by ray casting (after Choudhury and Parker 2009 and
//! Ogaki and Georgiev 2018): silhouettes, creases, borders of open meshes
//! and material boundaries, as an anti-aliased coverage mask.
//!
//! A first ray through every pixel centre finds the pixels within half the
//! line width plus a pixel of two neighbouring centres that differ (see
//! below); only those candidates are divided into a fixed grid of
//! [`SUBSAMPLES`] x [`SUBSAMPLES`] sub-pixel positions, with one ray cast
//! through each (and through the positions their stencils reach). A
//! feature no pixel-centre ray sees differ from its neighbours (something
//! thinner than a pixel between centres) is missed.
//! A ray that meets a perfect mirror or clear glass (a surface without a
//! lit lobe) is followed through it (refraction when it exists, reflection
//! otherwise) up to the settings' `max_depth`, so lines appear in mirrors
//! and through glass. Each ray records what it finally saw
//! ([`Feature`]): the specular path it took, the instance, the material,
//! the side, the point and the normals.
//!
//! A sub-pixel position is ink when some other position within half the
//! line width of it (its stencil) saw something [`Feature::edge`] calls
//! different: another object or the background (silhouette), another
//! specular path, another material, the other side of a surface (the
//! border of an open mesh seen from both sides), a normal deviating by more
//! than the crease angle, or a surface far off its own tangent plane (a
//! part of the same object occluding another). The ink band is therefore
//! the line width wide, centred on the edge. A pixel's coverage is the
//! fraction of its positions that are ink.
//!
//! Lines depend only on geometry, materials' classes and the camera: not on
//! lights, exposure, samples per pixel or the number of threads (bands of
//! rows are computed independently and each position's ray is a fixed
//! function of its coordinates).

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use crate::core::math::Ray;
use crate::core::settings::{LineSettings, RenderSettings};
use crate::image::lines::LineOverlay;
use crate::integrators::Progress;
use crate::scene::RenderScene;
use crate::scene::camera::CameraRays;
use crate::transport::interaction::Interaction;
use crate::transport::whitted::scatter;

/// Sub-pixel positions per pixel side: 16 rays per pixel.
pub const SUBSAMPLES: u32 = 4;

/// Pixel rows per parallel band.
const BAND_ROWS: u32 = 8;

/// Relative ray-distance mismatch above which two samples of one object
/// are on different parts of it (one occluding the other): each sample's
/// tangent plane must predict the other's distance within 2%.
pub const DEPTH_TOLERANCE: f32 = 0.02;

/// Extra angle (degrees) a normal deviation must exceed the crease angle
/// by: keeps a cube's 90-degree edges out at a threshold of exactly 90
/// despite rounding.
const CREASE_MARGIN_DEGREES: f32 = 1e-3;

/// What a sub-pixel ray finally saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feature {
    /// Hash of the specular bounces taken on the way (0 for none).
    pub path: u64,
    /// Instance seen, `u32::MAX` for the background.
    pub instance: u32,
    /// Material seen.
    pub material: u32,
    /// Whether the front (outward) side was seen.
    pub front: bool,
    /// World point.
    pub point: Vec3A,
    /// Shading normal on the viewer's side.
    pub ns: Vec3A,
    /// Geometric normal on the viewer's side.
    pub ng: Vec3A,
    /// Origin of the last ray segment.
    pub origin: Vec3A,
    /// Unit direction of the last ray segment.
    pub direction: Vec3A,
    /// Distance along the last segment.
    pub t: f32,
    /// Length of the whole path from the eye (the scale of the depth test).
    pub distance: f32,
}

impl Feature {
    const MISS: u32 = u32::MAX;

    /// A placeholder for positions that are not traced.
    const NOTHING: Feature = Feature {
        path: 0,
        instance: Self::MISS,
        material: Self::MISS,
        front: true,
        point: Vec3A::ZERO,
        ns: Vec3A::ZERO,
        ng: Vec3A::ZERO,
        origin: Vec3A::ZERO,
        direction: Vec3A::ZERO,
        t: f32::INFINITY,
        distance: f32::INFINITY,
    };

    /// What the ray `ray` sees, followed through mirrors and glass for at
    /// most `max_depth` bounces. Counts the rays cast in `rays`.
    pub fn trace(scene: &RenderScene, ray: Ray, max_depth: u32, rays: &mut u64) -> Self {
        let mut ray = ray;
        let mut path = 0u64;
        let mut depth = 0;
        let mut travelled = 0.0f32;
        loop {
            *rays += 1;
            let direction = ray.direction.normalize();
            let Some(hit) = scene.intersect(&ray, 0.0, f32::INFINITY) else {
                return Feature {
                    path,
                    instance: Self::MISS,
                    material: Self::MISS,
                    front: true,
                    point: Vec3A::ZERO,
                    ns: Vec3A::ZERO,
                    ng: Vec3A::ZERO,
                    origin: ray.origin,
                    direction,
                    t: f32::INFINITY,
                    distance: f32::INFINITY,
                };
            };
            let it = Interaction::new(scene, &ray, &hit);
            let s = &it.surface;
            let specular_only =
                !it.is_lit_by_lights() && (s.mirror.max_element() > 0.0 || s.transmission > 0.0);
            if specular_only && depth < max_depth {
                let [reflection, refraction] = scatter(&it);
                let next = match (refraction, reflection) {
                    (Some(r), _) => Some((r, 2u64)),
                    (None, Some(r)) => Some((r, 1u64)),
                    _ => None,
                };
                if let Some((next, kind)) = next {
                    path = (path ^ ((hit.instance as u64) << 2 | kind))
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                        .rotate_left(17)
                        | 1;
                    travelled += (hit.point - ray.origin).length();
                    ray = next.ray;
                    depth += 1;
                    continue;
                }
            }
            return Feature {
                path,
                instance: hit.instance,
                material: hit.material,
                front: it.front_face,
                point: hit.point,
                ns: it.ns,
                ng: it.ng,
                origin: ray.origin,
                direction,
                t: (hit.point - ray.origin).length(),
                distance: travelled + (hit.point - ray.origin).length(),
            };
        }
    }

    /// Whether a feature line separates `self` from `other`; `cos_crease`
    /// is the cosine of the crease angle plus a small margin.
    pub fn edge(&self, other: &Feature, cos_crease: f32) -> bool {
        if self.path != other.path || self.instance != other.instance {
            return true;
        }
        if self.instance == Self::MISS {
            return false;
        }
        if self.material != other.material || self.front != other.front {
            return true;
        }
        if self.ns.dot(other.ns) < cos_crease {
            return true;
        }
        self.off_plane(other) && other.off_plane(self)
    }

    /// Whether `self`'s tangent plane misses `other`'s distance along
    /// `other`'s last ray by more than [`DEPTH_TOLERANCE`] of `other`'s
    /// whole path length.
    fn off_plane(&self, other: &Feature) -> bool {
        let denom = self.ng.dot(other.direction);
        if denom.abs() < 1e-6 {
            return true;
        }
        let t_plane = self.ng.dot(self.point - other.origin) / denom;
        !((t_plane - other.t).abs() <= DEPTH_TOLERANCE * other.distance)
    }
}

/// Cosine below which two normals make a crease under `lines`.
pub fn crease_cosine(lines: &LineSettings) -> f32 {
    crease_cosine_degrees(lines.crease_degrees)
}

/// Cosine below which two unit normals deviate by more than `degrees`
/// (plus a margin of 0.001 degrees); below -1 when `degrees` is 180, so
/// that nothing is a crease.
pub fn crease_cosine_degrees(degrees: f32) -> f32 {
    if degrees >= 180.0 {
        return -2.0;
    }
    (degrees + CREASE_MARGIN_DEGREES)
        .min(180.0)
        .to_radians()
        .cos()
}

/// Stencil offsets, in sub-pixel steps, within half the line width: at
/// least the four axis neighbours.
pub fn stencil(width: f32) -> Vec<(i32, i32)> {
    let r = (0.5 * width * SUBSAMPLES as f32).max(1.0);
    let ri = r.floor() as i32;
    let mut v = Vec::new();
    for dy in -ri..=ri {
        for dx in -ri..=ri {
            let d2 = (dx * dx + dy * dy) as f32;
            if (dx, dy) != (0, 0) && d2 <= r * r + 1e-4 {
                v.push((dx, dy));
            }
        }
    }
    v
}

/// Summed-area table (`(gw + 1) x (gh + 1)`, exclusive prefix sums) of
/// the grid positions that [`Feature::edge`] separates from their right or
/// lower neighbour (both of the pair are counted).
fn edge_table(grid: &[Feature], gw: usize, gh: usize, cos_crease: f32) -> Vec<u32> {
    let mut flag = vec![0u32; gw * gh];
    for j in 0..gh {
        for i in 0..gw {
            let a = &grid[j * gw + i];
            if i + 1 < gw && a.edge(&grid[j * gw + i + 1], cos_crease) {
                flag[j * gw + i] = 1;
                flag[j * gw + i + 1] = 1;
            }
            if j + 1 < gh && a.edge(&grid[(j + 1) * gw + i], cos_crease) {
                flag[j * gw + i] = 1;
                flag[(j + 1) * gw + i] = 1;
            }
        }
    }
    let mut sat = vec![0u32; (gw + 1) * (gh + 1)];
    for j in 0..gh {
        let mut row = 0;
        for i in 0..gw {
            row += flag[j * gw + i];
            sat[(j + 1) * (gw + 1) + i + 1] = sat[j * (gw + 1) + i + 1] + row;
        }
    }
    sat
}

/// What the line pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LineReport {
    /// Rays cast (sub-pixel rays and their specular bounces).
    pub rays: u64,
}

/// Finds the feature lines of `scene` seen through `camera` at the
/// settings' image size, with `lines`' width, colour and crease angle.
/// `progress` is called with pixel rows finished.
pub fn render_lines(
    scene: &RenderScene,
    camera: &CameraRays,
    settings: &RenderSettings,
    lines: &LineSettings,
    progress: Option<Progress<'_>>,
) -> (LineOverlay, LineReport) {
    let (w, h) = (settings.width, settings.height);
    let s = SUBSAMPLES as i32;
    let offsets = stencil(lines.width);
    let halo = offsets
        .iter()
        .map(|&(x, y)| x.abs().max(y.abs()))
        .max()
        .unwrap_or(1);
    let cos_crease = crease_cosine(lines);
    let bands: Vec<u32> = (0..h.div_ceil(BAND_ROWS)).collect();
    let results: Vec<(Vec<f32>, u64)> = bands
        .par_iter()
        .with_max_len(1)
        .map(|&b| {
            let y0 = b * BAND_ROWS;
            let rows = BAND_ROWS.min(h - y0);
            // Sub-pixel grid of the band with its halo.
            let gx0 = -halo;
            let gy0 = y0 as i32 * s - halo;
            let gw = (w as i32 * s + 2 * halo) as usize;
            let gh = (rows as i32 * s + 2 * halo) as usize;
            let mut rays = 0u64;
            // Coarse pass: one ray through each pixel centre of the band
            // and a margin; pixels within `reach` of two differing
            // neighbouring centres are candidates, the only ones whose
            // sub-pixel positions are traced.
            let reach = (0.5 * lines.width).ceil() as i32 + 1;
            let margin = reach + 1;
            let cw = (w as i32 + 2 * margin) as usize;
            let ch = (rows as i32 + 2 * margin) as usize;
            let mut coarse = Vec::with_capacity(cw * ch);
            for j in 0..ch {
                for i in 0..cw {
                    let p = Vec2::new(
                        i as f32 - margin as f32 + 0.5,
                        (y0 as i32 + j as i32 - margin) as f32 + 0.5,
                    );
                    coarse.push(Feature::trace(
                        scene,
                        camera.ray(p),
                        settings.max_depth,
                        &mut rays,
                    ));
                }
            }
            let mut flagged = vec![false; cw * ch];
            for j in 0..ch {
                for i in 0..cw {
                    let a = &coarse[j * cw + i];
                    for (di, dj) in [(1i32, 0i32), (0, 1), (1, 1), (-1, 1)] {
                        let (ni, nj) = (i as i32 + di, j as i32 + dj);
                        if ni < 0 || ni >= cw as i32 || nj >= ch as i32 {
                            continue;
                        }
                        let n = nj as usize * cw + ni as usize;
                        if a.edge(&coarse[n], cos_crease) {
                            flagged[j * cw + i] = true;
                            flagged[n] = true;
                        }
                    }
                }
            }
            let candidate = |px: i32, py: i32| {
                let (ci, cj) = (px + margin, py + margin);
                (cj - reach..=cj + reach).any(|j| {
                    (ci - reach..=ci + reach).any(|i| flagged[j as usize * cw + i as usize])
                })
            };
            let candidates: Vec<bool> = (0..rows as i32)
                .flat_map(|py| (0..w as i32).map(move |px| (px, py)))
                .map(|(px, py)| candidate(px, py))
                .collect();
            // Sub-pixel positions of candidate pixels and their stencils.
            let mut needed = vec![false; gw * gh];
            for py in 0..rows as i32 {
                for px in 0..w as i32 {
                    if !candidates[(py as u32 * w + px as u32) as usize] {
                        continue;
                    }
                    for j in py * s..(py + 1) * s + 2 * halo {
                        for i in px * s..(px + 1) * s + 2 * halo {
                            needed[j as usize * gw + i as usize] = true;
                        }
                    }
                }
            }
            let mut grid = Vec::with_capacity(gw * gh);
            for j in 0..gh {
                for i in 0..gw {
                    if !needed[j * gw + i] {
                        // Never compared with a candidate's position.
                        grid.push(Feature::NOTHING);
                        continue;
                    }
                    let gx = gx0 + i as i32;
                    let gy = gy0 + j as i32;
                    let p = Vec2::new((gx as f32 + 0.5) / s as f32, (gy as f32 + 0.5) / s as f32);
                    grid.push(Feature::trace(
                        scene,
                        camera.ray(p),
                        settings.max_depth,
                        &mut rays,
                    ));
                }
            }
            // Prefilter: positions that differ from a horizontal or vertical
            // neighbour, summed over rectangles. A position whose square of
            // stencil radius holds none of them is not tested further (a
            // difference between two positions of the square implies one
            // between neighbours on the grid path joining them, for
            // everything but slow drifts of normal or depth, which are
            // not lines).
            let sat = edge_table(&grid, gw, gh, cos_crease);
            let near_edge = |i: usize, j: usize| {
                let r = halo as usize;
                let (x0, y0, x1, y1) = (i - r, j - r, i + r + 1, j + r + 1);
                sat[y1 * (gw + 1) + x1] + sat[y0 * (gw + 1) + x0]
                    > sat[y0 * (gw + 1) + x1] + sat[y1 * (gw + 1) + x0]
            };
            let mut cov = vec![0.0f32; (w * rows) as usize];
            let per_pixel = 1.0 / (s * s) as f32;
            for py in 0..rows as i32 {
                for px in 0..w as i32 {
                    if !candidates[(py as u32 * w + px as u32) as usize] {
                        continue;
                    }
                    let mut ink = 0;
                    for sy in 0..s {
                        for sx in 0..s {
                            let i = (px * s + sx + halo) as usize;
                            let j = (py * s + sy + halo) as usize;
                            let a = &grid[j * gw + i];
                            let on_line = near_edge(i, j)
                                && offsets.iter().any(|&(dx, dy)| {
                                    let b = &grid
                                        [(j as i32 + dy) as usize * gw + (i as i32 + dx) as usize];
                                    a.edge(b, cos_crease)
                                });
                            ink += on_line as u32;
                        }
                    }
                    cov[(py as u32 * w + px as u32) as usize] = ink as f32 * per_pixel;
                }
            }
            if let Some(p) = progress {
                p(rows as u64);
            }
            (cov, rays)
        })
        .collect();
    let mut coverage = Vec::with_capacity((w * h) as usize);
    let mut report = LineReport::default();
    for (c, r) in results {
        coverage.extend(c);
        report.rays += r;
    }
    (
        LineOverlay {
            width: w,
            height: h,
            coverage,
            color: lines.color,
        },
        report,
    )
}
