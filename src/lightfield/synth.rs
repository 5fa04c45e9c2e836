//! View synthesis from a two-plane light field: quadrilinear interpolation
//! in `(u, v, s, t)`, optionally depth-corrected by a proxy plane.
//!
//! Time per view is a fixed amount of work per pixel (two plane
//! intersections and at most 16 image reads); the scene the light field
//! was captured from plays no part, however many triangles it had.
//!
//! # Exactness at the samples
//! Interpolation positions within [`SNAP`] (a ten-thousandth of a grid
//! cell or of a pixel) of a sample are moved onto it, and samples of zero
//! weight are not read. A view from a grid camera's eye with its frame
//! and size ([`crate::lightfield::Rig::camera`]) therefore reads one
//! sample per pixel with weight 1 and reproduces the captured image bit
//! for bit.
//!
//! # Outside the light field
//! A ray carries light-field radiance only if it travels from the camera
//! plane towards the focal plane, crosses the camera plane inside the hull
//! of the camera centres and the focal plane inside the focal window. What
//! happens to other rays is the [`Outside`] policy: black (counted), the
//! nearest sample (clamped) or an error. A view none of whose rays is
//! inside is an error under every policy but clamping.

use glam::DVec3;
use rayon::prelude::*;

use crate::core::error::{Error, Result};
use crate::core::math::Color;
use crate::image::film::Film;
use crate::lightfield::{LightField, Rig};
use crate::scene::camera::{Camera, Projection};

/// Interpolation positions this close to a sample (in grid cells or
/// pixels) are snapped onto it.
pub const SNAP: f64 = 1e-4;

/// What a pixel whose ray lies outside the light field gets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Outside {
    /// Black, and the pixel is counted in [`Synthesis::outside`].
    #[default]
    Black,
    /// The nearest valid sample: the ray's camera-plane and focal-plane
    /// positions are clamped into the hull and the window (rays travelling
    /// away from the focal plane stay black). Counted as well.
    Clamp,
    /// An error saying how many pixels were outside.
    Error,
}

/// How to synthesise.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SynthOptions {
    /// Depth correction: distance from the camera plane (along the rig's
    /// forward) of a proxy plane parallel to it. `None` (or the focal
    /// distance) is plain quadrilinear interpolation.
    pub proxy_depth: Option<f64>,
    /// Rays outside the light field.
    pub outside: Outside,
}

/// A synthesised view.
#[derive(Clone, Debug)]
pub struct Synthesis {
    /// The image.
    pub film: Film,
    /// Pixels whose ray was outside the light field (black or clamped).
    pub outside: usize,
}

/// Position `x` in samples `0..n` (`n >= 1`): the first sample and the
/// weight of the next one, after clamping into `[0, n - 1]` and snapping.
#[inline]
fn split(x: f64, n: u32) -> (u32, f32) {
    if n == 1 {
        return (0, 0.0);
    }
    let x = x.clamp(0.0, (n - 1) as f64);
    let i = (x.floor() as u32).min(n - 2);
    let f = x - i as f64;
    let f = if f < SNAP {
        0.0
    } else if f > 1.0 - SNAP {
        1.0
    } else {
        f
    };
    (i, f as f32)
}

/// The light field prepared for lookups.
struct Lookup<'a> {
    lf: &'a LightField,
    rig: &'a Rig,
    /// Focal window width and height.
    window: (f64, f64),
    proxy: Option<f64>,
    outside: Outside,
}

impl Lookup<'_> {
    /// Continuous pixel coordinates (pixel centres at integers) of focal
    /// plane point `(x, y)` in the rig frame.
    #[inline]
    fn pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let (sw, sh) = self.window;
        let [w, h] = self.rig.resolution;
        (
            (x / sw + 0.5) * w as f64 - 0.5,
            (0.5 - y / sh) * h as f64 - 0.5,
        )
    }

    /// Radiance along the ray from `o` in direction `d` (both in the rig
    /// frame), and whether the ray was inside the light field.
    fn radiance(&self, o: DVec3, d: DVec3) -> (Color, bool) {
        let rig = self.rig;
        if d.z <= 0.0 || !(o.is_finite() && d.is_finite()) {
            return (Color::ZERO, false);
        }
        let [cols, rows] = rig.grid;
        let [w, h] = rig.resolution;
        let at = |z: f64| o + d * ((z - o.z) / d.z);
        let p0 = at(0.0);
        let gu = p0.x / rig.spacing + (cols as f64 - 1.0) * 0.5;
        let gv = (rows as f64 - 1.0) * 0.5 - p0.y / rig.spacing;
        let p1 = at(rig.focal_distance);
        let (sx, sy) = self.pixel(p1.x, p1.y);
        let inside = (-SNAP..=cols as f64 - 1.0 + SNAP).contains(&gu)
            && (-SNAP..=rows as f64 - 1.0 + SNAP).contains(&gv)
            && (-0.5 - SNAP..=w as f64 - 0.5 + SNAP).contains(&sx)
            && (-0.5 - SNAP..=h as f64 - 0.5 + SNAP).contains(&sy);
        if !inside && self.outside != Outside::Clamp {
            return (Color::ZERO, false);
        }
        let proxy_point = self.proxy.map(at);
        let (i0, fu) = split(gu, cols);
        let (j0, fv) = split(gv, rows);
        let mut sum = Color::ZERO;
        for (dj, wv) in [(0, 1.0 - fv), (1, fv)] {
            if wv == 0.0 {
                continue;
            }
            for (di, wu) in [(0, 1.0 - fu), (1, fu)] {
                if wu == 0.0 {
                    continue;
                }
                let (ci, cj) = (i0 + di, j0 + dj);
                let (sx, sy) = match proxy_point {
                    // The proxy point seen from camera (ci, cj), on the
                    // focal plane.
                    Some(p) => {
                        let (a, b) = rig.offset(ci, cj);
                        let k = rig.focal_distance / p.z;
                        self.pixel(a + (p.x - a) * k, b + (p.y - b) * k)
                    }
                    None => (sx, sy),
                };
                let image = self.lf.image(ci, cj);
                let (x0, fs) = split(sx, w);
                let (y0, ft) = split(sy, h);
                for (dy, wt) in [(0, 1.0 - ft), (1, ft)] {
                    if wt == 0.0 {
                        continue;
                    }
                    for (dx, ws) in [(0, 1.0 - fs), (1, fs)] {
                        if ws == 0.0 {
                            continue;
                        }
                        sum += image.get(x0 + dx, y0 + dy) * (wu * wv * ws * wt);
                    }
                }
            }
        }
        (sum, inside)
    }
}

