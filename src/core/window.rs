//! Render windows: the part of an image, and of each pixel's samples, that
//! one render covers, so that a render can be split into shards whose
//! results put together are exactly the whole render.
//!
//! A window is a set of columns of a set of image rows, and a range of
//! sample indices out of the image's `spp`. Nothing rendered inside a
//! window depends on the window: every random number is keyed by the
//! image-wide pixel index and the sample index, film positions depend on
//! the image's `spp` (not on how many of its samples are rendered), and
//! pixel sums are exact (see [`PixelSum`](crate::image::film::PixelSum)).

use std::ops::Range;

/// Columns `columns` of the image rows in `rows`, samples `samples` of
/// each pixel's `spp`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct RenderWindow {
    /// Image columns, half-open.
    pub columns: Range<u32>,
    /// Image rows as half-open ranges, ascending and disjoint.
    pub rows: Vec<Range<u32>>,
    /// Sample indices, half-open, within `0..spp`.
    pub samples: Range<u32>,
}

impl RenderWindow {
    /// The whole `width` x `height` image with all `spp` samples.
    #[allow(clippy::single_range_in_vec_init)] // one range of rows, meant
    pub fn full(width: u32, height: u32, spp: u32) -> Self {
        Self {
            columns: 0..width,
            rows: vec![0..height],
            samples: 0..spp,
        }
    }

    /// Number of image rows covered.
    pub fn row_count(&self) -> u32 {
        self.rows.iter().map(|r| r.end - r.start).sum()
    }

    /// Number of pixels covered.
    pub fn pixel_count(&self) -> u64 {
        (self.columns.end - self.columns.start) as u64 * self.row_count() as u64
    }

    /// Rejects a window that is empty or leaves the `width` x `height`
    /// image or its `spp` samples, or whose rows are not ascending and
    /// disjoint.
    pub fn validate(&self, width: u32, height: u32, spp: u32) -> Result<(), String> {
        let c = &self.columns;
        if c.start >= c.end || c.end > width {
            return Err(format!(
                "window columns {}..{} must be a non-empty range within the image width {width}",
                c.start, c.end
            ));
        }
        if self.rows.is_empty() {
            return Err("window has no rows".into());
        }
        let mut last_end = 0;
        for r in &self.rows {
            if r.start >= r.end || r.end > height || r.start < last_end {
                return Err(format!(
                    "window rows {}..{} must be non-empty, ascending, disjoint and within the image height {height}",
                    r.start, r.end
                ));
            }
            last_end = r.end;
        }
        let s = &self.samples;
        if s.start >= s.end || s.end > spp {
            return Err(format!(
                "window samples {}..{} must be a non-empty range within 0..{spp}",
                s.start, s.end
            ));
        }
        Ok(())
    }
}

/// Where each path of a window goes: path `p` (counted from 0 within the
/// window) is sample `samples.start + p % n` of the window's pixel `p / n`
/// (`n` samples per pixel), window pixels being row-major over the
/// window's columns and rows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PathMap {
    image_width: u32,
    x0: u32,
    columns: u32,
    /// The image row of each window row.
    rows: Vec<u32>,
    s0: u32,
    samples: u32,
}

/// The keys of one path: its image pixel and sample index, and its pixel
/// in the window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PathKey {
    /// Image column.
    pub x: u32,
    /// Image row.
    pub y: u32,
    /// Sample index within the image's `spp`.
    pub sample: u32,
    /// Pixel index within the window (row-major).
    pub window_pixel: u64,
}

impl PathKey {
    /// The image-wide pixel index that keys random numbers,
    /// `y * image_width + x`.
    #[inline]
    pub fn pixel(&self, image_width: u32) -> u32 {
        self.y * image_width + self.x
    }
}

impl PathMap {
    /// The map of `window` in an image `image_width` pixels wide.
    pub fn new(window: &RenderWindow, image_width: u32) -> Self {
        Self {
            image_width,
            x0: window.columns.start,
            columns: window.columns.end - window.columns.start,
            rows: window.rows.iter().flat_map(|r| r.clone()).collect(),
            s0: window.samples.start,
            samples: window.samples.end - window.samples.start,
        }
    }

    /// Window width in pixels.
    pub fn columns(&self) -> u32 {
        self.columns
    }

    /// First image column.
    pub fn first_column(&self) -> u32 {
        self.x0
    }

    /// The image row of each window row.
    pub fn rows(&self) -> &[u32] {
        &self.rows
    }

    /// Samples rendered per pixel.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// First sample index.
    pub fn first_sample(&self) -> u32 {
        self.s0
    }

    /// Number of paths: pixels times samples.
    pub fn path_count(&self) -> u64 {
        self.columns as u64 * self.rows.len() as u64 * self.samples as u64
    }

    /// The keys of path `p`.
    #[inline]
    pub fn path(&self, p: u64) -> PathKey {
        let n = self.samples as u64;
        let window_pixel = p / n;
        let sample = self.s0 + (p % n) as u32;
        let c = self.columns as u64;
        let x = self.x0 + (window_pixel % c) as u32;
        let y = self.rows[(window_pixel / c) as usize];
        PathKey {
            x,
            y,
            sample,
            window_pixel,
        }
    }