/// Renders the view of `camera` (a pinhole, its [`shift`](Camera::shift)
/// included) at `width` x `height` from the light field alone: one ray
/// through each pixel centre, computed in f64 like
/// [`CameraRays::ray`](crate::scene::camera::CameraRays::ray). Rows in
/// parallel; the result does not depend on the thread count.
pub fn synthesise(
    lf: &LightField,
    camera: &Camera,
    width: u32,
    height: u32,
    options: SynthOptions,
) -> Result<Synthesis> {
    camera.validate().map_err(Error::Invalid)?;
    if camera.projection != Projection::Perspective || camera.lens_radius > 0.0 {
        return Err(Error::Invalid(
            "views made from a light field are pinhole perspective views (no lens, not orthographic)"
                .into(),
        ));
    }
    if width == 0 || height == 0 {
        return Err(Error::Invalid(format!(
            "the view is empty ({width}x{height})"
        )));
    }
    let rig = lf.rig();
    if let Some(z) = options.proxy_depth
        && !(z.is_finite() && z > 0.0)
    {
        return Err(Error::Invalid(format!(
            "the proxy plane's depth must be finite and positive (in front of the camera plane), got {z}"
        )));
    }
    let lookup = Lookup {
        lf,
        rig,
        window: rig.window_size(),
        proxy: options.proxy_depth,
        outside: options.outside,
    };
    let forward = (camera.look_at - camera.look_from).normalize();
    let right = forward.cross(camera.up.as_dvec3()).normalize();
    let up = right.cross(forward);
    let half_h = (camera.vfov_degrees.to_radians() as f64 * 0.5).tan();
    let half_w = half_h * width as f64 / height as f64;
    let centre = forward
        + right * (2.0 * half_h * camera.shift.x as f64)
        + up * (2.0 * half_h * camera.shift.y as f64);
    let top_left = centre - right * half_w + up * half_h;
    let dx = right * (2.0 * half_w / width as f64);
    let dy = -up * (2.0 * half_h / height as f64);
    let eye = rig.to_rig(camera.look_from);
    let mut film = Film::new(width, height);
    let outside: usize = film
        .pixels
        .par_chunks_mut(width as usize)
        .enumerate()
        .with_max_len(1)
        .map(|(y, row)| {
            let mut outside = 0;
            for (x, px) in row.iter_mut().enumerate() {
                let d = top_left + dx * (x as f64 + 0.5) + dy * (y as f64 + 0.5);
                let (c, inside) = lookup.radiance(eye, rig.direction_to_rig(d.normalize()));
                *px = c;
                outside += !inside as usize;
            }
            outside
        })
        .sum();
    let total = width as usize * height as usize;
    let (gu, gv) = rig.grid_position(camera.look_from);
    let where_ = format!(
        "the view's eye is at grid column {gu:.3}, row {gv:.3} and {:.4} in front of the camera plane \
         (cameras span columns 0..{} and rows 0..{}; views are valid from eyes whose rays cross the \
         camera plane inside that hull, looking through the focal window)",
        eye.z,
        rig.grid[0] - 1,
        rig.grid[1] - 1
    );
    if outside == total && options.outside != Outside::Clamp {
        return Err(Error::Invalid(format!(
            "the view sees nothing of the light field: every ray is outside its valid region; {where_}"
        )));
    }
    if outside > 0 && options.outside == Outside::Error {
        return Err(Error::Invalid(format!(
            "{outside} of {total} pixels see rays outside the light field's valid region; {where_}"
        )));
    }
    Ok(Synthesis { film, outside })
}

impl Rig {
    /// Continuous grid column and row of world point `p` projected along
    /// `forward` onto the camera plane.
    pub fn grid_position(&self, p: DVec3) -> (f64, f64) {
        let q = self.to_rig(p);
        (
            q.x / self.spacing + (self.grid[0] as f64 - 1.0) * 0.5,
            (self.grid[1] as f64 - 1.0) * 0.5 - q.y / self.spacing,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions snap onto samples within `SNAP`, clamp at the ends, and a
    /// single sample takes all the weight.
    #[test]
    fn split_snaps_and_clamps() {
        assert_eq!(split(2.0, 5), (2, 0.0));
        assert_eq!(split(2.0 + SNAP / 2.0, 5), (2, 0.0));
        assert_eq!(split(3.0 - SNAP / 2.0, 5), (2, 1.0));
        assert_eq!(split(4.0, 5), (3, 1.0));
        assert_eq!(split(-1.0, 5), (0, 0.0));
        assert_eq!(split(7.5, 5), (3, 1.0));
        assert_eq!(split(0.25, 3), (0, 0.25));
        assert_eq!(split(0.7, 1), (0, 0.0));
    }
}