    /// The keys of paths `first`, `first + 1`, ... (up to the window's
    /// last path): each [`PathMap::path`] of its index, stepped from the
    /// previous one instead of divided out (for stages that walk a run of
    /// consecutive paths).
    pub fn paths_from(&self, first: u64) -> impl Iterator<Item = PathKey> + '_ {
        let count = self.path_count().saturating_sub(first);
        let mut k = (first < self.path_count()).then(|| self.path(first));
        let mut row = k.map_or(0, |k| (k.window_pixel / self.columns as u64) as usize);
        (0..count).map(move |_| {
            let key = k.expect("a path is left");
            let mut next = key;
            next.sample += 1;
            if next.sample == self.s0 + self.samples {
                next.sample = self.s0;
                next.window_pixel += 1;
                next.x += 1;
                if next.x == self.x0 + self.columns {
                    next.x = self.x0;
                    row += 1;
                    // Past the last row only when `key` was the last path.
                    next.y = self.rows.get(row).copied().unwrap_or(0);
                }
            }
            k = Some(next);
            key
        })
    }

    /// The image-wide pixel index and sample index of path `p`, the keys
    /// of its random numbers.
    #[inline]
    pub fn sampler_keys(&self, p: u64) -> (u32, u32) {
        let k = self.path(p);
        (k.pixel(self.image_width), k.sample)
    }
}

/// Bands of rows per shard: `--shard I/N` cuts the image into `4 N` bands
/// (fewer for short images) and gives shard `I` bands `I, I + N, ...`, so
/// that every shard gets rows from all over the image.
pub const BANDS_PER_SHARD: u32 = 4;

/// The rows of shard `index` of `count` in an image `height` rows tall:
/// the image is cut into `min(height, 4 count)` bands, band `b` covering
/// rows `b h / B .. (b + 1) h / B` (integer division: no band is lost or
/// shared whatever the sizes), and the shard takes every `count`-th band
/// from band `index`, adjacent bands joined.
pub fn shard_rows(index: u32, count: u32, height: u32) -> Result<Vec<Range<u32>>, String> {
    if count == 0 || index >= count || count > height {
        return Err(format!(
            "--shard {index}/{count}: the image has only {height} rows, so at most {height} shards"
        ));
    }
    let bands = (count * BANDS_PER_SHARD).min(height) as u64;
    let h = height as u64;
    let mut rows: Vec<Range<u32>> = Vec::new();
    for b in (index as u64..bands).step_by(count as usize) {
        let r = (b * h / bands) as u32..((b + 1) * h / bands) as u32;
        match rows.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => rows.push(r),
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Walking consecutive paths gives each path's keys, from any start,
    /// in windows of several rows, columns and sample ranges.
    #[test]
    #[allow(clippy::single_range_in_vec_init)] // one range of rows, meant
    fn walking_paths_gives_each_paths_keys() {
        for (columns, rows, samples) in [
            (0..7u32, vec![2..4u32, 6..7], 1..4u32),
            (3..4, vec![0..5], 0..1),
            (0..5, vec![1..2], 2..3),
        ] {
            let window = RenderWindow {
                columns,
                rows,
                samples,
            };
            let map = PathMap::new(&window, 9);
            let n = map.path_count();
            for first in [0, 1, 5, n - 1, n] {
                let walked: Vec<PathKey> = map.paths_from(first).collect();
                let divided: Vec<PathKey> = (first..n).map(|p| map.path(p)).collect();
                assert_eq!(walked, divided, "{window:?} from {first}");
            }
        }
    }

    #[test]
    fn shard_rows_partition_the_image_and_interleave() {
        for height in [1u32, 2, 7, 12, 100, 1081] {
            for count in 1..=height.min(9) {
                let mut seen = vec![0u32; height as usize];
                for i in 0..count {
                    let rows = shard_rows(i, count, height).unwrap();
                    assert!(!rows.is_empty(), "{i}/{count} of {height}");
                    for r in rows {
                        for y in r {
                            seen[y as usize] += 1;
                        }
                    }
                }
                assert!(seen.iter().all(|&c| c == 1), "{count} of {height}");
            }
        }
        // Interleaved bands: shard 0 of 2 on 16 rows has 4 bands of 2.
        assert_eq!(
            shard_rows(0, 2, 16).unwrap(),
            vec![0..2, 4..6, 8..10, 12..14]
        );
        assert_eq!(shard_rows(0, 1, 16).unwrap(), vec![0..16]);
        assert!(shard_rows(0, 9, 8).is_err());
    }

    #[test]
    fn full_window_paths_are_pixel_major_like_the_whole_image() {
        let w = RenderWindow::full(5, 3, 4);
        let m = PathMap::new(&w, 5);
        assert_eq!(m.path_count(), 60);
        for p in 0..60u64 {
            let k = m.path(p);
            assert_eq!(k.pixel(5) as u64, p / 4);
            assert_eq!(k.sample as u64, p % 4);
            assert_eq!(k.window_pixel, p / 4);
        }
    }

    #[test]
    fn partial_window_visits_each_pixel_sample_once() {
        let w = RenderWindow {
            columns: 2..5,
            rows: vec![1..2, 4..6],
            samples: 3..5,
        };
        assert!(w.validate(7, 6, 8).is_ok());
        let m = PathMap::new(&w, 7);
        let mut seen = std::collections::HashSet::new();
        for p in 0..m.path_count() {
            let k = m.path(p);
            assert!((2..5).contains(&k.x) && [1, 4, 5].contains(&k.y));
            assert!((3..5).contains(&k.sample));
            assert!(seen.insert((k.x, k.y, k.sample)));
        }
        assert_eq!(seen.len(), 3 * 3 * 2);
        assert!(w.validate(4, 6, 8).is_err());
        assert!(w.validate(7, 5, 8).is_err());
        assert!(w.validate(7, 6, 4).is_err());
        let unordered = RenderWindow {
            rows: vec![4..6, 1..2],
            ..w.clone()
        };
        assert!(unordered.validate(7, 6, 8).is_err());
    }
}
